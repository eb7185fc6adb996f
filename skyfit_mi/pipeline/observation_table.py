"""Observations without images: a table of measured radiances becomes a sequence folder.

A spectroradiometer or luminance meter aimed at a sample through a day, or another program's
radiances at chosen points, give values, not photographs.  ``skyfit ingest SPEC --table
OBS.csv -o DIR`` takes such a table with the spec's site, scene, camera and sky (its
``[time]`` replaced by the table's times, as for photographs) and writes the manifest contract
with each frame's ``observations = {"kind": "table", "file": "observations.csv"}``: ``fit``
then fits the table's regions with the same light cache, chi-square and intervals as image
regions, without any image or throw-away render.

The table (CSV, header names in any order, case ignored):

===========================  ==================================================================
column                       meaning
===========================  ==================================================================
``time``                     ISO 8601 date-time; with an offset, or naive with ``--tz``
``region``                   the scene material the point lies on (a ``ward`` material id)
``point``                    optional: the point's name within its region (default the region's)
``x``, ``y``, ``z``          optional: the point, world frame [scene units]; default: where the
                             camera's central ray meets the region's surface
``view_x``.. ``view_z``      optional: unit vector from the point toward the instrument, world
                             frame (+X east, +Y north, +Z up); or ``view_zenith_deg`` and
                             ``view_azimuth_deg`` (east of north); default: toward the camera
``normal_x``.. ``normal_z``  optional: the surface normal the user expects; checked against the
                             scene's (a wrong position or scene is refused)
``r``, ``g``, ``b``          the measured radiance, linear sRGB [W m^-2 sr^-1]
``sigma_r``.. ``sigma_b``    its standard deviation [W m^-2 sr^-1]; or one ``sigma`` for all
``luminance``                instead of r, g, b: a luminance meter's value as the project's
                             luminance-weighted radiance Y = 0.2126 R + 0.7152 G + 0.0722 B
                             [W m^-2 sr^-1] (cd m^-2 divided by the sky's luminous efficacy,
                             e.g. the spec's ``efficacy_clear``), with ``sigma``
===========================  ==================================================================

A point keeps its position through the day; its view may change from row to row (a
goniometer).  A point without a row at some time carries no information there.  The values
are put on a linear 16-bit scale for the fit (the brightest value plus 5 sigma at half scale,
one factor recorded as the sensor's exposure), so chi-square is eq. 6.2 in the table's own
units; a value at or below zero, which a radiance cannot be, is taken as censored at zero
(the fit's rule for code 0), but a region needs a positive value, and a value or sigma beyond
any radiance (:data:`MAX_RADIANCE`) is refused.  A luminance table is fitted through the model's luminance (the
first channel; :class:`~skyfit_mi.fitting.chi2.LuminanceModel`): it cannot tell colour, so
only the 2- and 3-parameter models take it.
"""

import csv
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SkyfitError
from ..files import FolderLock
from ..physics.camera import SensorModel
from ..physics.sun import SOLAR_CONSTANT, SUN_SOLID_ANGLE
from ..conventions import direction_from_angles

#: File name of the normalised table in a sequence folder.
TABLE_FILE = "observations.csv"
#: Largest angle [deg] between a given normal and the scene's at the point.
NORMAL_TOLERANCE_DEG = 5.0
#: Ray start off the surface, as a share of the scene's bounding-box diagonal.
RAY_OFFSET = 1e-4
#: Largest radiance, value or sigma, a table may give [W m^-2 sr^-1]: ten times the solar
#: disc's above the atmosphere (no surface reflects more than its brightest source).
MAX_RADIANCE = 10.0 * SOLAR_CONSTANT / SUN_SOLID_ANGLE
#: Share of the 16-bit full scale that the brightest value plus HEADROOM_SIGMAS sigma takes.
SCALE_SHARE, HEADROOM_SIGMAS = 0.5, 5.0

_VECTORS = {"x": ("x", "y", "z"), "view": ("view_x", "view_y", "view_z"),
            "normal": ("normal_x", "normal_y", "normal_z"), "value": ("r", "g", "b"),
            "sigma": ("sigma_r", "sigma_g", "sigma_b")}
_KNOWN = {"time", "region", "point", "view_zenith_deg", "view_azimuth_deg", "sigma",
          "luminance", "frame", *(c for v in _VECTORS.values() for c in v)}


@dataclass
class ObservationTable:
    """The rows of an observation table (N rows), checked.

    times : aware datetimes (N,);  regions, points : str (N,);  position, view, normal :
    (N, 3) float, NaN where not given;  value, sigma : (N, 3) [W m^-2 sr^-1] (a luminance
    table: Y in the first column, NaN in the others);  lines : the file's line of each row;
    path : the file;  luminance : whether the values are luminances;  frames : each row's
    frame index (the sequence folder's normalised table), else None.
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
    lines: list
    luminance: bool = False
    frames: list = None

    def point_keys(self):
        """The distinct (region, point) pairs in order of first appearance."""
        return list(dict.fromkeys(zip(self.regions, self.points)))


def _number(text, path, line, column):
    try:
        v = float(text)
    except ValueError:
        raise SkyfitError(f"{path} line {line}: {column} = {text!r} is not a number.") from None
    if not np.isfinite(v):
        raise SkyfitError(f"{path} line {line}: {column} = {text!r} is not finite; drop the row "
                          "or give a measured value.")
    return v


def _time(text, tz, path, line):
    from .photo_times import _iso, localize, parse_tz

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
    header = [c.strip().lower() for c in rows[0][1]]
    unknown = [c for c in header if c not in _KNOWN]
    if unknown:
        raise SkyfitError(f"{path}: unknown column {unknown[0]!r}; the columns are time, region, "
                          "point, x,y,z, view_x,view_y,view_z (or view_zenith_deg, "
                          "view_azimuth_deg), normal_x,normal_y,normal_z, r,g,b, "
                          "sigma_r,sigma_g,sigma_b (or sigma).")
    twice = sorted({c for c in header if header.count(c) > 1})
    if twice:
        raise SkyfitError(f"{path}: column {twice[0]!r} appears twice; keep one.")
    luminance = "luminance" in header
    if luminance and any(c in header for c in ("r", "g", "b", "sigma_r", "sigma_g", "sigma_b")):
        raise SkyfitError(f"{path}: give luminance with one sigma, or r, g, b with their sigma, "
                          "not both.")
    needed = ["time", "region"] + ([] if luminance else ["r", "g", "b"])
    missing = [c for c in needed if c not in header]
    if missing or not ("sigma" in header or all(c in header for c in _VECTORS["sigma"])):
        what = missing[0] if missing else "sigma (or sigma_r, sigma_g, sigma_b)"
        raise SkyfitError(f"{path}: no column {what}; a table needs time, region, r, g, b (or "
                          "luminance) and sigma (standard deviations, the values' units).")
    for name, cols in _VECTORS.items():
        some = [c in header for c in cols]
        if any(some) and not all(some):
            raise SkyfitError(f"{path}: give all of {', '.join(cols)} or none of them.")
    if ("view_zenith_deg" in header) != ("view_azimuth_deg" in header) or (
            "view_zenith_deg" in header and "view_x" in header):
        raise SkyfitError(f"{path}: give the view as view_x,view_y,view_z or as view_zenith_deg "
                          "and view_azimuth_deg, not a mix.")

    col = {c: i for i, c in enumerate(header)}
    n = len(rows) - 1
    out = {k: np.full((n, 3), np.nan) for k in ("x", "view", "normal", "value", "sigma")}
    times, regions, points, lines, frames = [], [], [], [], []
    for k, (line, row) in enumerate(rows[1:]):
        if len(row) != len(header):
            raise SkyfitError(f"{path} line {line}: {len(row)} fields, the header has "
                              f"{len(header)}.")
        cell = {c: row[i].strip() for c, i in col.items()}
        times.append(_time(cell["time"], tz, path, line))
        if not cell["region"]:
            raise SkyfitError(f"{path} line {line}: the region is empty; name the scene material "
                              "the point lies on.")
        regions.append(cell["region"])
        points.append(cell.get("point") or cell["region"])
        lines.append(line)
        if "frame" in cell:
            frames.append(int(_number(cell["frame"], path, line, "frame")))
        for name, cols in _VECTORS.items():
            if cols[0] in cell:
                out[name][k] = [_number(cell[c], path, line, c) for c in cols]
        if "sigma" in cell:
            out["sigma"][k] = _number(cell["sigma"], path, line, "sigma")
        if luminance:
            out["value"][k, 0] = _number(cell["luminance"], path, line, "luminance")
            out["sigma"][k, 1:] = np.inf             # no colour: G and B carry nothing
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
        for name, single in (("value", "luminance"), ("sigma", "sigma")):
            v = out[name][k]
            big = np.isfinite(v) & (np.abs(v) > MAX_RADIANCE)
            if big.any():
                i = int(np.argmax(big))
                column = single if single in cell else _VECTORS[name][i]
                raise SkyfitError(f"{path} line {line}: {column} = {v[i]:g} is "
                                  f"beyond any radiance (at most {MAX_RADIANCE:.2g} W m^-2 "
                                  "sr^-1, ten times the sun's disc); give radiances in "
                                  "W m^-2 sr^-1.")
        for name in ("view", "normal"):
            v = out[name][k]
            if np.isfinite(v).all():
                norm = np.linalg.norm(v)
                if norm < 1e-9:
                    raise SkyfitError(f"{path} line {line}: the {name} vector is zero; give a "
                                      "direction.")
                out[name][k] = v / norm
    seen = {}
    for t, r, p, line in zip(times, regions, points, lines):
        key = (t, r, p)
        if key in seen:
            raise SkyfitError(f"{path} line {line}: point {p!r} of {r!r} at {t.isoformat()} is "
                              f"measured again (first on line {seen[key]}); keep one row (or "
                              "average them with their sigma).")
        seen[key] = line
    for r in dict.fromkeys(regions):
        if not np.nanmax(out["value"][[i for i in range(n) if regions[i] == r]]) > 0:
            raise SkyfitError(f"{path}: every value of region {r!r} is zero or negative; give "
                              "measured radiances [W m^-2 sr^-1] (a radiance is positive).")
    table = ObservationTable(path, times, regions, points, out["x"], out["view"], out["normal"],
                             out["value"], out["sigma"], lines, luminance,
                             frames if "frame" in col else None)
    for r, p in table.point_keys():
        rows_p = [i for i in range(n) if table.regions[i] == r and table.points[i] == p]
        pos = table.position[rows_p]
        if np.isfinite(pos).any() and not np.allclose(pos, pos[0], rtol=0, atol=1e-9):
            raise SkyfitError(f"{path} line {lines[rows_p[0]]}: point {p!r} of {r!r} moves from "
                              "row to row; a point keeps its position (name each position as "
                              "its own point).")
    return table


# ---- the points in the scene -------------------------------------------------------------

def _camera(to_world):
    """A camera's origin and unit central direction (world frame) from its to_world 4x4."""
    m = np.asarray(to_world, dtype=float)
    return m[:3, 3], m[:3, 2] / np.linalg.norm(m[:3, 2])


def locate_points(spec, scene_xml, table, times):
    """Each point's position (P, 3), its view per frame (P, T, 3) and the scene's offset for
    rays, checked in the spec's scene: a point must lie on its region's surface, seen from
    the front, with the normal the table gives (if any).  ``scene_xml``: the spec's
    (xml, materials, camera to_world); ``times``: the frames' times."""
    from ..render.points import load_points_scene, surface_hits

    keys = table.point_keys()
    xml, _, to_world = scene_xml
    scene = load_points_scene(xml, spec.render["variant"])
    cam_o, cam_d = _camera(to_world)
    P, T = len(keys), len(times)
    first = {k: next(i for i in range(len(table.times))
                     if (table.regions[i], table.points[i]) == k) for k in keys}
    pos = table.position[[first[k] for k in keys]]
    unplaced = ~np.isfinite(pos).all(axis=1)
    hits = surface_hits(scene, np.repeat(cam_o[None], P, 0), np.repeat(cam_d[None], P, 0))
    pos[unplaced] = hits["p"][unplaced]
    view = np.repeat((cam_o[None] - pos)[:, None, :], T, axis=1)
    view /= np.linalg.norm(view, axis=2, keepdims=True)
    index = {t: j for j, t in enumerate(times)}
    for i, (t, r, p) in enumerate(zip(table.times, table.regions, table.points)):
        if np.isfinite(table.view[i]).all() and t in index:
            view[keys.index((r, p)), index[t]] = table.view[i]
    offset = RAY_OFFSET * hits["scale"]
    check = surface_hits(scene, (pos[:, None] + offset * view).reshape(-1, 3),
                         -view.reshape(-1, 3))
    for j, (r, p) in enumerate(keys):
        line = table.lines[first[(r, p)]]
        where = f"{table.path} line {line}: point {p!r}"
        sl = slice(j * T, (j + 1) * T)
        mats, dist = check["material"][sl], check["t"][sl]
        if not np.all(np.abs(dist - offset) <= 2 * offset):
            raise SkyfitError(f"{where} at {np.round(pos[j], 4).tolist()} is not on a surface of "
                              "the scene seen from its view (or the camera's central ray misses "
                              "it); give x,y,z on the sample.")
        if any(m != r for m in mats):
            raise SkyfitError(f"{where} lies on material {next(m for m in mats if m != r)!r}, "
                              f"not {r!r}; check its position or its region.")
        n_scene = check["n"][sl][0]
        given = table.normal[first[(r, p)]]
        if np.isfinite(given).all() and np.degrees(np.arccos(np.clip(
                given @ n_scene, -1, 1))) > NORMAL_TOLERANCE_DEG:
            raise SkyfitError(f"{where}: the scene's normal there is {np.round(n_scene, 3).tolist()}"
                              f", not the table's {np.round(given, 3).tolist()}; check the "
                              "position, the scene or the normal.")
        if np.any(view[j] @ n_scene <= 0.0):
            raise SkyfitError(f"{where} is viewed from behind its surface; the view points from "
                              "the surface toward the instrument.")
    return pos, view, offset


# ---- the sequence folder ---------------------------------------------------------------

def ingest_table(table_path, spec_path, out_dir, *, tz=None, site=None, overwrite=False,
                 log=print):
    """Turn an observation table into a sequence folder (module docstring); returns the
    manifest dict.  ``tz``: zone of naive times; ``site``: (lat, lon[, alt]) over the spec's."""
    from .ingest import measured_header, spec_for_times
    from .sequence import finish, frame_record, prepare_folder
    from ..files import write_text
    from ..render.scene_xml import build_scene_xml

    out = Path(out_dir)
    mine = out / TABLE_FILE
    if mine.exists() and mine.resolve() == Path(table_path).resolve():
        raise SkyfitError(f"the table {table_path} is the output folder's own {TABLE_FILE}, which "
                          "ingest writes; give another folder with -o.")
    if mine.exists() and not (out / "manifest.json").exists() and not overwrite:
        raise SkyfitError(f"{out} holds a file {TABLE_FILE} of no skyfit sequence; give another folder "
                          "with -o, or pass --overwrite to replace it.")
    table = read_observation_table(table_path, tz)
    times = sorted(set(table.times), key=lambda t: t.timestamp())
    if len(times) < 2:
        raise SkyfitError(f"{table.path} holds one time; a sequence needs at least 2.")
    raw, spec = spec_for_times(spec_path, times, tz, site)
    scene = build_scene_xml(spec)
    mats = scene[1]
    for r in dict.fromkeys(table.regions):
        if r not in mats:
            raise SkyfitError(f"{table.path}: region {r!r} is no material of the spec's scene; "
                              f"its materials are: {', '.join(mats)}.")
    night = [t for t, f in zip(times, spec.frames) if f.skipped]
    if len(night) == len(times):
        raise SkyfitError(f"every time of {table.path} has the sun below the horizon; check the "
                          "times, --tz and --site.")
    if night:
        log(f"{len(night)} time(s) with the sun below the horizon are kept out of the sequence: "
            f"{', '.join(t.isoformat() for t in night)}")
    pos, view, offset = locate_points(spec, scene, table, times)
    top = float(np.nanmax(np.where(np.isfinite(table.sigma),
                                   table.value + HEADROOM_SIGMAS * table.sigma, np.nan)))
    sensor = SensorModel(exposure=SCALE_SHARE / top, response="linear", bits=16)

    keys = table.point_keys()
    frame_of = {t: j for j, t in enumerate(times)}
    values = "luminance,sigma" if table.luminance else "r,g,b,sigma_r,sigma_g,sigma_b"
    lines = ["frame,time,region,point,x,y,z,view_x,view_y,view_z," + values]
    for i in sorted(range(len(table.times)), key=lambda i: (frame_of[table.times[i]], i)):
        j = frame_of[table.times[i]]
        if spec.frames[j].skipped:
            continue
        k = keys.index((table.regions[i], table.points[i]))
        nums = [*pos[k], *view[k, j], *((table.value[i, 0], table.sigma[i, 0]) if table.luminance
                                        else (*table.value[i], *table.sigma[i]))]
        lines.append(",".join([str(j), table.times[i].isoformat(), table.regions[i],
                               table.points[i]] + [repr(float(v)) for v in nums]))
    text = "\n".join(lines) + "\n"
    run_id = hashlib.sha256(json.dumps([text, spec.raw], sort_keys=True, default=str)
                            .encode()).hexdigest()[:16]
    with FolderLock(out):
        prepare_folder(out, run_id, None, overwrite, log=lambda message: None)
        manifest = measured_header(spec, sensor, run_id, "measured", "none: measured values",
                                   scene)
        manifest["ingest"] = {"table": str(table.path), "rows": len(table.times),
                              "points": [{"region": r, "point": p, "position": pos[k].tolist()}
                                         for k, (r, p) in enumerate(keys)],
                              "ray_offset": offset, "units": "W m^-2 sr^-1, linear sRGB"}
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
    return manifest


def is_table(doc):
    """Whether a manifest's frames are observed as a table (not images)."""
    return any(f.get("observations", {}).get("kind") == "table" for f in doc["frames"])


def table_regions(root):
    """The regions an observation-table sequence in folder ``root`` measures, in table order."""
    return list(dict.fromkeys(read_observation_table(Path(root) / TABLE_FILE).regions))


def table_observations(doc, root, region, points=None, frames=None):
    """The table rows of ``region`` in a table sequence: (point names (P,), frame indices
    (T,), positions (P, 3), views (P, T, 3), values (P, T, 3), sigmas (P, T, 3), whether
    they are luminances (in the first channel, the others' sigma inf)); a point without a
    row in a frame gets value 0 and sigma inf (no information).  ``points``: the points to
    take (default all of the region's); ``frames``: the frames (default all with a row)."""
    table = read_observation_table(root / TABLE_FILE)
    frame_col = table.frames
    keys = [p for r, p in table.point_keys() if r == region]
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
    rows = [i for i in range(len(frame_col)) if table.regions[i] == region
            and table.points[i] in keys]
    fr = sorted({frame_col[i] for i in rows} if frames is None else set(frames))
    P, T = len(keys), len(fr)
    pos = np.zeros((P, 3))
    view = np.zeros((P, T, 3))
    view[..., 2] = 1.0
    y, sig = np.zeros((P, T, 3)), np.full((P, T, 3), np.inf)
    for i in rows:
        if frame_col[i] not in fr:
            continue
        p, t = keys.index(table.points[i]), fr.index(frame_col[i])
        pos[p], view[p, t] = table.position[i], table.view[i]
        y[p, t], sig[p, t] = np.nan_to_num(table.value[i]), table.sigma[i]
    for p in range(P):                   # a frame without a row: the view of another frame
        have = np.isfinite(sig[p, :, 0])
        view[p, ~have] = view[p, np.argmax(have)]
    return keys, fr, pos, view, y, sig, table.luminance
