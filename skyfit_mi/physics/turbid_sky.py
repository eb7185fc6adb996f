"""A clear sky driven by the atmosphere's turbidity: one number for the sky's shape and levels.

The thesis's clear sky (eqs. 4.7, 4.10-4.15) fixes the sun's extinction and the sky's pattern;
it names skies for polluted and turbid atmospheres, driven by a turbidity factor, as their
extension (section 4.2.1).  Haze takes light from the sun's beam, more of it the longer the
beam's path through the air (so more in the morning and evening), and spreads it over the sky,
brightest toward the horizon and around the sun.  Here one number, the Linke turbidity T_L
(the atmosphere's optical depth in units of a clean, dry atmosphere's: about 2 very clear, 3-4
a common clear day, 5-7 hazy), sets both:

* the levels: the sun's direct normal irradiance and the sky's diffuse horizontal irradiance
  of Ineichen and Perez's clear-sky model (2002), through pvlib
  (``pvlib.clearsky.ineichen``, with the Kasten-Young air mass at the site's pressure and its
  altitude, as pvlib's own ``Location.get_clearsky`` calls it);
* the shape: Preetham, Shirley and Smits's luminance distribution (1999, appendix A.2), the
  Perez form (:func:`~skyfit_mi.physics.sky.perez_relative_luminance`) with coefficients
  linear in the turbidity (:data:`LUMINANCE_TURBIDITY`).

The two turbidities are not the same scale.  Preetham's T = (tau_air + tau_haze) / tau_air
counts the haze's scattering in the visible; the Linke factor counts the whole broadband
extinction, water vapour's absorption too, and runs about 1 higher for the same air (0.9-1.4
for 0.5-3 cm of precipitable water, Preetham's haze carried through pvlib's Bird-Hulstrom
aerosol depth and Kasten's Linke formula).  This module takes one number for both: its pattern
is Preetham's at the Linke value, so about one step hazier than Preetham's own for that air.
On the shared measured clear day the pattern fitted to the scans alone read 2.2 and the day's
diffuse light T_L 2.7-2.9 (``tests/test_real_sky.py``), about that offset.  A fit that moves
the turbidity (``fit --sky-shape``) moves both together.

The sky's colour is uniform (a colour temperature, thesis 4.2.3) and the sun's that of its
air mass (:func:`~skyfit_mi.physics.sun.sun_rgb`); Preetham's chromaticity distribution is not
modelled.  Both levels are broadband [W m^-2], carried as the luminance-weighted linear-sRGB
irradiance, as the Perez sky of measured irradiance is (:mod:`~skyfit_mi.physics.perez`).

References
----------
A. J. Preetham, P. Shirley, B. Smits, "A practical analytic model for daylight", SIGGRAPH 99,
91-100, 1999 (appendix A.2: the distribution coefficients of luminance Y).

P. Ineichen, R. Perez, "A new airmass independent formulation for the Linke turbidity
coefficient", Solar Energy 73(3), 151-157, 2002.
"""

from dataclasses import replace

import numpy as np

from ..conventions import direction_from_angles
from ..errors import check_range
from .colour import cct_to_rgb
from .sky import CCT_CLEAR, GROUND_ALBEDO, Sky, hemisphere_integral, perez_pattern
from .sun import SUN_SOLID_ANGLE, sun_rgb

#: Preetham et al. 1999, appendix A.2: the coefficients a, b, c, d, e of the luminance
#: distribution (their A-E) as (slope, intercept) in the turbidity T [unitless].
LUMINANCE_TURBIDITY = np.array([[0.1787, -1.4630],
                                [-0.3554, 0.4275],
                                [-0.0227, 5.3251],
                                [0.1206, -2.5771],
                                [-0.0670, 0.3703]])
#: The turbidities a turbid sky takes: from a very clear atmosphere to a hazy one (beyond,
#: the sun fades and the sky is no longer a clear one's; below about 1.2 the pattern's b
#: turns positive and the sky grows without bound toward the horizon).
TURBIDITY_RANGE = (2.0, 10.0)
#: One step of the turbidity in a fit of the sky's shape (``fit --sky-shape``,
#: :func:`shape_moves`): clear days' Linke turbidity scatters by about 1 about its mean
#: (2-6 over a year at one site; Ineichen and Perez 2002), so one step is the shape prior's
#: one standard deviation (:data:`~skyfit_mi.fitting.sky_fit.SHAPE_SD`).
TURBIDITY_STEP = 1.0


def coefficients(turbidity):
    """a, b, c, d, e of Preetham's luminance distribution at ``turbidity`` T (appendix A.2):
    each slope x T + intercept (:data:`LUMINANCE_TURBIDITY`) [unitless], shape T's + (5,)."""
    t = np.asarray(check_range("turbidity", turbidity, *TURBIDITY_RANGE), dtype=float)
    return t[..., None] * LUMINANCE_TURBIDITY[:, 0] + LUMINANCE_TURBIDITY[:, 1]


def levels(turbidity, sun_zenith_deg, day_of_year, elevation_m=0.0):
    """(direct normal, diffuse horizontal) irradiance [W m^-2] of Ineichen and Perez's
    clear sky (2002) at Linke ``turbidity`` with the sun ``sun_zenith_deg`` from the zenith,
    on ``day_of_year`` (the extraterrestrial irradiance's), ``elevation_m`` above sea level;
    both 0 with the sun at or below the horizon."""
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

    The Perez term carries Preetham's pattern (:func:`coefficients`), scaled so that its
    luminance-weighted horizontal irradiance is the diffuse horizontal irradiance of
    :func:`levels` and coloured by ``cct`` [K]; the sun's disc carries the direct normal
    irradiance (with ``sun``); the ground is Lambertian (``ground_albedo``), lit by both.  The
    sun ``sun_zenith_deg``, ``sun_azimuth_deg`` [degrees]; ``day`` of the year; the site
    ``elevation_m`` [m].  With the sun at or below the horizon, a black sky.

    Info: kind 'turbid', turbidity, the sun's angles, the day, the elevation, the two
    irradiances [W m^-2] and the ground albedo."""
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
    return replace(sky, ground=ground_albedo * sky.horizontal_irradiance() / np.pi)


def shape_moves(info):
    """The move of a turbid sky's shape that a fit mixes with it (``fit --sky-shape``,
    :func:`~skyfit_mi.physics.sky_shape.shape_variants`), for the sky of :func:`turbid_sky`'s
    ``info``: Preetham's pattern at the turbidity :data:`TURBIDITY_STEP` higher (+1) or lower
    (-1); None beyond :data:`TURBIDITY_RANGE`.  The variant is lit as the sky is
    (:func:`~skyfit_mi.physics.sky_shape.shape_variants`); the levels a fitted turbidity
    brings are :func:`level_factors`'.

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


#: The largest sun zenith [degrees] at which :func:`level_factors` follows the model: Ineichen
#: and Perez fitted it to the sun above about 4 degrees, and nearer the horizon its diffuse
#: light falls to 0 (pvlib issues 435, 1064); a lower sun's factors are its at this zenith.
FACTOR_ZENITH_DEG = 85.0


def level_factors(infos, variant_infos, mix):
    """(sun, sky), each (T,): how a fitted turbidity moves each frame's light, as the direct
    normal and the diffuse horizontal irradiance (:func:`levels`) at it over those of the
    frame's turbid sky (``infos``: :func:`turbid_sky`'s).  The turbidity is the one a fit of
    the sky's shape reads (``fit --sky-shape``): from + ``mix`` (to - from) of each frame's
    shape variant (``variant_infos``: :func:`~skyfit_mi.physics.sky_shape.shape_variants`'
    skies' info), held to :data:`TURBIDITY_RANGE`.  So one number moves the sky's shape, the
    sky's level and the sun's, the sun's the more the lower it stands (the beam's longer path
    through the haze), held at :data:`FACTOR_ZENITH_DEG` for a lower sun."""
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
