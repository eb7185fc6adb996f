"""The Cramer-Rao bound: the censored sensor's information against direct integration."""
import numpy as np
import pytest
from scipy import integrate
from scipy.stats import norm

from skyfit_mi.fitting.chi2 import LOW_CODE, parse_region
from skyfit_testkit.cramer_rao import bound, censored_information, fisher_jacobian


def _information_by_integration(m, sigma, top):
    """E[(d/dm ln p(y; m))^2] of a Gaussian read-out clipped at LOW_CODE and top - LOW_CODE,
    by quadrature over the measured values plus the two clipped masses; scores by central
    differences of the log-likelihood."""
    lo, hi, h = LOW_CODE, top - LOW_CODE, 1e-4 * sigma

    def log_p_low(mm):
        return norm.logcdf((lo - mm) / sigma)

    def log_p_high(mm):
        return norm.logsf((hi - mm) / sigma)

    def score(f):
        return (f(m + h) - f(m - h)) / (2 * h)

    inside, _ = integrate.quad(lambda y: ((y - m) / sigma**2) ** 2 * norm.pdf(y, m, sigma),
                               lo, hi, points=[m] if lo < m < hi else None, limit=200)
    return (inside + np.exp(log_p_low(m)) * score(log_p_low) ** 2
            + np.exp(log_p_high(m)) * score(log_p_high) ** 2)


@pytest.mark.parametrize("m", [-20.0, -2.0, 0.5, 3.0, 100.0, 250.0, 254.5, 258.0, 270.0])
@pytest.mark.parametrize("sigma", [0.3, 2.0, 12.75])
def test_censored_information_matches_integration(m, sigma):
    got = censored_information(m, sigma, 255)
    assert got == pytest.approx(_information_by_integration(m, sigma, 255), rel=1e-5, abs=1e-12)


def test_information_is_gaussian_far_from_the_clips_and_vanishes_deep_in_them():
    sigma = 3.0
    assert censored_information(128.0, sigma, 255) == pytest.approx(1 / sigma**2, rel=1e-12)
    assert censored_information(-60.0, sigma, 255) < 1e-30
    assert censored_information(400.0, sigma, 255) < 1e-30
    # never more than an unclipped value carries
    m = np.linspace(-20, 280, 601)
    assert np.all(censored_information(m, sigma, 255) <= 1 / sigma**2 * (1 + 1e-12))


def test_bound_of_a_straight_line_is_least_squares_standard_error():
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 1, 40)
    sigma = 0.7
    J = np.stack([np.ones_like(x), x], axis=1) / sigma
    X = np.stack([np.ones_like(x), x], axis=1)
    expected = sigma * np.sqrt(np.diag(np.linalg.inv(X.T @ X)))
    np.testing.assert_allclose(bound(J), expected, rtol=1e-12)


def test_fisher_jacobian_is_the_fits_jacobian_where_nothing_is_clipped(days):
    """Away from the clips the bound's J is the fit's own (residual) Jacobian up to sign, so the
    bound and the fit's covariance use one derivative chain; near a clip rows shrink."""
    from skyfit_mi.fitting.fit import FitCache, FitSession

    s = FitSession(days["noisy"], "disc", parse_region("rect:4,4,7,7"),
                   cache=FitCache(positions=2, directions=256))
    theta = np.array([0.3, 0.1])
    sigma = s.obs.sigma
    J = fisher_jacobian(s, theta, sigma)
    _, J_fit = s.problem.jacobian(theta)
    m = s.problem.predict(s.wm.radiance(theta))[s.problem.mask]
    sig = np.broadcast_to(sigma, s.obs.y.shape)[s.problem.mask]
    free = (m - LOW_CODE > 6 * sig) & (s.obs.sensor.max_code - LOW_CODE - m > 6 * sig)
    measured = ~np.isin(s.obs.y[s.problem.mask], (0, s.obs.sensor.max_code))
    rows = free & measured
    assert rows.sum() > 100
    np.testing.assert_allclose(J[rows], -J_fit[rows], rtol=1e-6, atol=1e-9)
    # a measured value near a clip carries less than an unclipped one
    assert np.all(np.abs(J[measured]) <= np.abs(J_fit[measured]) * (1 + 1e-9) + 1e-12)
    assert np.any(np.abs(J[measured & ~free]) < 0.99 * np.abs(J_fit[measured & ~free]))
    crb = bound(J)
    assert np.all(np.isfinite(crb)) and np.all(crb > 0) and crb[1] < 0.05
