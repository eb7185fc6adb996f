"""Daylight in Mitsuba scenes: the ``cie_sky`` emitter's dictionary and per-frame updates.

Importable before a variant is set; the functions need one (see
:func:`skyfit_mi.render.setup`).
"""

#: The emitter's RGB parameters, named as the :class:`~skyfit_mi.physics.sky.Sky` fields.
RGB_KEYS = ("sun_radiance", "clear", "overcast", "uniform", "intermediate", "ground")


def sky_dict(sky, scene_radius=1e4):
    """The ``mi.load_dict`` dictionary of a ``cie_sky`` emitter showing ``sky``."""
    import mitsuba as mi

    d = {"type": "cie_sky", "sun_direction": mi.ScalarVector3f(*map(float, sky.sun_direction)),
         "sun_solid_angle": float(sky.sun_solid_angle), "horizon_blend": bool(sky.horizon_blend),
         "scene_radius": float(scene_radius)}
    for k in RGB_KEYS:
        d[k] = mi.ScalarVector3f(*map(float, getattr(sky, k)))
    return d


def update_sky(params, sky, prefix):
    """Write ``sky`` into a ``cie_sky`` emitter through ``mi.traverse`` parameters.

    ``prefix`` is the emitter's key prefix in ``params`` (e.g. ``'sky.'`` for an
    emitter with id ``sky``).  Calls ``params.update()``; no recompilation.
    """
    import mitsuba as mi

    params[prefix + "sun_direction"] = mi.Vector3f(*map(float, sky.sun_direction))
    params[prefix + "sun_solid_angle"] = mi.Float(float(sky.sun_solid_angle))
    params[prefix + "horizon_blend"] = mi.Bool(bool(sky.horizon_blend))
    for k in RGB_KEYS:
        params[prefix + k] = mi.Color3f(*map(float, getattr(sky, k)))
    params.update()
