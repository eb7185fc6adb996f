"""What a JPEG does to a photograph's noise, found by compressing the scene again.

A JPEG rounds each 8x8 block's DCT coefficients (Y, Cb, Cr) to multiples of its quantisation
tables: on a smooth surface it *removes* noise (high frequencies round to zero), adds rounding
error to the kept coefficients and mixes the channels through YCbCr.  Neither the tables' bound
(:func:`tables_bound`) nor pixel-to-pixel differences give the error about the scene that
chi-square needs, so :func:`bootstrap_variance` finds it by a parametric bootstrap: draws of the
scene given the file (:func:`truth_sampler`), each photographed again with fresh sensor noise
(thesis ch. 5) and the file's own tables (:func:`recompress`), and decoded as ingest decodes
(:func:`decode`).  The bootstrap cannot draw the content that rings at an edge, so
:func:`skyfit_mi.pipeline.ingest.pixel_sigma` adds :func:`tables_bound` in blocks holding one.
Accuracy by quality: docs/BENCHMARKS.md, "A JPEG's sigma".  Noise is seeded (:data:`SEED`).
"""

import io
import os
import tempfile

import numpy as np

from .orientation import apply_orientation, undo_orientation

#: Re-compressed copies per frame for its error variance.
REPLICATES = 8
#: Seed of the bootstrap's noise (with the frame's index; recorded in the manifest).
SEED = 20261125
#: DCT coefficients (u + v <= 2: mean, gradients, curvature) whose rounding interval always
#: holds the scene's content, zeroed or not: smooth shading and vignetting live there.
LOW_ORDER = np.add.outer(np.arange(8), np.arange(8)) <= 2


def jpeg_settings(path):
    """The compression of JPEG ``path`` as Pillow re-applies it: ``{"qtables": ...,
    "subsampling": 0 (4:4:4, or one grey component) | 1 (4:2:2) | 2 (4:2:0)}``; None for
    other files."""
    from PIL import Image, JpegImagePlugin

    with Image.open(path) as im:
        if im.format != "JPEG" or not getattr(im, "quantization", None):
            return None
        sampling = JpegImagePlugin.get_sampling(im)
        return {"qtables": {k: list(v) for k, v in im.quantization.items()},
                "subsampling": 0 if im.mode == "L" else 2 if sampling < 0 else int(sampling)}


def stored(values, settings):
    """``values`` (H, W, ...) in the file's layout (``settings["orientation"]`` undone)."""
    return undo_orientation(values, settings.get("orientation", 1))


def displayed(values, settings):
    """The inverse of :func:`stored`: a contiguous array as the frame is displayed."""
    return np.ascontiguousarray(apply_orientation(values, settings.get("orientation", 1)))


def block_offset(orientation, shape, block=8):
    """(ox, oy) in [0, block) of the block grid of a frame displayed with ``shape`` after EXIF
    ``orientation``: pixel (x, y) lies in block ((x - ox) // block, (y - oy) // block)."""
    settings = {"orientation": orientation}
    fh, fw = stored(np.broadcast_to(False, tuple(shape[:2])), settings).shape
    yy, xx = np.mgrid[0:fh % block + block, 0:fw % block + block] // block
    shown = apply_orientation(np.stack([yy, xx], axis=-1), orientation)

    def first_edge(line):                      # where the block changes first, modulo block
        edges = np.flatnonzero(np.any(line[1:] != line[:-1], axis=-1))
        return int(edges[0] + 1) % block if edges.size else 0
    return first_edge(shown[0]), first_edge(shown[:, 0])


def block_size(settings):
    """Side of the JPEG's coding unit [pixels]: 16 with subsampled chroma, else 8."""
    return 16 if settings["subsampling"] else 8


def tables_bound(settings):
    """Error variance [DN^2] (3,) if every coefficient were rounded uniformly over its table
    entry q (mean q^2 / 12, through JFIF's inverse): an upper bound, reached at an edge."""
    var = {k: float(np.mean(np.asarray(v, dtype=float) ** 2)) / 12.0
           for k, v in settings["qtables"].items()}
    luma, chroma = var.get(0, 0.0), var.get(1, var.get(0, 0.0))
    return luma + (_JFIF_CHROMA ** 2).sum(axis=1) * chroma


def recompress(values, settings, sensor, noise, rng):
    """A copy of frame ``values`` [DN] with fresh ``noise`` (a [DN^2], b [DN]), compressed with
    ``settings``: (its decoded codes, the noisy codes before compression), (H, W, 3) [DN]."""
    from PIL import Image

    a, b = noise
    m = sensor.max_code
    lin = sensor.linearise(np.nan_to_num(values)) * m
    noisy = lin + rng.normal(size=lin.shape) * np.sqrt(np.maximum(a + b * lin, 0.0))
    codes = np.clip(sensor.respond(np.clip(noisy / m, 0.0, 1.0)) * m, 0, m)
    buf = io.BytesIO()
    Image.fromarray(np.rint(codes).astype(np.uint8)).save(
        buf, format="JPEG", qtables=settings["qtables"], subsampling=settings["subsampling"])
    return decode(buf.getvalue()), codes


#: The colour spaces in which :func:`decode` reads a JPEG's planes, and their planes.
_DECODED_SPACES = {"JCS_YCbCr": 3, "JCS_RGB": 3, "JCS_GRAYSCALE": 1}


def decode(source):
    """RGB codes [DN] (H, W, 3) float, or (H, W, 1) for grey, of JPEG ``source`` (path or
    bytes), decoded in floating point from its DCT coefficients (jpeglib): dequantised,
    orthonormal inverse DCT-II, chroma upsampled as libjpeg's "fancy" upsampling, and JFIF's
    YCbCr -> RGB (ITU-T T.871, eq. 7; RGB or grey files as they are), nothing rounded.

    (libjpeg's whole-code planes would put one undithered error on a smooth patch.)  Values
    are clamped to [0, 255], those within half a code of either end set to it.  None where
    jpeglib cannot read the file or it is CMYK or YCCK."""
    import jpeglib
    from scipy.fft import idctn

    path = source
    if not isinstance(source, (str, os.PathLike)):
        fd, path = tempfile.mkstemp(suffix=".jpg")
        with os.fdopen(fd, "wb") as f:
            f.write(bytes(source))
    try:
        im = jpeglib.read_dct(str(path))
        space = str(im.jpeg_color_space)
        comps = [im.Y] + ([im.Cb, im.Cr] if im.has_chrominance else [])
        if im.has_black or any(c is None for c in comps) or space not in _DECODED_SPACES \
                or len(comps) != _DECODED_SPACES[space]:
            return None
        h, w = int(im.height), int(im.width)
        factors = np.asarray(im.samp_factor, dtype=int).reshape(-1, 2)
        planes = []
        for c, coef in enumerate(comps):
            q = np.asarray(im.qt[int(im.quant_tbl_no[c])], dtype=float)
            pix = idctn(coef.astype(float) * q, axes=(2, 3), norm="ortho")
            nby, nbx = coef.shape[:2]
            plane = pix.transpose(0, 2, 1, 3).reshape(nby * 8, nbx * 8) + 128.0
            fy, fx = factors.max(axis=0) // factors[c]
            planes.append(_upsample(plane, fy, fx, h, w))
    except Exception:                   # noqa: BLE001 -- jpeglib: OSError, ValueError ..
        return None
    finally:
        if path is not source:
            os.unlink(path)
    if len(planes) == 1:
        rgb = planes[0][..., None]
    elif space == "JCS_RGB":                 # coded as R, G, B (an Adobe file, say): as they are
        rgb = np.stack(planes, axis=-1)
    else:
        y, cb, cr = planes
        rgb = y[..., None] + np.stack([cb - 128.0, cr - 128.0], axis=-1) @ _JFIF_CHROMA.T
    rgb = np.clip(rgb, 0.0, 255.0)
    return np.where(rgb >= 254.5, 255.0, np.where(rgb <= 0.5, 0.0, rgb))


def _upsample(plane, fy, fx, h, w):
    """The (h, w) image of ``plane``'s samples, each covering fy x fx pixels, by linear
    interpolation between sample centres, edges held (libjpeg's "fancy" upsampling)."""
    for axis, f, size in ((0, fy, h), (1, fx, w)):
        n = -(-size // f)                               # samples that cover the image
        x = np.clip((np.arange(size) + 0.5) / f - 0.5, 0, n - 1)
        i0 = np.floor(x).astype(int)
        i1 = np.minimum(i0 + 1, n - 1)
        t = x - i0
        a, b = np.take(plane, i0, axis=axis), np.take(plane, i1, axis=axis)
        t = t.reshape((-1, 1) if axis == 0 else (1, -1))
        plane = a * (1.0 - t) + b * t
    return plane


def bootstrap_variance(values, settings, sensor, noise, seed, replicates=REPLICATES):
    """Each value's error variance [DN^2] (H, W, 3), the errors' correlation within 8x8 blocks
    (3,), and their mean [DN] (H, W, 3); ``values`` as displayed (worked in :func:`stored`).

    The variance: mean over ``replicates`` draws (:func:`truth_sampler`) of (copy - draw)^2
    (:func:`recompress`), 3x3 averaged.  rho from the block means: var(mean) =
    var (1 + 63 rho) / 64 (:func:`skyfit_mi.fitting.chi2.load_observations`).  The mean is the
    compression's bias per coding unit: copy less its noisy codes, both linearised (copy - draw
    or a mean in codes would bias dark channels high), in codes at each pixel's level; its
    estimate's variance is added to the variance.
    """
    rng = np.random.default_rng(seed)
    values = stored(values, settings)
    sample = truth_sampler(values, settings)
    h, w = np.shape(values)[:2]
    bh, bw = h // 8 * 8, w // 8 * 8
    n = block_size(settings)
    var, block, total = 0.0, 0.0, 0.0
    cell_sum, cell_sq = 0.0, 0.0
    for _ in range(replicates):
        truth = sample(rng)
        copy, codes = recompress(truth, settings, sensor, noise, rng)
        err = copy - truth
        var = var + err ** 2
        e = err[:bh, :bw]                                  # whole 8x8 blocks
        block = block + np.mean(_cell_means(e, 8) ** 2, axis=(0, 1))
        total = total + np.mean(e ** 2, axis=(0, 1))
        cells = _cell_means(sensor.linearise(copy) - sensor.linearise(codes), n)
        cell_sum, cell_sq = cell_sum + cells, cell_sq + cells ** 2
    var = var / replicates
    pad = np.pad(var, ((1, 1), (1, 1), (0, 0)), mode="edge")
    smooth = sum(pad[i:i + h, j:j + w] for i in range(3) for j in range(3)) / 9.0
    with np.errstate(all="ignore"):
        rho = np.clip(np.nan_to_num((64.0 * block / total - 1.0) / 63.0), 0.0, 1.0)
    mean = cell_sum / replicates
    spread = (cell_sq - replicates * mean ** 2) / max(replicates - 1, 1)

    def to_pixels(x):
        return np.repeat(np.repeat(x, n, axis=0), n, axis=1)[:h, :w]

    # in codes at each pixel's own level (d code / d signal; 0 where clipped)
    slope = sensor.slope(sensor.linearise(np.nan_to_num(values))) * sensor.max_code
    bias = to_pixels(mean) * slope
    mean_var = np.mean(to_pixels(np.maximum(spread, 0.0)) * slope ** 2, axis=(0, 1)) / replicates
    return displayed(smooth + mean_var, settings), rho, displayed(bias, settings)


def _cell_means(x, n):
    """Means of (H, W, 3) ``x`` over its n x n cells from the top left (edges: partial cells)."""
    h, w = x.shape[:2]
    ph, pw = -h % n, -w % n
    ones = np.pad(np.ones((h, w, 1)), ((0, ph), (0, pw), (0, 0)))
    x = np.pad(x, ((0, ph), (0, pw), (0, 0)))
    shape = (x.shape[0] // n, n, x.shape[1] // n, n)
    return x.reshape(shape + (3,)).sum(axis=(1, 3)) / ones.reshape(shape + (1,)).sum(axis=(1, 3))


#: JFIF's RGB -> YCbCr (ITU-T T.871, eqs. 3-5; Cb, Cr offset by 128) and the weights of Cb and
#: Cr in each of R, G, B on the way back (eq. 7).
_RGB_TO_YCC = np.array([[0.299, 0.587, 0.114],
                        [-0.168736, -0.331264, 0.5],
                        [0.5, -0.418688, -0.081312]])
_JFIF_CHROMA = np.array([[0.0, 1.402], [-0.344136, -0.714136], [1.772, 0.0]])


def _factors(settings):
    """Chroma subsampling (rows, columns): 4:4:4 (1, 1), 4:2:2 (1, 2), 4:2:0 (2, 2)."""
    return {0: (1, 1), 1: (1, 2)}.get(settings["subsampling"], (2, 2))


def truth_sampler(values, settings):
    """A function of a numpy Generator drawing the scene's codes [DN] (H, W, 3) given the decoded
    ``values``: in each block's DCT of Y, Cb, Cr, every kept coefficient (above q / 2) or of
    :data:`LOW_ORDER` moves uniformly within its rounding interval; higher zeroed ones stay zero
    (a smooth surface has no content there)."""
    from scipy.fft import dctn, idctn

    v = np.nan_to_num(np.asarray(values, dtype=float))
    h, w = v.shape[:2]
    ycc = v @ _RGB_TO_YCC.T
    planes = []
    for c in range(3):
        fy, fx = (1, 1) if c == 0 else _factors(settings)
        table = np.asarray(settings["qtables"].get(0 if c == 0 else 1,
                                                   settings["qtables"][0]), dtype=float)
        ph, pw = -h % (8 * fy), -w % (8 * fx)
        plane = np.pad(ycc[..., c], ((0, ph), (0, pw)), mode="edge")
        plane = plane.reshape(plane.shape[0] // fy, fy, plane.shape[1] // fx, fx).mean(axis=(1, 3))
        nby, nbx = plane.shape[0] // 8, plane.shape[1] // 8
        q = table.reshape(8, 8)[None, :, None, :]
        coeff = dctn(plane.reshape(nby, 8, nbx, 8), axes=(1, 3), norm="ortho")
        step = np.where((np.abs(coeff) > q / 2.0) | LOW_ORDER[None, :, None, :], q, 0.0)
        planes.append((step, fy, fx))

    def draw(rng):
        delta = []
        for step, fy, fx in planes:
            move = rng.uniform(-0.5, 0.5, size=step.shape) * step
            nby, _, nbx, _ = step.shape
            d = idctn(move, axes=(1, 3), norm="ortho").reshape(nby * 8, nbx * 8)
            delta.append(np.repeat(np.repeat(d, fy, axis=0), fx, axis=1)[:h, :w])
        dy, dcb, dcr = delta
        return v + dy[..., None] + np.stack([dcb, dcr], axis=-1) @ _JFIF_CHROMA.T

    return draw


#: JFIF's Y, Cb, Cr -> R, G, B (columns: a unit error of each plane in each channel).
YCC_TO_RGB = np.column_stack([np.ones(3), _JFIF_CHROMA])
#: Harmonics of the rounding error's sawtooth summed by :func:`shared_error_sd`.
_HARMONICS = np.arange(1, 33)


def dc_record(settings):
    """What :func:`shared_error_sd` needs of JPEG ``settings``: the DC quantisation steps of Y,
    Cb and Cr and the chroma's subsampling (rows, columns)."""
    tables = settings["qtables"]
    luma, chroma = tables[0][0], tables.get(1, tables[0])[0]
    return {"dc_step": [float(luma), float(chroma), float(chroma)],
            "chroma_subsampling": list(_factors(settings))}


def shared_error_sd(values, noise_var, record):
    """Standard deviation [DN] (3,) of the error the pixels of one region of one JPEG frame
    share in Y, Cb, Cr (:data:`YCC_TO_RGB` takes it to R, G, B): the rounding of block means.

    A block's DC (8 x its mean) is rounded to a multiple of q (``record``, :func:`dc_record`);
    on one colour every block rounds alike, an error no number of pixels averages away.  Noise
    in the block means (sd s in units of q, from ``noise_var`` (P, 3) [DN^2]) dithers it, and a
    spread of the means (range R in q, from ``values`` (P, 3) [DN]) spreads it.  The sawtooth
    sum_k (-1)^(k+1) q sin(2 pi k x / q) / (pi k), damped by exp(-2 pi^2 k^2 s^2) and sinc(k R),
    gives the variance q^2 sum_k exp(-4 pi^2 k^2 s^2) sinc^2(k R) / (2 pi^2 k^2) (q^2 / 12
    without noise or spread); a pixel carries 1/8 of its block's DC error."""
    values = np.asarray(values, dtype=float).reshape(-1, 3)
    noise_var = np.asarray(noise_var, dtype=float).reshape(-1, 3)
    ok = np.all(np.isfinite(values) & np.isfinite(noise_var), axis=1)
    if ok.sum() < 1:
        return np.zeros(3)
    ycc = values[ok] @ _RGB_TO_YCC.T
    plane_var = np.mean(noise_var[ok], axis=0) @ (_RGB_TO_YCC ** 2).T        # (3,) per pixel
    fy, fx = record["chroma_subsampling"]
    cells = np.array([1.0, fy * fx, fy * fx])               # pixels per sample of each plane
    q = np.asarray(record["dc_step"], dtype=float)
    s = 8.0 * np.sqrt(plane_var / (64.0 * cells)) / q       # the DC's noise, in steps
    spread = np.var(ycc, axis=0) - plane_var if ok.sum() > 1 else np.zeros(3)
    r = 8.0 * np.sqrt(12.0 * np.maximum(spread, 0.0)) / q   # the DCs' range, in steps
    k = _HARMONICS[:, None]
    v = np.sum(np.exp(-4.0 * np.pi ** 2 * k ** 2 * s ** 2) * np.sinc(k * r) ** 2
               / (2.0 * np.pi ** 2 * k ** 2), axis=0)
    return np.sqrt(v) * q / 8.0
