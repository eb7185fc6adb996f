"""CIE skies against hand-derived values (thesis 4.2)."""
import numpy as np
import pytest

from skyfit_mi.physics import sky as sk
from skyfit_mi.physics import sky_shape
from skyfit_mi.physics.sun import SunDisc
from skyfit_mi.conventions import direction_from_angles
from skyfit_mi.errors import SkyfitError

LUM = np.array([0.2126, 0.7152, 0.0722])


def rel(s, theta_p, phi_p):
    d = direction_from_angles(np.radians(theta_p), np.radians(phi_p))
    z = direction_from_angles(0.0, 0.0)
    return (s.sky_radiance(d) @ LUM) / (s.sky_radiance(z) @ LUM)


# eq. 4.10 evaluated by hand, e.g. theta_s = 45, theta_p = 45, 180 degrees apart:
# zeta = 90 deg, f = 0.91 + 10 e^-4.712 = 0.99991, gamma(45) = 1 - e^-0.45255 = 0.36397,
# gamma(0) = 0.27385, f(45 deg) = 2.08273  ->  0.36397 * 0.99991 / (0.27385 * 2.08273) = 0.63806
@pytest.mark.parametrize("theta_s, theta_p, dphi, expected", [
    (45, 45, 180, 0.63806), (45, 45, 0, 7.24955), (30, 60, 90, 0.69468), (60, 80, 180, 2.49438)])
def test_clear_sky_relative_luminance(theta_s, theta_p, dphi, expected):
    s = sk.cie_sky("clear", theta_s, 180.0, sun=SunDisc(drawn=False))
    assert rel(s, theta_p, 180.0 + dphi) == pytest.approx(expected, rel=1e-4)


@pytest.mark.parametrize("theta_p, expected", [(0, 1.0), (60, 2 / 3), (89.999, 1 / 3)])
def test_overcast_relative_luminance(theta_p, expected):
    s = sk.cie_sky("overcast", 50, 120)
    assert rel(s, theta_p, 10.0) == pytest.approx(expected, rel=1e-4)


def test_zenith_luminance_models():
    assert sk.kittler_zenith_luminance(60) == pytest.approx(300 + 3000 / np.sqrt(3))
    assert sk.krochmann_seidl_zenith_luminance(60) == pytest.approx(123 + 4300)
    assert sk.kittler_zenith_luminance(120) == 0.0
    s = sk.cie_sky("clear", 60, 180, sun=SunDisc(drawn=False),
                   photometry=sk.CIEPhotometry(efficacy_clear=150.0))
    zen = s.sky_radiance(np.array([0.0, 0.0, 1.0]))
    assert zen @ LUM == pytest.approx((300 + 3000 / np.sqrt(3)) / 150.0)   # eq. 4.15 / 150 lm/W


def test_overcast_horizontal_irradiance_is_analytic():
    # E = int Lz (1 + 2 cos)/3 cos dw = 7 pi / 9 Lz
    s = sk.cie_sky("overcast", 40, 0, photometry=sk.CIEPhotometry(efficacy_overcast=120.0))
    lz = sk.krochmann_seidl_zenith_luminance(40) / 120.0
    assert s.sky_horizontal_irradiance() @ LUM == pytest.approx(7 * np.pi / 9 * lz, rel=1e-6)
    assert np.all(s.sun_horizontal_irradiance() == 0)


def test_intermediate_is_the_mixture_of_eq_4_18():
    d = direction_from_angles(np.radians([10, 50, 85]), np.radians([0, 90, 200]))
    cl, oc = sk.cie_sky("clear", 35, 150), sk.cie_sky("overcast", 35, 150)
    mid = sk.cie_sky("intermediate", 35, 150, phi=0.3)
    np.testing.assert_allclose(mid.sky_radiance(d),
                               0.3 * cl.sky_radiance(d) + 0.7 * oc.sky_radiance(d), rtol=1e-12)
    np.testing.assert_allclose(mid.sun_radiance, 0.3 * cl.sun_radiance)


def test_sun_disc_and_levels():
    s = sk.cie_sky("clear", 30, 180, day=172)
    n = 1377 * (1 + 0.01672 * np.cos(np.radians(170 * 360 / 365.2))) ** 2 / (1 - 0.01672**2) \
        * np.exp(-0.431 / np.cos(np.radians(30)))
    assert s.sun_horizontal_irradiance() @ LUM == pytest.approx(n * np.cos(np.radians(30)))
    assert s.sun_mask(s.sun_direction) and not s.sun_mask(np.array([0.0, 0.0, 1.0]))
    m = s.scaled(diffuse_horizontal=80.0, direct_normal=500.0)
    assert m.sky_horizontal_irradiance() @ LUM == pytest.approx(80.0)
    assert m.sun_radiance @ LUM * m.sun_solid_angle == pytest.approx(500.0)
    lux = s.scaled_to_illuminance(12000.0, efficacy=120.0)
    assert lux.sky_horizontal_irradiance() @ LUM == pytest.approx(100.0)


def test_ground_is_lambertian_reflection_of_global_irradiance():
    s = sk.cie_sky("clear", 40, 100, ground_albedo=0.3)
    np.testing.assert_allclose(s.ground, 0.3 * s.horizontal_irradiance() / np.pi, rtol=1e-3)
    # still so after scaling to measured levels: the ground follows its lighting
    m = s.scaled(diffuse_horizontal=60.0, direct_normal=300.0)
    np.testing.assert_allclose(m.ground, 0.3 * m.horizontal_irradiance() / np.pi, rtol=1e-3)
    assert not np.allclose(m.ground, s.ground, rtol=0.05)
    assert np.all(s.radiance(np.array([0.3, 0.1, -0.5])) == s.ground)


@pytest.mark.parametrize("kwargs, match", [
    (dict(kind="cloudy"), "valid values are: 'clear', 'overcast', 'intermediate'"),
    (dict(kind="intermediate", phi=1.5), r"phi = 1.5 is outside the valid range \[0, 1\]"),
    (dict(kind="intermediate", phi=-0.1), r"\[0, 1\]"),
    (dict(kind="intermediate"), "needs a sun probability phi"),
    (dict(kind="clear", phi=0.5), "give phi only for an intermediate sky"),
    (dict(kind="clear", ground_albedo=2.0), r"ground albedo = 2 .*\[0, 1\]"),
    (dict(kind="clear", sun=False), r"sun must be a SunDisc, got False: .*SunDisc\(drawn=False\)"),
    (dict(kind="clear", photometry=sk.CIEPhotometry(efficacy_clear=0.5)),
     r"efficacy_clear = 0.5 lm W\^-1 is outside"),
])
def test_bad_sky_input(kwargs, match):
    kind = kwargs.pop("kind")
    with pytest.raises(SkyfitError, match=match):
        sk.cie_sky(kind, 30, 180, **kwargs)


def test_a_skys_irradiance_is_computed_once_and_a_changed_copy_computes_its_own():
    from dataclasses import replace

    from skyfit_mi.physics.sky import cie_sky, hemisphere_integral

    sky = cie_sky("clear", 40.0, 120.0)
    e = sky.sky_horizontal_irradiance()
    assert sky.sky_horizontal_irradiance() is e and not e.flags.writeable
    assert np.array_equal(e, hemisphere_integral(sky.sky_radiance))
    assert sky.sky_horizontal_irradiance(8) is not e                    # per node count
    brighter = replace(sky, clear=2 * sky.clear)
    assert np.allclose(brighter.sky_horizontal_irradiance(), 2 * e)


@pytest.mark.parametrize("mix", [(0.0, 0.0), (0.6, -0.3)])
def test_a_shaped_sky_is_the_mix_of_its_pattern_and_variants(mix):
    """sky_shape.shaped (relight's sky of a fitted shape): the sun as the sky's own, the rest k
    times the mix of its pattern and its shape variants as a lat-long map, within 0.2% of the
    mix toward every direction 10 degrees from the sun and above the horizon (the map's
    bilinear cells), its horizontal irradiance within 1e-4; at mix 0 and k 1 the sky itself."""
    from skyfit_mi.physics import cie_general
    from skyfit_mi.physics.sky import cie_general_sky

    sky = cie_general_sky(cie_general.group_parameters(4, 4), 40.0, 120.0, day=200)
    variants = [v for _, v in sky_shape.shape_variants(sky)]
    k = 1.0 if not any(mix) else 1.2
    shaped = sky_shape.shaped(sky, k, mix, variants)
    d = np.random.default_rng(0).normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    sun, rest = sky.split()
    parts = [(k * (1 - sum(mix)), rest)] + [(k * m, v) for m, v in zip(mix, variants)]
    want = sun.sky_radiance(d) + sum(w * p.sky_radiance(d) for w, p in parts)
    away = (d @ sky.sun_direction < np.cos(np.radians(10.0))) & (d[:, 2] > 0.02)
    assert np.allclose(shaped.sky_radiance(d)[away], want[away], rtol=2e-3)
    assert np.allclose(shaped.sky_horizontal_irradiance(),
                       sum(w * p.sky_horizontal_irradiance() for w, p in parts), rtol=1e-4)
    assert np.array_equal(shaped.sun_radiance, sky.sun_radiance)
    if not any(mix):
        assert np.allclose(shaped.sky_radiance(d)[away], sky.sky_radiance(d)[away], rtol=2e-3)
