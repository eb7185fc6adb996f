"""Every pixel its own Ward fit, many at once: the per-pixel half of a material map.

A chunk's pixels (or patches) share one light-cache trace (MAP_CACHE) and one basis pass on
SIGMA_GRID; the global method's grid scores every (sigma_alpha, rho_s) point of every pixel with
its linear parameters in closed form on the device
(:func:`~.methods.global_search.grid_chi2_device`). There is no nonlinear polish, so sigma_alpha is
resolved to the grid's 8% steps and rho_s to 0.01. The cache's error (from its two halves), the
calibration's, the colour matrix's, the regions' shares of the EXIF labels' error where labels
scale a given exposure and, under a fitted sky, the regions' sky shares and the sun's level
(:func:`~.pixel_map.first_fits`) are added to the intervals in quadrature.

Intervals are the grid's profile, the 95% set {chi^2 <= chi^2_min + 3.84 s^2}, s^2 = max(1,
chi^2_min / dof): sigma_alpha's and rho_s's its extent widened by half a grid step, a linear
parameter's the union of L +- sqrt((threshold - chi^2) / hh) over the set. Warnings are a bit
field (:data:`WARNINGS`); a pixel off its material gets NaN.
"""

import numpy as np

from ..errors import SkyfitError
from ..pipeline.manifest import frame_sky, load_manifest
from ..render import setup
from ..render.scene import load_xml
from ..render.basis_table import TableModel, trace_basis
from ..render.fit_model import PARAMETERS, bounds, reflectance_sets
from ..render.light_cache import CacheOptions
from .chi2 import load_observations, usable_values
from .methods.global_search import (RHO_GRID, SIGMA_GRID, grid_chi2, grid_chi2_device,
                                    linear_curvature, linear_observations, near_saturation)
from .sky_fit import LEVEL_SCALED, light_level_sd, skies_at_level
from .tone import tone_level_rows
from .uncertainty import (Z, calibration_rows, colour_matrix_sd, colour_twins, rows_sd,
                          vignetting_error, widen_relative)

#: Light-cache samples per pixel of a map (positions, directions): a sixteenth of a region
#: fit's, so that a chunk fits in memory.
MAP_CACHE = (8, 64)
#: Fits whose grids are searched at once: bounds the grids' memory and keeps arrays in cache.
GRID_BLOCK = 64
#: Warning bits of a map pixel.
WARNINGS = {"misfit": 1, "sigma_alpha undetermined": 2, "rho_s undetermined": 4,
            "reflectance undetermined": 8, "few values": 16, "off the material": 32,
            "saturated values left out": 64, "saturated values contradicted": 128,
            "grey: plastic and metal readings alike": 256}
#: The bits that mean "not determined": a fit falling short of a left-out saturated value
#: contradicts it (a saturated highlight misleads it); one reaching it stays determined.
UNDETERMINED = (WARNINGS["sigma_alpha undetermined"] | WARNINGS["rho_s undetermined"]
                | WARNINGS["reflectance undetermined"] | WARNINGS["off the material"]
                | WARNINGS["saturated values contradicted"]
                | WARNINGS["grey: plastic and metal readings alike"])


def undetermined_bits(name):
    """The bits that leave parameter ``name`` of a pixel not determined: the pixel's as a whole
    (off the material, saturated values contradicted) and the parameter's own (a flat lobe
    width leaves a pixel's reflectance determined)."""
    own = {"rho_s": "rho_s undetermined", "sigma_alpha": "sigma_alpha undetermined"}
    twin = 0 if name == "sigma_alpha" else WARNINGS["grey: plastic and metal readings alike"]
    return (WARNINGS["off the material"] | WARNINGS["saturated values contradicted"]
            | WARNINGS[own.get(name, "reflectance undetermined")] | twin)
#: How far [sigma] a fit may fall below a left-out saturated value (one-sided, about 0.1%).
SATURATION_MARGIN = 3.0
#: A parameter is undetermined when its 95% interval spans more than this share of its range
#: (reflectances) or this factor in roughness.
SPAN_UNDETERMINED, SIGMA_FACTOR_UNDETERMINED = 0.5, 4.0
#: chi^2 quantile above which a pixel's fit is a misfit (the data are not described).
MISFIT_QUANTILE = 0.999
#: Delta chi^2 of a single parameter's 95% profile interval.
DELTA_95 = 3.841458820694124


def patch_groups(pixels, patch):
    """Group indices (P,) of pixels (P, 2) into ``patch`` x ``patch`` blocks of the image, and
    each group's block corner (G, 2); ``patch`` 1: every pixel its own group."""
    pixels = np.asarray(pixels, dtype=int)
    blocks = pixels // int(patch)
    corners, index = np.unique(blocks, axis=0, return_inverse=True)
    return index.ravel(), corners * int(patch)


def _stack_groups(x, groups, n_groups):
    """(P, T, ...) values regrouped as (G, T * m, ...), zero-padded (m the largest group)."""
    P, T = x.shape[:2]
    m = int(np.bincount(groups, minlength=n_groups).max())
    out = np.zeros((n_groups, m, T) + x.shape[2:], dtype=x.dtype)
    slot = np.zeros(P, dtype=int)
    seen = np.zeros(n_groups, dtype=int)
    for i, g in enumerate(groups):
        slot[i] = seen[g]
        seen[g] += 1
    out[groups, slot] = x
    return out.reshape((n_groups, m * T) + x.shape[2:])


def fit_pixels(manifest_path, materials, pixels, model="colour", normalisation="ward", seed=0,
               cache=MAP_CACHE, groups=None, variant=None, light=None):
    """Fit every pixel of ``pixels`` (P, 2), or every group, on its own, the light traced once;
    rebuilt from the manifest, so any worker process can run it.

    ``materials``: the material id(s); ``cache``: (positions, directions); ``groups``: each
    pixel's fit (P,) 0..G-1; ``light``: None (the spec's sky, no region's share) or by
    :func:`~.pixel_map.first_fits` (its ``fitted`` 'spec': the spec's sky, the regions' shares).
    Returns a dict over the G fits: ``pixels`` (G, 2), ``theta``, ``lo``, ``hi``,
    ``cache_error_sd`` (G, n) (95% intervals), ``chi2``, ``dof``, ``model_noise_chi2``,
    ``warnings``, ``sigma_index`` (G,), and ``names``.
    """
    pixels = np.asarray(pixels, dtype=int).reshape(-1, 2)
    groups = np.arange(len(pixels)) if groups is None else np.asarray(groups, dtype=int)
    n = int(groups.max()) + 1
    doc, root = load_manifest(manifest_path)
    obs = load_observations(manifest_path, pixels, one_fit=False)
    frames = {f["index"]: f for f in doc["frames"]}
    mi = setup(variant or doc["render"]["variant"])
    scene = load_xml(doc["scene"]["xml"])
    skies = [frame_sky(frames[i], root) for i in obs.frames]
    if light is not None and light["fitted"] != "spec":
        skies = skies_at_level(skies, light["sky"], obs.times)
    options = CacheOptions(cache[0], cache[1], seed,
                           max(1, int(doc["render"]["max_depth"]) - 1), normalisation, "anchors")
    (table,), _, _ = trace_basis(scene, mi.traverse(scene), [skies], pixels, materials, options,
                                 model=model)
    wm = TableModel(table, model)
    usable = usable_values(obs, table.hit)
    # every usable value's weight, and the grid's: values near saturation left out of it
    y, w_all = linear_observations(obs, usable, leave_out_saturated=False)
    saturated = usable & near_saturation(obs)
    w = np.where(saturated, 0.0, w_all)
    bases = wm.basis(SIGMA_GRID, halves=True)            # the whole cache, and its two halves
    whole = bases[0]
    hit = np.bincount(groups, weights=table.hit.all(axis=1), minlength=n) > 0
    first = pixels[np.unique(groups, return_index=True)[1]]
    y_pixels = y                                         # per pixel, for _contradicts
    if n < len(pixels) or not np.array_equal(groups, np.arange(len(pixels))):
        # in group order, as every per-group array below (a patch of 1 numbers its pixels in
        # the image's order, not the list's)
        y, w = (_stack_groups(a, groups, n) for a in (y, w))
        bases = [(_stack_groups(D, groups, n), np.stack([_stack_groups(g, groups, n) for g in G]))
                 for D, G in bases]
    names = PARAMETERS[model]
    parts = [_fit_block(model, names, y[b], w[b], [(D[b], G[:, b]) for D, G in bases])
             for b in (slice(i, i + GRID_BLOCK) for i in range(0, n, GRID_BLOCK))]
    fit = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    fit.update(pixels=np.asarray(first, dtype=int), names=list(names))
    sd = fit["cache_error_sd"]
    theta = fit["theta"]
    material = np.broadcast_to(np.asarray(materials, dtype=object), (len(pixels),))[
        np.unique(groups, return_index=True)[1]]
    region_sd, sky_span = _region_errors(light, material, names, theta)
    count = np.bincount(groups, minlength=n)
    vignetting = np.abs(np.bincount(groups, weights=vignetting_error(doc, pixels), minlength=n)
                        / np.maximum(count, 1))
    calibration = rows_sd(calibration_rows(doc, names, theta, vignetting))
    if not ((light or {}).get("sky") or {}).get("tone_curve"):  # else region_sd carries it
        calibration = np.hypot(calibration, rows_sd(tone_level_rows(doc, obs, groups, n, names,
                                                                    theta)))
    spread = Z["95"] * np.sqrt(sd ** 2 + calibration ** 2
                               + colour_matrix_sd(doc, names, theta) ** 2 + region_sd ** 2)
    lower, upper = bounds(model)
    fit["lo"] = np.maximum(theta - np.hypot(theta - fit["lo"], spread), lower)
    fit["hi"] = np.minimum(theta + np.hypot(fit["hi"] - theta, spread), upper)
    # under a fitted sky, the sun's level as the regions' fit counted it (sky_fit.light_level_sd)
    sun = Z["95"] * light_level_sd(doc, names, (light or {}).get("sun_level_sd", 0.0))
    fit["lo"], fit["hi"] = widen_relative(theta, (fit["lo"], fit["hi"]), sun, lower, upper)
    if sky_span is not None:                  # the regions' sky level was not determined
        fit["lo"] = np.maximum(np.minimum(fit["lo"], sky_span[0]), lower)
        fit["hi"] = np.minimum(np.maximum(fit["hi"], sky_span[1]), upper)
    left_out = np.bincount(groups, weights=saturated.any(axis=(1, 2)), minlength=n) > 0
    contradicted = np.bincount(groups, weights=_contradicts(model, y_pixels, w_all, saturated,
                                                            whole, fit, groups), minlength=n) > 0
    fit["warnings"] = _flags(model, names, fit, hit) \
        | np.where(left_out, WARNINGS["saturated values left out"], 0) \
        | np.where(contradicted, WARNINGS["saturated values contradicted"], 0)
    for k in ("theta", "lo", "hi", "cache_error_sd"):
        fit[k][~hit] = np.nan
    for k in ("chi2", "chi2_grid"):
        fit[k] = np.where(hit, fit[k], np.nan)
    return fit


def _region_errors(light, material, names, theta):
    """(The regions' shares of each fit's error (G, n): the sky's and the EXIF labels', in
    quadrature; the (lo, hi) the sky's untold levels reach or None) from its region's by
    ``material`` (G,), a reflectance's relative to the region's value."""
    sd = np.zeros_like(theta)
    if light is None:
        return sd, None
    span = None
    scaled = np.isin(names, LEVEL_SCALED)
    for name, region in light["regions"].items():
        at = material == name
        if not at.any():                     # a region of another chunk (maybe another model)
            continue
        value = np.array([region["value"][p] for p in names])
        scale = np.where(scaled & (value > 0), theta[at] / np.where(value > 0, value, 1.0), 1.0)
        shares = [np.array([share.get(p, 0.0) for p in names])
                  for share in (region.get("sd") or {}, region.get("labels_sd") or {})]
        sd[at] = scale * np.hypot(*shares)
        if region.get("span") is not None:
            if span is None:
                span = [theta.copy(), theta.copy()]
            for side, ends in zip(span, region["span"]):
                ends = np.array([ends[p] for p in names])
                side[at] = np.where(scaled, scale * ends, theta[at] + ends - value)
    return sd, span


def _contradicts(model, y, w, saturated, basis, fit, groups):
    """Which pixels (P,) hold a ``saturated`` value their group's fit falls short of by more than
    SATURATION_MARGIN sigma. ``y``, ``w`` (P, T, 3) linearised values and weights, saturated
    included; ``basis`` (D, G) per pixel on SIGMA_GRID."""
    if not saturated.any():
        return np.zeros(len(groups), bool)
    rd, sp = reflectance_sets(model, fit["theta"]).transpose(1, 0, 2)
    D, G = basis
    px = np.arange(len(groups))
    g = groups
    model_values = rd[g][:, None] * D + sp[g][:, None] * G[fit["sigma_index"][g], px]
    short = model_values < y - SATURATION_MARGIN / np.sqrt(np.maximum(w, 1e-300))
    return (saturated & short).any(axis=(1, 2))


def _fit_block(model, names, y, w, bases):
    """The grid fits (a dict) of a block of groups, on the whole cache and its halves."""
    search, half_a, half_b = (_grid_search(model, names, y, w, D, G) for D, G in bases)
    # the chi^2 the cache's noise adds: its halves differ by twice the whole's error
    rd, sp = reflectance_sets(model, search["theta"]).transpose(1, 0, 2)
    cols = np.arange(len(rd))
    La, Lb = (rd[:, None] * D + sp[:, None] * G[search["sigma_index"], cols]
              for D, G in bases[1:])
    noise = np.sum(w * ((La - Lb) / 2.0) ** 2, axis=(1, 2))
    lo, hi = _grid_intervals(model, names, y, w, *bases[0], search, noise)
    # the cache's own error in each parameter, from its halves' fits
    return {"theta": search["theta"], "lo": lo, "hi": hi, "chi2": search["chi2"],
            "chi2_grid": search["chi2_grid"], "dof": search["dof"], "model_noise_chi2": noise,
            "cache_error_sd": np.abs(half_a["theta"] - half_b["theta"]) / 2.0,
            "sigma_index": search["sigma_index"]}


def _grid_search(model, names, y, w, D, G):
    """Each group's best grid point (a dict) on linearised ``y``, weights ``w`` (G, T', 3) and
    basis D (G, T', 3), G (K, G, T', 3), with the grid's ``chi2`` (K, R, G) and linear ``L``."""
    n_par = len(names)
    if model == "two":
        chi2, thetas = grid_chi2(model, y, w, D, G, per_pixel=True)
        L = thetas[..., :0]
    else:
        chi2, L = grid_chi2_device(model, y, w, D, G, RHO_GRID)
    K, R, n_groups = chi2.shape
    flat = chi2.reshape(K * R, n_groups)
    best = np.argmin(flat, axis=0)
    cols = np.arange(n_groups)
    theta = np.concatenate([L.reshape(K * R, n_groups, -1)[best, cols],
                            RHO_GRID[best % R, None], SIGMA_GRID[best // R, None]], axis=1)
    # the grid point lies above the continuous minimum: s^2 and misfit take a parabola's
    vertex = np.minimum(_vertex(chi2.min(axis=1)), _vertex(chi2.min(axis=0)))
    return {"grid": chi2, "L": L, "theta": theta, "chi2_grid": flat[best, cols], "chi2": vertex,
            "dof": np.count_nonzero(w > 0, axis=(1, 2)) - n_par, "sigma_index": best // R}


def _grid_intervals(model, names, y, w, D, G, search, model_noise):
    """The 95% intervals (lo, hi), each (G, n), of a :func:`_grid_search` (module docstring)."""
    n_par = len(names)
    chi2, L_grid, dof = search["grid"], search["L"], search["dof"]
    K, R, n_groups = chi2.shape
    s2 = np.maximum(1.0, (search["chi2"] - model_noise) / np.maximum(dof, 1))
    chi2_min = search["chi2_grid"]
    thr = chi2_min + DELTA_95 * s2
    ok = chi2 <= thr                                                   # (K, R, G)
    lo, hi = np.empty((n_groups, n_par)), np.empty((n_groups, n_par))
    # sigma_alpha: the set's extent on the grid, half a (log) step wider each side
    k_ok = ok.any(axis=1)                                              # (K, G)
    k_lo = np.argmax(k_ok, axis=0)
    k_hi = K - 1 - np.argmax(k_ok[::-1], axis=0)
    step = np.sqrt(SIGMA_GRID[2] / SIGMA_GRID[1])
    lo[:, -1] = np.where(k_lo <= 1, 0.0, SIGMA_GRID[k_lo] / step)
    hi[:, -1] = np.minimum(SIGMA_GRID[k_hi] * step, SIGMA_GRID[-1])
    # rho_s
    j_ok = ok.any(axis=0)                                              # (R, G)
    half = 0.5 * (RHO_GRID[1] - RHO_GRID[0])
    r = names.index("rho_s")
    lo[:, r] = np.clip(RHO_GRID[np.argmax(j_ok, axis=0)] - half, 0, 1)
    hi[:, r] = np.clip(RHO_GRID[R - 1 - np.argmax(j_ok[::-1], axis=0)] + half, 0, 1)
    if model != "two":
        # a linear parameter's union of L +- reach over the 95% set's points only
        kk, rr, gg = np.nonzero(ok)
        L = L_grid[kk, rr, gg]                                         # (n, groups)
        hh = linear_curvature(model, w, D, G, RHO_GRID[rr], kk, gg)
        reach = np.sqrt(np.maximum(thr[gg] - chi2[kk, rr, gg], 0.0)[:, None]
                        / np.maximum(hh, 1e-300))
        low = np.full((n_groups, L.shape[1]), np.inf)
        high = np.full_like(low, -np.inf)
        np.minimum.at(low, gg, L - reach)
        np.maximum.at(high, gg, L + reach)
        # the grid's resolution: L halfway to each neighbour of the set lies within it too
        for dk, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            k2, r2 = kk + dk, rr + dj
            on = (k2 >= 0) & (k2 < K) & (r2 >= 0) & (r2 < R)
            mid = 0.5 * (L[on] + L_grid[k2[on], r2[on], gg[on]])
            np.minimum.at(low, gg[on], mid)
            np.maximum.at(high, gg[on], mid)
        lo[:, :-2], hi[:, :-2] = np.clip(low, 0, 1), np.clip(high, 0, 1)
    return lo, hi


def _vertex(profile):
    """Each column's minimum of ``profile`` (N, G) refined by a parabola through its lowest point
    and neighbours (never above it; the point itself at either end)."""
    n, g = profile.shape
    i = np.clip(np.argmin(profile, axis=0), 1, n - 2)
    cols = np.arange(g)
    a, b, c = profile[i - 1, cols], profile[i, cols], profile[i + 1, cols]
    curv = a - 2 * b + c
    with np.errstate(divide="ignore", invalid="ignore"):
        v = b - (c - a) ** 2 / (8 * curv)
    low = profile.min(axis=0)
    return np.where((curv > 0) & np.isfinite(v), np.clip(v, 0.0, low), low)


def _flags(model, names, fit, hit):
    """The warning bits (:data:`WARNINGS`) of each group's fit (intervals final)."""
    from scipy.stats import chi2 as chi2_dist

    lo, hi, dof, n_par = fit["lo"], fit["hi"], fit["dof"], len(names)
    r = names.index("rho_s")
    bits = np.zeros(len(dof), dtype=np.int32)
    with np.errstate(invalid="ignore"):
        misfit = (dof > 0) & (fit["chi2"] - fit["model_noise_chi2"]
                              > chi2_dist.ppf(MISFIT_QUANTILE, np.maximum(dof, 1)))
    bits |= np.where(misfit, WARNINGS["misfit"], 0)
    # the roughness spread over a factor, or open at its upper bound (a lower limit only)
    top = bounds(model)[1][-1]
    spread = hi[:, -1] > SIGMA_FACTOR_UNDETERMINED * np.maximum(lo[:, -1], SIGMA_GRID[1])
    bits |= np.where(spread | (hi[:, -1] >= top - 1e-9), WARNINGS["sigma_alpha undetermined"], 0)
    bits |= np.where(hi[:, r] - lo[:, r] > SPAN_UNDETERMINED, WARNINGS["rho_s undetermined"], 0)
    if model != "two":
        bits |= np.where((hi[:, :-2] - lo[:, :-2] > SPAN_UNDETERMINED).any(axis=1),
                         WARNINGS["reflectance undetermined"], 0)
    bits |= np.where(dof < 2 * n_par, WARNINGS["few values"], 0)
    if model == "colour":
        bits |= np.where(colour_twins(fit["theta"], lo[:, :3], hi[:, :3])[0],
                         WARNINGS["grey: plastic and metal readings alike"], 0)
    return bits | np.where(~hit, WARNINGS["off the material"], 0)


def check_map_region(pixels, shape):
    """Raise SkyfitError unless ``pixels`` (P, 2) is non-empty and inside ``shape`` (H, W)."""
    pixels = np.asarray(pixels).reshape(-1, 2)
    if len(pixels) == 0:
        raise SkyfitError("the map's mask selects no pixel; give a mask with the label's value "
                          "on the material.")
    h, w = shape
    if (pixels < 0).any() or (pixels[:, 0] >= w).any() or (pixels[:, 1] >= h).any():
        raise SkyfitError(f"the map's pixels fall outside the {w}x{h} frames.")
