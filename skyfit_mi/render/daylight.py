"""Daylight in Mitsuba scenes: the ``cie_sky`` emitter's dictionary and per-frame updates.

Importable before a variant is set; the functions need one (:func:`skyfit_mi.render.setup`).
"""

import numpy as np

from ..physics.sky_departure import BASIS

#: The emitter's RGB parameters, named as the :class:`~skyfit_mi.physics.sky.Sky` fields.
RGB_KEYS = ("sun_radiance", "clear", "overcast", "uniform", "intermediate", "perez", "ground")
#: The emitter's float parameters holding the Sky's ``perez_coefficients`` a..e.
PEREZ_KEYS = ("perez_a", "perez_b", "perez_c", "perez_d", "perez_e")
#: The emitter's float parameters holding the Sky's ``departure`` weights (in
#: :data:`~skyfit_mi.physics.sky_departure.BASIS` order).
DEPARTURE_KEYS = tuple(f"departure_{j}" for j in range(len(BASIS)))


def float_parameters(sky):
    """The emitter's float parameters of ``sky`` by name (Perez coefficients, departure weights)."""
    return dict(zip(PEREZ_KEYS + DEPARTURE_KEYS,
                    map(float, np.r_[sky.perez_coefficients, sky.departure])))


def sky_dict(sky, scene_radius=1e4):
    """The ``mi.load_dict`` dictionary of a ``cie_sky`` emitter showing ``sky``."""
    import mitsuba as mi

    d = {"type": "cie_sky", "sun_direction": mi.ScalarVector3f(*map(float, sky.sun_direction)),
         "sun_solid_angle": float(sky.sun_solid_angle), "horizon_blend": bool(sky.horizon_blend),
         "scene_radius": float(scene_radius)}
    for k in RGB_KEYS:
        d[k] = mi.ScalarVector3f(*map(float, getattr(sky, k)))
    d.update(float_parameters(sky))
    if sky.envmap is not None:
        d["envmap"] = mi.TensorXf(envmap_table(sky.envmap))
    return d


def envmap_table(envmap):
    """The emitter's ``envmap`` table of a Sky's ``envmap`` (H, W, 3) [W m^-2 sr^-1]: float32,
    or for None a single black cell."""
    return np.zeros((1, 1, 3), np.float32) if envmap is None else np.asarray(envmap, np.float32)


def jit_array(cls, *columns):
    """A Dr.Jit array of type ``cls`` from NumPy ``columns`` (one per vector component), each
    copied into a 64-byte aligned buffer: on the CPU Dr.Jit uses a NumPy buffer in place and
    compiles kernels for its alignment, so unaligned inputs would recompile them."""
    import drjit as dr

    dtype = np.dtype(dr.type_v(cls).name.lower())
    out = []
    for column in columns:
        column = np.asarray(column).ravel()
        buf = np.empty(column.size + 64 // dtype.itemsize, dtype)
        start = (-buf.ctypes.data % 64) // dtype.itemsize
        out.append(buf[start:start + column.size])
        out[-1][:] = column
    return cls(*out)


def opaque_value(cls, values):
    """An opaque Dr.Jit value of type ``cls`` holding ``values`` (a scalar or a triple), so every
    frame's sky reuses the same kernels; made from Python numbers, as a NumPy buffer's varying
    alignment would compile a kernel per frame."""
    import drjit as dr

    v = cls(*(x.item() for x in np.atleast_1d(np.asarray(values)).ravel()))
    dr.make_opaque(v)
    return v


def update_sky(params, sky, prefix):
    """Write ``sky`` into a ``cie_sky`` emitter's ``params`` under key ``prefix`` (e.g. ``'sky.'``)
    and update them; all values opaque, so nothing recompiles."""
    import mitsuba as mi

    params[prefix + "sun_direction"] = opaque_value(mi.Vector3f, sky.sun_direction)
    params[prefix + "sun_solid_angle"] = opaque_value(mi.Float, float(sky.sun_solid_angle))
    params[prefix + "horizon_blend"] = opaque_value(mi.Bool, bool(sky.horizon_blend))
    for k in RGB_KEYS:
        params[prefix + k] = opaque_value(mi.Color3f, getattr(sky, k))
    for k, v in float_parameters(sky).items():
        params[prefix + k] = opaque_value(mi.Float, v)
    table = envmap_table(sky.envmap)
    params[prefix + "envmap"] = mi.TensorXf(jit_array(mi.Float, table), table.shape)
    params.update()
