"""A camera's own tone curve in the fit: each value's move at one sd of each independent error of
the curve's prior (:mod:`skyfit_mi.physics.tone_curve`), taken as rows of the calibration's
errors (:func:`tone_rows`), or, where the light is fitted, among the light's coefficients
(:func:`tone_count`; :meth:`~.fit.FitSession.set_sky` reads each value's gain through the
fitted curve)."""

import warnings

import numpy as np

from . import uncertainty as unc
from ..physics import tone_curve


def level_moves(doc, obs, codes):
    """The relative change (..., T, C, E) at one sd of each independent error of a camera's own
    tone curve (:func:`~skyfit_mi.physics.tone_curve.moves`) of values at ``codes`` (..., T, C)
    [DN] of ``obs``'s frames, each calibrated at its frame's anchor (``doc``'s
    ``ingest.tone_curve``; a frame whose references were clipped took the others' scale, so
    their mean anchor); None where the ingest counted no curve. A value without a signal
    moves by 0."""
    rec = (doc.get("ingest") or {}).get("tone_curve")
    if obs.rays is not None or not rec:
        return None
    with np.errstate(all="ignore"):
        t = np.log(obs.sensor.linearise(np.asarray(codes, dtype=float)))
    anchors = rec.get("anchor_ln_signal")
    if anchors is None:                                  # a given exposure: at full scale
        a = np.zeros((len(obs.frames), 3))
    else:
        known = np.array([[np.nan if v is None else v for v in x] for x in anchors.values()])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mean = np.nanmean(known, axis=0)
        a = np.array([[np.nan if v is None else v for v in anchors.get(str(i), [None] * 3)]
                      for i in obs.frames], dtype=float)
        a = np.where(np.isfinite(a), a, mean)
    ok = np.isfinite(t + a)
    move = tone_curve.moves(np.where(ok, t, 0.0), np.where(ok, a, 0.0))
    return np.where(ok[..., None], move, 0.0)


def median_codes(y):
    """The median code (1, T, C) [DN] of values ``y`` (P, T, C) in each frame and channel: a
    region's level, by which its values move (a move read from each value's own noise would
    let a fitted curve follow it)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)          # a frame with no value
        return np.nanmedian(y, axis=0, keepdims=True)


def tone_moves(s):
    """Each value's relative change (P, T, C, E) from a camera's own tone curve
    (:func:`level_moves` at the region's :func:`median_codes`) of session ``s``, None where
    its ingest counted no curve."""
    move = level_moves(s.doc, s.obs, median_codes(s.obs.y))
    return None if move is None else np.broadcast_to(move, s.obs.y.shape + move.shape[-1:])


def tone_level_rows(doc, obs, groups, n, names, theta):
    """Signed rows (n, 2 E, names) a per-pixel map's ``n`` fits (each pixel's ``groups``) take
    from a camera's own tone curve's prior: each error moves a fit's level as the mean over its
    frames of its values' move (:func:`level_moves` at the group's median codes), through
    :func:`~.uncertainty.level_rows` (every channel at once); none (n, 0, names) where the
    ingest counted no curve."""
    codes = np.stack([median_codes(obs.y[groups == g])[0] for g in range(n)])   # (n, T, C)
    move = level_moves(doc, obs, codes)
    if move is None:
        return np.zeros((n, 0, len(names)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        u = np.nan_to_num(np.nanmean(np.where(np.isfinite(codes)[..., None], move, np.nan),
                                     axis=1))                                      # (n, C, E)
    return np.concatenate([unc.level_rows(u[..., e], names, theta, independent=False)
                           for e in range(u.shape[-1])], axis=-2)


def tone_count(sessions):
    """The independent errors of a camera's own tone curve a joint fit of the light takes
    among its coefficients: every one (:data:`~skyfit_mi.physics.tone_curve.PRIOR_ROOT`'s
    columns) where every region's ingest counted the curve, else none."""
    counted = all(tone_moves(s) is not None for s in sessions)
    return tone_curve.PRIOR_ROOT.shape[1] if sessions and counted else 0


#: What the tone curve's share of a fit's intervals is (the fit JSON's ``tone_curve_error``).
TONE_NOTE = ("the standard error each parameter takes from the camera's own JPEG tone curve, "
             "read as the response's (ingest.tone_curve): cameras' measured curves depart from "
             "sRGB's by tens of per cent between a grey reference's codes and a much brighter "
             "or darker surface's (skyfit_mi.physics.tone_curve). Where the light is fitted (the "
             "photographs' default) the curve is fitted with it from every region's values and "
             "this is its block of the light's share; under the spec's light, its prior's, "
             "among the calibration's errors. RAW files, several greys with ingest --response "
             "fit, or ingest --exact-curve for codes written from linear values take it out")


def tone_rows(s, J, problem, usable, theta, curvature_inverse):
    """Signed rows (E, n) from a camera's own tone curve (:func:`tone_moves`): each
    independent error of its prior moves each value by its move, one error for every frame and
    channel (:func:`~.uncertainty.shared_error_rows`); none where the ingest counted none, or
    where a joint fit of the light took the curve among its coefficients (``s.tone_weights``:
    the fitted light's share carries it)."""
    n = len(s.names)
    move = tone_moves(s)
    if move is None or s.tone_weights is not None:
        return np.zeros((0, n))
    Js = J * problem.value_scale(theta)[..., None]
    P, T, C, _ = J.shape
    flat = (P * T, 1, C, n)
    return np.concatenate([unc.shared_error_rows((Js * move[..., e, None]).reshape(flat),
                                                 usable.reshape(flat[:3]),
                                                 problem.obs.sigma.reshape(flat[:3]), [[1.0]],
                                                 np.ones((C, 1)), curvature_inverse)
                           for e in range(move.shape[-1])])
