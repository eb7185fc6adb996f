"""The microfacet lobes (GGX and Beckmann, plastic and metal) of the ``ward`` plugin against
Mitsuba's own ``roughplastic`` and ``roughconductor``, the NumPy reference, their mirror limit,
sampling and albedo quadrature."""
import numpy as np
import pytest

from skyfit_mi.physics import microfacet as mf
from skyfit_mi.physics import ward as ref
from test_plugin_ward import hemisphere, local_si, plugin_brdf

ALPHAS = (0.005, 0.02, 0.1, 0.3, 0.5)


def mitsuba_lobe(mi, name, alpha):
    """Mitsuba's own BSDF whose glossy lobe is ``name``'s with s = 1."""
    dist, kind = mf.split(name)
    if kind == "plastic":
        return mi.load_dict({"type": "roughplastic", "distribution": dist, "alpha": alpha,
                             "int_ior": mf.ETA_PLASTIC, "ext_ior": 1.0,
                             "diffuse_reflectance": 0.0})
    return mi.load_dict({"type": "roughconductor", "distribution": dist, "alpha": alpha,
                         "material": "none"})


@pytest.mark.parametrize("name", mf.LOBES)
def test_lobe_equals_mitsubas_bsdf_and_the_numpy_reference(mi, name):
    """f_r [sr^-1] of the plugin with rho_d = 0, rho_s = 1 against Mitsuba's BSDF at 4,000
    pairs of directions per roughness, half of them near the mirror direction (2e-6 apart in
    single precision), and the NumPy reference (5e-4: the float32 directions in the exponent)."""
    wi = hemisphere(4000, 21)
    rng = np.random.default_rng(22)
    for alpha in ALPHAS:
        wo = hemisphere(4000, 22)
        near = wi[:2000] * [-1, -1, 1] + rng.normal(scale=2 * alpha, size=(2000, 3))
        near[:, 2] = np.abs(near[:, 2]) + 1e-3
        wo[:2000] = near / np.linalg.norm(near, axis=1, keepdims=True)
        ours = mi.load_dict({"type": "ward", "model": "raw", "rho_d": 0.0, "rho_s": 1.0,
                             "sigma_alpha": alpha, "normalisation": name})
        got = plugin_brdf(mi, ours, wi, wo)[:, 0]
        theirs = plugin_brdf(mi, mitsuba_lobe(mi, name, alpha), wi, wo)[:, 0]
        np.testing.assert_allclose(got, theirs, rtol=2e-5, atol=1e-6 * theirs.max())
        np.testing.assert_allclose(got, ref.specular_lobe(wi, wo, alpha, name), rtol=5e-4,
                                   atol=1e-6 * theirs.max())
        assert theirs.max() > 1.0                  # the pairs reach the lobe's peak


def test_the_fresnel_terms_by_hand():
    """Dielectric Fresnel at eta = 1.5: 0.04 at normal incidence, 1 at grazing, zero for p
    polarisation at Brewster's angle (so half of s's there); the metal's F is 1."""
    assert mf.fresnel_dielectric(1.0) == pytest.approx(0.04)
    assert mf.fresnel_dielectric(0.0) == pytest.approx(1.0)
    c = np.cos(np.arctan(1.5))
    ct = np.sqrt(1 - (1 - c * c) / 2.25)
    assert mf.fresnel_dielectric(c) == pytest.approx(0.5 * ((c - 1.5 * ct) / (c + 1.5 * ct)) ** 2)
    np.testing.assert_array_equal(mf.fresnel([0.1, 0.9], "metal"), 1.0)


@pytest.mark.parametrize("name", mf.LOBES)
def test_the_mirror_reflects_rho_s_times_fresnel(mi, name):
    """sigma_alpha = 0: the delta lobe's sampled reflectance is rho_s F(cos_o)."""
    import drjit as dr
    wi = hemisphere(200, 23)
    b = mi.load_dict({"type": "ward", "model": "raw", "rho_d": 0.0, "rho_s": 0.8,
                      "sigma_alpha": 0.0, "normalisation": name})
    bs, w = b.sample(mi.BSDFContext(), local_si(mi, wi), mi.Float(0.5), mi.Point2f(0.3, 0.6))
    assert dr.all(mi.has_flag(bs.sampled_type, mi.BSDFFlags.DeltaReflection))
    np.testing.assert_allclose(np.array(w)[0] * np.array(bs.pdf),
                               0.8 * ref.mirror_reflectance(wi[:, 2], name), rtol=2e-5)


@pytest.mark.parametrize("alpha", [0.02, 0.1, 0.4])
@pytest.mark.parametrize("theta_i", [10.0, 60.0])
@pytest.mark.parametrize("name", ["ggx_plastic", "beckmann_metal"])
def test_chi2_sampling(mi, alpha, theta_i, name):
    from test_plugin_ward import assert_samples_its_pdf

    assert_samples_its_pdf(alpha, theta_i, name)


ALBEDO_CASES = [(n, a) for n in mf.LOBES for a in (0.005, 0.02, 0.05)]
FAST_ALBEDO = {("ggx_plastic", 0.05), ("ggx_metal", 0.02), ("beckmann_plastic", 0.05)}


@pytest.mark.parametrize("name, alpha", [
    c if c in FAST_ALBEDO else pytest.param(*c, marks=pytest.mark.slow) for c in ALBEDO_CASES])
def test_albedo_quadrature_against_brute_force(name, alpha):
    """The lobe's directional albedo by its few-node quadrature (the light cache's control
    variate, alpha up to 0.05) against a fine quadrature over the half vector's slope:
    Beckmann's (Ward's nodes) to 1e-5, GGX's (its tails cut by the horizon) to 5e-3."""
    views = np.radians([0.0, 30.0, 60.0, 70.0])
    tol = 1e-5 if mf.split(name)[0] == "beckmann" else 5e-3
    wo = np.stack([np.sin(views), 0 * views, np.cos(views)], axis=-1)
    got = ref.lobe_albedo(wo, alpha, name)
    # brute force: Gauss-Legendre in the GGX variable t (fine), 360 azimuths
    x, w = np.polynomial.legendre.leggauss(1500)
    t, wt = 0.5 * (x + 1), 0.5 * w
    phi = (np.arange(360) + 0.5) * 2 * np.pi / 360
    r = alpha * np.sqrt((1 - t) / t)[:, None]
    h = np.stack(np.broadcast_arrays(r * np.cos(phi), r * np.sin(phi), 1.0), -1)
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    for k, v in enumerate(wo):
        oh = h @ v
        wi = 2 * oh[..., None] * h - v
        area = alpha**2 / (2 * t * t)[:, None] * wt[:, None] * 2 * np.pi / 360
        f = ref.specular_lobe(wi, np.broadcast_to(v, wi.shape), alpha, name)
        exact = np.sum(f * np.clip(wi[..., 2], 0, None) * 4 * oh * h[..., 2] ** 3 * area)
        assert got[k] == pytest.approx(exact, rel=tol), (k, got[k], exact)
