"""Image output: linear EXR frames and PNG previews, written atomically."""

import numpy as np

from ..errors import SkyfitError
from ..files import atomic_write


def write_exr(path, image):
    """Write a linear float32 RGB image (H, W, 3) [W m^-2 sr^-1], or a one-channel map (H, W)
    (channel Y), as OpenEXR."""
    import mitsuba as mi

    fmt = mi.Bitmap.PixelFormat.Y if np.ndim(image) == 2 else mi.Bitmap.PixelFormat.RGB
    bmp = mi.Bitmap(np.ascontiguousarray(image, dtype=np.float32), fmt)
    return atomic_write(path, lambda p: bmp.write(p))


def read_exr(path):
    """Read an EXR written by :func:`write_exr` as a float32 array (H, W, 3)."""
    import mitsuba as mi

    return np.array(mi.Bitmap(str(path)), dtype=np.float32)


def read_exr_checked(path, shape):
    """:func:`read_exr`, raising SkyfitError (naming the file and what is wrong) unless the
    file reads as an image of ``shape`` (H, W, 3)."""
    try:
        img = read_exr(path)
    except Exception as exc:          # Mitsuba raises RuntimeError for unreadable files
        raise SkyfitError(f"cannot read {path} ({str(exc).splitlines()[0]})") from None
    if img.shape != tuple(shape):
        raise SkyfitError(f"{path} is {img.shape[1]}x{img.shape[0]} with "
                          f"{img.shape[2] if img.ndim == 3 else 1} channels, not the camera's "
                          f"{shape[1]}x{shape[0]} RGB")
    return img


def to_srgb8(image, exposure):
    """Linear RGB times ``exposure`` to 8-bit sRGB (IEC 61966-2-1 transfer curve)."""
    x = np.clip(np.nan_to_num(np.asarray(image, dtype=float) * exposure), 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(srgb * 255).astype(np.uint8)


#: zlib level of the PNG previews written with Pillow: level 1 encodes a contact sheet or a
#: comparison 2.5-3x faster than the default 6, in files 15-25% larger.
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

    Returns
    -------
    values : ndarray, shape (H, W, C)
        The file's pixels in its own component type (float32/float16 for EXR and RGBE,
        uint8/uint16 codes for PNG).
    channels : list of str
        Channel names, e.g. ``['R', 'G', 'B']``, ``['R', 'G', 'B', 'A']`` or ``['Y']``.

    Raises whatever Mitsuba raises on an unreadable file (``RuntimeError``); callers in the
    pipeline turn it into a :class:`~skyfit_mi.errors.SkyfitError` naming the file.
    """
    import mitsuba as mi

    bmp = mi.Bitmap(str(path))
    values = np.array(bmp)
    if values.ndim == 2:
        values = values[:, :, None]
    struct = bmp.struct_()
    channels = [struct[i].name for i in range(bmp.channel_count())]
    return values, channels
