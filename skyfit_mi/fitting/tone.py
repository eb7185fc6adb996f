"""A camera's own tone curve in the fit: each value's move at one sd of each independent error of
the curve's prior (:mod:`skyfit_mi.physics.tone_curve`), taken as rows of the calibration's
errors (:func:`tone_rows`), or, where the light is fitted, among the light's coefficients
(:func:`tone_count`; :meth:`~.fit.FitSession.set_sky` reads each value's gain through the
curve at those weights). A curve that greys of several levels measured reads every value
(:func:`curve_reading`, in :func:`~.chi2.load_observations`)."""

import warnings

import numpy as np

from . import uncertainty as unc
from ..errors import SkyfitError
from ..physics import tone_curve


def _from_anchor(doc, obs, codes):
    """(the ``ingest.tone_curve`` record, t (..., T, C), the anchors' phi (T, C, DEGREE)) of
    values at ``codes`` (..., T, C) [DN] of ``obs``'s frames: t their ln signal as the response
    reads it (NaN without a signal), each anchor its frame's (where its references calibrate
    it; a frame whose references were clipped took the others' scale, so their mean anchor;
    full scale for a given exposure). None where the ingest counted no curve."""
    rec = (doc.get("ingest") or {}).get("tone_curve")
    if obs.rays is not None or not rec:
        return None
    with np.errstate(all="ignore"):
        t = np.log(obs.sensor.linearise(np.asarray(codes, dtype=float)))
    return rec, np.where(np.isfinite(t), t, np.nan), \
        tone_curve.frame_anchors(rec.get("anchor_basis"), obs.frames)


def _moves(t, phi):
    """The prior's moves (..., E) of values at ln signal ``t`` (NaN: no signal, no move) from
    anchors ``phi``: (phi(t) - anchor) PRIOR_ROOT."""
    ok = np.isfinite(t)
    return np.where(ok[..., None], tone_curve.basis(np.where(ok, t, 0.0)) - phi, 0.0) \
        @ tone_curve.PRIOR_ROOT


def curve_reading(doc, obs):
    """(The ln factor (P, T, C) [unitless] by which each of ``obs``'s values, read through the
    response at its own code, stands above the true signal under the camera's own tone curve
    that grey references of several levels measured, relative to its frame's anchor
    (``ingest.tone_curve.weights``; beyond their levels at the nearest,
    :func:`~skyfit_mi.physics.tone_curve.reading`): true = read exp(-factor); and its slope
    (P, T, C), by which each value's sigma is one of (1 - slope) sigma in the true signal.)
    None where none was measured."""
    found = _from_anchor(doc, obs, obs.y)
    if found is None or not found[0].get("weights"):
        return None
    rec, t, phi = found
    if rec.get("measured_ln_signal") is None:
        raise SkyfitError("the sequence was ingested before skyfit read each value through the "
                          "tone curve its grey references measured (its manifest's "
                          "ingest.tone_curve has weights but no measured_ln_signal); ingest the "
                          "photographs again.")
    ok = np.isfinite(t)
    factor, slope = tone_curve.reading(np.where(ok, t, 0.0), phi, rec["weights"],
                                       rec["measured_ln_signal"])
    return np.where(ok, factor, 0.0), np.where(ok, slope, 0.0)


def level_tone(doc, obs, codes, own=None):
    """The moves (..., T, C, E) [unitless] of values at ``codes`` (..., T, C) [DN] of ``obs``'s
    frames under a camera's own tone curve (:mod:`~skyfit_mi.physics.tone_curve`; ``doc``'s
    ``ingest.tone_curve``), each relative to its frame's anchor: its relative change at one sd
    of each independent error the curve's prior leaves, or, within the levels references
    measured it at, its posterior (:func:`curve_reading` reads the values through that curve).
    ``own`` (..., T, C) [DN]: the values' own codes, which decide whether each lies within
    those levels, and beyond them its prior's moves there. None where the ingest counted no
    curve."""
    found = _from_anchor(doc, obs, codes)
    if found is None:
        return None
    rec, t, phi = found
    move = _moves(t, phi)
    if not rec.get("root"):
        return move
    span = rec.get("measured_ln_signal") or (-np.inf, np.inf)
    move = np.where(tone_curve.covered(t, span)[..., None],
                    move @ np.asarray(rec["root"], dtype=float), move)
    if own is None:
        return move
    _, t_own, _ = _from_anchor(doc, obs, own)
    return np.where(tone_curve.covered(t_own, span)[..., None], move, _moves(t_own, phi))


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
    """:func:`level_tone`'s moves (P, T, C, E) of session ``s``'s values at the region's
    :func:`median_codes` (beyond the levels references measured the curve at, each at its own
    code), None where its ingest counted no curve."""
    move = level_tone(s.doc, s.obs, median_codes(s.obs), own=s.obs.y)
    return None if move is None else np.broadcast_to(move, s.obs.y.shape + move.shape[-1:])


def tone_level_rows(doc, obs, groups, n, names, theta):
    """Signed rows (n, 2 E, names) a per-pixel map's ``n`` fits (each pixel's ``groups``) take
    from a camera's own tone curve's prior: each error moves a fit's level as the mean over its
    frames of its values' move (:func:`level_tone` at the group's median codes), through
    :func:`~.uncertainty.level_rows` (every channel at once); none (n, 0, names) where the
    ingest counted no curve."""
    codes = np.stack([median_codes(obs, groups == g)[0] for g in range(n)])       # (n, T, C)
    move = level_tone(doc, obs, codes)
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
                          s.tone, curvature_inverse)
