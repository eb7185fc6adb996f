"""Sequence specifications (TOML or JSON): reading, validation, resolution into frames.

A spec describes a day to render: where and when, each frame's sky, the scene and its materials,
the camera, the sensor and the render settings (``scenes/specs/*.toml``, ``docs/SPEC.md``).
Every problem raises a :class:`~skyfit_mi.errors.SpecError` naming the key and the fix.
"""

import copy
import datetime as dt
import hashlib
import json
import math
import re
import sys
import tomllib
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

import numpy as np

from ..conventions import direction_from_angles
from ..physics import cie_general
from ..physics.camera import SensorModel
from ..errors import SkyfitError
from ..physics.gensky import from_gensky
from ..physics.lens import FOV_RANGE, check_distortion
from ..render.fit_model import PARAMETERS, material_dict
from ..render.scene import POSE_ANGLES, camera_matrix, pose_sd
from ..render.scene_xml import resolve_materials
from ..render.variant import VARIANTS
from ..physics.sky import (EFFICACY_CLEAR, EFFICACY_OVERCAST, GROUND_ALBEDO, SKY_TYPES,
                           CIEPhotometry, cie_general_sky, cie_sky)
from ..physics.sun import SunDisc, solar_position
from ..physics.ward import MODELS, NORMALISATIONS, raw_parameters
from .fit_result import read_fit_result
from .illumination import directional_from_record, envmap_from_record, perez_from_irradiance
from .irradiance import irradiance_at, read_irradiance
from .photo_times import wall_time_problem
from .sky_series import MASK_MARGIN_DEG, series_entry
from ..physics.turbid_sky import TURBIDITY_RANGE, turbid_sky

#: Where the shipped scenes live; a spec's ``scene.file`` is looked up beside the spec first.
SCENES_DIR = Path(__file__).resolve().parents[2] / "scenes"


class SpecError(SkyfitError):
    """A sequence spec is invalid; the message names the key and the fix."""


#: [sky] keys whose values are numbers (their ranges are checked where they are used), or text.
_SKY_NUMBERS = {"phi", "efficacy_clear", "efficacy_overcast", "cct_clear", "cct_overcast",
                "ground_albedo", "extinction", "solar_constant", "clear_zenith_luminance",
                "overcast_zenith_luminance", "diffuse_horizontal_W_m2", "direct_normal_W_m2",
                "diffuse_horizontal_lux", "global_horizontal_W_m2", "cct", "north_rotation_deg",
                "scale", "rows", "sun_mask_deg", "zenith_deg", "azimuth_deg", "solid_angle_sr",
                "cie_type", "gradation", "indicatrix", "zenith_luminance", "turbidity"}
_SKY_TEXTS = {"type", "gensky", "gensky_file", "decomposition", "irradiance_file", "file",
              "projection"}
_SCHEMA = {
    "name": None,
    "location": {"latitude_deg", "longitude_deg", "timezone", "elevation_m"},
    "time": {"date", "times", "start", "end", "step_minutes"},
    "sky": _SKY_NUMBERS | _SKY_TEXTS | {"time", "frames", "sun", "direction", "irradiance_W_m2"},
    "scene": {"file", "ground_albedo"},
    "materials": None,
    "camera": {"azimuth_deg", "angle_deg", "distance", "target", "origin", "up", "matrix",
               "fov_deg", "width", "height", "distortion", "pose_sd_deg", "photo"},
    "sensor": {"exposure", "response", "gamma", "bits", "noise_percent", "cos4"},
    "render": {"spp", "seed", "variant", "max_depth", "below_horizon", "sampler", "integrator"},
}
SKY_KINDS = tuple(SKY_TYPES) + ("cie_general", "turbid", "gensky", "perez", "envmap",
                                 "directional")
#: The keys of an HDR environment map sky and of a directional lab light
#: (:mod:`skyfit_mi.pipeline.illumination`), and the other keys each takes.
_ENVMAP_KEYS = {"file", "projection", "north_rotation_deg", "scale", "rows", "sun_mask_deg"}
_DIRECTIONAL_KEYS = {"direction", "zenith_deg", "azimuth_deg", "irradiance_W_m2", "solid_angle_sr"}
#: The keys of a CIE S 011 general sky (:func:`skyfit_mi.physics.sky.cie_general_sky`).
_CIE_GENERAL_KEYS = {"cie_type", "gradation", "indicatrix", "zenith_luminance"}
#: The keys of a turbid clear sky (:func:`skyfit_mi.physics.turbid_sky.turbid_sky`).
_TURBID_KEYS = {"turbidity"}
_ALLOWED_WITH = {"turbid": _TURBID_KEYS | {"type", "time", "cct", "sun", "ground_albedo"},
                 "cie_general": _CIE_GENERAL_KEYS | {
                     "type", "time", "cct", "sun", "extinction", "solar_constant",
                     "ground_albedo", "diffuse_horizontal_W_m2", "direct_normal_W_m2",
                     "diffuse_horizontal_lux", "irradiance_file"},
                 "envmap": _ENVMAP_KEYS | {"type", "time", "diffuse_horizontal_W_m2",
                                          "direct_normal_W_m2", "global_horizontal_W_m2",
                                          "ground_albedo", "irradiance_file"},
                 "directional": _DIRECTIONAL_KEYS | {"type", "time"}}
#: [sky] keys a measured series (``irradiance_file``) fills per frame, by the series' column.
_SERIES_KEYS = {"ghi": "global_horizontal_W_m2", "dhi": "diffuse_horizontal_W_m2",
                "dni": "direct_normal_W_m2"}
BELOW_HORIZON = ("sky", "skip")
#: Mitsuba samplers a spec may choose; multijitter stratifies the sun/sky choice, for much lower
#: noise (docs/BENCHMARKS.md, "sun_sky_path against path and Radiance rpict").
SAMPLERS = ("multijitter", "stratified", "ldsampler", "independent")
#: Integrators a spec may choose: ``sun_sky_path`` (default: separate sun and sky samples, far
#: lower error at equal time, same BENCHMARKS section) or Mitsuba's ``path``.
INTEGRATORS = ("sun_sky_path", "path")


def _unknown(section, got, allowed):
    bad = sorted(set(got) - set(allowed))
    if bad:
        raise SpecError(f"unknown key(s) {', '.join(bad)} in [{section}]; allowed: "
                        f"{', '.join(sorted(allowed))}.")


def _num(section, key, v, lo=-np.inf, hi=np.inf, integer=False):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        quotes = "; write it without quotes" if isinstance(v, str) else ""
        raise SpecError(f"[{section}] {key} must be a number, got {v!r}{quotes}.")
    if isinstance(v, int) and abs(v) > sys.float_info.max:
        raise SpecError(f"[{section}] {key} is a whole number of {len(str(abs(v)))} digits, beyond "
                        f"any float; give a value in [{lo:g}, {hi:g}].")
    if not math.isfinite(v):
        raise SpecError(f"[{section}] {key} must be a number, got {v!r}.")
    if integer and int(v) != v:
        raise SpecError(f"[{section}] {key} must be a whole number, got {v!r}.")
    if not lo <= v <= hi:
        raise SpecError(f"[{section}] {key} = {v!r} is outside [{lo:g}, {hi:g}]; give a value in "
                        "that range.")
    return int(v) if integer else float(v)


def _plain(v):
    """The spec with TOML's native dates and times (``date = 2026-08-16``, unquoted) as the ISO
    strings a quoted value gives, so that both spellings mean the same and the spec is JSON."""
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, list):
        return [_plain(x) for x in v]
    if isinstance(v, (dt.datetime, dt.date, dt.time)):
        return v.isoformat()
    return v


#: Offsets from UTC that exist in civil time [hours] (UTC-12 to UTC+14).
UTC_OFFSETS = (-12.0, 14.0)


def _text(section, key, v):
    if not isinstance(v, str) or not v:
        raise SpecError(f"[{section}] {key} must be text, got {v!r}.")
    return v


def _tz(name):
    if name[:1] in "+-" and ":" in name:
        hh, _, mm = name[1:].partition(":")
        if not (hh.isdigit() and mm.isdigit() and len(mm) == 2):
            raise SpecError(f"[location] timezone {name!r} is not an offset; write it as '+01:00'.")
        hours = (1 if name[0] == "+" else -1) * (int(hh) + int(mm) / 60)
        if not UTC_OFFSETS[0] <= hours <= UTC_OFFSETS[1] or int(mm) >= 60:
            raise SpecError(f"[location] timezone {name!r} is not a civil time offset; give one "
                            "from '-12:00' to '+14:00' (minutes below 60).")
        return dt.timezone(dt.timedelta(hours=hours))
    try:
        return ZoneInfo(name)
    except (ZoneInfoNotFoundError, ValueError):
        raise SpecError(f"[location] timezone {name!r} is not a time zone; give an IANA name such "
                        "as 'Europe/London' or 'UTC', or an offset such as '+01:00'.") from None


#: A wall time on [time] date: HH:MM or HH:MM:SS (their ranges checked by datetime.time).
_CLOCK = re.compile(r"[0-9]{2}:[0-9]{2}(:[0-9]{2})?")


def _clock(s, date, tz, key):
    try:
        if not isinstance(s, str):
            raise TypeError(s)
        if "T" in s or len(s) > 8:
            t = dt.datetime.fromisoformat(s)
            if t.tzinfo is not None:
                off = t.utcoffset() / dt.timedelta(hours=1)
                if not UTC_OFFSETS[0] <= off <= UTC_OFFSETS[1]:
                    raise ValueError(off)
            if t.tzinfo is not None:
                return t
        elif date is None or not _CLOCK.fullmatch(s):
            raise ValueError(s)
        else:
            t = dt.datetime.combine(date, dt.time(*(int(x) for x in s.split(":"))))
    except (ValueError, TypeError, OverflowError):
        raise SpecError(f"[time] {key} {s!r} is not a time; write 'HH:MM' or 'HH:MM:SS' (on "
                        "[time] date) or an ISO date-time such as '2026-06-21T06:00'.") from None
    problem = wall_time_problem(t, tz)
    if problem is not None:
        raise SpecError(f"[time] {key} {s!r} {problem}; give it as an ISO date-time with its "
                        "offset, such as '2026-10-25T01:30+01:00'.")
    return t.replace(tzinfo=tz)


@dataclass
class Frame:
    """One resolved frame: its time (None for a lab light: frames by index), sun (a lab
    light's direction) and sky, and whether it is rendered."""

    index: int
    time: dt.datetime
    sun_zenith_deg: float
    sun_azimuth_deg: float
    sky: object
    skipped: bool = False
    below_horizon: bool = False


@dataclass
class Spec:
    """A validated spec: the raw dictionary plus resolved pieces."""

    raw: dict
    base_dir: Path
    scene_file: Path
    materials: dict
    camera: dict
    sensor: dict
    render: dict
    frames: list = field(default_factory=list)

    @property
    def lab(self):
        """Whether the frames are lab lights identified by index (no [time], no site)."""
        return "time" not in self.raw

    def run_id(self):
        """Hash of everything that determines the output (the resolved spec, and the contents
        of its environment maps)."""
        # the scene's text as UTF-8, other bytes kept as they are (an XML may declare Latin-1)
        scene = self.scene_file.read_text(encoding="utf-8", errors="surrogateescape")
        doc = {"spec": self.raw, "scene": scene, "materials": self.materials}
        maps = sorted({f.sky.info["file"] for f in self.frames if f.sky.envmap is not None})
        if maps:
            doc["envmaps"] = {p: hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in maps}
        return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _utf8(path, what):
    """The text of ``path`` as UTF-8, a leading byte-order mark (Windows Notepad's) dropped."""
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise SpecError(f"{what} {str(path)!r} is not UTF-8 text (byte "
                        f"0x{exc.object[exc.start]:02x} at offset {exc.start}); save it as "
                        "UTF-8.") from None


def read_spec(path):
    """The unvalidated tables of a spec file (``.toml`` or ``.json``)."""
    path = Path(path)
    if path.is_dir():
        inside = sorted(p.name for p in path.iterdir() if p.suffix.lower() in (".toml", ".json"))
        raise SpecError(f"spec {str(path)!r} is a folder; give a spec file (.toml or .json)"
                        + (f", such as {path / inside[0]}" if inside else "") + ".")
    if not path.is_file():
        raise SpecError(f"spec file {str(path)!r} does not exist.")
    text = _utf8(path, "spec file")
    is_json = path.suffix.lower() == ".json"
    try:
        return json.loads(text) if is_json else tomllib.loads(text)
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as exc:
        raise SpecError(f"{path.name} is not valid {'JSON' if is_json else 'TOML'}: {exc}") from None
    except ValueError:              # Python reads no integer of over 4300 digits
        raise SpecError(f"{path.name} holds a number of over 4300 digits; give every number in "
                        "ordinary notation (1e30, not its digits).") from None


def load_spec(path):
    """Read and validate a spec file (``.toml`` or ``.json``); returns :class:`Spec`."""
    return validate_spec(read_spec(path), Path(path).parent)


def validate_spec(raw, base_dir=".", sun=None):
    """Validate a spec dictionary and resolve its frames; returns :class:`Spec`.  ``sun``:
    {ISO time: (zenith, azimuth) [degrees]} from a manifest of this spec, used when it holds
    every time, to skip pvlib's slow import."""
    raw = _plain(copy.deepcopy(raw))
    base_dir = Path(base_dir)
    if not isinstance(raw, dict):
        raise SpecError("a spec must be a table of sections ([location], [time], ...).")
    _unknown("spec", raw, _SCHEMA)
    lab = "time" not in raw                 # lab lights: frames by index, no time or site
    for sec in ("scene", "camera") + (() if lab else ("location",)):
        if sec not in raw:
            raise SpecError(f"the spec has no [{sec}] section; it is required (see scenes/specs/ "
                            "for examples).")
    for sec, keys in _SCHEMA.items():
        if keys and sec in raw and sec != "sky":
            if not isinstance(raw[sec], dict):
                raise SpecError(f"[{sec}] must be a table.")
            _unknown(sec, raw[sec], keys)

    if lab:
        if "location" in raw:
            raise SpecError("the spec has [location] but no [time]; a sequence of lab lights "
                            "(every [[sky]] directional) takes neither, a day needs both.")
        times, tz, elevation = None, None, 0.0
    else:
        loc = raw["location"]
        for k in ("latitude_deg", "longitude_deg", "timezone"):
            if k not in loc:
                raise SpecError(f"[location] needs {k}.")
        lat = _num("location", "latitude_deg", loc["latitude_deg"], -90, 90)
        lon = _num("location", "longitude_deg", loc["longitude_deg"], -180, 180)
        elevation = _num("location", "elevation_m", loc.get("elevation_m", 0.0), -500, 9000)
        tz = _tz(_text("location", "timezone", loc["timezone"]))
        times = _times(raw["time"], tz)

    render = {"spp": 64, "seed": 0, "variant": "llvm_ad_rgb", "max_depth": 4, "below_horizon": "sky",
              "sampler": "multijitter", "integrator": INTEGRATORS[0], **raw.get("render", {})}
    for key, valid in (("sampler", SAMPLERS), ("integrator", INTEGRATORS)):
        if render[key] not in valid:
            raise SpecError(f"[render] {key} {render[key]!r}; valid: {', '.join(valid)}.")
    for key, lo, hi in (("spp", 1, 1 << 20), ("seed", 0, 2**31 - 1), ("max_depth", 1, 64)):
        _num("render", key, render[key], lo, hi, integer=True)
    if render["variant"] not in VARIANTS:
        raise SpecError(f"[render] variant {render['variant']!r}; valid: 'llvm_ad_rgb' (CPU), "
                        "'cuda_ad_rgb' (NVIDIA GPU).")
    if render["below_horizon"] not in BELOW_HORIZON:
        raise SpecError(f"[render] below_horizon = {render['below_horizon']!r}; give 'sky' (render "
                        "the sky alone) or 'skip' (leave the frame out).")

    scene_file = _scene_file(raw["scene"], base_dir)
    sensor = _sensor(raw.get("sensor", {}))
    camera = _camera(raw["camera"])
    materials = _materials(raw.get("materials", {}), base_dir)
    try:
        resolve_materials(scene_file, materials)       # the scene parses; its overrides exist
    except SkyfitError as exc:
        raise SpecError(f"[materials] {exc}") from None

    if lab:
        entries = _lab_entries(raw.get("sky"))
        times = [None] * len(entries)
        zeniths = azimuths = [np.nan] * len(entries)      # each light's own, below
    else:
        if sun and all(t.isoformat() in sun for t in times):
            zeniths, azimuths = np.array([sun[t.isoformat()] for t in times], dtype=float).T
        else:
            pos = solar_position(times, lat, lon, elevation=elevation)
            zeniths, azimuths = np.atleast_1d(pos.zenith_deg), np.atleast_1d(pos.azimuth_deg)
        entries = _with_series(_sky_entries(raw.get("sky", {"type": "clear"}), times, tz), times,
                               tz, base_dir)
    frames = []
    for i, (t, z, a, entry) in enumerate(zip(times, zeniths, azimuths, entries)):
        sky = _make_sky(entry, float(z), float(a), t, base_dir, i, elevation)
        if entry["type"] == "directional":      # the lab light is the frame's sun
            z, a = sky.info["sun_zenith_deg"], sky.info["sun_azimuth_deg"]
        below = (sky.sun_direction[2] <= 0.0) if entry.get("type") == "gensky" else z >= 90.0
        frames.append(Frame(i, t, float(z), float(a), sky,
                            skipped=bool(below and render["below_horizon"] == "skip"),
                            below_horizon=bool(below)))
    return Spec(raw, base_dir, scene_file, materials, camera, sensor, render, frames)


def _lab_entries(sec):
    """The [[sky]] entries of a spec without [time]: lab lights, one frame each in the order
    listed, every one directional (frames by index: no time, date or site)."""
    if sec is None:
        raise SpecError("the spec has no [time] section; it is required unless every [[sky]] is "
                        "a directional lab light (then the frames are the lights, by index).")
    entries = _sky_entries(sec, None, None)
    other = next((i for i, e in enumerate(entries) if e["type"] != "directional"), None)
    if other is not None:
        which = "[sky]" if isinstance(sec, dict) and "frames" not in sec else f"[[sky]] {other}"
        raise SpecError(f"the spec has no [time] section, but {which} is a "
                        f"{entries[other]['type']} sky; frames by index are for directional lab "
                        "lights only: give [time] and [location] for a day's sky.")
    return entries


def _times(sec, tz):
    if "times" in sec and (not isinstance(sec["times"], list) or not sec["times"]):
        raise SpecError("[time] times must be a non-empty list such as ['12:00', '12:30'].")
    if "date" not in sec and not all("T" in str(t) for t in sec.get("times", ["x"])):
        raise SpecError("[time] needs date = 'YYYY-MM-DD' (or ISO date-times in times).")
    try:
        date = dt.date.fromisoformat(sec["date"]) if "date" in sec else None
    except (ValueError, TypeError):             # TypeError: not text (20260621)
        raise SpecError(f"[time] date {sec['date']!r} is not a date; write 'YYYY-MM-DD'.") from None
    if "times" in sec:
        if any(k in sec for k in ("start", "end", "step_minutes")):
            raise SpecError("[time] give either times = [...] or start/end/step_minutes, not both.")
        out = [_clock(s, date, tz, "time") for s in sec["times"]]
    else:
        missing = [k for k in ("start", "end", "step_minutes") if k not in sec]
        if missing:
            raise SpecError(f"[time] needs times = [...] or start, end and step_minutes; missing "
                            f"{', '.join(missing)}.")
        start, end = _clock(sec["start"], date, tz, "start"), _clock(sec["end"], date, tz, "end")
        step = _num("time", "step_minutes", sec["step_minutes"], 1, 24 * 60)
        # steps of real time: through UTC, so that a daylight-saving change keeps them even
        start_utc, end_utc = (t.astimezone(dt.timezone.utc) for t in (start, end))
        if end_utc < start_utc:
            raise SpecError(f"[time] end {sec['end']} is before start {sec['start']} (for a "
                            "range past midnight, give ISO date-times).")
        n = int(np.floor((end_utc - start_utc) / dt.timedelta(minutes=step) + 1e-9)) + 1
        out = [(start_utc + k * dt.timedelta(minutes=step)).astimezone(start.tzinfo)
               for k in range(n)]
    if len(out) > 10000:
        raise SpecError(f"[time] gives {len(out)} frames; at most 10000.")
    for a, b in zip(out, out[1:]):
        if b.timestamp() <= a.timestamp():        # instants: the same zone compares wall time
            same = a.timestamp() == b.timestamp()
            raise SpecError(f"[time] times must increase: {b.isoformat()} "
                            f"{'repeats' if same else 'comes after'} {a.isoformat()}; list each "
                            "time once, in order.")
    return out


def _scene_file(sec, base_dir):
    if "file" not in sec:
        raise SpecError("[scene] needs file = 'disc.xml' (a file beside the spec or in scenes/).")
    _text("scene", "file", sec["file"])
    for cand in (base_dir / sec["file"], SCENES_DIR / sec["file"]):
        if cand.is_file():
            break
    else:
        shipped = ", ".join(sorted(p.name for p in SCENES_DIR.glob("*.xml")))
        raise SpecError(f"[scene] file {sec['file']!r} not found beside the spec or in scenes/ "
                        f"(shipped: {shipped}).")
    if "ground_albedo" in sec:
        _num("scene", "ground_albedo", sec["ground_albedo"], 0, 1)
    return cand.resolve()


def _sensor(sec):
    s = {"exposure": "auto", "response": "linear", "gamma": 2.2, "bits": 8, "noise_percent": 0.0,
         "cos4": False, **sec}
    if s["exposure"] != "auto":
        _num("sensor", "exposure", s["exposure"], 1e-12, 1e12)
    for k in ("gamma", "noise_percent", "bits"):    # their ranges and depths: SensorModel's
        _num("sensor", k, s[k], integer=k == "bits")
    _text("sensor", "response", s["response"])
    if not isinstance(s["cos4"], bool):
        raise SpecError(f"[sensor] cos4 must be true or false (the cos^4 falloff), got "
                        f"{s['cos4']!r}.")
    try:
        SensorModel(exposure=1.0 if s["exposure"] == "auto" else s["exposure"],
                    **{k: s[k] for k in ("response", "gamma", "bits", "noise_percent", "cos4")})
    except SkyfitError as exc:
        raise SpecError(f"[sensor] {exc}") from None
    return s


def _camera(sec):
    c = {"fov_deg": 30.0, "width": 128, "height": 128, "target": [0.0, 0.0, 0.0], **sec}
    forms = [k for k in ("azimuth_deg", "origin", "matrix") if k in sec]
    if len(forms) != 1:
        raise SpecError("[camera] place the camera one way: azimuth_deg + angle_deg + distance "
                        "(compass placement), origin (+ target, up), or matrix (4x4 to_world).")
    if "azimuth_deg" in sec:
        for k in ("angle_deg", "distance"):
            if k not in sec:
                raise SpecError(f"[camera] compass placement needs {k}.")
        _num("camera", "angle_deg", c["angle_deg"], 0, 89)
        _num("camera", "distance", c["distance"], 1e-6, 1e6)
        _num("camera", "azimuth_deg", c["azimuth_deg"], -360, 360)
    for k in ("target", "origin", "up"):
        if k in c and (not isinstance(c[k], list) or len(c[k]) != 3):
            raise SpecError(f"[camera] {k} must be a list of 3 numbers [x east, y north, z up].")
        for i, v in enumerate(c.get(k, ())):
            _num("camera", f"{k}[{i}]", v)
    if "matrix" in c and (not isinstance(c["matrix"], list) or len(c["matrix"]) != 4 or not all(
            isinstance(row, list) and len(row) == 4 for row in c["matrix"])):
        raise SpecError("[camera] matrix must be 4 rows of 4 numbers (the camera's to_world).")
    for i, row in enumerate(c.get("matrix", ())):
        for j, v in enumerate(row):
            _num("camera", f"matrix[{i}][{j}]", v)
    _num("camera", "fov_deg", c["fov_deg"], *FOV_RANGE)
    _num("camera", "width", c["width"], 1, 16384, integer=True)
    _num("camera", "height", c["height"], 1, 16384, integer=True)
    if "distortion" in c:
        k = c["distortion"]
        if not isinstance(k, list) or len(k) not in (1, 2):
            raise SpecError("[camera] distortion must be [k1] or [k1, k2] (radial, OpenCV's "
                            f"convention), got {k!r}.")
        for i, v in enumerate(k):
            _num("camera", f"distortion[{i}]", v)
    if isinstance(c.get("pose_sd_deg"), dict):     # numbers as every spec number; ranges below
        c["pose_sd_deg"] = {k: _num("camera", f"pose_sd_deg {k}", v) if k in POSE_ANGLES else v
                            for k, v in c["pose_sd_deg"].items()}
    elif "pose_sd_deg" in c:
        c["pose_sd_deg"] = _num("camera", "pose_sd_deg azimuth", c["pose_sd_deg"])
    try:
        if "distortion" in c:
            c["distortion"] = check_distortion(c["distortion"], c["fov_deg"], c["width"],
                                               c["height"])
        camera_matrix(c)
        if "pose_sd_deg" in c:
            c["pose_sd_deg"] = pose_sd(c["pose_sd_deg"])
    except SkyfitError as exc:
        raise SpecError(f"[camera] {exc}") from None
    if "photo" in c and not (isinstance(c["photo"], str) and c["photo"]):
        raise SpecError(f"[camera] photo = {c['photo']!r}: give the file name of the photograph "
                        "the pose was marked on (skyfit camera --photo writes it).")
    return c


def _fitted_material(name, m, base_dir):
    """The material a fit JSON (``fit_NAME.json`` of ``skyfit fit``) describes: its model,
    normalisation and fitted parameters, with ``source`` naming the file and region."""
    if set(m) != {"fit"}:
        raise SpecError(f"[materials.{name}] takes either fit = \"fit_NAME.json\" or a model "
                        f"and its parameters, not both (got {', '.join(sorted(m))}).")
    path = base_dir / _text(f"materials.{name}", "fit", m["fit"])
    try:
        result = read_fit_result(path)
    except SkyfitError as exc:
        raise SpecError(f"[materials.{name}] {exc} (Paths are relative to the spec.)") from None
    model = result["model"]
    theta = [result["parameters"][k] for k in PARAMETERS[model]]
    out = material_dict(model, theta, result.get("normalisation", "ward"))
    return {**out, "source": f"fit {path.name} (region {result.get('region', '?')})"}


#: The material parameters that may be an RGB triple [r, g, b], by Ward model.
_RGB_PARAMETERS = {"raw": ("rho_d", "rho_s"), "colour": ("C",)}


def _materials(sec, base_dir):
    if not isinstance(sec, dict):
        raise SpecError(f"[materials] must be a table of tables ([materials.disc] model = ..., "
                        f"rho_s = ...), got {sec!r}.")
    out = {}
    for name, m in sec.items():
        if not isinstance(m, dict):
            raise SpecError(f"[materials.{name}] must be a table (model = ..., rho_s = ...).")
        m = dict(m)
        source = None
        if "fit" in m:
            m = _fitted_material(name, m, base_dir)
            source = m.pop("source")
        model = m.get("model", "raw")
        norm = m.pop("normalisation", "ward")
        if norm not in NORMALISATIONS:
            raise SpecError(f"[materials.{name}] normalisation {norm!r}; valid: "
                            f"{', '.join(NORMALISATIONS)}.")
        if not isinstance(model, str) or model not in MODELS:
            raise SpecError(f"[materials.{name}] unknown Ward model {model!r}; valid: "
                            f"{', '.join(MODELS)}.")
        params = {k: v for k, v in m.items() if k != "model"}
        for k in set(params) & set(MODELS[model]):
            rgb = isinstance(params[k], list) and k in _RGB_PARAMETERS.get(model, ())
            for i, v in enumerate(params[k] if rgb else [params[k]]):
                _num(f"materials.{name}", f"{k}[{i}]" if rgb else k, v)
        try:
            raw_parameters(model, **params)
        except SkyfitError as exc:
            raise SpecError(f"[materials.{name}] {exc}") from None
        out[name] = {"model": model, "normalisation": norm, **params}
        if source:
            out[name]["source"] = source
    return out


def _indices(ix):
    """Entry indices as text: 'entry 3', 'entries 0, 2 and 5', the first five of more then
    '...'."""
    shown = [str(i) for i in ix[:5]] + (["..."] if len(ix) > 5 else [])
    if len(shown) == 1:
        return f"entry {shown[0]}"
    return f"entries {', '.join(shown[:-1])} and {shown[-1]}"


def _frame_times(times):
    """The frames' times as text: '09:00, 12:00, 15:00', or the first and last of many."""
    text = [f"{t:%H:%M:%S}".removesuffix(":00") for t in times]
    return ", ".join(text) if len(text) <= 6 else f"{len(text)} times, {text[0]} to {text[-1]}"


def _sky_entries(sec, times, tz):
    if isinstance(sec, dict):
        base = {k: v for k, v in sec.items() if k != "frames"}
        entries, where = sec.get("frames"), "[sky] frames"
    elif isinstance(sec, list):
        base, entries, where = {}, sec, "[[sky]]"
    else:
        raise SpecError("[sky] must be a table, or [[sky]] a list of tables (one per frame).")
    _unknown("sky", base, _SCHEMA["sky"] - {"frames"})
    if entries is not None:
        if not isinstance(entries, list) or not entries:
            raise SpecError(f"{where} must be a list of tables, one per frame; got {entries!r}.")
        for i, e in enumerate(entries):
            if not isinstance(e, dict):
                raise SpecError(f"{where} entry {i} is {e!r}, not a table; give one table of sky "
                                "keys per frame.")
            _unknown("sky", e, _SCHEMA["sky"] - {"frames"})
    if times is None and any("time" in e for e in [base, *(entries or [])]):
        raise SpecError("[sky] time: lab lights without [time] are frames by index, in the order "
                        "listed; drop time (or give [time] and [location] for a day).")
    if "time" in base:
        raise SpecError("[sky] time: one [sky] table is every frame's sky; give each frame's sky "
                        "its time in a [[sky]] table, or drop time.")
    timed = [i for i, e in enumerate(entries or []) if "time" in e]
    if entries is None:
        out = [dict(base) for _ in (times or [None])]
    elif timed and len(timed) < len(entries):
        untimed = sorted(set(range(len(entries))) - set(timed))
        raise SpecError(f"{where} gives a time in {_indices(timed)} but not in "
                        f"{_indices(untimed)}; give every entry its frame's time, or none (one "
                        "entry per frame, in order).")
    elif timed:
        by_time = {}
        for i, e in enumerate(entries):
            # by instant: in a repeated hour equal wall times are different instants
            at = _clock(e["time"], times[0].date(), tz, "sky time").timestamp()
            if at in by_time:
                raise SpecError(f"{where} entries {by_time[at][0]} and {i} both have time "
                                f"{e['time']!r}; give each frame's sky once.")
            by_time[at] = i, e
        missing = [t for t in times if t.timestamp() not in by_time]
        if missing:
            raise SpecError(f"[[sky]] has no entry for {missing[0]:%H:%M%z}; give one per frame "
                            "time (or drop 'time' and list one per frame in order).")
        frames = {t.timestamp() for t in times}
        extra = [i for at, (i, _) in by_time.items() if at not in frames]
        if extra:
            raise SpecError(f"{where} entry {extra[0]} has time {entries[extra[0]]['time']!r}, "
                            f"which is no frame's ([time] gives {_frame_times(times)}); drop the "
                            "entry or add its time to [time].")
        out = [{**base, **by_time[t.timestamp()][1]} for t in times]
    elif times is not None and len(entries) != len(times):
        raise SpecError(f"[[sky]] lists {len(entries)} skies for {len(times)} frames; give one "
                        "per frame, or a 'time' in each.")
    else:                                   # one entry per frame, in order
        out = [{**base, **e} for e in entries]
    for e in out:
        for k in _SKY_NUMBERS & set(e):
            _num("sky", k, e[k])
        for k in _SKY_TEXTS & set(e):
            _text("sky", k, e[k])
        if "sun" in e and not isinstance(e["sun"], bool):
            raise SpecError(f"[sky] sun must be true or false (draw the sun's disc), got {e['sun']!r}.")
        e.setdefault("type", "gensky" if ("gensky" in e or "gensky_file" in e) else "clear")
        if e["type"] not in SKY_KINDS:
            raise SpecError(f"[sky] type {e['type']!r} is unknown; valid: {', '.join(SKY_KINDS)}.")
        if e["type"] == "intermediate" and "phi" not in e:
            raise SpecError("[sky] an intermediate sky needs phi (sun probability) in [0, 1].")
        if "phi" in e and e["type"] != "intermediate":
            raise SpecError(f"[sky] phi (the sun's probability) belongs to an intermediate sky, not "
                            f"to a {e['type']} one; drop phi or set type = 'intermediate'.")
        if "phi" in e:
            _num("sky", "phi", e["phi"], 0, 1)
        perez_only = sorted({"global_horizontal_W_m2", "decomposition", "cct"} & set(e)
                            - ({"cct"} if e["type"] in ("cie_general", "turbid") else set())
                            - ({"global_horizontal_W_m2"} if e["type"] == "envmap" else set()))
        if perez_only and e["type"] != "perez":
            raise SpecError(f"[sky] {', '.join(perez_only)} belong to a Perez sky (type = "
                            f"'perez'), not to a {e['type']} one.")
        _check_light_keys(e)
    return out


def _check_light_keys(e):
    """Refuse the keys of an envmap or directional sky on other types, and other types' keys
    on those."""
    for kind, own in (("envmap", _ENVMAP_KEYS), ("directional", _DIRECTIONAL_KEYS),
                      ("cie_general", _CIE_GENERAL_KEYS), ("turbid", _TURBID_KEYS)):
        if e["type"] == kind:
            bad = sorted(set(e) - _ALLOWED_WITH[kind])
            if bad:
                raise SpecError(f"[sky] a {kind} sky takes {', '.join(sorted(_ALLOWED_WITH[kind]))}"
                                f"; drop {', '.join(bad)}.")
        elif own & set(e):
            keys = sorted(own & set(e))
            raise SpecError(f"[sky] {', '.join(keys)}: only type = '{kind}' takes "
                            f"{'this key' if len(keys) == 1 else 'these keys'}, not a {e['type']} "
                            f"sky; drop {'it' if len(keys) == 1 else 'them'} or set type = '{kind}'.")
    if e["type"] == "envmap" and "file" not in e:
        raise SpecError("[sky] an envmap sky needs file = 'maps/sky_{index:03d}.exr' (an HDR map "
                        "beside the spec; {index} and {time:%H%M} name each frame's).")
    if e["type"] == "cie_general":
        _cie_general_parameters(e)
    if e["type"] == "turbid":
        if "turbidity" not in e:
            raise SpecError("[sky] a turbid sky needs turbidity (the Linke turbidity, "
                            f"{TURBIDITY_RANGE[0]:g}-{TURBIDITY_RANGE[1]:g}: about 2 very clear, "
                            "3-4 a common clear day, 5-7 hazy).")
        _num("sky", "turbidity", e["turbidity"], *TURBIDITY_RANGE)
    if e["type"] == "directional":
        if "irradiance_W_m2" not in e:
            raise SpecError("[sky] a directional light needs irradiance_W_m2 (normal to the beam, "
                            "one number or [r, g, b]).")
        if ("direction" in e) == ("zenith_deg" in e or "azimuth_deg" in e) \
                or ("direction" not in e and not {"zenith_deg", "azimuth_deg"} <= set(e)):
            raise SpecError("[sky] give a directional light's direction either as direction = "
                            "[x east, y north, z up] or as zenith_deg and azimuth_deg.")
        for key, n in (("direction", (3,)), ("irradiance_W_m2", (1, 3))):
            if key not in e:
                continue
            v = [e[key]] if isinstance(e[key], (int, float)) and key == "irradiance_W_m2" else e[key]
            if not isinstance(v, list) or len(v) not in n:
                raise SpecError(f"[sky] {key} must be {' or '.join(map(str, n))} numbers, got "
                                f"{e[key]!r}.")
            for i, x in enumerate(v):
                _num("sky", f"{key}[{i}]", x)


def _cie_general_parameters(e):
    """a, b, c, d, e of a cie_general [sky] entry: a standard type, or group indices."""
    by_type, by_groups = "cie_type" in e, bool({"gradation", "indicatrix"} & set(e))
    if by_type == by_groups or (by_groups and not {"gradation", "indicatrix"} <= set(e)):
        raise SpecError("[sky] a cie_general sky needs either cie_type (a CIE S 011 standard type "
                        "1-15; 12 is the CIE clear sky) or both gradation and indicatrix (group "
                        "indices 1-6, e.g. 5.98 and 4 for the measured clear sky of docs/"
                        "BENCHMARKS.md), not both.")
    try:
        if by_type:
            return cie_general.standard_parameters(e["cie_type"])
        return cie_general.group_parameters(e["gradation"], e["indicatrix"])
    except SkyfitError as exc:
        raise SpecError(f"[sky] {exc}") from None


def _with_series(entries, times, tz, base_dir):
    """Entries with ``irradiance_file`` get that series' values at their frame's time."""
    series = {}
    out = []
    for e, t in zip(entries, times):
        if "irradiance_file" in e:
            path = base_dir / e["irradiance_file"]
            try:
                if path not in series:
                    series[path] = read_irradiance(path, tz, year=t.year)
                values = irradiance_at(series[path], [t], path)[0]
            except SkyfitError as exc:
                raise SpecError(f"[sky] irradiance_file: {exc}") from None
            ghi_alone = e["type"] == "envmap" and "ghi" in values and "dni" not in values
            if e["type"] not in ("perez", "envmap") and not {"dhi", "dni"} <= set(values) \
                    or e["type"] == "envmap" and not ghi_alone and "dni" not in values:
                raise SpecError(f"[sky] irradiance_file {e['irradiance_file']!r} gives "
                                f"{', '.join(values)}; a {e['type']} sky is scaled by dhi and "
                                "dni, so give both"
                                + (" (or ghi: the sun takes what the map leaves of it)"
                                   if e["type"] == "envmap" else "")
                                + ", or use type = 'perez' (ghi alone is split).")
            if e["type"] != "perez" and not ghi_alone:
                values.pop("ghi", None)
            e = {**e, **{_SERIES_KEYS[k]: v for k, v in values.items()}}
        out.append(e)
    return out


def _light(e, zenith, azimuth, t, index, base_dir):
    """The Sky of an envmap or directional [sky] entry (:mod:`.illumination`)."""
    if e["type"] == "directional":
        rec = {k: e[k] for k in ("direction", "irradiance_W_m2", "solid_angle_sr") if k in e}
        if "direction" not in rec:
            _num("sky", "zenith_deg", e["zenith_deg"], 0, 180)
            rec["direction"] = direction_from_angles(np.radians(e["zenith_deg"]),
                                                     np.radians(e["azimuth_deg"]))
        return directional_from_record(rec)
    try:
        name = e["file"].format(index=index, time=t)
    except (KeyError, IndexError, ValueError, AttributeError) as exc:
        raise SpecError(f"[sky] file {e['file']!r} is not a pattern of {{index}} and {{time}} "
                        f"({type(exc).__name__}: {exc}); write e.g. 'sky_{{index:03d}}.exr' or "
                        "'sky_{time:%H%M}.exr'.") from None
    rec = {"file": name, **{k: e[k] for k in ("projection", "north_rotation_deg", "scale", "rows",
                                              "sun_mask_deg", "diffuse_horizontal_W_m2",
                                              "direct_normal_W_m2", "global_horizontal_W_m2",
                                              "ground_albedo") if k in e}}
    if name.endswith(".json"):
        rec = _series_record(rec, base_dir, t, zenith, azimuth)
    return envmap_from_record(rec, base_dir, zenith, azimuth)


#: The [sky] keys that give an envmap's measured irradiance.
_MEASURED_KEYS = {"diffuse_horizontal_W_m2", "direct_normal_W_m2", "global_horizontal_W_m2"}


#: Largest angle [deg] between a sky map's clipped sun and the sun's computed position: beyond,
#: the fisheye's orientation, projection or clock is wrong (a level fisheye with the right north
#: and clock puts it within the sun's motion between map and frame, 1.25 deg in 5 minutes).
SUN_OFF_DEG = 5.0


def _series_record(rec, base_dir, t, zenith, azimuth):
    """An envmap record naming a sky series made the record of the map nearest time ``t``:
    file, projection, sun mask and (unless measured irradiance is given) the card's global
    horizontal irradiance times ``scale``.  SpecError where the map's clipped sun lies over
    :data:`SUN_OFF_DEG` from the sun at ``zenith``, ``azimuth`` [deg]."""
    try:
        entry, doc = series_entry(base_dir / rec["file"], t)
    except SkyfitError as exc:
        raise SpecError(f"[sky] file: {exc}") from None
    centre = entry.get("clipped_centre_deg")
    # the clipped pixels' centre is the sun's where none clip far from it (bright clouds)
    if centre is not None and not entry.get("clipped_elsewhere") and zenith < 90.0:
        north = rec.get("north_rotation_deg", 0.0)
        seen = direction_from_angles(*np.radians([centre[0], centre[1] + north]))
        off = np.degrees(np.arccos(np.clip(seen @ direction_from_angles(
            *np.radians([zenith, azimuth])), -1.0, 1.0)))
        if off > SUN_OFF_DEG:
            turn = (azimuth - centre[1] + 180.0) % 360.0 - 180.0
            hint = (f"; north_rotation_deg = {turn:.1f} would put it on the sun"
                    if abs(centre[0] - zenith) < SUN_OFF_DEG else "")
            raise SpecError(
                f"[sky] file {rec['file']}: the map at {entry['time']} has its clipped sun at "
                f"zenith {centre[0]:.1f}, azimuth {(centre[1] + north) % 360.0:.1f} deg, "
                f"{off:.1f} deg from the sun's position at {t.isoformat()} ({zenith:.1f}, "
                f"{azimuth:.1f} deg): check the fisheye's north_rotation_deg (the compass "
                "azimuth of the image's top), that the image is not mirrored, that the lens is "
                "equidistant and level, and the clocks" + hint + ".")
    if rec.get("projection", doc["projection"]) != doc["projection"]:
        raise SpecError(f"[sky] projection = {rec['projection']!r}, but the series "
                        f"{rec['file']} holds {doc['projection']} maps; drop projection.")
    out = {**rec, "file": str(Path(rec["file"]).parent / entry["file"]),
           "projection": doc["projection"]}
    # the mask of the map's own clipped sun (a hazy map's would take a clear map's sky), else
    # the series' (older series record only that)
    mask = (round(entry["clipped_radius_deg"] + MASK_MARGIN_DEG, 1)
            if entry.get("clipped_pixels") else None) if "clipped_radius_deg" in entry \
        else doc.get("sun_mask_deg")
    if mask and "sun_mask_deg" not in rec:
        out["sun_mask_deg"] = mask
    given = _MEASURED_KEYS & set(rec)
    if entry.get("sun_hidden") and given <= {"diffuse_horizontal_W_m2"}:
        out["direct_normal_W_m2"] = 0.0     # the card saw the sky's own light: no disc
        out["sun_measured"] = True
    elif "global_horizontal_W_m2" in entry and given <= {"diffuse_horizontal_W_m2"}:
        # the card's global irradiance on the map's scale, or in the ratio the card saw to the
        # map where a measured diffuse irradiance rescales the map
        out["global_horizontal_W_m2"] = entry["global_horizontal_W_m2"] * (
            rec["diffuse_horizontal_W_m2"] / entry["map_horizontal_W_m2"] if given
            else rec.get("scale", 1.0))
        out["sun_measured"] = True          # by the card, to its sun_sd
        if "sun_sd" in entry:
            out["sun_sd"] = entry["sun_sd"]
    elif given <= {"diffuse_horizontal_W_m2"} and entry.get("clipped_pixels") \
            and zenith < 90.0:
        raise SpecError(f"[sky] file {rec['file']}: the map at {entry['time']} clips the sun "
                        f"({entry['clipped_pixels']} pixels in every shot) and the series has no "
                        "card, so the sun's light is unknown: make the series with --card, or "
                        "give the measured direct_normal_W_m2 (or global_horizontal_W_m2) in "
                        "[sky].")
    return out


#: The [sky] keys of a CIE sky's photometry, named as the fields of
#: :class:`~skyfit_mi.physics.sky.CIEPhotometry`.
_CIE_PHOTOMETRY_KEYS = tuple(f.name for f in fields(CIEPhotometry))
#: The [sky] keys of the thesis's sun disc, and the :class:`~skyfit_mi.physics.sun.SunDisc`
#: fields they give.
_SUN_DISC_KEYS = {"sun": "drawn", "extinction": "extinction", "solar_constant": "solar_constant"}


def _sun_disc(e):
    """The :class:`~skyfit_mi.physics.sun.SunDisc` of a [sky] entry ``e`` (its ``sun``,
    ``extinction`` and ``solar_constant``; the thesis's where not given)."""
    return SunDisc(**{f: e[k] for k, f in _SUN_DISC_KEYS.items() if k in e})


def _make_sky(e, zenith, azimuth, t, base_dir, index, elevation=0.0):
    try:
        if e["type"] in ("envmap", "directional"):
            return _light(e, zenith, azimuth, t, index, base_dir)
        if e["type"] == "perez":
            return perez_from_irradiance(e, zenith, azimuth, t)
        if e["type"] == "turbid":
            return turbid_sky(e["turbidity"], zenith, azimuth, day=t.timetuple().tm_yday,
                              elevation_m=elevation, **{k: e[k] for k in (
                                  "cct", "sun", "ground_albedo") if k in e})
        if e["type"] == "cie_general":
            kw = {k: e[k] for k in ("cct", "ground_albedo", "zenith_luminance") if k in e}
            sky = cie_general_sky(_cie_general_parameters(e), zenith, azimuth,
                                  day=t.timetuple().tm_yday, sun=_sun_disc(e), **kw)
        elif e["type"] == "gensky":
            text = e.get("gensky")
            if text is None:
                p = base_dir / e.get("gensky_file", "")
                if not p.is_file():
                    raise SpecError(f"[sky] gensky_file {str(p)!r} not found; give gensky = '''...''' "
                                    "or a file beside the spec.")
                text = _utf8(p, "[sky] gensky_file")
            sky = from_gensky(text)
        else:
            photometry = CIEPhotometry(**{k: e[k] for k in _CIE_PHOTOMETRY_KEYS if k in e})
            phi = e.get("phi") if e["type"] == "intermediate" else None
            sky = cie_sky(e["type"], zenith, azimuth, phi=phi, day=t.timetuple().tm_yday,
                          photometry=photometry, sun=_sun_disc(e),
                          ground_albedo=e.get("ground_albedo", GROUND_ALBEDO))
        if {"diffuse_horizontal_W_m2", "direct_normal_W_m2", "diffuse_horizontal_lux"} & set(e):
            if "diffuse_horizontal_lux" in e:
                overcast = e["type"] == "overcast"
                sky = sky.scaled_to_illuminance(e["diffuse_horizontal_lux"], e.get(
                    "efficacy_overcast" if overcast else "efficacy_clear",
                    EFFICACY_OVERCAST if overcast else EFFICACY_CLEAR))
            sky = sky.scaled(diffuse_horizontal=e.get("diffuse_horizontal_W_m2"),
                             direct_normal=e.get("direct_normal_W_m2"))
            if "direct_normal_W_m2" in e:
                sky = replace(sky, info={**sky.info, "sun_measured": True})
    except SpecError:
        raise
    except SkyfitError as exc:
        raise SpecError(f"[sky] at {t:%Y-%m-%d %H:%M}: {exc}") from None
    return sky


def thesis_disc_spec(name, material, camera_azimuth_deg=90.0, size=16, noise_percent=0.0,
                     spp=1024, seed=0, sky="clear", exposure="auto"):
    """The thesis's synthetic experiment (ch. 7) as a raw spec for :func:`validate_spec`: the
    disc (``scenes/disc.xml``) of ``material`` seen at 45 degrees from ``camera_azimuth_deg``
    (0 north, 90 east) from 5 m, at 40 N 0 E on 21 June, hourly 06:00-18:00 UTC, under a CIE
    ``sky``; ``size``^2 pixels over 6 degrees, a 12-bit sensor of ``exposure`` [sr m^2 W^-1]."""
    return {"name": name,
            "location": {"latitude_deg": 40.0, "longitude_deg": 0.0, "timezone": "UTC"},
            "time": {"date": "2026-06-21", "start": "06:00", "end": "18:00", "step_minutes": 60},
            "sky": {"type": sky}, "scene": {"file": "disc.xml"},
            "materials": {"disc": dict(material)},
            "camera": {"azimuth_deg": float(camera_azimuth_deg), "angle_deg": 45.0,
                       "distance": 5.0, "fov_deg": 6.0, "width": int(size),
                       "height": int(size)},
            "sensor": {"exposure": exposure, "bits": 12,
                       "noise_percent": float(noise_percent)},
            "render": {"spp": int(spp), "seed": int(seed)}}
