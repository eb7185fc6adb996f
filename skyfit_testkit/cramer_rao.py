"""The Cramer-Rao bound: the smallest standard deviation any unbiased fit can reach.

The intervals of :mod:`uncertainty` are judged by it (``scripts/coverage.py``). The data are
Gaussian read-out (``sigma`` codes) about the mean code ``m``, clipped at both ends of the range:
a clipped value is a censored (Tobit) observation (thesis eq. 6.2 is the unclipped case).
"""

import numpy as np
from scipy.stats import norm

from skyfit_mi.fitting.chi2 import LOW_CODE


def censored_information(m, sigma, max_code):
    """Fisher information about the mean code ``m`` of one clipped Gaussian value [1/code^2].

    With a = (LOW_CODE - m) / sigma and u = (max_code - LOW_CODE - m) / sigma the clip points
    in standard units, the information is [phi(a)^2 / Phi(a) + phi(u)^2 / (1 - Phi(u)) + Phi(u)
    - Phi(a) - u phi(u) + a phi(a)] / sigma^2: 1 / sigma^2 far from either clip, falling to 0
    deep in it (Amemiya 1973, the Tobit model's information).
    """
    m, sigma = np.asarray(m, float), np.asarray(sigma, float)
    a = (LOW_CODE - m) / sigma
    u = (max_code - LOW_CODE - m) / sigma
    info = (norm.pdf(a) ** 2 / np.maximum(norm.cdf(a), 1e-300)
            + norm.pdf(u) ** 2 / np.maximum(norm.sf(u), 1e-300)
            + norm.cdf(u) - norm.cdf(a) - u * norm.pdf(u) + a * norm.pdf(a))
    return np.clip(info, 0.0, None) / sigma**2


def fisher_jacobian(session, theta, sigma):
    """J with J^T J the Fisher information of a :class:`~.fit.FitSession`'s data at ``theta``
    (one row per value); ``sigma`` the read-out noise [codes] (scalar or per value)."""
    problem = session.problem
    L, dL = session.wm.jacobian(theta)
    info = censored_information(problem.predict(L), sigma, session.obs.sensor.max_code)
    J = (np.sqrt(info) * problem.slope(L))[..., None] * dL
    return J[problem.mask]


def bound(J):
    """sqrt(diag(F^-1)) for F = J^T J: the bound on each parameter's standard deviation."""
    return np.sqrt(np.diag(np.linalg.pinv(J.T @ J)))
