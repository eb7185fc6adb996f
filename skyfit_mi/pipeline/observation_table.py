"""Observations without images: a table of measured radiances becomes a sequence folder.

A spectroradiometer or luminance meter aimed at a sample, or another program's radiances, give
values, not photographs.  ``skyfit ingest SPEC --table OBS.csv -o DIR`` takes such a table with
the spec (its ``[time]`` replaced by the table's times) and writes a sequence whose frames'
observations are the table: ``fit`` fits its regions as image regions, unrendered.  Lab lights
(one directional ``[[sky]]`` each, no ``[time]``) are named by the ``frame`` column.

The table (CSV, header names in any order, case ignored):

===========================  ==================================================================
column                       meaning
===========================  ==================================================================
``time``                     ISO 8601 date-time; with an offset, or naive with ``--tz``
``frame``                    instead of ``time``, for lab lights: 0-based index in ``[[sky]]``
``region``                   the scene material the point lies on (a ``ward`` material id)
``point``                    optional: the point's name within its region (default the region's)
``x``, ``y``, ``z``          optional: the point, world frame [scene units]; default: where the
                             camera's central ray meets the region's surface
``view_x``.. ``view_z``      optional: unit vector toward the instrument (+X east, +Y north, +Z
                             up), or ``view_zenith_deg``, ``view_azimuth_deg``; default: camera
``normal_x``.. ``normal_z``  optional: the expected surface normal; one unlike the scene's: refused
``r``, ``g``, ``b``          the measured radiance, linear sRGB [W m^-2 sr^-1]
``sigma_r``.. ``sigma_b``    its standard deviation [W m^-2 sr^-1]; or one ``sigma`` for all
``luminance``                instead of r, g, b: Y = 0.2126 R + 0.7152 G + 0.0722 B
                             [W m^-2 sr^-1] (cd m^-2 over the sky's luminous efficacy, e.g. the
                             spec's ``efficacy_clear``), with ``sigma``
``saturated``                optional, 0 or 1 (or ``saturated_r``.. ``saturated_b``): the value
                             is the level the instrument clipped at; the true one is at or above
===========================  ==================================================================

A point keeps its position; its view may change from row to row (a goniometer).  Values go on a
linear 16-bit scale (the brightest plus 5 sigma at half scale), so chi-square is eq. 6.2 in the
table's units; values at or below zero are censored at zero, saturated ones at their level
(:func:`skyfit_mi.fitting.chi2.load_table_observations`), values beyond :data:`MAX_RADIANCE`
refused.  A luminance table (:class:`~skyfit_mi.fitting.chi2.LuminanceModel`) cannot tell
colour: only the 2- and 3-parameter models take it.  Instrument units are scaled by references
(:func:`reference_scale`) or put on a relative scale (:func:`unknown_scale`).
"""

import csv
import hashlib
import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import SkyfitError
from ..files import FolderLock, write_text
from ..physics.camera import SensorModel
from ..physics.colour import SRGB_LUMINANCE
from ..physics.sun import SOLAR_CONSTANT, SUN_SOLID_ANGLE
from ..conventions import direction_from_angles
from ..render.light_cache import POINT_POSITIONS, point_rays
from ..render.points import lambertian_radiance, load_points_scene, surface_hits
from ..render.scene_xml import build_scene_xml
from .ingest import measured_header, reference_error, spec_for_times
from .manifest import frame_label
from .photo_times import _iso, localize, parse_tz
from .sequence import finish, frame_record, prepare_folder
from .spec import load_spec, read_spec

#: File name of the normalised table in a sequence folder.
TABLE_FILE = "observations.csv"
#: Largest angle [deg] between a given normal and the scene's at the point.
NORMAL_TOLERANCE_DEG = 5.0
#: Ray start off the surface, as a share of the scene's bounding-box diagonal.
RAY_OFFSET = 1e-4
#: The least sigma a value may carry, relative to it: a table's 1e-6 on values of 30 crashed the
#: fit's censored terms (0/0); instruments measure to 1e-3 at best.
SIGMA_FLOOR = 1e-5
#: Largest radiance, value or sigma, a table may give [W m^-2 sr^-1]: ten times the solar
#: disc's above the atmosphere (no surface reflects more than its brightest source).
MAX_RADIANCE = 10.0 * SOLAR_CONSTANT / SUN_SOLID_ANGLE
#: Share of the 16-bit full scale that the brightest value plus HEADROOM_SIGMAS sigma takes.
SCALE_SHARE, HEADROOM_SIGMAS = 0.5, 5.0

_VECTORS = {"x": ("x", "y", "z"), "view": ("view_x", "view_y", "view_z"),
            "normal": ("normal_x", "normal_y", "normal_z"), "value": ("r", "g", "b"),
            "sigma": ("sigma_r", "sigma_g", "sigma_b"),
            "saturated": ("saturated_r", "saturated_g", "saturated_b")}
_KNOWN = {"time", "region", "point", "view_zenith_deg", "view_azimuth_deg", "sigma",
          "luminance", "frame", "saturated", *(c for v in _VECTORS.values() for c in v)}


@dataclass
class ObservationTable:
    """The N checked rows of an observation table: times (N,) aware (None for lab lights);
    regions, points (N,); position, view, normal (N, 3), NaN where not given; value, sigma
    (N, 3) [W m^-2 sr^-1] (luminance: Y first); saturated (N, 3) bool; lines; frames (or None).
    """

    path: Path
    times: list
    regions: list
    points: list
    position: np.ndarray
    view: np.ndarray
    normal: np.ndarray
    value: np.ndarray
    sigma: np.ndarray
    saturated: np.ndarray
    lines: list
    luminance: bool = False
    frames: list = None

    @property
    def by_index(self):
        """Whether the rows name their frames by index alone (lab lights, no time)."""
        return self.times is None

    def point_rows(self):
        """{(region, point): its rows' indices}, in order of first appearance (linear time)."""
        out = {}
        for i, k in enumerate(zip(self.regions, self.points)):
            out.setdefault(k, []).append(i)
        return out


def _number(text, path, line, column):
    try:
        v = float(text)
    except ValueError:
        raise SkyfitError(f"{path} line {line}: {column} = {text!r} is not a number.") from None
    if not np.isfinite(v):
        raise SkyfitError(f"{path} line {line}: {column} = {text!r} is not finite; drop the row "
                          "or give a measured value.")
    return v


def _frame(text, path, line):
    """A row's frame index: a whole number from 0."""
    v = _number(text, path, line, "frame")
    if v != int(v) or v < 0:
        raise SkyfitError(f"{path} line {line}: frame = {text!r} is not a frame index; give the "
                          "0-based index of the row's light among the spec's [[sky]].")
    return int(v)


def _flag(text, path, line, column):
    """A ``saturated`` cell: 0 or 1."""
    if text not in ("0", "1"):
        raise SkyfitError(f"{path} line {line}: {column} = {text!r}; write 1 (the instrument "
                          "clipped the value) or 0.")
    return float(text)


def _time(text, tz, path, line):
    try:
        t = _iso(text)
    except ValueError:
        raise SkyfitError(f"{path} line {line}: time {text!r} is not an ISO 8601 date-time "
                          "(e.g. 2024-06-21T12:00:00+01:00).") from None
    if t.tzinfo is None:
        t = localize(t, parse_tz(tz), f"{path} line {line}",
                     "has no UTC offset; give times with offsets or --tz.")
    return t


def read_observation_table(path, tz=None):
    """The checked :class:`ObservationTable` of a CSV file (module docstring); SkyfitError
    naming the file, line and column of anything wrong."""
    path = Path(path)
    rows = _csv_rows(path)
    header = [c.strip().lower() for c in rows[0][1]]
    luminance = _check_columns(path, header)
    times, regions, points, lines, frames, out = _parse_rows(path, header, rows[1:], tz,
                                                             luminance)
    table = ObservationTable(path, times if "time" in header else None, regions, points,
                             out["x"], out["view"], out["normal"], out["value"], out["sigma"],
                             out["saturated"] > 0, lines, luminance,
                             frames if "frame" in header else None)
    _check_rows(table)
    return table


def _csv_rows(path):
    """The non-blank rows of the CSV file as (line number, cells), the header first."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise SkyfitError(f"cannot read the observation table {path}: "
                          f"{getattr(exc, 'strerror', None) or exc}; give a UTF-8 CSV.") from None
    rows = [(i + 1, r) for i, r in enumerate(csv.reader(text.splitlines()))
            if r and any(c.strip() for c in r)]
    if len(rows) < 2:
        raise SkyfitError(f"{path} has no rows; write a header (time,region,r,g,b,sigma,...) "
                          "and one row per measurement.")
    return rows


def _check_columns(path, header):
    """Refuse unknown, repeated, missing or mixed columns; whether the values are luminances."""
    unknown = [c for c in header if c not in _KNOWN]
    if unknown and any(";" in c or "\t" in c for c in unknown):
        raise SkyfitError(f"{path}: its columns are separated by semicolons or tabs "
                          f"({unknown[0]!r}); save it with commas (a comma-separated CSV, the "
                          "decimal point a full stop).")
    if unknown == [""]:
        raise SkyfitError(f"{path}: a column without a name (a comma at the header's end?); "
                          "remove it.")
    if unknown:
        raise SkyfitError(f"{path}: unknown column {unknown[0]!r}; the columns are time (or "
                          "frame), region, point, x,y,z, view_x,view_y,view_z (or "
                          "view_zenith_deg, view_azimuth_deg), normal_x,normal_y,normal_z, r,g,b "
                          "(or luminance), sigma_r,sigma_g,sigma_b (or sigma), saturated (or "
                          "saturated_r,saturated_g,saturated_b).")
    twice = sorted({c for c in header if header.count(c) > 1})
    if twice:
        raise SkyfitError(f"{path}: column {twice[0]!r} appears twice; keep one.")
    luminance = "luminance" in header
    if luminance and any(c in header for c in ("r", "g", "b", "sigma_r", "sigma_g", "sigma_b")):
        raise SkyfitError(f"{path}: give luminance with one sigma, or r, g, b with their sigma, "
                          "not both.")
    if "time" not in header and "frame" not in header:
        raise SkyfitError(f"{path}: no column time (or frame); give each row's time (ISO 8601), "
                          "or for lab lights the 0-based index of its [[sky]] light as frame.")
    needed = ["region"] + ([] if luminance else ["r", "g", "b"])
    missing = [c for c in needed if c not in header]
    if missing or not ("sigma" in header or all(c in header for c in _VECTORS["sigma"])):
        what = missing[0] if missing else "sigma (or sigma_r, sigma_g, sigma_b)"
        raise SkyfitError(f"{path}: no column {what}; a table needs time (or frame), region, "
                          "r, g, b (or luminance) and sigma (standard deviations, the values' "
                          "units).")
    if any(c in header for c in _VECTORS["saturated"]) and ("saturated" in header or luminance):
        raise SkyfitError(f"{path}: give saturated (every channel; a luminance table's one) or "
                          "saturated_r, saturated_g, saturated_b, not both.")
    for name, cols in _VECTORS.items():
        some = [c in header for c in cols]
        if any(some) and not all(some):
            raise SkyfitError(f"{path}: give all of {', '.join(cols)} or none of them.")
    if ("view_zenith_deg" in header) != ("view_azimuth_deg" in header) or (
            "view_zenith_deg" in header and "view_x" in header):
        raise SkyfitError(f"{path}: give the view as view_x,view_y,view_z or as view_zenith_deg "
                          "and view_azimuth_deg, not a mix.")
    return luminance


def _parse_rows(path, header, rows, tz, luminance):
    """Each row's cells parsed and checked: (times, regions, points, lines, frames, {x, view,
    normal, value, sigma: (N, 3), NaN where not given; saturated: (N, 3) 0/1}), vectors unit."""
    col = {c: i for i, c in enumerate(header)}
    n = len(rows)
    out = {k: np.full((n, 3), np.nan) for k in ("x", "view", "normal", "value", "sigma")}
    out["saturated"] = np.zeros((n, 3))
    times, regions, points, lines, frames = [], [], [], [], []
    for k, (line, row) in enumerate(rows):
        if len(row) != len(header):
            raise SkyfitError(f"{path} line {line}: {len(row)} fields, the header has "
                              f"{len(header)}.")
        cell = {c: row[i].strip() for c, i in col.items()}
        if "time" in cell:
            times.append(_time(cell["time"], tz, path, line))
        if not cell["region"]:
            raise SkyfitError(f"{path} line {line}: the region is empty; name the scene material "
                              "the point lies on.")
        regions.append(cell["region"])
        points.append(cell.get("point") or cell["region"])
        lines.append(line)
        if "frame" in cell:
            frames.append(_frame(cell["frame"], path, line))
        for name, cols in _VECTORS.items():
            if cols[0] in cell:
                out[name][k] = [(_flag if name == "saturated" else _number)(cell[c], path, line, c)
                                for c in cols]
        if "sigma" in cell:
            out["sigma"][k] = _number(cell["sigma"], path, line, "sigma")
        if "saturated" in cell:
            out["saturated"][k] = _flag(cell["saturated"], path, line, "saturated")
        if luminance:
            out["value"][k, 0] = _number(cell["luminance"], path, line, "luminance")
            out["sigma"][k, 1:] = np.inf             # no colour: G and B carry nothing
            out["saturated"][k, 1:] = 0.0
        if "view_zenith_deg" in cell:
            zen, azi = (_number(cell[c], path, line, c)
                        for c in ("view_zenith_deg", "view_azimuth_deg"))
            if not 0.0 <= zen < 90.0:
                raise SkyfitError(f"{path} line {line}: view_zenith_deg = {zen} is not in "
                                  "[0, 90); the instrument looks down at the sample.")
            out["view"][k] = direction_from_angles(np.radians(zen), np.radians(azi))
        if not np.all(out["sigma"][k] > 0):
            raise SkyfitError(f"{path} line {line}: sigma must be positive (the value's standard "
                              "deviation, in its units).")
        if np.any((out["sigma"][k] < SIGMA_FLOOR * np.abs(out["value"][k]))
                  & (np.abs(out["value"][k]) <= MAX_RADIANCE)):        # beyond: refused below
            raise SkyfitError(f"{path} line {line}: sigma is under {SIGMA_FLOOR:g} of the value, "
                              "below what any instrument measures (and what the fit's arithmetic "
                              "resolves); give the value's real standard deviation.")
        if np.any((out["saturated"][k] > 0) & ~(out["value"][k] > 0)):
            raise SkyfitError(f"{path} line {line}: a saturated value must be the positive level "
                              "the instrument clipped at; give that level, or saturated = 0.")
        for name in ("view", "normal"):
            v = out[name][k]
            if np.isfinite(v).all():
                norm = np.linalg.norm(v)
                if norm < 1e-9:
                    raise SkyfitError(f"{path} line {line}: the {name} vector is zero; give a "
                                      "direction.")
                out[name][k] = v / norm
    return times, regions, points, lines, frames, out


def _check_rows(table):
    """Refuse a region without a positive value, a point measured twice in a frame, and a
    point whose position changes from row to row."""
    path, regions, points, lines = table.path, table.regions, table.points, table.lines
    for r in dict.fromkeys(regions):
        if not np.nanmax(table.value[np.array(regions) == r]) > 0:
            raise SkyfitError(f"{path}: every value of region {r!r} is zero or negative; give "
                              "measured values (a radiance is positive).")
    seen = {}
    frame_keys = table.frames if table.by_index else table.times    # as the table names them
    for f, r, p, line in zip(frame_keys, regions, points, lines):
        key = (f, r, p)
        if key in seen:
            when = f"in frame {f}" if table.by_index else f"at {f.isoformat()}"
            raise SkyfitError(f"{path} line {line}: point {p!r} of {r!r} {when} is measured "
                              f"again (first on line {seen[key]}); keep one row (or average "
                              "them with their sigma).")
        seen[key] = line
    for (r, p), rows_p in table.point_rows().items():
        pos = table.position[rows_p]
        if np.isfinite(pos).any() and not np.allclose(pos, pos[0], rtol=0, atol=1e-9):
            raise SkyfitError(f"{path} line {lines[rows_p[0]]}: point {p!r} of {r!r} moves from "
                              "row to row; a point keeps its position (name each position as "
                              "its own point).")


# ---- the points in the scene -------------------------------------------------------------

def locate_points(spec, scene_xml, table, row_frames):
    """Each point's position (P, 3), each row's view (N, 3) and the rays' offset, checked in the
    spec's scene: a point must lie on its region's surface, seen from the front by each row's
    view (the table's, else toward the camera), with the table's normal if given.
    ``scene_xml``: the spec's (xml, materials, camera to_world); ``row_frames``: for messages."""
    groups = table.point_rows()
    xml, _, to_world = scene_xml
    scene = load_points_scene(xml, spec.render["variant"])
    m = np.asarray(to_world, dtype=float)          # the camera's origin and central direction
    cam_o, cam_d = m[:3, 3], m[:3, 2] / np.linalg.norm(m[:3, 2])
    first = [rows[0] for rows in groups.values()]          # each point's first row
    P = len(first)
    pos = table.position[first]
    unplaced = ~np.isfinite(pos).all(axis=1)
    hits = surface_hits(scene, np.repeat(cam_o[None], P, 0), np.repeat(cam_d[None], P, 0))
    pos[unplaced] = hits["p"][unplaced]
    point = np.empty(len(table.regions), dtype=int)
    for j, rows in enumerate(groups.values()):
        point[rows] = j
    given = np.isfinite(table.view).all(axis=1)
    toward_camera = cam_o[None] - pos[point]
    toward_camera /= np.linalg.norm(toward_camera, axis=1, keepdims=True)
    view = np.where(given[:, None], table.view, toward_camera)
    offset = RAY_OFFSET * hits["scale"]
    check = surface_hits(scene, pos[point] + offset * view, -view)
    for i, (r, p) in enumerate(zip(table.regions, table.points)):
        j = point[i]
        where = (f"{table.path} line {table.lines[i]}: point {p!r} of {r!r} ("
                 f"{frame_label(row_frames[i], None if table.by_index else table.times[i])})")
        at = np.round(pos[j], 4).tolist()
        if not abs(check["t"][i] - offset) <= 2 * offset:
            raise SkyfitError(f"{where} at {at} is not on a surface of the scene seen from its "
                              "view (or the camera's central ray misses it); give x,y,z on the "
                              "sample.")
        if check["material"][i] != r:
            raise SkyfitError(f"{where} lies on material {check['material'][i]!r}, not {r!r}; "
                              "check its position or its region.")
        n_scene = check["n"][i]
        normal = table.normal[first[j]]
        if np.isfinite(normal).all() and np.degrees(np.arccos(np.clip(
                normal @ n_scene, -1, 1))) > NORMAL_TOLERANCE_DEG:
            raise SkyfitError(f"{where}: the scene's normal there is {np.round(n_scene, 3).tolist()}"
                              f", not the table's {np.round(normal, 3).tolist()}; check the "
                              "position, the scene or the normal.")
        if view[i] @ n_scene <= 0.0:
            angle = np.degrees(np.arccos(np.clip(view[i] @ n_scene, -1, 1)))
            source = ("the row's view columns" if given[i] else
                      f"toward the camera at {np.round(cam_o, 3).tolist()}: the row gives no "
                      "view")
            raise SkyfitError(f"{where} at {at} is viewed from behind its surface: its view "
                              f"{np.round(view[i], 3).tolist()} ({source}) is {angle:.0f} deg from "
                              f"the scene's normal {np.round(n_scene, 3).tolist()}; the view "
                              "points from the surface toward the instrument, so give the row's "
                              "view on the normal's side (or check the point's position and "
                              "region).")
    return pos, view, offset


# ---- the sequence folder ---------------------------------------------------------------

def _lab_spec(spec_path, table, tz, site):
    """The validated spec of a table of lab lights, its lights the frames."""
    for name, given in (("--tz", tz), ("--site", site)):
        if given is not None:
            raise SkyfitError(f"{name}: {table.path} names its frames by index (lab lights), "
                              "which have no time or site; leave it out.")
    spec = load_spec(spec_path)
    if not spec.lab:
        raise SkyfitError(f"{table.path} names its frames by index (a frame column, no time), "
                          f"but {spec_path} has [time]: give the table each row's time, or a "
                          "spec of lab lights (directional [[sky]], no [time] or [location]).")
    n = len(spec.frames)
    for f, line in zip(table.frames, table.lines):
        if f >= n:
            raise SkyfitError(f"{table.path} line {line}: frame {f} is not one of the spec's "
                              f"{n} lights (0 to {n - 1}); give the index of the row's light "
                              "in its [[sky]] list.")
    return spec


def _table_spec(spec_path, table, tz, site, log):
    """(validated spec, each row's frame index) of an observation table: the spec's lights by
    index, or the spec at the table's times (:func:`.ingest.spec_for_times`)."""
    if table.by_index:
        spec = _lab_spec(spec_path, table, tz, site)
        if len(set(table.frames)) < 2:
            raise SkyfitError(f"{table.path} measures one frame; a sequence needs at least 2.")
        return spec, list(table.frames)
    times = sorted(set(table.times), key=lambda t: t.timestamp())
    if len(times) < 2:
        raise SkyfitError(f"{table.path} holds one time; a sequence needs at least 2.")
    if "time" not in read_spec(spec_path):
        raise SkyfitError(f"{spec_path} has lab lights (frames by index, no [time]) but "
                          f"{table.path} gives times: name each row's light by its 0-based "
                          "index in a frame column instead of time.")
    _, spec = spec_for_times(spec_path, times, tz, site)
    night = [t for t, f in zip(times, spec.frames) if f.skipped]
    if len(night) == len(times):
        raise SkyfitError(f"every time of {table.path} has the sun below the horizon; check the "
                          "times, --tz and --site.")
    if night:
        log(f"{len(night)} time(s) with the sun below the horizon are kept out of the sequence: "
            f"{', '.join(t.isoformat() for t in night)}")
    frame_of = {t: j for j, t in enumerate(times)}
    return spec, [frame_of[t] for t in table.times]


def _grid(table, cell, view, shape):
    """The rows at ``cell`` {row: (p, t)} on a (P, T) grid ``shape``: (view (P, T, 3), a frame
    without a row taking another's (none: +Z); value, sigma (no row: inf); saturated)."""
    v = np.zeros((*shape, 3))
    v[..., 2] = 1.0
    y, sig = np.zeros((*shape, 3)), np.full((*shape, 3), np.inf)
    sat = np.zeros((*shape, 3), bool)
    for i, (p, t) in cell.items():
        v[p, t], y[p, t] = view[i], np.nan_to_num(table.value[i])
        sig[p, t], sat[p, t] = table.sigma[i], table.saturated[i]
    for p in range(shape[0]):            # a frame without a row: the view of another frame
        have = np.isfinite(sig[p, :, 0])
        v[p, ~have] = v[p, np.argmax(have)]
    return v, y, sig, sat


def white_at_rows(spec, xml, table, rows, row_frames, pos, view, offset, **trace):
    """A white Lambertian's radiance L at the points of ``rows`` from each row's view, traced as a
    fit traces (:func:`~skyfit_mi.render.points.lambertian_radiance`): (L, its Monte Carlo
    variance (P, T, 3), each row's (p, t) cell, the points [(region, point)])."""
    index = {k: j for j, k in enumerate(table.point_rows())}
    points = list(dict.fromkeys((table.regions[i], table.points[i]) for i in rows))
    frames = sorted({row_frames[i] for i in rows})
    at_point = {k: j for j, k in enumerate(points)}
    at_frame = {f: j for j, f in enumerate(frames)}
    cell = {i: (at_point[(table.regions[i], table.points[i])], at_frame[row_frames[i]])
            for i in rows}
    v = _grid(table, cell, view, (len(points), len(frames)))[0]
    material = np.array([m for m, _ in points], dtype=object)
    L, var = lambertian_radiance(xml, spec.render["variant"], [spec.frames[j].sky for j in frames],
                                 point_rays(pos[[index[k] for k in points]], v, offset),
                                 material, max(1, int(spec.render["max_depth"]) - 1), **trace)
    return L, var, cell, points


def reference_scale(spec, xml, table, rows, row_frames, pos, view, offset, calibrate):
    """Radiance of one unit of a table's own scale per channel, from rows on references of
    ``calibrate`` {material: (r, g, b)} reflectance: ((3,) [W m^-2 sr^-1 per unit], record).
    With L a white Lambertian's traced radiance (:func:`white_at_rows`), y ~ a rho L by weighted
    least squares (weights 1 / (sigma^2 + a^2 rho^2 var L)), the error widened where chi^2/dof >
    1; ``scale_relative_sd`` widens fits' intervals (:mod:`skyfit_mi.fitting.uncertainty`)."""
    ref = [i for i in rows if table.regions[i] in calibrate and not table.saturated[i].all()]
    missing = [m for m in calibrate if m not in {table.regions[i] for i in ref}]
    if missing:
        raise SkyfitError(f"--calibrate {missing[0]}: {table.path} has no unsaturated row on "
                          f"region {missing[0]!r} in a lit frame; measure the reference in the "
                          "table (rows with that region).")
    L, var, cell, points = white_at_rows(spec, xml, table, ref, row_frames, pos, view, offset)
    _, y, sig, sat = _grid(table, cell, view, L.shape[:2])
    sig = np.where(sat, np.inf, sig)
    material = np.array([m for m, _ in points], dtype=object)
    rho = np.array([calibrate[m] for m in material], dtype=float)[:, None, :]
    m, m_var = rho * L, rho ** 2 * var
    if table.luminance:                  # one quantity: Y (its variance bounded, as the fit's)
        m = np.repeat((m @ SRGB_LUMINANCE)[..., None], 3, axis=2)
        m_var = np.repeat((np.sqrt(m_var) @ SRGB_LUMINANCE)[..., None] ** 2, 3, axis=2)
        y, sig = np.repeat(y[..., :1], 3, axis=2), np.repeat(sig[..., :1], 3, axis=2)
    ok = np.isfinite(sig) & (m > 0)
    a = np.zeros(3)
    for _ in range(2):                   # the weights take the trace's variance at a
        w = np.where(ok, 1.0 / (np.where(ok, sig, 1.0) ** 2 + a ** 2 * m_var), 0.0)
        mm = np.einsum("ptc,ptc->c", w * m, m)
        a = np.einsum("ptc,ptc->c", w * m, y) / np.where(mm > 0, mm, np.nan)
    n = ok.sum(axis=(0, 1))
    if not np.all(np.isfinite(a) & (a > 0)):
        raise SkyfitError(f"--calibrate: the reference rows of {table.path} give no positive "
                          "scale (unlit, or their values zero); check the reference's rows and "
                          "its reflectance.")
    chi2 = np.einsum("ptc,ptc->c", w, (y - a * m) ** 2)
    s2 = np.maximum(1.0, chi2 / np.maximum(n - 1, 1))
    rel_sd = np.sqrt(s2 / mm) / a
    record = {"references": {k: list(map(float, v)) for k, v in calibrate.items()},
              "reference_rows": len(ref), "scale_W_m2_sr_per_unit": (1.0 / a).tolist(),
              "scale_relative_sd": rel_sd.tolist(),
              "chi2_per_dof": (chi2 / np.maximum(n - 1, 1)).tolist(),
              "method": "the table's values in its own units (e.g. DN) scaled to radiance by "
                        "its rows on reference materials of known Lambertian reflectance, "
                        "traced as white Lambertians under each frame's light"}
    return 1.0 / a, record


#: Where an unknown scale puts the table's brightest apparent albedo (radiance over a white
#: Lambertian's): at 0.5 no Ward material fitting the data needs a bound (a lobe's peak apparent
#: albedo is at least its rho_s).
UNKNOWN_SCALE_ALBEDO = 0.5


def unknown_scale(spec, xml, table, rows, row_frames, pos, view, offset):
    """(factor, record) putting a table of unknown scale (DN, no reference) on the scale where
    its largest apparent albedo y / L (L a white Lambertian's traced radiance) is
    :data:`UNKNOWN_SCALE_ALBEDO`.  Fitted reflectances are then relative (one unknown factor
    for every material and channel); roughness and rho_s / rho_d do not depend on it."""
    # a saturated value is a lower bound of the true one: its albedo counts as at least that
    lit = [i for i in rows if np.nanmax(table.value[i]) > 0]
    if not lit:
        raise SkyfitError(f"{table.path} has no positive value in a lit frame, so its scale "
                          "cannot be found; check its values.")
    L, _, cell, _ = white_at_rows(spec, xml, table, lit, row_frames, pos, view, offset,
                                  positions=POINT_POSITIONS)
    channels = 1 if table.luminance else 3
    best = 0.0
    for i, (p, t) in cell.items():
        white = L[p, t]
        if table.luminance:
            white = np.array([white @ SRGB_LUMINANCE])
        y = table.value[i, :channels]
        lit_enough = white[:channels] > 1e-3 * np.max(L)      # not at grazing light
        if lit_enough.any():
            best = max(best, float(np.nanmax(np.where(lit_enough, y / white[:channels],
                                                      np.nan))))
    if not best > 0:
        raise SkyfitError(f"{table.path}: no value lies where the light reaches its point, so "
                          "its scale cannot be found; check the lights and the points.")
    factor = UNKNOWN_SCALE_ALBEDO / best
    record = {"known": False, "brightest_apparent_albedo_per_unit": best,
              "scale_per_unit": factor, "brightest_apparent_albedo_reads": UNKNOWN_SCALE_ALBEDO,
              "rows": len(lit),
              "meaning": "the table's radiometric scale is unknown: its values were multiplied "
                         f"by {factor:.6g} so that its brightest apparent albedo (pi L / E) "
                         f"reads {UNKNOWN_SCALE_ALBEDO}; the raw diffuse and specular "
                         "reflectances (rho_d = C (1 - rho_s), and rho_s or C rho_s) are "
                         "the true ones times one unknown factor, the same for every material "
                         "and channel, and the roughness is absolute; the model's C, R and "
                         "rho_s mix them, so a C or rho_s is not the true one times that "
                         "factor: compare materials by their raw reflectances"}
    return factor, record


def check_radiances(table, scaled=None):
    """SkyfitError naming the line and column of the first value or sigma of ``table`` (in
    W m^-2 sr^-1, ``scaled`` by what, if not given so) beyond :data:`MAX_RADIANCE`."""
    for name, single in (("value", "luminance"), ("sigma", "sigma")):
        v = getattr(table, name)
        big = np.isfinite(v) & (np.abs(v) > MAX_RADIANCE)
        if big.any():
            k, i = np.argwhere(big)[0]
            column = single if table.luminance or name == "sigma" and i == 0 else \
                _VECTORS[name][i]
            raise SkyfitError(f"{table.path} line {table.lines[k]}: {column} = {v[k, i]:g} W m^-2 "
                              f"sr^-1{f' (by {scaled})' if scaled else ''} is beyond any "
                              f"radiance (at most {MAX_RADIANCE:.2g}, ten times the sun's disc); "
                              "give radiances in W m^-2 sr^-1.")


def ingest_table(table_path, spec_path, out_dir, *, tz=None, site=None, calibrate=None,
                 reference_sd=None, scale_unknown=False, overwrite=False, log=print):
    """Turn an observation table into a sequence folder; returns the manifest dict.  ``tz``:
    zone of naive times; ``site``: (lat, lon[, alt]) over the spec's; ``calibrate``
    (:func:`reference_scale`, with the reflectances' errors ``reference_sd``, as
    :func:`.ingest.reference_error`) or ``scale_unknown`` (:func:`unknown_scale`) for own
    units."""
    out = Path(out_dir)
    mine = out / TABLE_FILE
    if mine.exists() and mine.resolve() == Path(table_path).resolve():
        raise SkyfitError(f"the table {table_path} is the output folder's own {TABLE_FILE}, which "
                          "ingest writes; give another folder with -o.")
    if mine.exists() and not (out / "manifest.json").exists() and not overwrite:
        raise SkyfitError(f"{out} holds a file {TABLE_FILE} of no skyfit sequence; give another "
                          "folder with -o, or pass --overwrite to replace it.")
    table = read_observation_table(table_path, tz)
    if table.saturated.all():
        raise SkyfitError(f"{table.path}: every value is flagged saturated, which tells only a "
                          "lower bound; measure the surface at an exposure (or gain) where some "
                          "values are not.")
    spec, row_frames = _table_spec(spec_path, table, tz, site, log)
    scene = build_scene_xml(spec)
    mats = scene[1]
    for r in dict.fromkeys(table.regions):
        if r not in mats:
            raise SkyfitError(f"{table.path}: region {r!r} is no material of the spec's scene; "
                              f"its materials are: {', '.join(mats)}.")
    for name, rho in (calibrate or {}).items():
        if name not in mats:
            raise SkyfitError(f"--calibrate {name}: no material {name!r} in the spec's scene; "
                              f"its materials are: {', '.join(mats)}.")
        if len(rho) != 3 or not all(0.0 < r <= 1.0 for r in rho):
            raise SkyfitError(f"--calibrate {name}: give the reference's reflectance as one "
                              "number or R,G,B, each in (0, 1].")
    if calibrate and scale_unknown:
        raise SkyfitError("--calibrate gives the table's scale from its references; leave out "
                          "--unknown-scale (or --calibrate, for a relative scale).")
    keep = [i for i in range(len(row_frames)) if not spec.frames[row_frames[i]].skipped]
    pos, view, offset = locate_points(spec, scene, table, row_frames)
    calibration = None
    if calibrate:
        scale, calibration = reference_scale(spec, scene[0], table, keep, row_frames, pos, view,
                                             offset, calibrate)
        calibration["reference_relative_sd"] = reference_error(
            calibrate, reference_sd or {}, log).tolist()
        log(f"calibration: one unit of {table.path.name} is "
            f"{', '.join(f'{v:.4g}' for v in scale)} W m^-2 sr^-1 (R, G, B), to "
            f"{', '.join(f'{v:.1%}' for v in calibration['scale_relative_sd'])} (standard "
            f"error), from {calibration['reference_rows']} reference rows")
    elif scale_unknown:
        scale, calibration = unknown_scale(spec, scene[0], table, keep, row_frames, pos, view,
                                           offset)
        log(f"scale: unknown (no reference); the values are multiplied by {scale:.4g} so that "
            f"the brightest apparent albedo reads {UNKNOWN_SCALE_ALBEDO}: fitted reflectances "
            "will be relative, roughness and ratios absolute")
    if calibration is not None:
        table = replace(table, value=table.value * scale, sigma=table.sigma * scale)
    check_radiances(table, "its reference's scale" if calibrate else
                    "the relative scale" if scale_unknown else None)
    top = float(np.nanmax(np.where(np.isfinite(table.sigma),
                                   table.value + HEADROOM_SIGMAS * table.sigma, np.nan)))
    sensor = SensorModel(exposure=SCALE_SHARE / top, response="linear", bits=16)

    index = {k: j for j, k in enumerate(table.point_rows())}
    saturated = bool(table.saturated.any())
    columns = ["frame", *([] if table.by_index else ["time"]), "region", "point", "x", "y", "z",
               "view_x", "view_y", "view_z",
               *(["luminance", "sigma"] if table.luminance else
                 [*_VECTORS["value"], *_VECTORS["sigma"]]),
               *((["saturated"] if table.luminance else list(_VECTORS["saturated"]))
                 if saturated else [])]
    lines = [",".join(columns)]
    for i in sorted(keep, key=lambda i: (row_frames[i], i)):
        k = index[(table.regions[i], table.points[i])]
        channels = slice(0, 1) if table.luminance else slice(0, 3)
        nums = [*pos[k], *view[i], *table.value[i, channels], *table.sigma[i, channels]]
        flags = [str(int(v)) for v in table.saturated[i, channels]] if saturated else []
        lines.append(",".join([str(row_frames[i]),
                               *([] if table.by_index else [table.times[i].isoformat()]),
                               table.regions[i], table.points[i]]
                              + [repr(float(v)) for v in nums] + flags))
    text = "\n".join(lines) + "\n"
    run_id = hashlib.sha256(json.dumps([text, spec.raw], sort_keys=True, default=str)
                            .encode()).hexdigest()[:16]
    with FolderLock(out):
        prepare_folder(out, run_id, None, overwrite, log=lambda message: None)
        manifest = measured_header(spec, sensor, run_id, "measured", "none: measured values",
                                   scene)
        manifest["ingest"] = {"table": str(table.path), "rows": len(table.regions),
                              "points": [{"region": r, "point": p, "position": pos[k].tolist()}
                                         for (r, p), k in index.items()],
                              "ray_offset": offset, "units": "W m^-2 sr^-1, linear sRGB"}
        if saturated:
            manifest["ingest"]["saturated_values"] = int(table.saturated[keep].sum())
        if calibration is not None:
            manifest["ingest"]["scale" if scale_unknown else "calibration"] = calibration
        for f in spec.frames:
            rec = frame_record(f, 0, out)
            rec.pop("seed")
            if f.skipped:
                rec["status"] = "skipped"
            else:
                rec.update(status="rendered", observations={"kind": "table", "file": TABLE_FILE})
            manifest["frames"].append(rec)
        write_text(out / TABLE_FILE, text)
        finish(out, manifest, sensor.exposure)
    log(f"wrote {len(keep)} rows of {len(index)} point(s) in "
        f"{len(set(table.regions[i] for i in keep))} region(s) over "
        f"{len(set(row_frames[i] for i in keep))} frame(s): {out / TABLE_FILE} and its manifest")
    return manifest


def relative_scale(doc):
    """Whether a manifest's values are on a relative scale (:func:`unknown_scale`)."""
    return ((doc.get("ingest") or {}).get("scale") or {}).get("known") is False


def table_regions(root):
    """The regions an observation-table sequence in folder ``root`` measures, in table order."""
    return list(dict.fromkeys(read_observation_table(Path(root) / TABLE_FILE).regions))


@dataclass
class RegionRows:
    """A region's rows of a table sequence by point and frame: names (P,); frames (T,) manifest
    indices; position (P, 3); view (P, T, 3) unit, surface toward instrument; value, sigma
    (P, T, 3) [W m^-2 sr^-1] (no row: sigma inf); saturated (P, T, 3) bool; luminance: Y in
    the first channel, the others' sigma inf."""

    names: list
    frames: list
    position: np.ndarray
    view: np.ndarray
    value: np.ndarray
    sigma: np.ndarray
    saturated: np.ndarray
    luminance: bool


def table_observations(doc, root, region, points=None, frames=None):
    """The :class:`RegionRows` of ``region`` in a table sequence (folder ``root``), of
    ``points`` and ``frames`` (default all)."""
    table = read_observation_table(root / TABLE_FILE)
    frame_col = table.frames
    keys = [p for r, p in table.point_rows() if r == region]
    if not keys:
        regions = ", ".join(dict.fromkeys(table.regions))
        raise SkyfitError(f"the observation table has no point on region {region!r}; its regions "
                          f"are: {regions}.")
    if points is not None:
        unknown = [p for p in points if p not in keys]
        if unknown:
            raise SkyfitError(f"region {region!r} has no point {unknown[0]!r}; its points are: "
                              f"{', '.join(keys)}.")
        keys = list(points)
    wanted = set(keys)
    rows = [i for i in range(len(frame_col)) if table.regions[i] == region
            and table.points[i] in wanted]
    fr = sorted({frame_col[i] for i in rows} if frames is None else set(frames))
    at_point, at_frame = {p: j for j, p in enumerate(keys)}, {f: j for j, f in enumerate(fr)}
    cell = {i: (at_point[table.points[i]], at_frame[frame_col[i]]) for i in rows
            if frame_col[i] in at_frame}
    pos = np.zeros((len(keys), 3))
    for i, (p, _) in cell.items():
        pos[p] = table.position[i]
    view, y, sig, sat = _grid(table, cell, table.view, (len(keys), len(fr)))
    return RegionRows(keys, fr, pos, view, y, sig, sat, table.luminance)

