"""The sequence manifest: the one contract between the forward and the inverse half.

``render``, ``ingest`` and ``relight`` write a folder with ``manifest.json``; ``fit``,
``pixels``, ``labels``, ``relight`` and ``chi2map`` read it.  Only this module reads, validates,
upgrades or writes that file; its format is the JSON Schema ``manifest.schema.json``
(``skyfit-manifest/2``) beside it, documented in ``docs/MANIFEST.md``.

Per frame it holds the time (local with offset, and UTC), the illumination (``sky``: CIE/gensky
pattern weights; ``gensky``: Radiance text; ``irradiance``: measured levels driving a sky model;
``envmap``: an HDR map; ``directional``: a lab light), the frame's own exposure where it differs
from the sensor's, and the observations (image files or a table).  Version 1 manifests are
upgraded on reading.
"""

import collections
import datetime as dt
import functools
import hashlib
import json
import threading
from importlib import metadata
from pathlib import Path

import numpy as np

from .. import __version__
from ..errors import SkyfitError
from ..files import jsonable, write_json
from ..physics.camera import SensorModel
from ..physics.gensky import from_gensky
from ..physics.sky import Sky
from ..render.image import check_exr, read_exr_checked
from .photos import camera_name
from .illumination import (directional_from_record, directional_record, envmap_from_record,
                           envmap_record, perez_from_irradiance)

SCHEMA = "skyfit-manifest/2"
#: Schemas this version reads (older ones are upgraded in memory).
READABLE = ("skyfit-manifest/1", SCHEMA)
SCHEMA_FILE = Path(__file__).with_name("manifest.schema.json")
FILENAME = "manifest.json"
#: The illumination kinds the schema defines (each one :func:`frame_sky` lights).
ILLUMINATION_KINDS = ("sky", "gensky", "irradiance", "envmap", "directional")
#: A frame record's images, each a file of its own.
FRAME_KINDS = ("radiance", "radiance_sigma", "sensor", "sigma")
#: The sky models an ``irradiance`` record may name (its ``model``; default the first).
IRRADIANCE_MODELS = ("perez",)
#: The SensorModel fields a manifest's ``sensor`` record carries.
SENSOR_FIELDS = ("exposure", "response", "gamma", "bits", "noise_percent", "cos4")


class ManifestError(SkyfitError):
    """A manifest is missing, damaged, foreign or invalid; the message says what to do."""


@functools.cache
def schema():
    """The manifest's JSON Schema (a dict)."""
    return json.loads(SCHEMA_FILE.read_text())


def _where(path_parts):
    out = ""
    for p in path_parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "(top level)"


@functools.lru_cache(maxsize=1)
def _validator():
    import jsonschema

    return jsonschema.Draft202012Validator(schema())


def validate_manifest(doc, source="manifest"):
    """Check ``doc`` against the schema; raise :class:`ManifestError` naming the first problem."""
    import jsonschema

    err = jsonschema.exceptions.best_match(_validator().iter_errors(doc))
    if err is not None:
        raise ManifestError(f"{source} is not a valid {SCHEMA} manifest: at "
                            f"{_where(err.absolute_path)}: {err.message}. See docs/MANIFEST.md.")
    return doc


def _utc(iso):
    t = dt.datetime.fromisoformat(iso)
    return t.astimezone(dt.timezone.utc).isoformat() if t.tzinfo else None


def upgrade(doc):
    """A version-1 manifest as version 2 (frames' ``sky`` -> ``illumination``; UTC times)."""
    if doc.get("schema") == SCHEMA:
        return doc
    doc = dict(doc, schema=SCHEMA)
    frames = []
    for f in doc.get("frames", []):
        f = dict(f)
        if "sky" in f:
            f["illumination"] = {"kind": "sky", **f.pop("sky")}
        if "time" in f and "time_utc" not in f and _utc(f["time"]):
            f["time_utc"] = _utc(f["time"])
        frames.append(f)
    doc["frames"] = frames
    return doc


def manifest_file(path):
    """The manifest file of ``path`` (a folder holding manifest.json, or the file itself)."""
    p = Path(path)
    return p / FILENAME if p.is_dir() else p


def load_manifest(path):
    """Read, upgrade and validate the manifest at ``path`` (folder or file); returns (doc,
    folder).  :class:`ManifestError` for a missing, damaged, foreign, newer or invalid file."""
    p = manifest_file(path)
    if p.is_file() and p.suffix.lower() != ".json":
        raise ManifestError(f"{p} is not a sequence: give the folder `skyfit render` or `skyfit "
                            "ingest` wrote (or its manifest.json); a spec is rendered first "
                            "(skyfit render SPEC -o DIR).")
    if not p.is_file():
        if (p.parent / "frames").is_dir():
            raise ManifestError(f"{str(p.parent)!r} holds frames but no manifest.json: a render "
                                "or ingest stopped before its end; run it again into that folder.")
        raise ManifestError(f"no manifest at {str(p)!r}; give a folder written by `skyfit render` "
                            "or `skyfit ingest` (or its manifest.json).")
    try:
        text = p.read_text(encoding="utf-8")
        doc = json.loads(text)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ManifestError(f"{p} is damaged (not complete JSON: {exc}); render it afresh "
                            "with `skyfit render SPEC -o DIR --overwrite`.") \
            from None
    except OSError as exc:
        raise ManifestError(f"cannot read {p}: {exc.strerror or exc}.") from None
    if not isinstance(doc, dict) or not str(doc.get("schema", "")).startswith("skyfit-manifest/"):
        raise ManifestError(f"{p} is not a skyfit manifest (no 'schema': 'skyfit-manifest/N'); "
                            "give a folder written by `skyfit render`.")
    if doc["schema"] not in READABLE:
        raise ManifestError(f"{p} has schema {doc['schema']!r}, which this skyfit-mi "
                            f"({__version__}) cannot read (it reads {', '.join(READABLE)}); "
                            "upgrade skyfit-mi.")
    # a text this process has validated (read again by one command's steps) is not re-validated
    key = hashlib.sha256(text.encode("utf-8")).digest()
    doc = upgrade(doc)
    if key not in _VALIDATED:
        validate_manifest(doc, str(p))
        _check_frame_records(doc, p)
        _VALIDATED.add(key)
    return doc, p.parent


def _check_frame_records(doc, p):
    """What the schema cannot say of a (hand-edited) manifest's frames: each index, and each
    frame's file of a kind, its own; each time a real instant."""
    seen = {}
    for i, f in enumerate(doc["frames"]):
        for key in ("index", *FRAME_KINDS):
            if key in f and (key, f[key]) in seen:
                raise ManifestError(f"{p}: frames[{seen[key, f[key]]}] and frames[{i}] share "
                                    f"their {key} {f[key]!r}; restore the manifest the run "
                                    "wrote, or run it again into a new folder.")
            if key in f:
                seen[key, f[key]] = i
        if "time" in f:
            try:
                dt.datetime.fromisoformat(str(f["time"]))
            except ValueError:
                raise ManifestError(f"{p}: frame {f['index']}'s time {f['time']!r} is not an ISO "
                                    "date and time; restore the manifest the run wrote.") from None


#: Digests of the manifest texts :func:`load_manifest` has validated in this process.
_VALIDATED = set()


def write_manifest(path, doc):
    """Validate ``doc`` and write it atomically to ``path`` (a folder or the file)."""
    doc = json.loads(json.dumps(doc, default=jsonable))   # the form a reader sees
    validate_manifest(doc, "the manifest to write")
    return write_json(manifest_file(path) if Path(path).is_dir() else Path(path), doc)


def versions():
    """Versions of skyfit-mi and of the packages its results depend on."""
    out = {"skyfit_mi": __version__}
    for pkg in ("mitsuba", "drjit", "numpy", "pvlib"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out


# ---- illumination -----------------------------------------------------------

def illumination_record(sky, folder):
    """The ``illumination`` record of a Sky for a manifest in ``folder`` (files relative to it)."""
    common = {"info": {k: v for k, v in sky.info.items() if k != "file"},
              "horizontal_irradiance_W_m2": sky.horizontal_irradiance()}
    if sky.envmap is not None:
        return {**envmap_record(sky, folder), **common}
    if sky.info.get("kind") == "directional":
        return {**directional_record(sky), **common}
    return {"kind": "sky", "sun_direction": sky.sun_direction, "sun_radiance": sky.sun_radiance,
            "sun_solid_angle_sr": sky.sun_solid_angle, "clear": sky.clear,
            "overcast": sky.overcast, "uniform": sky.uniform, "intermediate": sky.intermediate,
            "perez": sky.perez, "perez_coefficients": sky.perez_coefficients,
            "ground": sky.ground, "horizon_blend": sky.horizon_blend, "info": sky.info,
            "horizontal_irradiance_W_m2": sky.horizontal_irradiance(),
            "units": "weights and radiances W m^-2 sr^-1, linear sRGB"}


def _irradiance_sky(frame, rec):
    """The Perez sky of an ``irradiance`` record at its frame's sun and time."""
    model = str(rec.get("model", "perez")).lower()
    if model not in IRRADIANCE_MODELS:
        raise SkyfitError(f"model {rec.get('model')!r}; this version turns measured irradiance "
                          f"into a {' or '.join(IRRADIANCE_MODELS)} sky")
    try:
        t = dt.datetime.fromisoformat(str(frame["time"]))
    except (KeyError, ValueError):
        raise SkyfitError("the frame needs its time (ISO 8601), which the Perez sky's "
                          "clearness depends on; add it") from None
    return perez_from_irradiance(rec, float(frame["sun_zenith_deg"]),
                                 float(frame["sun_azimuth_deg"]), t)


def frame_sky(frame, folder):
    """The :class:`~skyfit_mi.physics.sky.Sky` of a manifest frame's illumination (``folder``
    the manifest's); :class:`ManifestError` names the manifest and frame of a bad record."""
    rec = frame.get("illumination")
    where = f"{Path(folder) / FILENAME} frame {frame.get('index')}"
    if rec is None:
        raise ManifestError(f"{where} has no illumination record; render or ingest the sequence "
                            "again.")
    kind = rec.get("kind")
    if kind not in ILLUMINATION_KINDS:
        raise ManifestError(f"{where}: illumination kind {kind!r} is part of the manifest format "
                            f"but this version of skyfit-mi can only light frames of kind "
                            f"{' or '.join(map(repr, ILLUMINATION_KINDS))}.")
    try:
        return _record_sky(frame, rec, kind, folder)
    except SkyfitError as exc:
        why = " ".join(str(exc).split()).rstrip(".")         # one line, whatever the values
        raise ManifestError(f"{where}: {kind} illumination: {why}; repair the record, or render "
                            "or ingest the sequence again.") from None
    except (KeyError, TypeError, ValueError) as exc:        # a field missing or malformed
        why = " ".join(f"{type(exc).__name__}: {exc}".split())
        raise ManifestError(f"{where}: {kind} illumination record is malformed ({why}); repair "
                            "the record, or render or ingest the sequence again.") from None


def _record_sky(frame, rec, kind, folder):
    """The Sky of one illumination record of kind ``kind`` (:func:`frame_sky`)."""
    if kind == "gensky":
        return from_gensky(rec["text"])
    if kind == "directional":
        return directional_from_record(rec)
    if kind in ("envmap", "irradiance") and ("sun_zenith_deg" not in frame
                                             or "sun_azimuth_deg" not in frame):
        raise SkyfitError(f"an {kind} frame needs sun_zenith_deg and sun_azimuth_deg "
                          "(they place the solar disc and the sky's pattern); add them")
    if kind == "irradiance":
        return _irradiance_sky(frame, rec)
    if kind == "envmap":
        return envmap_from_record(rec, folder, frame["sun_zenith_deg"],
                                  frame["sun_azimuth_deg"])
    keys = ("clear", "overcast", "uniform", "intermediate", "ground", "sun_radiance")
    optional = {k: np.asarray(rec[k], dtype=float) for k in ("perez", "perez_coefficients")
                if k in rec}                       # absent from older manifests
    return Sky(np.asarray(rec["sun_direction"], dtype=float),
               **{k: np.asarray(rec[k], dtype=float) for k in keys}, **optional,
               horizon_blend=bool(rec["horizon_blend"]),
               sun_solid_angle=float(rec["sun_solid_angle_sr"]), info=rec.get("info", {}))


# ---- the sensor and each frame's exposure ----------------------------------

def sensor_record(sensor):
    """The manifest's ``sensor`` record of a :class:`~skyfit_mi.physics.camera.SensorModel`."""
    return {**sensor.to_dict(), "max_code": sensor.max_code, "sigma_DN": sensor.sigma,
            "units": "exposure sr m^2 W^-1; values and sigma in DN"}


def sensor_from_record(rec):
    """The :class:`~skyfit_mi.physics.camera.SensorModel` of a manifest's ``sensor`` record."""
    defaults = {"gamma": 2.2, "noise_percent": 0.0, "cos4": False}
    try:
        return SensorModel(**{k: rec.get(k, defaults.get(k)) for k in SENSOR_FIELDS})
    except SkyfitError as exc:
        raise ManifestError(f"the manifest's sensor record is invalid: {exc}") from None


def frame_exposure(doc, frame):
    """Per-channel exposure [sr m^2 W^-1] (3,) of a frame: its own (times white balance), else
    the sensor's."""
    rec = frame.get("exposure")
    if rec is None:
        return np.full(3, float(doc["sensor"]["exposure"]))
    with np.errstate(over="ignore", under="ignore"):
        out = float(rec["exposure"]) * np.asarray(rec.get("white_balance", (1.0, 1.0, 1.0)),
                                                  dtype=float)
    if not np.all(np.isfinite(out) & (out > 0)):
        raise ManifestError(f"{frame_label(frame.get('index', '?'))}: its exposure times its "
                            "white balance is not a finite positive number (it overflows or "
                            "underflows); repair the frame's exposure record (or ingest the "
                            "photographs again).")
    return out


def frame_label(index, time=None):
    """How a frame is named to people: 'frame 3 at 12:00' (``time`` a datetime or ISO string),
    or 'frame 3' for a lab light."""
    if time is None:
        return f"frame {index}"
    return f"frame {index} at {(time if isinstance(time, str) else time.isoformat())[11:16]}"


def frame_axis(frames, times):
    """(x values, axis label) to plot over ``frames`` at ``times``: local time, else index."""
    if all(t is not None for t in times):
        return [dt.datetime.fromisoformat(t) for t in times], "local time"
    return [int(i) for i in frames], "frame (lab light, by index)"


#: Manifest sources whose frames skyfit rendered (their materials are known: synthetic).
RENDERED_SOURCES = ("render", "relight")


def rendered_frames(doc):
    """The frames that hold observations (status ``rendered``), in time order."""
    return [f for f in doc["frames"] if f.get("status") == "rendered"]


def photo_cameras(doc):
    """The EXIF cameras (make and model, sorted) of an ingested sequence's photographs; [] where
    none states one (a render, a table, files without EXIF)."""
    return sorted({camera_name(f["photo"]) for f in doc["frames"] if f.get("photo")} - {""})


def is_table(doc):
    """Whether a manifest's frames are observed as a table (not images)."""
    return any(f.get("observations", {}).get("kind") == "table" for f in doc["frames"])


def check_frames(doc, root, kinds=("radiance", "sensor", "sigma"), frames=None):
    """Light every rendered frame (of ``frames`` only) of sequence ``doc`` in ``root`` and check
    the headers of its images of ``kinds``, so a bad record or file is refused before a command
    writes anything."""
    shape = (doc["camera"]["height"], doc["camera"]["width"], 3)
    for f in rendered_frames(doc):
        if frames is not None and f["index"] not in frames:
            continue
        frame_sky(f, root)
        if f.get("observations", {}).get("kind") == "table":
            continue
        extra = ("radiance_sigma",) if "radiance" in kinds and "radiance_sigma" in f else ()
        for key in (*kinds, *extra):         # read_frame_image's checks, from the header alone
            _checked(f, check_exr, _frame_path(root, f, key), shape)


#: Bytes of decoded frame images kept for re-reading (each region reads the same frames), least
#: recently read first out; an image over an eighth of it is not kept.
FRAME_CACHE_BYTES = 256 << 20
_FRAMES = collections.OrderedDict()      # file identity and shape -> read-only image
_FRAMES_LOCK = threading.Lock()
_FRAMES_BYTES = [0]


def _file_identity(path, shape):
    """What changes when the file at ``path`` is written again, and the image's ``shape``: the
    frame cache's key; None if there is no such file."""
    try:
        st = path.stat()
    except OSError:
        return None
    return (str(path.resolve()), st.st_dev, st.st_ino, st.st_mtime_ns, st.st_ctime_ns,
            st.st_size, tuple(shape))


def read_frame_image(root, frame, key, shape):
    """Frame record ``frame``'s image ``key`` ('radiance', 'radiance_sigma', 'sensor', 'sigma')
    in folder ``root``, checked to be of ``shape`` (H, W, 3); SkyfitError naming the frame and
    fix otherwise.  The array is read-only and may be shared (cached, FRAME_CACHE_BYTES)."""
    path = _frame_path(root, frame, key)
    ident = _file_identity(path, shape)
    if ident is not None:
        with _FRAMES_LOCK:
            if ident in _FRAMES:
                _FRAMES.move_to_end(ident)
                return _FRAMES[ident]
    img = _checked(frame, read_exr_checked, path, shape)
    img.flags.writeable = False
    # kept only if the file did not change while it was read
    if ident is not None and _file_identity(path, shape) == ident:
        _keep(ident, img)
    return img


def _frame_path(root, frame, key):
    if key not in frame:
        raise SkyfitError(f"frame {frame['index']} has no {key} image (an older render, or a "
                          "sequence without it); render the sequence again with --overwrite.")
    return Path(root) / frame[key]


def _checked(frame, read, *args):
    """``read(*args)`` of a frame's image file, its SkyfitError naming the frame and the fix."""
    try:
        return read(*args)
    except SkyfitError as exc:
        raise SkyfitError(f"frame {frame['index']}: {exc}; render the sequence again (it resumes "
                          "and replaces damaged frames).") from None


def read_frame_pixels(root, frame, key, shape, pixels):
    """Frame record ``frame``'s image ``key`` at ``pixels`` ((P, 2) x, y) as (P, 3) float32,
    with :func:`read_frame_image`'s checks, reading only those rows (or from the cache)."""
    px = np.asarray(pixels, dtype=int).reshape(-1, 2)
    path = _frame_path(root, frame, key)
    ident = _file_identity(path, shape)
    if ident is not None:
        with _FRAMES_LOCK:
            img = _FRAMES.get(ident)
        if img is not None:
            return img[px[:, 1], px[:, 0]]
    return _checked(frame, read_exr_checked, path, shape, px)


def keep_frame_image(path, image):
    """Cache ``image``, just written to ``path`` as float32 EXR, for :func:`read_frame_image`."""
    img = np.array(image, dtype=np.float32)
    ident = _file_identity(Path(path), img.shape)
    if ident is not None:
        img.flags.writeable = False
        _keep(ident, img)


def _keep(ident, img):
    """Put read-only ``img`` in the frame cache under ``ident`` (file identity and shape)."""
    if img.nbytes > FRAME_CACHE_BYTES // 8:
        return
    with _FRAMES_LOCK:
        if ident not in _FRAMES:
            _FRAMES[ident] = img
            _FRAMES_BYTES[0] += img.nbytes
        while _FRAMES_BYTES[0] > FRAME_CACHE_BYTES:
            _FRAMES_BYTES[0] -= _FRAMES.popitem(last=False)[1].nbytes
