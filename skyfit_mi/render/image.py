"""Image files: linear float32 OpenEXR frames (read and written through OpenEXR's Python
bindings) and PNG previews, written atomically.

:func:`write_exr` writes single-part scanline float32 R, G, B (H, W, 3) or Y (H, W), ZIPS
compressed (one scanline per chunk, so reading a few pixels decodes only their rows), with the
frame's metadata in the header.

A missing, foreign or damaged file raises a one-line :class:`~skyfit_mi.errors.SkyfitError`
naming it, with what OpenEXR printed (:func:`_native_quiet`).  OpenEXR's reader is fuzzed
upstream (OSS-Fuzz) and raises rather than aborts, so EXR files are read in this process
(unlike Radiance RGBE: :mod:`skyfit_mi.pipeline.photos`).
"""

import contextlib
import datetime as dt
import io
import os
import sys
import tempfile
import threading

import numpy as np

from ..errors import SkyfitError
from ..files import atomic_write

#: The first four bytes of every OpenEXR file.
EXR_MAGIC = b"\x76\x2f\x31\x01"
#: Prefix of skyfit's own header attributes ('skyfit/kind', 'skyfit/frame'...).
META_PREFIX = "skyfit/"
#: Scanlines per chunk of each compression (OpenEXR's file layout): rows are read in whole
#: chunks.  Unknown ones: 32 (any count is correct).
CHUNK_LINES = {"NO_COMPRESSION": 1, "RLE_COMPRESSION": 1, "ZIPS_COMPRESSION": 1,
               "ZIP_COMPRESSION": 16, "PXR24_COMPRESSION": 16, "PIZ_COMPRESSION": 32,
               "B44_COMPRESSION": 32, "B44A_COMPRESSION": 32, "DWAA_COMPRESSION": 32,
               "DWAB_COMPRESSION": 256}
#: Channel orders read as an image's last axis: RGB(A) and grey as Mitsuba gave them.
_ORDERS = (("R", "G", "B", "A"), ("R", "G", "B"), ("Y", "A"), ("Y",))

_NATIVE_LOCK = threading.Lock()


@contextlib.contextmanager
def _native_quiet():
    """Capture what OpenEXR prints in the block (the C library on fd 2, the bindings on
    ``sys.stdout``): yields a list that receives those lines on an exception; on success the
    output is passed on unchanged (a good file prints nothing)."""
    with _NATIVE_LOCK:
        sys.stderr.flush()
        saved = os.dup(2)
        lines = []
        out = io.StringIO()
        with tempfile.TemporaryFile() as log:
            os.dup2(log.fileno(), 2)
            ok = False
            try:
                with contextlib.redirect_stdout(out):
                    yield lines
                ok = True
            finally:
                os.dup2(saved, 2)
                os.close(saved)
                log.seek(0)
                err = log.read().decode("utf-8", "replace")
                if ok:
                    if err:
                        os.write(2, err.encode())
                    if out.getvalue():
                        sys.stdout.write(out.getvalue())
                else:
                    lines += [ln.strip() for ln in (out.getvalue() + err).splitlines()
                              if ln.strip()]


def _why(path, exc, lines):
    """One line saying why ``path`` did not read as OpenEXR (``lines``: what OpenEXR printed)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
    except FileNotFoundError:
        return "no such file"
    except OSError as err:
        return err.strerror or str(err)
    if head != EXR_MAGIC:
        return "not an OpenEXR file" + (" (empty)" if not head else "")
    said = [ln for ln in lines if not ln.startswith("Warning: Exception raised")]
    detail = said[-1] if said else (str(exc).strip().splitlines() or [type(exc).__name__])[-1]
    if detail.startswith(f"{path}:"):             # the C library's "<path>: (EXR_ERR_..) .."
        detail = detail[len(str(path)) + 1:].strip()
    elif detail.startswith("Unable to open"):     # the bindings': the header did not read
        detail = "its header does not read"
    return f"a damaged or truncated OpenEXR file: {detail[:200]}"


class ExrError(SkyfitError):
    """An OpenEXR file that does not read: ``why`` says why, in a few words."""

    def __init__(self, path, why):
        super().__init__(f"cannot read {path}: {why}")
        self.path, self.why = str(path), why


@contextlib.contextmanager
def _reading(path):
    """The block quiet (:func:`_native_quiet`), its exceptions raised as one :class:`ExrError`
    on ``path`` (a SkyfitError or MemoryError as it is)."""
    lines = []
    try:
        with _native_quiet() as lines:
            yield
    except (SkyfitError, MemoryError):
        raise
    except Exception as exc:             # noqa: BLE001 -- RuntimeError, OSError, ValueError..
        raise ExrError(path, _why(path, exc, lines)) from None


def _header_meta(meta):
    """Header attributes of a frame's ``meta`` (dict), each under :data:`META_PREFIX` (dates as
    ISO text); a ``time`` (aware datetime or ISO text) also as the standard ``capDate`` (local,
    'YYYY:MM:DD hh:mm:ss') and ``utcOffset`` (seconds, UTC = local + utcOffset)."""
    out = {}
    for key, value in (meta or {}).items():
        if value is None:
            continue
        if isinstance(value, str):
            text = value
        elif isinstance(value, (dt.datetime, dt.date)):
            text = value.isoformat()
        elif isinstance(value, (bool, np.bool_)):
            text = "true" if value else "false"
        elif isinstance(value, (int, np.integer)):
            out[META_PREFIX + key] = int(value)
            continue
        elif isinstance(value, (float, np.floating)):
            out[META_PREFIX + key] = float(value)
            continue
        else:
            raise TypeError(f"EXR header value {key}={value!r}: give text, a number or a date")
        out[META_PREFIX + key] = text
    when = (meta or {}).get("time")
    if isinstance(when, str):
        when = dt.datetime.fromisoformat(when)
    if isinstance(when, dt.datetime):
        out["capDate"] = when.strftime("%Y:%m:%d %H:%M:%S")
        if when.utcoffset() is not None:
            out["utcOffset"] = float(-when.utcoffset().total_seconds())
    return out


def write_exr(path, image, meta=None):
    """Write a linear float32 RGB image (H, W, 3) [W m^-2 sr^-1], or a one-channel map (H, W),
    as OpenEXR, atomically; ``meta`` goes in the header (e.g. ``{"kind": "radiance", "frame":
    3, "time": datetime}``; :func:`read_exr_meta`).  Returns ``path``."""
    import OpenEXR

    image = np.ascontiguousarray(image, dtype=np.float32)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim == 2:
        channels = {"Y": image}
    elif image.ndim == 3 and image.shape[2] == 3:
        channels = {"RGB": image}
    else:
        raise ValueError(f"write_exr takes (H, W, 3) or (H, W), not {image.shape}")
    header = {"compression": OpenEXR.ZIPS_COMPRESSION, "type": OpenEXR.scanlineimage,
              "generatedBy": "skyfit-mi", **_header_meta(meta)}

    def write(tmp):
        try:
            with OpenEXR.File(header, channels) as f:
                f.write(str(tmp))
        except RuntimeError as exc:      # OpenEXR's I/O errors (a full disk): atomic_write's
            # OSError, with the reason after the temporary file's name ('Cannot write ... "tmp".
            # No space left on device.')
            raise OSError(str(exc).rsplit('". ', 1)[-1].rstrip(".")) from None
    return atomic_write(path, write)


def _layout(header):
    """(channel names in the order read, (H, W), first row's y, scanlines per chunk) of an
    EXR ``header``."""
    names = [c.name for c in header["channels"]]
    order = next((list(o) for o in _ORDERS if set(o) == set(names)), sorted(names))
    (x0, y0), (x1, y1) = (np.asarray(v) for v in header["dataWindow"])
    lines = CHUNK_LINES.get(getattr(header.get("compression"), "name", ""), 32)
    return order, (int(y1 - y0 + 1), int(x1 - x0 + 1)), int(y0), lines


def _stack(planes):
    """Channel planes -> (H, W) for one, (H, W, C) for more, float32."""
    if len(planes) == 1:
        return np.array(planes[0], dtype=np.float32)          # a copy of the file's buffer
    return np.stack(planes, axis=-1).astype(np.float32, copy=False)


def read_exr_channels(path):
    """OpenEXR ``path`` as stored: (values (H, W, C) in the file's pixel type, channel names of
    the last axis: R, G, B(, A), or Y(, A), else by name); raises :class:`ExrError`."""
    import OpenEXR

    path = str(path)
    with _reading(path), OpenEXR.File(path, separate_channels=True) as f:
        chans = f.channels()
        order, _, _, _ = _layout(f.header())
        return np.stack([chans[n].pixels for n in order], axis=-1), order


def read_exr_header(path):
    """The header of OpenEXR ``path`` (OpenEXR.File's dict; no pixels read)."""
    import OpenEXR

    with _reading(path), OpenEXR.File(str(path), header_only=True) as f:
        return dict(f.header())         # a copy: closing the file empties its own


def read_exr_meta(path):
    """The frame metadata :func:`write_exr` put in ``path``'s header ({} if none)."""
    return {k[len(META_PREFIX):]: v for k, v in read_exr_header(path).items()
            if k.startswith(META_PREFIX)}


def read_exr_shape(path):
    """(H, W, channel count), or (H, W) for one channel, of OpenEXR ``path`` from its header."""
    order, (h, w), _, _ = _layout(read_exr_header(path))
    return (h, w, len(order)) if len(order) > 1 else (h, w)


def read_exr(path, rows=None):
    """Read an OpenEXR file as float32: (H, W, 3) for RGB (RGBA: 4), (H, W) for one channel,
    else its channels in name order; with ``rows`` (from the top of the data window) only those
    scanlines, in that order, decoding only their chunks.  Raises SkyfitError."""
    path = str(path)
    if rows is None:
        values = read_exr_channels(path)[0].astype(np.float32, copy=False)
        return values[..., 0] if values.shape[-1] == 1 else values
    with _reading(path):
        return _read_rows(path, np.asarray(rows, dtype=int).reshape(-1))


def _read_rows(path, rows):
    """:func:`read_exr`'s rows: each needed chunk once, runs of chunks in one call of OpenEXR's
    ``InputFile`` (the whole image where the bindings lack it)."""
    import OpenEXR

    with OpenEXR.File(path, header_only=True) as f:
        order, (h, w), y0, lines = _layout(dict(f.header()))
    if rows.size and (rows.min() < 0 or rows.max() >= h):
        bad = rows[(rows < 0) | (rows >= h)][0]
        raise SkyfitError(f"cannot read row {bad} of {path}: it has rows 0 to {h - 1}")
    if not hasattr(OpenEXR, "InputFile"):                 # a future release without it
        with OpenEXR.File(path, separate_channels=True) as f:
            chans = f.channels()
            return _stack([chans[n].pixels[rows] for n in order])
    import Imath

    chunks = np.unique(rows // lines)
    # runs of consecutive chunks: [first chunk, last chunk]
    breaks = np.flatnonzero(np.diff(chunks) > 1)
    starts = np.concatenate([chunks[:1], chunks[breaks + 1]])
    ends = np.concatenate([chunks[breaks], chunks[-1:]])
    out = np.empty((rows.size, w, len(order)), np.float32)
    pt = Imath.PixelType(Imath.PixelType.FLOAT)
    src = OpenEXR.InputFile(path)
    try:
        for a, b in zip(starts, ends):
            r0, r1 = int(a * lines), int(min(h - 1, b * lines + lines - 1))
            data = src.channels(order, pt, y0 + r0, y0 + r1)
            run = np.stack([np.frombuffer(buf, np.float32).reshape(r1 - r0 + 1, w)
                            for buf in data], axis=-1)
            inside = (rows >= r0) & (rows <= r1)
            out[inside] = run[rows[inside] - r0]
    finally:
        src.close()
    return out[..., 0] if len(order) == 1 else out


def read_exr_pixels(path, pixels):
    """The values of ``pixels`` ((P, 2) x, y) of OpenEXR ``path``: (P, C) float32 ((P,) for one
    channel), reading only their rows (:func:`read_exr`)."""
    px = np.asarray(pixels, dtype=int).reshape(-1, 2)
    rows, at = np.unique(px[:, 1], return_inverse=True)
    img = read_exr(path, rows)
    return img[at.reshape(-1), px[:, 0]]


def check_exr_shape(path, shape, found):
    """SkyfitError unless an EXR's image shape ``found`` (H, W[, C]) is ``shape`` (H, W, 3)."""
    if tuple(found) != tuple(shape):
        raise SkyfitError(f"{path} is {found[1]}x{found[0]} with "
                          f"{found[2] if len(found) == 3 else 1} channels, not the camera's "
                          f"{shape[1]}x{shape[0]} RGB")


def check_exr(path, shape):
    """SkyfitError unless ``path`` is an OpenEXR of ``shape`` (H, W, 3) with all its chunks
    (header and chunk table only: damage inside a chunk shows when its pixels are read)."""
    import OpenEXR

    check_exr_shape(path, shape, read_exr_shape(path))
    if not hasattr(OpenEXR, "InputFile"):
        return
    with _reading(path):
        src = OpenEXR.InputFile(str(path))
        try:
            complete = src.isComplete()
        finally:
            src.close()
    if not complete:
        raise SkyfitError(f"cannot read {path}: a truncated OpenEXR file (some of its chunks "
                          "are missing)")


def read_exr_checked(path, shape, pixels=None):
    """:func:`read_exr` (or :func:`read_exr_pixels` of ``pixels``), raising SkyfitError unless
    the file is an image of ``shape`` (H, W, 3)."""
    if pixels is None:
        img = read_exr(path)
        check_exr_shape(path, shape, img.shape)
        return img
    check_exr_shape(path, shape, read_exr_shape(path))
    return read_exr_pixels(path, pixels)


def to_srgb8(image, exposure):
    """Linear RGB times ``exposure`` to 8-bit sRGB (IEC 61966-2-1 transfer curve)."""
    x = np.clip(np.nan_to_num(np.asarray(image, dtype=float) * exposure), 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(srgb * 255).astype(np.uint8)


#: zlib level of PNG previews: level 1 is several times faster than the default 6, files a
#: little larger.
PNG_COMPRESS_LEVEL = 1


def write_png(path, image8):
    """Write an 8-bit RGB image (H, W, 3) as PNG."""
    from PIL import Image

    return atomic_write(path, lambda p: Image.fromarray(
        np.ascontiguousarray(image8, dtype=np.uint8)).save(p, format="png",
                                                           compress_level=PNG_COMPRESS_LEVEL))


def contact_sheet(images, exposure, columns=5, gap=2):
    """Tile linear images (same shape) into one 8-bit sRGB preview at a common exposure."""
    h, w, _ = images[0].shape
    rows = -(-len(images) // columns)
    sheet = np.full((rows * (h + gap) - gap, columns * (w + gap) - gap, 3), 255, np.uint8)
    for i, im in enumerate(images):
        r, c = divmod(i, columns)
        sheet[r * (h + gap):r * (h + gap) + h, c * (w + gap):c * (w + gap) + w] = to_srgb8(im, exposure)
    return sheet


def read_bitmap(path):
    """Read any image Mitsuba's ``Bitmap`` reads (OpenEXR, Radiance RGBE ``.hdr``/``.pic``,
    PNG of 8 or 16 bits, PFM...) as it is stored, with no conversion.

    Returns (values (H, W, C) in the file's component type, channel names such as
    ``['R', 'G', 'B']`` or ``['Y']``); raises Mitsuba's ``RuntimeError`` on an unreadable file.
    """
    import mitsuba as mi

    bmp = mi.Bitmap(str(path))
    values = np.array(bmp)
    if values.ndim == 2:
        values = values[:, :, None]
    struct = bmp.struct_()
    channels = [struct[i].name for i in range(bmp.channel_count())]
    return values, channels
