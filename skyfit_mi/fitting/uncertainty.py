"""Uncertainty of fitted parameters and whether the data determine them (thesis 6.3).

Two estimates: the profile chi-square (sigma_alpha and rho_s, :mod:`.methods.profile`), where the
minimum of chi^2 over the other parameters stays within Delta = 1 (68%) or 3.84 (95%) of its
minimum; and the covariance C = (J^T J)^-1 at the optimum, intervals +- 1 and 1.96 sd.

Where chi^2 exceeds noise beyond chance (p < MISFIT_P) the model's error is fitted
(:func:`model_error`); any remaining excess widens both by the Birge ratio s^2. The light cache's
Monte Carlo error is added in quadrature, and the profile threshold raised by its chi^2 ripple.
"""

from dataclasses import dataclass

import numpy as np
from scipy.special import chdtrc, ndtr, ndtri

from ..physics.camera import SensorModel
from ..physics.ward import METAL_THRESHOLD, colour_rule_twin

LEVELS = {"68": 1.0, "95": 3.841458820694124}
Z = {"68": 1.0, "95": 1.959963984540054}


#: chi2/dof above which (and significant) a fit's parameters are called unreliable.
MISFIT_UNRELIABLE = 1.5
#: p-value of chi-square below which misfit is reported.
MISFIT_P = 1e-3


def scale(chi2, expected):
    """The Birge ratio s^2 = max(1, chi^2 / expected), ``expected`` noise's chi^2."""
    return max(1.0, chi2 / expected) if expected > 0 else 1.0


def covariance(J, s2=1.0):
    """Parameter covariance s^2 (J^T J)^-1 (pseudo-inverse when singular)."""
    a = J.T @ J
    try:
        c = np.linalg.inv(a)
        if not np.all(np.isfinite(c)):
            raise np.linalg.LinAlgError
    except np.linalg.LinAlgError:
        c = np.linalg.pinv(a)
    return c * s2


def channel_factors(r, J, usable, in_chi2=None):
    """Per parameter, the factor f^2 >= 1 by which correlated errors of a value's R, G and B
    widen its variance, and the channels' correlation R (C, C) it comes from.

    ``r`` (P, T, C) residuals, ``J`` (P, T, C, n) their derivatives, ``usable`` (P, T, C) the
    measured values, ``in_chi2`` those in chi-square (default ``usable``). R is the residuals'
    correlation between measured channels (zero unless above 2 / sqrt(n)); the covariance is the
    sandwich (J^T J)^-1 J^T R J (J^T J)^-1 and f^2 its diagonal over (J^T J)^-1's (eq. 6.11's
    when R = I; docs/BENCHMARKS.md, "Errors shared by a pixel's channels").
    """
    n_par = J.shape[-1]
    C = r.shape[-1]
    in_chi2 = usable if in_chi2 is None else in_chi2
    R = np.eye(C)
    for i in range(C):
        for j in range(i + 1, C):
            both = usable[..., i] & usable[..., j]
            n = int(both.sum())
            if n < 10:
                continue
            a, b = r[..., i][both], r[..., j][both]
            rho = float(np.sum(a * b) / max(np.sqrt(np.sum(a * a) * np.sum(b * b)), 1e-300))
            if abs(rho) > 2.0 / np.sqrt(n):
                R[i, j] = R[j, i] = rho
    w, v = np.linalg.eigh(R)
    R = (v * np.clip(w, 0.0, None)) @ v.T                      # positive semi-definite
    # every chi-square value in the curvature; correlation between measured ones only
    Jall = np.where(in_chi2[..., None], J, 0.0).reshape(-1, C, n_par)
    Jz = np.where(usable[..., None], J, 0.0).reshape(-1, C, n_par)
    Hi = covariance(Jall.reshape(-1, n_par))
    M = Jall.reshape(-1, n_par).T @ Jall.reshape(-1, n_par) \
        + np.einsum("nck,cd,ndl->kl", Jz, R - np.eye(C), Jz)
    with np.errstate(all="ignore"):
        f2 = np.diag(Hi @ M @ Hi) / np.diag(Hi)
    return np.where(np.isfinite(f2), np.maximum(f2, 1.0), 1.0), R


def covariance_intervals(theta, cov, lower, upper):
    """{level: (lo, hi) arrays} from the covariance, clipped to the bounds."""
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    return {lv: (np.clip(theta - z * sd, lower, upper), np.clip(theta + z * sd, lower, upper))
            for lv, z in Z.items()}


#: Gauss-Hermite nodes over which :func:`band_half_width` averages an uncertain model error.
KAPPA_NODES = 24


def band_half_width(variance, value, kappa, interval95=None, level=0.95):
    """The half-width of the central ``level`` band of a new value's error, Gaussian of variance
    ``variance`` + (kappa ``value``)^2; with ``interval95`` averaged over a log-normal kappa
    (Gauss-Hermite nodes)."""
    variance, value = np.broadcast_arrays(np.asarray(variance, float), np.asarray(value, float))
    z = float(ndtri(0.5 + level / 2))
    if not kappa or interval95 is None:
        return z * np.sqrt(variance + (kappa * value) ** 2)
    lo, hi = (float(x) for x in interval95)
    x, w = np.polynomial.hermite_e.hermegauss(KAPPA_NODES)        # standard normal nodes
    w = w / w.sum()
    spread = np.where(x < 0, np.log(kappa / lo) if lo > 0 else np.log(hi / kappa),
                      np.log(hi / kappa)) / Z["95"]
    kappas = kappa * np.exp(spread * x)
    sds = np.sqrt(variance[..., None] + (kappas * value[..., None]) ** 2)   # (..., nodes)

    def outside(h):
        return np.sum(w * 2.0 * ndtr(-h[..., None] / sds), axis=-1)
    a, b = np.zeros(variance.shape), z * sds.max(axis=-1) * 2.0      # bisection on h
    for _ in range(60):
        mid = 0.5 * (a + b)
        big = outside(mid) > 1.0 - level
        a, b = np.where(big, mid, a), np.where(big, b, mid)
    return 0.5 * (a + b)


def widen(value, interval, extra, lower, upper):
    """(lo, hi) with ``extra`` added in quadrature to each half-width, clipped to the bounds."""
    lo, hi = interval
    return (float(max(lower, value - np.hypot(max(value - lo, 0.0), extra))),
            float(min(upper, value + np.hypot(max(hi - value, 0.0), extra))))


def widen_relative(value, interval, extra, lower, upper):
    """(lo, hi) with a relative error ``extra`` (z times an sd of log value) added in quadrature
    to each side's log half-width (a factor's interval is lopsided), clipped to the bounds."""
    value, lo, hi, extra = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (
        value, *interval, extra)))
    moved = (value > 0) & (extra > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        down = np.where(moved & (lo > 0), np.log(value / lo), np.inf)
        up = np.where(moved & (hi > value), np.log(hi / value), 0.0)
        new_lo = np.where(moved, np.maximum(lower, value * np.exp(-np.hypot(down, extra))), lo)
        new_hi = np.where(moved, np.minimum(upper, value * np.exp(np.hypot(up, extra))), hi)
    if new_lo.ndim == 0:
        return float(new_lo), float(new_hi)
    return new_lo, new_hi


def rows_sd(rows):
    """The standard errors (..., n) of independent errors given as signed ``rows`` (..., E, n):
    each row one error's effect on the parameters at one sd of it."""
    return np.sqrt(np.sum(np.square(rows), axis=-2))


def level_rows(u, names, theta, independent=True):
    """Signed rows (..., E, n) (:func:`rows_sd`) from a relative error ``u`` (3,) or (G, 3) of
    the values per channel: C_c by its channel's, R and rho_s by the rms, roughness none. Each
    channel's error its own row where they are ``independent`` (the level a grey card's pixels
    measure in each channel); else one row, every channel's moving together (the card's stated
    reflectance, a lens falloff). rho_s moves with the level where it is a reflectance (the
    colour model's plastic, thesis 7.1: its highlight rho_s itself); elsewhere a fraction of R
    or C that a level leaves (diffuse R (1 - rho_s), highlight R rho_s), its share an
    independent row of its own, as wide."""
    u = np.asarray(u, dtype=float)
    theta = np.asarray(theta, dtype=float)
    rms = np.sqrt(np.mean(u ** 2, axis=-1))[..., None]
    if independent:
        channel = u[..., :, None] * np.eye(3)                            # (..., 3 rows, 3)
        grey = u / np.sqrt(3.0)
    else:
        channel, grey = u[..., None, :], rms
    if "rho_s" in names:
        absolute = ("C_r" in names) & (theta[..., list(names).index("rho_s")] < METAL_THRESHOLD)
        absolute = np.asarray(absolute)[..., None]
    else:
        absolute = np.ones(rms.shape, dtype=bool)
    zero = np.zeros_like(grey)
    rel = {"C_r": channel[..., 0], "C_g": channel[..., 1], "C_b": channel[..., 2], "R": grey,
           "rho_s": np.where(absolute, grey, 0.0)}
    own = {"rho_s": np.where(absolute, 0.0, rms)}                        # (..., 1)
    together = np.stack(np.broadcast_arrays(*(rel.get(p, zero) for p in names)), -1)
    apart = np.stack(np.broadcast_arrays(*(own.get(p, np.zeros_like(rms)) for p in names)), -1)
    lead = np.broadcast_shapes(together.shape[:-2], apart.shape[:-2], theta.shape[:-1])
    rows = np.concatenate([np.broadcast_to(a, lead + a.shape[-2:]) for a in (together, apart)],
                          axis=-2)
    return rows * np.abs(theta)[..., None, :]


def _no_rows(theta):
    """No rows (..., 0, n) for parameters ``theta`` (..., n)."""
    return np.zeros(np.shape(theta)[:-1] + (0, np.shape(theta)[-1]))


def reference_rows(doc, names, theta):
    """Signed rows (..., 1, n) from the error of the references' reflectances (``ingest
    --calibrate NAME=RHO+-SD``), which sets the level of every fitted reflectance at once;
    none without one."""
    u = ((doc.get("ingest") or {}).get("calibration") or {}).get("reference_relative_sd")
    return level_rows(u, names, theta, independent=False) if u else _no_rows(theta)


def vignetting_error(doc, pixels):
    """The signed relative error (P,) of the exposure carried from the references' place (else
    the image's centre, where a given exposure holds) to each of ``pixels`` (P, 2) (x, y) of
    photographs whose lens falloff was not corrected (``ingest --vignetting none``): half the
    cos^4 falloff (thesis eq. 5.6) between the two places, so that the 95% interval of a group
    of pixels (its mean's size) takes in a lens with none (or a camera that corrected it) and
    one with cos^4's; zeros otherwise."""
    ingest = doc.get("ingest") or {}
    pixels = np.asarray(pixels)
    if (ingest.get("options") or {}).get("vignetting") != "none" or "photos" not in ingest \
            or pixels.ndim != 2 or pixels.dtype.kind not in "iu":
        return np.zeros(len(pixels))
    cal = ingest.get("calibration") or {}
    if cal.get("references") and "reference_falloff" not in cal:
        return np.zeros(len(pixels))        # an older ingest: the references' place unknown
    cam = doc["camera"]
    f = SensorModel.falloff(cam["width"], cam["height"], cam["fov_deg"], pixels)
    return 0.5 * (1.0 - f / float(cal.get("reference_falloff", 1.0)))


def region_vignetting(doc, pixels):
    """The relative error of a group of ``pixels``' exposure from an uncorrected falloff: the
    size of their :func:`vignetting_error`'s mean (0 for a table's points)."""
    return abs(float(np.mean(vignetting_error(doc, pixels)))) \
        if pixels is not None and len(pixels) else 0.0


def shared_level_rows(doc, names, theta, vignetting=0.0):
    """Signed rows (..., E, n) from errors of the level every frame shares: the references'
    reflectances' (:func:`reference_rows`) and the uncorrected falloff's relative error
    ``vignetting`` (a number, or (G,); :func:`vignetting_error`), each on every channel."""
    theta = np.asarray(theta, dtype=float)
    v = np.asarray(vignetting, dtype=float)[..., None] * np.ones(3)
    return np.concatenate([reference_rows(doc, names, theta),
                           level_rows(v, names, theta, independent=False)], axis=-2)


def calibration_rows(doc, names, theta, vignetting=0.0):
    """Signed rows (..., E, n) from the calibration's relative error per channel, each
    channel's its own (:func:`level_rows`), and the errors of the level every frame shares
    (:func:`shared_level_rows`)."""
    theta = np.asarray(theta, dtype=float)
    u = ((doc.get("ingest") or {}).get("calibration") or {}).get("scale_relative_sd")
    scale = level_rows(u, names, theta) if u else _no_rows(theta)
    return np.concatenate([scale, shared_level_rows(doc, names, theta, vignetting)], axis=-2)


def colour_matrix_sd(doc, names, theta):
    """The standard error per parameter of ``names`` at ``theta`` (n,) or (G, n) that the colour
    matrix gives a single pixel's fit (a region's: :func:`~.intervals.matrix_rows`). Each entry
    E_cj errs by ``ingest.colour_matrix.relative_sd``, and channel c, calibrated on a grey,
    reads L_c + sum_(j != c) E_cj (L_j - L_c); so C_c errs by relative_sd sqrt(sum_(j != c)
    (C_j - C_c)^2) (a bound for glossy pixels). Zeros for other parameters and models."""
    theta = np.asarray(theta, dtype=float)
    rel = ((doc.get("ingest") or {}).get("colour_matrix") or {}).get("relative_sd")
    out = np.zeros(theta.shape)
    if not rel or "C_r" not in names:
        return out
    i = [list(names).index(p) for p in ("C_r", "C_g", "C_b")]
    C = theta[..., i]                                                    # (..., 3)
    out[..., i] = float(rel) * np.sqrt(np.sum((C[..., None, :] - C[..., :, None]) ** 2,
                                              axis=-1))
    return out


def shared_error_rows(J, usable, sigma, shared_sd, mixing, curvature_inverse, loading=None):
    """Signed rows (E, n) (:func:`rows_sd`) from errors every value of a region shares within a
    frame (e.g. a JPEG's block rounding), which chi-square would let shrink as 1 / sqrt(pixels).

    ``J`` (P, T, C, n), ``usable`` and ``sigma`` (P, T, C), ``shared_sd`` (T, K) each frame's
    independent shared errors' sds, ``mixing`` (C, K) how each reaches the channels. With
    g = sum over the frame's values of J mixing / sigma times the error's sd, each error's row
    is g^T (J^T J)^-1 (``curvature_inverse`` = (J^T J)^-1), the parameters' least-squares
    response to it (up to its sign, which no single row's draws need). Errors that several
    frames share: ``loading`` (E, T), how each of E independent errors reaches the frames (g
    summed over them), ``shared_sd`` then the same for every frame."""
    w = np.where(usable[..., None], J / np.where(usable, sigma, np.inf)[..., None], 0.0)
    g = np.einsum("ptcn,ck->tkn", w, np.asarray(mixing, dtype=float))      # (T, K, n)
    g = g * np.asarray(shared_sd, dtype=float)[..., None]
    if loading is not None:
        g = np.einsum("et,tkn->ekn", np.asarray(loading, dtype=float), g)
    return g.reshape(-1, g.shape[-1]) @ curvature_inverse


def moved_rows(J, usable, sigma, moves, curvature_inverse):
    """Signed rows (E, n) of E independent errors each moving every value of a region by its
    own amount, ``moves`` (P, T, C, E) at one sd (in the units ``J`` (P, T, C, n) takes), one
    error for every frame and channel (:func:`shared_error_rows`)."""
    P, T, C, n = J.shape
    flat = (P * T, 1, C, n)
    return np.concatenate([shared_error_rows((J * moves[..., e, None]).reshape(flat),
                                             usable.reshape(flat[:3]), sigma.reshape(flat[:3]),
                                             [[1.0]], np.ones((C, 1)), curvature_inverse)
                           for e in range(moves.shape[-1])])


def profile_interval(grid, profile, s2=1.0, ripple=0.0):
    """{level: (lo, hi)} where profile <= min + Delta s^2 + ripple, edges interpolated linearly.

    ``ripple`` is the chi^2 the model's own Monte Carlo noise can add or take away
    (:meth:`~skyfit_mi.fitting.chi2.Problem.model_noise_chi2`).
    """
    grid, profile = np.asarray(grid, float), np.asarray(profile, float)
    pmin = profile.min()
    out = {}
    for lv, delta in LEVELS.items():
        thr = pmin + delta * s2 + ripple
        inside = np.nonzero(profile <= thr)[0]
        i0, i1 = inside[0], inside[-1]

        def edge(i, j):
            if j < 0 or j >= len(grid):
                return grid[i]
            t = (thr - profile[i]) / (profile[j] - profile[i]) if profile[j] != profile[i] else 0
            return grid[i] + np.clip(t, 0, 1) * (grid[j] - grid[i])
        out[lv] = (float(edge(i0, i0 - 1)), float(edge(i1, i1 + 1)))
    return out


def identifiability(names, intervals95, lower, upper, profile_rise, s2, ripple=0.0):
    """Warnings for parameters the data do not determine (``s2``: Delta chi^2's scale(s))."""
    warnings = []
    span = np.asarray(upper) - np.asarray(lower)
    s2 = np.broadcast_to(np.asarray(s2, dtype=float), (len(names),))
    for i, name in enumerate(names):
        lo, hi = intervals95[name]
        rise = profile_rise.get(name)
        flat = rise is not None and rise < LEVELS["95"] * s2[i] + ripple
        if flat or (hi - lo) > 0.5 * span[i]:
            why = (f"chi-square changes by only {rise:.3g} across its whole range" if flat else
                   f"its 95% interval {lo:.3g}-{hi:.3g} covers over half its range")
            hint = (" The camera never sees this surface's specular lobe (e.g. a camera on the "
                    "sun's side, such as in the south, an overcast sky, or too few frames), so "
                    "the roughness is unknown; do not use the value." if name == "sigma_alpha"
                    else " Treat this parameter as unknown.")
            warnings.append(f"{name} is not determined by this sequence: {why}.{hint}")
    return warnings


def reading(name, value, interval95, lower, upper):
    """How a parameter's result reads: a value with its 95% interval, a one-sided limit where
    the interval reaches a bound, or "not determined" where it spans the range."""
    lo, hi = interval95
    eps = 1e-6 * (upper - lower)
    at_lo, at_hi = lo <= lower + eps, hi >= upper - eps
    if at_lo and at_hi:
        return f"{name} not determined (its 95% interval spans {lower:g}-{upper:g})"
    if at_lo:
        return f"{name} < {hi:.3g} (95%); lower end not determined"
    if at_hi:
        return f"{name} > {lo:.3g} (95%); upper end not determined"
    return f"{name} = {value:.4g} (95%: {lo:.3g}-{hi:.3g})"


def misfit(chi2, dof, s2, model_noise=0.0, noise=None, model_error=False):
    """Warnings when chi-square is larger than the data's noise explains (thesis 6.2).

    ``noise`` = (mean, variance) of noise's chi-square (default (dof, 2 dof)), ``model_noise``
    the model's own share (:func:`misfit_test`). Above MISFIT_UNRELIABLE times the expectation
    no parameter can be trusted; a smaller significant excess widens the intervals by s^2.
    ``model_error``: ``chi2`` already includes a fitted model error.
    """
    test = misfit_test(chi2, dof, model_noise, noise)
    by = (f"noise and the model's Monte Carlo error ({model_noise:.3g}) explain"
          if model_noise > 0.01 * test.noise_mean else "noise explains")
    if model_error:
        by = (f"noise, the fitted model error and the model's Monte Carlo error "
              f"({model_noise:.3g}) explain" if model_noise > 0.01 * test.noise_mean
              else "noise and the fitted model error explain")
    of = (f"chi-square is {test.ratio:.3g} times what {by} (p = {test.p:.2g}; noise alone "
          f"varies it by +- {np.sqrt(2 / test.k):.2g})")
    if test.ratio > MISFIT_UNRELIABLE and test.p < MISFIT_P:
        return [f"the model does not describe these data: {of}; its parameters and intervals are "
                "not reliable. Check the sensor model and sigmas, the region (one material "
                "only?), or use another reflection model."]
    if test.p < MISFIT_P:
        return [f"more misfit than the noise explains: {of}; intervals are widened by "
                f"s^2 = {s2:.3g}."]
    return []


def model_error_warning(test, model_error):
    """The warning of a fit whose model error was fitted after the misfit ``test``."""
    me = model_error
    of = (f"chi-square is {test.ratio:.3g} times what noise explains (p = {test.p:.2g}); "
          f"{me.meaning} (kappa = {me.kappa:.3g}, 95%: {me.interval95[0]:.3g}-"
          f"{me.interval95[1]:.3g}). The fit weights each value by what the model can "
          "reproduce, and its intervals and predictions include this error")
    if test.ratio > MISFIT_UNRELIABLE:
        return (f"the model does not describe these data: {of}; its parameters are this "
                "model's best description of the data, not necessarily the surface's own. "
                "Check the sensor model and sigmas, the region (one material only?), or use "
                "another reflection model.")
    return f"more misfit than the noise explains: {of}."


@dataclass(frozen=True)
class MisfitTest:
    """chi-square against noise and model noise (:func:`misfit_test`): ``ratio``, p-value ``p``
    on ``k`` dof, and noise's mean chi-square ``noise_mean``."""

    ratio: float
    p: float
    k: float
    noise_mean: float

    @property
    def significant(self):
        """Whether chi-square exceeds what noise explains beyond chance (p < MISFIT_P)."""
        return self.p < MISFIT_P


def misfit_test(chi2, dof, model_noise=0.0, noise=None):
    """The :class:`MisfitTest` of ``chi2`` against a chi-square of k = 2 mean^2 / variance dof
    matched to the expected mean and noise's variance (k = dof when nothing clips)."""
    mean, var = noise if noise is not None else (float(dof), 2.0 * dof)
    expected = mean + max(model_noise, 0.0)
    k = 2.0 * mean * mean / var if var > 0 else float(dof)
    return MisfitTest(ratio=chi2 / expected, p=float(chdtrc(k, chi2 * k / expected)), k=k,
                      noise_mean=mean)


#: The relative model errors searched: 0 and a geometric grid up to 10 (refined between points).
KAPPA_GRID = np.r_[0.0, np.geomspace(1e-4, 10.0, 81)]


@dataclass(frozen=True)
class ModelError:
    """A model's relative error beyond noise (:func:`model_error`): ``kappa``, its 95%
    ``interval95`` (lo, hi) at fixed parameters, and the number of ``values``."""

    kappa: float
    interval95: tuple
    values: int

    @property
    def meaning(self):
        """kappa in a sentence."""
        return (f"the model misses the data by about {self.kappa:.2g} (= {self.kappa:.1%}) of "
                "each value beyond their noise: each value's variance is its noise's plus "
                f"({self.kappa:.3g} x the value)^2")


def model_error(e, v, a, dof):
    """The relative model error kappa of residuals ``e`` [DN] (measured values only) with noise
    variances ``v`` [DN^2] and values ``a`` [DN] (:meth:`~.chi2.Problem.value_scale`), by
    restricted maximum likelihood: each residual is Gaussian of variance V = v + kappa^2 a^2,
    and kappa minimises

    .. math:: -2 \\ln L_R = \\sum e^2 / V + (\\nu / n) \\sum \\ln V

    (nu = ``dof`` of the n values: REML's simplest correction, keeping kappa from coming out
    low). 95% interval: where -2 ln L_R rises by 3.84. Returns a :class:`ModelError`."""
    from scipy.optimize import brentq, minimize_scalar    # lazy: only a misfit needs it

    e2, v, a2 = np.asarray(e, float) ** 2, np.asarray(v, float), np.asarray(a, float) ** 2
    weight = dof / max(len(e2), 1)

    def nll(kappa):
        V = v + kappa * kappa * a2
        return float(np.sum(e2 / V) + weight * np.sum(np.log(V)))

    grid = KAPPA_GRID
    f = np.array([nll(k) for k in grid])
    i = int(np.argmin(f))
    kappa, fmin = float(grid[i]), float(f[i])
    if 0 < i < len(grid) - 1:
        best = minimize_scalar(nll, bounds=(grid[i - 1], grid[i + 1]), method="bounded",
                               options={"xatol": 1e-6 * grid[i]})
        if best.fun < fmin:
            kappa, fmin = float(best.x), float(best.fun)
    thr = fmin + LEVELS["95"]

    def edge(j, step):
        """Where -2 ln L_R crosses the threshold going from the minimum by ``step``."""
        while 0 <= j + step < len(grid) and f[j + step] <= thr:
            j += step
        if not 0 <= j + step < len(grid):
            return float(grid[j])
        inner = kappa if j == i else grid[j]
        return float(brentq(lambda k: nll(k) - thr, *sorted((inner, grid[j + step]))))
    return ModelError(kappa, (edge(i, -1), edge(i, 1)), len(e2))


def colour_rule_ambiguity(theta, intervals95):
    """For the colour model: the other reading of the same BRDF when C is grey, or None.

    With C_r = C_g = C_b the plastic (rho_s < 0.5) and metal rules can give the same Ward model
    (thesis 3.4.5). Returns (C', rho_s') of the other reading if valid.
    """
    iv = np.array([intervals95[k] for k in ("C_r", "C_g", "C_b")], dtype=float)
    ok, c2, rho2 = colour_twins(np.asarray(theta, dtype=float)[None], iv[None, :, 0],
                                iv[None, :, 1])
    return (float(c2[0]), float(rho2[0])) if ok[0] else None


def colour_twins(theta, c_lo, c_hi):
    """For colour-model fits ``theta`` (G, 5) with C's intervals ``c_lo``, ``c_hi`` (G, 3):
    whether C is grey within them (one value in every channel's) and the colour rule's other
    reading of the same BRDF is valid (:func:`~skyfit_mi.physics.ward.colour_rule_twin`,
    across the plastic/metal rule, C' <= 1), and that reading's C' (grey) and rho_s', (G,) each."""
    grey = np.max(c_lo, axis=1) <= np.min(c_hi, axis=1) + 1e-9
    g, rho = np.mean(theta[:, :3], axis=1), theta[:, 3]
    c2, rho2 = colour_rule_twin(np.repeat(g[:, None], 3, axis=1), rho)
    ok = grey & ((rho2 < METAL_THRESHOLD) != (rho < METAL_THRESHOLD)) & (c2[:, 0] <= 1.0)
    return ok, c2[:, 0], rho2
