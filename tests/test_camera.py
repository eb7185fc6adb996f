"""Sensor model statistics (thesis 5 and 6.3.3)."""
import numpy as np
import pytest

from skyfit_mi.physics.camera import SensorModel
from skyfit_mi.errors import SkyfitError


def test_noise_sigma_and_mean():
    s = SensorModel(exposure=0.01, bits=10, noise_percent=5.0)
    img = np.full((400, 400, 3), 40.0)                      # signal 0.4 of full scale
    v, sigma = s.capture(img, np.random.default_rng(1))
    assert v.std() == pytest.approx(0.05 * 1023, rel=0.02)
    assert v.mean() == pytest.approx(0.4 * 1023, abs=0.3)
    assert np.all(sigma == pytest.approx(np.sqrt((0.05 * 1023) ** 2 + 1 / 12)))


@pytest.mark.parametrize("bits", [8, 10, 12, 16])
def test_quantisation_steps(bits):
    s = SensorModel(exposure=1.0, bits=bits)
    ramp = np.linspace(0, 1, 5000)[None, :, None] * np.ones((1, 1, 3))
    v, _ = s.capture(ramp, np.random.default_rng(0))
    assert v.dtype == np.uint16 and v.max() == 2**bits - 1
    err = v - ramp * (2**bits - 1)
    assert np.abs(err).max() <= 0.5 + 1e-9                  # rounding to the nearest code
    if bits == 8:                                          # a fine ramp hits every code once
        assert np.array_equal(np.unique(v), np.arange(256))


def test_clipping_never_negative_or_over_range():
    s = SensorModel(exposure=1.0, bits=8, noise_percent=20.0)
    img = np.concatenate([np.zeros((50, 50, 3)), np.full((50, 50, 3), 3.0)], axis=0)
    v, sigma = s.capture(img, np.random.default_rng(2))
    assert v.min() == 0 and v.max() == 255
    # the bright half clips at full scale, and noise leaves about half of it at the top code;
    # sigma stays finite (chi-square takes top-code values as censored)
    assert 0.4 < np.mean(v[50:] == 255) < 0.6 and np.all(np.isfinite(sigma))


def test_saturation_follows_the_captured_value():
    """Just under full scale, noise pushes some values to the top code and others below it;
    just over, the clipped signal plus noise may read below the top: a value is saturated when
    it reads the top code, whatever the noise-free signal was."""
    s = SensorModel(exposure=1.0, bits=8, noise_percent=2.0)
    for level in (0.99, 1.01):
        v, sigma = s.capture(np.full((40, 40, 3), level), np.random.default_rng(3))
        assert 0 < np.mean(v == 255) < 1
        np.testing.assert_allclose(sigma, s.sigma, rtol=1e-6)


def test_a_clipped_values_sigma_keeps_its_monte_carlo_error():
    """A value censored at the clip still has its radiance's Monte Carlo error about the clip
    (the slope just inside the range), not the quantisation alone: else one saturated pixel of
    a noisy render outweighs hundreds of measured ones."""
    s = SensorModel(exposure=1.0, bits=12)
    img = np.array([[[0.9, 0.9, 0.9], [1.5, 1.5, 1.5]]])
    sd = np.full(img.shape, 0.05)
    v, sigma = s.capture(img, np.random.default_rng(0), radiance_sd=sd)
    assert v[0, 1, 0] == 4095
    expected = np.hypot(s.sigma, 0.05 * 4095)
    np.testing.assert_allclose(sigma[0, 0], expected, rtol=1e-6)
    np.testing.assert_allclose(sigma[0, 1], expected, rtol=1e-6)


def test_responses_and_cos4():
    lin = SensorModel(exposure=1.0, bits=16)
    assert lin.respond(np.array(0.5)) == 0.5
    assert SensorModel(exposure=1.0, response="gamma", gamma=2.0).respond(np.array(0.25)) == 0.5
    assert SensorModel(exposure=1.0, response="srgb").respond(np.array(0.5)) == pytest.approx(0.735357, abs=1e-6)
    f = SensorModel.falloff(2, 2, 90.0)
    # pixel centres at tan = +-0.5 in x and y: tan^2 alpha = 0.5 -> cos^4 = (1/1.5)^2
    np.testing.assert_allclose(f, (1 / 1.5) ** 2)
    c = SensorModel(exposure=1.0, cos4=True).signal(np.ones((2, 2, 3)), fov_deg=90.0)
    np.testing.assert_allclose(c[..., 0], (1 / 1.5) ** 2)


@pytest.mark.parametrize("kw, match", [
    (dict(exposure=0.0), "must be a positive number"),
    (dict(exposure=1.0, bits=9), "valid values are: 8, 10, 12, 16"),
    (dict(exposure=1.0, response="log"), "'linear', 'gamma', 'srgb'"),
    (dict(exposure=1.0, noise_percent=-1), r"noise_percent = -1 % is outside the valid range \[0, 50\]"),
])
def test_bad_sensor(kw, match):
    with pytest.raises(SkyfitError, match=match):
        SensorModel(**kw)
