"""Sky light: CIE clear, overcast and intermediate skies (thesis section 4.2).

A :class:`Sky` holds the whole daylight environment: the sky's radiance
distribution and the sun as a disc of finite solid angle.  The sky is a
weighted sum of fixed angular patterns, each weight a linear-sRGB radiance
[W m^-2 sr^-1]:

* ``clear``: the CIE clear-sky pattern f(zeta) gamma(theta_p) (eqs. 4.12-4.14),
* ``overcast``: the CIE overcast pattern (1 + 2 cos theta_p)/3 (eq. 4.16),
* ``uniform``: 1,
* ``intermediate``: the Matsuura intermediate pattern used by Radiance's
  ``gensky +i`` (only reached through :func:`skyfit_mi.physics.gensky.from_gensky`),

plus a uniform ``ground`` radiance below the horizon, and optionally a tabulated radiance
over the whole sphere, ``envmap`` (an HDR environment map on a latitude-longitude grid,
:mod:`skyfit_mi.physics.envmap`), added to both.  The thesis's skies
(eqs. 4.10-4.18) and Radiance's ``skybright.cal`` skies are both exact
members of this family, and the ``cie_sky`` Mitsuba emitter evaluates the
same sum, so a frame's sky changes by changing numbers, never code.
"""

from dataclasses import dataclass, field, replace

import numpy as np

from . import cie_general
from .colour import SRGB_LUMINANCE, cct_to_rgb
from ..conventions import angles_from_direction, direction_from_angles
from ..errors import SkyfitError, check_choice, check_range
from .latlong import latlong_radiance
from .sky_departure import BASIS, field_factor
from .sun import SUN_SOLID_ANGLE, SunDisc, direct_normal_irradiance, sun_rgb

#: Luminous efficacy of clear-sky light [lm W^-1] (thesis 4.2.2).
EFFICACY_CLEAR = 150.0
#: Luminous efficacy of overcast-sky light [lm W^-1]; the thesis gives 115-125.
EFFICACY_OVERCAST = 120.0
#: Default sky colour temperatures [K] (thesis 4.2.3: 1e4-1e5 clear, 4500-7000 overcast).
CCT_CLEAR = 15000.0
CCT_OVERCAST = 6500.0
#: Default ground reflectance (as Radiance's gensky).
GROUND_ALBEDO = 0.2
#: cos theta_p is held at this value below it in the Perez pattern, as in Radiance's
#: perezlum.cal [unitless].
PEREZ_HORIZON_COS = 0.01
#: Zenith angle below which Kittler's zenith luminance (eq. 4.15) is held constant [deg].
KITTLER_MIN_ZENITH_DEG = 10.0

_PATTERNS = ("clear", "overcast", "uniform", "intermediate", "perez")

# What a fit may assume of a spec's light against the real one (skyfit_mi/fitting/sky_fit.py)
#: The prior's standard deviation of log k, the sky's level against the sun's about the spec's
#: (``fit --sky prior``): on the shared measured clear day the CIE clear sky holds 1.2-1.3 times
#: the scans' diffuse light and Perez from Erbs's split of the measured GHI 1.49-1.78 times
#: (docs/BENCHMARKS.md, "Measured light", "Perez from irradiance"); 0.35 puts 1.8 at 1.7 sd.
SKY_LEVEL_SD = 0.35
#: The prior's standard deviation of the log of the sun's level when the spec models the sun
#: (thesis eq. 4.7 with a fixed extinction): on the shared clear day its direct light is 13-20%
#: under the measured (BENCHMARKS, "Measured light"), and clear-sky direct normal irradiance
#: spans about +-20% over common turbidities (Linke 2-6).
SUN_LEVEL_SD = 0.2
#: The same where the spec's sun carries a measured direct normal irradiance (its sky's
#: ``info["sun_measured"]``: a spec's ``direct_normal_W_m2`` or ``dni`` column): a first-class
#: pyrheliometer (ISO 9060) reads DNI to about 2-3% (95%) in the field; 0.03 as one sd of
#: the log leaves room for its alignment and for the time between reading and frame.
MEASURED_SUN_SD = 0.03
#: How much the log of a modelled sun's level moves, more than SUN_LEVEL_SD allows, with the
#: log of the sky's fitted level against the spec's: in Ineichen and Perez's clear-sky model
#: over Linke turbidities 2-7 at air mass 1.1-2, log DNI falls 0.29-0.39 per unit rise of
#: log(DHI / DNI) (tests/test_sky_fit.py): a sky fitted brighter against the sun than the
#: spec's (k > 1: haze, thin cloud) says the air is not the model's, and then the model's sun
#: is not to be trusted to 20% either (under Perez skies of clearness 2 and 4 in the sky test
#: set, the sun's level was 0.45 and 0.7 of eq. 4.7's).  The sun's sd becomes
#: hypot(SUN_LEVEL_SD, SUN_SKY_COUPLING log k): wider, never shifted.
SUN_SKY_COUPLING = 0.35
#: How a fit takes the sky (``fit --sky``): the spec's as it is, its level fitted, or fitted
#: with its prior.
SKY_CHOICES = ("spec", "fit", "prior")


# --------------------------------------------------------------------------
# The angular patterns (shared, term by term, with the Mitsuba emitter)
# --------------------------------------------------------------------------

#: Gauss-Legendre nodes in cos(theta) of the hemisphere quadratures (eq. 4.19), by twice as
#: many azimuths.  Against 1024 nodes, 128 agree to 3e-6 relative on clear skies with the sun
#: 10-85 degrees from the zenith (the sharpest pattern) and cost 25x less than 512.
IRRADIANCE_NODES = 128


def unit_vector(v):
    """``v`` (a finite 3-vector, any magnitude: its largest component divided out first, so
    that no square overflows) as a unit vector, or None where it is not one or is zero."""
    v = np.asarray(v, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        return None
    m = np.max(np.abs(v))
    return None if m == 0 else v / m / np.linalg.norm(v / m)


def hemisphere_integral(f, n=IRRADIANCE_NODES):
    """Integral of f(d) cos(theta) dOmega over the upper hemisphere (thesis eq. 4.19).

    ``f`` maps world directions (..., 3) to values (...) or (..., k); the result is a
    number or (k,).  Gauss-Legendre in cos(theta) (``n`` nodes on (0, 1)) by ``2 n``
    equally spaced azimuths.
    """
    mu, wmu = np.polynomial.legendre.leggauss(n)
    mu, wmu = 0.5 * (mu + 1.0), 0.5 * wmu                 # nodes on (0, 1)
    m = 2 * n
    phi = (np.arange(m) + 0.5) * 2 * np.pi / m
    d = direction_from_angles(np.arccos(mu)[:, None], phi[None, :])
    return np.einsum("ij...,i->...", f(d), wmu * mu) * (2 * np.pi / m)


def gamma_factor(cos_theta_p):
    """gamma(theta_p) = 1 - exp(-0.32 / cos theta_p), thesis eq. 4.12.

    Taken as 1 for cos theta_p <= 0.01 (near and below the horizon), as in
    Radiance's ``skybright.cal``; the two agree to 1e-14 there.
    """
    c = np.asarray(cos_theta_p, dtype=float)
    return np.where(c > 0.01, -np.expm1(-0.32 / np.where(c > 0.01, c, 1.0)), 1.0)


def scattering_indicatrix(zeta):
    """f(zeta) = 0.91 + 10 exp(-3 zeta) + 0.45 cos^2 zeta, thesis eq. 4.13.

    ``zeta`` is the angle between the sky point and the sun [rad].
    """
    zeta = np.asarray(zeta, dtype=float)
    return 0.91 + 10.0 * np.exp(-3.0 * zeta) + 0.45 * np.cos(zeta) ** 2


def clear_pattern(d, sun):
    """CIE clear-sky pattern f(zeta) gamma(theta_p) (eqs. 4.12-4.14), unnormalised."""
    cos_zeta = np.clip(d @ sun, -1.0, 1.0)                                   # eq. 4.14
    return scattering_indicatrix(np.arccos(cos_zeta)) * gamma_factor(d[..., 2])


def overcast_pattern(d):
    """CIE overcast-sky pattern (1 + 2 cos theta_p)/3, thesis eq. 4.16."""
    return (1.0 + 2.0 * d[..., 2]) / 3.0


def intermediate_pattern(d, sun):
    """Matsuura's intermediate-sky pattern as in Radiance's ``skybright.cal``.

    ((1.35 sin(5.631 - 3.59 eta) + 3.12) sin(4.396 - 2.6 z_s) + 6.37 - eta)
    / 2.326 * exp(-0.563 gamma ((2.629 - eta)(1.562 - z_s) + 0.812)), with
    eta the point's zenith angle, z_s the sun's and gamma the angle between.
    This is Radiance's ``gensky +i`` sky, not the thesis's eq. 4.18 mixture.
    """
    eta = np.arccos(np.clip(d[..., 2], -1.0, 1.0))
    zt = np.arccos(np.clip(sun[2], -1.0, 1.0))
    gam = np.arccos(np.clip(d @ sun, -1.0, 1.0))
    return (((1.35 * np.sin(5.631 - 3.59 * eta) + 3.12) * np.sin(4.396 - 2.6 * zt) + 6.37 - eta)
            / 2.326 * np.exp(gam * -0.563 * ((2.629 - eta) * (1.562 - zt) + 0.812)))


def perez_relative_luminance(cos_theta_p, zeta, coeffs):
    """Perez relative sky luminance l_v, 1993 eq. 1 [unitless].

    .. math:: l_v = (1 + a\\, e^{b / \\cos\\theta_p})(1 + c\\, e^{d \\zeta} + e \\cos^2\\zeta)

    (the paper's zeta is ``theta_p`` here and its gamma is ``zeta``).  The coefficients come
    from measured irradiance (:func:`skyfit_mi.physics.perez.coefficients`).
    Below ``cos theta_p`` = :data:`PEREZ_HORIZON_COS` the value at :data:`PEREZ_HORIZON_COS` is used, as
    in Radiance's perezlum.cal: the result is finite down to and below the horizon whenever
    b <= 0 (:func:`skyfit_mi.physics.perez.perez_sky` refuses b > 0).  Not clamped at zero: at low
    Delta some bins give negative values (see :mod:`skyfit_mi.physics.perez`).

    Parameters
    ----------
    cos_theta_p : array_like
        Cosine of the sky element's zenith angle [unitless].
    zeta : array_like
        Angle between the sky element and the sun [rad], in [0, pi].
    coeffs : array_like, shape (..., 5)
        a, b, c, d, e, broadcast against the angles.

    Returns
    -------
    ndarray
        l_v [unitless].
    """
    a, b, c, d, e = np.moveaxis(np.asarray(coeffs, dtype=float), -1, 0)
    mu = np.maximum(np.asarray(cos_theta_p, dtype=float), PEREZ_HORIZON_COS)
    zeta = np.asarray(zeta, dtype=float)
    return (1.0 + a * np.exp(b / mu)) * (1.0 + c * np.exp(d * zeta) + e * np.cos(zeta) ** 2)


def perez_pattern(d, sun, coeffs):
    """The Perez all-weather pattern l_v toward world directions ``d`` (..., 3), clamped at 0
    (as Radiance's gendaymtx), for the sun toward ``sun`` (1993 eq. 1; unitless)."""
    zeta = np.arccos(np.clip(d @ sun, -1.0, 1.0))
    return np.maximum(perez_relative_luminance(d[..., 2], zeta, coeffs), 0.0)


def horizon_blend_weight(cos_theta_p):
    """Weight of the sky (vs. the ground) in Radiance's ``skybright.cal``.

    (cos+1.01)^10 / ((cos+1.01)^10 + (cos+1.01)^-10): 0.55 at the horizon,
    0.98 at 11.5 degrees altitude.
    """
    a = (np.asarray(cos_theta_p, dtype=float) + 1.01) ** 10
    return a / (a + 1.0 / a)


def _rgb(value, name):
    v = np.asarray(value, dtype=float)
    v = np.broadcast_to(v, (3,)).astype(float) if v.ndim == 0 or v.shape == (1,) else v
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise SkyfitError(f"{name} must be a finite number or an RGB triple, got {value!r}.")
    return v


@dataclass(frozen=True)
class Sky:
    """A daylight environment: sky radiance pattern weights and a sun disc.

    Attributes
    ----------
    sun_direction : ndarray (3,)
        Unit vector toward the sun's centre, world frame (+X east, +Y north, +Z up).
        It also orients the sky patterns.
    clear, overcast, uniform, intermediate, perez : ndarray (3,)
        Linear-sRGB weight of each sky pattern [W m^-2 sr^-1].
    perez_coefficients : ndarray (5,)
        a, b, c, d, e of the Perez pattern (:func:`perez_pattern`); zeros give l_v = 1, but
        the pattern counts only where ``perez`` is non-zero.
    envmap : ndarray (H, W, 3) or None
        A tabulated radiance [W m^-2 sr^-1] over the whole sphere, world frame, in the lat-long
        layout of :mod:`skyfit_mi.physics.latlong` (bilinear between cell centres), added to the
        patterns above the horizon and to the ground below it; float32, non-negative.
    ground : ndarray (3,)
        Radiance of the ground below the horizon [W m^-2 sr^-1].
    horizon_blend : bool
        Blend sky into ground across the horizon as Radiance does (True for
        skies imported from ``gensky``); otherwise a sharp horizon.
    sun_radiance : ndarray (3,)
        Radiance of the solar disc [W m^-2 sr^-1] (uniform over the disc).
    sun_solid_angle : float
        Solid angle of the solar disc [sr].
    departure : ndarray (5,)
        Weights a of the field 1 + sum_j a_j B_j (:mod:`~.sky_departure`) that multiplies
        the patterns above the horizon (not the map, nor the ground) [unitless]: the sky's
        departure from its model; zeros (the model as it is) unless a fit moved it.
    info : dict
        How the sky was made (kind, phi, sun angles, levels...), for manifests.
    """

    sun_direction: np.ndarray
    clear: np.ndarray = field(default_factory=lambda: np.zeros(3))
    overcast: np.ndarray = field(default_factory=lambda: np.zeros(3))
    uniform: np.ndarray = field(default_factory=lambda: np.zeros(3))
    intermediate: np.ndarray = field(default_factory=lambda: np.zeros(3))
    perez: np.ndarray = field(default_factory=lambda: np.zeros(3))
    perez_coefficients: np.ndarray = field(default_factory=lambda: np.zeros(5))
    envmap: np.ndarray = None
    ground: np.ndarray = field(default_factory=lambda: np.zeros(3))
    horizon_blend: bool = False
    sun_radiance: np.ndarray = field(default_factory=lambda: np.zeros(3))
    sun_solid_angle: float = SUN_SOLID_ANGLE
    departure: np.ndarray = field(default_factory=lambda: np.zeros(len(BASIS)))
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        s = unit_vector(self.sun_direction)
        if s is None:
            raise SkyfitError(f"sun_direction must be a non-zero 3-vector, got {self.sun_direction!r}.")
        object.__setattr__(self, "sun_direction", s)
        for name in _PATTERNS + ("ground", "sun_radiance"):
            v = _rgb(getattr(self, name), name)
            if np.any(v < 0):
                raise SkyfitError(f"{name} = {v.tolist()} is negative; a radiance (or a "
                                  "pattern's weight) [W m^-2 sr^-1] is at least 0.")
            object.__setattr__(self, name, v)
        c = np.asarray(self.perez_coefficients, dtype=float).ravel()
        if c.shape != (5,) or not np.all(np.isfinite(c)) or c[1] > 0:
            raise SkyfitError(f"perez_coefficients must be 5 finite numbers a, b, c, d, e with "
                              f"b <= 0, got {self.perez_coefficients!r}.")
        object.__setattr__(self, "perez_coefficients", c)
        a = np.asarray(self.departure, dtype=float).ravel()
        if a.shape != (len(BASIS),) or not np.all(np.isfinite(a)):
            raise SkyfitError(f"departure must be {len(BASIS)} finite weights, got "
                              f"{self.departure!r}.")
        object.__setattr__(self, "departure", a)
        if self.envmap is not None:
            t = np.asarray(self.envmap, dtype=np.float32)
            if t.ndim != 3 or t.shape[2] != 3 or not np.all(np.isfinite(t)) or np.any(t < 0):
                raise SkyfitError(f"envmap must be a lat-long table (rows, columns, 3) of finite, "
                                  f"non-negative radiances, got shape {np.shape(self.envmap)}.")
            object.__setattr__(self, "envmap", t)
        check_range("sun_solid_angle", self.sun_solid_angle, 1e-7, 0.5, "sr")

    # ---- evaluation -------------------------------------------------------
    @property
    def sun_chord2(self):
        """Squared chord |d - s|^2 at the solar disc's edge, 2 (1 - cos alpha) = Omega/pi.

        A direction d is in the disc when |d - s|^2 <= this; unlike d.s >= cos alpha
        the test keeps its precision in single precision.
        """
        return self.sun_solid_angle / np.pi

    def sky_radiance(self, directions):
        """Radiance of the sky alone (no sun) toward world ``directions`` (..., 3).

        Returns linear sRGB [W m^-2 sr^-1], shape (..., 3).
        """
        d = np.asarray(directions, dtype=float)
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        s = self.sun_direction
        # the patterns with a weight, summed in this order (a term without one is exactly
        # zero and left out)
        sky = np.zeros(d.shape[:-1] + (3,))
        for weight, pattern in ((self.clear, lambda: clear_pattern(d, s)),
                                (self.overcast, lambda: overcast_pattern(d)),
                                (self.uniform, lambda: 1.0),
                                (self.intermediate, lambda: intermediate_pattern(d, s)),
                                (self.perez, lambda: perez_pattern(d, s, self.perez_coefficients))):
            if np.any(weight):
                sky = sky + np.asarray(pattern())[..., None] * weight
        if np.any(self.departure):
            sky = sky * field_factor(d, s, self.departure)[..., None]
        if self.horizon_blend:
            w = horizon_blend_weight(d[..., 2])[..., None]
            out = w * sky + (1.0 - w) * self.ground
        else:
            out = np.where(d[..., 2:3] > 0.0, sky, self.ground)
        if self.envmap is not None:
            out = out + latlong_radiance(self.envmap, d)
        return out

    def sun_mask(self, directions):
        """True where ``directions`` fall inside the solar disc."""
        d = np.asarray(directions, dtype=float)
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        return np.sum((d - self.sun_direction) ** 2, axis=-1) <= self.sun_chord2

    def radiance(self, directions):
        """Radiance of sky and sun toward world ``directions`` (..., 3).

        Returns linear sRGB [W m^-2 sr^-1], shape (..., 3).
        """
        return self.sky_radiance(directions) + self.sun_mask(directions)[..., None] * self.sun_radiance

    # ---- irradiance -------------------------------------------------------
    def sky_horizontal_irradiance(self, n=IRRADIANCE_NODES):
        """Horizontal irradiance from the sky alone [W m^-2], RGB (3,).

        Independent quadrature of eq. 4.19: Gauss-Legendre in cos(theta) over
        the upper hemisphere (``n`` nodes) by ``2 n`` azimuths.  Computed once per sky and
        ``n`` (a frame's manifest record, exposure and ground each ask for it), read-only.
        """
        known = self.__dict__.setdefault("_sky_irradiance", {})   # not a field: a frozen
        if n not in known:                                         # copy starts anew
            known[n] = hemisphere_integral(self.sky_radiance, n)
            known[n].flags.writeable = False
        return known[n]

    def sun_horizontal_irradiance(self):
        """Horizontal irradiance from the solar disc [W m^-2], RGB (3,)."""
        return self.sun_radiance * self.sun_solid_angle * max(self.sun_direction[2], 0.0)

    def horizontal_irradiance(self, n=IRRADIANCE_NODES):
        """Global horizontal irradiance, sky plus sun [W m^-2], RGB (3,)."""
        return self.sky_horizontal_irradiance(n) + self.sun_horizontal_irradiance()

    # ---- levels -----------------------------------------------------------
    def scaled(self, diffuse_horizontal=None, direct_normal=None):
        """A copy with absolute levels set from measurements.

        Parameters
        ----------
        diffuse_horizontal : float, optional
            Measured horizontal diffuse (sky) irradiance [W m^-2]; the sky
            patterns and the map (not the ground) are scaled so that the luminance-weighted
            sky irradiance equals it.
        direct_normal : float, optional
            Measured direct normal irradiance [W m^-2]; sets the sun disc.

        The ground, a Lambertian reflector of the global horizontal irradiance
        (L_ground = albedo E / pi), is rescaled with it, channel by channel.
        """
        out = self
        if diffuse_horizontal is not None:
            check_range("diffuse horizontal irradiance", diffuse_horizontal, 0, 2000, "W m^-2")
            now = float(self.sky_horizontal_irradiance() @ SRGB_LUMINANCE)
            if now <= 0:
                raise SkyfitError("this sky is black above the horizon; cannot scale it to a "
                                  "measured irradiance. Build it with a non-zero level first.")
            k = diffuse_horizontal / now
            out = replace(out, **{p: getattr(out, p) * k for p in _PATTERNS},
                          envmap=None if out.envmap is None else out.envmap * np.float32(k))
        if direct_normal is not None:
            check_range("direct normal irradiance", direct_normal, 0, 1500, "W m^-2")
            lum = float(out.sun_radiance @ SRGB_LUMINANCE)
            colour = out.sun_radiance / lum if lum > 0 else sun_rgb(
                np.degrees(np.arccos(out.sun_direction[2])))
            out = replace(out, sun_radiance=colour * direct_normal / out.sun_solid_angle)
        before, after = self.horizontal_irradiance(), out.horizontal_irradiance()
        ratio = np.divide(after, before, out=np.ones(3), where=before > 0)
        return replace(out, ground=self.ground * ratio)

    @property
    def lit_by_sky(self):
        """Whether any light comes from other than the sun's disc: a pattern, the map or the
        ground."""
        return self._patterned or self.envmap is not None or bool(np.any(self.ground > 0))

    @property
    def ground_only(self):
        """Whether the only light other than the sun's disc is the ground's (the sun's part of
        :meth:`split`): no pattern, no map."""
        return not self._patterned and self.envmap is None and bool(np.any(self.ground > 0))

    @property
    def _patterned(self):
        """Whether any of the sky's patterns gives light."""
        return any(bool(np.any(getattr(self, p) > 0)) for p in _PATTERNS)

    def split(self):
        """(the sun's light: its disc and the ground's share lit by it; the sky's: its patterns,
        its map and the ground's share lit by them): two skies whose light adds up to this
        one's, which a fit of the sun-to-sky level scales apart (radiance is linear in the
        light).  The ground, a Lambertian reflector of the horizontal irradiance (L = albedo E
        / pi), is shared channel by channel as the sun's and the sky's horizontal irradiance
        (:meth:`sun_horizontal_irradiance`, :meth:`sky_horizontal_irradiance`): a sky scaled
        by k leaves the sun-lit ground as it is."""
        e_sun, e_sky = self.sun_horizontal_irradiance(), self.sky_horizontal_irradiance()
        total = e_sun + e_sky
        lit = np.divide(e_sun, total, out=np.zeros(3), where=total > 0)
        sun = replace(self, **{p: np.zeros(3) for p in _PATTERNS}, envmap=None,
                      ground=self.ground * lit)
        return sun, replace(self, sun_radiance=np.zeros(3), ground=self.ground * (1.0 - lit))

    def sky_scaled(self, k):
        """A copy whose sky's light (:meth:`split`'s second part: the patterns, the map and the
        sky-lit ground) is ``k`` times this one's: the sky at a fitted level against the sun
        (``fit --sky fit``)."""
        check_range("sky scale", k, 0.0, 1e3, "(relative)")
        sun, sky = self.split()
        return replace(self, **{p: getattr(self, p) * k for p in _PATTERNS},
                       envmap=None if self.envmap is None else self.envmap * np.float32(k),
                       ground=sun.ground + sky.ground * k)

    def tinted(self, factor):
        """A copy whose light, the sun's, the sky's and the ground's, is ``factor`` (3,) times
        this one's per channel [unitless]: the light as a reference of known reflectance in the
        scene calibrates it (:func:`~skyfit_mi.fitting.fit.reference_factor`); None: itself."""
        if factor is None:
            return self
        f = np.asarray(factor, dtype=float)
        return replace(self, **{p: getattr(self, p) * f for p in _PATTERNS + ("ground",
                                                                                "sun_radiance")},
                       envmap=None if self.envmap is None else self.envmap * f.astype(np.float32))

    def scaled_to_illuminance(self, diffuse_horizontal_lux, efficacy):
        """A copy scaled to a measured horizontal diffuse illuminance [lx].

        ``efficacy`` [lm W^-1] converts it to irradiance (thesis 4.2.2).
        """
        check_range("luminous efficacy", efficacy, 1, 683, "lm W^-1")
        return self.scaled(diffuse_horizontal=diffuse_horizontal_lux / efficacy)


# --------------------------------------------------------------------------
# The thesis's skies
# --------------------------------------------------------------------------

def kittler_zenith_luminance(sun_zenith_deg):
    """Clear-sky zenith luminance 300 + 3000 cot(theta_s) [cd m^-2], thesis eq. 4.15.

    Kittler's formula is stated for theta_s > 30 degrees and diverges as
    theta_s -> 0; it is held at its value for 10 degrees above that, and
    clamped at 0 for a sun far below the horizon.
    """
    z = np.radians(np.maximum(np.asarray(sun_zenith_deg, dtype=float), KITTLER_MIN_ZENITH_DEG))
    return np.maximum(300.0 + 3000.0 / np.tan(z), 0.0)


def krochmann_seidl_zenith_luminance(sun_zenith_deg):
    """Overcast-sky zenith luminance 123 + 8600 cos(theta_s) [cd m^-2], thesis eq. 4.17.

    Clamped at 0 for a sun far below the horizon.
    """
    return np.maximum(123.0 + 8600.0 * np.cos(np.radians(sun_zenith_deg)), 0.0)


def thesis_sun_radiance(sun_zenith_deg, day, disc, phi):
    """The sun disc's linear-sRGB radiance [W m^-2 sr^-1] (3,): ``phi`` times the direct
    normal irradiance of eq. 4.7 (with the :class:`~skyfit_mi.physics.sun.SunDisc` ``disc``'s
    extinction and solar constant) over the disc's solid angle [sr], in the colour of
    :func:`~skyfit_mi.physics.sun.sun_rgb`; zero when ``phi`` is 0 or the disc is not drawn
    (no sun)."""
    if not disc.drawn or phi <= 0:
        return np.zeros(3)
    n = float(direct_normal_irradiance(sun_zenith_deg, day, disc.extinction,
                                       disc.solar_constant))
    return phi * n / disc.solid_angle * sun_rgb(sun_zenith_deg)


@dataclass(frozen=True)
class CIEPhotometry:
    """The photometry of the thesis's CIE clear and overcast skies (:func:`cie_sky`): their
    levels, luminous efficacies and colours.

    Attributes
    ----------
    clear_zenith_luminance : float or None
        Clear-sky zenith luminance [cd m^-2], in [0, 1e6]; None: Kittler's, eq. 4.15
        (:func:`kittler_zenith_luminance`).
    overcast_zenith_luminance : float or None
        Overcast-sky zenith luminance [cd m^-2], in [0, 1e6]; None: Krochmann and Seidl's,
        eq. 4.17 (:func:`krochmann_seidl_zenith_luminance`).
    efficacy_clear, efficacy_overcast : float
        Luminous efficacies of clear and overcast skylight [lm W^-1], in [1, 683] (thesis
        4.2.2; defaults :data:`EFFICACY_CLEAR` 150 and :data:`EFFICACY_OVERCAST` 120).
    cct_clear, cct_overcast : float
        Sky colour temperatures [K] (thesis 4.2.3; defaults :data:`CCT_CLEAR` 15000 and
        :data:`CCT_OVERCAST` 6500).

    The values are checked where they are used (:func:`cie_sky`).
    """

    clear_zenith_luminance: float = None
    overcast_zenith_luminance: float = None
    efficacy_clear: float = EFFICACY_CLEAR
    efficacy_overcast: float = EFFICACY_OVERCAST
    cct_clear: float = CCT_CLEAR
    cct_overcast: float = CCT_OVERCAST


def _sun_disc(sun):
    """``sun`` if it is a :class:`~skyfit_mi.physics.sun.SunDisc`, else a SkyfitError (a
    bool, as ``sun`` was before the disc became a record, says how to write it now)."""
    if not isinstance(sun, SunDisc):
        raise SkyfitError(f"sun must be a SunDisc, got {sun!r}: SunDisc() draws the thesis's "
                          "sun, SunDisc(drawn=False) none (skyfit_mi.physics.sun.SunDisc).")
    return sun


#: The thesis's sky types and their sun probability phi (eq. 4.18).
SKY_TYPES = {"clear": 1.0, "overcast": 0.0, "intermediate": None}


def cie_sky(kind, sun_zenith_deg, sun_azimuth_deg, *, phi=None, day=172,
            photometry=CIEPhotometry(), sun=SunDisc(), ground_albedo=GROUND_ALBEDO):
    """A thesis sky: CIE clear, CIE overcast, or intermediate (eq. 4.18).

    L_in = (1 - phi) L_oc + phi L_cl (eq. 4.18); clear is phi = 1 and
    overcast phi = 0.  L_cl follows eqs. 4.10-4.14 with zenith luminance
    eq. 4.15; L_oc eq. 4.16 with eq. 4.17.  Luminance becomes radiance by
    the luminous efficacies (4.2.2) and gets its colour from a CCT (4.2.3).
    The sun disc carries phi times the direct normal irradiance of eq. 4.7
    (phi is the probability that the sun is out).  The ground is a
    Lambertian plane of reflectance ``ground_albedo`` lit by sky and sun.

    Parameters
    ----------
    kind : {'clear', 'overcast', 'intermediate'}
    sun_zenith_deg, sun_azimuth_deg : float
        Sun position [degrees], zenith in [0, 180], compass azimuth.
    phi : float, optional
        Sun probability in [0, 1]; required for 'intermediate'.
    day : int
        Day of the year (for eq. 4.5).
    photometry : CIEPhotometry
        The skies' zenith luminances (None: eqs. 4.15 / 4.17) [cd m^-2], luminous
        efficacies [lm W^-1] and colour temperatures [K] (default: the thesis's).
    sun : SunDisc
        The solar disc: whether it is drawn, beta and the solar constant of eq. 4.7
        [W m^-2], its solid angle [sr] (default: the thesis's, 0.431, 1377, 6e-5).
    ground_albedo : float
        Ground reflectance in [0, 1].

    Returns
    -------
    Sky
    """
    check_choice("sky type", kind, tuple(SKY_TYPES))
    if kind == "intermediate":
        if phi is None:
            raise SkyfitError("an intermediate sky needs a sun probability phi in [0, 1], "
                              "e.g. phi=0.5.")
    elif phi is not None and phi != SKY_TYPES[kind]:
        raise SkyfitError(f"a {kind} sky has phi = {SKY_TYPES[kind]:g}; give phi only for an "
                          f"intermediate sky (or use kind='intermediate').")
    phi = SKY_TYPES[kind] if phi is None else phi
    check_range("sun probability phi", phi, 0.0, 1.0)
    check_range("sun zenith", sun_zenith_deg, 0.0, 180.0, "degrees")
    check_range("ground albedo", ground_albedo, 0.0, 1.0)
    ph = photometry
    sun = _sun_disc(sun)
    for name, v in (("efficacy_clear", ph.efficacy_clear),
                    ("efficacy_overcast", ph.efficacy_overcast)):
        check_range(name, v, 1.0, 683.0, "lm W^-1")

    theta_s = np.radians(sun_zenith_deg)
    s = direction_from_angles(theta_s, np.radians(sun_azimuth_deg))
    lz_cl = kittler_zenith_luminance(sun_zenith_deg) if ph.clear_zenith_luminance is None \
        else check_range("clear zenith luminance", ph.clear_zenith_luminance, 0, 1e6, "cd m^-2")
    lz_oc = krochmann_seidl_zenith_luminance(sun_zenith_deg) \
        if ph.overcast_zenith_luminance is None else check_range(
            "overcast zenith luminance", ph.overcast_zenith_luminance, 0, 1e6, "cd m^-2")
    # eq. 4.10: L_cl = L_zcl * pattern / (gamma(0) f(theta_s))
    norm = float(gamma_factor(1.0) * scattering_indicatrix(theta_s))
    clear = phi * float(lz_cl) / norm / ph.efficacy_clear * cct_to_rgb(ph.cct_clear)
    overcast = (1.0 - phi) * float(lz_oc) / ph.efficacy_overcast * cct_to_rgb(ph.cct_overcast)

    sun_rad = thesis_sun_radiance(sun_zenith_deg, day, sun, phi)
    sky = Sky(s, clear=clear, overcast=overcast, sun_radiance=sun_rad,
              sun_solid_angle=sun.solid_angle,
              info={"kind": kind, "phi": phi, "sun_zenith_deg": float(sun_zenith_deg),
                    "sun_azimuth_deg": float(sun_azimuth_deg),
                    "clear_zenith_luminance_cd_m2": float(lz_cl),
                    "overcast_zenith_luminance_cd_m2": float(lz_oc),
                    "ground_albedo": ground_albedo})
    return replace(sky, ground=ground_albedo * sky.horizontal_irradiance() / np.pi)


def cie_general_sky(params, sun_zenith_deg, sun_azimuth_deg, *, day=172, zenith_luminance=None,
                    efficacy=EFFICACY_CLEAR, cct=CCT_CLEAR, sun=SunDisc(),
                    ground_albedo=GROUND_ALBEDO):
    """A CIE S 011 general sky (:mod:`skyfit_mi.physics.cie_general`) with the thesis's sun.

    L = L_z f(zeta) phi(theta_p) / (f(theta_s) phi(0)) [cd m^-2], rendered through the Perez
    term of the sky family (:func:`~skyfit_mi.physics.cie_general.perez_form`), turned into
    radiance by ``efficacy`` and coloured by ``cct``.  The level is the zenith luminance L_z,
    by default Kittler's (eq. 4.15, the thesis's clear sky), so standard type 12 is the thesis's
    clear sky (eqs. 4.10-4.15; their 0.91 is 1 - 10 e^{-3 pi/2} to 2e-4).  For other weather
    give ``zenith_luminance`` or rescale to measured light (:meth:`Sky.scaled`).  The sun disc
    carries the direct normal irradiance of eq. 4.7; the ground is Lambertian, lit by both.

    Parameters
    ----------
    params : array_like, shape (5,)
        a, b, c, d, e (:func:`~skyfit_mi.physics.cie_general.standard_parameters`,
        :func:`~skyfit_mi.physics.cie_general.group_parameters`).
    sun_zenith_deg, sun_azimuth_deg : float
        Sun position [degrees], zenith in [0, 180], compass azimuth.
    day : int
        Day of the year (eq. 4.5).
    zenith_luminance : float, optional
        L_z [cd m^-2] (default eq. 4.15).
    efficacy : float
        Luminous efficacy of the skylight [lm W^-1].
    cct : float
        Sky colour temperature [K].
    sun : SunDisc
        The solar disc (eq. 4.7), as :func:`cie_sky`'s.
    ground_albedo : float
        Ground reflectance in [0, 1].

    Returns
    -------
    Sky
    """
    check_range("sun zenith", sun_zenith_deg, 0.0, 180.0, "degrees")
    check_range("ground albedo", ground_albedo, 0.0, 1.0)
    check_range("efficacy", efficacy, 1.0, 683.0, "lm W^-1")
    sun = _sun_disc(sun)
    p = np.asarray(params, dtype=float)
    k, coefficients = cie_general.perez_form(p)
    theta_s = np.radians(sun_zenith_deg)
    lz = kittler_zenith_luminance(sun_zenith_deg) if zenith_luminance is None \
        else check_range("zenith luminance", zenith_luminance, 0, 1e6, "cd m^-2")
    norm = float(cie_general.indicatrix(theta_s, *p[2:])
                 * cie_general.gradation(1.0, *p[:2]))
    weight = float(lz) * k / norm / efficacy * cct_to_rgb(cct)
    sun_rad = thesis_sun_radiance(sun_zenith_deg, day, sun, 1.0)
    sky = Sky(direction_from_angles(theta_s, np.radians(sun_azimuth_deg)), perez=weight,
              perez_coefficients=coefficients, sun_radiance=sun_rad,
              sun_solid_angle=sun.solid_angle,
              info={"kind": "cie_general", "parameters_abcde": p.tolist(),
                    "sun_zenith_deg": float(sun_zenith_deg),
                    "sun_azimuth_deg": float(sun_azimuth_deg),
                    "zenith_luminance_cd_m2": float(lz), "efficacy_lm_W": float(efficacy),
                    "ground_albedo": ground_albedo})
    return replace(sky, ground=ground_albedo * sky.horizontal_irradiance() / np.pi)


def directional_sky(direction, irradiance, solid_angle=SUN_SOLID_ANGLE):
    """A lab light as a :class:`Sky`: a disc of uniform radiance E / Omega toward ``direction``,
    no sky, no ground.

    The disc's normal irradiance is then E (radiance times solid angle, exact for a uniform disc
    seen head on), and a horizontal surface receives E cos(theta) from it.

    Parameters
    ----------
    direction : array_like (3,)
        Toward the source, world frame (+X east, +Y north, +Z up); normalised here.  It must lie
        above the horizon (z > 0): skyfit treats a source at or below it as no sun (frames are
        skipped or unlit, the fit's light cache takes no samples of it).
    irradiance : float or array_like (3,)
        Irradiance normal to the beam [W m^-2], linear sRGB (one number: grey), >= 0.
    solid_angle : float
        The source's solid angle seen from the scene [sr] (default the sun's), in [1e-7, 0.5].
    """
    d = unit_vector(direction)
    if d is None:
        raise SkyfitError(f"a directional light needs a non-zero direction [x east, y north, "
                          f"z up] toward the source, got {direction!r}.")
    if d[2] <= 0:
        raise SkyfitError(f"the directional light's direction ({d[0]:.4g}, {d[1]:.4g}, "
                          f"{d[2]:.4g}) is at or below the horizon (zenith "
                          f"{np.degrees(np.arccos(np.clip(d[2], -1, 1))):.4g} degrees); give a "
                          "source above it (z > 0).")
    e = _rgb(irradiance, "directional irradiance")
    check_range("directional irradiance", e, 0.0, 1e6, "W m^-2")
    check_range("directional solid angle", solid_angle, 1e-7, 0.5, "sr")
    zenith, azimuth = (float(np.degrees(a)) for a in angles_from_direction(d))
    return Sky(d, sun_radiance=e / solid_angle, sun_solid_angle=solid_angle,
               info={"kind": "directional", "irradiance_W_m2": e.tolist(),
                     "sun_zenith_deg": zenith, "sun_azimuth_deg": azimuth})
