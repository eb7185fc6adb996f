"""Frames held out: how well a fit predicts the frames it was not fitted to.

The frames split into K interleaved folds (:func:`frame_folds`); each fold is predicted from
the minimum of the others. Used for a fit's model error on unseen light (:func:`held_out_error`)
and to rank models (:mod:`~skyfit_mi.fitting.selection`).
"""

import time

import numpy as np

from . import uncertainty as unc
from ..errors import SkyfitError
from .chi2 import Problem
from .methods.levenberg_marquardt import levenberg_marquardt


def frame_folds(valid, folds, ends=True):
    """(fit on, held out) masks of ``valid`` (P, T) in K = min(``folds``, frames) interleaved
    folds (frame t in fold t mod K); without ``ends`` the first and last are never held out."""
    T = valid.shape[1]
    held = np.arange(T) if ends else np.flatnonzero(valid.any(axis=0))[1:-1]
    k = min(int(folds), len(held))
    for f in range(k):
        test = np.isin(np.arange(T), held[np.arange(len(held)) % k == f])
        yield valid & ~test[None, :], valid & test[None, :]


#: Least frames for a held-out model error, and frames from which the first and last are held
#: out too (holding out an end extrapolates the day and reads false misfits).
HELD_OUT_FRAMES, END_FRAMES_FROM = 5, 6
#: Most folds: each frame held out alone up to 16 frames (the nearest test of the light
#: between fitted frames; fewer, larger folds miss misfits), interleaved beyond.
HELD_OUT_FOLDS = 16
#: Reach [deg] in the sun's (theta_h, theta_d) of a held-out residual in a prediction's model
#: error (:func:`local_error_scale`): a frame's own angles, its neighbours' (6-7 apart) at a
#: tenth of the weight.
ANGLE_REACH_DEG = 3.0
#: The weight, in frames, of the fit's kappa in a prediction's local model error.
KAPPA_FRAMES = 1.0


def held_out_error(problem, theta, lower, upper, folds=HELD_OUT_FOLDS, within=None,
                   frame_sd=None):
    """How well a fit at ``theta`` predicts frames it was not fitted to: each of ``folds``
    interleaved folds is predicted from the others' minimum (Levenberg-Marquardt from ``theta``).

    As relight predicts, an image region's mean per frame and channel (a table's every value) is
    tested; each residual's variance is its noise's (with ``frame_sd`` (3,), a relative error a
    frame shares) plus the prediction's, D C D^T. The excess, the model's error on unseen light,
    gives kappa by maximum likelihood where significant (p < MISFIT_P; docs/BENCHMARKS.md, "Real
    surfaces"). Folds leaving the 95% intervals (``within`` False) or too small are left out.

    Returns {kappa, interval95, chi2_per_value, p, values, folds, folds_outside, folds_too_small,
    level, wall_time_s}, for image means with ``by_frame`` relative residuals (held_out, fitted)
    and their sds (:func:`local_error_scale`); None with fewer than HELD_OUT_FRAMES frames."""
    if problem.valid.shape[1] < HELD_OUT_FRAMES:
        return None
    splits = list(frame_folds(problem.valid, folds, problem.valid.shape[1] >= END_FRAMES_FROM))
    t0 = time.perf_counter()
    means = problem.obs.rays is None
    es, vs, scales = [], [], []
    T, C = problem.valid.shape[1], problem.obs.y.shape[-1]
    rel = {k: np.full((T, C), np.nan) for k in ("held_out", "held_out_sd", "fitted",
                                                "fitted_sd")}
    outside = small = 0
    for train, test in splits:
        try:
            train = Problem(problem.obs, problem.model, valid=train)
            test = Problem(problem.obs, problem.model, valid=test)
        except SkyfitError:             # too few values to fit on, or to hold out
            small += 1
            continue
        th = np.asarray(levenberg_marquardt(train, theta, lower, upper)["theta"], dtype=float)
        if within is not None and not within(th):
            outside += 1
            continue
        e, v, a, use = predicted_residuals(test, th, means, frame_sd,
                                  unc.covariance(train.jacobian(th)[1]))
        es.append(e[use])
        scales.append(a[use])
        vs.append(v[use])
        if means:
            _keep_relative(rel, "held_out", e, v, a, use)
    out = {"kappa": 0.0, "values": 0, "folds": len(splits),
           "folds_outside": outside, "folds_too_small": small,
           "level": "region mean per frame and channel" if means else "value"}
    if means:                   # and the fit's own, on every frame (a fold left out too)
        _keep_relative(rel, "fitted", *predicted_residuals(
            problem, np.asarray(theta, dtype=float), means, frame_sd))
        out["by_frame"] = {k: [None if np.isnan(r).all() else [float(x) for x in r] for r in x]
                           for k, x in rel.items()}
    if sum(x.size for x in es):
        e, v, a = (np.concatenate(x) for x in (es, vs, scales))
        chi2 = float(np.sum(e * e / v))
        test = unc.misfit_test(chi2, len(e))
        out.update(values=len(e), chi2_per_value=chi2 / len(e), p=test.p)
        if test.significant:
            me = unc.model_error(e, v, a, len(e))
            out.update(kappa=me.kappa, interval95=list(me.interval95))
    out["wall_time_s"] = time.perf_counter() - t0
    return out


def predicted_residuals(problem, theta, means, frame_sd, cov=None):
    """(e [DN], v, a, use): ``problem``'s residuals at ``theta``, their variances (noise, Monte
    Carlo, ``frame_sd`` and with ``cov`` the prediction's spread D cov D^T), the values' scale
    (with ``means``: per frame and channel mean) and where there are values."""
    L, model_var = problem.model.radiance_and_variance(theta)
    use = problem.measured()
    sigma = np.where(use, problem.obs.sigma, 0.0)
    e = np.where(use, problem.obs.y - problem.predict(L), 0.0)
    v = np.where(use, sigma ** 2 + problem.slope(L) ** 2 * model_var, 0.0)
    a = np.where(use, problem.value_scale(theta), 0.0)
    D = None
    if cov is not None:
        _, J = problem.jacobian(theta, full=True)         # d r / d theta, r in sigma units
        D = J * sigma[..., None]                          # the prediction's derivatives [DN]
    if means:                                             # each frame's and channel's mean
        n = use.sum(axis=0)
        use = n > 0
        n = np.maximum(n, 1)
        e, v, a = e.sum(0) / n, v.sum(0) / n ** 2, a.sum(0) / n
        D = None if D is None else D.sum(0) / n[..., None]
    if frame_sd is not None:
        v = v + (np.asarray(frame_sd, dtype=float) * a) ** 2
    v = np.where(use, v, 0.0)
    if D is not None:
        v[use] += np.einsum("ij,jk,ik->i", D[use], cov, D[use])
    return e, v, a, use


def _keep_relative(rel, key, e, v, a, use):
    """Store e / a and sqrt(v) / a in ``rel[key]`` and ``rel[key + '_sd']`` where ``use``."""
    rel[key][use], rel[f"{key}_sd"][use] = e[use] / a[use], np.sqrt(v[use]) / a[use]


def local_error_scale(by_frame, fit_angles, angles, kappa):
    """A prediction's model error over the fit's one ``kappa`` (T, C) at the sun's ``angles``
    [(theta_h, theta_d) per frame, deg]: models miss at certain angles and little elsewhere
    (docs/BENCHMARKS.md, "Bands in a new view").

    From ``by_frame`` of :func:`held_out_error` at ``fit_angles``: each frame's excess
    max(e^2 - sd^2, 0) (the larger of held-out and fitted), weighted w = exp(-d^2 / 2
    ANGLE_REACH_DEG^2) by angular distance d:
    kappa_local^2 = (sum w excess + KAPPA_FRAMES kappa^2) / (sum w + KAPPA_FRAMES); returns
    kappa_local / kappa, 1 where no fitted frame lies near or without kappa or residuals."""
    T = len(angles)
    ones = np.ones((T, 1))
    if not (kappa > 0 and isinstance(by_frame, dict) and isinstance(fit_angles, list)):
        return ones
    try:
        excess = None
        for key in ("held_out", "fitted"):
            e, sd = (by_frame.get(k) for k in (key, f"{key}_sd"))
            if not (isinstance(e, list) and isinstance(sd, list) and len(e) == len(sd)
                    == len(fit_angles)):
                continue
            C = next((len(r) for r in e if r is not None), 1)
            x = np.array([np.full(C, np.nan) if r is None or u is None else
                          np.square(np.asarray(r, float)) - np.square(np.asarray(u, float))
                          for r, u in zip(e, sd)], dtype=float)
            excess = x if excess is None else np.fmax(excess, x)
        if excess is None:
            return ones
        at = np.array([[np.nan] * 2 if a is None else a for a in fit_angles], dtype=float)
    except (TypeError, ValueError):                     # edited or malformed: not used
        return ones
    rows = np.isfinite(excess).all(axis=1) & np.isfinite(at).all(axis=1)
    if not rows.any():
        return ones
    at, excess = at[rows], np.maximum(excess[rows], 0.0) / kappa ** 2          # (F, 2), (F, C)
    out = np.ones((T, excess.shape[1]))
    for t, a in enumerate(angles):
        if a is None:
            continue
        w = np.exp(-0.5 * np.sum((at - np.asarray(a, float)) ** 2, axis=1) / ANGLE_REACH_DEG**2)
        out[t] = np.sqrt((w @ excess + KAPPA_FRAMES) / (w.sum() + KAPPA_FRAMES))
    return out
