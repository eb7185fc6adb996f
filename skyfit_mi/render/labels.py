"""Label masks: which material each pixel of a sequence's camera sees (for fit regions)."""

import numpy as np

from .scene import pixel_rays, shape_index


def label_image(scene):
    """(H, W) int array: 1 + the index of the material seen at each pixel centre, 0 for none,
    and the sorted material ids (label k is ids[k - 1]), independent of the shapes' order."""
    sensor = scene.sensors()[0]
    w, h = sensor.film().crop_size()
    ys, xs = np.mgrid[0:h, 0:w]
    si = scene.ray_intersect(pixel_rays(sensor, np.c_[xs.ravel(), ys.ravel()] + 0.5))
    shapes = scene.shapes()
    bids = [shape.bsdf().id() for shape in shapes]
    ids = sorted(set(filter(None, bids)))
    label = np.array([0] + [ids.index(b) + 1 if b else 0 for b in bids], dtype=np.int32)
    return label[shape_index(si, shapes) + 1].reshape(h, w), ids
