"""The camera from the photos: pose, focal length and radial distortion from marked points.

In one photograph the user marks four or more scene points of measured world position (+X east,
+Y north, +Z up) [m], e.g. a board's corners.  The camera is the pinhole with radial distortion
of :mod:`skyfit_mi.physics.lens` (square pixels, centred principal point) whose projection is
nearest the marks in least squares (maximum likelihood for Gaussian marking errors, Hartley and
Zisserman 2004, sec. 7.2):

* focal length given: OpenCV's ``solvePnP`` from SQPnP (Terzakis and Lourakis 2020) and, for
  coplanar points, IPPE's two poses (Collins and Bartoli 2014), refined by Levenberg-Marquardt;
* focal length free: the best of those over a scan of fields of view, refined with the focal
  length (and k1, k2: :data:`K1_REACH`) by ``calibrateCamera`` (Zhang 2000).  A plane fixes the
  focal length only through its foreshortening: not face-on, nor too small.

The uncertainty is linearised (Hartley and Zisserman 2004, sec. 5.2.3): cov = sigma^2 (J^T J)^-1,
sigma [px] the larger of the stated marking accuracy and the residuals', carried numerically to
the camera's azimuth, angle from the vertical, distance from a target and field of view.

References: R. Hartley and A. Zisserman, "Multiple View Geometry in Computer Vision", 2nd ed.,
2004; Z. Zhang, IEEE TPAMI 22(11), 1330-1334, 2000, doi:10.1109/34.888718; T. Collins and
A. Bartoli, IJCV 109, 252-286, 2014, doi:10.1007/s11263-014-0725-5; G. Terzakis and
M. Lourakis, ECCV 2020, doi:10.1007/978-3-030-58452-8_28; OpenCV 4 ``calib3d``.
"""

import csv
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy.stats import norm

from ..errors import OutputError, SkyfitError
from ..files import write_json, write_text
from ..physics.lens import FOV_RANGE, check_distortion, fov_deg, focal_px, intrinsics
from ..render.scene import POSE_SD_MAX

#: Points needed with the focal length given (six pose parameters) and free (plus f and k1).
MIN_POINTS = {"given": 4, "free": 6}
#: With the focal length free, k1 is fitted when the marks reach this fraction of the image's
#: half-diagonal, k2 when they reach :data:`K2_REACH` with :data:`K2_POINTS` points: nearer the
#: centre the distortion is below the marking error.  Otherwise the given one (default zero).
K1_REACH, K2_REACH, K2_POINTS = 0.5, 0.7, 10
#: Below this chi-square probability the residuals are "far beyond the marking accuracy".
P_MISFIT = 1e-3
#: A second pose within this chi-square of the best makes the answer ambiguous (3 sigma).
AMBIGUOUS_CHI2 = 9.0
#: A free focal length known no better than this relative standard deviation is not determined.
FOCAL_REL_SD = 0.2
#: Relative singular values below which points are collinear (scene or image) or coplanar.
FLAT = 1e-3
#: Two-sided 95% factor of a Gaussian.
Z95 = float(norm.ppf(0.975))
COLUMNS = ("x_px", "y_px", "X", "Y", "Z")


@dataclass(frozen=True)
class MarkedPoints:
    """Image marks of scene points: ``names`` (N,), ``image`` (N, 2) pixel column and row [px]
    (0, 0 the centre of the top-left pixel), ``world`` (N, 3) east, north, up [m]."""

    names: tuple
    image: np.ndarray
    world: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "names", tuple(self.names))
        for key, n in (("image", 2), ("world", 3)):          # OpenCV takes contiguous arrays
            object.__setattr__(self, key, np.ascontiguousarray(getattr(self, key),
                                                               dtype=float).reshape(-1, n))


def read_points(path, width, height):
    """Read a CSV of marked points (columns ``name`` (optional), ``x_px``, ``y_px``, ``X``,
    ``Y``, ``Z``) for a ``width`` x ``height`` [px] photograph as :class:`MarkedPoints`;
    SkyfitError naming the row of a missing column, bad number, repeated name or mark off it."""
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            reader = csv.DictReader(f)
            rows = list(reader)
            header = [h.strip() for h in reader.fieldnames or []]
    except OSError as exc:
        raise SkyfitError(f"cannot read points file {str(path)!r}: {exc.strerror or exc}.") \
            from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise SkyfitError(f"{path.name} is not a CSV text file ({exc}).") from None
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise SkyfitError(f"{path.name} lacks column(s) {', '.join(missing)}; give a header row "
                          "name,x_px,y_px,X,Y,Z (pixel column and row, world east, north, up "
                          "[m]; name optional).")
    names, values = [], []
    for i, row in enumerate(rows, start=2):
        if None in row or None in row.values():
            raise SkyfitError(f"{path.name} line {i} has {'more' if None in row else 'fewer'} "
                              f"cells than the header's {len(header)}; give one cell per column "
                              "(decimal points, not commas, in numbers).")
        row = {k.strip(): v.strip() for k, v in row.items()}
        name = row.get("name") or f"row {i}"
        try:
            v = [float(row[c]) for c in COLUMNS]
            if not np.all(np.isfinite(v)):
                raise ValueError
        except ValueError:
            bad = next(c for c in COLUMNS if not _finite(row[c]))
            raise SkyfitError(f"{path.name} line {i} ({name}): {bad} = {row[bad]!r} is not a "
                              "finite number; give pixel coordinates and metres as numbers.") \
                from None
        if name in names:
            raise SkyfitError(f"{path.name} line {i}: the point name {name!r} is given twice; "
                              "name each marked point once.")
        if not (-0.5 <= v[0] <= width - 0.5 and -0.5 <= v[1] <= height - 0.5):
            raise SkyfitError(f"{path.name} line {i} ({name}): the mark ({v[0]:g}, {v[1]:g}) px "
                              f"is off the {width}x{height} image (x in [0, {width - 1}], y in "
                              f"[0, {height - 1}]); check the image size or the mark.")
        names.append(name)
        values.append(v)
    values = np.array(values, dtype=float).reshape(-1, 5)
    return MarkedPoints(tuple(names), values[:, :2], values[:, 2:])


def _finite(text):
    try:
        return bool(np.isfinite(float(text)))
    except ValueError:
        return False


def _flatness(x):
    """Singular values of the centred rows of ``x``, relative to the largest."""
    s = np.linalg.svd(x - x.mean(axis=0), compute_uv=False)
    return s / s[0] if s[0] > 0 else s


def _check_configuration(points, need, mode):
    """Refuse too few points and collinear ones; return whether the scene points are coplanar."""
    n = len(points.names)
    if n < need:
        raise SkyfitError(f"{n} marked point(s); the camera needs at least {need} with the focal "
                          f"length {mode} ({'give --fov-deg or ' if mode == 'free' else ''}mark "
                          "more points).")
    for what, x in (("scene", points.world), ("image", points.image)):
        if _flatness(x)[1] < FLAT:
            raise SkyfitError(f"the marked points lie on one line in the {what}: they cannot fix "
                              "the camera; mark points spread over an area (e.g. all four corners "
                              "of the board)." if what == "scene" else
                              "the marked points lie on one line in the image (their plane seen "
                              "edge-on): they cannot fix the camera; mark points off that plane.")
    return bool(_flatness(points.world)[2] < FLAT)


@dataclass
class _Fit:
    """One solution (rvec, tvec [m], focal [px], [k1, k2]); ``ssr``: squared residuals [px^2]."""

    rvec: np.ndarray
    tvec: np.ndarray
    focal: float
    k: np.ndarray
    ssr: float


def _project(world, fit, width, height):
    """Projected points (N, 2) [px] and ``projectPoints``' Jacobian (2N, 14)."""
    uv, jac = cv2.projectPoints(world, fit.rvec, fit.tvec, intrinsics(fit.focal, width, height),
                                np.r_[fit.k, 0.0, 0.0])
    return uv.reshape(-1, 2), jac


def _depths(world, fit):
    """Depth [m] of each world point along the camera's view."""
    return world @ cv2.Rodrigues(fit.rvec)[0][2] + fit.tvec[2]


def _poses(points, focal, k, coplanar, width, height):
    """Pose solutions at a given focal length and distortion, refined, best first."""
    K, dist = intrinsics(focal, width, height), np.r_[k, 0.0, 0.0]
    rvecs, tvecs = [], []
    for flag in ((cv2.SOLVEPNP_IPPE,) if coplanar else ()) + (cv2.SOLVEPNP_SQPNP,):
        try:
            _, r, t, _ = cv2.solvePnPGeneric(points.world, points.image, K, dist, flags=flag)
        except cv2.error:
            continue
        rvecs, tvecs = rvecs + list(r), tvecs + list(t)
    out = []
    for r0, t0 in zip(rvecs, tvecs):
        _, r, t = cv2.solvePnP(points.world, points.image, K, dist, r0.copy(), t0.copy(),
                               useExtrinsicGuess=True, flags=cv2.SOLVEPNP_ITERATIVE)
        # the refined pose, or the first one if refining turned the camera away (bad marks)
        fit = next((f for f in (_Fit(rv.ravel(), tv.ravel(), float(focal), np.asarray(k, float),
                                     0.0) for rv, tv in ((r, t), (r0, t0)))
                    if np.median(_depths(points.world, f)) > 0), None)
        if fit is None:
            continue
        fit.ssr = float(np.sum((_project(points.world, fit, width, height)[0]
                                - points.image) ** 2))
        out.append(fit)
    return sorted(out, key=lambda f: f.ssr)


def _calibrate(points, start, free_k, width, height, fix_focal=False):
    """``start`` refined by ``calibrateCamera`` (the focal length unless ``fix_focal``, and the
    first ``free_k`` k, free)."""
    flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_PRINCIPAL_POINT
             | cv2.CALIB_FIX_ASPECT_RATIO | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K3
             | (cv2.CALIB_FIX_K1 if free_k < 1 else 0) | (cv2.CALIB_FIX_K2 if free_k < 2 else 0)
             | (cv2.CALIB_FIX_FOCAL_LENGTH if fix_focal else 0))
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    _, K, dist, rvecs, tvecs = cv2.calibrateCamera(
        [points.world.astype(np.float32)], [points.image.astype(np.float32)], (width, height),
        intrinsics(start.focal, width, height), np.r_[start.k, 0.0, 0.0, 0.0],
        flags=flags, criteria=crit)
    fit = _Fit(rvecs[0].ravel(), tvecs[0].ravel(), float(K[0, 0]), dist.ravel()[:2].copy(), 0.0)
    fit.ssr = float(np.sum((_project(points.world, fit, width, height)[0]
                            - points.image) ** 2))
    return fit


def _angle_between(r1, r2):
    """Angle between two rotations given as rotation vectors [degrees]."""
    d = cv2.Rodrigues(r1)[0] @ cv2.Rodrigues(r2)[0].T
    return float(np.degrees(np.arccos(np.clip((np.trace(d) - 1.0) / 2.0, -1.0, 1.0))))


def _solve(points, width, height, focal, k, free_k, coplanar):
    """The best fit, and the best pose over a degree from it (a plane's other view, or None)."""
    if focal is not None:
        fits = _poses(points, focal, k, coplanar, width, height)
    else:
        fits = [f for fov in np.geomspace(5.0, 140.0, 36)
                for f in _poses(points, focal_px(fov, width), k, coplanar, width, height)]
    if not fits:
        raise SkyfitError("OpenCV found no camera for these points; check that each mark and "
                          "its scene position belong to the same point.")
    best = min(fits, key=lambda f: f.ssr)
    if focal is None or free_k:
        try:
            best = min(best, _calibrate(points, best, free_k, width, height, focal is not None),
                       key=lambda f: f.ssr)
        except cv2.error as exc:
            raise SkyfitError(f"OpenCV's calibrateCamera failed on these points ({exc.err}); "
                              "give --fov-deg, or mark more points.") from None
        fits = _poses(points, best.focal, best.k, coplanar, width, height)
    other = next((f for f in fits if _angle_between(f.rvec, best.rvec) > 1.0), None)
    return best, other


@dataclass
class CameraEstimate:
    """A camera estimated from marked points (:func:`estimate_camera`): ``rvec``, ``tvec``
    OpenCV's world-to-camera rotation vector and translation [m]; ``focal`` [px]; ``k`` [k1,
    k2]; ``free`` the parameters in ``covariance``'s order (``r1 r2 r3`` [rad], ``t1 t2 t3``
    [m], ``focal`` [px], ``k1``, ``k2``); ``sigma_px`` the marking error assumed; ``target``
    [m] the point azimuth, angle and distance are measured from."""

    points: MarkedPoints
    width: int
    height: int
    rvec: np.ndarray
    tvec: np.ndarray
    focal: float
    k: np.ndarray
    free: tuple
    covariance: np.ndarray
    residuals: np.ndarray
    marking_px: float
    sigma_px: float
    dof: int
    coplanar: bool
    target: np.ndarray
    other_rms_px: float | None
    photo: str | None = None

    @property
    def rotation(self):
        """World-to-camera rotation (OpenCV's camera frame: x right, y down, z forward)."""
        return cv2.Rodrigues(self.rvec)[0]

    @property
    def origin(self):
        """The camera's centre in the world [m]."""
        return -self.rotation.T @ self.tvec

    def to_world(self):
        """Mitsuba's camera to_world 4x4 (columns: left, up, forward, origin)."""
        m = np.eye(4)
        m[:3, :3] = self.rotation.T @ np.diag([-1.0, -1.0, 1.0])
        m[:3, 3] = self.origin
        return m

    def camera_section(self):
        """The spec's [camera] table: origin, a target on the view axis at ``self.target``'s
        depth, up, fov_deg, width, height, distortion, the pose's 1-sd in azimuth, angle and
        roll [deg] (:meth:`placement`), which fits propagate into their intervals, and the
        photograph it was marked on (which ingest registers the frames on)."""
        m = self.to_world()
        depth = float(np.dot(self.target - self.origin, m[:3, 2]))
        p = self.placement()
        return {"origin": self.origin.tolist(),
                "target": (self.origin + depth * m[:3, 2]).tolist(),
                "up": m[:3, 1].tolist(), "fov_deg": fov_deg(self.focal, self.width),
                "width": self.width, "height": self.height,
                "distortion": [float(v) for v in self.k],
                "pose_sd_deg": {"azimuth": p["azimuth_deg"][1], "angle": p["angle_deg"][1],
                                "roll": p["roll_deg"][1]},
                **({"photo": self.photo} if self.photo else {})}

    def _placement(self, p):
        """Azimuth, angle from the vertical [deg], distance [m], fov and roll [deg] (the image's
        up turned about the view axis from the world's vertical, counter-clockwise as seen by
        the camera) at free parameters ``p``."""
        q = dict(zip(self.free, p))
        rvec = np.array([q["r1"], q["r2"], q["r3"]])
        R = cv2.Rodrigues(rvec)[0]
        origin = -R.T @ np.array([q["t1"], q["t2"], q["t3"]])
        v = origin - self.target
        dist = np.linalg.norm(v)
        forward, up = R[2], -R[1]                 # the camera's z and -y in the world
        level = np.array([0.0, 0.0, 1.0]) - forward[2] * forward
        roll = np.degrees(np.arctan2(np.dot(np.cross(level, up), forward), np.dot(level, up)))
        return np.array([np.degrees(np.arctan2(v[0], v[1])) % 360.0,
                         np.degrees(np.arccos(np.clip(v[2] / dist, -1.0, 1.0))), dist,
                         fov_deg(q.get("focal", self.focal), self.width), roll])

    def parameters(self):
        """The free parameters' values, in the order of ``free``."""
        allv = dict(zip(("r1", "r2", "r3", "t1", "t2", "t3", "focal", "k1", "k2"),
                        [*self.rvec, *self.tvec, self.focal, *self.k]))
        return np.array([allv[n] for n in self.free])

    def placement(self):
        """{name: (value, linearised sd)} of ``azimuth_deg``, ``angle_deg`` (from the vertical),
        ``distance_m`` (from ``target``), ``fov_deg``, ``roll_deg``, and ``k1``/``k2`` when
        free."""
        p = self.parameters()
        g0 = self._placement(p)
        G = np.empty((5, len(p)))
        for j in range(len(p)):
            h = 1e-6 * max(1.0, abs(p[j]))
            dp = np.zeros_like(p)
            dp[j] = h
            d = self._placement(p + dp) - self._placement(p - dp)
            d[[0, 4]] = (d[[0, 4]] + 180.0) % 360.0 - 180.0    # azimuth across north, roll
            G[:, j] = d / (2 * h)
        sd = np.sqrt(np.maximum(np.diag(G @ self.covariance @ G.T), 0.0))
        out = dict(zip(("azimuth_deg", "angle_deg", "distance_m", "fov_deg", "roll_deg"),
                       zip(g0, sd)))
        for i, name in enumerate(self.free):
            if name in ("k1", "k2"):
                out[name] = (float(p[i]), float(np.sqrt(self.covariance[i, i])))
        return {k: (float(v), float(s)) for k, (v, s) in out.items()}

    def report(self):
        """The JSON report: the camera, its placement with 1-sigma and 95% bounds, the fit's
        statistics and each point's residual [px]."""
        err = np.hypot(*self.residuals.T)
        return {
            "units": "angles [deg], lengths [m], image coordinates and residuals [px] (0, 0 the "
                     "centre of the top-left pixel)",
            "method": ("solvePnP (IPPE and SQPnP starts, refined iteratively)" if self.coplanar
                       else "solvePnP (SQPnP start, refined iteratively)")
            if "focal" not in self.free
            else "calibrateCamera on one view (focal length and radial distortion free)",
            "free_parameters": list(self.free), "points": len(err), "coplanar": self.coplanar,
            "camera": self.camera_section(), "to_world": self.to_world().tolist(),
            "target": self.target.tolist(),
            "placement": {k: {"value": v, "sd": s, "ci95": [v - Z95 * s, v + Z95 * s]}
                          for k, (v, s) in self.placement().items()},
            "covariance": {"parameters": list(self.free), "matrix": self.covariance.tolist()},
            "marking_px": self.marking_px, "sigma_px": self.sigma_px,
            "reprojection_rms_px": float(np.sqrt(np.mean(err ** 2))),
            "reprojection_max_px": float(err.max()), "dof": self.dof,
            "chi2": float(np.sum(self.residuals ** 2) / self.marking_px ** 2),
            "other_pose_rms_px": self.other_rms_px,
            "residuals": [{"name": n, "x_px": float(x), "y_px": float(y), "dx_px": float(dx),
                           "dy_px": float(dy), "error_px": float(e)}
                          for n, (x, y), (dx, dy), e in zip(self.points.names, self.points.image,
                                                             self.residuals, err)],
            "opencv": cv2.__version__,
        }


def estimate_camera(points, width, height, fov=None, distortion=None, marking_px=0.5,
                    target=None):
    """The :class:`CameraEstimate` that saw ``points`` in a ``width`` x ``height`` [px] photo.

    ``fov``: horizontal field of view [degrees] if known, else fitted; ``distortion``: known
    [k1] or [k1, k2], else zero with ``fov``, fitted without; ``marking_px``: a mark's sd per
    coordinate [px]; ``target``: point [m] azimuth, angle and distance are measured from
    (default the centroid).  SkyfitError for too few or collinear points, a point behind the
    camera, residuals far beyond ``marking_px`` (naming the likeliest mislabelled point), two
    poses that fit alike, or an undetermined free focal length.
    """
    if not (np.isfinite(marking_px) and marking_px > 0):
        raise SkyfitError(f"the marking accuracy {marking_px!r} px must be a positive number.")
    if fov is not None and not (np.isfinite(fov) and FOV_RANGE[0] <= fov <= FOV_RANGE[1]):
        raise SkyfitError(f"--fov-deg {fov!r}: give the lens's horizontal field of view, "
                          f"{FOV_RANGE[0]:g}-{FOV_RANGE[1]:g} degrees (as the spec takes it).")
    if target is not None and not np.all(np.isfinite(np.asarray(target, float))):
        raise SkyfitError(f"--target {list(target)!r}: give three finite coordinates [m].")
    mode = "given" if fov is not None else "free"
    coplanar = _check_configuration(points, MIN_POINTS[mode], mode)
    k = np.r_[np.asarray(distortion if distortion is not None else [], float), 0.0, 0.0][:2]
    reach = np.max(np.hypot(*(points.image - [(width - 1) / 2, (height - 1) / 2]).T)) \
        / np.hypot(width, height) * 2
    reach_k = 0 if reach < K1_REACH else \
        (2 if len(points.names) >= K2_POINTS and reach >= K2_REACH else 1)
    focal = None if fov is None else focal_px(fov, width)
    free_k = reach_k if distortion is None and focal is None else 0
    best, other = _solve(points, width, height, focal, k, free_k, coplanar)
    if reach_k and (focal is not None or distortion is not None):
        # the marks' say on the distortion: fitted where they ask for it (a lens left without
        # --distortion), a given one refused where they reject it
        n_k = 1 if distortion is not None else reach_k
        free, free_other = _solve(points, width, height, focal, k, n_k, coplanar)
        dof = 2 * len(points.names) - 6 - n_k - (focal is None)
        sigma2 = max(marking_px ** 2, free.ssr / dof if dof > 0 else 0.0)
        rejected = (best.ssr - free.ssr) / sigma2 > AMBIGUOUS_CHI2
        if distortion is not None and rejected:
            raise SkyfitError(
                f"--distortion k1 = {best.k[0]:g} disagrees with the marks, which put k1 at "
                f"{free.k[0]:.3g} (reprojection rms {np.sqrt(best.ssr / len(points.names)):.2f}"
                f" px against {np.sqrt(free.ssr / len(points.names)):.2f}): check its value and "
                "sign (barrel distortion is negative), or leave --distortion out to fit it.")
        if distortion is None and rejected:
            best, other, free_k = free, free_other, n_k

    behind = [n for n, z in zip(points.names, _depths(points.world, best)) if z <= 0]
    if behind:
        raise SkyfitError(f"the best camera has {', '.join(behind)} behind it; check those "
                          "points' scene coordinates (signs, east/north order) and marks.")
    if coplanar:
        _check_side(points, best)

    uv, jac = _project(points.world, best, width, height)
    residuals = points.image - uv
    cols = [jac[:, :6]] + ([jac[:, 6:7] + jac[:, 7:8]] if focal is None else []) \
        + [jac[:, 10 + i:11 + i] for i in range(free_k)]
    J = np.hstack(cols)
    free = ("r1", "r2", "r3", "t1", "t2", "t3") + (("focal",) if focal is None else ()) \
        + ("k1", "k2")[:free_k]
    dof = 2 * len(points.names) - len(free)
    _check_misfit(points, best, dof, marking_px, width, height, focal, k, free_k, coplanar)
    if other is not None and (other.ssr - best.ssr) / marking_px ** 2 < AMBIGUOUS_CHI2:
        raise SkyfitError("two camera poses fit the marks alike (the two views one plane allows, "
                          f"rms {np.sqrt(best.ssr / len(uv)):.2f} and "
                          f"{np.sqrt(other.ssr / len(uv)):.2f} px); mark points off the board's "
                          "plane, or more points over a larger area.")
    sigma = max(marking_px, np.sqrt(best.ssr / dof)) if dof > 0 else marking_px
    JtJ = J.T @ J
    scale = np.sqrt(np.diag(JtJ))
    if np.any(scale == 0) or np.linalg.cond(JtJ / np.outer(scale, scale)) > 1e12:
        raise SkyfitError("these points do not determine the camera (a degenerate arrangement); "
                          "mark points spread over a larger area.")
    cov = sigma ** 2 * np.linalg.inv(JtJ)
    if focal is None and np.sqrt(cov[6, 6]) > FOCAL_REL_SD * best.focal:
        raise SkyfitError(f"the points do not determine the focal length (fov "
                          f"{fov_deg(best.focal, width):.1f} deg, +-"
                          f"{100 * np.sqrt(cov[6, 6]) / best.focal:.0f}%): one view of a plane "
                          "shows it only through perspective; give --fov-deg (from the lens and "
                          "sensor), or mark points off the plane or over more of the image.")
    est = CameraEstimate(points, int(width), int(height), best.rvec, best.tvec, best.focal,
                         best.k, free, cov, residuals, float(marking_px), float(sigma), dof,
                         coplanar, np.asarray(points.world.mean(axis=0) if target is None
                                              else target, float),
                         None if other is None else float(np.sqrt(other.ssr / len(uv))))
    section = est.camera_section()
    try:
        check_distortion(section["distortion"], section["fov_deg"], int(width), int(height))
    except SkyfitError as exc:
        if "k1" not in free:
            raise
        raise SkyfitError(f"the fitted {exc} The lens is beyond the two-term radial model the "
                          "marks fit (a wide-angle lens's corners, or a fisheye, which skyfit "
                          "does not take): give --fov-deg and --distortion from the lens's "
                          "profile, or mark points nearer the image's centre.") from None
    sd = section["pose_sd_deg"]
    if max(sd.values()) > POSE_SD_MAX:
        raise SkyfitError(f"the points fix the camera's direction only to +-{max(sd.values()):.1f} "
                          f"deg (1 sd; a fit takes at most {POSE_SD_MAX:g}): mark more points, "
                          "points off the board's plane, or mark them more precisely.")
    return est


#: A plane of marks whose normal lies within this angle of the vertical [degrees] is seen from
#: above: a camera below it sees the plane's mirror image.
FACING_DEG = 60.0


def _check_side(points, best):
    """Refuse a camera below the ground (z < 0) and below a plane of marks that faces up (a
    board on the ground): the mirror image of the marks (image rows counted up, x and y or east
    and north swapped) fits a camera on the plane's other side as well as the true one fits
    from above.  A camera above the ground under a ceiling's marks is a view from below."""
    centre = points.world.mean(axis=0)
    normal = np.linalg.svd(points.world - centre)[2][-1]
    normal = normal if normal[2] >= 0 else -normal
    origin = -cv2.Rodrigues(best.rvec)[0].T @ best.tvec
    if normal[2] > np.cos(np.radians(FACING_DEG)) and np.dot(origin - centre, normal) < 0 \
            and origin[2] < 0:
        raise SkyfitError(
            f"the camera comes out below the ground and the marked points' plane (at height "
            f"{origin[2]:.2f} m, the points at {centre[2]:.2f} m), seeing it from behind: the "
            "marks are a mirror "
            "image of the scene's. Check that y_px counts rows down from the image's top, that "
            "x_px is the column, and that X, Y, Z are east, north, up.")


def _check_misfit(points, best, dof, marking_px, width, height, focal, k, free_k, coplanar):
    """Refuse residuals far beyond the marking accuracy, naming the likeliest culprit point."""
    from scipy.stats import chi2

    if dof <= 0 or chi2.sf(best.ssr / marking_px ** 2, dof) >= P_MISFIT:
        return
    n = len(points.names)
    err = np.hypot(*(_project(points.world, best, width, height)[0] - points.image).T)
    worst = int(np.argmax(err))
    if n - 1 >= MIN_POINTS["given" if focal is not None else "free"]:
        gains = []
        for i in range(n):
            keep = np.arange(n) != i
            sub = MarkedPoints(tuple(np.array(points.names)[keep]), points.image[keep],
                               points.world[keep])
            try:
                gains.append(best.ssr - _solve(sub, width, height, focal, k, free_k,
                                               coplanar)[0].ssr)
            except SkyfitError:
                gains.append(-np.inf)
        worst = int(np.argmax(gains))
    rms = np.sqrt(np.mean(err ** 2))
    lens = ("the --fov-deg given (the horizontal field of view, the long side's only for a "
            "landscape photo) or the lens's distortion may be wrong, " if focal is not None
            else "the lens may be beyond the two-term radial model (a fisheye), ")
    raise SkyfitError(f"the marks miss the best camera by {rms:.2f} px rms, far beyond the "
                      f"marking accuracy {marking_px:g} px; point {points.names[worst]!r} is the "
                      f"likeliest mislabelled ({err[worst]:.1f} px off): check its mark and scene "
                      f"coordinates; else {lens}or give --marking-px as you marked.")


def point_text(p):
    """A point [m] as '[x, y, z]', without round-off noise (9e-18 shown as 0)."""
    return f"[{', '.join(f'{v + 0.0:.4g}' for v in np.round(p, 6))}]"


def camera_toml(estimate, source=""):
    """The [camera] table of ``estimate`` as TOML text, with its placement in a comment."""
    p = estimate.placement()
    sec = estimate.camera_section()

    def val(v):
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {x!r}" for k, x in v.items()) + " }"
        return "[" + ", ".join(repr(float(x)) for x in v) + "]" if isinstance(v, list) \
            else repr(v)

    t = estimate.target
    lines = [f"# skyfit camera{': from ' + source if source else ''}, "
             f"{len(estimate.points.names)} marked points, reprojection rms "
             f"{np.sqrt(np.mean(np.sum(estimate.residuals ** 2, axis=1))):.2f} px",
             f"# seen from azimuth {p['azimuth_deg'][0]:.3f} +- {p['azimuth_deg'][1]:.3f} deg, "
             f"{p['angle_deg'][0]:.3f} +- {p['angle_deg'][1]:.3f} deg from the vertical, "
             f"{p['distance_m'][0]:.4f} +- {p['distance_m'][1]:.4f} m from "
             f"{point_text(t)}; "
             f"fov {p['fov_deg'][0]:.3f} +- "
             f"{p['fov_deg'][1]:.3f} deg (1 sigma)",
             "# distortion: [k1, k2] of OpenCV's radial model; the renderer is a pinhole, "
             "ingest undoes it; pose_sd_deg: the 1-sigma above, which fits carry into their "
             "intervals", "[camera]"]
    lines += [f"{k} = {val(v)}" for k, v in sec.items()]
    return "\n".join(lines) + "\n"


def write_camera(estimate, path, overwrite=False, source=""):
    """Write ``path`` (the [camera] TOML) and its ``.json`` report atomically (replacing them
    only with ``overwrite``); returns the two paths."""
    path = Path(path)
    if path.suffix.lower() != ".toml":
        raise OutputError(f"-o {path}: the camera is a TOML table; give a path ending in .toml.")
    report = path.with_suffix(".json")
    for p in (path, report):
        if p.exists() and not overwrite:
            raise OutputError(f"{str(p)!r} exists; give another -o, or --overwrite to replace it.")
    write_json(report, {**estimate.report(), "points_file": source})
    write_text(path, camera_toml(estimate, source))
    return path, report
