"""Label masks: which material each pixel of a sequence's camera sees (for fit regions)."""

import numpy as np


def label_image(scene):
    """(H, W) int array: 1 + the index of the material seen at each pixel centre, 0 for none,
    and the sorted material ids (label k is ids[k - 1]), independent of the shapes' order."""
    import mitsuba as mi

    sensor = scene.sensors()[0]
    w, h = sensor.film().crop_size()
    ys, xs = np.mgrid[0:h, 0:w]
    u = (xs.ravel() + 0.5) / w
    v = (ys.ravel() + 0.5) / h
    ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5), mi.Point2f(u, v), mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(ray)
    valid = np.array(si.is_valid())
    hits = [(shape.bsdf().id(), np.array(si.shape == mi.ShapePtr(shape)) & valid)
            for shape in scene.shapes() if shape.bsdf().id()]
    ids = sorted({bid for bid, _ in hits})
    labels = np.zeros(w * h, dtype=np.int32)
    for bid, hit in hits:
        labels[hit] = ids.index(bid) + 1
    return labels.reshape(h, w), ids
