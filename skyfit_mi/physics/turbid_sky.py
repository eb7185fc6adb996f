"""A clear sky driven by the atmosphere's turbidity: one number for the sky's shape and levels.

The thesis names turbidity-driven skies as the extension of its clear sky (section 4.2.1): haze
takes light from the sun's beam, more the longer its path, and spreads it over the sky, brightest
toward the horizon and the sun.  One number, the Linke turbidity T_L (about 2 very clear, 3-4 a
common clear day, 5-7 hazy), sets:

* the levels: DNI and DHI of Ineichen and Perez's clear-sky model (2002) via
  ``pvlib.clearsky.ineichen`` (Kasten-Young air mass at the site's pressure, as pvlib's
  ``Location.get_clearsky``);
* the shape: Preetham, Shirley and Smits's luminance distribution (1999, appendix A.2), the
  Perez form (:func:`~skyfit_mi.physics.sky.perez_relative_luminance`) with coefficients linear
  in turbidity (:data:`LUMINANCE_TURBIDITY`).

Preetham's turbidity counts visible haze scattering, Linke's the whole broadband extinction
(water vapour too), about 1 higher for the same air; taking Preetham's pattern at the Linke
value makes it about one step hazier than Preetham's own.  A sky-shape fit moves both together.

The sky's colour is uniform (a CCT, thesis 4.2.3), the sun's that of its air mass
(:func:`~skyfit_mi.physics.sun.sun_rgb`); levels are broadband [W m^-2], carried as the
luminance-weighted linear-sRGB irradiance, as in :mod:`~skyfit_mi.physics.perez`.

References
----------
A. J. Preetham, P. Shirley, B. Smits, "A practical analytic model for daylight", SIGGRAPH 99,
91-100, 1999 (appendix A.2: the distribution coefficients of luminance Y).

P. Ineichen, R. Perez, "A new airmass independent formulation for the Linke turbidity
coefficient", Solar Energy 73(3), 151-157, 2002.
"""

import numpy as np

from ..conventions import direction_from_angles
from ..errors import check_range
from .colour import cct_to_rgb
from .sky import CCT_CLEAR, GROUND_ALBEDO, Sky, hemisphere_integral, perez_pattern
from .sun import SUN_SOLID_ANGLE, sun_rgb

#: Preetham et al. 1999, appendix A.2: a, b, c, d, e of the luminance distribution (their A-E)
#: as (slope, intercept) in the turbidity T [unitless].
LUMINANCE_TURBIDITY = np.array([[0.1787, -1.4630],
                                [-0.3554, 0.4275],
                                [-0.0227, 5.3251],
                                [0.1206, -2.5771],
                                [-0.0670, 0.3703]])
#: The turbidities a turbid sky takes, very clear to hazy (below about 1.2 the pattern's b
#: turns positive, unbounded toward the horizon).
TURBIDITY_RANGE = (2.0, 10.0)
#: One turbidity step of a sky-shape fit (:func:`shape_moves`): clear days' Linke turbidity
#: scatters by about 1 about its mean (Ineichen and Perez 2002), the shape prior's one sd.
TURBIDITY_STEP = 1.0


def coefficients(turbidity):
    """a, b, c, d, e [unitless], shape T's + (5,), of Preetham's luminance distribution at
    ``turbidity`` T (appendix A.2)."""
    t = np.asarray(check_range("turbidity", turbidity, *TURBIDITY_RANGE), dtype=float)
    return t[..., None] * LUMINANCE_TURBIDITY[:, 0] + LUMINANCE_TURBIDITY[:, 1]


def levels(turbidity, sun_zenith_deg, day_of_year, elevation_m=0.0):
    """(DNI, DHI) [W m^-2] of Ineichen and Perez's clear sky (2002) at Linke ``turbidity``, sun
    zenith ``sun_zenith_deg``, ``day_of_year`` and site ``elevation_m`` [m]; both 0 with the sun
    at or below the horizon."""
    check_range("turbidity", turbidity, *TURBIDITY_RANGE)
    check_range("sun zenith", sun_zenith_deg, 0.0, 180.0, "degrees")
    check_range("elevation", elevation_m, -500.0, 9000.0, "m")
    if sun_zenith_deg >= 90.0:
        return 0.0, 0.0
    import pvlib.atmosphere
    import pvlib.clearsky
    import pvlib.irradiance

    air_mass = pvlib.atmosphere.get_absolute_airmass(
        pvlib.atmosphere.get_relative_airmass(sun_zenith_deg, "kastenyoung1989"),
        pvlib.atmosphere.alt2pres(elevation_m))
    sky = pvlib.clearsky.ineichen(sun_zenith_deg, air_mass, turbidity, altitude=elevation_m,
                                  dni_extra=pvlib.irradiance.get_extra_radiation(day_of_year))
    return float(sky["dni"]), float(sky["dhi"])


def turbid_sky(turbidity, sun_zenith_deg, sun_azimuth_deg, *, day=172, elevation_m=0.0,
               cct=CCT_CLEAR, sun=True, ground_albedo=GROUND_ALBEDO,
               sun_solid_angle=SUN_SOLID_ANGLE):
    """The clear sky of Linke ``turbidity`` (module docstring) as a :class:`Sky`.

    The Perez term carries Preetham's pattern scaled to :func:`levels`' DHI (luminance-
    weighted), coloured by ``cct`` [K]; the sun's disc carries the DNI (if ``sun``); the ground
    is Lambertian, lit by both.  A black sky with the sun at or below the horizon.
    """
    check_range("ground albedo", ground_albedo, 0.0, 1.0)
    c = coefficients(turbidity)
    dni, dhi = levels(turbidity, sun_zenith_deg, day, elevation_m)
    s = direction_from_angles(np.radians(sun_zenith_deg), np.radians(sun_azimuth_deg))
    pattern = float(hemisphere_integral(lambda d: perez_pattern(d, s, c))) if dhi > 0 else 1.0
    sky = Sky(s, perez=dhi / pattern * cct_to_rgb(cct), perez_coefficients=c,
              sun_radiance=(dni if sun else 0.0) / sun_solid_angle * sun_rgb(
                  min(float(sun_zenith_deg), 90.0)),
              sun_solid_angle=sun_solid_angle,
              info={"kind": "turbid", "turbidity": float(turbidity),
                    "sun_zenith_deg": float(sun_zenith_deg),
                    "sun_azimuth_deg": float(sun_azimuth_deg),
                    "day_of_year": int(day), "elevation_m": float(elevation_m),
                    "direct_normal_W_m2": dni, "diffuse_horizontal_W_m2": dhi,
                    "ground_albedo": ground_albedo})
    return sky.with_ground(ground_albedo)


def shape_moves(info):
    """The move of a turbid sky's shape that a sky-shape fit mixes with it, for
    :func:`turbid_sky`'s ``info``: Preetham's pattern :data:`TURBIDITY_STEP` higher (+1) or
    lower (-1); None beyond :data:`TURBIDITY_RANGE`.  The levels it brings are
    :func:`level_factors`'.

    Returns
    -------
    list of dict
        One: ``of`` 'turbidity', ``index`` 'T', ``from`` and ``moves`` {+1, -1: None or
        ``to`` and ``coefficients`` (a..e)}.
    """
    t = float(info["turbidity"])
    moves = {}
    for sign in (1, -1):
        to = t + sign * TURBIDITY_STEP
        moves[sign] = ({"to": to, "coefficients": coefficients(to).tolist()}
                       if TURBIDITY_RANGE[0] <= to <= TURBIDITY_RANGE[1] else None)
    return [{"of": "turbidity", "index": "T", "from": t, "moves": moves}]


#: Largest sun zenith [degrees] at which :func:`level_factors` follows the model (fitted to
#: suns above about 4 degrees; its diffuse light falls to 0 nearer the horizon).
FACTOR_ZENITH_DEG = 85.0


def level_factors(infos, variant_infos, mix):
    """(sun, sky) factors, each (T,): DNI and DHI (:func:`levels`) at a fitted turbidity over
    those of each frame's turbid sky (``infos``).  The turbidity is from + ``mix`` (to - from)
    of each frame's shape variant (``variant_infos``), held to :data:`TURBIDITY_RANGE`, so one
    number moves the sky's shape and level and the sun's (more for a low sun); a sun lower than
    :data:`FACTOR_ZENITH_DEG` takes its factors there."""
    sun, sky = [], []
    for info, v in zip(infos, variant_infos):
        t = float(np.clip(v["from"] + float(mix) * (v["to"] - v["from"]), *TURBIDITY_RANGE))
        z = min(float(info["sun_zenith_deg"]), FACTOR_ZENITH_DEG)
        at = [levels(x, z, info["day_of_year"], info["elevation_m"])
              for x in (t, float(info["turbidity"]))]
        (dni, dhi), (dni0, dhi0) = at
        sun.append(dni / dni0 if dni0 > 0 else 1.0)
        sky.append(dhi / dhi0 if dhi0 > 0 else 1.0)
    return np.array(sun), np.array(sky)
