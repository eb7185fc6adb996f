"""A camera's own tone curve in the fit: each value's move at one sd of each independent error of
the curve's prior (:mod:`skyfit_mi.physics.tone_curve`), taken as rows of the calibration's
errors (:func:`tone_rows`), or, where the light is fitted, among the light's coefficients
(:func:`tone_count`; :meth:`~.fit.FitSession.set_sky` reads each value's gain through the
fitted curve)."""

import warnings

import numpy as np

from . import uncertainty as unc
from ..physics import tone_curve


def level_tone(doc, obs, codes):
    """(base (..., T, C), moves (..., T, C, E)) of values at ``codes`` (..., T, C) [DN] of
    ``obs``'s frames read through a camera's own tone curve (:mod:`~skyfit_mi.physics.
    tone_curve`; ``doc``'s ``ingest.tone_curve``), each relative to its frame's anchor (where
    its references calibrate it; a frame whose references were clipped took the others'
    scale, so their mean anchor; full scale for a given exposure): base, the ln change the
    curve its references measured gives it (0 from one grey); moves, its relative change at
    one sd of each independent error left. None where the ingest counted no curve; a value
    without a signal 0."""
    rec = (doc.get("ingest") or {}).get("tone_curve")
    if obs.rays is not None or not rec:
        return None
    with np.errstate(all="ignore"):
        t = np.log(obs.sensor.linearise(np.asarray(codes, dtype=float)))
    anchors = rec.get("anchor_basis")
    if anchors is None:                                  # a given exposure: at full scale
        phi = np.zeros((len(obs.frames), 3, tone_curve.DEGREE))
    else:
        known = np.array(list(anchors.values()), dtype=float)              # (F, 3, DEGREE)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mean = np.nan_to_num(np.nanmean(known, axis=0))
        phi = np.array([anchors.get(str(i), np.full((3, tone_curve.DEGREE), np.nan))
                        for i in obs.frames], dtype=float)
        phi = np.where(np.isfinite(phi), phi, mean)
    root = tone_curve.PRIOR_ROOT
    weights = np.asarray(rec.get("weights") or np.zeros(root.shape[1]), dtype=float)
    posterior = np.asarray(rec["root"], dtype=float) if rec.get("root") else np.eye(len(weights))
    ok = np.isfinite(t)
    dphi = np.where(ok[..., None], tone_curve.basis(np.where(ok, t, 0.0)) - phi, 0.0)
    return dphi @ root @ weights, dphi @ root @ posterior


def median_codes(obs, rows=slice(None)):
    """The median code (1, T, C) [DN] of ``obs``'s values (of pixels ``rows``) in each frame and
    channel, of those usable (a finite sigma: not clipped, mixed or missing): a region's level,
    by which its values move (a move read from each value's own noise would let a fitted
    curve follow it)."""
    y = np.where(np.isfinite(obs.sigma), obs.y, np.nan)[rows]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)          # a frame with no value
        return np.nanmedian(y, axis=0, keepdims=True)


def region_tone(s):
    """:func:`level_tone` (base (P, T, C), moves (P, T, C, E)) of session ``s``'s values at the
    region's :func:`median_codes`, None where its ingest counted no curve."""
    tone = level_tone(s.doc, s.obs, median_codes(s.obs))
    if tone is None:
        return None
    base, move = tone
    return (np.broadcast_to(base, s.obs.y.shape),
            np.broadcast_to(move, s.obs.y.shape + move.shape[-1:]))


def tone_level_rows(doc, obs, groups, n, names, theta):
    """Signed rows (n, 2 E, names) a per-pixel map's ``n`` fits (each pixel's ``groups``) take
    from a camera's own tone curve's prior: each error moves a fit's level as the mean over its
    frames of its values' move (:func:`level_tone` at the group's median codes), through
    :func:`~.uncertainty.level_rows` (every channel at once); none (n, 0, names) where the
    ingest counted no curve."""
    codes = np.stack([median_codes(obs, groups == g)[0] for g in range(n)])       # (n, T, C)
    tone = level_tone(doc, obs, codes)
    if tone is None:
        return np.zeros((n, 0, len(names)))
    move = tone[1]
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
    counted = all(s.tone is not None for s in sessions)
    return tone_curve.PRIOR_ROOT.shape[1] if sessions and counted else 0


#: What the tone curve's share of a fit's intervals is (the fit JSON's ``tone_curve_error``).
TONE_NOTE = ("the standard error each parameter takes from the camera's own JPEG tone curve, "
             "read as the response's (ingest.tone_curve): cameras' measured curves depart from "
             "sRGB's by tens of per cent between a grey reference's codes and a much brighter "
             "or darker surface's (skyfit_mi.physics.tone_curve), less where greys of several "
             "reflectances measured it. Where the light is fitted (the photographs' default) "
             "the curve's weights, held at 0, are among its coefficients, and this is their "
             "share through it and directly; under the spec's light, its rows among the "
             "calibration's errors. "
             "RAW files, greys of several reflectances, or ingest --exact-curve for codes "
             "written from linear values narrow it")


def tone_rows(s, J, problem, usable, theta, curvature_inverse):
    """Signed rows (E, n) from a camera's own tone curve (``s.tone``, :func:`region_tone`): each
    independent error of its prior moves each value by its move
    (:func:`~.uncertainty.moved_rows`); none where the ingest counted none, or where a joint
    fit of the light took the curve among its coefficients (``s.tone_weights``: the fitted
    light's share carries it)."""
    if s.tone is None or s.tone_weights is not None:
        return np.zeros((0, len(s.names)))
    return unc.moved_rows(J * problem.value_scale(theta)[..., None], usable, problem.obs.sigma,
                          s.tone[1], curvature_inverse)
