"""Frames registered: a tripod nudged between photographs, measured and undone, and the lens's
distortion undone with it.

A frame's motion is a Euclidean map of the reference frame's pixels q onto its own,

    p = R(theta) (q - c) + c + (dx, dy),

c the image's centre, theta positive turning the scene clockwise as displayed (image y down).
It is measured on the high-passed luminance (:func:`features`) of undistorted frames: phase
correlation (Kuglin and Hines 1975) gives the shift, ECC (Evangelidis and Psarakis 2008) the
rotation, :func:`motion_covariance` the uncertainty.  Each photograph is resampled once onto the
reference's pinhole pixels (motion and distortion in one bilinear map), after its noise is found
on its own pixels.  The variance is resampled with the values' weights, not their squares: a
resampled pixel shares its errors with its neighbours, so a fit treating pixels as independent
gets a region's error right.  Regions are eroded by 1 px plus three sd of the motion.

References: C. D. Kuglin and D. C. Hines, "The phase correlation image alignment method",
Proc. IEEE Int. Conf. Cybernetics and Society, 163-165, 1975; G. D. Evangelidis and E. Z.
Psarakis, "Parametric image alignment using enhanced correlation coefficient maximization",
IEEE TPAMI 30(10), 1858-1865, 2008, doi:10.1109/TPAMI.2008.113; H. White, "A
heteroskedasticity-consistent covariance matrix estimator and a direct test for
heteroskedasticity", Econometrica 48(4), 817-838, 1980; K.-Y. Liang and S. L. Zeger,
"Longitudinal data analysis using generalized linear models", Biometrika 73(1), 13-22, 1986.
"""

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..errors import SkyfitError
from ..physics.camera import clipped
from ..physics.colour import SRGB_LUMINANCE
from ..physics.lens import distort, focal_px

#: The largest displacement [px] of any pixel of a frame from the reference (--register-limit).
LIMIT_PX = 5.0
#: The high-pass: luminance less its (normalised) Gaussian blur of this sd [px].
HIGHPASS_SD_PX = 1.5
#: ECC: OpenCV's Gaussian pre-filter size [px], most iterations, and stopping step [px].
ECC_FILTER, ECC_ITERATIONS, ECC_EPS = 1, 200, 1e-5
#: The least ECC correlation of a registered frame with the reference: below it the frames do
#: not show one scene alike enough to align.
MIN_CORRELATION = 0.5
#: Below this ECC correlation a registered frame is named: a helper's flare in the reference
#: read 0.55 (from 0.92) and biased turns by 0.25 degrees, shifts still right.
WEAK_CORRELATION = 0.75
#: A frame that moved less than this [px] (or than 3 sd of its motion) is taken as still and
#: not resampled: ECC finds small apparent motion on a still day, and resampling costs.
STILL_PX = 0.1
#: The tiles [px] of the motion's sandwich covariance: the high-passed residual (the day's
#: change of light) is correlated within a few pixels, not across this.
BLOCK_PX = 8
#: Shares of a resampled pixel from clipped sources within this of 0 or 1 count as none or all.
_SHARE_TOL = 1e-4


def luminance(values, sensor, falloff):
    """Linear luminance [1] of codes ``values`` (H, W, 3) [DN] over the vignetting ``falloff``;
    NaN where a channel is not finite or clipped (:func:`~skyfit_mi.physics.camera.clipped`): a
    clipped pixel's luminance is not known, and it would tie the match to where the light
    clips."""
    s = sensor.linearise(np.nan_to_num(values)) @ SRGB_LUMINANCE
    known = np.all(np.isfinite(values), axis=-1) & ~np.any(clipped(values, sensor.max_code),
                                                           axis=-1)
    return np.where(known, s / falloff, np.nan)


def features(lum):
    """(high-passed luminance (H, W) float32, validity mask uint8) of ``lum`` [1]: luminance over
    its median less its Gaussian blur of HIGHPASS_SD_PX, normalised over the valid pixels.
    Linear, not log: a pixel integrates the scene, so an edge's centroid moves with the camera
    whatever the grid's phase; a curve of the pixels biases sub-pixel shifts."""
    ok = np.isfinite(lum) & (lum > 0)
    if not ok.any():
        return np.zeros(lum.shape, np.float32), ok.astype(np.uint8)
    x = np.where(ok, lum / np.median(lum[ok]), 0.0)
    blur = lambda a: cv2.GaussianBlur(a, (0, 0), HIGHPASS_SD_PX)
    low = blur(x) / np.maximum(blur(ok.astype(float)), 1e-6)
    return np.where(ok, x - low, 0.0).astype(np.float32), ok.astype(np.uint8)


def measure_motion(ref, img):
    """The motion of ``img`` against ``ref`` (:func:`features` pairs): (M (2, 3), p = M [q, 1]
    of reference pixels q onto the frame's [px], ECC correlation); cv2.error if ECC diverges."""
    (f0, m0), (f1, m1) = ref, img
    h, w = f0.shape
    window = cv2.createHanningWindow((w, h), cv2.CV_32F)
    (dx, dy), _ = cv2.phaseCorrelate(f0.astype(np.float64), f1.astype(np.float64),
                                     window.astype(np.float64))
    M = np.float32([[1, 0, dx], [0, 1, dy]])
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, ECC_ITERATIONS, ECC_EPS)
    rho, M = cv2.findTransformECCWithMask(f0, f1, m0, m1, M, cv2.MOTION_EUCLIDEAN, criteria,
                                          ECC_FILTER)
    return M.astype(np.float64), float(rho)


def motion_covariance(ref, img, M):
    """Covariance (3, 3) of the motion (theta [rad] about the centre, tx, ty [px]) at ``M``.

    The fit is least squares of ref ~ a img(M q) + b, J the gradient along each parameter,
    H = a^2 J^T J.  Its residual r is mostly the day's change of light, spatially coherent, so
    the Gauss-Newton sigma^2 H^-1 understates it: the covariance is the sandwich
    H^-1 (sum_b g_b g_b^T) H^-1 over tiles b of BLOCK_PX (g_b = a J_b^T r_b), scaled by
    G/(G-3) for G tiles (White 1980; Liang and Zeger 1986), or the Gauss-Newton one where that
    is larger (few tiles).  Coverage: docs/BENCHMARKS.md, "The camera from marked points, and
    frames registered"."""
    (f0, m0), (f1, m1) = ref, img
    h, w = f0.shape
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    warped = cv2.warpAffine(f1, M.astype(np.float32), (w, h), flags=flags)
    valid = (m0 > 0) & (cv2.warpAffine(m1, M.astype(np.float32), (w, h), flags=flags) > 0)
    gy, gx = np.gradient(warped.astype(np.float64))
    yy, xx = np.mgrid[0:h, 0:w]
    xc, yc = xx - (w - 1) / 2.0, yy - (h - 1) / 2.0
    J = np.stack([-yc * gx + xc * gy, gx, gy], axis=-1)[valid]
    t = f0[valid] - f0[valid].mean()
    i = warped[valid] - warped[valid].mean()
    a = float(t @ i) / max(float(i @ i), 1e-12)
    r = t - a * i
    h_inv = np.linalg.pinv(a * a * J.T @ J)
    gauss_newton = float(r @ r) / max(len(r) - 4, 1) * h_inv
    tile = ((yy // BLOCK_PX) * (w // BLOCK_PX + 1) + xx // BLOCK_PX)[valid]
    tiles, idx = np.unique(tile, return_inverse=True)
    g = np.zeros((len(tiles), 3))
    np.add.at(g, idx, a * J * r[:, None])
    n = len(tiles)
    sandwich = h_inv @ (g.T @ g) @ h_inv * n / max(n - 3, 1)
    return max((sandwich, gauss_newton), key=lambda c: displacement_sd(c, w, h))


def displacement_sd(cov, width, height):
    """Rms over the pixels of one coordinate's displacement sd [px] under covariance ``cov``."""
    yy, xx = np.mgrid[0:height, 0:width]
    xc, yc = xx - (width - 1) / 2.0, yy - (height - 1) / 2.0
    var_x = cov[1, 1] + yc ** 2 * cov[0, 0] - 2 * yc * cov[0, 1]
    var_y = cov[2, 2] + xc ** 2 * cov[0, 0] + 2 * xc * cov[0, 2]
    return float(np.sqrt(np.mean(var_x + var_y) / 2.0))


def motion_record(M, width, height):
    """A motion M (2, 3) as a frame's manifest ``registration`` record in a ``width`` x
    ``height`` image: the centre's displacement (``dx_px``, ``dy_px``) and ``rotation_deg``."""
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    d = M[:, :2] @ c + M[:, 2] - c
    return {"dx_px": float(d[0]), "dy_px": float(d[1]),
            "rotation_deg": float(np.degrees(np.arctan2(M[1, 0], M[0, 0])))}


def motion_of_record(record, width, height):
    """The motion M (2, 3) of a :func:`motion_record` in a ``width`` x ``height`` image."""
    d = np.array([record["dx_px"], record["dy_px"]])
    t = np.radians(record["rotation_deg"])
    R = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    return np.c_[R, c + d - R @ c]


def pixel_map(M, camera):
    """(map_x, map_y) (H, W) float32: where each reference pinhole pixel lies in a photograph of
    motion ``M`` through the lens of ``camera`` (:func:`~skyfit_mi.physics.lens.distort`)."""
    h, w = camera["height"], camera["width"]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    u = M[0, 0] * xx + M[0, 1] * yy + M[0, 2]
    v = M[1, 0] * xx + M[1, 1] * yy + M[1, 2]
    k = camera.get("distortion") or []
    if any(k):
        f, cx, cy = focal_px(camera["fov_deg"], w), (w - 1) / 2.0, (h - 1) / 2.0
        x, y = distort((u - cx) / f, (v - cy) / f, k)
        u, v = f * x + cx, f * y + cy
    return u.astype(np.float32), v.astype(np.float32)


def remap(img, maps):
    """``img`` (H, W[, C]) sampled bilinearly at ``maps`` (:func:`pixel_map`); NaN off it."""
    planes = np.asarray(img, np.float32).reshape(img.shape[0], img.shape[1], -1)
    out = np.stack([cv2.remap(np.ascontiguousarray(planes[..., c]), *maps, cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=float("nan"))
                    for c in range(planes.shape[2])], axis=-1)
    return out.reshape(img.shape)


#: The motion of a frame that did not move (:func:`pixel_map`).
NO_MOTION = np.float64([[1, 0, 0], [0, 1, 0]])


def undistort_image(img, camera):
    """A photograph ``img`` (H, W[, C]) with the radial ``distortion`` of the validated
    ``camera`` undone: the image the spec's pinhole sees (float32, or float64 if ``img`` is;
    NaN where a ray lands off it; ``img`` itself without distortion)."""
    img = np.asarray(img)
    h, w = camera["height"], camera["width"]
    if img.shape[:2] != (h, w):
        raise SkyfitError(f"the image is {img.shape[1]}x{img.shape[0]} px, the camera "
                          f"{w}x{h}; undistort photographs of the camera's size.")
    dtype = np.float64 if img.dtype == np.float64 else np.float32
    if not any(camera.get("distortion") or []):
        return img.astype(dtype)
    return remap(img, pixel_map(NO_MOTION, camera)).astype(dtype)


def variance_share(maps):
    """Mean over pixels of the summed squared bilinear weights of ``maps``: the share of a source
    pixel's noise variance a resampled pixel keeps."""
    fx, fy = (m - np.floor(m) for m in maps)
    return float(np.mean(((1 - fx) ** 2 + fx ** 2) * ((1 - fy) ** 2 + fy ** 2)))


@dataclass
class Registration:
    """Each resampled frame's map (index -> :func:`pixel_map`), each lit frame's manifest
    record (index -> ``registration``) and the day's (``ingest.registration``)."""

    maps: dict
    frames: dict
    record: dict

    def warp(self, i, values, top=None):
        """Frame ``i``'s ``values`` (H, W, 3) on the reference's pinhole pixels; with ``top``,
        a pixel mixing a clipped code (0 or ``top``) with others is NaN."""
        if i not in self.maps:
            return values
        out = remap(values, self.maps[i])
        bounds = () if top is None else ((0.0, values <= 0), (top, values >= top))
        for bound, at in bounds:
            share = remap(at.astype(np.float32), self.maps[i])
            out = np.where(share > 1 - _SHARE_TOL, bound,
                           np.where(share > _SHARE_TOL, np.nan, out))
        return out.astype(np.float32)

    def sigma(self, i, sigma, warped):
        """Frame ``i``'s sigma (H, W, 3) [DN] on the reference's pixels (variance resampled with
        the values' weights), inf where the ``warped`` value is NaN."""
        if i not in self.maps:
            return sigma
        var = remap(np.where(np.isfinite(sigma), np.square(sigma), 0.0), self.maps[i])
        return np.where(np.isfinite(warped), np.sqrt(var), np.inf).astype(np.float32)


#: The least share of a frame's pixels known (neither clipped nor black), relative to the best
#: frame's, for it to be the registration's reference.
REFERENCE_KNOWN = 0.5


def register_frames(frames, linear, register=True, limit=LIMIT_PX, log=print):
    """The :class:`Registration` of ingest's ``frames``: with ``register``, each lit frame's
    motion against the one the pose was marked on (the spec's [camera] ``photo``), else the one
    nearest midday (of those mostly unclipped: :data:`REFERENCE_KNOWN`), plus the lens
    distortion; SkyfitError for a frame that moved over ``limit`` [px] or cannot
    be registered."""
    camera, lit, names = frames.spec.camera, frames.lit, [p.name for p in frames.paths]
    h, w = frames.size
    k = [float(x) for x in camera.get("distortion") or []]
    motion = {i: NO_MOTION for i in lit}
    records, ref = {}, None
    if register:
        feats = {i: features(undistort_image(luminance(linear.values[i], linear.sensor,
                                                       linear.falloff), camera)) for i in lit}
        # the reference: nearest midday among the frames with most of the scene unclipped
        known = {i: float(feats[i][1].mean()) for i in lit}
        usable = [i for i in lit if known[i] >= REFERENCE_KNOWN * max(known.values())]
        t = {i: frames.times[i].timestamp() for i in lit}
        mid = 0.5 * (min(t.values()) + max(t.values()))
        ref = min(usable, key=lambda i: abs(t[i] - mid))
        marked = camera.get("photo")             # the photograph the pose was marked on
        if marked is not None:
            on = [i for i in usable if names[i] == marked] or [     # or its RAW's, JPEG's
                i for i in usable if Path(names[i]).stem.lower() == Path(marked).stem.lower()]
            if on:
                ref = on[0]
            else:
                log(f"registration: the pose was marked on {marked}, which is not among the "
                    f"lit, mostly unclipped frames; registering on {names[ref]}, so the pose "
                    "holds as far as the camera did not move between the two")
        corners = np.array([[0, 0, 1], [w - 1, 0, 1], [0, h - 1, 1], [w - 1, h - 1, 1.0]])
        for i in lit:
            if i == ref:
                records[i] = {**motion_record(NO_MOTION, w, h), "sd_px": 0.0,
                              "reference": True}
                continue
            try:
                M, rho = measure_motion(feats[ref], feats[i])
            except cv2.error:
                M, rho = None, float("nan")
            if M is None or not rho >= MIN_CORRELATION:
                why = "ECC did not converge" if M is None else \
                    f"ECC correlation {rho:.2f}, at least {MIN_CORRELATION:g} needed"
                lost = [f"{names[j]} {1 - known[j]:.0%}" for j in (i, ref)
                        if known[j] < REFERENCE_KNOWN]
                raise SkyfitError(f"{names[i]}: cannot be registered on {names[ref]}, the "
                                  f"reference ({why}); check that both show the same view"
                                  + (f" and exposure (clipped or black: {', '.join(lost)} of "
                                     "the pixels)" if lost else "")
                                  + ", drop the odd one, or give --no-register.")
            moved = float(np.max(np.hypot(*(corners @ M.T - corners[:, :2]).T)))
            if moved > limit:
                raise SkyfitError(f"{names[i]}: it moved {moved:.1f} px from {names[ref]} "
                                  f"(at most {limit:g} px, --register-limit); check the tripod "
                                  "and drop the frame, or raise --register-limit.")
            sd_i = displacement_sd(motion_covariance(feats[ref], feats[i], M), w, h)
            records[i] = {**motion_record(M, w, h), "sd_px": sd_i, "correlation": rho,
                          "resampled": bool(moved > max(STILL_PX, 3.0 * sd_i))}
            if rho < WEAK_CORRELATION:
                log(f"registration: {names[i]} matches {names[ref]} weakly (ECC correlation "
                    f"{rho:.2f}; a still scene's reads over {WEAK_CORRELATION:g}): flare, "
                    "moving shadows or clouds in either may bias its measured turn; look at it")
            if records[i]["resampled"]:
                motion[i] = M
    maps = {i: pixel_map(motion[i], camera) for i in lit
            if any(k) or (register and i != ref and records[i]["resampled"])}
    for i, m in maps.items():
        off = (m[0] < 0) | (m[0] > w - 1) | (m[1] < 0) | (m[1] > h - 1)
        records.setdefault(i, {}).update(pixel_variance_share=variance_share(m),
                                         off_photo_pixels=int(off.sum()))
    sd = max((r.get("sd_px", 0.0) for r in records.values()), default=0.0)
    erode = int(np.ceil(1.0 + 3.0 * sd)) if maps else 0     # a still day: none moved, none
    record = {"registered": bool(register), "reference": names[ref] if register else None,
              "limit_px": float(limit), "distortion_undone": k if any(k) else None,
              "erode_px": erode, "interpolation": "bilinear, once (motion and distortion "
              "composed)", "method": "phase correlation (Kuglin and Hines 1975) then ECC, "
              "Euclidean (Evangelidis and Psarakis 2008), on the high-passed linear luminance of "
              "the undistorted frames; sd_px from the sandwich covariance over tiles of "
              f"{BLOCK_PX} px (robust to the residual's correlation)",
              "sigma": "variance resampled with the values' weights: a region's mean keeps the "
                       "photograph's error; a pixel's own scatter is pixel_variance_share of "
                       "sigma^2"}
    if register:
        moves = [r for i, r in records.items() if i != ref]
        log(f"registration on {names[ref]}: shifts up to "
            f"{max((np.hypot(r['dx_px'], r['dy_px']) for r in moves), default=0.0):.2f} px, "
            f"rotations up to {max((abs(r['rotation_deg']) for r in moves), default=0.0):.3f} "
            f"deg, sd up to {sd:.3f} px; regions eroded by {erode} px")
    if any(k):
        log(f"lens distortion k = {k} undone: the frames resampled onto the spec's pinhole")
    return Registration(maps, records, record)
