"""Rendering one frame with Mitsuba: the image and the Monte Carlo error of each pixel."""

import numpy as np


def render_with_error(mi, scene, params, seed, half):
    """A frame and each pixel's Monte Carlo standard error, from two independent renders a, b
    of ``half`` spp: their mean, and (a - b)^2 / 4 averaged over 3x3 pixels as its variance."""
    a = np.array(mi.render(scene, params, seed=seed, spp=half), dtype=np.float64)
    b = np.array(mi.render(scene, params, seed=seed + 2**31, spp=half), dtype=np.float64)
    var = (a - b) ** 2 / 4.0
    pad = np.pad(var, ((1, 1), (1, 1), (0, 0)), mode="edge")
    h, w = var.shape[:2]
    var = sum(pad[i:i + h, j:j + w] for i in range(3) for j in range(3)) / 9.0
    return (0.5 * (a + b)).astype(np.float32), np.sqrt(var).astype(np.float32)
