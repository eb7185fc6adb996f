"""The nearest material of another renderer's form to a fitted one, with its error stated.

A fitted material is f_r = rho_d / pi + s lobe(wi, wo; sigma_alpha, normalisation) [sr^-1]
(thesis eq. 3.19's form; the lobe is :func:`~.ward.specular_lobe`).  The forms:

* ``'mitsuba'``: Mitsuba 3's ``blendbsdf`` of a ``diffuse`` (reflectance a) and a
  ``roughconductor`` (beckmann or ggx, alpha, specular_reflectance b, ``material="none"``
  (F = 1) or eta = 1.5, k = 0 (dielectric Fresnel)), weight w: f = (1 - w) a / pi + w b lobe.
  Exact for the microfacet normalisations (:data:`~.microfacet.LOBES`).
* ``'radiance'``: Radiance's ``plastic`` (rho_d = C (1 - spec), rho_s = spec, white) or
  ``metal`` (rho_s = C spec), the ``'balanced'`` lobe with roughness = rms slope.  Exact for
  ``'balanced'`` and ``'radiance'`` when s is grey or proportional to rho_d.
* ``'gltf'``: glTF 2.0 metallic-roughness (:func:`gltf_brdf`) with KHR_materials_specular,
  never exact (height-correlated Smith GGX, Schlick's Fresnel).  The nearest is a dielectric
  whose specularColorFactor 25 s / max(s) makes F0 = F90, so the Fresnel term is constant in
  the channel of max(s); base = rho_d / (1 - specular).  Metallic 1 would lose rho_d.

Error: per RGB channel, |f' - f_r| / max(f_r, :data:`F_FLOOR`) (the reflected radiance's
relative error under a distant light) over :func:`error_pairs` (both directions within
:data:`THETA_MAX`: a 10-degree zenith by 45-degree azimuth grid plus each view's highlight).
``max`` bounds the error of any sky and sun within 80 degrees up to the grid's resolution;
``rms`` is its root mean square; ``albedo_max`` the largest relative error of the directional
albedo at view zeniths 0-80 degrees.  The lobe fit minimises sum ((k lobe' - lobe) / (lobe +
1/pi))^2 over the pairs (k in closed form, roughness by golden section); it depends only on
sigma_alpha and the normalisation, so :func:`nearest_maps` reads it from a table.

Ideal mirrors (sigma_alpha <= :data:`~.ward.SIGMA_MIRROR`) take the forms' mirrors (exact for
Mitsuba's microfacet lobes and ``'radiance'``, never for glTF) with specular reflectance k s,
k = 2 / (min q + max q), q the form's mirror over the fitted one at view zeniths 0-80 degrees.
Their error (:data:`MIRROR_DOMAIN`) is that of the directional albedo at :data:`MIRROR_ZENITHS`.
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import SkyfitError, check_choice, check_range
from .microfacet import (LOBES, albedo_nodes, distribution, half_vector, microfacet_lobe,
                         split)
from .ward import (NORMALISATIONS, RADIANCE_FRESNEL_K, RADIANCE_FRESNEL_MIN, SIGMA_MAX,
                   SIGMA_MIRROR, lobe_albedo_directions, lobe_albedo_nodes, mirror_reflectance,
                   radiance_fresnel, specular_lobe, ward_brdf)

FORMS = ("mitsuba", "radiance", "gltf")
#: The lobes each form can take (a microfacet lobe, ``'balanced'``, ``'gltf'``).
FAMILIES = {"mitsuba": LOBES, "radiance": ("balanced",), "gltf": ("gltf",)}
#: The normalisations each form reproduces exactly (lobe and roughness unchanged).
NATIVE = {"mitsuba": {n: n for n in LOBES}, "radiance": {"balanced": "balanced",
                                                          "radiance": "balanced"}, "gltf": {}}
#: Largest zenith angle of light and view in the error measure [degrees].
THETA_MAX = 80.0
#: Floor of the denominator of the relative error: a 0.3 % grey diffuse's f_r [sr^-1].
F_FLOOR = 1e-3
#: The diffuse level of the lobe fit's relative error (rho_d = s = 1) [sr^-1].
TAU = 1.0 / np.pi
#: glTF's dielectric F0 at ior 1.5 (glTF 2.0 Appendix B) [unitless].
GLTF_F0 = 0.04
#: The sigma_alpha nodes of :func:`nearest_maps`'s table (ratio 1.157) [unitless].
SIGMA_NODES = np.geomspace(SIGMA_MIRROR, SIGMA_MAX, 64)
#: View zeniths [degrees] and half-vector slopes [sigma_alpha] of the error's highlight pairs.
HIGHLIGHT_ZENITHS = (0.0, 20.0, 40.0, 60.0, 70.0, 75.0, 78.0, 80.0)
HIGHLIGHT_U = np.r_[np.arange(0.25, 3.01, 0.25), 3.5, 4.0, 5.0, 6.0]
#: View zeniths of the albedo error [degrees].
ALBEDO_ZENITHS = (0.0, 20.0, 40.0, 60.0, 70.0, 80.0)
DOMAIN = ("f_r per RGB channel relative to max(f_r, 1e-3 sr^-1), light and view within 80 deg of "
          "the normal: 10-deg zenith x 45-deg azimuth grid plus the highlight in steps of "
          "sigma_alpha; albedo at view zeniths 0-80 deg")
#: View zeniths of an ideal mirror's error [degrees] and of its scale fit.
MIRROR_ZENITHS, MIRROR_FIT_ZENITHS = np.linspace(0.0, THETA_MAX, 321), np.linspace(0.0, THETA_MAX, 81)
MIRROR_DOMAIN = ("ideal mirror: directional albedo (diffuse + mirror reflectance) per RGB channel "
                 "relative to max(albedo, pi 1e-3) at view zeniths 0-80 deg by 0.25 deg")
MIRROR_NOTE = "an ideal mirror: the error is that of the mirror's reflectance over view zeniths 0-80 deg"
#: 2 int_0^1 F(mu) mu dmu of Radiance's Fresnel estimate F (:func:`~.ward.radiance_fresnel`):
#: a Lambertian's albedo lost to it at the light's side [unitless].
_RAD_LOSS = 2 * ((1 - np.exp(-5.85) * 6.85) / 5.85 ** 2 - RADIANCE_FRESNEL_K / 2)
_BLOCK = 2000


@dataclass(frozen=True)
class Match:
    """The nearest material of a form: ``params`` ready for the form's file, ``exact`` when it
    reproduces the fitted BRDF, ``error`` (rms, max, albedo_max [unitless], domain, notes)."""
    form: str
    params: dict
    exact: bool
    error: dict


def _dir(theta, phi):
    """Unit vectors at zenith ``theta`` and azimuth ``phi`` [degrees], (..., 3)."""
    t, p = np.radians(theta), np.radians(phi)
    return np.stack(np.broadcast_arrays(np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)), -1)


def error_pairs(sigma_alpha):
    """(wi, wo), each (G, 3), of the error measure at roughness ``sigma_alpha``: zeniths 0-80
    by 10 degrees at relative azimuths 0-180 by 45, and the views at :data:`HIGHLIGHT_ZENITHS`
    with lights reflected about half vectors of slope sigma_alpha :data:`HIGHLIGHT_U` (16
    azimuths), lights beyond 80 degrees moved to 80 (the grazing edge, where errors peak)."""
    t = np.arange(0.0, THETA_MAX + 1, 10.0)
    ti, to, dp = np.meshgrid(t, t, np.arange(0.0, 181, 45.0), indexing="ij")
    wi, wo = _dir(ti.ravel(), 0.0), _dir(to.ravel(), dp.ravel())
    psi = np.arange(16) * np.pi / 8
    a = np.r_[0.0, (sigma_alpha * HIGHLIGHT_U[:, None] * np.cos(psi)).ravel()]
    b = np.r_[0.0, (sigma_alpha * HIGHLIGHT_U[:, None] * np.sin(psi)).ravel()]
    h = np.stack([a, b, np.ones_like(a)], -1) / np.sqrt(1 + a * a + b * b)[:, None]
    v = _dir(np.array(HIGHLIGHT_ZENITHS), 180.0)[:, None, :]
    li = (2 * np.sum(v * h, -1)[..., None] * h - v).reshape(-1, 3)
    zmin = np.cos(np.radians(THETA_MAX))
    low = li[:, 2] < zmin
    li[low] = _dir(THETA_MAX, np.degrees(np.arctan2(li[low, 1], li[low, 0])))
    return np.r_[wi, li], np.r_[wo, np.broadcast_to(v, (len(v), len(h), 3)).reshape(-1, 3)]


def _schlick_w(wi, wo):
    """Schlick's weight (1 - |v.h|)^5 [unitless] (glTF 2.0 Appendix B, "Fresnel")."""
    h = half_vector(wi, wo)
    return (1.0 - np.abs(np.sum(wo * h, -1))) ** 5


def gltf_specular(wi, wo, alpha):
    """glTF's specular_brdf = V D [sr^-1] (glTF 2.0 Appendix B): GGX D of alpha = roughness^2,
    height-correlated Smith V = 1 / (2 (|n.v| sqrt(a^2 + (1 - a^2)(n.l)^2) + |n.l| sqrt(a^2 +
    (1 - a^2)(n.v)^2))); 0 below the surface."""
    wi, wo = np.asarray(wi, dtype=float), np.asarray(wo, dtype=float)
    ci, co = wi[..., 2], wo[..., 2]
    h = half_vector(wi, wo)
    a2 = alpha * alpha
    with np.errstate(divide="ignore", invalid="ignore"):
        v = 0.5 / (co * np.sqrt(a2 + (1 - a2) * ci * ci) + ci * np.sqrt(a2 + (1 - a2) * co * co))
    return np.where((ci > 0) & (co > 0), np.nan_to_num(v * distribution(h[..., 2], alpha, "ggx")), 0.0)


def gltf_brdf(wi, wo, base_color, metallic, roughness, specular=1.0, specular_colour=(1, 1, 1)):
    """f_r [sr^-1], RGB (..., 3), of glTF 2.0's metallic-roughness material (Appendix B:
    mix(dielectric_brdf, metal_brdf, metallic)) with KHR_materials_specular (dielectric_f0 =
    min(0.04 specular_colour, 1) specular, f90 = specular, dielectric_brdf = F V D + (1 -
    max_rgb F) base / pi).  Inputs in [0, 1], except ``specular_colour`` may exceed 1."""
    base, sc = np.asarray(base_color, dtype=float), np.asarray(specular_colour, dtype=float)
    m, lobe = np.asarray(metallic, dtype=float)[..., None], gltf_specular(wi, wo, roughness**2)[..., None]
    w = _schlick_w(np.asarray(wi, dtype=float), np.asarray(wo, dtype=float))[..., None]
    f0 = np.minimum(GLTF_F0 * sc, 1.0) * np.asarray(specular)[..., None]
    fd = f0 + (np.asarray(specular)[..., None] - f0) * w
    up = ((np.asarray(wi)[..., 2] > 0) & (np.asarray(wo)[..., 2] > 0))[..., None]
    dielectric = fd * lobe + (1 - np.max(fd, -1, keepdims=True)) * base / np.pi * up
    metal = (base + (1 - base) * w) * lobe
    return (1 - m) * dielectric + m * metal


def _family_lobe(family, wi, wo, alpha):
    """A form's lobe without its reflectance [sr^-1]: glTF's V D, Radiance's balanced Ward
    lobe, or a microfacet lobe."""
    if family == "gltf":
        return gltf_specular(wi, wo, alpha)
    if family == "balanced":
        return specular_lobe(wi, wo, alpha, "balanced")
    return microfacet_lobe(wi, wo, alpha, family)


def _fit_lobe(sigma, normalisation, family):
    """(alpha, k, cost): the roughness alpha and scale k with k lobe'(alpha) nearest to the
    lobe of ``normalisation`` at ``sigma`` over :func:`error_pairs` (module docstring)."""
    wi, wo = error_pairs(sigma)
    lobe = specular_lobe(wi, wo, sigma, normalisation)
    wt = 1.0 / (lobe + TAU) ** 2

    def cost(x):
        lp = _family_lobe(family, wi, wo, np.exp(x))
        k = np.sum(wt * lp * lobe) / max(np.sum(wt * lp * lp), 1e-300)
        return np.sum(wt * (k * lp - lobe) ** 2), k

    lo = max(np.log(sigma) - 1.6, np.log(1.01 * SIGMA_MIRROR))
    hi = min(np.log(sigma) + 1.6, 0.0 if family == "gltf" else np.log(2.0))
    xs = np.linspace(lo, hi, 9)
    j = int(np.argmin([cost(x)[0] for x in xs]))
    a, b = xs[max(j - 1, 0)], xs[min(j + 1, 8)]
    g = (np.sqrt(5) - 1) / 2
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = cost(c)[0], cost(d)[0]
    for _ in range(20):                                  # golden section on [a, b]
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = cost(c)[0]
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = cost(d)[0]
    c, k = cost(0.5 * (a + b))
    return np.exp(0.5 * (a + b)), k, c


@lru_cache(maxsize=None)
def _table(normalisation, family):
    """:func:`_fit_lobe` at every :data:`SIGMA_NODES`, (K, 3) read-only."""
    t = np.array([_fit_lobe(s, normalisation, family) for s in SIGMA_NODES])
    t.setflags(write=False)
    return t


def _albedo_nodes(family):
    """Fine nodes of the albedo quadrature of a lobe (GGX's long tails, Ward's and Beckmann's)."""
    ggx = family == "gltf" or (family in LOBES and split(family)[0] == "ggx")
    return albedo_nodes(32, 24) if ggx else lobe_albedo_nodes(8, 24)


def _albedos(fn, alpha, family):
    """Directional albedo [unitless] of the lobe fn(wi, wo) of roughness alpha at the views
    of :data:`ALBEDO_ZENITHS` (:func:`~.ward.lobe_albedo_directions` quadrature), (6,)."""
    v = _dir(np.array(ALBEDO_ZENITHS), 180.0)
    wi, wt = lobe_albedo_directions(v, alpha, _albedo_nodes(family))
    return np.sum(fn(wi, np.broadcast_to(v[:, None], wi.shape)) * np.clip(wi[..., 2], 0, None) * wt, -1)


def _reflectances(form, family, rho_d, s, alpha, k):
    """The form's parameters for texels (rho_d, s (N, 3); alpha, k (N,) of the lobe fit),
    notes, and the effective BRDF f' = D / pi + (A + B w) lobe' (w Schlick's weight) as
    (D, A, B), each (N, 3).  One distribution, Fresnel, weight or type for all texels."""
    ks, notes = _ks(k, s), []
    zero = np.zeros_like(s)
    if form == "mitsuba":
        md, ms = float(np.max(rho_d)), float(np.max(ks))
        w = ms / (md + ms) if md + ms > 0 else 0.5
        if md + ms > 1 + 1e-9:
            notes.append(f"max(rho_d) + max(k s) = {md + ms:.4g} > 1: the diffuse and specular "
                         "reflectances exceed 1 by that factor (their blend is the fit)")
        dist, fr = split(family)
        p = {"distribution": dist, "alpha": alpha,
             "material": "none" if fr == "metal" else {"eta": 1.5, "k": 0},
             "diffuse_reflectance": rho_d / (1 - w) if w < 1 else zero,
             "specular_reflectance": ks / w if w > 0 else zero, "weight": w}
        return p, notes, (rho_d, ks, zero)
    if form == "radiance":
        spec_p = np.mean(ks, -1)
        c_m = rho_d + ks
        tot = np.sum(c_m, -1)
        spec_m = np.divide(np.sum(ks, -1), tot, out=np.zeros_like(tot), where=tot > 0)
        miss_p = np.sum(np.abs(ks - spec_p[:, None]))
        miss_m = np.sum(np.abs(c_m * spec_m[:, None] - ks) + np.abs(c_m * (1 - spec_m[:, None]) - rho_d))
        metal = miss_m < miss_p
        spec = spec_m if metal else spec_p
        c = c_m if metal else rho_d / np.maximum(1 - spec_p[:, None], 1e-12)
        if np.max(c) > 1 + 1e-9 or np.max(spec) > 1:
            notes.append(f"Radiance colour up to {np.max(c):.4g}, spec up to {np.max(spec):.4g}: "
                         "above 1 (rho_d + k s > 1)")
        p = {"type": "metal" if metal else "plastic", "colour": c, "spec": spec, "roughness": alpha}
        sp = c * spec[:, None] if metal else np.broadcast_to(spec[:, None], c.shape)
        return p, notes, (c * (1 - spec[:, None]), sp, zero)
    m = np.max(ks, -1)
    spec = np.minimum(m, 1.0)
    sc = np.divide(ks, GLTF_F0 * m[:, None], out=np.ones_like(ks), where=m[:, None] > 0)
    base = np.divide(rho_d, 1 - spec[:, None], out=np.ones_like(ks), where=spec[:, None] < 1)
    if np.max(m) > 1 or np.max(base) > 1 + 1e-9:
        notes.append(f"glTF base colour {np.max(base):.4g} or specular {np.max(m):.4g} above 1, "
                     "clipped to 1 (rho_d + k max(s) > 1)")
    base = np.minimum(base, 1.0)
    f0 = np.minimum(GLTF_F0 * sc, 1.0) * spec[:, None]
    p = {"baseColorFactor": np.c_[base, np.ones(len(base))], "metallicFactor": np.zeros(len(base)),
         "roughnessFactor": np.sqrt(alpha),
         "KHR_materials_specular": {"specularFactor": spec, "specularColorFactor": sc}}
    return p, notes, ((1 - spec[:, None]) * base, f0, spec[:, None] - f0)


def _ks(k, s):
    """k s (N, 3) for a scale k (N,) or per channel (N, 3)."""
    return np.reshape(k, (len(s), -1)) * s


def form_brdf(form, params, wi, wo):
    """f_r [sr^-1], RGB (..., 3), of one material of ``form`` with ``params`` as :func:`nearest`
    returns them, at light ``wi`` and view ``wo`` (unit vectors, normal +Z).  A mirror's delta
    is left out."""
    check_choice("material form", form, FORMS)
    wi, wo = np.asarray(wi, dtype=float), np.asarray(wo, dtype=float)
    if form == "mitsuba":
        name = f"{params['distribution']}_{'metal' if params['material'] == 'none' else 'plastic'}"
        w, up = params["weight"], ((wi[..., 2] > 0) & (wo[..., 2] > 0))[..., None]
        lobe = 0.0 if name.startswith("mirror") else microfacet_lobe(wi, wo, params["alpha"], name)
        return (1 - w) * np.asarray(params["diffuse_reflectance"]) / np.pi * up \
            + w * np.asarray(params["specular_reflectance"]) * np.asarray(lobe)[..., None]
    if form == "radiance":
        c, spec = np.asarray(params["colour"], dtype=float), params["spec"]
        rho_s = c * spec if params["type"] == "metal" else np.full(3, spec)
        return ward_brdf(wi, wo, c * (1 - spec), rho_s, params["roughness"], "radiance", spec)
    ext = params["KHR_materials_specular"]
    return gltf_brdf(wi, wo, params["baseColorFactor"][:3], params["metallicFactor"],
                     params["roughnessFactor"], ext["specularFactor"], ext["specularColorFactor"])


def _check(form, rho_d, s, sigma_alpha, normalisation):
    """Validated (rho_d, s (N, 3), sigma (N,)) or SkyfitError."""
    check_choice("material form", form, FORMS)
    check_choice("normalisation", normalisation, NORMALISATIONS)
    d, sp = np.asarray(rho_d, dtype=float), np.asarray(s, dtype=float)
    sig = np.asarray(sigma_alpha, dtype=float)
    if d.shape != sp.shape or d.shape[-1:] != (3,) or d.shape[:-1] != sig.shape:
        raise SkyfitError(f"rho_d {d.shape}, s {sp.shape} and sigma_alpha {sig.shape} do not "
                          "match: give RGB triples (N, 3), (N, 3) and N roughnesses.")
    check_range("rho_d", d, 0.0, 1.0)
    check_range("s", sp, 0.0, 1.0)
    check_range("sigma_alpha", sig, 0.0, SIGMA_MAX)
    return d.reshape(-1, 3), sp.reshape(-1, 3), sig.reshape(-1)


def _errors(rel, alb, alb_ref):
    """rms, max of the relative errors ``rel`` (..., G, 3), albedo_max of albedos (..., 6, 3)."""
    a = np.abs(alb - alb_ref) / np.maximum(alb_ref, np.pi * F_FLOOR)
    return (np.sqrt(np.mean(rel ** 2, axis=(-2, -1))), np.max(rel, axis=(-2, -1)),
            np.max(a, axis=(-2, -1)))


def _lobe_albedos(form, family, normalisation, sigma, alpha):
    """Albedos (6,) of the fitted lobe, the form's lobe, and the form's lobe times Schlick's
    weight."""
    exact = _albedos(lambda i, o: specular_lobe(i, o, sigma, normalisation), sigma, normalisation)
    other = _albedos(lambda i, o: _family_lobe(family, i, o, alpha), alpha, family)
    w = _albedos(lambda i, o: _schlick_w(i, o) * _family_lobe(family, i, o, alpha), alpha, family) \
        if form == "gltf" else np.zeros(6)
    return exact, other, w


def _choose(form, normalisation, rho_d, s, fits):
    """The family of ``form`` for these texels: the native lobe, else the least lobe-fit cost
    (``fits``: family -> (alpha, k, cost)), preferring those with max(rho_d) + max(k s) <= 1."""
    if normalisation in NATIVE[form]:
        return NATIVE[form][normalisation]
    fams = FAMILIES[form]
    ok = [f for f in fams if np.max(rho_d) + np.max(_ks(fits[f][1], s)) <= 1 + 1e-9]
    return min(ok or fams, key=lambda f: np.sum(fits[f][2]))


def _mirror_albedo(name, fr, d, a, b, c):
    """Directional albedo (N, Z, 3) at view cosines c (Z,) of a diffuse d (N, 3) and a mirror
    a P(c) + b (1 - c)^5 (P: :func:`~.ward.mirror_reflectance`; b glTF's Schlick rise), with
    Radiance's Fresnel estimate F where fr (N,) is 1 (mirror a + F (1 - a), diffuse
    d (1 - F(c)) (1 - :data:`_RAD_LOSS`))."""
    f = fr[:, None, None] * radiance_fresnel(c)[:, None]
    return d[:, None] * (1 - f) * (1 - _RAD_LOSS * fr[:, None, None]) + f * (1 - a[:, None]) \
        + a[:, None] * mirror_reflectance(c, name)[:, None] + b[:, None] * ((1 - c) ** 5)[:, None]


def _fitted_mirror(normalisation, d, s, c):
    """The fitted mirror's albedo (N, Z, 3), with Radiance's estimate where max(s) reaches its
    threshold."""
    fr = (np.max(s, -1) >= RADIANCE_FRESNEL_MIN) * float(normalisation == "radiance")
    return _mirror_albedo(normalisation, fr, d, s, np.zeros_like(s), c)


def _mirror_k(form, family, normalisation, s):
    """The scale k (N, 3) of a mirror's k s and its max relative error (N,) over
    :data:`MIRROR_FIT_ZENITHS` (module docstring), in blocks of texels."""
    c, k, e = np.cos(np.radians(MIRROR_FIT_ZENITHS)), np.ones_like(s), np.zeros(len(s))
    for b in range(0, len(s), _BLOCK):
        sb = s[b:b + _BLOCK]
        m = _fitted_mirror("balanced" if form == "radiance" and normalisation == "radiance"
                           else normalisation, np.zeros_like(sb), sb, c)
        q = sb[:, None] * mirror_reflectance(c, family if form == "mitsuba" else "balanced")[:, None] \
            / np.where(m > 0, m, 1.0)
        lo, hi = np.min(q, 1), np.max(q, 1)
        k[b:b + _BLOCK] = np.where(hi > 0, 2 / np.where(hi > 0, lo + hi, 1), 1.0)
        e[b:b + _BLOCK] = np.max(np.where(hi > 0, (hi - lo) / np.where(hi > 0, lo + hi, 1), 0), -1)
    return k, e


def _mirror_errors(form, family, normalisation, d, s, eff, spec):
    """rms, max, albedo_max (N,) of mirrors: the relative error of the form's albedo (eff =
    (D, A, B) of _reflectances; ``spec`` Radiance's) against the fitted one at MIRROR_ZENITHS."""
    c, out = np.cos(np.radians(MIRROR_ZENITHS)), np.zeros((3, len(d)))
    fr = np.asarray(spec) >= RADIANCE_FRESNEL_MIN if form == "radiance" else np.zeros(len(d))
    for b in range(0, len(d), _BLOCK):
        sl = slice(b, b + _BLOCK)
        ref = _fitted_mirror(normalisation, d[sl], s[sl], c)
        alb = _mirror_albedo(family if form == "mitsuba" else "balanced", fr[sl] * 1.0,
                             *(e[sl] for e in eff), c)
        rel = np.abs(alb - ref) / np.maximum(ref, np.pi * F_FLOOR)
        out[0, sl], out[1, sl] = np.sqrt(np.mean(rel ** 2, axis=(-2, -1))), np.max(rel, axis=(-2, -1))
    out[2] = out[1]
    return out


def nearest(form, rho_d, s, sigma_alpha, normalisation="ward"):
    """The nearest material (:class:`Match`) of ``form`` to f_r = rho_d / pi + s
    lobe(sigma_alpha, normalisation) [sr^-1], and its error (module docstring).

    Parameters
    ----------
    form : {'mitsuba', 'radiance', 'gltf'}
    rho_d, s : RGB triples, diffuse and specular reflectance [unitless, 0-1]
    sigma_alpha : float, roughness (rms slope) [unitless, 0-1; <= SIGMA_MIRROR an ideal mirror]
    normalisation : one of :data:`~.ward.NORMALISATIONS`
    """
    d, sp, sig = _check(form, rho_d, s, np.reshape(sigma_alpha, ()), normalisation) \
        if np.ndim(sigma_alpha) == 0 else _check(form, rho_d, s, sigma_alpha, normalisation)
    sigma = float(sig[0])
    if sigma <= SIGMA_MIRROR:                            # no lobe fit: nearest_maps's path
        p, e = nearest_maps(form, d, sp, sig, normalisation)
        return Match(form, _plain(p), e.pop("exact"),
                     {k: float(v[0]) if isinstance(v, np.ndarray) else v for k, v in e.items()})
    if normalisation in NATIVE[form]:
        fits = {NATIVE[form][normalisation]: (np.array([sigma]), np.ones(1), np.zeros(1))}
    else:
        fits = {f: tuple(np.array([v]) for v in _fit_lobe(sigma, normalisation, f))
                for f in FAMILIES[form]}
    family = _choose(form, normalisation, d, sp, fits)
    p, notes, (dd, aa, bb) = _reflectances(form, family, d, sp, *fits[family][:2])
    params = _plain(p)
    exact = normalisation in NATIVE[form] and np.allclose(dd, d, atol=1e-12) \
        and np.allclose(aa, sp, atol=1e-12)
    if exact:
        return Match(form, params, True, {"rms": 0.0, "max": 0.0, "albedo_max": 0.0,
                                          "domain": DOMAIN, "notes": tuple(notes)})
    wi, wo = error_pairs(sigma)
    f = ward_brdf(wi, wo, d[0], sp[0], sigma, normalisation)
    rel = np.abs(form_brdf(form, params, wi, wo) - f) / np.maximum(f, F_FLOOR)
    ex, other, w = _lobe_albedos(form, family, normalisation, sigma, fits[family][0][0])
    alb = dd + aa * other[:, None] + bb * w[:, None]
    rms, mx, am = _errors(rel, alb, d + sp * ex[:, None])
    return Match(form, params, False, {"rms": float(rms), "max": float(mx), "albedo_max": float(am),
                                       "domain": DOMAIN, "notes": tuple(notes)})


def _plain(p):
    """One texel's parameters as Python floats and lists (JSON and XML ready)."""
    if isinstance(p, dict):
        return {k: _plain(v) for k, v in p.items()}
    if isinstance(p, np.ndarray):
        return [float(x) for x in p[0]] if p.ndim == 2 else float(p[0])
    return p


@lru_cache(maxsize=None)
def _node_tables(form, family, normalisation, j):
    """At SIGMA_NODES[j], from the table's fit: the pairs' features (G, 3) (exact lobe, form
    lobe, form lobe times Schlick's weight), the indices of the pairs on their convex hull
    (where any texel's largest relative error lies, a ratio of affine functions of the
    features) and of every 12th pair (for the rms), and :func:`_lobe_albedos`."""
    from scipy.spatial import ConvexHull, QhullError

    sigma, (alpha, _, _) = SIGMA_NODES[j], _table(normalisation, family)[j]
    wi, wo = error_pairs(sigma)
    other = _family_lobe(family, wi, wo, alpha)
    feat = np.stack([specular_lobe(wi, wo, sigma, normalisation), other,
                     _schlick_w(wi, wo) * other], -1)
    cols = feat if form == "gltf" else feat[:, :2]
    try:
        hull = ConvexHull(cols / np.maximum(cols.max(0), 1e-300)).vertices
    except QhullError:                                   # degenerate: every pair
        hull = np.arange(len(feat))
    return feat, np.sort(hull), np.arange(0, len(feat), 12), \
        _lobe_albedos(form, family, normalisation, sigma, alpha)


def _map_errors(d, s, eff, feat, pick):
    """Relative errors (n, P, 3) of texels (rho_d, s, eff = (D, A, B) as from _reflectances)
    at the pairs ``pick`` of the node's features."""
    lobe, other, wother = (feat[pick, i][:, None] for i in range(3))
    f = d[:, None] / np.pi + s[:, None] * lobe
    g = eff[0][:, None] / np.pi + eff[1][:, None] * other + eff[2][:, None] * wother
    return np.abs(g - f) / np.maximum(f, F_FLOOR)


def nearest_maps(form, rho_d, s, sigma_alpha, normalisation="ward"):
    """:func:`nearest` for a map's texels: rho_d, s (N, 3), sigma_alpha (N,).

    The lobe fit is interpolated in log sigma from the :data:`SIGMA_NODES` table; one
    distribution, Fresnel, type and weight serve the whole map (chosen by its rough texels).
    Returns (params, error): params as :func:`nearest`'s, texel-varying entries (N,) or (N, 3)
    (``baseColorFactor`` (N, 4)); error {"rms", "max", "albedo_max"} (N,), "domain", "notes",
    "exact".  A rough texel's error is that at its nearest node (max over the convex-hull
    pairs, rms over every 12th); a mirror's as :func:`nearest`'s.
    """
    d, sp, sig = _check(form, rho_d, s, sigma_alpha, normalisation)
    n, mir = len(sig), sig <= SIGMA_MIRROR
    rough, native = ~mir, normalisation in NATIVE[form]
    xr, xs = np.log(sig[rough]), np.log(SIGMA_NODES)
    fits = {}
    for fam in ([NATIVE[form][normalisation]] if native else FAMILIES[form]):
        alpha, k, cost = np.zeros(n), np.ones((n, 3)), np.zeros(n)
        if native:
            alpha[rough] = sig[rough]
        elif rough.any():
            t = _table(normalisation, fam)
            alpha[rough] = np.maximum(np.exp(np.interp(xr, xs, np.log(t[:, 0]))), 1.01 * SIGMA_MIRROR)
            k[rough], cost[rough] = np.interp(xr, xs, t[:, 1])[:, None], np.interp(xr, xs, t[:, 2])
        k[mir], cost[mir] = _mirror_k(form, fam, normalisation, sp[mir])
        fits[fam] = (alpha, k, cost)
    sel = rough if rough.any() else mir
    family = _choose(form, normalisation, d[sel], sp[sel], {f: tuple(v[sel] for v in fit)
                                                            for f, fit in fits.items()})
    params, notes, (dd, aa, bb) = _reflectances(form, family, d, sp, *fits[family][:2])
    err = {k: np.zeros(n) for k in ("rms", "max", "albedo_max")}
    exact = not rough.any() or native and np.allclose(dd[rough], d[rough], atol=1e-12) \
        and np.allclose(aa[rough], sp[rough], atol=1e-12)
    if not exact:
        node = np.clip(np.rint((xr - xs[0]) / (xs[1] - xs[0])), 0, len(SIGMA_NODES) - 1)
        for j in np.unique(node).astype(int):
            idx = np.flatnonzero(rough)[node == j]
            t = _table(normalisation, family)[j]
            _, _, eff = _reflectances(form, family, d[idx], sp[idx], np.full(len(idx), t[0]),
                                      np.full(len(idx), t[1]))
            feat, hull, every, (ex, oth, wal) = _node_tables(form, family, normalisation, j)
            floored = np.min(d[idx], -1) < np.pi * F_FLOOR      # the floor may hold the max
            for c in range(0, len(idx), 20000):
                sl, ti = slice(c, c + 20000), idx[c:c + 20000]
                ef = tuple(e[sl] for e in eff)
                mx = np.max(_map_errors(d[ti], sp[ti], ef, feat, hull), axis=(-2, -1))
                rms = np.sqrt(np.mean(_map_errors(d[ti], sp[ti], ef, feat, every) ** 2, axis=(-2, -1)))
                alb = ef[0][:, None] + ef[1][:, None] * oth[:, None] + ef[2][:, None] * wal[:, None]
                _, _, am = _errors(np.zeros((1, 1)), alb, d[ti][:, None] + sp[ti][:, None] * ex[:, None])
                err["max"][ti], err["rms"][ti], err["albedo_max"][ti] = mx, rms, am
            for i in idx[floored]:
                k = np.flatnonzero(idx == i)
                err["max"][i] = np.max(_map_errors(d[[i]], sp[[i]], tuple(e[k] for e in eff), feat,
                                                   slice(None)))
    domain = DOMAIN
    if mir.any():
        e = _mirror_errors(form, family, normalisation, d[mir], sp[mir],
                           (dd[mir], aa[mir], bb[mir]), params.get("spec", np.zeros(n))[mir])
        exact = exact and form != "gltf" and np.max(e[1]) <= 1e-12
        err["rms"][mir], err["max"][mir], err["albedo_max"][mir] = (0 * e if exact else e)
        notes.append(MIRROR_NOTE)
        domain = MIRROR_DOMAIN if not rough.any() else f"{DOMAIN}; {MIRROR_DOMAIN}"
        if form == "gltf":
            notes.append("roughness 0: glTF renderers clamp it to a small value (a near-mirror)")
        elif form == "mitsuba" and rough.any():
            notes.append("mirror texels have alpha 0 in the map's roughconductor (a near-mirror)")
        elif form == "mitsuba":
            params["distribution"] = "mirror"
    err.update(domain=domain, notes=tuple(notes), exact=bool(exact))
    return params, err
