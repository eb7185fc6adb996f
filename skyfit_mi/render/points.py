"""Where rays meet a scene: the surface, its material and normal (for measured points), and
the light a white Lambertian surface reflects there (an observation table's reference)."""

import numpy as np

from . import setup
from .basis_table import trace_basis
from .light_cache import DIRECTIONS, POSITIONS, CacheOptions
from .scene import load_xml, pixel_rays, shape_index


def load_points_scene(xml, variant):
    """The scene ``xml`` loaded in Mitsuba ``variant``, for :func:`surface_hits`."""
    setup(variant)
    return load_xml(xml)


def surface_hits(scene, origins, directions):
    """Trace rays (origins, unit directions (N, 3), world frame) through a loaded ``scene``:
    a dict of hit points ``p`` (N, 3) (NaN on a miss), shading normals ``n``, distances ``t``
    (N,) (inf), the hit ``material`` id (None) and ``scale``, the bounding-box diagonal."""
    import mitsuba as mi

    o = np.asarray(origins, dtype=float)
    d = np.asarray(directions, dtype=float)
    si = scene.ray_intersect(mi.Ray3f(mi.Point3f(*o.T), mi.Vector3f(*d.T)))
    valid = np.array(si.is_valid(), dtype=bool)
    shapes = scene.shapes()
    ids = np.array([None] + [s.bsdf().id() for s in shapes], dtype=object)
    box = scene.bbox()
    scale = float(np.linalg.norm(np.array(box.max, dtype=float) - np.array(box.min, dtype=float)))
    return {"p": np.where(valid[:, None], np.array(si.p, dtype=float).T, np.nan),
            "n": np.array(si.sh_frame.n, dtype=float).T,
            "t": np.where(valid, np.array(si.t, dtype=float), np.inf),
            "material": ids[shape_index(si, shapes) + 1], "scale": scale}


def pixel_points(scene, pixels):
    """Where the central rays of ``pixels`` ((P, 2) x, y) of the scene's first sensor meet the
    scene: :func:`surface_hits`' dict (``p`` NaN where a ray misses)."""
    ray = pixel_rays(scene.sensors()[0], np.asarray(pixels, dtype=float).reshape(-1, 2) + 0.5)
    return surface_hits(scene, np.array(ray.o, dtype=float).T, np.array(ray.d, dtype=float).T)


def lambertian_radiance(xml, variant, skies, rays, material, max_depth, seed=0,
                        positions=POSITIONS, directions=DIRECTIONS):
    """The radiance a white Lambertian surface on ``material`` reflects along ``rays``
    (:class:`~.light_cache.PointRays`, P points x T frames) under ``skies`` (T), traced by the
    light cache as a fit traces its points, and its Monte Carlo variance: (P, T, 3)
    [W m^-2 sr^-1] and [(W m^-2 sr^-1)^2]."""
    scene = load_points_scene(xml, variant)
    options = CacheOptions(positions, directions, seed, max_depth)
    (diffuse,), _, _ = trace_basis(scene, setup(variant).traverse(scene), [list(skies)], rays,
                                   material, options, model="colour", diffuse_only=True)
    return diffuse
