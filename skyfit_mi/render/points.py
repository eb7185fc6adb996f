"""Where rays meet a scene: the surface, its material and normal (for measured points)."""

import numpy as np


def surface_hits(xml, variant, origins, directions):
    """Trace rays (origins, unit directions (N, 3), world frame) through the scene ``xml``.

    Returns a dict: ``p`` hit points (N, 3) (NaN on a miss), ``n`` shading normals (N, 3),
    ``t`` distances (N,) (inf on a miss), ``material`` the hit shape's BSDF id (None on a
    miss), and ``scale`` the scene's bounding-box diagonal [scene units].
    """
    from . import setup

    mi = setup(variant)
    scene = mi.load_string(xml)
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
