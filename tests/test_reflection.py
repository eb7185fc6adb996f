"""The lobe's albedo quadrature and the reflected-radiance reference, against hand-derived
limits and brute-force integrals."""
import numpy as np
import pytest

from skyfit_mi.physics.reflection import cap_quadrature, reflected_radiance
from skyfit_mi.physics.sky import Sky
from skyfit_mi.physics.ward import lobe_albedo, mirror_reflectance, specular_lobe


def _view(theta_deg):
    t = np.radians(theta_deg)
    return np.array([np.sin(t), 0.0, np.cos(t)])


@pytest.mark.parametrize("normalisation", ["ward", "duer", "balanced"])
@pytest.mark.parametrize("theta", [0.0, 45.0, 70.0])
def test_narrow_lobe_albedo_is_the_mirror_reflectance(normalisation, theta):
    # sigma -> 0: Ward's lobe reflects cos(theta_o), Duer's and the balanced one 1
    wo = _view(theta)
    expected = mirror_reflectance(wo[2], normalisation)
    assert lobe_albedo(wo, 1e-3, normalisation) == pytest.approx(expected, rel=2e-5)


@pytest.mark.parametrize("normalisation", ["ward", "duer", "balanced", "radiance"])
@pytest.mark.parametrize("sigma", [0.002, 0.01, 0.05])
@pytest.mark.parametrize("theta", [45.0, 70.0])
def test_lobe_albedo_matches_a_brute_force_integral(sigma, theta, normalisation):
    wo = _view(theta)
    mirror = np.array([-wo[0], -wo[1], wo[2]])
    d, w = cap_quadrature(mirror, 20 * sigma, n_r=200, n_phi=256)
    brute = np.sum(specular_lobe(d, wo, sigma, normalisation) * np.clip(d[:, 2], 0, None) * w)
    assert lobe_albedo(wo, sigma, normalisation) == pytest.approx(brute, rel=2e-6)


def test_reflected_radiance_under_a_uniform_sky_and_a_sun():
    # uniform sky L0: a Lambertian part reflects rho_d L0, the lobe rho_s L0 A(sigma)
    L0 = np.array([1.0, 2.0, 3.0])
    wo = _view(40.0)
    sky = Sky(np.array([0.0, -0.6, 0.8]), uniform=L0)
    L = reflected_radiance(sky, wo, 0.3, 0.5, 0.02)
    assert L == pytest.approx(0.3 * L0 + 0.5 * L0 * lobe_albedo(wo, 0.02), rel=1e-6)
    # a sun alone and a Lambertian surface: rho_d / pi * E_sun, E_sun = L_sun Omega cos(theta_s)
    sun = Sky(np.array([0.0, -0.6, 0.8]), sun_radiance=np.array([1e5, 1e5, 1e5]))
    E = 1e5 * sun.sun_solid_angle * 0.8
    assert reflected_radiance(sun, wo, 0.4, 0.0, 0.02) == pytest.approx(0.4 / np.pi * E, rel=1e-5)
