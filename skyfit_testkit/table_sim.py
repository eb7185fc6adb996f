"""A rendered sequence measured at points: an observation table, for tests and the lab example.

:func:`measure_table` reads a ``render`` sequence folder at the centres of chosen pixels, as an
instrument would: each pixel's central ray gives the point and its region, each rendered frame's
radiance there, with Gaussian noise, the row's value and sigma; the view is the table's default
(toward the camera).  Lab lights name frames by index, a day by time.  Noise is drawn from
``numpy.random.default_rng([seed, frame index])``; the settings go to ``<table>.json``.
"""

import csv
import io
from pathlib import Path

import numpy as np

from skyfit_mi.errors import SkyfitError
from skyfit_mi.files import write_json, write_text
from skyfit_mi.pipeline.manifest import load_manifest, read_frame_pixels, rendered_frames
from skyfit_mi.render.points import load_points_scene, pixel_points


def measure_table(sequence, pixels, out, *, noise=0.01, seed=0, saturate=None):
    """Write ``sequence``'s observation table at the centres of ``pixels`` ((P, 2) x, y) to CSV
    ``out`` (settings beside it, ``.json``); returns its path.  ``noise``: relative sd of each
    point's channel mean, in quadrature with ``radiance_sigma``; ``saturate``: clipping level
    [W m^-2 sr^-1] (values above it flagged ``saturated``), or None."""
    doc, root = load_manifest(sequence)
    frames = rendered_frames(doc)
    if not frames:
        raise SkyfitError(f"{sequence} holds no rendered frame; render it first.")
    pixels = np.asarray(pixels, dtype=int).reshape(-1, 2)
    hits = pixel_points(load_points_scene(doc["scene"]["xml"], doc["render"]["variant"]), pixels)
    missed = ~np.isfinite(hits["p"]).all(axis=1) | (hits["material"] == None)  # noqa: E711
    if missed.any():
        x, y = pixels[missed][0]
        raise SkyfitError(f"pixel {x},{y} of {sequence} sees no surface of its scene; choose "
                          "pixels on the sample.")
    by_index = any("time" not in f for f in frames)
    shape = (doc["camera"]["height"], doc["camera"]["width"], 3)
    flags = ["saturated_r", "saturated_g", "saturated_b"] if saturate is not None else []
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["frame" if by_index else "time", "region", "point", "x", "y", "z", "r", "g", "b",
                "sigma_r", "sigma_g", "sigma_b", *flags])
    n_clipped = 0
    for f in frames:
        L = read_frame_pixels(root, f, "radiance", shape, pixels)
        mc = read_frame_pixels(root, f, "radiance_sigma", shape, pixels)
        sigma = np.sqrt((noise * L.mean(axis=1, keepdims=True)) ** 2 + mc.astype(float) ** 2)
        value = L + sigma * np.random.default_rng([seed, f["index"]]).standard_normal(L.shape)
        clipped = value >= saturate if saturate is not None else np.zeros(L.shape, bool)
        value = np.where(clipped, saturate, value) if saturate is not None else value
        n_clipped += int(clipped.sum())
        for k, ((x, y), p) in enumerate(zip(pixels, hits["p"])):
            w.writerow([f["index"] if by_index else f["time"], hits["material"][k],
                        f"x{x}y{y}", *(f"{v:.6g}" for v in (*p, *value[k], *sigma[k])),
                        *(int(c) for c in (clipped[k] if flags else ()))])
    out = write_text(Path(out), buf.getvalue())
    write_json(out.with_suffix(".json"), {
        "sequence": doc.get("name"), "run_id": doc["run_id"], "pixels": pixels.tolist(),
        "noise": noise, "seed": seed, "saturate_W_m2_sr": saturate,
        "saturated_values": n_clipped,
        "rule": "value = radiance + sigma N(0, 1), numpy.random.default_rng([seed, frame "
                "index]); sigma = noise x the point's mean radiance over channels, in "
                "quadrature with the render's radiance_sigma"})
    return out
