"""The Perez all-weather sky, driven by measured irradiance (Perez, Seals and Michalsky 1993).

Relative luminance toward an element at zenith angle theta_p and angle zeta from the sun
(1993, eq. 1):

    l_v = (1 + a exp(b / cos theta_p)) (1 + c exp(d zeta) + e cos^2 zeta),

with a..e depending on the sun's zenith Z, the sky clearness epsilon (picking one of eight bins
of 1993 Table 1) and the sky brightness Delta (Perez et al. 1990, eqs. 1-2).  The absolute sky
scales l_v so its horizontal irradiance equals the measured diffuse horizontal irradiance;
luminance uses the 1990 diffuse luminous efficacy (eq. 7, Table 4).  Names follow
``docs/CONVENTIONS.md`` (the paper's zeta and gamma are ``theta_p`` and ``zeta`` here).

Departures from the paper, as Radiance: ``cos theta_p`` is held at >= 0.01 (``perezlum.cal``)
to keep exp(b / cos theta_p) finite; ``PerezOptions.delta_floor`` raises Delta to 0.2 for
1.065 < epsilon < 2.8 (``gendaylit``), where lower Delta gives b > 0 (unbounded toward the
horizon) or negative luminance.  Radiance's other clamps, air mass and normalisation are not
copied.

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

from dataclasses import dataclass, field

import numpy as np

from ..conventions import direction_from_angles, unit_directions
from ..errors import InputRangeError, SkyfitError, check_choice, check_range
from .colour import cct_to_rgb
from .sky import (CCT_CLEAR, CCT_OVERCAST, GROUND_ALBEDO, IRRADIANCE_NODES, SKY_LEVEL_SD, Sky,
                  hemisphere_integral, perez_pattern)
from .sun import SUN_SOLID_ANGLE, sun_rgb

#: Lower edges of the eight clearness bins, then +inf (1990 Table 1; 1993 the same).  Bin i
#: holds edges[i] <= epsilon < edges[i + 1].
CLEARNESS_BIN_EDGES = np.array([1.0, 1.065, 1.23, 1.5, 1.95, 2.8, 4.5, 6.2, np.inf])

#: 1993 Table 1 (as gendaylit.c, gendaymtx.c, with the erratum): per bin (axis 0) and
#: coefficient a..e (axis 1), x1..x4 of x = x1 + x2 Z + Delta (x3 + x4 Z), Z in rad (axis 2).
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

#: 1990 Table 4, diffuse luminous efficacy per clearness bin: a_i [lm W^-1], b_i
#: [lm W^-1 cm^-1], c_i, d_i [lm W^-1] of K = a + b W + c cos Z + d ln Delta (eq. 7).
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
#: Solar constant for Delta's extraterrestrial irradiance [W m^-2]: WMO (1981), as gendaylit.
PEREZ_SOLAR_CONSTANT = 1367.0
#: Radiance's lower limit on Delta for 1.065 < epsilon < 2.8, the default of :func:`perez_sky`.
RADIANCE_DELTA_FLOOR = 0.2
#: gendaylit's upper clamp on epsilon; closes the open clear bin in :data:`CLEARNESS_BIN_CENTRES`.
GENDAYLIT_MAX_CLEARNESS = 12.01
#: The epsilon standing for each bin in a sky-shape fit (:func:`shape_moves`): its centre (the
#: open bin closed at :data:`GENDAYLIT_MAX_CLEARNESS`); the pattern depends only on the bin.
CLEARNESS_BIN_CENTRES = 0.5 * (CLEARNESS_BIN_EDGES[:-1]
                               + np.r_[CLEARNESS_BIN_EDGES[1:-1], GENDAYLIT_MAX_CLEARNESS])
#: Factor by which a sky-shape fit moves Delta: one sd of the sky's level prior, since Delta is
#: proportional to the diffuse irradiance (1-3 times Delta's spread in a bin in TMY3 data).
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


# ---- Input checks ----

def _checked(value, ok, message):
    """``value`` as a float array, or InputRangeError ``message`` with its first value where
    ``ok(value)`` fails in place of ``{}``."""
    v = np.asarray(value, dtype=float)
    good = ok(v)
    if not np.all(good):
        raise InputRangeError(message.format(f"{v[~good].ravel()[0]:g}"))
    return v


def _sun_zenith(sun_zenith_deg):
    """Sun zenith [rad] from degrees, or InputRangeError unless in [0, 90) everywhere."""
    return np.radians(_checked(sun_zenith_deg, lambda z: (z >= 0.0) & (z < 90.0),
                               "sun zenith = {} degrees: the Perez sky needs the sun above the "
                               "horizon (zenith in [0, 90) degrees); skip night-time steps."))


def _irradiance(name, value, hi, positive=False):
    """``value`` as an array [W m^-2]; InputRangeError if negative, NaN, above ``hi``, or zero
    where ``positive``."""
    check_range(name, value, 0.0, hi, "W m^-2")
    v = np.asarray(value, dtype=float)
    if positive and np.any(v == 0.0):
        raise InputRangeError(f"{name} = 0 W m^-2: the Perez sky needs some diffuse light "
                              "(0 means night or a missing record); skip that time step.")
    return v


def _clearness_value(epsilon):
    return _checked(epsilon, lambda e: np.isfinite(e) & (e >= 1.0),
                    "sky clearness epsilon = {} is outside [1, inf); compute it with clearness() "
                    "from a positive diffuse irradiance.")


def _brightness_value(delta, positive=False):
    rng = "(0, inf)" if positive else "[0, inf)"
    return _checked(delta, lambda d: np.isfinite(d) & ((d > 0.0) if positive else (d >= 0.0)),
                    f"sky brightness Delta = {{}} is outside {rng}; compute it with brightness() "
                    "from a positive diffuse irradiance.")


# ---- Sky indices (Perez et al. 1990) ----

def clearness(dhi, dni, sun_zenith_deg):
    """Perez sky clearness epsilon [unitless], >= 1 (1: no direct sun; > 6.2: clear), 1990 eq. 1.

    .. math:: \\varepsilon = \\frac{(E_{dh} + E_{dn}) / E_{dh} + \\kappa Z^3}{1 + \\kappa Z^3},
              \\quad \\kappa = 1.041\\ \\mathrm{rad}^{-3}

    Parameters
    ----------
    dhi, dni : array_like
        Diffuse horizontal E_dh, in (0, 2000], and direct normal E_dn, in [0, 1500],
        irradiance [W m^-2].
    sun_zenith_deg : array_like
        Solar zenith Z [degrees], in [0, 90).

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
    """Perez sky brightness Delta [unitless], typically 0.01-0.6, Perez et al. 1990 eq. 2.

    .. math:: \\Delta = E_{dh}\\, m / E_0

    with m the relative air mass (pvlib's ``get_relative_airmass``; Kasten and Young 1989 by
    default, as pvlib's Perez models) and E_0 the extraterrestrial normal irradiance, given or
    from ``day_of_year`` (pvlib, Spencer 1971, :data:`PEREZ_SOLAR_CONSTANT`, as gendaylit).

    Parameters
    ----------
    dhi : array_like
        Diffuse horizontal irradiance E_dh [W m^-2], in [0, 2000].
    sun_zenith_deg : array_like
        Solar zenith [degrees], in [0, 90).
    day_of_year, extraterrestrial : array_like, optional
        Exactly one (else SkyfitError): day 1-366, or E_0 [W m^-2] in (0, 1500].
    airmass_model : str
        A key of :data:`AIRMASS_MODELS`.
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
    """Index 0-7 of the clearness bin holding ``epsilon`` (finite, >= 1; 1990/1993 Table 1).
    Bins are closed below, open above (1.065 is in bin 1), as in Radiance and pvlib."""
    eps = _clearness_value(epsilon)
    return np.minimum(np.searchsorted(CLEARNESS_BIN_EDGES, eps, side="right") - 1, 7)[()]


# ---- The luminance distribution (Perez et al. 1993) ----

def coefficients(epsilon, delta, sun_zenith_deg):
    """The coefficients a, b, c, d, e of the Perez sky, 1993 eqs. 6-8 and Table 1.

    Each is x = x1 + x2 Z + Delta (x3 + x4 Z) with the x_i of ``epsilon``'s clearness bin
    (eq. 6), except in the overcast bin (epsilon < 1.065), where (eqs. 7-8)

    .. math:: c = \\exp\\left([\\Delta (c_1 + c_2 Z)]^{c_3}\\right) - c_4, \\qquad
              d = -\\exp\\left(\\Delta (d_1 + d_2 Z)\\right) + d_3 + \\Delta d_4.

    As published: no limits on Delta (see :class:`PerezOptions` ``delta_floor``).

    Parameters
    ----------
    epsilon, delta : array_like
        Sky clearness (>= 1) and brightness (>= 0) [unitless].
    sun_zenith_deg : array_like
        Solar zenith Z [degrees], in [0, 90).

    Returns
    -------
    ndarray, shape (..., 5)
        a, b, c [unitless], d [rad^-1], e [unitless] along the last axis.
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
    """The Delta [unitless] :func:`perez_sky` gives :func:`coefficients`: raised to
    ``delta_floor`` where 1.065 < epsilon < 2.8, as gendaylit/gendaymtx; else, or when
    ``delta_floor`` is None, ``delta`` itself (scalars)."""
    if delta_floor is None or not 1.065 < epsilon < 2.8:
        return float(delta)
    return max(float(delta), float(delta_floor))


def diffuse_efficacy(epsilon, delta, sun_zenith_deg, precipitable_water=PRECIPITABLE_WATER):
    """Luminous efficacy K [lm W^-1] of diffuse skylight (diffuse horizontal illuminance per
    unit irradiance), Perez et al. 1990 eq. 7 and Table 4.

    .. math:: K = a_i + b_i W + c_i \\cos Z + d_i \\ln\\Delta

    with the coefficients of ``epsilon``'s bin i.  W from the dew point T_d [C]:
    exp(0.07 T_d - 0.075) (1990, eq. 3).

    Parameters
    ----------
    epsilon, delta : array_like
        Sky clearness (>= 1) and brightness (> 0) [unitless].
    sun_zenith_deg : array_like
        Solar zenith Z [degrees], in [0, 90).
    precipitable_water : array_like
        Precipitable water W [cm], in [0, 10]; 2 cm (Radiance's default).
    """
    check_range("precipitable water", precipitable_water, 0.0, 10.0, "cm")
    k = clearness_bin(epsilon)
    a, b, c, d = np.moveaxis(DIFFUSE_EFFICACY_COEFFICIENTS[k], -1, 0)
    z = _sun_zenith(sun_zenith_deg)
    return (a + b * np.asarray(precipitable_water, dtype=float) + c * np.cos(z)
            + d * np.log(_brightness_value(delta, positive=True)))[()]


# ---- An absolute sky ----

@dataclass(frozen=True)
class PerezSky:
    """A Perez sky scaled to measured irradiance; build it with :func:`perez_sky`.  Radiance is
    broadband (solar), as the measured irradiance; colour is the caller's choice.

    Attributes
    ----------
    sun_direction : ndarray (3,)
        Unit vector toward the sun, world frame.
    coefficients : ndarray (5,)
        a..e of :func:`~skyfit_mi.physics.sky.perez_relative_luminance`.
    scale : float
        Radiance per unit relative luminance [W m^-2 sr^-1], giving the measured DHI.
    efficacy : float
        Luminous efficacy of the skylight [lm W^-1].
    info : dict
        Inputs, indices (epsilon, delta, delta of the coefficients, bin) and models used.
    """

    sun_direction: np.ndarray
    coefficients: np.ndarray
    scale: float
    efficacy: float
    info: dict = field(default_factory=dict)

    def relative_luminance(self, directions):
        """l_v toward world ``directions`` (..., 3) [unitless], clamped at 0, and 0 at and
        below the horizon (no ground)."""
        d = unit_directions(directions)
        return np.where(d[..., 2] > 0.0, perez_pattern(d, self.sun_direction, self.coefficients),
                        0.0)

    def radiance(self, directions):
        """Sky radiance toward world ``directions`` (..., 3) [W m^-2 sr^-1], broadband."""
        return self.scale * self.relative_luminance(directions)

    def luminance(self, directions):
        """Sky luminance toward world ``directions`` (..., 3) [cd m^-2]."""
        return self.efficacy * self.radiance(directions)

    def horizontal_irradiance(self, n=IRRADIANCE_NODES):
        """The sky's horizontal irradiance [W m^-2] by
        :func:`~skyfit_mi.physics.sky.hemisphere_integral` (thesis eq. 4.19): 128 nodes agree
        with 512 to 3e-6 relative (1.5e-4 where the clamp at zero puts a kink in l_v)."""
        return float(hemisphere_integral(self.radiance, n))


    def to_sky(self, cct=None, ground_albedo=GROUND_ALBEDO, sun=True,
               sun_solid_angle=SUN_SOLID_ANGLE):
        """This sky and its sun as a linear-sRGB :class:`~skyfit_mi.physics.sky.Sky` (``perez``
        pattern): the sky in the unit-luminance colour of ``cct`` [K] (default
        :func:`default_cct`), keeping the measured DHI; the disc carrying the measured DNI over
        ``sun_solid_angle`` [sr] in :func:`~skyfit_mi.physics.sun.sun_rgb`'s colour; a Lambertian
        ground of ``ground_albedo`` lit by both."""
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
        return sky.with_ground(ground_albedo)


def default_cct(epsilon):
    """Sky colour temperature [K] for clearness ``epsilon``: 6500 K (overcast, epsilon = 1) to
    15000 K (clear, epsilon >= 6.2), linear in mired between.  A choice, not a published model
    (thesis 4.2.3: 4500-7000 K overcast, 1e4-1e5 K clear)."""
    w = float(np.clip((float(epsilon) - 1.0) / (CLEARNESS_BIN_EDGES[-2] - 1.0), 0.0, 1.0))
    return 1.0 / ((1.0 - w) / CCT_OVERCAST + w / CCT_CLEAR)


@dataclass(frozen=True)
class PerezOptions:
    """The model choices of a Perez sky (:func:`perez_sky`), checked where used.

    Attributes
    ----------
    decomposition, airmass_model : str
        Keys of :data:`DECOMPOSITIONS` (splitting GHI into DHI and DNI) and
        :data:`AIRMASS_MODELS` (for Delta, 1990 eq. 2).
    delta_floor : float or None
        Floor on Delta, in [0, 1], for the coefficients when 1.065 < epsilon < 2.8; None is the
        published model, which refuses (b > 0) some dark skies with a little sun.  The efficacy
        always uses the measured Delta.
    precipitable_water : float
        W [cm], in [0, 10], for the luminous efficacy (1990, eq. 7).
    nodes : int
        Quadrature nodes in cos theta_p of the normalisation (1993, eq. 3).
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
    """A Perez all-weather sky (1993, :class:`PerezSky`) scaled to measured irradiance.

    epsilon and Delta from :func:`clearness` and :func:`brightness`; the pattern from
    :func:`coefficients` (negative values clamped at 0, as gendaymtx); the level
    scale = E_dh / integral of l_v cos theta_p dOmega (1993, eq. 3); luminance from
    :func:`diffuse_efficacy`.

    Parameters
    ----------
    sun_zenith_deg, sun_azimuth_deg : float
        Solar zenith, in [0, 90), and compass azimuth [degrees].
    day_of_year : int
        1-366, for the extraterrestrial irradiance (and the decomposition).
    dhi, dni : float, optional
        Measured diffuse horizontal (> 0) and direct normal irradiance [W m^-2].
    ghi : float, optional
        Global horizontal irradiance [W m^-2], instead of ``dhi`` and ``dni``: split by
        ``options.decomposition``.
    options : PerezOptions
        The model choices (default: Radiance's floor and water, Erbs, Kasten and Young 1989).

    Raises
    ------
    SkyfitError
        On bad or missing irradiance, a sun on or below the horizon, an unknown model, or
        coefficients with b > 0 (as gendaylit; with the default floor only for epsilon >= 2.8
        and a low Delta).
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
    total = float(hemisphere_integral(unit.relative_luminance, options.nodes))  # 1993 eq. 3
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
    """The moves of a Perez sky's shape that a sky-shape fit mixes with it
    (:func:`~skyfit_mi.physics.sky_shape.shape_variants`), for :func:`perez_sky`'s ``info``:

    * ``clearness``: the next bin toward clearer (+1) or more overcast (-1), at the spec's Delta
      (floored by :func:`floored_delta`), its epsilon from :data:`CLEARNESS_BIN_CENTRES`;
    * ``brightness``: the spec's clearness at the coefficients' Delta times (+1) or over (-1)
      :data:`BRIGHTNESS_STEP`.

    A move is None beyond the first or last bin, below the spec bin's Delta floor, or where
    its coefficients leave the model (b > 0, or a black sky).

    Returns
    -------
    list of dict
        One per index: ``of`` ('clearness', 'brightness'), ``index`` ('epsilon', 'Delta'),
        ``from`` (the spec's epsilon, or its coefficients' Delta) and ``moves`` {+1, -1: None or
        ``to`` (the index), ``epsilon``, ``delta_coefficients``, ``clearness_bin``,
        ``coefficients``}.  Empty without epsilon (sun below the horizon).
    """
    if "epsilon" not in info:
        return []
    eps, delta, z = float(info["epsilon"]), float(info["delta"]), float(info["sun_zenith_deg"])
    delta_c = float(info.get("delta_coefficients", delta))
    k = int(clearness_bin(eps))
    sun = direction_from_angles(np.radians(z), 0.0)

    def move(to, epsilon, delta_to, k_to):
        c = coefficients(epsilon, delta_to, z)
        if not (np.all(np.isfinite(c)) and c[1] <= 0 and float(hemisphere_integral(
                PerezSky(sun, c, 1.0, 1.0).relative_luminance)) > 0):
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
