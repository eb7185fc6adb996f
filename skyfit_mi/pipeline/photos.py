"""Reading one photograph, with the metadata ingest needs.

:func:`read_photo` turns one file (camera RAW, 8- or 16-bit JPEG/PNG/TIFF, float OpenEXR or
Radiance RGBE) into a :class:`Photo`: values as stored (RGB float32), their kind (integer codes or
floats), an encoding hint (sRGB or linear) and EXIF metadata.  :func:`check_same_size` refuses
frames of differing size or orientation.  Every failure is one
:class:`~skyfit_mi.errors.SkyfitError` line naming the file and what to do.

Formats and decisions
---------------------
* ``.jpg .jpeg``, ``.png`` of up to 8 bits (Pillow), ``.tif .tiff`` of 8 bits (tifffile): bits
  8, hint 'srgb' ('linear' for PNG gAMA 1.0 or an ICC profile named linear).  JPEG codes are
  decoded in floating point from the DCT coefficients (:func:`.jpeg_noise.decode`): libjpeg's
  whole codes put one shared error on every pixel of a smooth patch.
* ``.png`` of 16 bits (Mitsuba's Bitmap: Pillow truncates to 8) and 16-bit ``.tif``: bits 16,
  hint 'linear' (as ``dcraw -4 -T`` writes; 'srgb' for an sRGB chunk, gAMA 1/2.2 or an ICC
  profile named sRGB).
* float ``.tif``, ``.exr``, ``.hdr .pic .rgbe``: kind 'float', hint 'linear', capture time from
  the header; RGBE is read in a child process (:data:`_BITMAPS`) that a damaged file may abort.
* camera RAW (:data:`RAW_SUFFIXES`, rawpy / LibRaw): bits 16, developed to linear sRGB with fixed
  levels (:data:`RAW_DEVELOP`), so codes are proportional to exposure across frames.
* EXIF orientation is applied (as Pillow's ``ImageOps.exif_transpose``; RAWs by LibRaw's flip)
  and recorded in ``metadata['orientation']``.  Alpha is dropped; grey is repeated into RGB.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import io
import logging
import math
import struct
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..child import CallFailed, Child, ChildDied, one_line
from ..errors import SkyfitError
from ..physics.camera import SensorModel
from ..render.image import ExrError, read_bitmap, read_exr_channels
from . import jpeg_noise
from .orientation import ORIENTATIONS, apply_orientation
from .photo_times import format_offset

#: Camera RAW suffixes handed to rawpy (LibRaw), lower case.
RAW_SUFFIXES = frozenset({
    ".dng", ".cr2", ".cr3", ".crw", ".nef", ".nrw", ".arw", ".srf", ".sr2", ".raf", ".orf",
    ".rw2", ".pef", ".srw", ".x3f", ".3fr", ".fff", ".iiq", ".mos", ".mef", ".mrw", ".erf",
    ".kdc", ".dcr", ".rwl", ".raw",
})
JPEG_SUFFIXES = frozenset({".jpg", ".jpeg", ".jpe"})
#: Largest rms difference [DN] from libjpeg's codes at which the floating-point JPEG decoder is
#: used: libjpeg's rounding stays well below it; more means a coding the decoder does not follow.
DECODER_AGREEMENT_DN = 1.5

#: LibRaw's ``sizes.flip`` -> the EXIF orientation code of the same turn.
_LIBRAW_FLIP_TO_EXIF = {0: 1, 3: 3, 5: 8, 6: 6}

#: How a RAW is developed (rawpy's ``postprocess``, :func:`develop`): AHD demosaicing, linear
#: 16-bit, the camera's as-shot white balance, no brightening or per-frame white level.
RAW_DEVELOP = {"gamma": (1, 1), "no_auto_bright": True, "output_bps": 16, "use_camera_wb": True,
               "adjust_maximum_thr": 0.0}
#: How far [pixels] AHD demosaicing mixes a pixel's colour with its neighbours' (measured on
#: saturated paints: three pixels from an edge the mixing is within the noise).
RAW_COLOUR_REACH = 2


@dataclass(frozen=True, eq=False)
class Photo:
    """One photograph as read by :func:`read_photo`.

    Attributes
    ----------
    path, format : str
        The file; 'jpeg', 'png', 'tiff', 'exr', 'rgbe' or 'raw'.
    values : ndarray, float32, shape (H, W, 3)
        RGB values as stored, EXIF orientation applied: codes (0 .. ``max_code``) for integer
        formats (fractional for a JPEG), the floats otherwise.  Writable, not copied.
    kind : str
        'integer' or 'float'.
    bits, max_code : int or None
        8 or 16 and 2**bits - 1 (saturation) for integer formats; None for floats.
    encoding_hint, encoding_source : str
        'srgb' or 'linear' (the user may override it), and why: 'assumed', 'PNG sRGB chunk',
        'PNG gAMA 1.0', 'PNG gAMA 1/2.2', 'ICC profile "<description>"' (sRGB or linear by
        name), 'the ICC profile "<description>"' (another: the hint a guess), 'RAW' or 'float'.
    nan_count, inf_count : int
    metadata : dict
        ``datetime_original`` ('YYYY:MM:DD HH:MM:SS' or None), ``offset_time_original``
        ('+01:00' or None), ``subsec_time_original``, ``exposure_time_s``, ``f_number``,
        ``iso``, ``make``, ``model``, ``orientation`` (EXIF code applied, 1 = none),
        ``icc_profile``, and for RAW ``raw`` (levels, white balances, what was applied).
    """

    path: str
    format: str
    values: np.ndarray
    kind: str
    bits: int | None
    max_code: int | None
    encoding_hint: str
    encoding_source: str
    nan_count: int
    inf_count: int
    metadata: dict = field(default_factory=dict)

    @property
    def height(self):
        """Rows [pixels]."""
        return self.values.shape[0]

    @property
    def width(self):
        """Columns [pixels]."""
        return self.values.shape[1]

    @property
    def size(self):
        """(width, height) [pixels]."""
        return self.width, self.height


# ----------------------------------------------------------------------------------- helpers

def _fail(path, what, fix=None):
    msg = f"{path}: {what}"
    if fix:
        msg += f"; {fix}"
    return SkyfitError(msg if msg.endswith(".") else msg + ".")


def _first_line(exc):
    """A one-line summary of a library exception (Mitsuba's messages span many lines)."""
    text = one_line(exc)
    if text.startswith(']".'):           # Mitsuba: '...FileStream[ ... ]". The reason.'
        text = text[3:].strip()
    return text


def _rgb(values, channels, path):
    """(H, W, C) -> (H, W, 3): alpha dropped, grey repeated; ``channels``: names or None."""
    c = values.shape[2]
    if channels is not None:
        names = [n.upper() for n in channels]
        if names[:3] == ["R", "G", "B"]:
            return values[:, :, :3]
        if names[:1] in (["Y"], ["L"]):
            return np.repeat(values[:, :, :1], 3, axis=2)
        raise _fail(path, f"has channels {', '.join(channels)}, not RGB or grey",
                    "save the image as RGB")
    if c in (3, 4):
        return values[:, :, :3]
    if c in (1, 2):
        return np.repeat(values[:, :, :1], 3, axis=2)
    raise _fail(path, f"has {c} channels per pixel, not RGB or grey", "save the image as RGB")


def _text(v):
    """An EXIF value (exifread's tag or Pillow's value) as stripped text, or None."""
    v = getattr(v, "values", v)
    if v is None:
        return None
    if isinstance(v, bytes):
        v = v.decode("ascii", "replace")
    if isinstance(v, (list, tuple)):
        v = " ".join(str(x) for x in v)
    v = str(v).strip().strip("\x00").strip()
    return v if v.replace(":", "").strip() else None     # EXIF's blank "    :  :  " too


def _number(v):
    """An EXIF value (exifread's tag or Pillow's; a list's first) as a finite float, or None."""
    v = getattr(v, "values", v)
    if isinstance(v, (list, tuple)):
        v = v[0] if v else None
    if v is None:
        return None
    try:
        if hasattr(v, "num") and hasattr(v, "den"):        # exifread Ratio
            if v.den == 0:
                return None
            return float(v.num) / float(v.den)
        x = float(v)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return x if math.isfinite(x) else None


#: :attr:`Photo.metadata` keys read from EXIF: exifread's tag name, Pillow's IFD (0x8769 the
#: Exif IFD, 0 the image's) and tag number, and whether the value is a number (else text).
_EXIF_TAGS = {"datetime_original": ("EXIF DateTimeOriginal", 0x8769, 0x9003, False),
              "offset_time_original": ("EXIF OffsetTimeOriginal", 0x8769, 0x9011, False),
              "subsec_time_original": ("EXIF SubSecTimeOriginal", 0x8769, 0x9291, False),
              "exposure_time_s": ("EXIF ExposureTime", 0x8769, 0x829A, True),
              "f_number": ("EXIF FNumber", 0x8769, 0x829D, True),
              "iso": ("EXIF ISOSpeedRatings", 0x8769, 0x8827, True),
              "make": ("Image Make", 0, 0x010F, False),
              "model": ("Image Model", 0, 0x0110, False),
              "colour_space": ("EXIF ColorSpace", 0x8769, 0xA001, True),
              "interop_index": ("Interoperability InteroperabilityIndex", 0xA005, 0x0001, False)}


def camera_name(metadata):
    """EXIF's make and model of a photograph's :attr:`Photo.metadata`, '' without them."""
    return " ".join(str(metadata.get(k) or "").strip() for k in ("make", "model")).strip()


def _empty_metadata():
    return {**dict.fromkeys(_EXIF_TAGS), "orientation": 1, "icc_profile": None}


@contextlib.contextmanager
def _quiet(*names):
    """Silence the named loggers and Python warnings (the reader's one error line suffices)."""
    loggers = [logging.getLogger(n) for n in names]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL + 1)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)


def read_exif(path):
    """EXIF metadata of ``path`` (JPEG, TIFF, PNG eXIf, most TIFF-based RAWs) by ``exifread``,
    as :attr:`Photo.metadata` (``orientation``: the code the file asks for, 1 without one).
    Unreadable EXIF gives empty values, never an error: the pixel reader judges the file."""
    import exifread

    meta = _empty_metadata()
    try:
        with _quiet("exifread"), open(path, "rb") as fh:
            tags = exifread.process_file(fh, details=False, extract_thumbnail=False)
    except Exception:                           # noqa: BLE001 -- corrupt EXIF is not fatal
        tags = {}
    for key, (name, _, _, number) in _EXIF_TAGS.items():
        meta[key] = (_number if number else _text)(tags.get(name))
    if meta["iso"] is None:
        meta["iso"] = _number(tags.get("EXIF PhotographicSensitivity"))
    meta["iso"] = None if meta["iso"] is None else int(meta["iso"])
    o = _number(tags.get("Image Orientation"))
    meta["orientation"] = int(o) if o is not None and int(o) in ORIENTATIONS else 1
    return meta


def _pil_exif_metadata(im, meta):
    """Fill what exifread missed from Pillow's ``getexif()`` (PNG eXIf chunks)."""
    try:
        exif = im.getexif()
        ifds = {0: exif, 0x8769: exif.get_ifd(0x8769), 0xA005: exif.get_ifd(0xA005)}
    except Exception:                           # noqa: BLE001
        return meta
    for key, (_, ifd, tag, number) in _EXIF_TAGS.items():
        v = (_number if number else _text)(ifds[ifd].get(tag))
        if meta.get(key) is None and v is not None:
            meta[key] = int(v) if key == "iso" else v
    if meta.get("orientation", 1) == 1 and exif.get(0x0112) in ORIENTATIONS:
        meta["orientation"] = int(exif.get(0x0112))
    return meta


def _icc_description(icc):
    if not icc:
        return None
    try:
        from PIL import ImageCms

        return ImageCms.ImageCmsProfile(io.BytesIO(icc)).profile.profile_description or "unnamed"
    except Exception:                           # noqa: BLE001 -- no LittleCMS, odd profile
        return "unreadable"


#: The start of an encoding source naming an ICC profile that is neither sRGB nor linear.
OTHER_PROFILE = "the ICC profile"
#: The start of one naming EXIF's colour space 'Uncalibrated' in a file without a profile (DCF's
#: mark of Adobe RGB, as cameras set to it write their JPEGs).
EXIF_SPACE = "the EXIF colour space"
#: The starts of the sources ingest refuses unless told the encoding.
NOT_SRGB = (OTHER_PROFILE, EXIF_SPACE)
#: The start of one naming a profile of sRGB's curve and wider primaries (Display P3, phones').
WIDE_PRIMARIES = "the wide-primaries ICC profile"


def _hint_from_icc(desc, default):
    """(hint, source) of an ICC profile's description ``desc``: 'linear' or 'srgb' by name
    (Display P3 'srgb', its source starting :data:`WIDE_PRIMARIES`, for ingest to say so); a
    profile of another name (Adobe RGB, ProPhoto) keeps ``default`` with a source that starts
    :data:`OTHER_PROFILE`, for ingest to refuse unless told the encoding."""
    if desc and desc not in ("unreadable", "unnamed"):
        d = desc.lower()
        if "linear" in d or "gamma 1.0" in d or "g10" in d:
            return "linear", f'ICC profile "{desc}"'
        if "srgb" in d or "iec61966" in d:
            return "srgb", f'ICC profile "{desc}"'
        if "p3" in d:                                    # Display P3: sRGB's curve
            return "srgb", f'{WIDE_PRIMARIES} "{desc}"'
        return default, f'{OTHER_PROFILE} "{desc}"'
    return default, "assumed"


def _png_hint(info, hint, source):
    """The encoding a PNG's sRGB or gAMA chunk states (Pillow's ``info``), else (hint, source)."""
    if "srgb" in info:
        return "srgb", "PNG sRGB chunk"
    g = float(info.get("gamma", 0.0))
    if abs(g - 1.0) < 1e-3:
        return "linear", "PNG gAMA 1.0"
    if abs(g - 1 / 2.2) < 2e-3:
        return "srgb", "PNG gAMA 1/2.2"
    return hint, source


def _integer_photo(path, fmt, codes, bits, info, meta):
    """An integer format's photo, EXIF orientation applied; its encoding hint a PNG's sRGB or
    gAMA chunk's, else its ICC profile's (both in Pillow's ``info``), else 'srgb' at 8 bits and
    'linear' at 16."""
    meta["icc_profile"] = _icc_description(info.get("icc_profile"))
    hint, source = _hint_from_icc(meta["icc_profile"], "srgb" if bits == 8 else "linear")
    if meta["icc_profile"] is None and (meta.get("colour_space") == 0xFFFF
                                        or meta.get("interop_index") == "R03"):
        source = f"{EXIF_SPACE} 'Uncalibrated' " + (
            "(Adobe RGB by its interoperability index R03)"
            if meta.get("interop_index") == "R03" else "(not sRGB)")
    if fmt == "png":
        hint, source = _png_hint(info, hint, source)
    values = apply_orientation(_rgb(codes, None, path), meta["orientation"])
    return Photo(path=str(path), format=fmt,
                 values=np.ascontiguousarray(values, dtype=np.float32), kind="integer",
                 bits=bits, max_code=2 ** bits - 1, encoding_hint=hint, encoding_source=source,
                 nan_count=0, inf_count=0, metadata=meta)


def _float_photo(path, fmt, values, meta):
    values = np.ascontiguousarray(apply_orientation(values, meta["orientation"]),
                                  dtype=np.float32)
    return Photo(path=str(path), format=fmt, values=values, kind="float", bits=None,
                 max_code=None, encoding_hint="linear", encoding_source="float",
                 nan_count=int(np.isnan(values).sum()), inf_count=int(np.isinf(values).sum()),
                 metadata=meta)


# ----------------------------------------------------------------------------------- readers

def _read_pillow(path, fmt, exact=True):
    """8-bit JPEG or PNG through Pillow; a JPEG decoded in floating point where ``exact``."""
    from PIL import Image

    meta = read_exif(path)
    try:
        with _quiet("PIL"), Image.open(path) as im:
            im.load()
            if fmt == "png":
                meta = _pil_exif_metadata(im, meta)
            info = dict(im.info)
            mode = im.mode
            if mode == "CMYK":
                raise _fail(path, "is a CMYK image", "export it as RGB")
            if mode in ("I;16", "I;16B", "I;16L", "I", "F"):
                raise _fail(path, f"has Pillow mode {mode}, not an 8-bit image",
                            "export it as 8-bit or 16-bit RGB")
            if mode not in ("RGB", "L"):
                im = im.convert("RGBA" if "A" in mode or "transparency" in info else "RGB")
            codes = np.asarray(im)
    except SkyfitError:
        raise
    except Image.DecompressionBombError:
        raise _fail(path, "has more pixels than Pillow reads safely",
                    "reduce the image size") from None
    except Exception as exc:                    # noqa: BLE001 -- Pillow: OSError, SyntaxError..
        raise _fail(path, f"cannot be read as a {fmt.upper()} image ({_first_line(exc)})",
                    "check that the file is complete and really a "
                    f"{fmt.upper()}, or remove it") from None
    if codes.ndim == 2:
        codes = codes[:, :, None]
    if fmt == "jpeg" and not exact:
        meta["decoder"] = "libjpeg, whole codes (Pillow)"
    elif fmt == "jpeg":
        decoded = jpeg_noise.decode(path)
        differ = None if decoded is None or decoded.shape != codes.shape else \
            float(np.sqrt(np.mean((decoded - codes) ** 2)))
        if differ is not None and differ <= DECODER_AGREEMENT_DN:
            codes = decoded
            meta["decoder"] = "floating point from the DCT coefficients (jpeglib)"
        else:
            meta["decoder"] = "libjpeg, whole codes (Pillow): the floating-point decoder " + (
                "could not read the file" if differ is None else
                f"disagrees with libjpeg by {differ:.3g} DN rms")
    return _integer_photo(path, fmt, codes, 8, info, meta)


def _png_header(path):
    """(bit depth, colour type) from a PNG's IHDR, or raise naming the file."""
    with open(path, "rb") as fh:
        head = fh.read(33)
    if len(head) < 26 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        raise _fail(path, "is not a PNG file (no PNG signature and header)",
                    "check the file, or give it the suffix of its real format")
    return head[24], head[25]


def _read_png(path):
    depth, _ = _png_header(path)
    if depth <= 8:
        return _read_pillow(path, "png")
    # Pillow reads 16-bit RGB PNG as 8 bits; Mitsuba's Bitmap (libpng) keeps all 16.
    from PIL import Image

    meta = read_exif(path)
    try:
        with _quiet("PIL"), Image.open(path) as im:   # header only: metadata, colour chunks
            info = dict(im.info)
            meta = _pil_exif_metadata(im, meta)
    except Exception:                            # noqa: BLE001
        info = {}
    try:
        codes, channels = read_bitmap(path)
    except Exception as exc:                     # noqa: BLE001 -- Mitsuba: RuntimeError
        raise _fail(path, f"cannot be read as a 16-bit PNG ({_first_line(exc)})",
                    "check that the file is complete, or remove it") from None
    if codes.dtype != np.uint16:
        raise _fail(path, f"reads as {codes.dtype}, not 16-bit codes", "export it again")
    return _integer_photo(path, "png", _rgb(codes, channels, path), 16, info, meta)


def _read_tiff(path):
    import tifffile

    meta = read_exif(path)
    try:
        with _quiet("tifffile"), tifffile.TiffFile(path) as tif:
            page = tif.pages.first if hasattr(tif.pages, "first") else tif.pages[0]
            photometric = int(page.photometric)
            icc = page.tags.get(34675)
            icc = icc.value if icc is not None else None
            orient = page.tags.get(274)
            axes = tif.series[0].axes
            arr = tif.series[0].asarray()
    except Exception as exc:                     # noqa: BLE001 -- TiffFileError, ValueError..
        raise _fail(path, f"cannot be read as a TIFF image ({_first_line(exc)})",
                    "check that the file is complete and uncompressed or deflate/LZW-"
                    "compressed, or export it again") from None
    if orient is not None and meta["orientation"] == 1 and int(orient.value) in ORIENTATIONS:
        meta["orientation"] = int(orient.value)
    if photometric not in (1, 2):                # MINISBLACK, RGB
        raise _fail(path, f"has TIFF photometric interpretation {photometric}, not RGB or grey",
                    "export it as RGB")
    axes = axes.replace("Q", "")
    if axes == "SYX":
        arr = np.moveaxis(arr, 0, -1)
    elif axes == "YX":
        arr = arr[:, :, None]
    elif axes != "YXS":
        raise _fail(path, f"holds an image of axes {axes!r} (several pages or planes?)",
                    "export a single RGB image")
    if arr.dtype in (np.uint8, np.uint16):
        return _integer_photo(path, "tiff", arr, 8 * arr.dtype.itemsize, {"icc_profile": icc},
                              meta)
    if arr.dtype.kind == "f":
        meta["icc_profile"] = _icc_description(icc)
        return _float_photo(path, "tiff", _rgb(arr, None, path), meta)
    raise _fail(path, f"holds {arr.dtype} samples, not 8- or 16-bit codes or floats",
                "export it as 8-bit, 16-bit or float TIFF")


def exr_header_times(path):
    """``datetime_original``, ``offset_time_original`` from an OpenEXR header's ``capDate``
    (local) and ``utcOffset`` ([s], UTC = local + utcOffset); None where absent or unreadable."""
    out = {"datetime_original": None, "offset_time_original": None}
    try:
        with open(path, "rb") as fh:
            data = fh.read(1 << 16)
    except OSError:
        return out
    if data[:4] != b"\x76\x2f\x31\x01":
        return out
    i = 8
    while i < len(data) and data[i] != 0:
        try:
            j = data.index(b"\0", i)
            k = data.index(b"\0", j + 1)
            name, kind = data[i:j].decode("latin-1"), data[j + 1:k].decode("latin-1")
            size = struct.unpack_from("<i", data, k + 1)[0]
        except (ValueError, struct.error):
            break
        value = data[k + 5:k + 5 + size]
        if name == "capDate" and kind == "string":
            out["datetime_original"] = value.decode("latin-1").strip()
        elif name == "utcOffset" and kind in ("float", "double") and size in (4, 8):
            offset = struct.unpack("<f" if size == 4 else "<d", value)[0]
            out["offset_time_original"] = format_offset(dt.timedelta(seconds=-offset))
        i = k + 5 + size
    return out


def rgbe_header_times(path):
    """``datetime_original`` and ``offset_time_original`` from a Radiance RGBE header's
    ``CAPDATE=`` (local) and ``GMT=`` (UTC) lines; GMT alone gives +00:00.  None where absent."""
    lines = {}
    try:
        with open(path, "rb") as fh:
            for raw in iter(lambda: fh.readline(4096), b""):
                line = raw.decode("latin-1").strip()
                if not line:
                    break
                key, _, value = line.partition("=")
                lines[key.strip().upper()] = value.strip()
    except OSError:
        pass
    out = {"datetime_original": None, "offset_time_original": None}

    def parse(text):
        try:
            return dt.datetime.strptime(text, "%Y:%m:%d %H:%M:%S")
        except (TypeError, ValueError):
            return None
    local, utc = parse(lines.get("CAPDATE")), parse(lines.get("GMT"))
    if local is not None:
        out["datetime_original"] = lines["CAPDATE"]
        if utc is not None:
            out["offset_time_original"] = format_offset(local - utc)
    elif utc is not None:
        out["datetime_original"], out["offset_time_original"] = lines["GMT"], "+00:00"
    return out


#: The function that reads an RGBE file in the child process (tests name one that crashes).
READ_BITMAP = "skyfit_mi.render.image:read_bitmap"
#: Deadline of one such read [s]: [0] + [1] per MB of the file (an overrun child can spin).
READ_DEADLINE = (60.0, 0.1)
#: The child process that reads RGBE files: Mitsuba 3.9.1's RGBE reader overruns its buffer on
#: a non-run-length-encoded scanline after the first and aborts (or spins), killing the child
#: instead of the caller.  Each read adds a copy of its pixels through a pipe.
_BITMAPS = Child()


def _read_exr(path):
    """An OpenEXR file, read in this process (a damaged file raises, it does not abort)."""
    try:
        values, channels = read_exr_channels(path)
    except ExrError as exc:
        raise _fail(path, f"cannot be read as an OpenEXR image ({exc.why})",
                    "check that the file is complete, or remove it") from None
    return _float_image(path, "exr", values, channels, exr_header_times(path))


def _read_rgbe(path):
    """A Radiance RGBE file through Mitsuba's Bitmap, read in the child process :data:`_BITMAPS`."""
    try:
        values, channels = _BITMAPS.call(
            READ_BITMAP, str(path),
            timeout=READ_DEADLINE[0] + READ_DEADLINE[1] * path.stat().st_size / 1e6)
    except ChildDied as exc:
        raise _fail(path, "cannot be read as a Radiance RGBE image (the image reader crashed "
                    f"on it: {exc})", "check that the file is complete, or remove it") from None
    except CallFailed as exc:
        raise _fail(path, f"cannot be read as a Radiance RGBE image ({_first_line(exc)})",
                    "check that the file is complete, or remove it") from None
    return _float_image(path, "rgbe", values, channels, rgbe_header_times(path))


def _float_image(path, kind, values, channels, times):
    """A float image's photo (``kind`` 'exr' or 'rgbe'), its header's ``times`` in metadata."""
    if values.dtype.kind != "f":
        raise _fail(path, f"reads as {values.dtype} codes, not floats",
                    "give it the suffix of its real format")
    return _float_photo(path, kind, _rgb(values, channels, path), {**_empty_metadata(), **times})


def _wb(values):
    return [float(x) for x in values] if values is not None else None


def develop(raw):
    """An open rawpy image developed by :data:`RAW_DEVELOP`: (H, W, 3) uint16 sRGB, turned."""
    import rawpy

    return raw.postprocess(**RAW_DEVELOP, output_color=rawpy.ColorSpace.sRGB)


def _read_raw(path):
    import rawpy

    meta = read_exif(path)
    try:
        with rawpy.imread(str(path)) as raw:
            cam_wb = _wb(raw.camera_whitebalance)
            use_camera = bool(cam_wb) and cam_wb[0] > 0 and cam_wb[1] > 0
            flip = int(raw.sizes.flip)
            info = {
                "black_level_per_channel": [int(x) for x in raw.black_level_per_channel],
                "white_level": int(raw.white_level),
                "camera_whitebalance": cam_wb,
                "daylight_whitebalance": _wb(raw.daylight_whitebalance),
                "color_desc": raw.color_desc.decode("ascii", "replace"),
                "applied_white_balance": "camera (as shot)" if use_camera
                else "daylight (the file has no as-shot balance)",
                "applied": {"demosaic": "AHD",
                            **{k: list(v) if isinstance(v, tuple) else v
                               for k, v in RAW_DEVELOP.items() if k != "use_camera_wb"},
                            "output_color": "sRGB primaries, linear",
                            "black_subtracted": True, "white_level_to": 65535,
                            "highlight_mode": "clip", "libraw_flip": flip},
            }
            try:
                other = raw.other
                fallback = {"iso": getattr(other, "iso_speed", None),
                            "exposure_time_s": getattr(other, "shutter_speed", None),
                            "f_number": getattr(other, "aperture", None)}
            except Exception:                    # noqa: BLE001 -- older rawpy
                fallback = {}
            rgb = develop(raw)
    except (rawpy.LibRawError, OSError, ValueError) as exc:
        kind = type(exc).__name__
        why = {"LibRawFileUnsupportedError": "is not a camera RAW file LibRaw supports",
               "LibRawIOError": "is truncated or unreadable",
               "LibRawDataError": "has corrupt image data"}.get(
                   kind, f"cannot be read as a camera RAW file ({kind}: {_first_line(exc)})")
        raise _fail(path, why, "check the file, or convert it to DNG or 16-bit TIFF "
                    "(linear) and ingest that") from None
    for k, v in fallback.items():
        if meta.get(k) is None and v is not None and v > 0:
            meta[k] = int(v) if k == "iso" else float(v)
    meta["raw"] = info
    # LibRaw has already turned the image by its flip; record that, do not turn again.
    meta["orientation"] = _LIBRAW_FLIP_TO_EXIF.get(flip, 1)
    values = np.ascontiguousarray(_rgb(rgb, None, path), dtype=np.float32)
    del rgb
    return Photo(path=str(path), format="raw", values=values, kind="integer", bits=16,
                 max_code=65535, encoding_hint="linear", encoding_source="RAW", nan_count=0,
                 inf_count=0, metadata=meta)


#: The reader of each suffix, lower case.
_READERS = {s: reader for suffixes, reader in (
    (JPEG_SUFFIXES, lambda p, exact: _read_pillow(p, "jpeg", exact)), ((".png",), _read_png),
    ((".tif", ".tiff"), _read_tiff), ((".exr",), _read_exr),
    ((".hdr", ".pic", ".rgbe"), _read_rgbe), (RAW_SUFFIXES, _read_raw)) for s in suffixes}
#: Every suffix :func:`read_photo` reads.
SUFFIXES = frozenset(_READERS)


def read_photo(path, exact_jpeg=True):
    """Read one photograph (any suffix in :data:`SUFFIXES`) as a :class:`Photo`; without
    ``exact_jpeg``, a JPEG gets libjpeg's whole codes (faster, for uses that average pixels).
    SkyfitError naming the file if it cannot be read as RGB/grey 8-bit, 16-bit or float."""
    p = Path(path)
    suffix = p.suffix.lower()
    reader = _READERS.get(suffix)
    if reader is None:
        raise _fail(p, f"has the suffix {suffix or '(none)'!r}, not an image format skyfit "
                    "reads", f"give one of: {' '.join(sorted(SUFFIXES))}")
    if not p.is_file():
        raise _fail(p, "does not exist or is not a file", "check the path")
    if p.stat().st_size == 0:
        raise _fail(p, "is empty (0 bytes)", "copy the photograph again or remove it")
    try:
        return reader(p) if suffix not in JPEG_SUFFIXES else reader(p, exact_jpeg)
    except SkyfitError:
        raise
    except MemoryError:
        raise _fail(p, "is too large to read into memory", "reduce the image size") from None
    except Exception as exc:                     # noqa: BLE001 -- any library's surprise
        raise _fail(p, f"cannot be read ({type(exc).__name__}: {_first_line(exc)})",
                    "check that the file is complete, or remove it") from None


#: The EXIF fields of a photograph's exposure, by name: its :attr:`Photo.metadata` keys.
EXPOSURE_KEYS = {"exposure time": "exposure_time_s", "f-number": "f_number", "ISO": "iso"}


#: Relative sd of the exposure each EXIF label (a shutter time, f-number or ISO) stands for
#: about the label's own: cameras set exact third stops (2^(-k/3) s, f/2^(k/6)) and label them
#: with the rounded nominal series (1/125 s for 1/128, 1/60 for 1/64, f/11 for f/11.31), whose
#: offsets spread 1.9% about their mean over the shutter times 1/4000-1/8 s and 2.4% in N^2 over
#: f/1.4-22 (the mean cancels in a ratio to the first frame's exposure).
EXIF_LABEL_SD = 0.02


def exif_exposure(photo):
    """The exposure t S / N^2 [s] of ``photo`` from EXIF (:data:`EXPOSURE_KEYS`), or None."""
    t, n, iso = (photo.metadata.get(k) for k in EXPOSURE_KEYS.values())
    return float(t) * float(iso) / float(n) ** 2 if t and n and iso else None


def exif_setting(metadata):
    """A photograph's EXIF exposure labels (:data:`EXPOSURE_KEYS`) from its ``metadata``."""
    return tuple(metadata.get(k) for k in EXPOSURE_KEYS.values())


def exif_label_loading(first, settings):
    """How the errors of the EXIF labels (:data:`EXIF_LABEL_SD` each) reach the exposures of
    frames labelled ``settings`` (T, :func:`exif_setting`) where their ratios to the first
    frame's (labelled ``first``) scale its given exposure: (K, T) loadings of K independent
    relative errors, one per label value of each key (shutter time, f-number, ISO) other than
    the first frame's (+1 on the frames with it), and the first frame's value of each key that
    some frame changes (-1 on those frames). K is 0 where every frame has the first's labels."""
    rows = []
    for key, base in enumerate(first):
        values = [v[key] for v in settings]
        other = np.array([v != base for v in values], dtype=float)
        rows += [[float(v == u) for v in values] for u in sorted(set(values) - {base}, key=str)]
        rows += [-other] if other.any() else []
    return np.array(rows, dtype=float).reshape(-1, len(settings))


def exif_scaled(doc, frames=None):
    """The label loading (:func:`exif_label_loading`) of the manifest ``doc``'s ``frames``
    (indices; default every lit frame) where EXIF's relative exposures scale a given exposure
    (no reference calibrates the frames) and some frame's labels differ from the first's; else
    None."""
    ingest = doc.get("ingest") or {}
    if ingest.get("calibration") or not ingest.get("relative_exposure_from_exif"):
        return None
    records = {r["index"]: r for r in doc["frames"]}
    frames = [r["index"] for r in doc["frames"] if r.get("status") == "rendered"] \
        if frames is None else frames
    loading = exif_label_loading(exif_setting(doc["frames"][0].get("photo") or {}),
                                 [exif_setting(records[i].get("photo") or {}) for i in frames])
    return loading if len(loading) and loading.any() else None


#: Image formats a folder may hold that skyfit does not read, and what to make of them.
UNREAD_SUFFIXES = {".heic": "HEIF", ".heif": "HEIF", ".avif": "AVIF", ".webp": "WebP",
                   ".jxl": "JPEG XL"}


def list_photos(items):
    """Paths of the photographs in ``items`` (files, or folders in name order, hidden files such
    as macOS's ``._NAME`` copies left out); SkyfitError if one does not exist, or if a folder
    holds images of a format skyfit does not read (a sequence would silently lose them)."""
    paths, unread, below = [], [], []
    for p in map(Path, items):
        if p.is_dir():
            inside = sorted(q for q in p.iterdir() if not q.name.startswith("."))
            paths += [q for q in inside if q.suffix.lower() in SUFFIXES]
            unread += [q for q in inside if q.suffix.lower() in UNREAD_SUFFIXES]
            below += [q for q in inside if q.is_dir()]
        elif p.is_file():
            paths.append(p)
        else:
            raise SkyfitError(f"{p} does not exist; give photographs or a folder of them.")
    if unread:
        kind = UNREAD_SUFFIXES[unread[0].suffix.lower()]
        raise SkyfitError(f"{unread[0].parent} holds {len(unread)} {kind} image(s) "
                          f"({unread[0].name}, ...), which skyfit does not read, beside "
                          f"{len(paths)} it reads; export them as JPEG, 16-bit TIFF or PNG with "
                          "their EXIF (or give the camera's RAW files), or give only the files "
                          "of the sequence.")
    if not paths and below:
        raise SkyfitError(f"{below[0].parent} holds no photographs, only folders "
                          f"({below[0].name}, ...); give the folder that holds them.")
    return paths


def read_flat_field(path, size):
    """The flat field at ``path`` as relative response (H, W), 1 at its brightest, NaN where it
    has no signal (a fisheye's corners beyond its image circle: the frames' pixels there are
    left out); SkyfitError unless of ``size`` (height, width) with some positive value."""
    image = read_photo(Path(path))
    h, w = size
    if image.values.shape[:2] != (h, w):
        raise SkyfitError(f"flat field {path} is {image.values.shape[1]}x{image.values.shape[0]}, "
                          f"the frames {w}x{h}; give one of their size.")
    fl = np.nanmean(image.values if image.kind == "float" else
                    SensorModel(1.0, response=image.encoding_hint, bits=image.bits)
                    .linearise(image.values), axis=2)
    with np.errstate(invalid="ignore"):
        fl = np.where(np.isfinite(fl) & (fl > 0), fl, np.nan)
    if np.all(np.isnan(fl)):
        raise SkyfitError(f"flat field {path} has no positive value; give one exposed so that "
                          "the frames' pixels have signal.")
    return fl / np.nanmax(fl)


def check_same_size(photos_by_path):
    """Refuse frames that differ in size or orientation (SkyfitError naming the first); returns
    their (width, height) [pixels].  ``photos_by_path``: path -> :class:`Photo` or
    ``(height, width[, orientation])`` (mapping or pairs), the first entry the reference."""
    items = list(photos_by_path.items() if hasattr(photos_by_path, "items") else photos_by_path)
    if not items:
        raise SkyfitError("no photographs given; give a folder with at least one image.")

    def shape(v):
        if isinstance(v, Photo):
            return v.width, v.height, v.metadata.get("orientation", 1)
        h, w = int(v[0]), int(v[1])
        return w, h, (int(v[2]) if len(v) > 2 else 1)

    ref_path, ref = items[0]
    rw, rh, ro = shape(ref)
    for path, v in items[1:]:
        w, h, o = shape(v)
        if o != ro:
            raise SkyfitError(
                f"{Path(path).name} has EXIF orientation {o} ({ORIENTATIONS.get(o, '?')}), "
                f"{Path(ref_path).name} has {ro} ({ORIENTATIONS.get(ro, '?')}): a fixed "
                "camera should not turn between frames; set one orientation on every file "
                "(e.g. exiftool -Orientation=1 -n) or remove the odd frames.")
        if (w, h) != (rw, rh):
            raise SkyfitError(
                f"{Path(path).name} is {w}x{h}, {Path(ref_path).name} is {rw}x{rh}: every "
                "frame of a sequence must have the same size; remove or re-export the frames "
                "that differ.")
    return rw, rh
