"""An HDR fisheye series of the sky: exposure brackets merged into linear maps.

A zenith-pointing fisheye beside the scene photographs the sky in a bracket of exposures at each
frame.  :func:`sky_series` merges each bracket into a linear map (OpenEXR, the equidistant
fisheye of :mod:`~skyfit_mi.physics.envmap`) and writes ``sky_series.json``, which a spec's
``envmap`` sky names as its ``file``: each frame is lit by the map nearest its time.

Merging is Debevec-Malik's with the response known: linearised, flat-fielded shots divided by
their exposure H = t S / N^2 are averaged with weight H (inverse variance under shot noise)
where neither clipped (:data:`~skyfit_mi.physics.camera.CLIP_FRACTION`) nor below
:data:`FLOOR_FRACTION`.  Pixels clipped in every shot (the sun) keep the shortest shot's lower
bound; the series recommends a ``sun_mask_deg`` (:func:`clipped_extent`).

Units: W m^-2 sr^-1 through ISO 12232's saturation-based exposure (v at H is
v :data:`SATURATION_LUMINANCE` / H [cd m^-2]) over the clear sky's efficacy
(:data:`~skyfit_mi.physics.sky.EFFICACY_CLEAR`): nominal, right to a factor of about 1.5.  The
sun's level comes from a horizontal grey card of reflectance rho photographed with each bracket:
E = pi L_card / rho (eq. 3.19's diffuse term rho_d / pi), recorded as
``global_horizontal_W_m2``; the envmap sky takes the disc from (E - E_map) / cos theta_s
(:func:`~skyfit_mi.physics.envmap.direct_normal_from_global`).  Keep the card out of your shadow
and away from the sun's mirror direction (not Lambertian there).
"""

from __future__ import annotations

import datetime as dt
import json
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.ndimage import binary_erosion

from ..conventions import angles_from_direction, direction_from_angles
from ..errors import OutputError, SkyfitError
from ..files import check_dir, ensure_dir, write_json
from ..physics.camera import CLIP_FRACTION, SensorModel, clipped
from ..physics import tone_curve
from ..physics.colour import SRGB_LUMINANCE
from ..physics.sky import EFFICACY_CLEAR
from ..render.image import write_exr
from .photo_times import frame_times
from .photos import (EXPOSURE_KEYS, camera_name, check_same_size, exif_exposure, list_photos,
                     read_flat_field, read_photo)

#: Luminance [cd m^-2] saturating a sensor at H = t S / N^2 = 1 [s]: ISO 12232's H_sat = 78 / S
#: [lux s] with the lens and angle factor q = 0.65 (sensor illuminance q L / N^2): 78 / 0.65.
SATURATION_LUMINANCE = 78.0 / 0.65
#: Most pixels across a merged map: ample for a sky table of at most 256 rows
#: (:data:`~skyfit_mi.physics.latlong.MAX_ROWS`); larger shots are binned to it as read.
MAP_PIXELS = 1024
#: A shot whose largest channel is below this fraction of saturation is used only when no
#: brighter unclipped shot exists (quantisation and read noise dominate down there).
FLOOR_FRACTION = 0.02
#: Shots more than this many seconds after the previous one start a new bracket (default).
BRACKET_GAP_S = 30.0
#: The grey card's reflectance (default): a photographer's 18% card.
CARD_REFLECTANCE = 0.18
#: A card shot is paired with a bracket within this many seconds at most (default).
CARD_MAX_GAP_S = 300.0
#: Default relative sd (of the log) of a grey card's global horizontal irradiance: reflectance
#: known to 1-2%, a few per cent off Lambert's law.  The sun's share E - E_map carries it
#: magnified by E / (E - E_map): the map's ``sun_sd``.
CARD_SD = 0.02
#: The sun's share of the card's irradiance below which its uncertainty stops growing.
SUN_SHARE_FLOOR = 0.05
#: Largest 10-90% range of a card box's luminance over its median: an evenly lit card's varies
#: by its noise and texture (a few per cent), a box reaching shade or off the card by far more.
CARD_UNIFORMITY = 0.1
#: Pixels a side of the bins whose spread it measures (a 4% noise per pixel is 1% per bin).
UNIFORM_BIN = 4
#: Pixels usable in two shots at least, for their agreement to be measured.
AGREEMENT_PIXELS = 20
#: Largest departure of two shots' agreement from 1 before the series warns.
AGREEMENT_TOL = 0.03
#: Pixels of a bracket the camera's tone curve is measured on at most (:func:`bracket_curve`).
CURVE_SAMPLES = 4000
#: The highest signal [fraction of full scale] a value the curve is measured on may have: a
#: JPEG's codes just below clipping are pulled down by the clipped noise and the ringing of
#: blocks that hold clipped pixels (the sun's aureole).
CURVE_TOP = 0.8
#: Pixels [binned] a value the curve is measured on keeps from any clipped or dark one (the
#: sun, the black beyond the horizon): a JPEG mixes codes over its 8-16 pixel blocks, and a mix
#: of codes read through a curve bends as a tone curve would.
CURVE_MARGIN = 8
#: The relative error [unitless] of one value's ln in that measurement: a JPEG's rounding and
#: noise near FLOOR_FRACTION, 1% (fit_references floors it at the references' 1.5% and widens
#: it by the fit's chi-square).
CURVE_SD = 0.01
#: The recommended sun mask reaches this far beyond the clipped pixels [degrees].
MASK_MARGIN_DEG = 1.0
#: Clipped pixels farther than this from the clipped centre are not the sun's [degrees].
SUN_CLIP_MAX_DEG = 15.0
#: A frame takes the map nearest its time within this many seconds at most.
MAP_MAX_GAP_S = 300.0
SERIES_NAME = "sky_series.json"


@dataclass(frozen=True)
class Shot:
    """One photograph of a series: its linear values (H, W, 3) as a fraction of saturation,
    which of its pixels are clipped (H, W), its exposure t S / N^2 [s], its time, its
    camera's EXIF make and model ('' if not given), the flat field its values were divided by,
    and whether its codes were read through a curve (8-bit JPEGs: a camera's own tone curve)."""

    path: Path
    linear: np.ndarray
    clipped: np.ndarray
    floor: np.ndarray
    exposure: float
    time: dt.datetime
    camera: str = ""
    flat: object = 1.0          # the flat field (binned) its linear values were divided by
    curved: bool = False        # integer codes read through a curve (a camera's own may bend)


def _exposure(photo):
    """t S / N^2 [s] of ``photo`` from its EXIF; SkyfitError naming what is missing."""
    h = exif_exposure(photo)
    if h is None:
        missing = [name for name, key in EXPOSURE_KEYS.items() if not photo.metadata.get(key)]
        raise SkyfitError(f"{Path(photo.path).name}: no EXIF {', '.join(missing)}; a bracket "
                          "is merged by its shots' exposures, so keep the camera's EXIF.")
    return h


def _blocks(a, b, reduce):
    """``a`` (H, W, ...) reduced over b x b blocks by ``reduce``, cropped evenly to whole blocks."""
    if b == 1:
        return a
    h, w = (n // b * b for n in a.shape[:2])
    y0, x0 = (a.shape[0] - h) // 2, (a.shape[1] - w) // 2
    a = a[y0:y0 + h, x0:x0 + w]
    return reduce(a.reshape(h // b, b, w // b, b, *a.shape[2:]), axis=(1, 3))


def _linear(photo):
    """A photograph's linear values (H, W, 3) as a fraction of saturation and its clipped pixels
    (H, W); SkyfitError for floats (a merged map: the spec reads it as it is)."""
    if photo.kind == "float":
        raise SkyfitError(f"{Path(photo.path).name} holds linear floats, a map merged already; "
                          "name it in the spec's envmap sky as it is (docs/cli.md), or give "
                          "the bracket's camera shots.")
    sensor = SensorModel(1.0, response=photo.encoding_hint, bits=photo.bits)
    table = sensor.linearise(np.arange(photo.max_code + 1)).astype(np.float32)
    codes = np.rint(photo.values).astype(np.uint16)     # whole codes (exact_jpeg=False)
    return table[codes], clipped(codes, photo.max_code).any(axis=2)


def _check_box(box, photo):
    """SkyfitError unless the card's ``box`` lies within ``photo``."""
    x0, y0, x1, y1 = box
    if not (x0 < x1 and y0 < y1):
        raise SkyfitError(f"--card-box {x0},{y0},{x1},{y1}: give the card's corners as "
                          "X0,Y0,X1,Y1 with X0 < X1 and Y0 < Y1 (top left, then bottom right).")
    if not (0 <= x0 < x1 <= photo.width and 0 <= y0 < y1 <= photo.height):
        raise SkyfitError(f"--card-box {x0},{y0},{x1},{y1} leaves {Path(photo.path).name} "
                          f"({photo.width}x{photo.height}); give the card's pixels as "
                          "X0,Y0,X1,Y1 within the image.")


def _check_uniform(path, linear, clipped):
    """SkyfitError where a card box's unclipped pixels, in :data:`UNIFORM_BIN` square bins,
    vary in luminance by over :data:`CARD_UNIFORMITY` (their 10-90% range over their median):
    part of it in shade or off the card."""
    lum = np.where(clipped.any(axis=-1), np.nan, linear @ SRGB_LUMINANCE)
    if min(lum.shape) >= 2 * UNIFORM_BIN:          # binned: a noisy card's pixels average out
        h, w = (n // UNIFORM_BIN * UNIFORM_BIN for n in lum.shape)
        lum = lum[:h, :w].reshape(h // UNIFORM_BIN, UNIFORM_BIN, w // UNIFORM_BIN,
                                  UNIFORM_BIN).mean(axis=(1, 3))
    lum = lum[np.isfinite(lum)]
    if lum.size < 4:
        return
    lo, mid, hi = np.percentile(lum, [10, 50, 90])
    if mid > 0 and (hi - lo) / mid > CARD_UNIFORMITY:
        raise SkyfitError(f"{path.name}: the pixels inside --card-box vary by "
                          f"{100 * (hi - lo) / mid:.0f}% (their 10-90% range over the median): "
                          "part of the box is in shade, off the card or on a highlight; draw "
                          "it inside the card's evenly lit part.")


def read_shots(items, tz=None, times_csv=None, flat=None, box=None):
    """The :class:`Shot` of every photograph in ``items`` in time order (EXIF or ``times_csv``
    times).  Sky shots are flat-fielded by ``flat`` and binned to :data:`MAP_PIXELS`; card shots
    keep only ``box``'s mean (1, 1, 3).  SkyfitError for an unusable file or box."""
    paths = list_photos(items)
    if not paths:
        raise SkyfitError(f"no photographs in {', '.join(map(str, items))}.")
    kept, metas, shapes, response, binned, b = [], [], {}, 1.0, 1.0, 1
    for path in paths:
        photo = read_photo(path, exact_jpeg=False)        # averaged: libjpeg's codes suffice
        shapes[path] = (photo.height, photo.width, photo.metadata.get("orientation", 1))
        check_same_size(shapes)
        linear, clipped = _linear(photo)
        if box is not None:
            _check_box(box, photo)
            x0, y0, x1, y1 = box
            _check_uniform(path, linear[y0:y1, x0:x1], clipped[y0:y1, x0:x1])
            linear = linear[y0:y1, x0:x1].mean(axis=(0, 1), keepdims=True)
            clipped = clipped[y0:y1, x0:x1].any(keepdims=True)
            floor = linear.max(axis=2) < FLOOR_FRACTION
        else:
            if not kept:
                response = 1.0 if flat is None else \
                    read_flat_field(flat, (photo.height, photo.width))[..., None]
                b = max(1, -(-min(photo.height, photo.width) // MAP_PIXELS))
                binned = response if np.ndim(response) == 0 else _blocks(response, b, np.mean)
            floor = _blocks(linear.max(axis=2), b, np.mean) < FLOOR_FRACTION
            linear, clipped = _blocks(linear / response, b, np.mean), _blocks(clipped, b, np.any)
        curved = photo.kind == "integer" and photo.encoding_hint != "linear"
        kept.append((path, linear.astype(np.float32), clipped, floor, _exposure(photo),
                     1.0 if box is not None else binned, curved))
        metas.append(photo.metadata)
        del photo
    times = frame_times(paths, metas, times_csv=times_csv, tz=tz, warn=lambda message: None)
    cameras = [camera_name(m) for m in metas]
    shots = sorted((Shot(*k[:4], exposure=k[4], time=t, camera=c, flat=k[5], curved=k[6])
                    for k, t, c in zip(kept, times, cameras)),
                   key=lambda s: (s.time, s.path.name))         # a bracket shares a second
    for a, b in zip(shots, shots[1:]):
        if a.time == b.time and np.isclose(a.exposure, b.exposure, rtol=0.01):
            raise SkyfitError(f"{a.path.name} and {b.path.name} are one shot twice (the same "
                              f"time, {a.time.isoformat()}, and exposure): remove the copy.")
    return shots


def brackets(shots, gap_s=BRACKET_GAP_S):
    """``shots`` (in time order) split where one follows the previous by more than ``gap_s``,
    or repeats an exposure of the bracket so far (a time-lapse, not a bracket)."""
    out = []
    for s in shots:
        if out and (s.time - out[-1][-1].time).total_seconds() <= gap_s \
                and all(not np.isclose(s.exposure, o.exposure, rtol=0.01) for o in out[-1]):
            out[-1].append(s)
        else:
            out.append([s])
    return out


def bracket_curve(groups, seed=0):
    """A camera's own tone curve (:mod:`~skyfit_mi.physics.tone_curve`) measured on the
    brackets ``groups``' overlaps: a pixel unclipped and above the floor in two shots or more
    reads ln(v / H) = ln L + d(ln s) in each (s its signal before the flat field, d the curve's
    departure, 0 at full scale), L profiled per pixel and channel
    (:func:`~skyfit_mi.physics.tone_curve.fit_references`, a seeded sample of at most
    :data:`CURVE_SAMPLES` pixels a bracket). Returns {weights, root, chi2_per_dof,
    measured_ln_signal, values} or None where no bracket of curved shots overlaps."""
    rng = np.random.default_rng(seed)
    width = max(len(g) for g in groups)
    ts, rs = [], []
    for group in groups:
        if len(group) < 2 or not all(s.curved for s in group):
            continue
        use = np.stack([binary_erosion(~s.clipped & ~s.floor, iterations=CURVE_MARGIN).ravel()
                        for s in group], axis=1)                                  # (N, k)
        idx = np.flatnonzero(use.sum(axis=1) >= 2)
        idx = np.sort(rng.choice(idx, min(len(idx), CURVE_SAMPLES), replace=False))
        sig = np.stack([(s.linear * s.flat).reshape(-1, 3)[idx] for s in group], axis=1)
        lin = np.stack([s.linear.reshape(-1, 3)[idx] / s.exposure for s in group], axis=1)
        ok = use[idx][..., None] & (sig >= FLOOR_FRACTION) & (sig < CURVE_TOP)      # (n, k, 3)
        with np.errstate(all="ignore"):
            t = np.where(ok, np.log(sig), np.nan)
            r = np.where(ok, np.log(lin), np.nan)
        pad = ((0, 0), (0, width - len(group)))
        ts.append(np.pad(np.moveaxis(t, 2, 1).reshape(-1, len(group)), pad,
                         constant_values=np.nan))
        rs.append(np.pad(np.moveaxis(r, 2, 1).reshape(-1, len(group)), pad,
                         constant_values=np.nan))
    if not ts:
        return None
    t, r = np.concatenate(ts), np.concatenate(rs)
    pairs = np.isfinite(t).sum(axis=1) >= 2                   # a pixel seen in two shots or more
    if not pairs.any():
        return None
    t, r = t[pairs], r[pairs]
    weights, root, _, chi2 = tone_curve.fit_references(t, r, np.full(t.shape, CURVE_SD))
    return {"weights": weights.tolist(), "root": root.tolist(), "chi2_per_dof": chi2,
            "measured_ln_signal": [float(np.nanmin(t)), float(np.nanmax(t))],
            "values": int(np.isfinite(t).sum())}


def read_through(shots, curve):
    """``shots`` with their curved ones' values read through the measured ``curve``
    (:func:`bracket_curve`), in place: v exp(-d(ln s)), s the signal before the flat field,
    taken to the nearest measured level beyond them
    (:func:`~skyfit_mi.physics.tone_curve.read_table`, anchored at full scale)."""
    full_scale = np.zeros((3, tone_curve.DEGREE))
    for s in shots:
        if s.curved:
            factor, _ = tone_curve.read_table(s.linear * s.flat, full_scale, curve["weights"],
                                              curve["measured_ln_signal"])
            np.multiply(s.linear, np.exp(-factor), out=s.linear)
    return shots


def merge(bracket):
    """The merged map (H, W, 3) of a ``bracket`` [linear / (t S / N^2)], and where all clip."""
    by_exposure = sorted(bracket, key=lambda s: s.exposure)
    num = np.zeros(bracket[0].linear.shape, np.float64)
    den = np.zeros(bracket[0].linear.shape[:2], np.float64)
    longest = np.full(den.shape, -1)
    for i, s in enumerate(by_exposure):
        use = ~s.clipped & ~s.floor
        num += np.where(use[..., None], s.linear, 0.0)       # (v / H) weighted by H
        den += np.where(use, s.exposure, 0.0)
        longest = np.where(~s.clipped, i, longest)
    merged = num / np.maximum(den, 1e-300)[..., None]
    dark = (den == 0) & (longest >= 0)
    for i, s in enumerate(by_exposure):
        pick = dark & (longest == i)
        merged[pick] = s.linear[pick] / s.exposure
    clipped = longest < 0
    shortest = by_exposure[0]
    merged[clipped] = shortest.linear[clipped] / shortest.exposure
    return merged, clipped


def agreement(bracket):
    """Per adjacent-exposure pair of ``bracket``, the median ratio of their luminance per unit
    exposure over pixels usable in both (1 if response and EXIF are right; None if none)."""
    by_exposure = sorted(bracket, key=lambda s: s.exposure)
    out = []
    for a, b in zip(by_exposure, by_exposure[1:]):
        both = ~a.clipped & ~a.floor & ~b.clipped & ~b.floor
        la, lb = (s.linear[both] @ SRGB_LUMINANCE / s.exposure for s in (a, b))
        ok = la > 0
        out.append(float(np.median(lb[ok] / la[ok])) if ok.sum() >= AGREEMENT_PIXELS else None)
    return out


def _fisheye_grid(height, width):
    """A fisheye frame's pixel centres from its centre, left and up [px] (H, W) each, their
    radius r and the horizon's R = half the shorter side, and each one's equidistant zenith
    theta = r / R 90 deg [rad]."""
    R = min(height, width) / 2.0
    y, x = np.mgrid[0:height, 0:width] + 0.5
    dx, dy = width / 2.0 - x, height / 2.0 - y
    r = np.hypot(dx, dy)
    return dx, dy, r, R, np.minimum(r / R, 1.0) * np.pi / 2


def fisheye_directions(height, width, north_rotation_deg=0.0):
    """World directions (H, W, 3) of an equidistant fisheye's pixel centres (the image's top at
    azimuth ``north_rotation_deg``), and the mask of pixels within the horizon's circle."""
    dx, dy, r, R, theta = _fisheye_grid(height, width)
    phi = np.arctan2(dx, dy) + np.radians(north_rotation_deg)
    return direction_from_angles(theta, phi), r <= R


#: The fisheye projections a series takes: r / R = theta / 90 deg (equidistant, the maps'), or
#: sqrt(2) sin(theta / 2) (equisolid: equal areas, many circular fisheyes), R the horizon's.
LENSES = ("equidistant", "equisolid")


def to_equidistant(merged, clipped, lens):
    """A merged map (H, W, 3) and its clipped pixels (H, W) taken through ``lens`` (one of
    :data:`LENSES`) resampled onto the equidistant fisheye of :func:`fisheye_directions`
    (bilinear; the clipped mask by nearest pixel); unchanged for an equidistant lens."""
    if lens == "equidistant":
        return merged, clipped
    from scipy.ndimage import map_coordinates

    h, w = clipped.shape
    dx, dy, r, R, theta = _fisheye_grid(h, w)
    scale = np.where(r > 0, R * np.sqrt(2.0) * np.sin(theta / 2) / np.maximum(r, 1e-12), 1.0)
    scale = np.where(r <= R, scale, 1.0)                     # beyond the horizon: as it is
    at = [h / 2.0 - dy * scale - 0.5, w / 2.0 - dx * scale - 0.5]
    out = np.stack([map_coordinates(merged[..., c], at, order=1, mode="nearest")
                    for c in range(merged.shape[-1])], axis=-1)
    return out, map_coordinates(clipped.astype(np.uint8), at, order=0, mode="nearest") > 0


def clipped_extent(clipped, merged):
    """(angle [deg] from the clipped pixels' centre to the farthest within
    :data:`SUN_CLIP_MAX_DEG`, count of clipped pixels beyond, the centre's [zenith, azimuth]
    [deg] in the image's frame (its top at azimuth 0)) of a fisheye map; (0, 0, None) if none."""
    if not clipped.any():
        return 0.0, 0, None
    d, inside = fisheye_directions(*clipped.shape)
    c = clipped & inside
    if not c.any():
        return 0.0, 0, None
    w = merged[c] @ SRGB_LUMINANCE
    centre = (d[c] * np.maximum(w, 1e-30)[:, None]).sum(0)
    centre /= np.linalg.norm(centre)
    angle = np.degrees(np.arccos(np.clip(d[c] @ centre, -1.0, 1.0)))
    near = angle <= SUN_CLIP_MAX_DEG
    zenith, azimuth = np.degrees(angles_from_direction(centre))
    return (float(angle[near].max()) if near.any() else 0.0, int((~near).sum()),
            [round(float(zenith), 3), round(float(azimuth), 3)])


def map_irradiance(merged, clipped):
    """Horizontal irradiance (luminance) of an equidistant fisheye map, clipped pixels left out:
    sum L cos theta d omega, d omega = sin theta / r (pi / 2R) (r, R [px] from the centre)."""
    h, w = clipped.shape
    d, inside = fisheye_directions(h, w)
    theta = np.arccos(np.clip(d[..., 2], -1.0, 1.0))
    r = theta / (np.pi / 2) * (min(h, w) / 2.0)
    omega = np.sin(theta) / np.maximum(r, 1e-9) * np.pi / min(h, w)
    use = inside & ~clipped
    return float(((merged[use] @ SRGB_LUMINANCE) * d[use][:, 2] * omega[use]).sum())


def card_irradiance(shots, reflectance):
    """(time, global horizontal irradiance pi L / ``reflectance`` [W m^-2]) of each usable card
    shot; SkyfitError when none is usable."""
    out = []
    for s in shots:
        if s.clipped.any() or s.floor.any():
            continue
        lum = float(s.linear[0, 0] @ SRGB_LUMINANCE)
        radiance = lum * SATURATION_LUMINANCE / s.exposure / EFFICACY_CLEAR
        out.append((s.time, float(np.pi * radiance / reflectance)))
    if not out:
        raise SkyfitError(f"the card clips or is too dark inside --card-box in all of its "
                          f"{len(shots)} shots; expose it between {100 * FLOOR_FRACTION:g}% "
                          f"and {100 * CLIP_FRACTION:g}% of full scale.")
    return out


def _nearest(times, t):
    """The index of the aware datetime in ``times`` nearest ``t``, and its distance [s]."""
    gaps = [abs((c - t).total_seconds()) for c in times]
    i = int(np.argmin(gaps))
    return i, gaps[i]


def _card_at(readings, t, max_gap_s):
    """The card reading nearest ``t`` within ``max_gap_s`` and its distance [s], or SkyfitError."""
    i, gap = _nearest([c for c, _ in readings], t)
    if gap > max_gap_s:
        raise SkyfitError(f"the bracket at {t.isoformat()} has no card shot within "
                          f"{max_gap_s:g} s (nearest {gap:.0f} s away); photograph the card "
                          "with every bracket, or raise --card-max-gap-s.")
    return readings[i][1], gap


@dataclass(frozen=True)
class CardOptions:
    """A grey card photographed with each bracket: shots, box (x0, y0, x1, y1) [pixels],
    reflectance, longest gap to a bracket [s], relative sd of its global irradiance."""

    photos: tuple
    box: tuple
    reflectance: float = CARD_REFLECTANCE
    max_gap_s: float = CARD_MAX_GAP_S
    sd: float = CARD_SD


def _check_options(card, gap_s):
    """SkyfitError in one line for options out of their range."""
    if not 0.0 < gap_s <= 3600.0:
        raise SkyfitError(f"--bracket-gap-s {gap_s:g} must lie in (0, 3600] seconds.")
    if card is None:
        return
    if not 0.01 <= card.reflectance <= 1.0:
        raise SkyfitError(f"--card-reflectance {card.reflectance:g} must lie in [0.01, 1].")
    if not 0.0 < card.sd <= 1.0:
        raise SkyfitError(f"--card-sd {card.sd:g} must lie in (0, 1] (a relative uncertainty).")
    if not 0.0 < card.max_gap_s <= 86400.0:
        raise SkyfitError(f"--card-max-gap-s {card.max_gap_s:g} must lie in (0, 86400] seconds.")


def _card_entry(readings, t, image, clipped, card, name, log):
    """The card's fields of a map's entry: its global horizontal irradiance, the map's own and
    the sun's sd.  Where the map clips no sun and the card reads the sky's own irradiance within
    3 of its sds, the sun was behind cloud (``sun_hidden``: no disc, said); SkyfitError where
    it read less than the sky alone gives (in shade)."""
    ghi, gap = _card_at(readings, t, card.max_gap_s)
    e_map = map_irradiance(image, clipped)
    hidden = not clipped.any() and ghi > e_map * (1.0 - 3.0 * card.sd)
    if ghi <= e_map and not hidden:
        raise SkyfitError(f"{name}: the card's global irradiance ({ghi:.4g}) is below the sky's "
                          f"own ({e_map:.4g}): the card was in shade"
                          + (" while the map shows the sun (clipped)" if clipped.any() else
                             f" (by over 3 of its sds, {card.sd:.0%})")
                          + "; photograph it in the sun.")
    if ghi <= e_map:
        log(f"{name}: the card reads the sky's own irradiance ({ghi:.4g} against {e_map:.4g}, "
            "within its uncertainty) and the map clips no sun: the sun was behind cloud, so the "
            "map has no sun's disc")
        return {"card_gap_s": gap, "global_horizontal_W_m2": ghi, "map_horizontal_W_m2": e_map,
                "sun_hidden": True}
    return {"card_gap_s": gap, "global_horizontal_W_m2": ghi, "map_horizontal_W_m2": e_map,
            "sun_sd": card.sd * ghi / max(ghi - e_map, SUN_SHARE_FLOOR * ghi)}


@dataclass(frozen=True)
class ShotOptions:
    """How the sky's camera reads: ``flat`` its lens's flat field (None: none), undoing the
    sky's vignetting (not the card's: keep its box central); ``lens`` its projection
    (:data:`LENSES`; the maps are equidistant); ``exact_curve``: its integer codes follow their
    stated curve exactly (written from linear values by software), else they are read through
    the camera's own tone curve measured on the brackets' overlaps (:func:`bracket_curve`)."""

    flat: object = None
    lens: str = "equidistant"
    exact_curve: bool = False


def sky_series(items, out_dir, *, card=None, tz=None, times_csv=None, shots=ShotOptions(),
               gap_s=BRACKET_GAP_S, overwrite=False, log=print):
    """Merge the bracketed fisheye shots ``items`` into ``out_dir``: one EXR per bracket and
    :data:`SERIES_NAME`; returns the series document.  ``card`` (:class:`CardOptions`) gives
    each map its global irradiance; ``shots`` (:class:`ShotOptions`) how the camera reads. A
    refusal leaves nothing; ``overwrite`` removes the replaced maps."""
    options, flat, lens = shots, shots.flat, shots.lens
    _check_options(card, gap_s)
    if lens not in LENSES:
        raise SkyfitError(f"--lens {lens}: give one of {', '.join(LENSES)} (the fisheye's "
                          "projection; remap others to equidistant first).")
    out = check_dir(out_dir)
    old = out / SERIES_NAME
    if old.exists() and not overwrite:
        raise OutputError(f"{str(old)!r} exists; give another -o, or --overwrite to replace the "
                          "series.")
    if card is not None:
        both = sorted({p.resolve() for p in list_photos(items)}
                      & {p.resolve() for p in list_photos(card.photos)})
        if both:
            raise SkyfitError(f"{both[0].name}: given both as a sky shot and as a card shot; "
                              "put the card's shots in a folder of their own (--card).")
    shots = read_shots(items, tz, times_csv, flat)
    curve = None if options.exact_curve else bracket_curve(brackets(shots, gap_s))
    if curve is None and not options.exact_curve and any(s.curved for s in shots):
        log("the shots' codes are read through their files' stated curve alone: no two shots of "
            "a bracket both expose a pixel, which a camera's own tone curve is measured on "
            "(bracket each exposure with others two stops apart)")
    if curve is not None:
        shots = read_through(shots, curve)
        log(f"the camera's own tone curve measured on the brackets' overlaps "
            f"({curve['values']} values, chi-square {curve['chi2_per_dof']:.2g} per dof): the "
            "shots are read through it, not through their files' stated curve alone")
    groups = brackets(shots, gap_s)
    readings = None
    if card is not None:
        card_shots = read_shots(card.photos, tz, times_csv, box=card.box)
        sky_cams, card_cams = ({s.camera for s in x if s.camera} for x in (shots, card_shots))
        if sky_cams and card_cams and sky_cams != card_cams:
            log(f"the card's shots are from {', '.join(sorted(card_cams))}, the sky's from "
                f"{', '.join(sorted(sky_cams))}: the sun's level rests on their ISO speeds "
                "agreeing, which cameras' often do not (by up to a third); shoot the card with "
                "the sky's camera")
        elif curve is not None:                 # the sky's camera: its curve
            card_shots = read_through(card_shots, curve)
        readings = card_irradiance(card_shots, card.reflectance)
    created = not out.exists()
    ensure_dir(out)
    work = Path(tempfile.mkdtemp(prefix=".sky_series.", dir=out))
    done = False
    try:
        entries, radius = [], 0.0
        for n, group in enumerate(groups):
            merged, clipped = to_equidistant(*merge(group), lens)
            image = merged * (SATURATION_LUMINANCE / EFFICACY_CLEAR)
            t = group[len(group) // 2].time
            name = f"sky_{t:%Y%m%d_%H%M%S}.exr"
            e = {"time": t.isoformat(), "file": name, "shots": [s.path.name for s in group],
                 "exposures": [s.exposure for s in group], "clipped_pixels": int(clipped.sum())}
            e["clipped_radius_deg"], e["clipped_elsewhere"], e["clipped_centre_deg"] = \
                clipped_extent(clipped, merged)
            e["shot_agreement"] = agreement(group)
            off = [a for a in e["shot_agreement"] if a is not None and abs(a - 1) > AGREEMENT_TOL]
            if off:
                log(f"{name}: shots of adjacent exposure disagree by up to "
                    f"{100 * max(abs(a - 1) for a in off):.0f}% where both are exposed: the "
                    "camera's response is not the one its files state (a JPEG tone curve: "
                    "shoot RAW), or its EXIF exposures are nominal")
            radius = max(radius, e["clipped_radius_deg"])
            if readings is not None:
                e.update(_card_entry(readings, t, image, clipped, card, name, log))
            write_exr(work / name, image, {"time": t, "kind": "sky", "units": "W m^-2 sr^-1",
                                           "shots": len(group)})
            entries.append(e)
            if e["clipped_elsewhere"]:
                log(f"{name}: {e['clipped_elsewhere']} pixels clip more than "
                    f"{SUN_CLIP_MAX_DEG:g} deg from the sun in every shot; add a shorter "
                    "exposure to the bracket")
            log(f"[{n + 1}/{len(groups)}] {name}: {len(group)} shots, "
                f"{e['clipped_pixels']} pixels clipped in all")
        stale = _series_maps(old) - {e["file"] for e in entries} if old.exists() else set()
        for e in entries:
            os.replace(work / e["file"], out / e["file"])
        done = True
    finally:
        shutil.rmtree(work if done or not created else out, ignore_errors=True)
    doc = {"kind": "sky_series", "projection": "fisheye", "lens": lens,
           "units": "W m^-2 sr^-1",
           "flat_field": None if flat is None else str(flat),
           "exposure": "H = t S / N^2 [s] (EXIF exposure time, ISO speed, f-number)",
           "scale_source": "the exposure equation of a saturation-based ISO speed (ISO 12232), "
                           "nominal: within a factor of about 1.5",
           "sun_mask_deg": round(radius + MASK_MARGIN_DEG, 1) if radius else None,
           "bracket_gap_s": gap_s,
           "tone_curve": None if curve is None else {
               **curve, "meaning": "a camera's own tone curve (skyfit_mi.physics.tone_curve: "
                                   "weights of PRIOR_ROOT's columns, root their posterior's) "
                                   "measured on the brackets' overlaps, the shots read through "
                                   "it; beyond measured_ln_signal at its nearest level"},
           "maps": entries}
    if card is not None:
        doc["card"] = {"reflectance": card.reflectance, "box": list(card.box),
                       "shots": len(readings), "max_gap_s": card.max_gap_s, "sd": card.sd}
    write_json(out / SERIES_NAME, doc)
    for name in stale:
        (out / name).unlink(missing_ok=True)
    return doc


def _series_maps(path):
    """The map files a series file names (none when it cannot be read)."""
    try:
        return {Path(e["file"]).name for e in json.loads(Path(path).read_text())["maps"]}
    except (OSError, ValueError, KeyError, TypeError):
        return set()


def series_entry(path, time):
    """The entry of series file ``path`` nearest ``time`` (aware), and the series document;
    SkyfitError if it is not a series or no map lies within :data:`MAP_MAX_GAP_S`."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise SkyfitError(f"{path}: not a sky series ({type(exc).__name__}); make it with "
                          "`skyfit sky-series`.") from None
    if not isinstance(doc, dict) or doc.get("kind") != "sky_series" or not doc.get("maps"):
        raise SkyfitError(f"{path}: not a sky series with maps; make it with `skyfit sky-series`.")
    times = []
    for k, e in enumerate(doc["maps"]):
        try:
            t = dt.datetime.fromisoformat(e["time"])
            if t.utcoffset() is None or not isinstance(e["file"], str):
                raise ValueError
        except (TypeError, KeyError, ValueError):
            raise SkyfitError(f"{path}: map {k} needs a 'file' and a 'time' in ISO 8601 with its "
                              "offset (e.g. 2013-05-27T10:00:00-04:00); repair it, or make the "
                              "series again.") from None
        times.append(t)
    i, gap = _nearest(times, time)
    if gap > MAP_MAX_GAP_S:
        raise SkyfitError(f"{path}: no sky map within {MAP_MAX_GAP_S:g} s of the frame at "
                          f"{time.isoformat()} (nearest {gap:.0f} s away); photograph the "
                          "sky with every frame.")
    return doc["maps"][i], doc
