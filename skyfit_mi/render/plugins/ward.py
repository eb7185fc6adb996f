"""The ``ward`` BSDF: Ward's isotropic model (thesis eq. 3.19) with the thesis's parameterisations.

Implements exactly :func:`skyfit_mi.physics.ward.ward_brdf` with importance sampling after
B. Walter, "Notes on the Ward BRDF", Cornell PCG-05-06, 2005 (half vector with tan^2 delta =
-sigma^2 ln u), mixed with cosine-weighted diffuse sampling in proportion to the reflectances.
sigma_alpha <= 1e-4 is an ideal mirror (a Dirac delta) reflecting rho_s times the sigma -> 0
limit of the normalisation; with ``radiance`` (Radiance 6's ``plastic``/``metal``: the balanced
lobe plus Radiance's smooth-surface Fresnel estimate, src/rt/normal.c) the mirror reflects
rho_s + F(cos) (1 - rho_s) and the diffuse part is scaled by (1 - F(cos_i)) (1 - F(cos_o)) when
the specularity (``rho_s``; max(rho_s) in ``raw``) is at least 0.018.

Parameters (reflectances unitless, sigma_alpha the rms slope):

=================  =========  ============  =============  ===============================================
name               type       range         default        notes
=================  =========  ============  =============  ===============================================
``model``          string     see below     ``raw``        which parameters the plugin takes
``normalisation``  string     see below     ``ward``       ``ward`` (eq. 3.19), ``duer``, ``balanced``, ``radiance``,
                                                           or a microfacet lobe (``ggx_plastic``...)
``rho_d``          rgb/float  [0, 1]        0.5            ``raw`` only; rho_d + rho_s <= 1
``rho_s``          rgb/float  [0, 1]        0.05           rgb in ``raw``, float in the other models
``sigma_alpha``    float      [0, 1]        0.1            0 = mirror
``R``              float      [0, 1]        1.0            ``achromatic`` only (eq. 3.20)
``C``              rgb        [0, 1]        (1, 1, 1)      ``colour`` only; plastic/metal rule at rho_s 0.5
=================  =========  ============  =============  ===============================================

A microfacet ``normalisation`` (:mod:`skyfit_mi.physics.microfacet`: ``beckmann_plastic``,
``beckmann_metal``, ``ggx_plastic``, ``ggx_metal``) replaces Ward's lobe by F D G1 G1 / (4 cos_i
cos_o) with alpha = sigma_alpha, sampled by its own distribution of half vectors; its ideal
mirror reflects rho_s F(cos_o).

Models: ``raw`` (rho_d, rho_s, sigma_alpha), ``two`` (rho_s, sigma_alpha; rho_d = 1 - rho_s),
``achromatic`` (R, rho_s, sigma_alpha), ``colour`` (C, rho_s, sigma_alpha).  ``traverse``
exposes exactly the model's parameters, all differentiable; values set through
``params.update()`` are clamped in the kernel (validated only when built from properties).
"""

import drjit as dr
import mitsuba as mi
import numpy as np

from ...errors import check_choice
from .properties import property_values
from ...physics.colour import SRGB_LUMINANCE
from ...physics.microfacet import ETA_PLASTIC, LOBES, split
from ...physics.ward import (METAL_THRESHOLD, MODELS, NORMALISATIONS, RADIANCE_FRESNEL_K,
                              RADIANCE_FRESNEL_MIN, SIGMA_MAX, SIGMA_MIRROR, raw_parameters)

_DEFAULTS = {"rho_d": 0.5, "rho_s": 0.05, "sigma_alpha": 0.1, "R": 1.0, "C": (1.0, 1.0, 1.0)}
_RGB_PARAMS = {"raw": ("rho_d", "rho_s"), "colour": ("C",)}


def _prop(props, name):
    a = property_values(props, name, _DEFAULTS[name])
    return float(a[0]) if a.size == 1 else a


def _lum(c):
    wr, wg, wb = (float(w) for w in SRGB_LUMINANCE)
    return wr * c.x + wg * c.y + wb * c.z


class WardBSDF(mi.BSDF):
    """Ward's isotropic BRDF (see the module docstring for parameters)."""

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        self.model = check_choice("Ward model", props.get("model", "raw"), tuple(MODELS))
        self.normalisation = check_choice("Ward normalisation", props.get("normalisation", "ward"),
                                          NORMALISATIONS)
        values = {k: _prop(props, k) for k in MODELS[self.model]}
        raw_parameters(self.model, **values)          # validates; raises SkyfitError
        self.names = MODELS[self.model]
        for k, v in values.items():
            if k in _RGB_PARAMS.get(self.model, ()):
                setattr(self, k, mi.Color3f(*map(float, np.broadcast_to(v, (3,)))))
            else:
                setattr(self, k, mi.Float(float(v)))
        front = mi.BSDFFlags.FrontSide
        self.m_components = [mi.BSDFFlags.DiffuseReflection | front,
                             mi.BSDFFlags.GlossyReflection | front,
                             mi.BSDFFlags.DeltaReflection | front]
        self.m_flags = self.m_components[0] | self.m_components[1] | self.m_components[2]

    def traverse(self, cb):
        for k in self.names:
            cb.put(k, getattr(self, k), mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys=[]):
        pass

    # ---- the model --------------------------------------------------------
    def raw(self):
        """(rho_d, rho_s, sigma) as Dr.Jit values, clamped to valid ranges (the fitting model's
        control variate needs rho_d)."""
        sigma = dr.clip(self.sigma_alpha, 0.0, SIGMA_MAX)
        if self.model == "raw":
            rho_s = dr.clip(self.rho_s, 0.0, 1.0)
            rho_d = dr.minimum(dr.clip(self.rho_d, 0.0, 1.0), 1.0 - rho_s)
            return rho_d, rho_s, sigma
        ps = dr.clip(self.rho_s, 0.0, 1.0)
        if self.model == "two":
            return mi.Color3f(1.0 - ps), mi.Color3f(ps), sigma
        if self.model == "achromatic":
            r = dr.clip(self.R, 0.0, 1.0)
            return mi.Color3f(r * (1.0 - ps)), mi.Color3f(r * ps), sigma          # eq. 3.20
        c = dr.clip(self.C, 0.0, 1.0)
        spec = dr.select(ps >= METAL_THRESHOLD, c * ps, mi.Color3f(ps))
        return c * (1.0 - ps), spec, sigma

    def _mirror_fraction(self, cos_i):
        if self.normalisation in LOBES:
            return _fresnel(cos_i, split(self.normalisation)[1])
        return dr.clip(cos_i, 0.0, 1.0) if self.normalisation == "ward" else mi.Float(1.0)

    def _fresnel(self, cos, rho_s, sigma):
        """The 'radiance' normalisation's Fresnel estimate at ``cos`` (0 where it does not
        apply), as skyfit_mi.physics.ward.smooth_fresnel with the model's specularity."""
        spec = dr.maximum(dr.maximum(rho_s.x, rho_s.y), rho_s.z) if self.model == "raw" \
            else dr.clip(self.rho_s, 0.0, 1.0)
        on = (sigma <= SIGMA_MIRROR) & (spec >= RADIANCE_FRESNEL_MIN)
        return dr.select(on, dr.exp(-5.85 * dr.abs(cos)) - RADIANCE_FRESNEL_K, 0.0)

    def _mix(self, ci, rho_d, rho_s, sigma):
        """(diffuse, specular) reflectances seen from the view at cosine ``ci``, that split the
        samples: rho_d, rho_s, or with the 'radiance' Fresnel rho_d (1 - F), rho_s + F (1 - rho_s)."""
        if self.normalisation != "radiance":
            return rho_d, rho_s
        f = self._fresnel(ci, rho_s, sigma)
        return rho_d * (1.0 - f), rho_s + f * (1.0 - rho_s)

    def _p_spec(self, ctx, ci, rho_d, rho_s, sigma):
        """The chance of a specular sample (1 or 0 where ``ctx`` disables a side)."""
        en_d, en_g, en_delta = self._enabled(ctx)
        if not (en_d and (en_g or en_delta)):
            return mi.Float(1.0 if en_g or en_delta else 0.0)
        ld, ls = (_lum(x) for x in self._mix(ci, rho_d, rho_s, sigma))
        return dr.select(ld + ls > 0, ls / dr.maximum(ld + ls, 1e-12), 0.0)

    def _enabled(self, ctx):
        return (ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 0),
                ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 1),
                ctx.is_enabled(mi.BSDFFlags.DeltaReflection, 2))

    def eval(self, ctx, si, wo, active=True):
        wi = si.wi
        ci, co = mi.Frame3f.cos_theta(wi), mi.Frame3f.cos_theta(wo)
        rho_d, rho_s, sigma = self.raw()
        en_d, en_g, _ = self._enabled(ctx)
        f = mi.Color3f(0.0)
        if en_d:
            if self.normalisation == "radiance":
                rho_d = rho_d * ((1.0 - self._fresnel(ci, rho_s, sigma))
                                 * (1.0 - self._fresnel(co, rho_s, sigma)))
            f += rho_d * dr.inv_pi
        if en_g:
            f += rho_s * lobe(wi, wo, sigma, self.normalisation)
        valid = mi.Bool(active) & (ci > 0) & (co > 0)
        return mi.Spectrum(dr.select(valid, f * co, 0.0))

    def pdf(self, ctx, si, wo, active=True):
        wi = si.wi
        ci, co = mi.Frame3f.cos_theta(wi), mi.Frame3f.cos_theta(wo)
        rho_d, rho_s, sigma = self.raw()
        en_d, en_g, _ = self._enabled(ctx)
        mirror = sigma <= SIGMA_MIRROR
        p_spec = self._p_spec(ctx, ci, rho_d, rho_s, sigma)
        pdf = mi.Float(0.0)
        if en_d:
            pdf += (1.0 - p_spec) * co * dr.inv_pi
        if en_g:
            pdf += dr.select(mirror, 0.0, p_spec * glossy_pdf(wi, wo, sigma,
                                                              lobe_distribution(self.normalisation)))
        valid = mi.Bool(active) & (ci > 0) & (co > 0)
        return dr.select(valid, pdf, 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        wi = si.wi
        ci = mi.Frame3f.cos_theta(wi)
        rho_d, rho_s, sigma = self.raw()
        en_d, en_g, en_delta = self._enabled(ctx)
        mirror = sigma <= SIGMA_MIRROR
        p_spec = self._p_spec(ctx, ci, rho_d, rho_s, sigma)
        pick_spec = sample1 < p_spec
        if not en_g:
            pick_spec &= mirror
        if not en_delta:
            pick_spec &= ~mirror

        wo_glossy = sample_glossy(wi, sample2, sigma, lobe_distribution(self.normalisation))
        wo_mirror = mi.reflect(wi)
        wo_diffuse = mi.warp.square_to_cosine_hemisphere(sample2)

        wo = dr.select(pick_spec, dr.select(mirror, wo_mirror, wo_glossy), wo_diffuse)
        bs = dr.zeros(mi.BSDFSample3f)
        bs.wo = wo
        bs.eta = 1.0
        delta = pick_spec & mirror
        bs.sampled_component = dr.select(pick_spec, dr.select(mirror, mi.UInt32(2), mi.UInt32(1)),
                                         mi.UInt32(0))
        bs.sampled_type = dr.select(delta, mi.UInt32(+mi.BSDFFlags.DeltaReflection),
                                    dr.select(pick_spec, mi.UInt32(+mi.BSDFFlags.GlossyReflection),
                                              mi.UInt32(+mi.BSDFFlags.DiffuseReflection)))
        smooth_pdf = self.pdf(ctx, si, wo, active)
        bs.pdf = dr.select(delta, p_spec, smooth_pdf)
        f = self.eval(ctx, si, wo, active)
        w_smooth = f / dr.maximum(smooth_pdf, 1e-20)
        w_delta = mi.Spectrum(self._mix(ci, rho_d, rho_s, sigma)[1] * self._mirror_fraction(ci)) \
            / dr.maximum(p_spec, 1e-20)
        weight = dr.select(delta, w_delta, w_smooth)
        ok = mi.Bool(active) & (ci > 0) & (mi.Frame3f.cos_theta(wo) > 0) & (bs.pdf > 0)
        bs.pdf = dr.select(ok, bs.pdf, 0.0)
        return bs, dr.select(ok, weight, 0.0)

    def to_string(self):
        vals = ", ".join(f"{k}={getattr(self, k)}" for k in self.names)
        return f"WardBSDF[model={self.model}, normalisation={self.normalisation}, {vals}]"


# ---- the glossy lobe as functions (used without plugins: each registered BSDF adds a
# virtual-call target to the path integrator) -------------------------------------------------
def lobe(wi, wo, sigma, normalisation):
    """Specular lobe value (no rho_s) [sr^-1] at roughness ``sigma`` (any Dr.Jit value), as
    skyfit_mi.physics.ward.specular_lobe; 0 below either horizon and for a mirror."""
    ci, co = mi.Frame3f.cos_theta(wi), mi.Frame3f.cos_theta(wo)
    valid = (ci > 0) & (co > 0) & (sigma > SIGMA_MIRROR)
    if normalisation in LOBES:
        return dr.select(valid, _microfacet(wi, wo, sigma, normalisation), 0.0)
    hu = wi + wo
    hz = hu.z
    hh = dr.squared_norm(hu)
    s2 = dr.square(dr.maximum(sigma, SIGMA_MIRROR))
    hz2 = dr.maximum(dr.square(hz), 1e-20)
    # tan^2 delta from the tangential components: (hh - hz^2) cancels in single precision
    e = dr.exp(-(dr.square(hu.x) + dr.square(hu.y)) / (hz2 * s2))
    if normalisation == "ward":
        f = e / (4.0 * dr.pi * s2 * dr.safe_sqrt(ci * co))                       # eq. 3.19
    elif normalisation == "duer":
        f = e / (4.0 * dr.pi * s2 * ci * co)
    else:
        f = e * hh / (dr.pi * s2 * dr.square(hz2))
    return dr.select(valid, f, 0.0)


# ---- microfacet lobes (skyfit_mi.physics.microfacet, Mitsuba's MicrofacetDistribution) ----
def lobe_distribution(normalisation):
    """The half vectors' distribution of lobe ``normalisation``: 'ggx' or 'beckmann' (Ward's)."""
    return split(normalisation)[0] if normalisation in LOBES else "beckmann"


def _fresnel(cos, kind):
    """F at cosine ``cos`` for the lobe's Fresnel ``kind`` (microfacet.fresnel)."""
    if kind != "plastic":
        return mi.Float(1.0)
    c = dr.clip(dr.abs(cos), 0.0, 1.0)
    eta = ETA_PLASTIC
    ct = dr.safe_sqrt(1.0 - (1.0 - c * c) / (eta * eta))
    rs = (c - eta * ct) / (c + eta * ct)
    rp = (eta * c - ct) / (eta * c + ct)
    return 0.5 * (rs * rs + rp * rp)


def _tan2(x, y, z):
    """tan^2 of a direction (x, y, z) from its tangential part (no cancellation)."""
    return (dr.square(x) + dr.square(y)) / dr.maximum(dr.square(z), 1e-20)


def _smith_g1(v, alpha, kind):
    """Smith's G1 of the local direction ``v`` (microfacet.smith_g1)."""
    t2 = dr.square(alpha) * _tan2(v.x, v.y, v.z)
    if kind == "beckmann":
        a = dr.rsqrt(dr.maximum(t2, 1e-30))
        g = dr.select(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a)
                      / (1.0 + 2.276 * a + 2.577 * a * a))
    else:
        g = 2.0 / (1.0 + dr.sqrt(1.0 + t2))
    return dr.select(v.z > 0, g, 0.0)


def _ndf(h, alpha, kind):
    """D(h) [sr^-1] of unit half vectors ``h`` (microfacet.distribution)."""
    a2 = dr.square(dr.maximum(alpha, SIGMA_MIRROR))
    t2 = _tan2(h.x, h.y, h.z)
    c4 = dr.square(dr.square(h.z))
    if kind == "beckmann":
        return dr.exp(-t2 / a2) / (dr.pi * a2 * c4)
    return a2 / (dr.pi * c4 * dr.square(a2 + t2))


def _microfacet(wi, wo, alpha, normalisation):
    """F(wi.h) D(h) G1(wi) G1(wo) / (4 cos_i cos_o) (microfacet.microfacet_lobe)."""
    dist, kind = split(normalisation)
    h = dr.normalize(wi + wo)
    f = _fresnel(dr.dot(wi, h), kind) * _ndf(h, alpha, dist) * _smith_g1(wi, alpha, dist) \
        * _smith_g1(wo, alpha, dist)
    return f / (4.0 * dr.maximum(mi.Frame3f.cos_theta(wi) * mi.Frame3f.cos_theta(wo), 1e-20))


def glossy_pdf(wi, wo, sigma, distribution="beckmann"):
    """Walter's half-vector density D(h) cos(theta_h) of ``distribution`` mapped to wo
    [sr^-1] (:func:`sample_glossy`'s)."""
    h = dr.normalize(wi + wo)
    cz = dr.maximum(h.z, 1e-6)
    d_h = _ndf(mi.Vector3f(h.x, h.y, cz), sigma, distribution) * cz
    return d_h / (4.0 * dr.maximum(dr.abs(dr.dot(wo, h)), 1e-6))


def sample_glossy(wi, sample2, sigma, distribution="beckmann"):
    """A direction reflected about a half vector from Walter's sampling of D(h) cos(theta_h):
    Beckmann tan^2 delta = -sigma^2 ln(1 - u), GGX sigma^2 u / (1 - u); phi = 2 pi v."""
    s2 = dr.square(dr.maximum(sigma, SIGMA_MIRROR))
    if distribution == "ggx":
        u = dr.minimum(sample2.x, 1.0 - 1e-7)
        tan2 = s2 * u / (1.0 - u)
    else:
        tan2 = -s2 * dr.log(dr.maximum(1.0 - sample2.x, 1e-12))
    cos_h = dr.rsqrt(1.0 + tan2)
    sin_h = dr.safe_sqrt(1.0 - cos_h * cos_h)
    sp, cp = dr.sincos(2.0 * dr.pi * sample2.y)
    return mi.reflect(wi, mi.Vector3f(sin_h * cp, sin_h * sp, cos_h))
