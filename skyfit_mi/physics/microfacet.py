"""Microfacet specular lobes (Beckmann and GGX with Smith shadowing and Fresnel), NumPy reference.

The fitting model f_r = rho_d / pi + s lobe(wi, wo; alpha) is linear in the reflectances and
non-linear in one roughness (thesis eq. 3.19's form).  Besides Ward's lobes (:mod:`.ward`), the
lobe can be a Cook-Torrance microfacet lobe (B. Walter, S. Marschner, H. Li, K. Torrance,
"Microfacet models for refraction through rough surfaces", EGSR 2007, eqs. 20, 33, 27, 34):

    lobe = F(wi.h) D(h) G1(wi) G1(wo) / (4 cos_i cos_o)            [sr^-1]

with h the half vector, D the normal distribution of roughness alpha (Beckmann:
exp(-tan^2 theta_h / alpha^2) / (pi alpha^2 cos^4 theta_h), alpha the rms slope, as Ward's
sigma_alpha; GGX: alpha^2 / (pi cos^4 theta_h (alpha^2 + tan^2 theta_h)^2)), G1 Smith's
separable shadowing (Walter's rational approximation for Beckmann, exact for GGX), and F:

* ``plastic``: dielectric Fresnel at index ETA_PLASTIC, the lobe of Mitsuba 3's
  ``roughplastic`` without its diffuse part, which here is Lambertian rho_d / pi (roughplastic's
  Fresnel-weighted base is not linear in one diffuse basis);
* ``metal``: F = 1 (``roughconductor`` with ``material="none"``); s is the specular colour.

These match Mitsuba 3.9's ``MicrofacetDistribution`` and ``fresnel``.  Each lobe is a
``normalisation`` (:data:`LOBES`: ``<distribution>_<fresnel>``).  Below
:data:`~.ward.SIGMA_MIRROR` the lobe is an ideal mirror reflecting s F(cos_o).
"""

import numpy as np

#: The microfacet distributions, Fresnel terms and their lobes (``normalisation`` names).
DISTRIBUTIONS = ("beckmann", "ggx")
FRESNELS = ("plastic", "metal")
LOBES = tuple(f"{d}_{f}" for d in DISTRIBUTIONS for f in FRESNELS)
#: The plastic coating's refractive index (to air) [unitless]: Mitsuba's ``roughplastic`` default.
ETA_PLASTIC = 1.5


def split(name):
    """(distribution, fresnel) of the lobe ``name`` (one of LOBES)."""
    return tuple(name.split("_"))


def fresnel_dielectric(cos_theta, eta=ETA_PLASTIC):
    """Unpolarised Fresnel reflectance [unitless] of a dielectric interface of relative index
    ``eta`` at incident cosine ``cos_theta`` (outside, >= 0): the mean of s and p (Born and
    Wolf, Principles of Optics, eq. 1.5.21)."""
    c = np.clip(np.abs(np.asarray(cos_theta, dtype=float)), 0.0, 1.0)
    s2 = (1.0 - c * c) / (eta * eta)                   # sin^2 of the transmitted angle
    ct = np.sqrt(np.maximum(1.0 - s2, 0.0))
    rs = (c - eta * ct) / (c + eta * ct)
    rp = (eta * c - ct) / (eta * c + ct)
    return 0.5 * (rs * rs + rp * rp)


def fresnel(cos_theta, kind):
    """F of the lobe's ``kind`` (FRESNELS) at cosine ``cos_theta`` [unitless]."""
    if kind == "plastic":
        return fresnel_dielectric(cos_theta)
    return np.ones_like(np.asarray(cos_theta, dtype=float))


def distribution(cos_h, alpha, kind):
    """The normal distribution D(h) [sr^-1] of microfacet normals at cos theta_h ``cos_h``
    (Walter et al. eqs. 25 and 33), roughness ``alpha`` [unitless]."""
    c2 = np.asarray(cos_h, dtype=float) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        tan2 = (1.0 - c2) / c2
        a2 = alpha * alpha
        if kind == "beckmann":
            d = np.exp(-tan2 / a2) / (np.pi * a2 * c2 * c2)
        else:
            d = a2 / (np.pi * c2 * c2 * (a2 + tan2) ** 2)
    return np.where(c2 > 0, np.nan_to_num(d), 0.0)


def smith_g1(cos_v, alpha, kind):
    """Smith's shadowing of a direction at cosine ``cos_v`` with the normal (Walter et al.
    eq. 27 with its rational approximation for Beckmann, eq. 34 for GGX) [unitless]."""
    c = np.asarray(cos_v, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        tan2 = alpha * alpha * (1.0 - c * c) / (c * c)          # (alpha tan theta)^2
        if kind == "beckmann":
            a = 1.0 / np.sqrt(tan2)
            g = np.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a)
                         / (1.0 + 2.276 * a + 2.577 * a * a))
        else:
            g = 2.0 / (1.0 + np.sqrt(1.0 + tan2))
    return np.where(c >= 1.0, 1.0, np.where(c > 0, np.nan_to_num(g), 0.0))


def half_vector(wi, wo):
    """The unit half vector (wi + wo) / |wi + wo| (..., 3) of unit directions ``wi``, ``wo``."""
    h = np.asarray(wi, dtype=float) + np.asarray(wo, dtype=float)
    return h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)


def microfacet_lobe(wi, wo, alpha, name):
    """The lobe ``name`` without s [sr^-1]: F(wi.h) D(h) G1(wi) G1(wo) / (4 cos_i cos_o); 0
    where either local unit direction (both away from the surface) is below it."""
    dist, kind = split(name)
    wi, wo = np.asarray(wi, dtype=float), np.asarray(wo, dtype=float)
    ci, co = wi[..., 2], wo[..., 2]
    up = (ci > 0) & (co > 0)
    h = half_vector(wi, wo)
    ih = np.sum(wi * h, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = fresnel(ih, kind) * distribution(h[..., 2], alpha, dist) \
            * smith_g1(ci, alpha, dist) * smith_g1(co, alpha, dist) / (4.0 * ci * co)
    return np.where(up, np.nan_to_num(f), 0.0)


def mirror_fraction(cos_theta, name):
    """Fraction of s that the alpha -> 0 lobe ``name`` reflects at the view's cosine
    ``cos_theta``: F(cos_theta) (G1 -> 1 and D -> a delta of unit projected area)."""
    c = np.clip(np.asarray(cos_theta, dtype=float), 0.0, 1.0)
    return fresnel(c, split(name)[1])


def albedo_nodes(n_u=16, n_phi=6):
    """Nodes (a, b, c) of a microfacet lobe's albedo quadrature per unit alpha, as
    :func:`~.ward.lobe_albedo_nodes`: node j's half vector is normalise(alpha a_j, alpha b_j, 1),
    its weight c_j 2 alpha^2 (wo.h) cos^3 theta_h.

    Gauss-Legendre in t = alpha^2 / (alpha^2 + tan^2 theta_h), in which GGX's D cos^4 theta_h
    times the slope area is constant (its tails are too long for Gauss-Laguerre), by the
    trapezoid rule in azimuth.  The horizon cuts the tails: accurate to about 3e-5-4e-3 up to
    70 degrees (Beckmann takes Ward's nodes).
    """
    x, w = np.polynomial.legendre.leggauss(int(n_u))
    t, wt = 0.5 * (x + 1.0), 0.5 * w
    phi = (np.arange(int(n_phi)) + 0.5) * 2 * np.pi / int(n_phi)
    r = np.sqrt((1.0 - t) / t)[:, None]                 # tan theta_h / alpha
    a, b = r * np.cos(phi), r * np.sin(phi)
    # d(slope area) = r dr dphi = alpha^2 dt / (2 t^2) dphi; the weight's form takes alpha^2 / 2
    c = np.broadcast_to((wt / (t * t))[:, None] * (2 * np.pi / int(n_phi)), a.shape)
    return a.ravel(), b.ravel(), c.ravel()
