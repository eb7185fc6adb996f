"""Chi-square landscapes: chi^2 over two parameters of a region, the others fixed at a fit
or, over (rho_s, sigma_alpha), at their best (thesis figs 6.5-6.21 and 7.10).

Ward's radiance is linear in its reflectances given sigma_alpha (thesis eq. 3.19), so the basis
D, G is evaluated once per roughness and each grid point costs one NumPy chi^2.
"""

import csv
import io
from pathlib import Path

import numpy as np

from .methods.global_search import (RHO_GRID, SIGMA_GRID, linear_observations,
                                    linear_quadratics)
from ..errors import SkyfitError
from ..files import output_prefix, save_figure, write_json, write_text
from ..render.fit_model import PARAMETERS, bounds, reflectances


def truth_parameters(truth, model, names, normalisation="ward"):
    """The true parameters in the fit's parameterisation from the manifest's material record, or
    None when it is in another model or normalisation."""
    if not isinstance(truth, dict) or truth.get("model") != model \
            or truth.get("normalisation", "ward") != normalisation:
        return None
    values = dict(truth)
    if model == "colour" and isinstance(truth.get("C"), (list, tuple)):
        values.update(zip(("C_r", "C_g", "C_b"), truth["C"]))
    try:
        return np.array([float(values[k]) for k in names])
    except (KeyError, TypeError, ValueError):
        return None


def map_axes(model, x, y, x_range=None, y_range=None, n=60, profile=False):
    """The grid (xs, ys) of ``model``'s parameters ``x`` and ``y``, ``n`` values over each range
    (default the bounds); raises SkyfitError for bad parameters or ranges."""
    names, (lower, upper) = list(PARAMETERS[model]), bounds(model)
    if profile and len(names) == 2:
        raise SkyfitError("the 2-parameter model has no other parameter to profile; leave "
                          "out --profile.")
    if x == y:
        raise SkyfitError("give two different parameters for the map's axes.")
    axes = []
    for name, given in ((x, x_range), (y, y_range)):
        if name not in names:
            raise SkyfitError(f"{name!r} is not a parameter of the {model} model; its "
                              f"parameters are {', '.join(names)}.")
        i = names.index(name)
        lo, hi = given if given is not None else (lower[i], upper[i])
        if not lower[i] <= lo < hi <= upper[i]:
            raise SkyfitError(f"the {name} range {lo:g},{hi:g} must rise within "
                              f"[{lower[i]:g}, {upper[i]:g}].")
        axes.append(np.linspace(lo, hi, n))
    return tuple(axes)


def chi2_map(session, theta, x, y, xs, ys):
    """chi^2 (len(ys), len(xs)) on the grid of ``x``, ``y``, every other parameter at ``theta``."""
    names = list(session.names)
    ix, iy = names.index(x), names.index(y)
    last = len(names) - 1
    theta = np.asarray(theta, dtype=float)
    # the basis at every roughness the map needs (an axis, or the fixed value)
    sigmas = xs if ix == last else ys if iy == last else np.array([theta[last]])
    D, G = session.wm.basis(np.asarray(sigmas, dtype=float))
    out = np.empty((len(ys), len(xs)))
    point = theta.copy()
    for j, vy in enumerate(ys):
        for i, vx in enumerate(xs):
            point[ix], point[iy] = vx, vy
            k = i if ix == last else j if iy == last else 0
            out[j, i] = _chi2_from_basis(session, point, D, G[k])
    return out


def _radiance_from_basis(model, theta, D, G):
    """Ward's radiance rho_d D + rho_s G at ``theta`` from the basis D, G at its sigma_alpha."""
    rho_d, spec = reflectances(model, theta)[:2]
    return rho_d * D + spec * G


def _chi2_from_basis(session, theta, D, G):
    """The true chi^2 (censored values included) at ``theta`` from the basis at its sigma."""
    problem = session.problem
    r = problem.residual_terms(_radiance_from_basis(session.model, theta, D, G),
                               derivative=False)[0][problem.mask]
    return float(r @ r)


#: Gauss-Newton steps of a profile point on the true chi-square.
PROFILE_STEPS = 4


def _polish(session, theta, free, D, G):
    """The lowest true chi^2 that bounded Gauss-Newton steps from ``theta`` over the parameters
    ``free`` (never sigma_alpha) reach, by forward differences on the basis model."""
    problem, model = session.problem, session.model
    theta = np.array(theta, dtype=float)
    free = np.asarray(free, dtype=int)
    best = np.inf
    for step in range(PROFILE_STEPS + 1):
        rad = _radiance_from_basis(model, theta, D, G)
        r, dr = problem.residual_terms(rad)
        r = r[problem.mask]
        chi2 = float(r @ r)
        if not chi2 < best:                         # no lower: keep the best so far
            break
        best = chi2
        if step == PROFILE_STEPS or not len(free):
            break
        ds = (dr * problem.slope(rad))[problem.mask]
        J = np.empty((len(r), len(free)))
        for c, g in enumerate(free):
            h = 1e-4 if theta[g] + 1e-4 <= session.upper[g] else -1e-4
            t = theta.copy()
            t[g] += h
            J[:, c] = ds * (_radiance_from_basis(model, t, D, G) - rad)[problem.mask] / h
        JTJ = J.T @ J
        delta = np.linalg.lstsq(JTJ + 1e-9 * np.diag(np.diag(JTJ)), -(J.T @ r), rcond=None)[0]
        theta[free] = np.clip(theta[free] + delta, session.lower[free], session.upper[free])
    return best


def profiled_map(session, theta, x, y, xs, ys):
    """The profile chi^2 (len(ys), len(xs)) on the grid ``xs`` x ``ys`` of ``x`` and ``y``, every
    other parameter at its best (3- and 5-parameter models): each point polished
    (:func:`_polish`) from the linearised grid's best and from ``theta``, the lower kept, so the
    map never exceeds :func:`chi2_map`'s and bounds the profile from above."""
    names = list(session.names)
    theta = np.asarray(theta, dtype=float)
    axes = {x: np.asarray(xs, dtype=float), y: np.asarray(ys, dtype=float)}
    # the grids hold the fit's values, so that its start is a grid point
    sigma = axes.get("sigma_alpha", np.union1d(SIGMA_GRID, [theta[-1]]))
    rho = axes.get("rho_s", np.union1d(RHO_GRID, [theta[-2]]))
    obs, w = linear_observations(session.problem.obs, session.problem.mask)
    D, G = session.wm.basis(sigma)
    zz, yh, hh = linear_quadratics(session.model, obs, w, D, G, rho)       # (K, R, groups)
    at_best = np.clip(yh / np.maximum(hh, 1e-300), 0.0, 1.0)
    best = zz - 2 * at_best * yh + at_best**2 * hh          # each group's best
    linear = names[:-2]                                      # R, or C_r, C_g, C_b
    ix, iy = names.index(x), names.index(y)
    free = [n for n in range(len(names) - 1) if n not in (ix, iy)]
    out = np.empty((len(ys), len(xs)))
    for j, vy in enumerate(ys):
        for i, vx in enumerate(xs):
            at, pos = {x: vx, y: vy}, {x: i, y: j}
            # the (sigma, rho) grid rows this point may use: its own where one is an axis
            k0, r0 = pos.get("sigma_alpha", 0), pos.get("rho_s", 0)
            ks = slice(k0, k0 + 1) if "sigma_alpha" in pos else slice(None)
            rs = slice(r0, r0 + 1) if "rho_s" in pos else slice(None)
            q = best[ks, rs].copy()
            for g, name in enumerate(linear):
                if name in at:
                    v = at[name]
                    q[..., g] = zz[ks, rs, g] - 2 * v * yh[ks, rs, g] + v * v * hh[ks, rs, g]
            qs = q.sum(axis=-1)                                   # (K', R')

            def grid_point(k, r):
                return np.array([*(at.get(n, at_best[k, r, g]) for g, n in enumerate(linear)),
                                 rho[r], sigma[k]])

            def best_rho(row):
                return r0 if "rho_s" in pos else int(np.argmin(qs[row]))
            if "sigma_alpha" in pos:
                k, r = k0, best_rho(0)
            else:
                # every roughness at its linearised best; the true chi^2 picks among them
                k = min(range(len(sigma)), key=lambda kk: _chi2_from_basis(
                    session, grid_point(kk, best_rho(kk)), D, G[kk]))
                r = best_rho(k)
            grid = grid_point(k, r)
            at_fit = theta.copy()
            at_fit[ix], at_fit[iy] = vx, vy
            k_fit = k0 if "sigma_alpha" in pos else int(np.searchsorted(sigma, theta[-1]))
            out[j, i] = min(_polish(session, grid, free, D, G[k]),
                            _polish(session, at_fit, free, D, G[k_fit]))
    return out


def map_prefix(prefix, default_name, overwrite=False):
    """The path prefix of a map's files (a folder, existing or written with a trailing slash:
    ``default_name`` in it), refusing to replace files that are not an earlier map's (CSV header
    X,Y,chi2) unless ``overwrite``."""
    prefix = output_prefix(prefix, default_name)
    table, image = prefix.with_suffix(".csv"), prefix.with_suffix(".png")
    if overwrite or not (table.exists() or image.exists()):
        return prefix
    try:
        with open(table, newline="", encoding="utf-8") as f:
            header = next(csv.reader(f), [])
    except (OSError, UnicodeDecodeError):
        header = []
    if len(header) != 3 or header[2] != "chi2":
        held = table if table.exists() else image
        raise SkyfitError(f"{held} exists and is not a chi-square map's; give another -o, or "
                          "pass --overwrite to replace it.")
    return prefix


def write_chi2_map(prefix, x, y, xs, ys, chi2, marks, walk=None, others="at the fit",
                   record=None):
    """Write ``<prefix>.csv`` (x, y, chi2), ``<prefix>.png`` (:func:`draw_chi2_map`) and, with
    ``record`` (what the map was made from: fit, seed, ...), ``<prefix>.chi2map.json`` (not
    ``<prefix>.json``: a map may be written beside the fit JSON it was made from)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    prefix = Path(prefix)
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow([x, y, "chi2"])
    for j, vy in enumerate(ys):
        for i, vx in enumerate(xs):
            w.writerow([f"{vx:.6g}", f"{vy:.6g}", f"{chi2[j, i]:.6g}"])
    csv_path = write_text(prefix.with_suffix(".csv"), buf.getvalue())
    fig, ax = plt.subplots(figsize=(6, 5), layout="constrained")
    draw_chi2_map(fig, ax, x, y, xs, ys, chi2, marks, walk)
    ax.set_title(f"chi-square over {x} and {y} (others {others})", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    png_path = save_figure(fig, prefix.with_suffix(".png"))
    if record is None:
        return csv_path, png_path
    minimum = np.unravel_index(np.argmin(chi2), chi2.shape)
    json_path = write_json(prefix.with_suffix(".chi2map.json"), {
        **record, "x": x, "y": y, "others": others,
        "minimum": {"chi2": float(chi2[minimum]), x: float(xs[minimum[1]]),
                    y: float(ys[minimum[0]])},
        "marks": {k: [float(v) for v in xy] for k, xy in marks.items()}})
    return csv_path, png_path, json_path


#: How each mark of a chi-square map is drawn: (marker, colour).
MARK_STYLES = {"fit": ("*", "r"), "map minimum": ("+", "w"), "truth": ("o", "orange")}


def draw_chi2_map(fig, ax, x, y, xs, ys, chi2, marks, walk=None):
    """Log-scaled filled contours of chi^2 - min + 1 on ``ax`` with a colour bar, ``marks``
    {label: (x, y)} (MARK_STYLES) and an optional walk (N, 2), clipped to the map's ranges."""
    from matplotlib.colors import LogNorm
    from matplotlib.ticker import LogLocator

    rise = chi2 - chi2.min() + 1.0
    levels = np.geomspace(1.0, max(rise.max(), 10.0), 25)
    cs = ax.contourf(xs, ys, rise, levels=levels, norm=LogNorm(), cmap="viridis")
    fig.colorbar(cs, ax=ax, ticks=LogLocator(), label="chi2 - min + 1")
    if walk is not None and len(walk) > 1:
        ax.plot(walk[:, 0], walk[:, 1], "-", color="w", lw=0.8, alpha=0.8, label="walk")
    for label, (mx, my) in marks.items():
        m, c = MARK_STYLES.get(label, ("x", "k"))
        ax.plot(mx, my, m, color=c, ms=10, mfc="none" if m == "o" else c, label=label,
                clip_on=False)
    ax.set_xlim(xs[0], xs[-1])
    ax.set_ylim(ys[0], ys[-1])
    ax.set_xlabel(x)
    ax.set_ylabel(y)
