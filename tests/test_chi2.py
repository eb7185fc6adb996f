"""Chi-square: values clipped at code 0 are censored, not exact zeros (Tobit likelihood)."""
import numpy as np
import pytest
from scipy.optimize import minimize_scalar
from scipy.stats import norm

from skyfit_mi.camera import SensorModel
from skyfit_mi.chi2 import LOW_CODE, Observations, Problem


class _Flat:
    """Radiance a (the one parameter) at every pixel, frame and channel."""

    names = ("a",)

    def __init__(self, shape):
        self.shape = shape

    def radiance(self, theta):
        return np.full(self.shape, float(theta[0]))

    def jacobian(self, theta):
        return self.radiance(theta), np.ones(self.shape + (1,))


def _problem(mean_dn, noise_percent=10.0, n=4000, seed=0):
    sensor = SensorModel(exposure=1.0, bits=8, noise_percent=noise_percent)
    rng = np.random.default_rng(seed)
    shape = (n, 1, 3)
    y = np.clip(np.rint(mean_dn + rng.normal(0, sensor.sigma, shape)), 0, sensor.max_code)
    obs = Observations(np.zeros((n, 2), int), [0], ["t"], y, np.full(shape, sensor.sigma),
                       np.ones(n), sensor)
    return Problem(obs, _Flat(shape)), sensor


def test_censored_residuals_and_jacobian():
    problem, sensor = _problem(10.0, n=50)
    assert problem.low.any() and not problem.low.all()
    theta = np.array([12.0 / sensor.max_code])
    r, J = problem.jacobian(theta)
    m = 12.0
    low = problem.low[problem.mask]
    expected = np.sqrt(-2 * norm.logcdf((LOW_CODE - m) / sensor.sigma))
    assert np.allclose(r[low], expected)
    h = 1e-6
    fd = (problem.residuals(theta + h) - problem.residuals(theta - h)) / (2 * h)
    assert np.allclose(J[:, 0], fd, rtol=1e-5, atol=1e-8)


def test_clipped_dark_values_give_an_unbiased_estimate():
    # a dark channel at 10 DN under noise of sigma 25.5 DN: a third of its values read 0
    problem, sensor = _problem(10.0)
    assert 0.25 < problem.low.mean() < 0.45
    fit = minimize_scalar(lambda a: problem.chi2([a / sensor.max_code]), bounds=(0, 100),
                          method="bounded")
    se = sensor.sigma / np.sqrt(problem.n_data)
    assert fit.x == pytest.approx(10.0, abs=4 * se)              # about 1.4 DN
    naive = problem.obs.y.mean()                                 # zeros taken as measured
    assert naive - 10.0 > 10 * se
