"""Draws from a fit's likelihood (skyfit_mi.fitting.draws): against the exact posterior of a
linear model, and along a curved ridge (a grey plastic's metal twin) that the intervals'
Gaussian misses."""

import numpy as np

from skyfit_mi.fitting.draws import DRAWS, interval_covariance, interval_draws, likelihood_draws
from skyfit_mi.fitting.uncertainty import Z


class _Model:
    """Radiance (n, P, T, 3) of parameter sets from a function of the sets (n, k) -> (n, m)."""

    def __init__(self, f):
        self.f = f

    def radiances(self, thetas):
        return self.f(np.atleast_2d(thetas)).reshape(len(thetas), -1, 1, 3)


class _Problem:
    """Chi-square of values y with noise sigma (the one method the draws use)."""

    def __init__(self, f, y, sigma):
        self.model, self.y, self.sigma = _Model(f), y, sigma

    def chi2_at(self, thetas):
        r = (self.y - self.model.radiances(thetas).reshape(len(thetas), -1)) / self.sigma
        return np.sum(r * r, axis=1)


def _intervals(theta, sd, lower, upper):
    return np.clip(np.stack([theta - Z["95"] * sd, theta + Z["95"] * sd], axis=1),
                   lower[:, None], upper[:, None])


def test_draws_of_a_linear_model_have_its_posterior_mean_and_covariance():
    """y = A theta + noise: the draws' mean and covariance are the least-squares estimate and
    (A^T A)^-1 sigma^2 s (s the scale), within their Monte Carlo error, from the intervals'
    Gaussian and from one 3 times too wide alike; from one 30 or 100 times too wide (errors
    the data share can widen the intervals so) too, beside the curvature's Gaussian
    (``local``); without it, from 100 times too wide, too few effective draws are found, and
    none are given rather than a few sets repeated."""
    rng = np.random.default_rng(1)
    A = rng.normal(size=(60, 3))
    A[:, 2] *= 0.2                                   # a poorly determined last parameter
    truth, sigma, scale = np.array([0.4, 0.3, 0.2]), 0.05, 1.5
    y = A @ truth + sigma * rng.standard_normal(60)
    theta = np.linalg.lstsq(A, y, rcond=None)[0]
    cov = np.linalg.inv(A.T @ A) * sigma**2 * scale
    problem = _Problem(lambda th: th @ A.T, y, sigma)
    chi2 = float(np.sum(((y - A @ theta) / sigma) ** 2))
    lower, upper = np.zeros(3) - 5, np.ones(3) * 5
    for widen in (1.0, 3.0, 30.0, 100.0):
        start = interval_covariance(_intervals(theta, widen * np.sqrt(np.diag(cov)), lower,
                                               upper), cov)
        local = cov if widen > 3 else None
        d = likelihood_draws(problem, theta, chi2, scale, start, lower, upper, seed=2, n=400,
                             local=local)
        if widen == 100.0:
            assert likelihood_draws(problem, theta, chi2, scale, start, lower, upper, seed=2,
                                    n=400) is None
        assert d.effective_size >= 400 and d.values.shape == (400, 3)
        se = np.sqrt(np.diag(cov) / 400)
        assert np.all(np.abs(d.values.mean(axis=0) - theta) < 4 * se), widen
        ratio = np.sqrt(np.diag(np.cov(d.values.T)) / np.diag(cov))
        assert np.all((ratio > 0.85) & (ratio < 1.15)), (widen, ratio)


def test_a_nearly_singular_curvature_beside_the_intervals_still_draws():
    """Two parameters that trade off almost exactly: the curvature's covariance is vast (1e10
    and more), its Gaussian capped at the bounds' range beside the intervals' (uncapped,
    rounding left some kernels indefinite and their Cholesky factorisation failed, 14 of 100
    such days); every set drawn fits y to about its noise."""
    done = 0
    for seed in range(40):
        rng = np.random.default_rng(seed)
        A = rng.normal(size=(60, 4))
        A[:, 3] = A[:, 2] + 1e-8 * rng.normal(size=60)
        y = A @ np.array([0.4, 0.3, 0.2, 0.1]) + 0.05 * rng.standard_normal(60)
        theta = np.linalg.lstsq(A, y, rcond=1e-6)[0]            # the pair at its least norm
        try:
            local = np.linalg.inv(A.T @ A) * 0.05**2
        except np.linalg.LinAlgError:
            continue
        assert np.max(np.abs(local)) > 1e10
        problem = _Problem(lambda th: th @ A.T, y, 0.05)
        chi2 = float(np.sum(((y - A @ theta) / 0.05) ** 2))
        start = interval_covariance([[0.3, 0.5], [0.2, 0.4], [-5, 5], [-5, 5]], local)
        d = likelihood_draws(problem, theta, chi2, 1.0, start, -5 * np.ones(4), 5 * np.ones(4),
                             seed, local=local)
        done += 1
        if d is not None:                    # each set fits y to about its noise
            assert np.sqrt(np.mean((d.values @ A.T - y) ** 2, axis=1)).max() < 0.065
    assert done >= 20


def test_draws_follow_a_curved_ridge_and_predict_the_data_as_the_fit_does():
    """A product model y = a b x (a metal's C times its specular, read the same along
    a b = const): the intervals' Gaussian, broad along the ridge, gives predictions far
    wider than the data allow; the draws stay on the ridge (a b within its noise) and
    spread along it as its likelihood does within the bounds (flat in a and b, so a's
    density along a b = 0.3 goes as 1/a on [0.3, 1]: quantile q at 0.3 (1/0.3)^q)."""
    rng = np.random.default_rng(3)
    x = np.linspace(0.5, 1.5, 90)
    sigma, ab = 0.01, 0.3
    y = ab * x + sigma * rng.standard_normal(len(x))
    problem = _Problem(lambda th: (th[:, 0] * th[:, 1])[:, None] * x, y, sigma)
    theta = np.array([0.6, 0.5])
    theta[1] = float(x @ y / (x @ x)) / theta[0]
    chi2 = float(np.sum(((y - theta[0] * theta[1] * x) / sigma) ** 2))
    lower, upper = np.array([0.3, 0.3]), np.array([1.0, 1.0])
    start = interval_covariance([[0.3, 1.0], [0.3, 1.0]])       # "not determined" along it
    d = likelihood_draws(problem, theta, chi2, 1.0, start, lower, upper, seed=4)
    assert d.effective_size >= DRAWS
    products = d.values[:, 0] * d.values[:, 1]
    se = sigma / np.sqrt(x @ x)
    assert np.std(products) < 2 * se and abs(np.mean(products) - theta[0] * theta[1]) < 3 * se
    q = np.percentile(d.values[:, 0], [5, 50, 95])                   # along the ridge
    assert 0.3 < q[0] < 0.4 and 0.47 < q[1] < 0.65 and q[2] > 0.85, q
    naive = theta + rng.standard_normal((DRAWS, 2)) @ np.linalg.cholesky(start).T
    assert np.std(naive[:, 0] * naive[:, 1]) > 20 * se


def test_no_draws_where_the_likelihood_cannot_be_found():
    """A chi-square that is nowhere finite, or bounds that no proposal meets: no draws (relight
    then takes the intervals)."""
    problem = _Problem(lambda th: np.full((len(th), 3), np.nan), np.zeros(3), 1.0)
    cov = np.eye(2) * 0.01
    lower, upper = np.zeros(2), np.ones(2)
    assert likelihood_draws(problem, np.array([0.5, 0.5]), 0.0, 1.0, cov, lower, upper,
                            seed=0) is None
    assert likelihood_draws(problem, np.array([0.5, 0.5]), 0.0, 1.0, cov, lower + 5,
                            upper + 5, seed=0) is None


def test_interval_covariance_takes_the_intervals_widths_and_the_covariances_correlations():
    cov = np.array([[4.0, -1.0], [-1.0, 1.0]])
    c = interval_covariance([[0.0, 2 * Z["95"]], [1.0, 1.0 + 6 * Z["95"]]], cov)
    assert np.allclose(np.diag(c), [1.0, 9.0]) and np.isclose(c[0, 1], -0.5 * 3)
    assert np.allclose(interval_covariance([[0, 1], [0, 1]], np.full((2, 2), np.nan)),
                       np.eye(2) / (2 * Z["95"]) ** 2)


def test_interval_draws_spread_each_side_as_its_interval_says():
    # a gloss at 0.089 in [0, 0.103], a roughness at its bound 0.5 in [0, 0.5], a C in [0.4, 0.6]
    theta = np.array([0.089, 0.5, 0.5])
    iv = [[0.0, 0.103], [0.0, 0.5], [0.4, 0.6]]
    cov = np.array([[1.0, -0.8, 0.0], [-0.8, 1.0, 0.0], [0.0, 0.0, 4.0]])
    x = interval_draws(theta, iv, cov, 40000, np.random.default_rng(0))
    lo, hi = np.array(iv).T
    for i in range(3):
        assert abs(np.mean(x[:, i] < lo[i]) - 0.025) < 0.004
        assert abs(np.mean(x[:, i] > hi[i]) - 0.025) < 0.004 or hi[i] == theta[i]
        assert abs(np.median(x[:, i]) - theta[i]) < 0.01 * (hi[i] - lo[i])
    assert np.all(x[:, 1] <= 0.5)                          # nothing above a bound the fit sits at
    # half the gloss's draws lie below the fit, spread to the interval's lower end; the
    # correlation's sign kept: a sharper gloss comes with a rougher second parameter
    assert np.mean(x[:, 0] < 0.045) > 0.15
    assert np.corrcoef(x[:, 0], x[:, 1])[0, 1] < -0.5
    assert abs(np.corrcoef(x[:, 0], x[:, 2])[0, 1]) < 0.03
