"""Chi-square landscapes: chi^2 over two parameters of a region, the others fixed at a fit
or, over (rho_s, sigma_alpha), at their best (thesis figs 6.5-6.21 and 7.10).

The map uses the fit's fast model: Ward's radiance is linear in its reflectances once
sigma_alpha is given (thesis eq. 3.19, L = rho_d D + s G(sigma) per channel), so the light is
traced once, the basis D, G is evaluated once per roughness on the map, and every grid point
costs one NumPy evaluation of chi^2 (:meth:`~skyfit_mi.fitting.chi2.Problem.residuals_from`,
censored values included).
"""

import csv
import io
from pathlib import Path

import numpy as np

from ..errors import SkyfitError
from ..render.fit_model import reflectances


def truth_parameters(truth, model, names):
    """The true parameters in the fit's parameterisation, from the manifest's material record
    (``truth`` in a fit JSON), or None when the material was given in another model."""
    if not isinstance(truth, dict) or truth.get("model") != model:
        return None
    values = dict(truth)
    if model == "colour" and isinstance(truth.get("C"), (list, tuple)):
        values.update(zip(("C_r", "C_g", "C_b"), truth["C"]))
    try:
        return np.array([float(values[k]) for k in names])
    except (KeyError, TypeError, ValueError):
        return None


def map_axes(model, x, y, x_range=None, y_range=None, n=60):
    """The grid (xs, ys) of a map of ``model``'s parameters ``x`` and ``y``: ``n`` values over
    each range (default the parameter's bounds); SkyfitError for an unknown or repeated
    parameter or a range outside its bounds."""
    from ..render.fit_model import PARAMETERS, bounds

    names, (lower, upper) = list(PARAMETERS[model]), bounds(model)
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
    """chi^2 on the grid ``xs`` x ``ys`` of parameters ``x`` and ``y`` (names, checked by
    :func:`map_axes`), every other parameter at ``theta``: array (len(ys), len(xs))."""
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
            rho_d, spec = reflectances(session.model, point)[:2]
            r = session.problem.residuals_from(rho_d * D + spec * G[k])
            out[j, i] = float(r @ r)
    return out


def profiled_rho_sigma_map(session, xs, ys, x="rho_s"):
    """chi^2 over (rho_s, sigma_alpha) with R or C at their best for each point, closed form
    on the linearised data (:func:`~skyfit_mi.fitting.methods.global_search.grid_chi2`, the
    global search's grid: values near saturation left out, no censoring): array
    (len(ys), len(xs)); ``x`` names the parameter on the x axis."""
    from .methods.global_search import _linearise, grid_chi2

    rho, sigma = (xs, ys) if x == "rho_s" else (ys, xs)
    y, w = _linearise(session.problem)
    D, G = session.wm.basis(np.asarray(sigma, dtype=float))
    chi2, _ = grid_chi2(session.model, y, w, D, G, np.asarray(rho, dtype=float))  # (sigma, rho)
    return chi2 if x == "rho_s" else chi2.T


def write_chi2_map(prefix, x, y, xs, ys, chi2, marks, walk=None, others="at the fit"):
    """``<prefix>.csv`` (x, y, chi2 per grid point) and ``<prefix>.png`` (log-scaled filled
    contours of chi^2 - min + 1, ``marks`` {label: (x, y)} such as the fit, the map's
    minimum and the truth, and an optional walk (N, 2) such as an annealing trace)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    from ..files import save_figure, write_text

    prefix = Path(prefix)
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow([x, y, "chi2"])
    for j, vy in enumerate(ys):
        for i, vx in enumerate(xs):
            w.writerow([f"{vx:.6g}", f"{vy:.6g}", f"{chi2[j, i]:.6g}"])
    csv_path = write_text(prefix.with_suffix(".csv"), buf.getvalue())
    rise = chi2 - chi2.min() + 1.0
    fig, ax = plt.subplots(figsize=(6, 5))
    levels = np.geomspace(1.0, max(rise.max(), 10.0), 25)
    cs = ax.contourf(xs, ys, rise, levels=levels, norm=LogNorm(), cmap="viridis")
    fig.colorbar(cs, ax=ax, label="chi2 - min + 1 (log scale)")
    if walk is not None and len(walk) > 1:
        ax.plot(walk[:, 0], walk[:, 1], "-", color="w", lw=0.8, alpha=0.8, label="walk")
    styles = {"fit": ("*", "r"), "map minimum": ("+", "w"), "truth": ("o", "orange")}
    for label, (mx, my) in marks.items():
        m, c = styles.get(label, ("x", "k"))
        ax.plot(mx, my, m, color=c, ms=10, mfc="none" if m == "o" else c, label=label)
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    ax.set_title(f"chi-square over {x} and {y} (others {others})", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    png_path = save_figure(fig, prefix.with_suffix(".png"))
    return csv_path, png_path
