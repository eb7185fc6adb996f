"""Reading plugin properties given as numbers, lists, 'a, b, c' strings or constant textures."""

import drjit as dr
import mitsuba as mi
import numpy as np


def property_values(props, name, default):
    """The property ``name`` as a 1-D float array (``default`` when it is absent)."""
    if name not in props:
        return np.atleast_1d(np.asarray(default, dtype=float))
    v = props[name]
    if isinstance(v, mi.Texture):                 # <rgb>/<float> written as a constant texture
        v = np.array(v.eval(dr.zeros(mi.SurfaceInteraction3f)), dtype=float)
    if isinstance(v, str):
        v = [float(x) for x in v.replace(",", " ").split()]
    return np.asarray(v, dtype=float).ravel()
