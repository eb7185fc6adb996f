"""The Perez all-weather sky, driven by measured irradiance (Perez, Seals and Michalsky 1993).

The sky's relative luminance toward a sky element at zenith angle theta_p and angle zeta
from the sun is (1993, eq. 1)

    l_v = (1 + a exp(b / cos theta_p)) (1 + c exp(d zeta) + e cos^2 zeta),

with five coefficients a..e that depend on the sun's zenith Z and on two indices computed
from measured irradiance (Perez et al. 1990, eqs. 1-2): the sky clearness epsilon, which
picks one of eight bins of a table of 8 x 5 x 4 numbers (1993, Table 1), and the sky
brightness Delta.  The absolute sky follows by scaling l_v so that the sky's horizontal
irradiance equals the measured diffuse horizontal irradiance, and luminance by the Perez
1990 diffuse luminous efficacy (1990, eq. 7 and Table 4).

The paper names the element's zenith angle zeta and its angle to the sun gamma; this module
follows ``docs/CONVENTIONS.md`` instead: ``theta_p`` is the element's zenith angle and
``zeta`` its angle to the sun.  World frame +X east, +Y north, +Z up; azimuths from north
toward east; degrees only in arguments named ``*_deg``.

Where this module, or common implementations, depart from the paper:

* the horizon: ``cos theta_p`` is held at 0.01 below 0.01, as Radiance's ``perezlum.cal``
  does, so that exp(b / cos theta_p) stays finite;
* ``delta_floor`` of :class:`PerezOptions`: Radiance's ``gendaylit`` and ``gendaymtx`` (and
  other implementations) raise Delta to 0.2 for the coefficients when 1.065 < epsilon < 2.8:
  at lower Delta the published coefficients of those bins give b > 0 (a sky growing without
  bound toward the horizon, e.g. DHI 60 and DNI 50 W m^-2 under a high sun) or negative
  luminance near the horizon (a low sun in bin 2).  :func:`perez_sky` does the same by
  default; ``PerezOptions(delta_floor=None)`` gives the published model unchanged.  :func:`coefficients`
  is always the published model.
* Radiance's ``gendaylit`` also clamps epsilon to [1, 12.01), Delta to [0.01, 0.6] and the
  solar altitude to at most 87 degrees, computes the air mass with Kasten (1966) and
  normalises with a 145-point sum over the sky; none of this is done here.

References
----------
R. Perez, R. Seals, J. Michalsky, "All-weather model for sky luminance distribution -
preliminary configuration and validation", Solar Energy 50(3), 235-245, 1993,
doi:10.1016/0038-092X(93)90017-I; erratum, Solar Energy 51(5), 423, 1993.

R. Perez, P. Ineichen, R. Seals, J. Michalsky, R. Stewart, "Modeling daylight availability
and irradiance components from direct and global irradiance", Solar Energy 44(5), 271-289,
1990, doi:10.1016/0038-092X(90)90055-H.

Equation numbers of the 1993 paper are those cited by Radiance's ``gendaymtx.c`` (I. Ashdown).
"""

from dataclasses import dataclass, field, replace

import numpy as np

from ..conventions import direction_from_angles
from ..errors import InputRangeError, SkyfitError, check_choice, check_range
from .colour import cct_to_rgb
from .sky import (CCT_CLEAR, CCT_OVERCAST, GROUND_ALBEDO, IRRADIANCE_NODES, SKY_LEVEL_SD, Sky,
                  hemisphere_integral as sky_hemisphere_integral, perez_pattern)
from .sun import SUN_SOLID_ANGLE, sun_rgb

#: Lower edges of the eight sky-clearness bins, then +inf (Perez et al. 1990, Table 1;
#: the same bins in 1993) [unitless].  Bin i holds edges[i] <= epsilon < edges[i + 1].
CLEARNESS_BIN_EDGES = np.array([1.0, 1.065, 1.23, 1.5, 1.95, 2.8, 4.5, 6.2, np.inf])

#: Perez et al. 1993, Table 1: for each clearness bin (axis 0) and each coefficient a, b, c,
#: d, e (axis 1), the terms x1..x4 of x = x1 + x2 Z + Delta (x3 + x4 Z) (axis 2), Z in
#: radians.  In bin 1, c and d take other forms (see :func:`coefficients`).  Transcribed
#: from, and identical digit for digit in, three implementations: Radiance's gendaylit.c
#: (J.-J. Delaunay 1994) and gendaymtx.c (I. Ashdown, who cites the 1993 erratum), and
#: cPerezSkyModel.cpp.
LUMINANCE_COEFFICIENTS = np.array([
    # epsilon 1.000 - 1.065 (overcast)
    [[1.3525, -0.2576, -0.2690, -1.4366], [-0.7670, 0.0007, 1.2734, -0.1233],
     [2.8000, 0.6004, 1.2375, 1.0000], [1.8734, 0.6297, 0.9738, 0.2809],
     [0.0356, -0.1246, -0.5718, 0.9938]],
    # 1.065 - 1.230
    [[-1.2219, -0.7730, 1.4148, 1.1016], [-0.2054, 0.0367, -3.9128, 0.9156],
     [6.9750, 0.1774, 6.4477, -0.1239], [-1.5798, -0.5081, -1.7812, 0.1080],
     [0.2624, 0.0672, -0.2190, -0.4285]],
    # 1.230 - 1.500
    [[-1.1000, -0.2515, 0.8952, 0.0156], [0.2782, -0.1812, -4.5000, 1.1766],
     [24.7219, -13.0812, -37.7000, 34.8438], [-5.0000, 1.5218, 3.9229, -2.6204],
     [-0.0156, 0.1597, 0.4199, -0.5562]],
    # 1.500 - 1.950
    [[-0.5484, -0.6654, -0.2672, 0.7117], [0.7234, -0.6219, -5.6812, 2.6297],
     [33.3389, -18.3000, -62.2500, 52.0781], [-3.5000, 0.0016, 1.1477, 0.1062],
     [0.4659, -0.3296, -0.0876, -0.0329]],
    # 1.950 - 2.800
    [[-0.6000, -0.3566, -2.5000, 2.3250], [0.2937, 0.0496, -5.6812, 1.8415],
     [21.0000, -4.7656, -21.5906, 7.2492], [-3.5000, -0.1554, 1.4062, 0.3988],
     [0.0032, 0.0766, -0.0656, -0.1294]],
    # 2.800 - 4.500
    [[-1.0156, -0.3670, 1.0078, 1.4051], [0.2875, -0.5328, -3.8500, 3.3750],
     [14.0000, -0.9999, -7.1406, 7.5469], [-3.4000, -0.1078, -1.0750, 1.5702],
     [-0.0672, 0.4016, 0.3017, -0.4844]],
    # 4.500 - 6.200
    [[-1.0000, 0.0211, 0.5025, -0.5119], [-0.3000, 0.1922, 0.7023, -1.6317],
     [19.0000, -5.0000, 1.2438, -1.9094], [-4.0000, 0.0250, 0.3844, 0.2656],
     [1.0468, -0.3788, -2.4517, 1.4656]],
    # 6.200 - (clear)
    [[-1.0500, 0.0289, 0.4260, 0.3590], [-0.3250, 0.1156, 0.7781, 0.0025],
     [31.0625, -14.5000, -46.1148, 55.3750], [-7.2312, 0.4050, 13.3500, 0.6234],
     [1.5000, -0.6426, 1.8564, 0.5636]],
])

#: Perez et al. 1990, Table 4, diffuse luminous efficacy: a_i [lm W^-1], b_i [lm W^-1 cm^-1],
#: c_i, d_i [lm W^-1] per clearness bin, for K = a + b W + c cos Z + d ln Delta (eq. 7).
#: Identical in Radiance's gendaylit.c and gendaymtx.c and in cPerezSkyModel.cpp.
DIFFUSE_EFFICACY_COEFFICIENTS = np.array([
    [97.24, -0.46, 12.00, -8.91],
    [107.22, 1.15, 0.59, -3.95],
    [104.97, 2.96, -5.53, -8.77],
    [102.39, 5.59, -13.95, -13.90],
    [100.71, 5.94, -22.75, -23.74],
    [106.42, 3.83, -36.15, -28.83],
    [141.88, 1.90, -53.24, -14.03],
    [152.23, 0.35, -45.27, -7.98],
])

#: kappa of the clearness, 1.041 for Z in radians (Perez et al. 1990, eq. 1) [rad^-3].
KAPPA = 1.041
#: Solar constant for the extraterrestrial irradiance of Delta [W m^-2]: the WMO (1981)
#: value of the Perez model's time, used by Radiance's gendaylit and gendaymtx.
PEREZ_SOLAR_CONSTANT = 1367.0
#: Radiance's lower limit on Delta for 1.065 < epsilon < 2.8 (gendaylit.c, gendaymtx.c),
#: the default of :func:`perez_sky`.
RADIANCE_DELTA_FLOOR = 0.2
#: Radiance's gendaylit clamps epsilon below this value [unitless]: the top this module gives
#: the open clear bin where it needs one (:data:`CLEARNESS_BIN_CENTRES`).
GENDAYLIT_MAX_CLEARNESS = 12.01
#: The clearness that stands for each bin in a fit of the sky's shape (``fit --sky-shape``,
#: :func:`shape_moves`): the bin's centre, the open clear bin's taken to
#: :data:`GENDAYLIT_MAX_CLEARNESS` (9.1; the clear skies of pvlib's two TMY3 files have
#: epsilon 6.7-8.5 between quartiles, 10.1-10.6 at the 99th percentile) [unitless].  Within a
#: bin the pattern depends on epsilon only through the bin (1993, Table 1): the value names the
#: bin on the clearness scale of a fitted index.
CLEARNESS_BIN_CENTRES = 0.5 * (CLEARNESS_BIN_EDGES[:-1]
                               + np.r_[CLEARNESS_BIN_EDGES[1:-1], GENDAYLIT_MAX_CLEARNESS])
#: The factor by which a fit of the sky's shape (``fit --sky-shape``, :func:`shape_moves`)
#: moves the sky brightness Delta: e^0.35 = 1.42, one standard deviation of the sky's level
#: in a fit (:data:`~skyfit_mi.physics.sky.SKY_LEVEL_SD`), since Delta = E_dh m / E_0 is
#: proportional to the diffuse irradiance whose level that prior doubts.  In log, that is 1-3
#: times Delta's spread within one clearness bin (relative standard deviation 0.11-0.14 in the
#: bins of epsilon >= 2.8 and 0.22-0.31 in those below 1.23, in pvlib's TMY3 files 723170TYA,
#: Greensboro NC, and 703165TY, Sand Point AK, over their hours with the sun above 5 degrees):
#: one step, the shape prior's standard deviation, is a change of sky that the spec's
#: irradiance could plausibly miss.
BRIGHTNESS_STEP = float(np.exp(SKY_LEVEL_SD))
#: Atmospheric precipitable water assumed by Radiance's gendaylit (dew point 11 C) [cm].
PRECIPITABLE_WATER = 2.0

#: Relative air mass models for Delta, by pvlib name.
AIRMASS_MODELS = {
    "kastenyoung1989": "F. Kasten, A. T. Young, Applied Optics 28, 4735-4738, 1989 "
                       "(pvlib's choice for the Perez models)",
    "kasten1966": "F. Kasten, Arch. Meteorol. Geophys. Bioklimatol. B14, 206-233, 1966 "
                  "(Radiance's gendaylit and gendaymtx)",
}

#: Models splitting global horizontal irradiance into direct normal and diffuse, by the
#: name of their pvlib.irradiance function.
DECOMPOSITIONS = {
    "erbs": "D. G. Erbs, S. A. Klein, J. A. Duffie, Solar Energy 28(4), 293-302, 1982",
    "erbs_driesse": "A. Driesse, A. Jensen, R. Perez, Solar Energy 267, 112093, 2024",
    "boland": "J. Boland, B. Ridley, in Modeling Solar Radiation at the Earth's Surface, "
              "Springer, 2008, doi:10.1007/978-3-540-77455-6_8",
    "orgill_hollands": "J. F. Orgill, K. G. T. Hollands, Solar Energy 19(4), 357-359, 1977",
    "louche": "A. Louche, G. Notton, P. Poggi, G. Simonnot, Solar Energy 46, 261-266, 1991",
}


# --------------------------------------------------------------------------
# Input checks
# --------------------------------------------------------------------------

def _sun_zenith(sun_zenith_deg):
    """Sun zenith [rad] from degrees, or InputRangeError unless in [0, 90) everywhere."""
    z = np.asarray(sun_zenith_deg, dtype=float)
    ok = (z >= 0.0) & (z < 90.0)
    if not np.all(ok):
        bad = z[~ok].ravel()[0]
        raise InputRangeError(f"sun zenith = {bad:g} degrees: the Perez sky needs the sun above "
                              "the horizon (zenith in [0, 90) degrees); skip night-time steps.")
    return np.radians(z)


def _irradiance(name, value, hi, positive=False):
    """``value`` as an array [W m^-2], or InputRangeError if negative, NaN, above ``hi``,
    or zero where ``positive``."""
    check_range(name, value, 0.0, hi, "W m^-2")
    v = np.asarray(value, dtype=float)
    if positive and np.any(v == 0.0):
        raise InputRangeError(f"{name} = 0 W m^-2: the Perez sky needs some diffuse light "
                              "(0 means night or a missing record); skip that time step.")
    return v


def _clearness_value(epsilon):
    eps = np.asarray(epsilon, dtype=float)
    if not np.all(np.isfinite(eps) & (eps >= 1.0)):
        bad = eps[~(np.isfinite(eps) & (eps >= 1.0))].ravel()[0]
        raise InputRangeError(f"sky clearness epsilon = {bad:g} is outside [1, inf); compute it "
                              "with clearness() from a positive diffuse irradiance.")
    return eps


def _brightness_value(delta, positive=False):
    d = np.asarray(delta, dtype=float)
    ok = np.isfinite(d) & ((d > 0.0) if positive else (d >= 0.0))
    if not np.all(ok):
        bad = d[~ok].ravel()[0]
        rng = "(0, inf)" if positive else "[0, inf)"
        raise InputRangeError(f"sky brightness Delta = {bad:g} is outside {rng}; compute it with "
                              "brightness() from a positive diffuse irradiance.")
    return d


# --------------------------------------------------------------------------
# Sky indices (Perez et al. 1990)
# --------------------------------------------------------------------------

def clearness(dhi, dni, sun_zenith_deg):
    """Perez sky clearness epsilon, Perez et al. 1990 eq. 1.

    .. math:: \\varepsilon = \\frac{(E_{dh} + E_{dn}) / E_{dh} + \\kappa Z^3}{1 + \\kappa Z^3},
              \\quad \\kappa = 1.041\\ \\mathrm{rad}^{-3}

    Parameters
    ----------
    dhi : array_like
        Diffuse horizontal irradiance E_dh [W m^-2], in (0, 2000].
    dni : array_like
        Direct normal irradiance E_dn [W m^-2], in [0, 1500].
    sun_zenith_deg : array_like
        Solar zenith Z [degrees], in [0, 90).

    Returns
    -------
    ndarray
        epsilon [unitless], >= 1 (1: no direct sun; above 6.2: clear).

    Raises
    ------
    InputRangeError
        On a negative, zero (``dhi``) or NaN irradiance, or a sun on or below the horizon.
    """
    z = _sun_zenith(sun_zenith_deg)
    e_dh = _irradiance("diffuse horizontal irradiance", dhi, 2000.0, positive=True)
    e_dn = _irradiance("direct normal irradiance", dni, 1500.0)
    kz3 = KAPPA * z**3
    return (((e_dh + e_dn) / e_dh + kz3) / (1.0 + kz3))[()]


def brightness(dhi, sun_zenith_deg, day_of_year=None, *, extraterrestrial=None,
               airmass_model="kastenyoung1989"):
    """Perez sky brightness Delta, Perez et al. 1990 eq. 2.

    .. math:: \\Delta = E_{dh}\\, m / E_0

    with m the relative optical air mass (pvlib's ``get_relative_airmass``, model
    ``airmass_model``; Kasten and Young 1989 by default, which pvlib uses for its Perez
    models) and E_0 the extraterrestrial normal irradiance: ``extraterrestrial`` if given,
    else pvlib's ``get_extra_radiation`` for ``day_of_year`` (Spencer 1971) with the solar
    constant :data:`PEREZ_SOLAR_CONSTANT`, as Radiance's gendaylit computes it.

    Parameters
    ----------
    dhi : array_like
        Diffuse horizontal irradiance E_dh [W m^-2], in [0, 2000].
    sun_zenith_deg : array_like
        Solar zenith [degrees], in [0, 90).
    day_of_year : array_like, optional
        Day of the year, 1-366.  Give this or ``extraterrestrial``.
    extraterrestrial : array_like, optional
        E_0 [W m^-2], in (0, 1500].
    airmass_model : str
        A key of :data:`AIRMASS_MODELS`.

    Returns
    -------
    ndarray
        Delta [unitless], typically 0.01-0.6.

    Raises
    ------
    SkyfitError
        On bad irradiance or sun zenith, an unknown air mass model, or unless exactly one of
        ``day_of_year`` and ``extraterrestrial`` is given.
    """
    from pvlib.atmosphere import get_relative_airmass
    from pvlib.irradiance import get_extra_radiation

    z_deg = np.degrees(_sun_zenith(sun_zenith_deg))
    e_dh = _irradiance("diffuse horizontal irradiance", dhi, 2000.0)
    check_choice("air mass model", airmass_model, tuple(AIRMASS_MODELS))
    if (day_of_year is None) == (extraterrestrial is None):
        raise SkyfitError("give exactly one of day_of_year (1-366) and extraterrestrial "
                          "(the extraterrestrial normal irradiance, W m^-2).")
    if extraterrestrial is None:
        check_range("day of year", day_of_year, 1, 366)
        e_0 = get_extra_radiation(np.asarray(day_of_year, dtype=float),
                                  solar_constant=PEREZ_SOLAR_CONSTANT, method="spencer")
    else:
        e_0 = _irradiance("extraterrestrial irradiance", extraterrestrial, 1500.0, positive=True)
    m = get_relative_airmass(z_deg, model=airmass_model)
    return np.asarray(e_dh * m / e_0, dtype=float)[()]


def clearness_bin(epsilon):
    """Index 0-7 of the Perez clearness bin holding ``epsilon`` (1990 and 1993, Table 1).

    Bins are closed below and open above: 1.065 is in bin 1 (0-based), as in Radiance and
    pvlib.  ``epsilon`` must be finite and >= 1 [unitless].
    """
    eps = _clearness_value(epsilon)
    return np.minimum(np.searchsorted(CLEARNESS_BIN_EDGES, eps, side="right") - 1, 7)[()]


# --------------------------------------------------------------------------
# The luminance distribution (Perez et al. 1993)
# --------------------------------------------------------------------------

def coefficients(epsilon, delta, sun_zenith_deg):
    """The coefficients a, b, c, d, e of the Perez sky, 1993 eqs. 6-8 and Table 1.

    Each is x = x1 + x2 Z + Delta (x3 + x4 Z) with the x_i of ``epsilon``'s clearness bin
    (eq. 6), except in the overcast bin (epsilon < 1.065), where (eqs. 7-8)

    .. math:: c = \\exp\\left([\\Delta (c_1 + c_2 Z)]^{c_3}\\right) - c_4, \\qquad
              d = -\\exp\\left(\\Delta (d_1 + d_2 Z)\\right) + d_3 + \\Delta d_4.

    This is the model as published: no limits on Delta (see ``delta_floor`` of
    :class:`PerezOptions` for Radiance's).

    Parameters
    ----------
    epsilon : array_like
        Sky clearness [unitless], >= 1.
    delta : array_like
        Sky brightness [unitless], >= 0.
    sun_zenith_deg : array_like
        Solar zenith Z [degrees], in [0, 90).

    Returns
    -------
    ndarray, shape (..., 5)
        a [unitless], b [unitless], c [unitless], d [rad^-1], e [unitless] along the last axis.
    """
    eps, dlt, z = np.broadcast_arrays(_clearness_value(epsilon), _brightness_value(delta),
                                      _sun_zenith(sun_zenith_deg))
    k = clearness_bin(eps)
    x = LUMINANCE_COEFFICIENTS[k]                                           # (..., 5, 4)
    zz, dd = z[..., None], dlt[..., None]
    out = x[..., 0] + x[..., 1] * zz + dd * (x[..., 2] + x[..., 3] * zz)    # eq. 6
    (c1, c2, c3, c4), (d1, d2, d3, d4) = LUMINANCE_COEFFICIENTS[0, 2:4]
    overcast = k == 0
    out[..., 2] = np.where(overcast, np.exp((dlt * (c1 + c2 * z)) ** c3) - c4, out[..., 2])  # eq. 7
    out[..., 3] = np.where(overcast, -np.exp(dlt * (d1 + d2 * z)) + d3 + dlt * d4,           # eq. 8
                           out[..., 3])
    return out


def floored_delta(epsilon, delta, delta_floor=RADIANCE_DELTA_FLOOR):
    """The Delta [unitless] that :func:`perez_sky` gives :func:`coefficients` for a sky of
    clearness ``epsilon`` and brightness ``delta``: raised to ``delta_floor`` where
    1.065 < epsilon < 2.8, as Radiance's gendaylit and gendaymtx do; ``delta`` itself
    elsewhere or when ``delta_floor`` is None (numbers, not arrays)."""
    if delta_floor is None or not 1.065 < epsilon < 2.8:
        return float(delta)
    return max(float(delta), float(delta_floor))


def diffuse_efficacy(epsilon, delta, sun_zenith_deg, precipitable_water=PRECIPITABLE_WATER):
    """Luminous efficacy of diffuse skylight, Perez et al. 1990 eq. 7 and Table 4.

    .. math:: K = a_i + b_i W + c_i \\cos Z + d_i \\ln\\Delta

    with the coefficients of ``epsilon``'s clearness bin i.  W can be had from the surface
    dew point T_d [C] as exp(0.07 T_d - 0.075) (1990, eq. 3).

    Parameters
    ----------
    epsilon : array_like
        Sky clearness [unitless], >= 1.
    delta : array_like
        Sky brightness [unitless], > 0.
    sun_zenith_deg : array_like
        Solar zenith Z [degrees], in [0, 90).
    precipitable_water : array_like
        Atmospheric precipitable water W [cm], in [0, 10]; 2 cm (Radiance's default).

    Returns
    -------
    ndarray
        K [lm W^-1]: diffuse horizontal illuminance per unit diffuse horizontal irradiance.
    """
    check_range("precipitable water", precipitable_water, 0.0, 10.0, "cm")
    k = clearness_bin(epsilon)
    a, b, c, d = np.moveaxis(DIFFUSE_EFFICACY_COEFFICIENTS[k], -1, 0)
    z = _sun_zenith(sun_zenith_deg)
    return (a + b * np.asarray(precipitable_water, dtype=float) + c * np.cos(z)
            + d * np.log(_brightness_value(delta, positive=True)))[()]


def hemisphere_integral(f, n=IRRADIANCE_NODES):
    """Integral of f(d) cos theta_p over the upper hemisphere, dOmega in sr: the rule of
    :func:`skyfit_mi.physics.sky.hemisphere_integral` (thesis eq. 4.19), as a number.  With
    the default 128 nodes, Perez skies of every clearness bin with the sun 0-87 degrees from
    the zenith agree with a 512-node rule to 3e-6 relative; where :class:`PerezSky` clamps
    negative model values at zero (``delta_floor=None`` and a low Delta) the kink limits
    the agreement to about 1.5e-4.
    """
    return float(sky_hemisphere_integral(f, n))


# --------------------------------------------------------------------------
# An absolute sky
# --------------------------------------------------------------------------

@dataclass(frozen=True)
class PerezSky:
    """A Perez sky scaled to measured irradiance; build it with :func:`perez_sky`.

    Radiance is broadband (solar), as the measured irradiance; a colour, e.g. from
    :func:`skyfit_mi.physics.colour.cct_to_rgb`, is the caller's choice.

    Attributes
    ----------
    sun_direction : ndarray (3,)
        Unit vector toward the sun, world frame (+X east, +Y north, +Z up).
    coefficients : ndarray (5,)
        a, b, c, d, e of :func:`~skyfit_mi.physics.sky.perez_relative_luminance`.
    scale : float
        Radiance per unit relative luminance [W m^-2 sr^-1]: the sky's horizontal
        irradiance equals the diffuse horizontal irradiance.
    efficacy : float
        Luminous efficacy of the skylight [lm W^-1].
    info : dict
        Inputs and indices: sun angles [degrees], dhi, dni [W m^-2], epsilon, delta (and
        the delta used for the coefficients), the clearness bin, the models used.
    """

    sun_direction: np.ndarray
    coefficients: np.ndarray
    scale: float
    efficacy: float
    info: dict = field(default_factory=dict)

    def relative_luminance(self, directions):
        """l_v toward world ``directions`` (..., 3), clamped at 0, and 0 at and below the
        horizon (the Perez model has no ground) [unitless]."""
        d = np.asarray(directions, dtype=float)
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        return np.where(d[..., 2] > 0.0, perez_pattern(d, self.sun_direction, self.coefficients),
                        0.0)

    def radiance(self, directions):
        """Sky radiance toward world ``directions`` (..., 3) [W m^-2 sr^-1], broadband."""
        return self.scale * self.relative_luminance(directions)

    def luminance(self, directions):
        """Sky luminance toward world ``directions`` (..., 3) [cd m^-2]."""
        return self.efficacy * self.radiance(directions)

    def horizontal_irradiance(self, n=IRRADIANCE_NODES):
        """The sky's horizontal irradiance by :func:`hemisphere_integral` [W m^-2]."""
        return hemisphere_integral(self.radiance, n)


    def to_sky(self, cct=None, ground_albedo=GROUND_ALBEDO, sun=True,
               sun_solid_angle=SUN_SOLID_ANGLE):
        """This sky with its sun as a :class:`~skyfit_mi.physics.sky.Sky` (the ``perez``
        pattern of the family the ``cie_sky`` emitter renders), linear sRGB.

        The sky gets the colour of ``cct`` [K] (default :func:`default_cct`), whose luminance
        is 1, so the sky's luminance-weighted horizontal irradiance stays the measured DHI; the
        sun disc carries the measured DNI [W m^-2] over ``sun_solid_angle`` [sr] in the colour
        of :func:`~skyfit_mi.physics.sun.sun_rgb`; the ground is a Lambertian plane of
        reflectance ``ground_albedo`` lit by sky and sun (as the CIE skies' ground).
        """
        check_range("ground albedo", ground_albedo, 0.0, 1.0)
        eps = self.info.get("epsilon", 1.0)
        colour = cct_to_rgb(default_cct(eps) if cct is None else cct)
        z = float(np.degrees(np.arccos(np.clip(self.sun_direction[2], -1.0, 1.0))))
        dni = float(self.info.get("dni_w_m2", 0.0)) if sun else 0.0
        sky = Sky(self.sun_direction, perez=self.scale * colour,
                  perez_coefficients=self.coefficients,
                  sun_radiance=dni / sun_solid_angle * sun_rgb(z),
                  sun_solid_angle=sun_solid_angle,
                  info={**self.info, "kind": "perez", "ground_albedo": float(ground_albedo),
                        "efficacy_lm_W": self.efficacy,
                        "sun_measured": bool(sun) and "decomposition" in self.info
                        and self.info["decomposition"] is None})
        return replace(sky, ground=ground_albedo * sky.horizontal_irradiance() / np.pi)


def default_cct(epsilon):
    """The sky colour temperature [K] skyfit gives a Perez sky of clearness ``epsilon``: the
    thesis's overcast 6500 K at epsilon = 1 to its clear 15000 K at epsilon >= 6.2 (the last
    bin's edge), linear in reciprocal temperature (mired) between.  A choice, not a published
    model: the thesis gives 4500-7000 K overcast and 1e4-1e5 K clear (4.2.3); give ``cct`` to
    override."""
    w = float(np.clip((float(epsilon) - 1.0) / (CLEARNESS_BIN_EDGES[-2] - 1.0), 0.0, 1.0))
    return 1.0 / ((1.0 - w) / CCT_OVERCAST + w / CCT_CLEAR)


@dataclass(frozen=True)
class PerezOptions:
    """The model choices of a Perez sky (:func:`perez_sky`), apart from the irradiance it is
    scaled to.

    Attributes
    ----------
    decomposition : str
        A key of :data:`DECOMPOSITIONS` (the pvlib.irradiance function of that name), splitting
        a global horizontal irradiance into diffuse and direct normal (default 'erbs').
    airmass_model : str
        A key of :data:`AIRMASS_MODELS`, for Delta (1990, eq. 2; default 'kastenyoung1989').
    delta_floor : float or None
        Delta is raised to at least this value [unitless], in [0, 1], for the coefficients
        when 1.065 < epsilon < 2.8, as Radiance's gendaylit and gendaymtx do with the default
        :data:`RADIANCE_DELTA_FLOOR` (0.2); None uses the published model unchanged, which
        refuses (b > 0) some dark skies with a little sun.  The efficacy always uses the
        measured Delta.
    precipitable_water : float
        W [cm], in [0, 10], for the luminous efficacy (1990, eq. 7; default
        :data:`PRECIPITABLE_WATER`, 2 cm).
    nodes : int
        Quadrature nodes in cos theta_p of the normalisation (1993, eq. 3; see
        :func:`hemisphere_integral`; default :data:`~skyfit_mi.physics.sky.IRRADIANCE_NODES`).

    The values are checked where they are used (:func:`perez_sky`).
    """

    decomposition: str = "erbs"
    airmass_model: str = "kastenyoung1989"
    delta_floor: float = RADIANCE_DELTA_FLOOR
    precipitable_water: float = PRECIPITABLE_WATER
    nodes: int = IRRADIANCE_NODES


def _check_scalars(**values):
    for name, value in values.items():
        if value is not None and np.ndim(value) != 0:
            raise SkyfitError(f"perez_sky builds one sky, so {name} must be a number, not an "
                              "array; call clearness(), brightness() and coefficients() for many.")


def perez_sky(sun_zenith_deg, sun_azimuth_deg, day_of_year, *, dhi=None, dni=None, ghi=None,
              options=PerezOptions()):
    """A Perez all-weather sky (1993) scaled to measured irradiance.

    epsilon and Delta come from :func:`clearness` and :func:`brightness`, the pattern from
    :func:`coefficients` and :func:`~skyfit_mi.physics.sky.perez_relative_luminance` (negative values clamped at 0, as
    Radiance's gendaymtx does), and its level from the diffuse horizontal irradiance:
    scale = E_dh / integral of l_v cos theta_p dOmega (1993, eq. 3), by
    :func:`hemisphere_integral`.  Luminance uses :func:`diffuse_efficacy`.

    Parameters
    ----------
    sun_zenith_deg : float
        Solar zenith [degrees], in [0, 90).
    sun_azimuth_deg : float
        Solar compass azimuth, from north toward east [degrees].
    day_of_year : int
        1-366, for the extraterrestrial irradiance (and the decomposition).
    dhi, dni : float, optional
        Measured diffuse horizontal and direct normal irradiance [W m^-2]; dhi > 0.
    ghi : float, optional
        Global horizontal irradiance [W m^-2], instead of ``dhi`` and ``dni``: split into
        them by ``options.decomposition``.
    options : PerezOptions
        The model choices: decomposition, air mass model, Delta floor, precipitable water
        [cm] and quadrature nodes (default: Radiance's floor and water, Erbs, Kasten and
        Young 1989, 128 nodes).

    Returns
    -------
    PerezSky

    Raises
    ------
    SkyfitError
        On bad or missing irradiance (negative, NaN, dhi = 0), a sun on or below the horizon,
        an unknown decomposition or air mass model, or coefficients with b > 0 (a sky growing
        without bound toward the horizon, outside the model's range; gendaylit refuses these
        too: with the default ``options.delta_floor`` they need epsilon >= 2.8 and a low
        Delta, e.g. epsilon 2.8-4.5 with Delta < 0.075 and the sun near the zenith).
    """
    _check_scalars(sun_zenith_deg=sun_zenith_deg, sun_azimuth_deg=sun_azimuth_deg,
                   day_of_year=day_of_year, dhi=dhi, dni=dni, ghi=ghi)
    _sun_zenith(sun_zenith_deg)
    z = float(sun_zenith_deg)
    check_range("sun azimuth", sun_azimuth_deg, -360.0, 360.0, "degrees")
    check_range("day of year", day_of_year, 1, 366)
    if ghi is not None:
        if dhi is not None or dni is not None:
            raise SkyfitError("give either ghi alone or both dhi and dni, not both kinds.")
        check_choice("decomposition", options.decomposition, tuple(DECOMPOSITIONS))
        import pvlib.irradiance

        _irradiance("global horizontal irradiance", ghi, 2000.0, positive=True)
        parts = getattr(pvlib.irradiance, options.decomposition)(float(ghi), z, day_of_year)
        dhi, dni = float(parts["dhi"]), float(parts["dni"])
    elif dhi is None or dni is None:
        raise SkyfitError("give the measured dhi and dni (W m^-2), or ghi alone to split it "
                          f"with a decomposition model ({', '.join(DECOMPOSITIONS)}).")

    eps = float(clearness(dhi, dni, z))
    delta = float(brightness(dhi, z, day_of_year, airmass_model=options.airmass_model))
    if options.delta_floor is not None:
        check_range("delta_floor", options.delta_floor, 0.0, 1.0)
    delta_c = floored_delta(eps, delta, options.delta_floor)
    coeffs = coefficients(eps, delta_c, z)
    if coeffs[1] > 0:
        raise SkyfitError(f"the Perez coefficient b = {coeffs[1]:.4g} > 0 for epsilon = {eps:.4g}, "
                          f"Delta = {delta_c:.4g}, sun zenith {z:.4g} degrees: the sky would grow "
                          "without bound toward the horizon. These irradiances are outside the "
                          "model's range; check dhi, dni and the sun position (or keep "
                          "delta_floor at its default).")
    sun = direction_from_angles(np.radians(z), np.radians(sun_azimuth_deg))
    unit = PerezSky(sun, coeffs, 1.0, 1.0)
    total = hemisphere_integral(unit.relative_luminance, options.nodes)    # 1993 eq. 3
    if not total > 0:
        raise SkyfitError(f"the Perez sky for epsilon = {eps:.4g}, Delta = {delta_c:.4g} is "
                          "black above the horizon; check dhi, dni and the sun position.")
    info = {"model": "perez1993", "sun_zenith_deg": z, "sun_azimuth_deg": float(sun_azimuth_deg),
            "day_of_year": int(day_of_year), "dhi_w_m2": float(dhi), "dni_w_m2": float(dni),
            "ghi_w_m2": None if ghi is None else float(ghi),
            "decomposition": None if ghi is None else options.decomposition,
            "epsilon": eps, "delta": delta, "delta_coefficients": delta_c,
            "clearness_bin": int(clearness_bin(eps)), "airmass_model": options.airmass_model,
            "precipitable_water_cm": float(options.precipitable_water)}
    return PerezSky(sun, coeffs, float(dhi) / total,
                    float(diffuse_efficacy(eps, delta, z, options.precipitable_water)), info)


def shape_moves(info):
    """The moves of a Perez sky's shape that a fit mixes with it (``fit --sky-shape``,
    :func:`~skyfit_mi.physics.sky_shape.shape_variants`), for the sky of :func:`perez_sky`'s
    ``info`` (epsilon, delta, delta_coefficients, sun_zenith_deg):

    * ``clearness``: the pattern of the next clearness bin toward the clearer (+1) or the more
      overcast (-1), at the spec's Delta (raised by :func:`floored_delta` where that bin
      takes it), its epsilon the bin's :data:`CLEARNESS_BIN_CENTRES` value;
    * ``brightness``: the spec's clearness at the coefficients' Delta times (+1) or over (-1)
      :data:`BRIGHTNESS_STEP`.

    A move is None beyond the first or last bin, below the Delta floor of the spec's bin
    (which the spec's coefficients already use), or where its coefficients leave the model
    (b > 0, or a black sky: :func:`perez_sky` refuses these too).

    Returns
    -------
    list of dict
        One per index: ``of`` ('clearness', 'brightness'), ``index`` ('epsilon', 'Delta'),
        ``from`` (the spec's epsilon, or the Delta of its coefficients) and ``moves``
        {+1, -1: None or ``to`` (the index), ``epsilon``, ``delta_coefficients``,
        ``clearness_bin`` and ``coefficients`` (a..e)}.  Empty for a sky without epsilon
        (the sun below the horizon).
    """
    if "epsilon" not in info:
        return []
    eps, delta, z = float(info["epsilon"]), float(info["delta"]), float(info["sun_zenith_deg"])
    delta_c = float(info.get("delta_coefficients", delta))
    k = int(clearness_bin(eps))
    sun = direction_from_angles(np.radians(z), 0.0)

    def move(to, epsilon, delta_to, k_to):
        c = coefficients(epsilon, delta_to, z)
        if not (np.all(np.isfinite(c)) and c[1] <= 0 and hemisphere_integral(
                PerezSky(sun, c, 1.0, 1.0).relative_luminance) > 0):
            return None
        return {"to": float(to), "epsilon": float(epsilon), "delta_coefficients": delta_to,
                "clearness_bin": k_to, "coefficients": c.tolist()}

    clearer = {}
    for sign in (1, -1):
        k_to = k + sign
        clearer[sign] = None if not 0 <= k_to < len(CLEARNESS_BIN_CENTRES) else move(
            CLEARNESS_BIN_CENTRES[k_to], CLEARNESS_BIN_CENTRES[k_to],
            floored_delta(CLEARNESS_BIN_CENTRES[k_to], delta), k_to)
    brighter = {}
    for sign in (1, -1):
        to = delta_c * BRIGHTNESS_STEP ** sign
        brighter[sign] = None if floored_delta(eps, to) != to else move(to, eps, to, k)
    return [{"of": "clearness", "index": "epsilon", "from": eps, "moves": clearer},
            {"of": "brightness", "index": "Delta", "from": delta_c, "moves": brighter}]
