"""Pixel values across a rendered sequence (thesis figs. 6.3, 6.14, 6.17): CSV and a plot."""

import csv
import io
from pathlib import Path

import numpy as np

from ..errors import SkyfitError
from ..files import save_figure, write_text
from ..render import setup
from ..render.labels import label_image
from .manifest import frame_axis, is_table, load_manifest, read_frame_pixels
from .observation_table import table_regions

SOURCES = {"radiance": "W m^-2 sr^-1", "radiance_sigma": "W m^-2 sr^-1", "sensor": "DN",
           "sigma": "DN"}


def parse_pixel(text):
    """'X,Y' -> (x, y) integers (x across, y down, from the top-left pixel)."""
    try:
        x, y = (int(v) for v in str(text).split(","))
    except ValueError:
        raise SkyfitError(f"pixel {text!r} is not 'X,Y' (two whole numbers, e.g. 64,40).") from None
    return x, y


def pixel_series(manifest_path, pixels, source="radiance"):
    """Rows (frame, time, x, y, R, G, B) for every rendered frame and pixel."""
    if source not in SOURCES:
        raise SkyfitError(f"unknown source {source!r}; valid: {', '.join(SOURCES)}.")
    doc, root = load_manifest(manifest_path)
    w, h = doc["camera"]["width"], doc["camera"]["height"]
    for x, y in pixels:
        if not (0 <= x < w and 0 <= y < h):
            raise SkyfitError(f"pixel {x},{y} is outside the {w}x{h} image; x in [0, {w - 1}], "
                              f"y in [0, {h - 1}].")
    rows = []
    for f in doc["frames"]:
        if f.get("status") != "rendered":
            continue
        values = read_frame_pixels(root, f, source, (h, w, 3), pixels)
        for (x, y), v in zip(pixels, values):
            rows.append((f["index"], f.get("time", ""), x, y, *map(float, v)))
    return rows, SOURCES[source]


def frame_values(manifest_path, pixels, frames, source="radiance"):
    """Values of ``pixels`` ((P, 2) x, y) in the frames whose index is in ``frames``, in time
    order: (P, T, 3) [``SOURCES[source]``]; each frame checked as ``fit`` checks it, and only
    the pixels' rows read."""
    doc, root = load_manifest(manifest_path)
    shape = (doc["camera"]["height"], doc["camera"]["width"], 3)
    px = np.asarray(pixels, dtype=int)
    wanted = set(int(i) for i in frames)
    return np.stack([read_frame_pixels(root, f, source, shape, px)
                     for f in doc["frames"] if f["index"] in wanted], axis=1).astype(float)


def write_pixels(manifest_path, pixels, out_prefix=None, source="radiance"):
    """Write ``<prefix>.csv`` and ``<prefix>.png``; returns their paths."""
    rows, unit = pixel_series(manifest_path, pixels, source)
    root = Path(manifest_path) if Path(manifest_path).is_dir() else Path(manifest_path).parent
    prefix = Path(out_prefix) if out_prefix else root / f"pixels_{source}"
    buf = io.StringIO()
    wr = csv.writer(buf)
    wr.writerow(["frame", "time", "x", "y", f"R [{unit}]", f"G [{unit}]", f"B [{unit}]"])
    wr.writerows(rows)
    csv_path = write_text(prefix.with_suffix(".csv"), buf.getvalue())

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    styles = ["-", "--", ":", "-."]
    for k, (x, y) in enumerate(pixels):
        sel = [r for r in rows if r[2] == x and r[3] == y]
        t, t_label = frame_axis([r[0] for r in sel], [r[1] or None for r in sel])
        vals = np.array([r[4:] for r in sel])
        for c, colour in enumerate("rgb"):
            ax.plot(t, vals[:, c], styles[k % 4], color=colour, marker="o", ms=3,
                    label=f"({x},{y}) {'RGB'[c]}")
    ax.set_xlabel(t_label)
    ax.set_ylabel(f"{source} [{unit}]")
    ax.set_title(f"pixel values across the sequence ({source})")
    ax.legend(fontsize=7, ncol=len(pixels))
    fig.autofmt_xdate()
    fig.tight_layout()
    return csv_path, save_figure(fig, prefix.with_suffix(".png"))


def scene_labels(manifest):
    """(manifest document, its folder, label image, material ids) of a rendered sequence."""
    doc, root = load_manifest(manifest)
    mi = setup(doc["render"]["variant"])
    return (doc, root, *label_image(mi.load_string(doc["scene"]["xml"])))


def colour_reach(doc):
    """How many pixels from itself a frame of the sequence ``doc`` mixes a pixel's colour
    with others', at most over its frames: 0 but for JPEGs with subsampled chroma and RAWs.
    A RAW's demosaicing draws a pixel's missing colours from photosites around it (AHD's
    reach, :data:`~.photos.RAW_COLOUR_REACH`, recorded in each frame's ``raw_demosaic``).  A
    JPEG of chroma subsampled by f (2 for 4:2:0 and 4:2:2) averages each f x f cell's colour
    into one sample, and the decoder interpolates between neighbouring samples (libjpeg's "fancy"
    upsampling, :func:`~.jpeg_noise.decode`): a pixel's colour then draws on pixels up to f
    away.  One more covers a camera's encoder that smooths its chroma before subsampling.  At
    a boundary between materials the mix is a bias, not noise (measured on a board of
    saturated paints at quality 95, 4:2:0: the blue of yellow paint +26% on the ring next to
    the boundary), so a fit leaves such pixels out (:func:`colour_mixed`).  Registered or
    undistorted photographs (:mod:`.registration`) mix each pixel with its neighbours by their
    resampling, and their motion's uncertainty moves it: ``ingest.registration.erode_px``."""
    frames = doc.get("frames", ())
    factor = max((max(f["jpeg_dc"]["chroma_subsampling"]) for f in frames if "jpeg_dc" in f),
                 default=1)
    jpeg = factor + 1 if factor > 1 else 0
    resampled = int(((doc.get("ingest") or {}).get("registration") or {}).get("erode_px", 0))
    return max([jpeg, resampled] + [int(f["raw_demosaic"]["colour_reach_px"]) for f in frames
                                    if "raw_demosaic" in f])


def colour_mixed(labels, reach):
    """(H, W) bool: the pixels of the label image ``labels`` (:func:`scene_labels`) within
    ``reach`` pixels (a square's half-width) of a pixel of another label, whose colour a
    frame mixes with another material's (:func:`colour_reach`); none for ``reach`` 0."""
    from scipy.ndimage import maximum_filter, minimum_filter

    if reach <= 0:
        return np.zeros(labels.shape, dtype=bool)
    size = 2 * int(reach) + 1
    return maximum_filter(labels, size, mode="nearest") \
        != minimum_filter(labels, size, mode="nearest")


#: The fewest of a material's pixels in JPEG blocks of its own (:func:`jpeg_edge_blocks`) a
#: region takes alone; with fewer it keeps the pixels of blocks its edges cross.
JPEG_CLEAN_MIN = 16


def jpeg_edge_blocks(labels, doc):
    """(H, W) bool: the pixels of the label image ``labels`` that lie in a JPEG coding block
    holding another label too, in any frame of the sequence ``doc`` whose tables round (a
    luminance DC step above 1: below quality 100).  A JPEG rounds each block's coefficients
    together, so an edge's high orders, rounded, ring across its block: an error of the
    scene's edge, the same in every frame, that neither noise nor the bootstrap's draws
    (:func:`~.jpeg_noise.truth_sampler`, which cannot restore what the file zeroed) describe,
    and which stops at the block's border.  Measured on the sample board at quality 92
    (4:4:4): 1-3% of the signal at 2-3 pixels from an edge, at most 0.3% in blocks of one
    material.  Blocks are 8 pixels, 8 f with chroma subsampled by f, from each frame's
    ``jpeg_block_offset``."""
    h, w = labels.shape
    out = np.zeros((h, w), dtype=bool)
    grids = {(tuple(f.get("jpeg_block_offset", (0, 0))),
              8 * max(f["jpeg_dc"]["chroma_subsampling"]))
             for f in doc.get("frames", ()) if "jpeg_dc" in f and max(f["jpeg_dc"]["dc_step"]) > 1}
    for (ox, oy), n in grids:
        yy, xx = np.mgrid[0:h, 0:w]
        cell = ((yy - oy) // n) * (w // n + 2) + (xx - ox) // n
        cell = np.unique(cell, return_inverse=True)[1].reshape(h, w)
        lo = np.full(cell.max() + 1, np.iinfo(np.int64).max)
        hi = np.full(cell.max() + 1, np.iinfo(np.int64).min)
        np.minimum.at(lo, cell.ravel(), labels.ravel())
        np.maximum.at(hi, cell.ravel(), labels.ravel())
        out |= (lo != hi)[cell]
    return out


def pose_reach(doc, pose_sd_deg=None):
    """How many pixels the camera's pose uncertainty may move the scene's labels in its frames
    (``pose_sd_deg``, {angle: 1 sd [deg]} as :func:`~skyfit_mi.render.scene.pose_sd` reads
    it, or the sequence ``doc``'s ``camera.pose_sd_deg``; absent: 0): twice (95%) the
    displacement of the frame's farthest pixel, a turn in azimuth or angle moving the view's
    centre by f theta (f the focal length in pixels) and a roll the corners by their radius
    times it, the angles independent.  The regions a fit takes from the spec's labels stay
    that far inside each material: a pose given to +-1 degree moves a 160-pixel-wide view of
    40 degrees by 4 pixels."""
    from ..physics.lens import focal_px

    sd = pose_sd_deg if pose_sd_deg is not None else doc.get("camera", {}).get("pose_sd_deg")
    if not sd:
        return 0
    cam = doc["camera"]
    w, h = cam["width"], cam["height"]
    f = focal_px(cam["fov_deg"], w)
    rad = {k: np.radians(float(v)) for k, v in sd.items()}
    move = np.sqrt((f * rad.get("azimuth", 0.0)) ** 2 + (f * rad.get("angle", 0.0)) ** 2
                   + (np.hypot(w, h) / 2.0 * rad.get("roll", 0.0)) ** 2)
    return int(np.ceil(2.0 * move - 1e-9))


def material_regions(manifest, pose_sd_deg=None):
    """(name, pixels) of every Ward material the camera sees, from the scene's label image:
    the pixels inside each material's area (edge pixels, which also see a neighbour, left
    out, and in JPEGs with subsampled chroma, demosaiced RAWs or registered photographs those
    whose colour mixes a neighbour's, :func:`colour_reach`, or that the pose's uncertainty,
    ``pose_sd_deg`` or the sequence's, may move onto a neighbour, :func:`pose_reach`; in lossy
    JPEGs those in blocks an edge crosses, :func:`jpeg_edge_blocks`, where JPEG_CLEAN_MIN
    remain without them); SkyfitError when it sees none.
    For an observation table, (name, None) of each region it measures."""
    from scipy.ndimage import binary_erosion

    doc, root = load_manifest(manifest)
    if is_table(doc):                      # (name, None): every point of the region
        return [(name, None) for name in table_regions(root)]
    doc, _, labels, ids = scene_labels(manifest)
    ward = set(doc["scene"]["materials"])
    reach = pose_reach(doc, pose_sd_deg)
    mixed = colour_mixed(labels, max(colour_reach(doc), reach))
    ringing = jpeg_edge_blocks(labels, doc)
    regions = []
    for k, name in enumerate(ids):
        inside = binary_erosion(labels == k + 1, border_value=1) & ~mixed
        if np.sum(inside & ~ringing) >= JPEG_CLEAN_MIN:
            inside &= ~ringing
        ys, xs = np.nonzero(inside)
        if name in ward and len(xs):
            regions.append((name, np.stack([xs, ys], axis=1)))
    if not regions:
        raise SkyfitError(f"the camera sees no Ward material of {manifest} away from its edges"
                          f"{' and the colour its frames mix across them' if mixed.any() else ''}"
                          + (f" by the {reach} pixels the pose's uncertainty may move them (give "
                             "the camera better: skyfit camera)" if reach else "")
                          + "; give regions with --region.")
    return regions
