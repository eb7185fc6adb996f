"""Mitsuba's built-in ``sunsky`` emitter (Hosek-Wilkie) as a reference sky for comparisons.

The emitter's default frame is +Z up, so world vectors in the project's frame go in unchanged.
Only the sky is evaluated (``sun_scale`` 0); its RGB radiance, on the emitter's own scale, is
weighted to luminance by :data:`~skyfit_mi.physics.colour.SRGB_LUMINANCE`.

References
----------
L. Hosek, A. Wilkie, "An analytic model for full spectral sky-dome radiance", ACM
Transactions on Graphics 31(4), 95, 2012, doi:10.1145/2185520.2185591.
"""

import numpy as np

from skyfit_mi.conventions import unit_directions
from skyfit_mi.physics.colour import SRGB_LUMINANCE
from skyfit_mi.physics.sky import GROUND_ALBEDO
from skyfit_mi.render.variant import setup

from .sky_measurement import SkyModel

#: Turbidities tried per scan by :func:`sunsky_model`: the emitter's range [1, 10], step 0.25.
TURBIDITIES = tuple(float(t) for t in np.round(np.arange(1.0, 10.0 + 1e-9, 0.25), 2))


def sunsky_luminance(directions, sun_direction, turbidities, albedo=GROUND_ALBEDO):
    """Luminance of Mitsuba's ``sunsky`` sky (no sun disc) toward world ``directions``.

    ``directions`` (n, 3), ``sun_direction`` (3,) unit, world frame; ``turbidities`` each in
    [1, 10]; ``albedo`` in [0, 1].  Returns (len(turbidities), n): the luminance on the
    emitter's own scale, 0 at and below the horizon.
    """
    mi = setup()
    import drjit as dr

    d = unit_directions(directions)
    emitter = mi.load_dict({"type": "sunsky", "turbidity": float(turbidities[0]),
                            "albedo": float(albedo), "sun_scale": 0.0,
                            "sun_direction": mi.ScalarVector3f(*map(float, sun_direction))})
    params = mi.traverse(emitter)
    si = dr.zeros(mi.SurfaceInteraction3f, len(d))
    si.wi = mi.Vector3f(*(-d.T))                  # wi points away from the sky
    out = []
    for t in turbidities:
        params["turbidity"] = float(t)
        params.update()
        out.append(np.array(emitter.eval(si), dtype=float).T @ SRGB_LUMINANCE)
    return np.array(out)


def sunsky_model(turbidities=TURBIDITIES):
    """The ``sunsky`` sky as a :class:`~skyfit_testkit.sky_measurement.SkyModel`, its
    turbidity fitted per scan over ``turbidities``."""
    return SkyModel("sunsky_fit",
                    lambda d, scan, values: sunsky_luminance(d, scan.sun_direction, values),
                    parameters=tuple(turbidities), parameter_name="turbidity", held_out=True,
                    description="Mitsuba sunsky (Hosek-Wilkie), sky only, albedo "
                                f"{GROUND_ALBEDO:g}, turbidity in [1, 10] fitted per scan "
                                "(step 0.25)")
