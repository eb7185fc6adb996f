"""Photographs in: a day of real frames becomes the sequence folder ``render`` writes.

``skyfit ingest SPEC PHOTOS... -o DIR`` reads and times the photographs (:mod:`.photos`,
:mod:`.photo_times`), takes each time's sun and sky from the spec and writes a manifest with
``source = "ingest"`` that the other commands read unchanged.  The sensor model is the synthetic
sequences' (thesis ch. 5): values stay in camera codes [DN] (float frames on a linear 16-bit
scale; codes at 0 or the top censored), linearised by a given or fitted response
(:func:`fit_response`), with vignetting none, cos^4 (eq. 5.6) or a flat field, exposure from
EXIF, ``--exposure`` or grey references (:func:`calibrate_exposure`), and noise
sigma^2 = Q'(s)^2 (a + b s M) + 1/12 [DN^2] plus a JPEG's error (:func:`pixel_sigma`).  Nothing
is written until every input is checked.
"""

import hashlib
import json
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..conventions import time_legendre
from ..errors import SkyfitError, listed
from ..files import FolderLock
from ..physics.camera import SensorModel, clipped
from ..physics import tone_curve
from ..physics.colour import SRGB_LUMINANCE
from ..render.image import write_exr
from ..render.labels import label_image
from ..render.scene_xml import build_scene_xml
from .colorchecker import NAMES, NEUTRAL, find_chart, matrix_error, reference_rgb, swatch_check
from .jpeg_noise import (REPLICATES, SEED, block_offset, block_size, bootstrap_variance,
                         dc_record, displayed, jpeg_settings, recompress, stored, tables_bound)
from .manifest import FILENAME
from .photo_times import check_times, frame_times
from .photos import (EXIF_LABEL_SD, EXPOSURE_KEYS, NOT_SRGB, RAW_COLOUR_REACH,
                     WIDE_PRIMARIES, camera_name, check_same_size, exif_exposure,
                     exif_label_loading, exif_setting, list_photos, read_flat_field, read_photo)
from .raw_noise import REPLICATES as RAW_REPLICATES, SEED as RAW_SEED, SMOOTH as RAW_SMOOTH
from .raw_noise import bootstrap, cfa_planes
from .region_edges import colour_mixed, pose_reach
from .registration import LIMIT_PX, register_frames
from .sequence import (FrameRenderer, finish, frame_record, manifest_header, prepare_folder,
                       write_frame)
from .spec import SpecError, read_spec, validate_spec

#: Float frames are scaled so that the day's brightest value is this share of 16-bit full scale.
FLOAT_HEADROOM = 0.9
#: Level bins and the least pixels per bin of the noise estimate.
NOISE_BINS, NOISE_MIN_PIXELS = 16, 200
#: Robust sds beyond which a neighbour difference is an outlier; spread of the four diagonal
#: neighbours [noise sd] marking a scene edge (noise alone exceeds it ~1.4% of the time); passes.
NOISE_CLIP, NOISE_FLAT, NOISE_PASSES = 3.5, 4.5, 3
#: JPEG noise (:mod:`.jpeg_noise`): iterations and relative tolerance of the sensor-noise search.
JPEG_NOISE_ITERATIONS, JPEG_NOISE_TOL = 12, 0.01
#: Below this share of the estimated noise shown by neighbouring pixels a JPEG hides the noise.
JPEG_NOISE_PASSED_MIN = 0.15
#: Spread about a plane [sigma] marking a JPEG block with an edge (noise alone: ~1e-5 of blocks).
JPEG_EDGE_RANGE = 8.0
#: Frames and crop [pixels] re-compressed to find the sensor noise of JPEGs.
JPEG_CALIBRATION_FRAMES, JPEG_CALIBRATION_SIZE = 3, 512
#: ``--response fit`` (:func:`fit_response`): families, accepted gamma, least span of the
#: patches' signals at one exposure, and rms relative code error above which it warns.
RESPONSE_FAMILIES = ("linear", "srgb", "gamma")
GAMMA_RANGE = (1.0, 4.0)
#: Prior relative error of each entry of a RAW's colour matrix when none is given: fitted to one
#: chart, light and sensor, a maker's matrix mixes a few per cent of each channel elsewhere.
RAW_MATRIX_ERROR = 0.03
RESPONSE_SPAN_MIN = 2.0
RESPONSE_RMS_WARN = 0.05
#: The least span of the grey references' signals in a frame [ratio] over which they measure a
#: camera's own tone curve (:func:`tone_curve_record`).
TONE_LEVELS_MIN = 2.0


# ---- the sensor ------------------------------------------------------------------------

def _sensor(photos, response, gamma, spec_sensor, cos4, fitted=False):
    """The day's SensorModel (exposure 1 for now), the float scale (None for codes) and the
    lines saying what was assumed of the encoding; ``fitted``: the response is fitted later."""
    kinds = {p.kind for p in photos}
    if len(kinds) > 1:
        raise SkyfitError("the frames mix floating-point (EXR/HDR) and integer images; give one "
                          "kind for the whole day.")
    bits = {p.bits for p in photos}
    if len(bits) > 1:
        raise SkyfitError(f"the frames mix bit depths {sorted(bits, key=str)}; give one depth for "
                          "the whole day.")
    first = photos[0]
    scale = None
    if first.kind == "float":
        peak = max(float(p.values[np.isfinite(p.values)].max(initial=0.0)) for p in photos)
        if not peak > 0:
            raise SkyfitError("every floating-point frame is black or NaN; nothing to ingest.")
        scale = FLOAT_HEADROOM * 65535.0 / peak
        depth = 16
    else:
        depth = int(first.bits)
    if response is None and (first.kind == "float" or all(p.format == "raw" for p in photos)):
        response = "linear"           # EXR/HDR and RAWs as read are linear, whatever the spec
    if response is None:
        response = spec_sensor.get("response")
    said = []
    wide = next((p for p in photos if p.encoding_source.startswith(WIDE_PRIMARIES)), None)
    if wide is not None:
        profile = wide.encoding_source[len(WIDE_PRIMARIES):].strip()
        said.append(f"encoding: {Path(wide.path).name}'s ICC profile {profile} has sRGB's curve "
                    "but wider primaries: colours are read in its red, green and blue, not "
                    "sRGB's (a grey reference calibrates alike; C of a saturated colour differs "
                    "from sRGB's by up to a few tens of per cent)")
    other = next((p for p in photos if p.encoding_source.startswith(NOT_SRGB)), None)
    if response is None and other is not None and not fitted:
        raise SkyfitError(f"{Path(other.path).name}: {other.encoding_source} is neither sRGB "
                          "nor linear, which skyfit reads; convert the photographs to sRGB, "
                          "primaries as well as curve (the camera maker's software, or "
                          "ImageMagick: magick IN -profile sRGB.icc OUT), or, for codes of "
                          "sRGB's primaries under another curve, give --response (srgb, "
                          "linear, or gamma with --gamma).")
    if other is not None:
        said.append(f"encoding: {Path(other.path).name}: {other.encoding_source}; --response "
                    "sets the curve, not the primaries: if they are not sRGB's (Adobe RGB's, "
                    "ProPhoto's), colours are read in its red, green and blue (a grey reference "
                    "calibrates alike; C of a saturated colour differs by up to a few tens of "
                    "per cent): convert the photographs to sRGB for sRGB's")
    if response is None:
        hints = {p.encoding_hint for p in photos}
        response = hints.pop() if len(hints) == 1 else "srgb"
        if depth == 16 and first.kind != "float" and not fitted and all(
                p.encoding_source == "assumed" for p in photos):
            raise SkyfitError(
                f"{Path(first.path).name}: 16-bit codes without a colour profile may be linear "
                "(dcraw -4, a raw converter's linear export) or not (dcraw -6 writes a gamma "
                "curve, read as linear C comes out about half); say which with --response "
                "linear (or srgb, or gamma with --gamma), or the spec's [sensor] response.")
    g = gamma if gamma is not None else spec_sensor.get("gamma", 2.2)
    return SensorModel(exposure=1.0, response=response, gamma=g, bits=depth, cos4=cos4), scale, \
        said


def _relative_exposures(photos, log):
    """t ISO / N^2 of each frame over the first's, or None when some frame lacks EXIF."""
    vals = [exif_exposure(p) for p in photos]
    if None in vals:
        if any(v is not None for v in vals):
            log(f"{Path(photos[vals.index(None)].path).name}: no EXIF exposure (time, f-number, "
                "ISO); every frame's exposure is taken from the calibration instead of EXIF")
        return None
    return np.asarray(vals) / vals[0]


# ---- noise --------------------------------------------------------------------------------

def estimate_noise(values, sensor, jpeg=None, shown=None, log=None):
    """Read and shot noise (a [DN^2], b [DN]) of the linear codes of frames (H, W, 3) [DN];
    ``jpeg`` each frame's :func:`.jpeg_noise.jpeg_settings` (or None).

    A pixel's difference r from the mean of its four neighbours has 5/4 of its variance where
    the scene is smooth.  Level and smoothness come from the four diagonal neighbours, whose
    noise is independent of r's; pixels whose diagonals spread beyond NOISE_FLAT sigma (of the
    previous pass; the first uses a MAD) are edges, left out.  Per level bin the clipped
    variance (:func:`_clipped_variance`) is fitted by Q'(s)^2 (a + b s M) + 1/12, a, b >= 0.

    A JPEG hides part of the noise, so for JPEGs the sensor's (a, b) is iterated until
    re-compressed copies of centred crops (:func:`.jpeg_noise.recompress`) show what the frames
    show; below JPEG_NOISE_PASSED_MIN shown, ``log`` asks for --noise.
    """
    shown = shown_noise(values, sensor) if shown is None else shown
    jpeg = list(jpeg or [None] * len(values))

    # in each file's own layout (blocks from the top left); the estimate ignores the turn
    pairs = [(stored(v, st), st) for v, st in zip(values, jpeg) if st is not None]
    if not pairs:
        return shown

    picks = np.unique(np.linspace(0, len(pairs) - 1, JPEG_CALIBRATION_FRAMES).round()
                      .astype(int))
    crops = []
    for i in picks:
        v, st = pairs[i]
        n = block_size(st)
        y0, x0 = (max((d - JPEG_CALIBRATION_SIZE) // 2 // n * n, 0) for d in v.shape[:2])
        crops.append((v[y0:y0 + JPEG_CALIBRATION_SIZE, x0:x0 + JPEG_CALIBRATION_SIZE], st))
    views = [v for v, _ in crops]
    a, b = shown
    for it in range(JPEG_NOISE_ITERATIONS):
        rng = np.random.default_rng([SEED, it])
        errors = [recompress(v, st, sensor, (a, b), rng)[0] - np.nan_to_num(v) for v, st in crops]
        # edges judged by the frames' noise (the errors' is shrunk by compression)
        sa, sb = _fit_noise(_noise_parts(views, sensor, errors), sensor, shown)
        na, nb = max(a + shown[0] - sa, 0.0), max(b + shown[1] - sb, 0.0)
        done = abs(na - a) <= JPEG_NOISE_TOL * max(a, 1e-2) and \
            abs(nb - b) <= JPEG_NOISE_TOL * max(b, 1e-3)
        a, b = na, nb
        if done:
            break
    rows = _noise_bins(_noise_parts(views, sensor), sensor, shown)[0]
    with np.errstate(all="ignore"):
        passed = float(np.nan_to_num(np.median((rows @ shown) / (rows @ [a, b]))))
    if log is not None and passed < JPEG_NOISE_PASSED_MIN:
        log(f"the JPEGs show only {passed:.0%} of the noise between neighbouring pixels (their "
            "compression removes the rest), too little to tell the sensor's noise: the estimate "
            f"(read {a:.3g} DN^2, shot {b:.3g} DN) may be low, and sigma with it; give --noise "
            "READ,SHOT from the camera (e.g. measured on its RAW or TIFF frames)")
    return a, b


def shown_noise(values, sensor):
    """(a [DN^2], b [DN]) the frames' neighbouring pixels show: no JPEG correction; fitted in
    NOISE_PASSES passes, each dropping the edges the previous found."""
    parts, noise = _noise_parts(values, sensor), None
    for _ in range(NOISE_PASSES):
        noise = _fit_noise(parts, sensor, noise)
    return noise


def _noise_parts(values, sensor, errors=None):
    """Per frame (r, level, spread) of :func:`estimate_noise`'s pixels (r of ``errors`` if any)."""
    parts = []
    for i, v in enumerate(values):
        e = v if errors is None else errors[i]
        r = (e[1:-1, 1:-1] - 0.25 * (e[:-2, 1:-1] + e[2:, 1:-1] + e[1:-1, :-2]
                                     + e[1:-1, 2:])).ravel()
        diag = np.stack([v[:-2, :-2], v[:-2, 2:], v[2:, :-2], v[2:, 2:]])
        lvl = diag.mean(axis=0).ravel()
        spread = (diag.max(axis=0) - diag.min(axis=0)).ravel()
        ok = np.isfinite(r) & np.isfinite(spread) & (lvl > 0) & (lvl < sensor.max_code)
        if ok.sum() >= NOISE_MIN_PIXELS:
            parts.append((r[ok], lvl[ok], spread[ok]))
    return parts


def _noise_bins(parts, sensor, noise):
    """Per level bin: the noise model's row [Q'^2, Q'^2 s M], var(r) / 1.25 [DN^2] and weight
    sqrt(pixels); edges left out by ``noise`` (None: every pixel, variance from a MAD)."""
    rows, var, weights = [], [], []
    for r, lvl, spread in parts:
        if noise is not None:
            keep = spread <= NOISE_FLAT * pixel_sigma(lvl, sensor, noise)[0]
            r, lvl = r[keep], lvl[keep]
            if len(r) < NOISE_MIN_PIXELS:
                continue
        edges = np.quantile(lvl, np.linspace(0, 1, NOISE_BINS + 1))
        for lo, hi in zip(edges[:-1], edges[1:]):
            sel = (lvl >= lo) & (lvl <= hi)
            if sel.sum() < NOISE_MIN_PIXELS:
                continue
            rr = r[sel]
            var.append((_clipped_variance(rr) if noise is not None
                        else (1.4826 * np.median(np.abs(rr - np.median(rr)))) ** 2) / 1.25)
            s = float(sensor.linearise(np.median(lvl[sel])))
            q = float(sensor.slope(np.clip(s, 1e-6, 1 - 1e-6))) ** 2
            rows.append([q, q * s * sensor.max_code])
            weights.append(np.sqrt(sel.sum()))
    if len(rows) < 2:
        raise SkyfitError("too few usable pixels to estimate the noise (it needs "
                          f"{NOISE_MIN_PIXELS} unsaturated, lit pixels away from edges in each "
                          "of two signal levels at least; small frames and busy scenes have "
                          "fewer); give --noise READ,SHOT [DN^2, DN] explicitly.")
    return np.asarray(rows), np.asarray(var), np.asarray(weights)


def _fit_noise(parts, sensor, noise):
    """One pass of :func:`estimate_noise`, edges left out by the previous ``noise`` (or None):
    (a, b) >= 0 fitting the bins' variance less 1/12 by weighted least squares."""
    from scipy.optimize import nnls

    rows, var, weights = _noise_bins(parts, sensor, noise)
    w = weights / np.mean(weights)
    (a, b), _ = nnls(rows * w[:, None], np.maximum(var - 1.0 / 12.0, 0.0) * w)
    return float(a), float(b)


def _clipped_variance(r):
    """Variance of ``r`` without outliers (edges): mean square about the median within
    NOISE_CLIP robust sds, iterated, corrected for the normal tail beyond the clip.  Unlike a
    squared MAD it is not biased by whole-number codes."""
    from scipy.stats import norm

    r = r - np.median(r)
    q75, q25 = np.percentile(r, [75, 25])
    var = max(((q75 - q25) / 1.349) ** 2, 1e-12)
    k = NOISE_CLIP
    # E[x^2 | |x| < k] / sigma^2 for a normal x
    share = 1.0 - 2.0 * k * norm.pdf(k) / (2.0 * norm.cdf(k) - 1.0)
    for _ in range(5):
        inside = r[np.abs(r) < k * np.sqrt(var)]
        var = max(float(np.mean(inside ** 2)) / share, 1e-12)
    return var


def pixel_sigma(values, sensor, noise, jpeg=None):
    """(sigma [DN] of each value (H, W, 3) (or level (n,)), inf where NaN; a JPEG's edge-block
    mask, else None): sqrt(Q'(s)^2 (a + b s M) + 1/12).  For a JPEG (``jpeg`` = {"variance",
    "shown", "settings"}), the bootstrap variance floored by that formula of the shown noise,
    plus :func:`.jpeg_noise.tables_bound` in blocks holding an edge (:func:`edge_blocks`), whose
    ringing the bootstrap cannot draw."""
    a, b = noise if jpeg is None else jpeg["shown"]
    s = sensor.linearise(np.nan_to_num(values))
    q = sensor.slope(np.clip(s, 1e-6, 1 - 1e-6))
    var = q * q * (a + b * s * sensor.max_code) + 1.0 / 12.0
    edge = None
    if jpeg is not None:
        var = np.maximum(jpeg["variance"].astype(np.float32), var)
        st = jpeg["settings"]
        edge = displayed(edge_blocks(stored(np.nan_to_num(values), st), stored(var, st)), st)
        var = np.where(edge, var + tables_bound(st), var)
    return np.where(np.isfinite(values), np.sqrt(var), np.inf).astype(np.float32), edge


def edge_blocks(values, variance, block=8):
    """(H, W, 1) bool: the pixel's 8x8 JPEG block (from the top left) spreads about its fitted
    plane by more than JPEG_EDGE_RANGE times its median sigma in some channel.  A plane, since
    shading tilts smooth blocks; luma blocks, since chroma upsampling steps would read as edges."""
    h, w = values.shape[:2]
    ph, pw = -h % block, -w % block
    nby, nbx = (h + ph) // block, (w + pw) // block

    def blocks(x):
        x = np.pad(x, ((0, ph), (0, pw), (0, 0)), mode="edge")
        return x.reshape(nby, block, nbx, block, 3).transpose(0, 2, 1, 3, 4) \
            .reshape(nby, nbx, block * block, 3)

    yy, xx = np.mgrid[0:block, 0:block]
    design = np.stack([np.ones(block * block), xx.ravel(), yy.ravel()], axis=1)
    residual = np.eye(block * block) - design @ np.linalg.pinv(design)
    r = np.einsum("ij,abjc->abic", residual, blocks(values))
    spread = r.max(axis=2) - r.min(axis=2)
    sigma = np.sqrt(np.median(blocks(variance), axis=2))
    edge = np.any(spread > JPEG_EDGE_RANGE * sigma, axis=-1)
    return np.repeat(np.repeat(edge, block, axis=0), block, axis=1)[:h, :w, None]


# ---- calibration from patches of known reflectance ----------------------------------------

#: Patch label of the ColorChecker's first swatch (:func:`patch_samples`); the material it lies
#: on is rendered as a grey Lambertian of reflectance CHART_GREY, scaled to each swatch's.
CHART_LABEL, CHART_GREY = 1000, 0.5


def reference_error(calibrate, reference_sd, log):
    """The relative error (3,) of the level the references ``calibrate`` {name: rho (3,)} set
    from their reflectances' standard errors ``reference_sd`` {name: sd (3,)}: the largest of
    their sds over their reflectances (the level pools their pixels, so one large reference
    may hold it alone).  Those without one are taken as exact, which a line says."""
    exact = [n for n in calibrate if n not in reference_sd]
    if exact:
        log(f"calibration: {listed([f'{n}={calibrate[n][0]:g}' for n in exact])} taken as "
            "exact: the intervals leave out the error of its reflectance, which sets every "
            "fitted reflectance's level (a grey card's maker states it, often 1-3%); give it as "
            f"--calibrate {exact[0]}={calibrate[exact[0]][0]:g}+-SD (or +-N%) to count it")
    u = [np.asarray(reference_sd[n], dtype=float) / np.asarray(calibrate[n], dtype=float)
         for n in calibrate if n in reference_sd]
    return np.max(u, axis=0) if u else np.zeros(3)


def _calibration_spec(raw, calibrate, base_dir):
    """The spec with each calibration material a grey (or RGB) Lambertian of its reflectance."""
    raw = json.loads(json.dumps(raw))
    mats = raw.setdefault("materials", {})
    for name, rho in calibrate.items():
        mats[name] = {"model": "raw", "rho_d": list(rho), "rho_s": 0.0, "sigma_alpha": 0.1}
    return validate_spec(raw, base_dir)


def patch_samples(spec, values, falloff, calibrate, chart=None, reach=0):
    """The calibration patches' pixels in every frame of ``values`` (the spec's lit frames).

    Patches: the ``calibrate`` materials' pixels (labels 1, 2, ...) eroded from their edges by
    ``reach`` more (mixed pixels bias every material calibrated on them), and with ``chart`` =
    (material, swatch labels (H, W)) the 24 swatches (labels CHART_LABEL + index).  Returns per
    frame (codes (n, 3) [DN], L (n, 3) [W m^-2 sr^-1] rendered for the known reflectance times
    ``falloff``), each pixel's label (n,), and the (H, W) mask.
    """
    from scipy.ndimage import binary_erosion

    renderer = FrameRenderer(spec)
    labels, ids = label_image(renderer.scene)
    patch = np.zeros(labels.shape, np.int32)
    scale = np.ones((CHART_LABEL + 24, 3))
    for k, name in enumerate(calibrate, start=1):
        if name not in ids:
            raise SkyfitError(f"--calibrate {name}: the camera sees no material {name!r}; it sees "
                              f"{', '.join(ids) or 'none'}.")
        m = binary_erosion(labels == ids.index(name) + 1, border_value=1) \
            & ~colour_mixed(labels, reach)
        if m.sum() < 4:
            raise SkyfitError(f"--calibrate {name}: fewer than 4 pixels of it lie away from its "
                              "edges" + (f" by the {reach} pixels registration or the pose's "
                                         "uncertainty may move them" if reach else "")
                              + "; frame the reference patch larger.")
        patch[m] = k
    if chart is not None:
        material, swatches = chart
        if material not in ids:
            raise SkyfitError(f"--colorchecker {material}: the camera sees no material "
                              f"{material!r}; it sees {', '.join(ids) or 'none'}.")
        on = labels == ids.index(material) + 1
        off = [NAMES[k] for k in NEUTRAL if not on[swatches == k + 1].all()]
        if off:
            raise SkyfitError(f"--colorchecker {material}: the chart's {', '.join(off)} "
                              f"swatch(es) lie off material {material!r} in the scene; model "
                              "the chart's surface as that material where the photographs show "
                              "the chart.")
        inside = (swatches > 0) & on
        patch[inside] = CHART_LABEL + swatches[inside] - 1
        scale[CHART_LABEL:] = reference_rgb() / CHART_GREY
    mask = patch > 0
    lit = [f for f in spec.frames if not f.skipped]
    out = []
    for f, v in zip(lit, values):
        radiance, _ = renderer.render(f)
        out.append((v[mask], radiance[mask] * falloff[mask][:, None] * scale[patch[mask]]))
    # each patch's pixels are kept apart by their label, for the response fit's levels
    return out, patch[mask], mask


def _select(samples, patch, keep):
    """The samples and labels of the patches whose labels are in ``keep``."""
    sel = np.isin(patch, list(keep))
    return [(y[sel], L[sel]) for y, L in samples], patch[sel]


def _swatch_ratios(samples, patch, sensor, exposures):
    """(24, 3) each swatch's observed over predicted signal: its :func:`central_mean` in each
    frame (NaN where clipped or black pixels reach the middle half), the median over the frames
    that tell it; NaN where none does."""
    ratio = np.full((len(samples), 24, 3), np.nan)
    for f, ((y, L), e) in enumerate(zip(samples, exposures)):
        r = _signal_ratio(y, L, sensor)[1] / e
        for k in range(24):
            if np.any(patch == CHART_LABEL + k):
                ratio[f, k] = central_mean(r[patch == CHART_LABEL + k])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)          # a swatch no frame tells
        return np.nanmedian(ratio, axis=0)


def central_mean(x):
    """Interquartile mean of ``x`` along its first axis, NaN where it has no value: the
    calibration's robust level (unlike a median, it does not snap to whole codes).  NaN values
    are left out; -inf and +inf stand for values known to lie below or above every other (black
    or clipped pixels, :func:`_signal_ratio`), ranked but never averaged: where one falls among
    the middle half, the level is not known and the mean is NaN."""
    x = np.asarray(x, dtype=float)
    s = np.sort(np.where(np.isnan(x), np.inf, x), axis=0)           # NaN last, with +inf
    n = np.sum(~np.isnan(x), axis=0)
    rank = np.arange(len(s)).reshape((-1,) + (1,) * (s.ndim - 1))
    keep = (rank >= n // 4) & (rank < n - n // 4)
    with np.errstate(all="ignore"):
        mean = np.sum(np.where(keep, s, 0.0), axis=0) / np.maximum(np.sum(keep, axis=0), 1)
    return np.where((n > 0) & np.isfinite(mean), mean, np.nan)


def _ranked_codes(y, max_code):
    """Codes ``y`` [DN] with the clipped ones (:data:`~skyfit_mi.physics.camera.CLIP_FRACTION`
    of ``max_code``) set to +inf and the black ones (<= 0) to -inf: for :func:`central_mean`,
    which ranks them, since within a patch's middle half they would bias its level."""
    with np.errstate(invalid="ignore"):
        return np.where(clipped(y, max_code), np.inf, np.where(y <= 0, -np.inf, y))


def _signal_ratio(y, L, sensor):
    """Linear signal of codes ``y`` (n, 3) [DN] and its ratio to the rendered radiance ``L``
    (n, 3) [W m^-2 sr^-1]: NaN where not finite or unlit, -inf where black and +inf where
    clipped (:func:`_ranked_codes`), which :func:`central_mean` ranks (the one usability
    rule)."""
    ranked = np.where(np.isfinite(y) & (L > 0), _ranked_codes(y, sensor.max_code), np.nan)
    ok = np.isfinite(ranked)
    s = np.where(ok, sensor.linearise(np.where(ok, y, 0.0)), ranked)
    with np.errstate(all="ignore"):
        return s, np.where(ok, s / np.where(ok, L, 1.0), ranked)


def fit_response(samples, patch, max_code, rel, log):
    """The sensor response that the calibration patches' codes follow: (response, gamma, info).

    Each of :data:`RESPONSE_FAMILIES` is fitted to the patches' central codes v against their
    rendered radiance L, with an exposure per channel (times EXIF's ``rel``, else per frame too);
    'gamma' (v = (k L) ^ (1 / gamma), thesis eq. 5.11) by least squares in log v.  The lowest
    rms relative error wins.  SkyfitError unless the signals span RESPONSE_SPAN_MIN.
    """
    v, group, u = [], [], []
    for f, (codes, radiance) in enumerate(samples):
        for m in np.unique(patch):
            sel = patch == m
            for c in range(3):
                y, x = codes[sel, c], radiance[sel, c]
                lit = np.isfinite(y) & (x > 0)
                code = central_mean(_ranked_codes(y[lit], max_code))
                if lit.sum() < 4 or not np.isfinite(code):
                    continue
                v.append(code / max_code)
                group.append(c if rel is not None else 3 * f + c)
                u.append(np.log(central_mean(x[lit])) + (0.0 if rel is None else np.log(rel[f])))
    v, u = np.array(v), np.array(u)
    group = np.unique(group, return_inverse=True)[1].ravel() if len(v) else np.array([], int)
    # what sets the shape: the spread of the signals that share an exposure
    centred = u - (np.bincount(group, weights=u) / np.maximum(np.bincount(group), 1))[group] \
        if len(v) else u
    span = float(np.exp(np.ptp(centred))) if len(v) else 1.0
    if span < RESPONSE_SPAN_MIN:
        raise SkyfitError(f"--response fit: the calibration patches' signals span a factor of "
                          f"{span:.2f} at a fixed exposure (at least {RESPONSE_SPAN_MIN:g} is "
                          "needed); name patches of more reflectances with --calibrate, keep "
                          "the EXIF exposures, or give --response.")
    n_groups = int(group.max()) + 1
    onehot = np.eye(n_groups)[group]

    def rms(pred):
        return float(np.sqrt(np.mean((pred / v - 1.0) ** 2)))

    fits = {}
    for family in RESPONSE_FAMILIES[:-1]:               # the fixed curves; 'gamma' (last) below
        sensor = SensorModel(1.0, response=family, bits=16)
        log_k = np.log(sensor.linearise(v * sensor.max_code)) - u
        b = np.array([np.median(log_k[group == g]) for g in range(n_groups)])
        fits[family] = {"rms_rel": rms(sensor.respond(np.exp(u + b[group])))}
    coef, *_ = np.linalg.lstsq(np.column_stack([u, onehot]), np.log(v), rcond=None)
    gamma = float(1.0 / coef[0]) if coef[0] > 0 else None       # None: codes fall with signal
    fits["gamma"] = {"rms_rel": rms(np.exp(coef[0] * u + onehot @ coef[1:])), "gamma": gamma}
    usable = {k: f for k, f in fits.items() if k != "gamma" or (
        f["gamma"] is not None and GAMMA_RANGE[0] <= f["gamma"] <= GAMMA_RANGE[1])}
    best = min(usable, key=lambda k: usable[k]["rms_rel"])
    gamma = fits["gamma"]["gamma"] if best == "gamma" else 2.2
    info = {"families": fits, "chosen": best, "values": int(len(v)), "span": span}
    log(f"response fitted to {len(v)} patch values (signals spanning {span:.1f}x): "
        + ", ".join(f"{k}{' ' + format(f['gamma'], '.3g') if f.get('gamma') else ''} "
                    f"{100 * f['rms_rel']:.2g}%" for k, f in fits.items()) + f"; using {best}")
    if fits[best]["rms_rel"] > RESPONSE_RMS_WARN:
        log(f"warning: no response family describes the calibration patches well (best, {best}, "
            f"misses their codes by {100 * fits[best]['rms_rel']:.1f}% rms); check the patches' "
            "reflectances, their lighting, or give --response")
        info["warning"] = "no family describes the patches within " \
            f"{100 * RESPONSE_RMS_WARN:g}% rms"
    return best, gamma, info


#: Most parts a patch's pixels are split into, whose spread measures a frame's exposure error
#: (:func:`calibrate_exposure`): 8 give 7 degrees of freedom per frame and channel.
CALIBRATION_PARTS = 8
#: The most a grey reference's channels may read apart (largest over smallest exposure): a
#: white-balanced camera's grey reads within a few tens of per cent, a raw one's without its
#: balance about 2x; beyond, the reference's box lies on something else (a frame turned or
#: cropped: an upside-down day's "card" read the red sample, 2.73 : 0.54 : 0.46).
GREY_BALANCE_MAX = 3.0


def _patch_exposure(s, r, patch, parts=1, cells=None):
    """One frame's exposure (3,) from its patches' signals ``s`` and ratios ``r`` (n, 3)
    (:func:`_signal_ratio`): per patch the central mean of its ratios, weighted by pixels x
    central signal^2; NaN where no patch's middle half is free of clipped or black pixels.
    With ``parts`` > 1, (parts, 3) from runs of each patch's pixels (bands of rows), or of its
    JPEG coding units with ``cells`` (n,)."""
    out = np.zeros((parts, 3))
    for part in range(parts):
        num = den = 0.0
        with np.errstate(all="ignore"):
            for m in np.unique(patch):
                idx = np.flatnonzero(patch == m)
                if cells is None:
                    idx = np.array_split(idx, parts)[part]
                else:
                    idx = idx[np.isin(cells[idx], np.array_split(np.unique(cells[idx]),
                                                                 parts)[part])]
                level = central_mean(r[idx])
                weight = np.where(np.isfinite(level), np.sum(~np.isnan(r[idx]), axis=0)
                                  * np.nan_to_num(central_mean(s[idx])) ** 2, 0.0)
                num = num + weight * np.nan_to_num(level)
                den = den + weight
            out[part] = np.where(den > 0, num / den, np.nan)
    return out if parts > 1 else out[0]


#: p-value of the exposures' chi^2 about EXIF's below which each frame takes its patches' own.
EXIF_SCATTER_P = 1e-3
#: Legendre terms in time (level, drift, curvature) of the smooth day curve about which exposures
#: are tested against EXIF's: a sky unlike the spec's moves the light smoothly, a shutter frame by
#: frame (docs/BENCHMARKS.md, "The sample board photographed").
EXPOSURE_CURVE_TERMS = 3


def exif_scatter(ratio, var, seconds=None):
    """How the frames' patch exposures depart from EXIF's: ``ratio`` (F, 3) patch over EXIF
    exposure, ``var`` (3,) a frame's relative variance, ``seconds`` (F,) frame times (or None).
    Scatter about a smooth curve in log ``ratio`` (:data:`EXPOSURE_CURVE_TERMS`) is the
    camera's (``shutter``), the curve beyond its level the light's (``curved``), each a chi^2
    test at EXIF_SCATTER_P; the dict also holds the spreads and ``scatter_chi2_per_dof``."""
    from scipy.stats import chi2 as chi2_dist

    dev = np.log(np.asarray(ratio, dtype=float))
    n = len(dev)
    terms = 1 if seconds is None else max(1, min(EXPOSURE_CURVE_TERMS, n - 1))
    basis = np.ones((n, 1)) if terms == 1 else time_legendre(
        seconds, (seconds.min(), seconds.max()), terms)
    curve = basis @ np.linalg.lstsq(basis, dev, rcond=None)[0]
    w = 1.0 / np.maximum(np.asarray(var, dtype=float), 1e-12)
    chi2 = float(np.sum((dev - curve) ** 2 * w))                 # about the curve
    drift = float(np.sum((curve - curve.mean(axis=0)) ** 2 * w))   # the curve beyond its level
    dof = 3 * (n - terms)
    return {"relative_spread": float(np.std(dev @ SRGB_LUMINANCE)),
            "frame_spread": float(np.std((dev - curve) @ SRGB_LUMINANCE)),
            "curve_relative_spread": float(np.std(curve @ SRGB_LUMINANCE)),
            "curve_terms": terms, "scatter_chi2_per_dof": chi2 / dof,
            "furthest": int(np.argmax(np.abs((dev - curve) @ SRGB_LUMINANCE))),
            "shutter": bool(chi2_dist.sf(chi2, dof) < EXIF_SCATTER_P),
            "curved": bool(terms > 1 and chi2_dist.sf(drift, 3 * (terms - 1)) < EXIF_SCATTER_P)}


def calibrate_exposure(samples, patch, sensor, photos, rel, log, cells, seconds):
    """Per-frame, per-channel exposure [sr m^2 W^-1] (F, 3) from the patches'
    :func:`patch_samples` (``patch``: each pixel's label), and the calibration's record.

    Each frame's exposure is :func:`_patch_exposure`, its standard error the spread over up to
    CALIBRATION_PARTS parts of the patches (in JPEGs whole coding units ``cells``, which share
    errors), pooled over frames.  With EXIF exposures ``rel`` the day shares one scale per
    channel, unless (3+ frames) they scatter beyond the patches' noise about a smooth day curve
    in ``seconds`` (:func:`exif_scatter`): then each frame takes its own.  A smooth departure is
    the light's, left for a fit of the sky.  ``scale_relative_sd`` (3,) widens the fits'
    intervals (:func:`skyfit_mi.fitting.intervals.calibration_rows`).
    """
    units = [len(np.unique(cells[patch == m])) if cells is not None else
             int(np.sum(patch == m)) // 8 for m in np.unique(patch)]
    n_parts = int(np.clip(min(units), 2, CALIBRATION_PARTS))
    parts = np.full((len(samples), n_parts, 3), np.nan)
    k = np.full((len(samples), 3), np.nan)
    for i, (y, L) in enumerate(samples):
        s, r = _signal_ratio(y, L, sensor)
        k[i] = _patch_exposure(s, r, patch)
        # the parts measure the spread only: each from its unclipped values, since a highlight
        # within a quarter of the patch may fill more than a quarter of one part
        unclipped = [np.where(np.isinf(x), np.nan, x) for x in (s, r)]
        parts[i] = _patch_exposure(*unclipped, patch, parts=n_parts, cells=cells)
    good = np.isfinite(k).all(axis=1)
    if not good.any():
        raise SkyfitError("the calibration patches are saturated, black or unlit in every frame; "
                          "they cannot set the exposure. Give --exposure instead.")
    with np.errstate(all="ignore"):
        balance = np.max(k, axis=1) / np.min(k, axis=1)
    off = np.flatnonzero(good & (balance > GREY_BALANCE_MAX))
    if off.size:
        i = int(off[np.argmax(balance[off])])
        grey = k[i] / k[i].max()                     # its codes per unit of light
        raise SkyfitError(
            f"{len(off)} frame(s) ({Path(photos[i].path).name}, ...) read the grey reference as "
            f"R:G:B {grey[0]:.2f} : {grey[1]:.2f} : {grey[2]:.2f}, not grey: its region does not "
            "lie on the card there (a frame turned or cropped, a wrong EXIF orientation, the "
            "spec's region) or the frames are not white-balanced; check the region on the "
            "contact sheet.")
    # a frame's relative variance, pooled over frames: the parts' variance over their number
    with np.errstate(all="ignore"):
        d = parts[good] / k[good, None, :]
        var_f = np.nanmean(np.nanvar(d, axis=1, ddof=1), axis=0) / n_parts
    info = {"frame_relative_sd": np.sqrt(var_f).tolist()}
    own_sd = np.sqrt(var_f / good.sum()).tolist()        # exposures of the frames' own
    missing = [Path(photos[i].path).name for i in np.flatnonzero(~good)]
    curved = False
    if rel is not None:
        scale = np.nanmedian(k[good] / rel[good, None], axis=0)
    if rel is not None and good.sum() >= 3:
        test = exif_scatter(k[good] / (rel[good, None] * scale), var_f,
                            np.asarray(seconds, dtype=float)[good])
        curved, shutter = test.pop("curved"), test.pop("shutter")
        furthest = Path(photos[np.flatnonzero(good)[test.pop("furthest")]].path).name
        info.update(test)
        if shutter and not missing:
            log(f"calibration: the frames' exposures scatter by {test['frame_spread']:.1%} "
                "about a smooth curve through their EXIF relative exposures, "
                f"{np.sqrt(test['scatter_chi2_per_dof']):.1f}x what the patches' noise allows, "
                f"most at {furthest} (a shutter or aperture off its nominal value, a label "
                "wrong, the camera's white balance or processing changed, or a frame's time "
                "off): each frame's exposure is taken from its own patches")
        if shutter:                 # EXIF cannot stand in for a frame without its reference
            rel = None
            info["exif_relative_exposures"] = "not used: they scatter beyond the patches' noise"
    if rel is None:
        if missing:
            raise SkyfitError(f"{listed(missing)}: the calibration patches are clipped, black "
                              "or unlit, and the frames' EXIF exposures cannot stand in for them "
                              "(missing, or scattered beyond the patches' noise); drop those "
                              "frames, or give --exposure.")
        info.update(per_frame=True, scale_relative_sd=own_sd)
        return k, info
    if missing:
        log(f"calibration: the references are clipped, black or unlit in {listed(missing)}: "
            "those frames take their EXIF exposures, on the others' scale")
        info["frames_without_reference"] = missing
    info.update(per_frame=False,
                scale_relative_sd=np.sqrt(np.pi / 2.0 * var_f / good.sum()).tolist())
    exif = rel[:, None] * scale[None, :]
    log(f"calibration: the first frame's exposure {exif[0] @ SRGB_LUMINANCE:.4g} sr m^2 W^-1, "
        "the others' by their EXIF relative exposures (frame-to-frame spread "
        f"{100 * info.get('relative_spread', 0.0):.1f}%)")
    info["light_drift"] = curved
    if not curved:
        return exif, info
    log(f"calibration: the references' light drifts from the spec's by "
        f"{info['curve_relative_spread']:.1%} over the day, smoothly as a sky unlike the "
        "spec's does: the frames keep their EXIF exposures' level, which a fit of the sky "
        "with the references among its regions (fit --all) takes, and each its own colour "
        "balance from the references")
    # colour from the references frame by frame (no fitted light moves it); level from EXIF
    ratio = (k @ SRGB_LUMINANCE) / (exif @ SRGB_LUMINANCE)
    info.update(per_frame=True, scale_relative_sd=own_sd)
    return np.where(good[:, None], k / ratio[:, None], exif), info


# ---- the whole ingest ---------------------------------------------------------------------

def _chart_record(material, chart, samples, patch, sensor, exposures, log):
    """The manifest's record of a ColorChecker calibration, with its chromatic check and the
    colour matrix's error (:func:`.colorchecker.matrix_error`; None if too few swatches)."""
    ratio = _swatch_ratios(samples, patch, sensor, exposures)
    check = swatch_check(ratio)
    if check["rms"] is not None:
        log(f"ColorChecker check: the calibrated chromatic swatches are "
            f"{check['rms']:.1%} rms from their rendered reference (worst {check['worst'][0]}, "
            f"{check['worst'][1]:.1%}); the neutral swatches calibrated")
    labels = np.tile(patch, len(samples))
    L = np.concatenate([x for _, x in samples])
    predicted = np.array([np.nanmean(L[labels == CHART_LABEL + k], axis=0)
                          if np.any(labels == CHART_LABEL + k) else np.full(3, np.nan)
                          for k in range(24)])
    mixing = matrix_error(ratio, predicted)
    if mixing is not None:
        log(f"ColorChecker colour: the camera's colour matrix mixes its channels by up to "
            f"{np.max(np.abs(mixing['mixing'])):.1%} (each entry +-"
            f"{np.sqrt(np.mean(mixing['standard_error'] ** 2)):.1%}); the frames are corrected "
            f"by it, leaving the chromatic swatches {mixing['residual_rms']:.1%} rms")
        mixing = {k: (v.tolist() if isinstance(v, np.ndarray) else v)
                  for k, v in mixing.items()}
    return {"material": material, "swatches_used": [NAMES[k] for k in NEUTRAL],
            "outline_px": np.round(chart["corners"], 1).tolist(),
            "pixels_per_swatch": chart["pixels"].tolist(), "match_rms": chart["match"],
            "chromatic_check": check, "colour_matrix": mixing,
            "reference": "linear sRGB of ColorChecker24 - After November 2014 (colour-science, "
                         "via colour-checker-detection)"}


def spec_for_times(spec_path, times, tz=None, site=None, size=None):
    """(raw, validated spec) of ``spec_path`` for frames at ``times`` (aware datetimes, in
    order), night frames skipped; ``site`` (lat_deg, lon_deg[, elevation_m]) overrides its
    [location], ``size`` (width, height) is its camera's (a spec naming another is refused)."""
    spec_path = Path(spec_path)
    raw = read_spec(spec_path)
    if "time" not in raw:
        raise SpecError(f"{spec_path.name} has lab lights (frames by index, no [time]), but "
                        "measured frames are placed by their times: give a spec of the day "
                        "([location], [time], its sky), or the lab values as a table (ingest "
                        "--table with a frame column).")
    cam = dict(raw.get("camera", {}))
    turned = size is not None and [cam.get("width"), cam.get("height")] == [size[1], size[0]]
    for key, n in zip(("width", "height"), size or ()):
        if key in cam and int(cam[key]) != n:
            raise SpecError(f"[camera] {key} = {cam[key]} but the photographs are "
                            f"{size[0]}x{size[1]}"
                            + (" (the spec's size turned a quarter: their EXIF Orientation, "
                               "which skyfit applies, turns them as displayed; a wrong tag "
                               "turns them wrongly)" if turned else "")
                            + f"; give the camera of these photographs as they are displayed "
                            f"(drop {key} from the spec only if its field of view is theirs: a "
                            "cropped photograph sees a narrower one).")
        cam[key] = n
    raw["camera"] = cam
    loc = dict(raw.get("location", {}))
    if site is not None:
        loc.update(zip(("latitude_deg", "longitude_deg", "elevation_m"), site))
    loc.setdefault("timezone", tz or times[0].isoformat()[-6:])
    raw["location"] = loc
    raw["time"] = {"times": [t.isoformat() for t in times]}
    raw["render"] = {**raw.get("render", {}), "below_horizon": "skip"}
    return raw, validate_spec(raw, spec_path.parent)


def measured_header(spec, sensor, run_id, what, seed_rule, scene=None):
    """The manifest header of measured frames, materials marked placeholders; ``scene``: the
    spec's (xml, materials, to_world) if already built."""
    xml, materials, to_world = scene or build_scene_xml(spec)
    for m in materials.values():
        m["source"] = f"{m.get('source', 'spec')}: a placeholder; the {what} material is " \
                      "unknown until fitted"
    return manifest_header(spec, sensor, (xml, materials, to_world),
                           {**spec.render, "seed_rule": seed_rule}, source="ingest",
                           run_id=run_id)


def _run_id(paths, spec_raw, options):
    h = hashlib.sha256()
    for p in paths:
        h.update(p.name.encode())
        h.update(hashlib.sha256(p.read_bytes()).digest())
    h.update(json.dumps([spec_raw, options], sort_keys=True, default=str).encode())
    return h.hexdigest()[:16]


def _neutral_labels(calibrate):
    """Labels of the patches that set the exposure: ``calibrate``'s and the neutral swatches."""
    return list(range(1, len(calibrate) + 1)) + [CHART_LABEL + k for k in NEUTRAL]


def _unbiased(values, bias, max_code):
    """``values`` [DN] less the compression's mean error ``bias``, clipped or missing ones kept."""
    keep = ~np.isfinite(values) | (values <= 0) | (values >= max_code)
    return np.where(keep, values, np.clip(values - bias, 0.0, max_code)).astype(values.dtype)


def _jpeg_errors(values, jpeg, sensor, noise, shown, progress, patches, registration):
    """Per JPEG frame (index -> settings in ``jpeg``) its compression's bootstrap
    (:func:`.jpeg_noise.bootstrap_variance`): {"variance" (float16, to save memory), "rho",
    "bias_mean", "bias_patches" (at the registered mask ``patches``, or None), "settings",
    "shown"}.  ``values`` (a list) lose the mean error in place (:func:`_unbiased`)."""
    from tqdm import tqdm

    out = {}
    todo = [i for i, st in jpeg.items() if st is not None]
    for i in tqdm(todo, desc="JPEG errors", unit="frame", disable=not (progress and todo)):
        var, rho, bias = bootstrap_variance(values[i], jpeg[i], sensor, noise, [SEED, i])
        values[i] = _unbiased(values[i], bias, sensor.max_code)
        out[i] = {"variance": var.astype(np.float16), "rho": rho,
                  "bias_mean": np.nanmean(bias, axis=(0, 1)),
                  "bias_patches": None if patches is None
                  else registration.warp(i, bias)[patches].astype(np.float32),
                  "settings": jpeg[i], "shown": shown}
    return out


@dataclass
class IngestOptions:
    """What the user chose for an ingest (:func:`ingest`'s keywords, the CLI's options)."""

    times_csv: object = None
    name_pattern: str = None
    tz: str = None
    site: tuple = None
    response: str = None
    gamma: float = None
    exposure: float = None
    calibrate: dict = None
    reference_sd: dict = None
    colorchecker: str = None
    vignetting: str = "none"
    noise: tuple = None
    colour_matrix_error: float = None
    register: bool = True
    register_limit_px: float = LIMIT_PX
    exact_curve: bool = False

    @property
    def fitted(self):
        """Whether the response is fitted from the calibration patches."""
        return self.response == "fit"


@dataclass
class Frames:
    """The photographs, in time order, with their times and the spec's frames for them."""

    paths: list
    photos: list
    times: list
    raw: dict
    spec: object
    lit: list                                      # indices of the frames with the sun up

    @property
    def size(self):
        """(height, width)."""
        return self.photos[0].values.shape[:2]


@dataclass
class Linear:
    """The frames' encoding: sensor, float scale [DN per unit], vignetting (h, w), flat field."""

    sensor: SensorModel
    float_scale: float
    falloff: np.ndarray
    flat: np.ndarray
    values: list


@dataclass
class Patches:
    """The references seen in the lit frames (or, without any, the given first exposure), the
    chart found, the response fitted from them, and EXIF's relative exposures."""

    sensor: SensorModel
    rel: np.ndarray
    samples: list = None
    patch: object = None
    mask: np.ndarray = None
    chart: dict = None
    response_info: dict = None
    given: float = None


@dataclass
class Noise:
    """Read + shot noise (a [DN^2], b [DN]; for RAWs of the photosites), its record, and by
    frame index the JPEG errors (:func:`_jpeg_errors`) or RAW noise (:func:`_raw_noise`)."""

    a: float
    b: float
    info: dict
    jpeg_errors: dict
    raw: dict = None


@dataclass
class Exposures:
    """Each lit frame's RGB exposure [sr m^2 W^-1] by index, with the first frame's sensor."""

    sensor: SensorModel
    by_frame: dict
    calibration: dict
    rel: np.ndarray
    tone_curve: dict = None


def ingest(photo_paths, spec_path, out_dir, *, overwrite=False, progress=True, log=print,
           **choices):
    """Turn photographs into a sequence folder; returns the manifest dict.

    Stages, each with a typed result: :func:`check_choices`, :func:`read_frames`,
    :func:`linearise`, :func:`.registration.register_frames`, :func:`calibration_patches`,
    :func:`noise_model`, :func:`frame_exposures`, then :func:`_write`.

    Parameters
    ----------
    photo_paths : list of paths (files, or folders whose images are taken in name order)
    spec_path : the spec (TOML/JSON) giving site, camera, scene and sky; its [time] is unused
    out_dir : the sequence folder to write
    choices : :class:`IngestOptions`' fields:
        times_csv, name_pattern, tz : the frames' times (:func:`.photo_times.frame_times`)
        site : (latitude_deg, longitude_deg[, elevation_m]) overriding the spec's [location]
        response, gamma : the encoding to invert (default: the spec's [sensor], else the
            files'), or response 'fit' (:func:`fit_response`)
        exposure : absolute exposure of the first frame [sr m^2 W^-1]
        calibrate : {material: (r, g, b) reflectance} of grey Lambertian references
        colorchecker : scene material a ColorChecker Classic lies on; its neutral swatches
            calibrate, its chromatic ones check (``calibration.colorchecker``)
        vignetting : 'none' (not corrected: its error counted, fitting.uncertainty.
            vignetting_error), 'corrected' (by the camera: none left), 'cos4', or the path of a
            flat-field image
        noise : (a [DN^2], b [DN]), or None to estimate it from the frames
        register, register_limit_px : register the frames on the one nearest midday
            (default True), refusing a frame that moved more than the limit [px]
    """
    o = check_choices(IngestOptions(**choices))
    frames = read_frames(photo_paths, spec_path, out_dir, o, log)
    linear = linearise(frames, o, log)
    registration = register_frames(frames, linear, o.register, o.register_limit_px, log)
    patches = calibration_patches(frames, linear, registration, o, log)
    noise = noise_model(frames, linear.values, patches, registration, o, progress, log)
    exposures = frame_exposures(frames, patches, noise, o, log)
    # the choices as recorded (the site is in the spec's [location]), with the encoding used
    options = {k: x for k, x in vars(o).items() if k != "site"}
    options.update(times_csv=str(o.times_csv), vignetting=str(o.vignetting),
                   response=("fit: " if o.fitted else "") + exposures.sensor.response,
                   gamma=exposures.sensor.gamma, noise=[noise.a, noise.b])
    run_id = _run_id(frames.paths, frames.spec.raw, options)
    out = Path(out_dir)
    with FolderLock(out):
        prepare_folder(out, run_id, frames.size + (3,), overwrite, log)
        return _write(out, frames, linear, registration, noise, exposures, options, run_id,
                      progress)


def check_choices(o):
    """``o`` with calibrate made a dict; SkyfitError for unusable or contradictory choices."""
    o.calibrate = dict(o.calibrate or {})
    o.reference_sd = dict(o.reference_sd or {})
    unknown = sorted(set(o.reference_sd) - set(o.calibrate))
    if unknown:
        raise SkyfitError(f"a reflectance error is given for {', '.join(unknown)}, which "
                          "--calibrate does not name; give it as --calibrate NAME=RHO+-SD.")
    if o.noise is not None and not (len(o.noise) == 2 and np.all(np.isfinite(o.noise))
                                    and min(o.noise) >= 0):
        raise SkyfitError(f"--noise {','.join(f'{v:g}' for v in o.noise)}: give the read "
                          "variance [DN^2] and the shot gain [DN] as two finite numbers of at "
                          "least 0 (e.g. 0.64,0.02), or leave --noise out to estimate them.")
    if o.colour_matrix_error is not None and not (np.isfinite(o.colour_matrix_error)
                                                  and 0 <= o.colour_matrix_error < 1):
        raise SkyfitError(f"--colour-matrix-error {o.colour_matrix_error:g}: give the relative "
                          "error of the colour matrix's entries as a number in [0, 1) (e.g. "
                          "0.03), or leave it out.")
    if not (np.isfinite(o.register_limit_px) and o.register_limit_px > 0):
        raise SkyfitError(f"--register-limit {o.register_limit_px:g}: give the largest shift a "
                          "frame may have [px] as a positive number (e.g. 5).")
    if str(o.vignetting) not in VIGNETTING and not Path(o.vignetting).is_file():
        raise SkyfitError(f"--vignetting {o.vignetting}: give none, corrected, cos4, or the path "
                          "of a flat-field image (no such file).")
    if o.exposure is not None and not (np.isfinite(o.exposure) and o.exposure > 0):
        raise SkyfitError(f"--exposure {o.exposure:g}: give the first frame's exposure as a "
                          "positive number [sr m^2 W^-1] (1 / the radiance that saturates the "
                          "sensor), or calibrate it on a reference with --calibrate.")
    if o.exposure is not None and (o.calibrate or o.colorchecker):
        raise SkyfitError("--exposure is not used when --calibrate or --colorchecker set the "
                          "exposure from the scene's reference; give one or the other.")
    if o.colorchecker is not None and o.colorchecker in o.calibrate:
        raise SkyfitError(f"{o.colorchecker!r} is named by both --calibrate and --colorchecker; "
                          "the chart's material takes its reflectances from the chart's swatches: "
                          "drop it from --calibrate.")
    if o.fitted and not (o.calibrate or o.colorchecker):
        raise SkyfitError("--response fit needs patches of known reflectance: name them with "
                          "--calibrate MATERIAL=REFLECTANCE (two or more reflectances, or one "
                          "seen at several EXIF exposures), or --colorchecker MATERIAL.")
    return o


def _grey(values, max_code=None):
    """Whether photograph ``values`` (H, W, 3) hold one channel repeated: R = G = B in every
    pixel that tells (finite, neither black nor clipped at ``max_code``), and some do; a grey
    image, as a colour camera's frame never is."""
    v = np.asarray(values, dtype=float)
    with np.errstate(invalid="ignore"):
        tells = np.all(np.isfinite(v) & (v > 0), axis=-1)
        if max_code is not None:
            tells &= ~np.any(clipped(v, max_code), axis=-1)
    v = v[tells]
    return bool(len(v) and np.array_equal(v[:, 0], v[:, 1]) and np.array_equal(v[:, 1], v[:, 2]))


#: ``--vignetting``'s named choices (else a flat field's path): the falloff not corrected (its
#: error counted), corrected by the camera already, or the cos^4 law.
VIGNETTING = ("none", "corrected", "cos4")
#: A frame further than this from the others' median date [days] is named (a reset clock).
CLOCK_OFF_DAYS = 30.0


def read_frames(photo_paths, spec_path, out_dir, o, log):
    """The :class:`Frames` of the photographs: read, timed, sorted, with the spec at their times."""
    made = next((p for p in map(Path, photo_paths) if (p / FILENAME).is_file()), None)
    if made is not None:
        raise SkyfitError(f"{made} is a sequence folder (skyfit render or ingest wrote it), not "
                          "photographs; give the folder of the camera's files.")
    paths = list_photos(photo_paths)
    if len(paths) < 2:
        raise SkyfitError(f"{len(paths)} photograph(s) given; a sequence needs at least 2.")
    target = Path(out_dir).resolve()
    inside = next((p for p in paths if target in p.resolve().parents), None)
    if inside is not None:
        raise SkyfitError(f"the output folder {out_dir} holds the photographs ({inside.name}); "
                          "give another with -o (--overwrite would clear it, and its contact "
                          "sheet would be read as a photograph next time).")
    photos = [read_photo(p) for p in paths]
    w, h = check_same_size(list(zip(paths, photos)))
    times = frame_times(paths, [p.metadata for p in photos], times_csv=o.times_csv,
                        name_pattern=o.name_pattern, tz=o.tz, warn=log)
    order = check_times(paths, times)                  # refuses frames sharing an instant
    paths, photos, times = ([x[i] for i in order] for x in (paths, photos, times))
    days = np.array([t.timestamp() for t in times]) / 86400.0
    far = [p.name for p, d in zip(paths, days) if abs(d - np.median(days)) > CLOCK_OFF_DAYS]
    if far:
        log(f"{listed(far)}: taken over {CLOCK_OFF_DAYS:g} days from the other frames' median "
            f"date ({times[len(times) // 2].date().isoformat()}): a camera clock reset or "
            "wrong? Check the EXIF times, or give them in a CSV (--times)")
    cameras = [camera_name(p.metadata) for p in photos]
    named = [c for c in cameras if c]
    if len(set(named)) > 1:
        usual = max(set(named), key=named.count)
        odd = [p.name for p, c in zip(paths, cameras) if c and c != usual]
        log(f"{listed(odd)}: taken by another camera than the rest ({usual}), by EXIF: its "
            "sensor, lens and processing differ (each frame is calibrated alike only with a grey "
            "reference in it); leave such frames out unless they belong to the sequence")
    raw, spec = spec_for_times(spec_path, times, o.tz, o.site, (w, h))
    night = [paths[f.index].name for f in spec.frames if f.skipped]
    if len(night) == len(paths):
        raise SkyfitError(f"every frame was taken with the sun below the horizon (first: "
                          f"{paths[0].name} at {times[0].isoformat()}); check the times, --tz and "
                          "--site.")
    if night:
        log(f"{len(night)} night frame(s) (sun below the horizon) are kept out of the sequence: "
            f"{', '.join(night)}")
    lit = [i for i, f in enumerate(spec.frames) if not f.skipped]
    grey = [paths[i].name for i in lit if _grey(photos[i].values, photos[i].max_code)]
    if grey:
        raise SkyfitError(f"{listed(grey)}: grey (one channel, or R = G = B in every pixel); "
                          "a fit measures each colour channel's reflectance, which a grey "
                          "photograph cannot tell: give the camera's colour photographs.")
    return Frames(paths, photos, times, raw, spec, lit)


def linearise(frames, o, log):
    """The :class:`Linear` encoding of ``frames`` (a fitted response comes later)."""
    photos, (h, w) = frames.photos, frames.size
    sensor, float_scale, said = _sensor(photos, None if o.fitted else o.response, o.gamma,
                                        frames.raw.get("sensor", {}), o.vignetting == "cos4",
                                        o.fitted)
    for line in said:
        log(line)
    if o.fitted and float_scale is not None:
        raise SkyfitError("--response fit: the frames are floating-point (EXR/HDR), which hold "
                          "linear values; leave out --response.")
    if o.gamma is not None and (o.fitted or sensor.response != "gamma"):
        raise SkyfitError(f"--gamma is the exponent of a gamma response, but the response is "
                          f"{'fitted' if o.fitted else repr(sensor.response)}; add --response "
                          "gamma, or leave out --gamma.")
    if o.exact_curve and not o.fitted and sensor.response == "linear":
        raise SkyfitError("--exact-curve says codes follow their response's curve exactly, but "
                          "these frames are linear (RAW, EXR/HDR, or --response linear), which "
                          "no camera's tone curve bends; leave out --exact-curve.")
    falloff = sensor.falloff(w, h, frames.spec.camera["fov_deg"]) if sensor.cos4 \
        else np.ones((h, w))
    flat = None
    if o.vignetting not in VIGNETTING:
        falloff = flat = read_flat_field(o.vignetting, (h, w))
    values = [(p.values * float_scale) if float_scale else p.values for p in photos]
    return Linear(sensor, float_scale, falloff, flat, values)


def calibration_patches(frames, linear, registration, o, log):
    """The :class:`Patches` of the lit frames: references sampled on the registered frames (and
    the fitted response), or without references the first frame's given exposure."""
    lit, sensor = frames.lit, linear.sensor
    values = {i: registration.warp(i, linear.values[i], sensor.max_code) for i in lit}
    rel = _relative_exposures(frames.photos, log)
    out = Patches(sensor, rel)
    if o.colorchecker is not None:
        out.chart = find_chart([sensor.linearise(values[i]) / linear.falloff[..., None]
                                for i in lit], log)
    if o.calibrate or out.chart:
        materials = {**o.calibrate, **({o.colorchecker: (CHART_GREY,) * 3} if out.chart else {})}
        cal_spec = _calibration_spec(frames.spec.raw, materials, frames.spec.base_dir)
        reach = max(int(registration.record.get("erode_px", 0)),
                    pose_reach(frames.spec.camera))
        out.samples, out.patch, out.mask = patch_samples(
            cal_spec, [values[i] for i in lit], linear.falloff, o.calibrate,
            None if out.chart is None else (o.colorchecker, out.chart["labels"]), reach)
        if o.fitted:
            chosen, g, out.response_info = fit_response(
                *_select(out.samples, out.patch, _neutral_labels(o.calibrate)), sensor.max_code,
                None if rel is None else rel[lit], log)
            out.sensor = replace(sensor, response=chosen, gamma=g)
        return out
    out.given = o.exposure if o.exposure is not None else (
        frames.spec.sensor.get("exposure")
        if frames.raw.get("sensor", {}).get("exposure", "auto") != "auto" else None)
    if out.given is None:
        raise SkyfitError("the photographs' absolute scale is unknown: give --exposure E "
                          "[sr m^2 W^-1] for the first frame, or --calibrate MATERIAL="
                          "REFLECTANCE naming a grey reference in the scene.")
    # an HDR merge's float frames share one scale; a camera's codes scale by their labels
    bare = [Path(p.path).name for p in frames.photos
            if p.kind != "float" and exif_exposure(p) is None]
    if rel is None and len(frames.photos) > 1 and bare:
        raise SkyfitError(
            f"{len(bare)} of {len(frames.photos)} photographs have no EXIF exposure (time, "
            f"f-number, ISO: {', '.join(bare[:3])}{', ...' if len(bare) > 3 else ''}), which "
            "scales the given exposure from the first frame to each: calibrate every frame on "
            "a grey reference (--calibrate MATERIAL=REFLECTANCE), or give the files their "
            "exposure labels (exiftool -ExposureTime= -FNumber= -ISO=).")
    return out


def noise_model(frames, values, patches, registration, o, progress, log):
    """The :class:`Noise` of the lit frames: read + shot noise estimated (or the option's), and
    each JPEG frame's compression errors by bootstrap; for Bayer RAWs, :func:`_raw_noise`."""
    lit, sensor = frames.lit, patches.sensor
    if all(frames.photos[i].format == "raw" for i in lit):
        planes = [cfa_planes(frames.paths[i]) for i in lit]
        if all(p is not None for p in planes):
            return _raw_noise(frames, values, planes, o, progress, log)
    shown = None
    try:
        shown = shown_noise([values[i] for i in lit], sensor)
    except SkyfitError:
        if o.noise is None:
            raise
    jpeg = {i: jpeg_settings(frames.paths[i]) for i in lit
            if frames.photos[i].format == "jpeg"}
    for i, st in jpeg.items():
        if st is not None:                      # the blocks lie in the file's own layout
            st["orientation"] = frames.photos[i].metadata.get("orientation", 1)
    if any(st and st["subsampling"] for st in jpeg.values()):
        log("the JPEGs' chroma is subsampled (4:2:2 or 4:2:0): colour edges blur by a pixel, "
            "an error sigma does not hold; keep pixels beside edges out of fits (regions from "
            "the scene's labels are eroded by a pixel; erode a --region too)")
    if o.noise is None:
        a, b = estimate_noise([values[i] for i in lit], sensor, [jpeg.get(i) for i in lit],
                              shown, log)
        info = {"read_DN2": a, "shot_DN": b, "source": "estimated from the frames",
                "shown_by_the_frames": list(shown)}
    else:
        a, b = (float(x) for x in o.noise)
        info = {"read_DN2": a, "shot_DN": b, "source": "given"}
    log(f"noise model: read {np.sqrt(a):.3g} DN rms, shot {b:.3g} DN per linear DN "
        f"({info['source']})")
    return Noise(a, b, info, _jpeg_errors(values, jpeg, sensor, (a, b), shown or (0.0, 0.0),
                                          progress, patches.mask, registration))


def _raw_noise(frames, values, planes, o, progress, log):
    """The :class:`Noise` of RAW frames: photosite noise [raw DN] from the CFA ``planes`` (or
    given), and each frame's developed noise sd and correlations (:mod:`.raw_noise`)."""
    lit = frames.lit
    if o.noise is None:
        a, b = shown_noise([p for ps in planes for p in ps], SensorModel(1.0, "linear", bits=16))
        info = {"read_DN2": a, "shot_DN": b,
                "source": "estimated from the RAWs' photosites (CFA planes)"}
    else:
        a, b = (float(x) for x in o.noise)
        info = {"read_DN2": a, "shot_DN": b, "source": "given"}
    info["units"] = "the photosites' raw DN above black"
    log(f"noise model of the RAWs' photosites: read {np.sqrt(a):.3g} raw DN rms, shot {b:.3g} "
        f"raw DN per DN ({info['source']})")
    from tqdm import tqdm

    draws = {i: bootstrap(frames.paths[i], (a, b), [RAW_SEED, i], values[i])
             for i in tqdm(lit, desc="RAW noise", unit="frame", disable=not progress)}
    info["raw"] = {
        "method": "parametric bootstrap: the frame's photosites smoothed (each CFA plane over "
                  f"{RAW_SMOOTH}x{RAW_SMOOTH} of its sites), given fresh read and shot noise "
                  "and developed as ingest develops them; the mean square of the differences "
                  f"from the smoothed sites developed, over each pixel's {RAW_SMOOTH}x"
                  f"{RAW_SMOOTH} neighbourhood", "replicates": RAW_REPLICATES,
        "seed": [RAW_SEED, "frame index"]}
    return Noise(a, b, info, {}, {i: {"sd": np.sqrt(draws[i][0]).astype(np.float16),
                                      "noise_correlation": draws[i][1],
                                      "channel_correlation": draws[i][2]} for i in lit})


def frame_exposures(frames, patches, noise, o, log):
    """The :class:`Exposures` of the lit frames: calibrated on the references (JPEG bias taken
    out as from the frames), or the given first exposure scaled by EXIF's relative exposures."""
    lit, sensor, rel = frames.lit, patches.sensor, patches.rel
    calibration = references = None
    if patches.samples is not None:
        samples = [(_unbiased(y, noise.jpeg_errors[i]["bias_patches"], sensor.max_code)
                    if i in noise.jpeg_errors else y, L) for i, (y, L) in zip(lit, patches.samples)]
        cells = None
        if noise.jpeg_errors:                       # each pixel's JPEG coding unit
            unit = block_size(next(iter(noise.jpeg_errors.values()))["settings"])
            ys, xs = np.nonzero(patches.mask)
            cells = (ys // unit) * (patches.mask.shape[1] // unit + 1) + xs // unit
            cells = cells[np.isin(patches.patch, _neutral_labels(o.calibrate))]
        references = neutral = _select(samples, patches.patch, _neutral_labels(o.calibrate))
        per_frame, calibration = calibrate_exposure(
            *neutral, sensor,
            [frames.photos[i] for i in lit], None if rel is None else rel[lit], log, cells,
            [frames.times[i].timestamp() for i in lit])
        # by name, for a fit of the light to recalibrate on (fitting.fit.reference_factor)
        calibration["references"] = {name: [float(v) for v in np.broadcast_to(rho, 3)]
                                     for name, rho in o.calibrate.items()}
        if o.calibrate:
            calibration["reference_relative_sd"] = reference_error(
                o.calibrate, o.reference_sd, log).tolist()
        # the cos^4 falloff where the references lie, from which an uncorrected one's error
        # (--vignetting none) to each region is carried (fitting.uncertainty.vignetting_error)
        h, w = frames.size
        at = np.argwhere(patches.mask)[np.isin(patches.patch, _neutral_labels(o.calibrate))]
        calibration["reference_falloff"] = float(np.mean(SensorModel.falloff(
            w, h, frames.spec.camera["fov_deg"], at[:, ::-1])))
        if patches.response_info is not None:
            calibration["response_fit"] = patches.response_info
        if patches.chart is not None:
            calibration["colorchecker"] = _chart_record(o.colorchecker, patches.chart, samples,
                                                        patches.patch, sensor, per_frame, log)
            log("calibration: the ColorChecker's greys taken at their published reflectances: a "
                "chart departs from them by its batch and age (1-2%), which the intervals leave "
                "out; a grey card of stated error beside it (--calibrate NAME=RHO+-SD) counts it")
        e0 = float(per_frame[0] @ SRGB_LUMINANCE)
        by_frame = {i: per_frame[j] for j, i in enumerate(lit)}
    else:
        e0 = float(patches.given)
        r = np.ones(len(frames.paths)) if rel is None else rel      # one frame: no labels
        by_frame = {i: np.full(3, e0 * r[i]) for i in lit}
        settings = [exif_setting(frames.photos[i].metadata) for i in lit]
        if rel is not None and len(exif_label_loading(exif_setting(frames.photos[0].metadata),
                                                      settings)):
            log(f"exposure: the given {e0:.4g} sr m^2 W^-1 scaled by the frames' EXIF labels "
                f"({len(set(settings))} settings), each label's exposure taken to be off what "
                f"it says by an sd of {EXIF_LABEL_SD:.0%} (the intervals count it); a grey card "
                "(--calibrate) measures them, and the first frame's labels on every frame have "
                "none")
    return Exposures(replace(sensor, exposure=e0), by_frame, calibration, rel,
                     tone_curve_record(frames, sensor, references,
                                       bool((calibration or {}).get("per_frame")), o, log))


def tone_curve_record(frames, sensor, references, per_frame, o, log):
    """The record of the error a camera's own JPEG tone curve leaves
    (:mod:`skyfit_mi.physics.tone_curve`), or None where the codes' curve is known: linear
    (RAW, EXR, linear 16-bit) or said exact (``--exact-curve``); a fitted response's families
    hold no camera's curve. ``references``: the grey references' (samples [(codes (n, 3)
    [DN], rendered radiance (n, 3))] per lit frame, labels (n,)), whose signals anchor the
    curve's error in each frame (``per_frame``: each frame calibrated on its own, else one
    scale for the day, anchored where the frames' mean holds), and, at several levels, measure
    the curve (:func:`~skyfit_mi.physics.tone_curve.fit_references`); None: a given exposure,
    anchored at full scale."""
    if sensor.response == "linear" or o.exact_curve \
            or any(p.kind != "integer" for p in frames.photos):
        return None
    record = {"response": sensor.response, "anchored_at": "full scale",
              "anchor_ln_signal": None, "anchor_basis": None,
              "prior": "skyfit_mi.physics.tone_curve.PRIOR_ROOT (darktable's measured camera "
                       "base curves)"}
    if references is not None:
        samples, patch = references
        labels = np.unique(patch)
        t = np.full((len(samples), 3, len(labels)), np.nan)
        ratio, sd, weight = t.copy(), t.copy(), t.copy()
        for f, (y, L) in enumerate(samples):
            for k, m in enumerate(labels):
                s, r = _signal_ratio(y[patch == m], L[patch == m], sensor)
                with np.errstate(all="ignore"), warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)
                    t[f, :, k] = np.log(central_mean(s))
                    ratio[f, :, k] = np.log(central_mean(r))
                    # as the exposure weighs it (_patch_exposure): pixels x signal^2
                    weight[f, :, k] = np.sum(~np.isnan(r), axis=0) * np.exp(2 * t[f, :, k])
                    lr = np.log(np.where(np.isfinite(r) & (r > 0), r, np.nan))
                    sd[f, :, k] = np.nanstd(lr, axis=0) / np.sqrt(np.sum(np.isfinite(lr), 0))
        weights, root, phi, chi2 = tone_curve.fit_references(
            *(a.reshape(-1, len(labels)) for a in (t, ratio, sd)),
            anchor_weight=weight.reshape(-1, len(labels)))
        phi = phi.reshape(len(samples), 3, -1)
        if not per_frame:                   # one scale for the day: where the frames' mean holds
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                phi = np.broadcast_to(np.nanmean(phi, axis=0), phi.shape)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            level = np.nanmean(t, axis=2)
        record.update(
            anchored_at="references",
            anchor_ln_signal={str(i): [float(v) if np.isfinite(v) else None for v in a]
                              for i, a in zip(frames.lit, level)},
            anchor_basis={str(i): np.where(np.isfinite(a), a, None).tolist()
                          for i, a in zip(frames.lit, phi)})
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            spread = np.nanmedian(np.nanmax(t, axis=2) - np.nanmin(t, axis=2))
        if spread > np.log(TONE_LEVELS_MIN):
            with warnings.catch_warnings():      # the levels of groups that read two or more
                warnings.simplefilter("ignore", RuntimeWarning)
                told = np.where((np.isfinite(t).sum(axis=2) >= 2)[..., None], t, np.nan)
            record.update(weights=weights.tolist(), root=root.tolist(),
                          measured_ln_signal=[float(np.nanmin(told)), float(np.nanmax(told))],
                          references_chi2_per_dof=chi2)
            log(f"encoding: the camera's own tone curve measured on the references' "
                f"{len(labels)} levels (their exposures agree to chi-square {chi2:.2g} per dof "
                "about it): the codes are read through it, and its error left is counted")
            return record
    where = ("each frame's grey references" if references is not None
             else "full scale (the given exposure)")
    log(f"encoding: the codes are read through {sensor.response}'s curve, but a camera's JPEG "
        "engine applies its own tone curve (cameras' measured curves depart from sRGB's by "
        "tens of per cent between a grey card's codes and a white's); its error, calibrated at "
        f"{where}, is counted in the intervals, most for surfaces far darker or brighter than "
        "the references. RAW files (linear), greys of several reflectances (a ColorChecker's), "
        "or --exact-curve (codes written from linear values by software) take it out")
    return record


def _unmix(values, mixing, sensor):
    """Codes ``values`` (H, W, 3) [DN] with the colour matrix's error G = ``mixing``
    (:func:`.colorchecker.matrix_error`) taken out, (I + G)^-1 s; clipped pixels kept."""
    top = sensor.max_code
    ok = np.all(np.isfinite(values) & (values > 0) & (values < top), axis=-1)
    s = sensor.linearise(np.where(ok[..., None], values, 0.0))
    fixed = np.clip(s @ np.linalg.inv(np.eye(3) + np.asarray(mixing, dtype=float)).T, 0.0, 1.0)
    return np.where(ok[..., None], sensor.respond(fixed) * top, values).astype(values.dtype)


def colour_matrix(photos, given, measured=None):
    """The manifest's ``colour_matrix`` record, the relative error of the colour matrix's
    entries: ``given``; else the standard error of a ColorChecker's ``measured`` mixing (the
    frames corrected by it); else :data:`RAW_MATRIX_ERROR` for RAWs; else (or given 0) None."""
    if given is None and measured is not None:
        return {"relative_sd": float(np.sqrt(np.mean(np.square(measured["standard_error"])))),
                "source": "measured on the ColorChecker's chromatic swatches (the frames "
                          "corrected by the mixing found: ingest.calibration.colorchecker."
                          "colour_matrix); its standard error"}
    if given is None and all(p.format == "raw" for p in photos):
        return {"relative_sd": RAW_MATRIX_ERROR,
                "source": "a prior for RAWs developed with their file's colour matrix, "
                          "--colour-matrix-error"}
    if not given:
        return None
    return {"relative_sd": float(given), "source": "given, --colour-matrix-error"}


def _write(out, frames, linear, registration, noise, exposures, options, run_id, progress):
    """Write the sequence folder, each frame resampled onto the reference's pinhole pixels."""
    paths, photos, sensor, rel = frames.paths, frames.photos, exposures.sensor, exposures.rel
    mixing = ((exposures.calibration or {}).get("colorchecker") or {}).get("colour_matrix")
    manifest = measured_header(frames.spec, sensor, run_id, "photographed",
                               "none: frames are photographs")
    manifest["sensor"]["noise_model"] = {**noise.info,
                                         "sigma2_DN2": "Q'(s)^2 (read + shot s M) + 1/12"}
    if linear.flat is not None:
        write_exr(out / "frames" / "flat_field.exr", np.repeat(linear.flat[..., None], 3, axis=2),
                  {"kind": "flat_field", "units": "1"})
        manifest["sensor"]["flat_field"] = "frames/flat_field.exr"
    manifest["ingest"] = {"photos": [p.name for p in paths], "options": options,
                          "float_scale_DN": linear.float_scale,
                          "calibration": exposures.calibration,
                          "colour_matrix": colour_matrix(photos, options["colour_matrix_error"],
                                                         mixing),
                          "relative_exposure_from_exif": None if rel is None else rel.tolist(),
                          "tone_curve": exposures.tone_curve,
                          "registration": registration.record}
    from tqdm import tqdm

    curve = exposures.tone_curve if (exposures.tone_curve or {}).get("weights") else None
    for f, p, photo, v in tqdm(zip(frames.spec.frames, paths, photos, linear.values),
                               total=len(paths), desc="ingest", unit="frame", disable=not progress):
        rec = frame_record(f, 0, out)
        rec.pop("seed")
        rec["photo"] = {"file": p.name, **{k: x for k, x in photo.metadata.items()
                                            if isinstance(x, (str, int, float, type(None)))}}
        if f.skipped:
            rec["status"] = "skipped"
        else:
            e = exposures.by_frame[f.index]
            gain = e[None, None, :] * linear.falloff[..., None]
            frame_jpeg = noise.jpeg_errors.get(f.index)
            if noise.raw is not None:
                var = noise.raw[f.index]["sd"].astype(np.float32) ** 2 + np.float32(1.0 / 12)
                sig = np.where(np.isfinite(v), np.sqrt(var), np.inf).astype(np.float32)
            else:
                sig, edge = pixel_sigma(v, sensor, (noise.a, noise.b), frame_jpeg)
            offset = block_offset(frame_jpeg["settings"].get("orientation", 1), v.shape) \
                if frame_jpeg is not None else None
            v = registration.warp(f.index, v, sensor.max_code)
            sig = registration.sigma(f.index, sig, v)
            moved = registration.frames.get(f.index)
            if moved is not None:
                rec["registration"] = moved
                if offset is not None and moved.get("resampled"):   # the blocks move with it
                    offset = [int(o - round(moved.get(d, 0.0))) % 8
                              for o, d in zip(offset, ("dx_px", "dy_px"))]
            if mixing is not None:
                v = _unmix(v, mixing["mixing"], sensor)
            s = sensor.linearise(np.nan_to_num(v))
            slope = sensor.slope(np.clip(s, 1e-6, 1 - 1e-6)) * sensor.max_code
            moved = 0.0
            if curve is not None:      # read through the curve the references measured
                factor, moved = tone_curve.read_table(
                    s, tone_curve.frame_anchors(curve["anchor_basis"], [f.index])[0],
                    curve["weights"], curve["measured_ln_signal"])
                gain = gain * np.exp(factor)
            radiance = np.where(np.isfinite(v), s / gain, np.nan).astype(np.float32)
            rad_sd = np.where(np.isfinite(v), sig * np.maximum(np.abs(1.0 - moved),
                                                               tone_curve.SLOPE_FLOOR)
                              / (slope * gain), np.inf).astype(np.float32)
            names = write_frame(out, f.index, radiance, rad_sd, v, sig, f.time)
            rec.update(status="rendered", **names,
                       exposure={"exposure": float(e @ SRGB_LUMINANCE),
                                 "white_balance": (e / float(e @ SRGB_LUMINANCE)).tolist(),
                                 **{k: photo.metadata[k] for k in EXPOSURE_KEYS.values()
                                    if photo.metadata.get(k)}})
            if frame_jpeg is not None:
                rec["jpeg_error_DN2"] = np.mean(frame_jpeg["variance"], axis=(0, 1),
                                                 dtype=np.float64).tolist()
                rec["jpeg_block_correlation"] = frame_jpeg["rho"].tolist()
                rec["jpeg_block_offset"] = list(offset)
                rec["jpeg_edge_block_share"] = float(np.mean(edge))
                rec["jpeg_bias_removed_DN"] = frame_jpeg["bias_mean"].tolist()
                rec["jpeg_dc"] = dc_record(frame_jpeg["settings"])
            if noise.raw is not None:
                rec["raw_demosaic"] = {
                    "algorithm": "AHD", "colour_reach_px": RAW_COLOUR_REACH,
                    "noise_correlation": np.round(
                        noise.raw[f.index]["noise_correlation"], 4).tolist(),
                    "channel_correlation": noise.raw[f.index]["channel_correlation"]}
            bad = int(photo.nan_count + photo.inf_count)
            if bad:
                rec["non_finite_values"] = bad
        manifest["frames"].append(rec)
    if noise.raw is not None:
        manifest["sensor"]["noise_model"]["sigma2_DN2"] = (
            "RAWs: the variance of the developed noise by bootstrap (noise_model.raw), + 1/12; "
            "each frame's raw_demosaic.noise_correlation, between pixels up to "
            "colour_reach_px apart, by which a fit widens the sigma of a region's pixels")
    if noise.jpeg_errors:
        manifest["sensor"]["noise_model"]["jpeg"] = {
            "method": "parametric bootstrap: draws of the scene given each frame's DCT "
                      "coefficients, photographed again with fresh sensor noise and the "
                      "frame's own tables; the mean square error over the copies, 3x3 "
                      "averaged; their mean error over each coding unit taken out of the values "
                      "(frame means in jpeg_bias_removed_DN)", "replicates": REPLICATES,
            "seed": [SEED, "frame index"]}
        manifest["sensor"]["noise_model"]["sigma2_DN2"] += (
            "; JPEG frames: the bootstrap's variance, at least the formula of the noise the "
            "frames' neighbouring pixels show (shown_by_the_frames), plus the tables' bound "
            "in blocks holding an edge (share: jpeg_edge_block_share); bootstrap frame means "
            "in jpeg_error_DN2; the errors' correlation within a JPEG block in "
            "jpeg_block_correlation, by which a fit widens the sigma of pixels sharing a block; "
            "the tables' steps of the blocks' means (Y, Cb, Cr) and the chroma's subsampling "
            "in jpeg_dc, from which a fit finds the rounding error a region's blocks share")
    finish(out, manifest, sensor.exposure)
    return manifest

