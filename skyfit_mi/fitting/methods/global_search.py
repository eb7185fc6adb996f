"""The global method: sigma_alpha searched on a grid, the linear parameters solved in closed form.

Given sigma_alpha, Ward's model is linear in rho_d and rho_s (thesis eq. 3.19): with the basis
L = rho_d * D + rho_s * G(sigma) (:meth:`WardModel.basis`) every model's other parameters have
closed-form bounded least-squares solutions on linearised data (y and sigma mapped back through
the sensor response):

* 2 parameters: L = D + rho_s (G - D), scored on a grid of rho_s;
* 3 parameters: L = R ((1 - rho_s) D + rho_s G): for each rho_s on a grid, R in closed form;
* 5 parameters: per channel, plastic (rho_s < 0.5) L_c = C_c (1 - rho_s) D_c + rho_s G_c,
  metal L_c = C_c ((1 - rho_s) D_c + rho_s G_c): for each rho_s on a grid, C_c in closed form.

Every (sigma, rho_s) grid point is scored at once; the best few distinct candidates are polished
by Levenberg-Marquardt on the full model, giving the global minimum from any start. The grid also
gives the profile chi-square of sigma_alpha and rho_s.
"""

import numpy as np

from ...physics.ward import METAL_THRESHOLD
from ...render.basis_table import sigma_chunk
from ...render.linear_grid import grid_on_device, linear_form
from .levenberg_marquardt import polish

#: sigma_alpha grid: the ideal mirror, then log-spaced.
SIGMA_GRID = np.concatenate([[0.0], np.geomspace(0.004, 0.5, 64)])
RHO_GRID = np.linspace(0.0, 1.0, 101)
#: Resolution of the profiles near the optimum.
RHO_FINE = np.linspace(0.0, 1.0, 2001)
SIGMA_FINE_POINTS = 21
#: Values within this many sigma of the top code are left out of the linear grid [sigma].
SATURATION_BAND = 3.0
#: Relative rise of chi-square beyond which a polish counts as failed: float32 evaluations with
#: and without derivatives differ by ~1e-7 relative.
POLISH_TOLERANCE = 1e-6


def linear_observations(obs, mask, leave_out_saturated=True):
    """(y_lin, w = 1/sigma_lin^2) (P, T, 3) of ``obs`` in radiance where ``mask`` (else w 0);
    values near saturation get weight 0 unless ``leave_out_saturated`` is False."""
    sensor = obs.sensor
    v = np.clip(obs.y / sensor.max_code, 0.0, 1.0)
    if sensor.response == "linear":
        s = v
    elif sensor.response == "gamma":
        s = v ** sensor.gamma
    else:
        s = np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)
    g = obs.gain
    y = s / g
    slope = sensor.slope(np.clip(s, 1e-6, 1 - 1e-6)) * sensor.max_code * g
    # the linear grid cannot saturate: values at or within SATURATION_BAND sigma of the top code
    # would pull a highlight down, so the grid leaves them out (the polish uses them; a narrower
    # band still misranks lobes). A value at code 0 stays: as zero it errs by under its sigma.
    if leave_out_saturated:
        mask = mask & ~near_saturation(obs)
    w = np.where(mask, (slope / obs.sigma) ** 2, 0.0)
    return y, w


def near_saturation(obs):
    """Which values (P, T, 3) of ``obs`` lie within SATURATION_BAND sigma of the top code."""
    return obs.y >= obs.sensor.max_code - SATURATION_BAND * obs.sigma


def sigma_chunks(G):
    """(slice, values) over the roughness axis of the lobe basis ``G`` (an array (K, P, T, 3) or
    a lazy :class:`~skyfit_mi.render.basis_table.Lobes`), a few roughness values at a time."""
    if hasattr(G, "chunks"):
        yield from G.chunks()
        return
    n = sigma_chunk(G.shape[1:])
    for k in range(0, len(G), n):
        yield slice(k, k + n), G[k:k + n]


def _per_sigma(G, *terms):
    """Each of ``terms`` (functions of a chunk of G) over all of G, concatenated."""
    parts = [[] for _ in terms]
    for _, g in sigma_chunks(G):
        for out, f in zip(parts, terms):
            out.append(f(g))
    return tuple(np.concatenate(p) for p in parts)


def _basis_sums(w, D, G, keep):
    """The basis's weighted inner products <D,D>, <D,G_k>, <G_k,G_k>, summed over frames and the
    axes of 'pc' not in ``keep`` (kept axes follow the K of the G terms)."""
    Dw = D * w
    return (np.einsum(f"ptc,ptc->{keep}", Dw, D),
            *_per_sigma(G, lambda g: np.einsum(f"ptc,kptc->k{keep}", Dw, g),
                        lambda g: np.einsum(f"ptc,kptc->k{keep}", w, g * g)))


def _weighted_sums(y, w, D, G, keep):
    """:func:`_basis_sums` and the data's <y,D>, <y,G_k>, <y,y>, reduced alike."""
    yw, Dw = y * w, D * w
    dg, gg, yg = _per_sigma(G, lambda g: np.einsum(f"ptc,kptc->k{keep}", Dw, g),
                            lambda g: np.einsum(f"ptc,kptc->k{keep}", w, g * g),
                            lambda g: np.einsum(f"ptc,kptc->k{keep}", yw, g))
    return (np.einsum(f"ptc,ptc->{keep}", Dw, D), dg, gg, np.einsum(f"ptc,ptc->{keep}", yw, D),
            yg, np.einsum(f"ptc,ptc->{keep}", yw, y))


def grid_chi2(model, y, w, D, G, rho=RHO_GRID, per_pixel=False):
    """(chi2 (K, R), thetas (K, R, n_params)): linearised chi^2 and closed-form linear
    parameters at every (sigma, rho_s) point; with ``per_pixel`` (K, R, P) and (K, R, P, n)."""
    p = "p" if per_pixel else ""
    if model == "two":
        # with H = G - D (K, P, T, 3), a few roughness values at a time
        r = w * (y - D)
        A = np.einsum(f"ptc,ptc->{p}", r, y - D)
        B, C = _per_sigma(G, lambda g: np.einsum(f"ptc,kptc->k{p}", r, g - D),
                          lambda g: np.einsum(f"ptc,kptc->k{p}", w, (g - D) ** 2))
        r = _along_rho(rho, np.ndim(A))
        chi2 = A - 2 * r * B[:, None] + r ** 2 * C[:, None]
        thetas = np.stack([np.broadcast_to(r, chi2.shape), np.zeros_like(chi2)], axis=-1)
        return chi2, thetas
    chi2 = thetas = None
    rho = np.asarray(rho, dtype=float)
    for idx, zz, yh, hh in _quadratic_parts(model, y, w, D, G, rho, per_pixel):
        L, c = solve_quadratics(zz, yh, hh)
        if thetas is None:
            chi2 = np.empty(c.shape[:1] + (len(rho),) + c.shape[2:])
            thetas = np.zeros(chi2.shape + (L.shape[-1] + 2,))
        chi2[:, idx] = c
        thetas[:, idx, ..., :-2] = L
        thetas[:, idx, ..., -2] = _along_rho(rho[idx], c.ndim - 2)
    return chi2, thetas


def solve_quadratics(zz, yh, hh):
    """The bounded minimum of chi^2 = sum over groups of zz - 2 L yh + L^2 hh: each group's
    linear parameter L in [0, 1] (R, or C per channel; last axis) and the chi^2 there."""
    L = np.clip(yh / np.maximum(hh, 1e-300), 0.0, 1.0)
    return L, np.sum(zz - L * (2 * yh - L * hh), axis=-1)


def _along_rho(rho, extra):
    """``rho`` shaped (1, R, 1, ...) with ``extra`` trailing axes, against (K, R, ...)."""
    return np.reshape(rho, (1, -1) + (1,) * extra)


def linear_quadratics(model, y, w, D, G, rho, per_pixel=False):
    """The 3- and 5-parameter models' linearised chi^2 at each (sigma_k, rho_s) as a quadratic in
    each group's linear parameter L (R, or C_c): chi^2 = sum over groups of zz - 2 L yh + L^2 hh.
    Returns (zz, yh, hh), each (K, R, groups), or (K, R, P, groups) with ``per_pixel``."""
    out = None
    for idx, *parts in _quadratic_parts(model, y, w, D, G, rho, per_pixel):
        if out is None:
            shape = parts[2].shape[:1] + (len(rho),) + parts[2].shape[2:]
            out = [np.empty(shape) for _ in parts]
        for o, v in zip(out, parts):
            o[:, idx] = v
    return tuple(out)


def linear_curvature(model, w, D, G, rho, k, p):
    """hh of :func:`linear_quadratics` (per pixel) at listed points only (``rho`` (n,), roughness
    indices ``k``, pixels ``p``): (n, groups), for conditional ranges without the whole grid."""
    a, b, c = _basis_sums(w, D, G, "p" if model == "achromatic" else "pc")
    a, b, c = a[p], b[k, p], c[k, p]
    r2 = np.asarray(rho, dtype=float).reshape((-1,) + (1,) * (np.ndim(a) - 1))
    metal = (r2 >= METAL_THRESHOLD) | (model == "achromatic")
    hh = np.where(metal, *(linear_form(m, r2, a, b, c, 0, 0, 0)[2] for m in (True, False)))
    return hh[:, None] if model == "achromatic" else hh


def _quadratic_parts(model, y, w, D, G, rho, per_pixel):
    """:func:`linear_quadratics` in parts (slice of ascending ``rho``, zz, yh, hh), one per form
    (a colour model's plastics, then metals), each computed only for its own rho_s."""
    p = "p" if per_pixel else ""
    # h = (1 - rho) D + rho G: (K, R, P, T, 3) built lazily by channel sums
    a, b, c, yd, yg, yy = _weighted_sums(y, w, D, G, p if model == "achromatic" else p + "c")
    b, c, yg = b[:, None], c[:, None], yg[:, None]
    split = 0 if model == "achromatic" else int(np.searchsorted(_ascending(rho),
                                                                METAL_THRESHOLD))
    for form, idx in ((False, slice(0, split)), (True, slice(split, len(rho)))):
        if idx.stop == idx.start:
            continue
        r2 = _along_rho(np.asarray(rho, dtype=float)[idx], np.ndim(a))
        zz, yh, hh = linear_form(form, r2, a, b, c, yd, yg, yy)
        zz, hh = (np.broadcast_to(v, yh.shape) for v in (zz, hh))
        if model == "achromatic":
            zz, yh, hh = zz[..., None], yh[..., None], hh[..., None]
        yield idx, zz, yh, hh


def _ascending(rho):
    """``rho`` as floats; ValueError unless ascending."""
    rho = np.asarray(rho, dtype=float)
    if np.any(np.diff(rho) < 0):
        raise ValueError("the rho_s grid must be ascending")
    return rho


def grid_chi2_device(model, y, w, D, G, rho=RHO_GRID):
    """:func:`grid_chi2` with ``per_pixel`` (3- and 5-parameter models) on the Mitsuba device:
    chi2 (K, R, P) and the linear parameters L (K, R, P, groups)."""
    achromatic = model == "achromatic"
    sums = _weighted_sums(y, w, D, G, "p" if achromatic else "pc")
    if achromatic:
        sums = tuple(v[..., None] for v in sums)
    return grid_on_device(sums, _ascending(rho), achromatic)


def global_search(problem, start, lower, upper, candidates=3, profile=True, grid_basis=None, **_):
    """Grid over sigma_alpha (and rho_s) with closed-form linear parameters, then LM polish.

    ``start`` is unused (uniform interface). ``profile`` = False skips the refined profiles.
    ``grid_basis`` = (D, G) on SIGMA_GRID from ``problem.model.lobes``, if already made.
    """
    wm = problem.model
    model = wm.model
    y, w = linear_observations(problem.obs, problem.mask)
    D, G = grid_basis if grid_basis is not None else wm.lobes(SIGMA_GRID)
    chi2, thetas = grid_chi2(model, y, w, D, G)
    thetas[..., -1] = SIGMA_GRID[:, None]
    # candidates: the best grid point, then the best at other roughness, ranked by the true
    # chi-square (the grid, without saturated values, can favour too narrow a lobe)
    rows = np.arange(len(SIGMA_GRID))
    best_j = np.argmin(chi2, axis=1)
    order = np.argsort(problem.chi2_at(thetas[rows, best_j]))
    picks = []
    for k in order:
        if all(abs(np.log((SIGMA_GRID[k] + 0.01) / (SIGMA_GRID[j] + 0.01))) > 0.5 for j in picks):
            picks.append(k)
        if len(picks) == candidates:
            break
    results = []
    for k in picks:
        j = int(best_j[k])
        res = polish(problem, thetas[k, j], lower, upper)
        # a polish that fails (singular curvature) keeps the grid point
        at_grid = problem.chi2(thetas[k, j])
        if res["status"] == "failed" or \
                not problem.chi2(res["theta"]) <= at_grid * (1 + POLISH_TOLERANCE):
            res = {**res, "theta": thetas[k, j], "chi2": at_grid,
                   "status": "grid_point", "message": "the Levenberg-Marquardt polish did not "
                   f"lower chi-square ({res['message']}); the best grid point is reported"}
        results.append(res)
    best = min(results, key=lambda r: r["chi2"])
    prof = refined_profile(wm, y, w, D, G, chi2, float(best["theta"][-1])) \
        if profile else None
    message = (f"global grid of {len(SIGMA_GRID)} roughness values, {len(picks)} candidates "
               f"polished; polish of the best: {best['status']} ({best['message']})")
    return {**best, "status": best["status"], "message": message, "profile_linearised": prof,
            "grid_candidates": [results[i]["theta"].tolist() for i in range(len(results))]}


def refined_profile(wm, y, w, D, G, chi2, sigma_best):
    """Profile chi^2 of sigma_alpha and rho_s: the coarse grid plus a fine one near the optimum."""
    k = int(np.argmin(np.abs(SIGMA_GRID - sigma_best)))
    lo = SIGMA_GRID[max(k - 3, 1)] if sigma_best > 0 else 0.0
    hi = SIGMA_GRID[min(k + 3, len(SIGMA_GRID) - 1)]
    fine = np.geomspace(max(lo, 1e-3), hi, SIGMA_FINE_POINTS)
    _, Gf = wm.lobes(fine)
    chi2_f, _ = grid_chi2(wm.model, y, w, D, Gf, RHO_FINE)
    chi2_all, _ = grid_chi2(wm.model, y, w, D, G, RHO_FINE)
    sig = np.concatenate([SIGMA_GRID, fine])
    prof_s = np.concatenate([chi2.min(axis=1), chi2_f.min(axis=1)])
    order = np.argsort(sig, kind="stable")
    prof_r = np.minimum(chi2_all.min(axis=0), chi2_f.min(axis=0))
    return {"sigma_alpha": sig[order], "chi2_sigma": prof_s[order], "rho_s": RHO_FINE,
            "chi2_rho": prof_r}
