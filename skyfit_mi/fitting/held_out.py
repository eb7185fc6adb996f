"""Frames held out: how well a fit predicts the frames it was not fitted to.

The frames split into K interleaved folds (frame t in fold t mod K, :func:`frame_folds`); each
fold is predicted from the minimum of the others.  A fit's model error on light it did not
see (:func:`held_out_error`, :mod:`~skyfit_mi.fitting.fit`) and the ranking of candidate
models (:mod:`~skyfit_mi.fitting.selection`, which runs fits) both hold frames out this way.
"""

import time

import numpy as np

from . import uncertainty as unc
from ..errors import SkyfitError
from .chi2 import Problem
from .methods.levenberg_marquardt import levenberg_marquardt


def frame_folds(valid, folds, ends=True):
    """(fit on, held out) masks of values ``valid`` (P, T) in K interleaved folds of frames
    (frame t in fold t mod K, K = min(``folds``, frames)); without ``ends``, the first and
    last frames with values are never held out (each fold's frames lie between fitted ones)."""
    T = valid.shape[1]
    held = np.arange(T) if ends else np.flatnonzero(valid.any(axis=0))[1:-1]
    k = min(int(folds), len(held))
    for f in range(k):
        test = np.isin(np.arange(T), held[np.arange(len(held)) % k == f])
        yield valid & ~test[None, :], valid & test[None, :]


#: Frames a fit needs at least for its held-out model error (:func:`held_out_error`), and
#: frames from which the first and last are held out too.  Below that, only frames between
#: fitted ones are: a fold without an end frame extrapolates the day from four, and under the
#: spec's own sky one disc fit of 8 (the quick sky test set, 5 frames) read a misfit of 6.4 per
#: held-out value (p 6e-14); held out between fitted frames, none of the 8 did, and two of the
#: Perez 4 sphere's four fits read their wrong sky's misfit (p 3e-5, 2e-6).
HELD_OUT_FRAMES, END_FRAMES_FROM = 5, 6
#: Folds of that check at most: each frame held out alone up to 16 frames (the nearest
#: test of the light between the fitted frames; four folds of two frames missed a rough gold
#: disc's misfit: kappa 0.017 against 0.197 frame by frame), interleaved beyond.
HELD_OUT_FOLDS = 16
#: The reach in the sun's (theta_h, theta_d) of a held-out frame's residual in a prediction's
#: model error (:func:`local_error_scale`) [degrees]: a frame's own angles (another camera
#: seeing them mirrored in time lies within a degree), its neighbours' on the day (6-7
#: apart) at a tenth of the weight.
ANGLE_REACH_DEG = 3.0
#: The weight of the fit's one kappa in a prediction's local model error, in frames: where no
#: held-out frame saw the prediction's angles, the error is that kappa.
KAPPA_FRAMES = 1.0


def held_out_error(problem, theta, lower, upper, folds=HELD_OUT_FOLDS, within=None,
                   frame_sd=None):
    """How well a fit at ``theta`` predicts frames it was not fitted to: each of ``folds``
    interleaved folds of ``problem``'s frames (each frame alone where there are no more; the
    first and last only from END_FRAMES_FROM frames) predicted from the others' minimum
    nearest the fit (Levenberg-Marquardt from ``theta`` within ``lower``/``upper``: a fifth of
    the time of a global search, and the same minimum on the days measured).

    What is predicted is what relight predicts: an image region's mean per frame and channel
    (its pixels see the light alike, so a highlight the model misses it misses in all of
    them), a table's every value.  Each held-out residual e [DN] has the variance of its
    noise (with the model's Monte Carlo error; a mean's from its values' taken as
    independent, plus an error that every value of a frame and channel shares, ``frame_sd``
    (3,) relative: a photographed frame's calibration) plus that of the prediction, D C D^T
    from the parameters' spread C on the other folds (linearised; D the prediction's
    derivatives).  The excess beyond these is the model's error on light it did not see:
    kappa by maximum likelihood (:func:`~.uncertainty.model_error`, no parameters fitted to
    these values), where the held-out chi-square exceeds them beyond chance (p < MISFIT_P).
    A model error fitted in-sample sees only the fitted frames' residuals, which the
    parameters bend to: Ward's lobe on a rough gold conductor passed through the highlights
    it was fitted on at chi2/dof 1.23 and missed the ones between them by 36-64%
    (BENCHMARKS, "Real surfaces").

    A fold whose parameters leave the fit's 95% intervals (``within`` (theta) False) lost
    frames the parameters depend on (a glossy paint's one highlight frame: its own lobe,
    fitted without it, missed it by 2.4x); its misses tell how the day was sampled, which the
    linearised spread cannot follow, not the model's error, and it is left out
    (``folds_outside``); so is a fold with fewer values than parameters to fit on or to hold
    out (``folds_too_small``).

    Returns {kappa, interval95 (only where kappa was fitted), chi2_per_value, p, values,
    folds, folds_outside, folds_too_small, level, wall_time_s}, and for an image region's
    means ``by_frame``: each frame's relative residuals e / a per channel held out
    (``held_out``; None where its fold was left out) and at the fit (``fitted``; the
    residuals of the frames whose folds were left out, a glossy paint's highlight, are often
    the largest), with their sd sqrt(v) / a (noise, and held out the prediction's spread;
    None where nothing was measured): :func:`local_error_scale` reads them.  None with fewer
    than HELD_OUT_FRAMES frames."""
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
    if es:
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
    """``problem``'s residuals at ``theta`` e [DN], their variances v (noise, the model's Monte
    Carlo error, ``frame_sd``'s shared error and, with the parameters' covariance ``cov``, the
    prediction's spread D cov D^T) and the values' scale a (each value's, or with ``means``
    each frame's and channel's mean), and where there are values (``use``)."""
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
    """Put residuals ``e`` and their sd sqrt(``v``) relative to the values' scale ``a`` into
    ``rel[key]`` and ``rel[key + '_sd']`` where ``use``."""
    rel[key][use], rel[f"{key}_sd"][use] = e[use] / a[use], np.sqrt(v[use]) / a[use]


def local_error_scale(by_frame, fit_angles, angles, kappa):
    """The model error of a prediction at the sun's angles ``angles`` [(theta_h, theta_d) per
    frame, degrees, None without sun] over the fit's one ``kappa``, per frame and channel
    (T, C): a model misses where its lobe or its diffuse cannot take the surface, at certain
    pairs of angles (the Fresnel rise and a non-Lambertian diffuse of a low sun in front of
    the camera), and by little elsewhere, so one relative error for every frame is too wide
    at most and too narrow at a few (docs/BENCHMARKS.md, "Bands in a new view").

    From the residuals of the fit's frames (``by_frame`` of :func:`held_out_error`, at the
    frames' ``fit_angles``): each frame's excess over its noise, max(e^2 - sd^2, 0), the larger
    of its held-out and its fitted one, weighted by exp(-d^2 / 2 ANGLE_REACH_DEG^2) at its
    distance d in angles from the prediction's, beside kappa^2 with weight KAPPA_FRAMES:
    kappa_local^2 = (sum w excess + KAPPA_FRAMES kappa^2) / (sum w + KAPPA_FRAMES).  Where no
    frame of the fit lies near (or the frame has no sun), the scale is 1; so it is
    everywhere for a fit without kappa or without residuals (edited ones are not read)."""
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
