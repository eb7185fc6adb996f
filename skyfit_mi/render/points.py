"""Where rays meet a scene: the surface, its material and normal (for measured points)."""

import numpy as np


def load_points_scene(xml, variant):
    """The scene ``xml`` loaded in Mitsuba ``variant``, for :func:`surface_hits`."""
    from . import setup

    return setup(variant).load_string(xml)


def surface_hits(scene, origins, directions):
    """Trace rays (origins, unit directions (N, 3), world frame) through a loaded ``scene``.

    Returns a dict: ``p`` hit points (N, 3) (NaN on a miss), ``n`` shading normals (N, 3),
    ``t`` distances (N,) (inf on a miss), ``material`` the hit shape's BSDF id (None on a
    miss), and ``scale`` the scene's bounding-box diagonal [scene units].
    """
    import mitsuba as mi

    o = np.asarray(origins, dtype=float)
    d = np.asarray(directions, dtype=float)
    si = scene.ray_intersect(mi.Ray3f(mi.Point3f(*o.T), mi.Vector3f(*d.T)))
    valid = np.array(si.is_valid(), dtype=bool)
    ids = np.full(len(o), None, dtype=object)
    for shape in scene.shapes():
        on = np.array(si.shape == mi.ShapePtr(shape), dtype=bool) & valid
        ids[on] = shape.bsdf().id()
    box = scene.bbox()
    scale = float(np.linalg.norm(np.array(box.max, dtype=float) - np.array(box.min, dtype=float)))
    return {"p": np.where(valid[:, None], np.array(si.p, dtype=float).T, np.nan),
            "n": np.array(si.sh_frame.n, dtype=float).T,
            "t": np.where(valid, np.array(si.t, dtype=float), np.inf), "material": ids,
            "scale": scale}
