"""A camera's own tone curve: how an in-camera JPEG departs from the curve it is read with.

Ingest reads integer codes with a response (thesis ch. 5, eq. 5.11; sRGB's by default for
8-bit files).  A
camera's JPEG engine applies its own tone curve instead (a brighter middle, compressed
highlights, a toe), so a value read as the linear signal s [fraction of full scale] stands
for a true signal s exp(-d(ln s)).  Calibrated on a grey reference at signal s_a, a value's
relative error is d(ln s) - d(ln s_a); with no reference (a given exposure) the curves meet at
full scale, d(0) = 0.  Here d is a random smooth function,

    d(t) = sum_j b_j phi_j(t),   phi_j(t) = P_j(x) - 1,   x = 1 - 2 t / T_MIN,

P_j the Legendre polynomials on t = ln s in [T_MIN, 0] (t below clipped), so phi_j(0) = 0, and b
~ N(0, M) with M = :data:`PRIOR_ROOT` :data:`PRIOR_ROOT`^T: the second moment (mean included) of
the weights fitted to cameras' measured JPEG curves (darktable's base-curve presets, each
measured from a camera's RAW and JPEG pairs; ``scripts/tone_curve_prior.py``), with a
floor.  The columns of PRIOR_ROOT are independent errors (one normal each, :func:`moves`).
Grey references at several levels (a ColorChecker's six) measure the weights
(:func:`fit_references`): their posterior replaces the prior.
"""

import warnings

import numpy as np
from numpy.polynomial import legendre

#: Least ln signal [ln of a fraction of full scale] of the basis, the least the prior was fitted
#: at (a camera's curve at lower codes is its toe, unmeasured); darker values take its value.
T_MIN = float(np.log(5e-3))
#: Degree of the basis (its functions P_1 ... P_DEGREE less 1).
DEGREE = 4
#: Root (DEGREE, E) [unitless] of the weights' prior second moment: the eigenvectors times the
#: root of the eigenvalues of the mean b b^T over the measured cameras' curves, each fitted by
#: least squares in ln signal over the codes' 0.5-90%, and a floor, an independent slope of
#: 0.18 in d per unit ln signal (on phi_1, linear in t), the least that holds 95% of each
#: camera's curve left out and of the makers' generic curves within 1.96 sd
#: (``scripts/tone_curve_prior.py``: 11 cameras; without the floor a left-out camera's held
#: 91-100%, 97.7% on average).  Calibrated at 18% of full scale, a value read at 10% errs by
#: an sd of 0.25 in ln, at 30% by 0.14, at 3% by 0.73: a camera's JPEG says little of a surface
#: much darker or brighter than its grey reference.
PRIOR_ROOT = np.array([[-0.0126, 0.0578, 0.0245, -0.6203, 0.4768],
                       [-0.0346, 0.0485, -0.0827, 0.3932, 0.0],
                       [-0.0215, 0.0098, 0.1583, 0.2725, 0.0],
                       [0.0465, 0.0564, 0.0184, 0.2500, 0.0]])


def basis(t):
    """phi (..., DEGREE) [unitless] at ln signal ``t`` (...,): zero at full scale (t = 0)."""
    x = 1.0 + 2.0 * np.clip(np.asarray(t, dtype=float), T_MIN, 0.0) / -T_MIN
    return np.stack([legendre.legval(x, np.eye(DEGREE + 1)[j]) - 1.0
                     for j in range(1, DEGREE + 1)], axis=-1)


def basis_slope(t):
    """d phi / d t (..., DEGREE) [unitless] at ln signal ``t`` (...,); 0 beyond [T_MIN, 0],
    where :func:`basis` holds its end value."""
    t = np.asarray(t, dtype=float)
    x = 1.0 + 2.0 * np.clip(t, T_MIN, 0.0) / -T_MIN
    inside = ((t >= T_MIN) & (t <= 0.0))[..., None]
    return np.where(inside, np.stack([legendre.legval(x, legendre.legder(np.eye(DEGREE + 1)[j]))
                                      for j in range(1, DEGREE + 1)], axis=-1) * 2.0 / -T_MIN,
                    0.0)


#: The least share of a value's sigma its error keeps in the true signal where a measured
#: curve reads it (:func:`reading`: (1 - slope) sigma) [unitless]: cameras' curves depart from
#: sRGB's by slopes of 0.1-0.5 in ln; near 1 the reading would call a value exact.
SLOPE_FLOOR = 0.25


def reading(t, anchor_basis, weights, span):
    """(The ln factor (...) by which a value at ln signal ``t`` (...) read through the response
    stands above the true signal under a curve that grey references measured (``weights`` of
    PRIOR_ROOT's columns, over the levels ``span`` (lo, hi), relative to the anchor's phi
    ``anchor_basis`` (..., DEGREE)): true = read exp(-factor), beyond ``span`` the factor at
    its nearest end (:func:`covered`); its slope d factor / d t (...), 0 beyond ``span``, by
    which the value's noise moves its own reading: a value's error of sigma is one of
    (1 - slope) sigma in the true signal.)"""
    t = np.asarray(t, dtype=float)
    w = PRIOR_ROOT @ np.asarray(weights, dtype=float)
    factor = (basis(np.clip(t, *span)) - np.asarray(anchor_basis, dtype=float)) @ w
    return factor, np.where(covered(t, span), basis_slope(t) @ w, 0.0)


#: Points of the table :func:`read_table` interpolates in.
TABLE_POINTS = 2048


def read_table(signal, anchor_basis, weights, span):
    """:func:`reading` (factor, slope; float32, the shape of ``signal``) of linear signals
    ``signal`` (..., C) [fraction of full scale] with channel c's anchor ``anchor_basis[c]``
    (C, DEGREE), interpolated linearly in a table of :data:`TABLE_POINTS` ln signals per channel
    over ``span`` (held beyond it, the slope 0 there; a signal of 0 or NaN takes the low end):
    whole images at a time, to 2e-7 of the direct reading."""
    lo, hi = span
    grid = np.linspace(lo, hi, TABLE_POINTS)
    factor = np.empty(np.shape(signal), np.float32)
    slope = np.empty(np.shape(signal), np.float32)
    for c in range(factor.shape[-1]):
        f_c, m_c = reading(grid, anchor_basis[c], weights, span)
        with np.errstate(divide="ignore", invalid="ignore"):
            pos = (np.log(signal[..., c]) - lo) * ((TABLE_POINTS - 1) / (hi - lo))
        inside = (pos >= 0) & (pos <= TABLE_POINTS - 1)              # NaN: neither
        pos = np.clip(np.nan_to_num(pos, nan=0.0), 0, TABLE_POINTS - 1)
        i = np.minimum(pos.astype(np.int32), TABLE_POINTS - 2)
        frac = pos - i
        factor[..., c] = f_c[i] * (1 - frac) + f_c[i + 1] * frac
        slope[..., c] = np.where(inside, m_c[i] * (1 - frac) + m_c[i + 1] * frac, 0.0)
    return factor, slope


def moves(t, anchor=0.0, root=None):
    """Each independent error's relative change (..., E) [unitless, at one sd] of a value at
    ln signal ``t`` (...,) calibrated at ln signal ``anchor`` (broadcast with ``t``; 0: full
    scale, for a given exposure): (phi(t) - phi(anchor)) @ ``root`` (default PRIOR_ROOT)."""
    return moves_from(t, basis(anchor), root)


def moves_from(t, anchor_basis, root=None):
    """:func:`moves` from the anchor's phi (..., DEGREE) itself (several references' mean,
    :func:`fit_references`)."""
    root = PRIOR_ROOT if root is None else np.asarray(root, dtype=float)
    return (basis(t) - np.asarray(anchor_basis, dtype=float)) @ root


def covered(t, span):
    """Whether ln signals ``t`` (...,) lie within ``span`` (lo, hi) [ln of a fraction of full
    scale], the levels grey references measured the curve at: between them the measured curve
    holds within its posterior; beyond, the four terms' extrapolation does not (a camera's toe
    and shoulder), and a value takes the curve's value at the nearest covered level with the
    prior's error (``scripts/tone_curve_prior.py``: read so, each measured camera left out
    holds 95% or more of its values within 1.96 sd)."""
    return (np.asarray(t) >= span[0]) & (np.asarray(t) <= span[1])


def frame_anchors(anchor_basis, frames):
    """The anchors' phi (F, 3, DEGREE) of ``frames`` (F,) from ``anchor_basis`` ({frame: (3,
    DEGREE) per channel, None entries where its references read none}; None: a given
    exposure, full scale): a frame without its own takes the others' mean (their scale, where
    its references were clipped)."""
    if anchor_basis is None:
        return np.zeros((len(frames), 3, DEGREE))
    known = np.array(list(anchor_basis.values()), dtype=float)              # (K, 3, DEGREE)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nan_to_num(np.nanmean(known, axis=0))
    phi = np.array([anchor_basis.get(str(i), np.full((3, DEGREE), np.nan)) for i in frames],
                   dtype=float)
    return np.where(np.isfinite(phi), phi, mean)


def relative_sd(t, anchor=0.0, root=None):
    """The sd (...,) [unitless] of the relative error of a value at ln signal ``t`` calibrated
    at ``anchor`` (:func:`moves`)."""
    return np.sqrt(np.sum(np.square(moves(t, anchor, root)), axis=-1))


#: The least relative error [unitless] of a reference's ln exposure in the curve's fit from
#: several greys (:func:`fit_references`): a chart's greys depart from their published
#: reflectances by 1-2% with its batch and age.
REFERENCE_FLOOR = 0.015
#: The least share of the prior's sd the curve's error keeps however many references measure
#: it [unitless]: the basis's own residual on the measured cameras' curves (median rms 0.067 in
#: ln, ``scripts/tone_curve_prior.py``) over the prior's sd a factor of two from a reference
#: (0.25): between the references' levels the four terms cannot follow a curve exactly. The
#: script's check (each measured camera left out and the makers' curves, measured by a
#: three-card set or a ColorChecker's greys over 13 frames, read as :func:`covered` says) finds
#: 0.23 the least holding 95% of each; 0.27 keeps a margin.
POSTERIOR_FLOOR = 0.27


def fit_references(t, ratio, sd, root=None, anchor_weight=None, floor=POSTERIOR_FLOOR):
    """The curve's weights from grey references at several levels: (weights w (E,), their
    posterior root L (E, E): w = weights + L z, z ~ N(0, 1); anchors (G, DEGREE): each
    group's mean phi weighted by ``anchor_weight`` (G, K) (as its exposure weighed its
    references; default 1 / sd^2), where its calibration holds, NaN where it read none;
    chi-square per dof).

    ``t`` (G, K) each group's (a frame and channel) K references' ln signal [ln of a fraction
    of full scale], ``ratio`` (G, K) their ln exposure read (ln of signal over reflectance
    times light; NaN where unread), ``sd`` (G, K) its error, floored at REFERENCE_FLOOR. Each
    group's exposure is free (profiled); ln ratio = c_g + phi(t) root w under w ~ N(0, 1)
    (the prior's). Where the references disagree beyond their errors the posterior widens by
    the chi-square per dof (at least 1), and it keeps ``floor``^2 of the prior."""
    root = PRIOR_ROOT if root is None else np.asarray(root, dtype=float)
    t, ratio = np.asarray(t, dtype=float), np.asarray(ratio, dtype=float)
    ok = np.isfinite(t) & np.isfinite(ratio)
    w = np.where(ok, 1.0 / np.maximum(np.nan_to_num(np.asarray(sd, dtype=float), nan=1.0),
                                      REFERENCE_FLOOR) ** 2, 0.0)
    A = basis(np.where(ok, t, 0.0)) @ root                                  # (G, K, E)
    wsum = np.maximum(w.sum(axis=1, keepdims=True), 1e-300)
    aw = w if anchor_weight is None else np.where(ok, np.nan_to_num(anchor_weight), 0.0)
    anchors = np.einsum("gk,gkd->gd", aw, basis(np.where(ok, t, 0.0))) \
        / np.maximum(aw.sum(axis=1, keepdims=True), 1e-300)
    anchors[~(aw > 0).any(axis=1)] = np.nan               # a group with no reference read
    Ac = A - np.einsum("gk,gke->ge", w, A)[:, None, :] / wsum[..., None]      # offsets profiled
    rc = np.where(ok, ratio, 0.0) - np.sum(w * np.where(ok, ratio, 0.0), axis=1,
                                           keepdims=True) / wsum
    H = np.einsum("gk,gke,gkf->ef", w, Ac, Ac)
    g = np.einsum("gk,gke,gk->e", w, Ac, rc)
    E = root.shape[1]
    weights = np.linalg.solve(H + np.eye(E), g)
    res = rc - Ac @ weights
    dof = max(int(ok.sum()) - int(np.sum(ok.any(axis=1))), 1)
    chi2 = float(np.sum(w * res ** 2)) / dof
    cov = np.linalg.inv(H / max(chi2, 1.0) + np.eye(E))
    cov = (1.0 - floor ** 2) * cov + floor ** 2 * np.eye(E)
    val, vec = np.linalg.eigh((cov + cov.T) / 2)
    return weights, vec * np.sqrt(np.clip(val, 0.0, None)), anchors, chi2
