"""Pixel values across a rendered sequence (thesis figs. 6.3, 6.14, 6.17): CSV and a plot."""

import csv
import io
from pathlib import Path

import numpy as np

from ..errors import SkyfitError
from ..files import output_prefix, save_figure, write_text
from ..render import setup
from ..render.scene import load_xml
from ..render.labels import label_image
from .manifest import frame_axis, is_table, load_manifest, read_frame_pixels
from .observation_table import table_regions
from .region_edges import (JPEG_CLEAN_MIN, colour_mixed, colour_reach, jpeg_edge_blocks,
                           pose_reach)

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
    if is_table(doc):
        raise SkyfitError(f"{root} is an observation table (values per point, no images): its "
                          "values are in its table; pixels reads the frames of a rendered or "
                          "photographed sequence.")
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
    """Values (P, T, 3) [``SOURCES[source]``] of ``pixels`` ((P, 2) x, y) in ``frames``, in time
    order, checked as ``fit`` checks them; only the pixels' rows are read."""
    doc, root = load_manifest(manifest_path)
    shape = (doc["camera"]["height"], doc["camera"]["width"], 3)
    px = np.asarray(pixels, dtype=int)
    wanted = set(int(i) for i in frames)
    return np.stack([read_frame_pixels(root, f, source, shape, px)
                     for f in doc["frames"] if f["index"] in wanted], axis=1).astype(float)


def write_pixels(manifest_path, pixels, out_prefix=None, source="radiance"):
    """Write ``<prefix>.csv`` and ``<prefix>.png`` (``out_prefix`` a folder: pixels_SOURCE in
    it; default the sequence's folder); returns their paths."""
    rows, unit = pixel_series(manifest_path, pixels, source)
    root = Path(manifest_path) if Path(manifest_path).is_dir() else Path(manifest_path).parent
    prefix = output_prefix(out_prefix or root, f"pixels_{source}")
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
    setup(doc["render"]["variant"])
    return (doc, root, *label_image(load_xml(doc["scene"]["xml"])))


def material_regions(manifest, pose_sd_deg=None, log=None):
    """(name, pixels) of every Ward material the camera sees: each material's inner pixels, away
    from edges, colour mixing, pose uncertainty (``pose_sd_deg`` or the sequence's) and JPEG
    edge blocks (:mod:`.region_edges`); ``log`` names a material left without pixels;
    SkyfitError if none is seen.  For an observation table, (name, None) per region."""
    from scipy.ndimage import binary_erosion

    doc, root = load_manifest(manifest)
    if is_table(doc):                      # (name, None): every point of the region
        return [(name, None) for name in table_regions(root)]
    doc, _, labels, ids = scene_labels(manifest)
    ward = set(doc["scene"]["materials"])
    reach = pose_reach(doc["camera"], pose_sd_deg)
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
        elif name in ward and log is not None:
            log(f"{name}: no pixel lies away from its edges"
                + (f" by the {reach} pixels the pose's uncertainty may move them" if reach
                   else "") + "; not fitted (give it with --region)")
    if not regions:
        raise SkyfitError(f"the camera sees no Ward material of {manifest} away from its edges"
                          f"{' and the colour its frames mix across them' if mixed.any() else ''}"
                          + (f" by the {reach} pixels the pose's uncertainty may move them (give "
                             "the camera better: skyfit camera)" if reach else "")
                          + "; give regions with --region.")
    return regions
