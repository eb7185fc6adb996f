"""Parameter sets drawn from the likelihood of a region's data (thesis ch. 6: chi-square's rise is
-2 ln L), for the bands of a relight: unlike sets drawn from the intervals, they stay where the
data allow. The errors the sequence's light, calibration and pose share are left out of them:
they cancel in a relight of the fitted sequence itself, and relight adds them under other light
(:func:`skyfit_mi.fitting.relight.parameter_draws`)."""

from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp

from .uncertainty import LEVELS, Z

#: Parameter sets kept (relight's default draws) and tried in each round of the sampling.
DRAWS, PROPOSALS = 200, 1000
#: Most and least rounds of the sampling; it stops once the effective number suffices and did
#: not fall (a fall means a round found likelihood the earlier proposals missed).
ROUNDS, MIN_ROUNDS = 6, 3
#: A mixture component's covariance: that of this many favoured sets nearest it, its width
#: times SPREAD, plus FLOOR times the first proposal's covariance.
NEIGHBOURS, SPREAD, FLOOR = 20, 2.0, 1e-4


@dataclass
class Draws:
    """``values`` (n, parameters) drawn from the likelihood, with the sampling's statistics."""

    values: np.ndarray
    effective_size: float
    proposals: int
    rounds: int


def likelihood_draws(problem, theta, chi2_min, scale, cov, bounds, seed, n=DRAWS,
                     local=None, centre=None):
    """``n`` parameter sets drawn with probability exp(-(chi2 - chi2_min) / (2 ``scale``)) within
    the ``bounds`` (lower, upper), by importance sampling (population Monte Carlo): first from the Gaussian of
    ``cov`` about ``theta`` (with ``local``, the curvature's covariance there, an equal mixture
    with its Gaussian: the intervals' is broad along a thin ridge, or wider than the
    likelihood where errors the data share widen them; with ``centre``, the intervals'
    middle, also ``cov``'s Gaussian there: a fit at one end of an interval, a roughness at
    its bound whose data allow a sharp lobe too, reaches the other end), then mixtures around
    the favoured sets, with deterministic-mixture weights, until ``n`` effective draws. None
    where that fails after ROUNDS or no set is valid."""
    rng = np.random.default_rng(seed)
    lower, upper = (np.asarray(b, float) for b in bounds)
    tiny = np.diag((1e-6 * (upper - lower)) ** 2)
    first = _psd(cov) + tiny
    kernels = [first] if local is None or not np.all(np.isfinite(local)) else \
        [first, _psd(_within_range(local, upper - lower)) + tiny]
    means = [theta] * len(kernels)
    if centre is not None and not np.allclose(centre, theta):
        means, kernels = means + [np.asarray(centre, dtype=float)], kernels + [first]
    proposals, logq, counts = [(np.array(means), np.array(kernels))], [], []
    x_all, log_likelihood, last = np.empty((0, len(theta))), np.empty(0), 0.0
    for r in range(ROUNDS):
        x, accepted = _propose(rng, *proposals[-1], lower, upper)
        if not len(x):
            return None
        proposals[-1] += (accepted,)
        counts.append(len(x))
        logq = [np.concatenate([q, _log_mixture(x, *p[:2]) - np.log(p[2])])
                for q, p in zip(logq, proposals)]
        logq.append(_log_mixture(np.concatenate([x_all, x]), *proposals[-1][:2])
                    - np.log(accepted))
        x_all = np.concatenate([x_all, x])
        chi2 = problem.chi2_at(x)
        log_likelihood = np.concatenate([log_likelihood, np.where(
            np.isfinite(chi2), -(chi2 - chi2_min) / (2 * scale), -np.inf)])
        share = np.log(np.array(counts) / len(x_all))[:, None]
        logw = log_likelihood - logsumexp(np.array(logq) + share, axis=0)
        if not np.isfinite(logw).any():
            return None
        w = np.exp(logw - logsumexp(logw))
        ess = 1.0 / np.sum(w * w)
        if ess >= n and r + 1 >= MIN_ROUNDS and ess >= last:
            break
        last = ess
        means = x_all[_systematic(w, n, rng)]
        proposals.append((means, _local_kernels(means, first)))
    if ess < n:
        return None
    return Draws(x_all[_systematic(w, n, rng)], float(ess), len(x_all), r + 1)


def _within_range(cov, span):
    """``cov`` with each sd at most ``span`` (the bounds' range), its correlations kept: a
    nearly singular curvature's covariance can be vast, beyond what its rounding leaves
    positive definite."""
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    shrink = np.divide(np.minimum(sd, span), sd, out=np.ones_like(sd), where=sd > 0)
    return cov * np.outer(shrink, shrink)


def _psd(cov):
    """``cov`` with its negative eigenvalues (clipped correlations) set to zero."""
    root = root_of(cov)
    return root @ root.T


def _local_kernels(means, first):
    """Each mixture component's covariance: its NEIGHBOURS nearest ``means``' times SPREAD (to
    follow a curved ridge), plus FLOOR times ``first`` (so none collapses)."""
    z = np.linalg.solve(np.linalg.cholesky(first), means.T).T
    dist = np.sum((z[:, None] - z[None]) ** 2, axis=-1)
    near = np.argsort(dist, axis=1)[:, :min(NEIGHBOURS, len(means))]
    local = means[near] - means[near].mean(axis=1, keepdims=True)          # (K, q, n)
    return (SPREAD**2 * np.einsum("kqi,kqj->kij", local, local) / near.shape[1]
            + FLOOR * first)


def interval_covariance(intervals95, covariance=None):
    """The Gaussian of a fit's intervals: sds from ``intervals95`` (n, 2) half-widths / 1.96,
    correlations from ``covariance`` (n, n) where given and finite."""
    iv = np.asarray(intervals95, dtype=float)
    sd = (iv[:, 1] - iv[:, 0]) / (2 * Z["95"])
    return correlation(covariance, len(iv)) * np.outer(sd, sd)


def interval_draws(theta, intervals95, covariance, n, rng):
    """``n`` parameter sets (n, parameters) Gaussian about ``theta`` as the intervals' Gaussian
    (:func:`interval_covariance`) spreads them: where a fit keeps no likelihood draws."""
    root = root_of(interval_covariance(intervals95, covariance))
    return np.asarray(theta, dtype=float) + rng.standard_normal((n, len(root))) @ root.T


def correlation(covariance, n):
    """The correlations of ``covariance`` (n, n); the identity where it is None, not finite or
    has a variance of 0."""
    if covariance is not None:
        c = np.asarray(covariance, dtype=float)
        d = np.sqrt(np.clip(np.diag(c), 0, None))
        if np.all(np.isfinite(c)) and np.all(d > 0):
            return np.clip(c / np.outer(d, d), -1, 1)
    return np.eye(n)


def draws_scale(interval_scale, channel_factors, ripple):
    """The scale of chi-square's rise in the draws' likelihood: s^2 times the largest channel
    factor, with ``ripple`` spread so the 95% level lies at LEVELS 95 s^2 + ripple."""
    return interval_scale * float(np.max(channel_factors)) + ripple / LEVELS["95"]


def _propose(rng, means, kernels, lower, upper):
    """(Up to PROPOSALS sets of the Gaussian mixture within the bounds, its share within them)."""
    roots = np.array([root_of(k) for k in kernels])
    kept, tried = [], 0
    while sum(len(k) for k in kept) < PROPOSALS and tried < 50 * PROPOSALS:
        c = rng.integers(len(means), size=PROPOSALS)
        x = means[c] + np.einsum("mij,mj->mi", roots[c],
                                 rng.standard_normal((PROPOSALS, len(lower))))
        tried += PROPOSALS
        kept.append(x[np.all((x >= lower) & (x <= upper), axis=1)])
    x = np.concatenate(kept)
    accepted = max(len(x), 1) / tried
    x = x[:PROPOSALS]
    return x, accepted


def root_of(cov):
    """A square root R of a symmetric positive semi-definite ``cov`` (cov = R R^T)."""
    w, v = np.linalg.eigh(cov)
    return v * np.sqrt(np.clip(w, 0, None))


def _log_mixture(x, means, kernels):
    """Log density at ``x`` (m, n) of the equal Gaussian mixture ``means``, ``kernels``."""
    chol = np.linalg.cholesky(kernels)                                      # (K, n, n)
    whiten = np.linalg.inv(chol)
    z = whiten @ x.T - whiten @ means[:, :, None]                          # (K, n, m)
    log_norm = (np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2)), axis=1)
                + 0.5 * x.shape[1] * np.log(2 * np.pi))
    return (logsumexp(-0.5 * np.sum(z * z, axis=1) - log_norm[:, None], axis=0)
            - np.log(len(means)))


def _systematic(w, n, rng):
    """Indices of ``n`` draws by systematic resampling of the normalised weights ``w``."""
    edges = np.cumsum(w)
    edges[-1] = 1.0
    return np.searchsorted(edges, (rng.random() + np.arange(n)) / n)
