"""Sky light: CIE clear, overcast and intermediate skies (thesis section 4.2).

A :class:`Sky` is the whole daylight environment: a sun disc of finite solid angle and a sky
that is a weighted sum of fixed patterns, each weight a linear-sRGB radiance [W m^-2 sr^-1]:

* ``clear``: CIE clear sky f(zeta) gamma(theta_p) (eqs. 4.12-4.14),
* ``overcast``: CIE overcast (1 + 2 cos theta_p)/3 (eq. 4.16),
* ``uniform``: 1,
* ``intermediate``: Matsuura's, as Radiance's ``gensky +i`` (via
  :func:`skyfit_mi.physics.gensky.from_gensky`),
* ``perez``: the Perez all-weather pattern,

plus a uniform ``ground`` below the horizon and an optional lat-long ``envmap``
(:mod:`skyfit_mi.physics.envmap`) added to both.  The thesis's skies (eqs. 4.10-4.18) and
Radiance's ``skybright.cal`` are exact members; the ``cie_sky`` Mitsuba emitter evaluates the
same sum, so a frame's sky changes by numbers, never code.
"""

from dataclasses import dataclass, field, replace

import numpy as np

from . import cie_general
from .colour import SRGB_LUMINANCE, cct_to_rgb
from ..conventions import angles_from_direction, direction_from_angles, unit_directions
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
#: cos theta_p is held at >= this in the Perez pattern, as Radiance's perezlum.cal [unitless].
PEREZ_HORIZON_COS = 0.01
#: Zenith angle below which Kittler's zenith luminance (eq. 4.15) is held constant [deg].
KITTLER_MIN_ZENITH_DEG = 10.0

_PATTERNS = ("clear", "overcast", "uniform", "intermediate", "perez")

# What a fit may assume of a spec's light against the real one (skyfit_mi/fitting/sky_fit.py)
#: Prior sd of log k, the sky's level against the sun's about the spec's (``fit --sky prior``):
#: wide enough for the CIE and Perez skies' excess diffuse light on a measured clear day
#: (``docs/BENCHMARKS.md``, "Measured light").
SKY_LEVEL_SD = 0.35
#: Prior sd of the log of a modelled sun's level (thesis eq. 4.7, fixed extinction): clear-sky
#: DNI spans about +-20% over Linke turbidities 2-6.
SUN_LEVEL_SD = 0.2
#: The same for a sun carrying a measured DNI (``info["sun_measured"]``): a first-class
#: pyrheliometer (ISO 9060) reads 2-3% (95%), plus alignment and timing.
MEASURED_SUN_SD = 0.03
#: Widening of a modelled sun's log-level sd with the sky's fitted log level k, as sd =
#: hypot(SUN_LEVEL_SD, SUN_SKY_COUPLING log k): in Ineichen and Perez's model log DNI falls
#: 0.29-0.39 per unit log(DHI / DNI), so a sky fitted brighter says the model's air is off.
SUN_SKY_COUPLING = 0.35
#: How a fit takes the sky (``fit --sky``): as the spec's, its level fitted, or with its prior.
SKY_CHOICES = ("spec", "fit", "prior")


# ---- The angular patterns (shared, term by term, with the Mitsuba emitter) ----

#: Gauss-Legendre nodes in cos(theta) of the hemisphere quadratures (eq. 4.19), by twice as
#: many azimuths: 3e-6 relative on the sharpest (clear) skies, 25x cheaper than 512.
IRRADIANCE_NODES = 128


def unit_vector(v):
    """``v`` (a finite 3-vector) as a unit vector, or None if it is not one or is zero.  The
    largest component is divided out first so that no square overflows."""
    v = np.asarray(v, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        return None
    m = np.max(np.abs(v))
    return None if m == 0 else v / m / np.linalg.norm(v / m)


def hemisphere_integral(f, n=IRRADIANCE_NODES):
    """Integral of f(d) cos(theta) dOmega over the upper hemisphere (thesis eq. 4.19).

    ``f`` maps world directions (..., 3) to (...) or (..., k); returns a number or (k,).
    Gauss-Legendre in cos(theta) (``n`` nodes) by ``2 n`` equally spaced azimuths.
    """
    mu, wmu = np.polynomial.legendre.leggauss(n)
    mu, wmu = 0.5 * (mu + 1.0), 0.5 * wmu                 # nodes on (0, 1)
    m = 2 * n
    phi = (np.arange(m) + 0.5) * 2 * np.pi / m
    d = direction_from_angles(np.arccos(mu)[:, None], phi[None, :])
    return np.einsum("ij...,i->...", f(d), wmu * mu) * (2 * np.pi / m)


def gamma_factor(cos_theta_p):
    """gamma(theta_p) = 1 - exp(-0.32 / cos theta_p), thesis eq. 4.12; 1 for
    cos theta_p <= 0.01, as Radiance's ``skybright.cal`` (they agree to 1e-14 there)."""
    c = np.asarray(cos_theta_p, dtype=float)
    return np.where(c > 0.01, -np.expm1(-0.32 / np.where(c > 0.01, c, 1.0)), 1.0)


def scattering_indicatrix(zeta):
    """f(zeta) = 0.91 + 10 exp(-3 zeta) + 0.45 cos^2 zeta, thesis eq. 4.13; ``zeta`` is the
    angle between the sky point and the sun [rad]."""
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
    """Matsuura's intermediate-sky pattern as in Radiance's ``skybright.cal`` (``gensky +i``,
    not the thesis's eq. 4.18 mixture):

    ((1.35 sin(5.631 - 3.59 eta) + 3.12) sin(4.396 - 2.6 z_s) + 6.37 - eta)
    / 2.326 * exp(-0.563 gamma ((2.629 - eta)(1.562 - z_s) + 0.812)), with
    eta the point's zenith angle, z_s the sun's and gamma the angle between.
    """
    eta = np.arccos(np.clip(d[..., 2], -1.0, 1.0))
    zt = np.arccos(np.clip(sun[2], -1.0, 1.0))
    gam = np.arccos(np.clip(d @ sun, -1.0, 1.0))
    return (((1.35 * np.sin(5.631 - 3.59 * eta) + 3.12) * np.sin(4.396 - 2.6 * zt) + 6.37 - eta)
            / 2.326 * np.exp(gam * -0.563 * ((2.629 - eta) * (1.562 - zt) + 0.812)))


def perez_relative_luminance(cos_theta_p, zeta, coeffs):
    """Perez relative sky luminance l_v, 1993 eq. 1 [unitless].

    .. math:: l_v = (1 + a\\, e^{b / \\cos\\theta_p})(1 + c\\, e^{d \\zeta} + e \\cos^2\\zeta)

    (the paper's zeta is ``theta_p`` here, its gamma ``zeta``), coefficients from
    :func:`skyfit_mi.physics.perez.coefficients`.  ``cos theta_p`` is held at
    >= :data:`PEREZ_HORIZON_COS`, as perezlum.cal: finite at and below the horizon when b <= 0.
    Not clamped at zero (some bins give negative values at low Delta).

    Parameters
    ----------
    cos_theta_p, zeta : array_like
        Cosine of the element's zenith angle, and its angle to the sun [rad] in [0, pi].
    coeffs : array_like, shape (..., 5)
        a, b, c, d, e, broadcast against the angles.
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
    """Weight of the sky (vs. the ground) in Radiance's ``skybright.cal``:
    (cos+1.01)^10 / ((cos+1.01)^10 + (cos+1.01)^-10), 0.55 at the horizon."""
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
        Unit vector toward the sun's centre, world frame; it also orients the patterns.
    clear, overcast, uniform, intermediate, perez : ndarray (3,)
        Linear-sRGB weight of each sky pattern [W m^-2 sr^-1].
    perez_coefficients : ndarray (5,)
        a, b, c, d, e of :func:`perez_pattern`; used only where ``perez`` is non-zero.
    envmap : ndarray (H, W, 3) or None
        Tabulated radiance [W m^-2 sr^-1] over the sphere, world frame, lat-long layout of
        :mod:`skyfit_mi.physics.latlong`, added to the patterns and the ground; float32, >= 0.
    ground, sun_radiance : ndarray (3,)
        Radiance of the ground below the horizon and of the uniform solar disc [W m^-2 sr^-1].
    sun_solid_angle : float
        Solid angle of the solar disc [sr].
    horizon_blend : bool
        Blend sky into ground across the horizon as Radiance does (``gensky`` skies).
    departure : ndarray (5,)
        Weights a of the field 1 + sum_j a_j B_j (:mod:`~.sky_departure`) multiplying the
        patterns above the horizon (not map or ground) [unitless]; zeros unless fitted.
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
        """Squared chord |d - s|^2 at the disc's edge, 2 (1 - cos alpha) = Omega/pi: d is in
        the disc when |d - s|^2 <= this, a test that keeps its precision in float32."""
        return self.sun_solid_angle / np.pi

    def sky_radiance(self, directions):
        """Radiance of the sky alone (no sun) toward world ``directions`` (..., 3): linear
        sRGB [W m^-2 sr^-1], (..., 3)."""
        d = unit_directions(directions)
        s = self.sun_direction
        # the patterns with a weight, in this order (a term without one is left out)
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
        d = unit_directions(directions)
        return np.sum((d - self.sun_direction) ** 2, axis=-1) <= self.sun_chord2

    def radiance(self, directions):
        """Radiance of sky and sun toward world ``directions`` (..., 3): linear sRGB
        [W m^-2 sr^-1], (..., 3)."""
        return self.sky_radiance(directions) + self.sun_mask(directions)[..., None] * self.sun_radiance

    # ---- irradiance -------------------------------------------------------
    def sky_horizontal_irradiance(self, n=IRRADIANCE_NODES):
        """Horizontal irradiance from the sky alone [W m^-2], RGB (3,), by eq. 4.19's
        quadrature; cached per ``n``, read-only."""
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

    def with_ground(self, albedo):
        """A copy whose ground is a Lambertian reflector of ``albedo`` lit by this sky and
        sun: L = albedo E / pi [W m^-2 sr^-1]."""
        return replace(self, ground=albedo * self.horizontal_irradiance() / np.pi)

    # ---- levels -----------------------------------------------------------
    def scaled(self, diffuse_horizontal=None, direct_normal=None):
        """A copy with absolute levels set from measurements [W m^-2].

        ``diffuse_horizontal`` scales the patterns and the map so that the luminance-weighted
        sky irradiance equals it; ``direct_normal`` sets the sun disc.  The ground, a
        Lambertian reflector of the global horizontal irradiance (L = albedo E / pi), is
        rescaled with them, channel by channel.
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
        """Whether any light comes from other than the sun's disc (pattern, map or ground)."""
        return self._patterned or self.envmap is not None or bool(np.any(self.ground > 0))

    @property
    def ground_only(self):
        """Whether the only light other than the sun's disc is the ground's (no pattern or
        map)."""
        return not self._patterned and self.envmap is None and bool(np.any(self.ground > 0))

    @property
    def _patterned(self):
        """Whether any of the sky's patterns gives light."""
        return any(bool(np.any(getattr(self, p) > 0)) for p in _PATTERNS)

    def split(self):
        """(sun's light, sky's light): two skies adding up to this one, for a fit that scales
        them apart.  The sun's has the disc, the sky's the patterns and map; the Lambertian
        ground is shared per channel as the sun's and sky's horizontal irradiance."""
        e_sun, e_sky = self.sun_horizontal_irradiance(), self.sky_horizontal_irradiance()
        total = e_sun + e_sky
        lit = np.divide(e_sun, total, out=np.zeros(3), where=total > 0)
        sun = replace(self, **{p: np.zeros(3) for p in _PATTERNS}, envmap=None,
                      ground=self.ground * lit)
        return sun, replace(self, sun_radiance=np.zeros(3), ground=self.ground * (1.0 - lit))

    def sky_scaled(self, k):
        """A copy whose sky's light (:meth:`split`'s second part) is ``k`` times this one's
        (``fit --sky fit``)."""
        check_range("sky scale", k, 0.0, 1e3, "(relative)")
        sun, sky = self.split()
        return replace(self, **{p: getattr(self, p) * k for p in _PATTERNS},
                       envmap=None if self.envmap is None else self.envmap * np.float32(k),
                       ground=sun.ground + sky.ground * k)

    def tinted(self, factor):
        """A copy with all light (sun, sky, ground) times ``factor`` (3,) per channel, as a
        reference of known reflectance calibrates it; None: itself."""
        if factor is None:
            return self
        f = np.asarray(factor, dtype=float)
        return replace(self, **{p: getattr(self, p) * f for p in _PATTERNS + ("ground",
                                                                                "sun_radiance")},
                       envmap=None if self.envmap is None else self.envmap * f.astype(np.float32))

    def scaled_to_illuminance(self, diffuse_horizontal_lux, efficacy):
        """A copy scaled to a measured horizontal diffuse illuminance [lx]; ``efficacy``
        [lm W^-1] converts it to irradiance (thesis 4.2.2)."""
        check_range("luminous efficacy", efficacy, 1, 683, "lm W^-1")
        return self.scaled(diffuse_horizontal=diffuse_horizontal_lux / efficacy)


# ---- The thesis's skies ----

def kittler_zenith_luminance(sun_zenith_deg):
    """Clear-sky zenith luminance 300 + 3000 cot(theta_s) [cd m^-2], thesis eq. 4.15: stated
    for theta_s > 30 degrees and divergent at 0, so held at its 10-degree value above that;
    clamped at 0."""
    z = np.radians(np.maximum(np.asarray(sun_zenith_deg, dtype=float), KITTLER_MIN_ZENITH_DEG))
    return np.maximum(300.0 + 3000.0 / np.tan(z), 0.0)


def krochmann_seidl_zenith_luminance(sun_zenith_deg):
    """Overcast-sky zenith luminance 123 + 8600 cos(theta_s) [cd m^-2], thesis eq. 4.17,
    clamped at 0."""
    return np.maximum(123.0 + 8600.0 * np.cos(np.radians(sun_zenith_deg)), 0.0)


def thesis_sun_radiance(sun_zenith_deg, day, disc, phi):
    """The sun disc's linear-sRGB radiance [W m^-2 sr^-1] (3,): ``phi`` times eq. 4.7's direct
    normal irradiance (``disc``'s extinction and solar constant) over its solid angle, in
    :func:`~skyfit_mi.physics.sun.sun_rgb`'s colour; zero if phi is 0 or no disc is drawn."""
    if not disc.drawn or phi <= 0:
        return np.zeros(3)
    n = float(direct_normal_irradiance(sun_zenith_deg, day, disc.extinction,
                                       disc.solar_constant))
    return phi * n / disc.solid_angle * sun_rgb(sun_zenith_deg)


@dataclass(frozen=True)
class CIEPhotometry:
    """The photometry of the thesis's CIE clear and overcast skies (:func:`cie_sky`), checked
    where used.

    Attributes
    ----------
    clear_zenith_luminance, overcast_zenith_luminance : float or None
        Zenith luminances [cd m^-2], in [0, 1e6]; None: eq. 4.15 (Kittler) and eq. 4.17
        (Krochmann and Seidl).
    efficacy_clear, efficacy_overcast : float
        Luminous efficacies [lm W^-1], in [1, 683] (thesis 4.2.2).
    cct_clear, cct_overcast : float
        Sky colour temperatures [K] (thesis 4.2.3).
    """

    clear_zenith_luminance: float = None
    overcast_zenith_luminance: float = None
    efficacy_clear: float = EFFICACY_CLEAR
    efficacy_overcast: float = EFFICACY_OVERCAST
    cct_clear: float = CCT_CLEAR
    cct_overcast: float = CCT_OVERCAST


def _sun_disc(sun):
    """``sun`` if it is a :class:`~skyfit_mi.physics.sun.SunDisc`, else a SkyfitError."""
    if not isinstance(sun, SunDisc):
        raise SkyfitError(f"sun must be a SunDisc, got {sun!r}: SunDisc() draws the thesis's "
                          "sun, SunDisc(drawn=False) none (skyfit_mi.physics.sun.SunDisc).")
    return sun


#: The thesis's sky types and their sun probability phi (eq. 4.18).
SKY_TYPES = {"clear": 1.0, "overcast": 0.0, "intermediate": None}


def cie_sky(kind, sun_zenith_deg, sun_azimuth_deg, *, phi=None, day=172,
            photometry=CIEPhotometry(), sun=SunDisc(), ground_albedo=GROUND_ALBEDO):
    """A thesis sky (:class:`Sky`): CIE clear, CIE overcast, or intermediate (eq. 4.18).

    L_in = (1 - phi) L_oc + phi L_cl (eq. 4.18), phi the probability that the sun is out (1
    clear, 0 overcast).  L_cl follows eqs. 4.10-4.15, L_oc eqs. 4.16-4.17; luminance becomes
    radiance by the efficacies (4.2.2), coloured by a CCT (4.2.3).  The sun disc carries phi
    times eq. 4.7's direct normal irradiance; the ground is Lambertian, lit by sky and sun.

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
        Zenith luminances, efficacies and colour temperatures (default: the thesis's).
    sun : SunDisc
        The solar disc: drawn or not, eq. 4.7's beta and solar constant, solid angle.
    ground_albedo : float
        Ground reflectance in [0, 1].
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
    return sky.with_ground(ground_albedo)


def cie_general_sky(params, sun_zenith_deg, sun_azimuth_deg, *, day=172, zenith_luminance=None,
                    efficacy=EFFICACY_CLEAR, cct=CCT_CLEAR, sun=SunDisc(),
                    ground_albedo=GROUND_ALBEDO):
    """A CIE S 011 general sky (:mod:`skyfit_mi.physics.cie_general`) with the thesis's sun.

    L = L_z f(zeta) phi(theta_p) / (f(theta_s) phi(0)) [cd m^-2], rendered through the sky's
    Perez term (:func:`~skyfit_mi.physics.cie_general.perez_form`), converted by ``efficacy``
    and coloured by ``cct``.  L_z defaults to Kittler's (eq. 4.15), making standard type 12 the
    thesis's clear sky (eqs. 4.10-4.15; their 0.91 is 1 - 10 e^{-3 pi/2} to 2e-4); for other
    weather give ``zenith_luminance`` or use :meth:`Sky.scaled`.

    Parameters
    ----------
    params : array_like, shape (5,)
        a, b, c, d, e (:func:`~skyfit_mi.physics.cie_general.standard_parameters`).
    zenith_luminance : float, optional
        L_z [cd m^-2] (default eq. 4.15).
    efficacy, cct : float
        Luminous efficacy [lm W^-1] and colour temperature [K] of the skylight.
    sun_zenith_deg, sun_azimuth_deg, day, sun, ground_albedo
        As :func:`cie_sky`'s.
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
    return sky.with_ground(ground_albedo)


def directional_sky(direction, irradiance, solid_angle=SUN_SOLID_ANGLE):
    """A lab light as a :class:`Sky`: a disc of uniform radiance E / Omega toward
    ``direction``, no sky, no ground (its normal irradiance is then E).

    Parameters
    ----------
    direction : array_like (3,)
        Toward the source, world frame; normalised here.  Must be above the horizon (z > 0):
        skyfit treats a source at or below it as no sun.
    irradiance : float or array_like (3,)
        Irradiance normal to the beam [W m^-2], linear sRGB (one number: grey), >= 0.
    solid_angle : float
        The source's solid angle [sr] (default the sun's), in [1e-7, 0.5].
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
