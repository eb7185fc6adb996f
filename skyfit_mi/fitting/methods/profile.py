"""Profile chi-square intervals on the true chi-square, by constrained fits (thesis 6.3).

The profile of parameter k is P_k(x) = the minimum of chi^2 over the other parameters with
theta_k held at x; its interval at level Delta is {x : P_k(x) - chi^2_min <= Delta} (Press et
al., Numerical Recipes 15.6). The global grid gives P_k cheaply but on linearised data
(:mod:`.global_search`), offset wherever the sensor clips (a code-0 value taken as exact 0).

So each edge is placed on the true chi^2: P_k(x) is a Levenberg-Marquardt fit with theta_k held
at x, started at the conditional mean theta + (x - theta_k) C[:, k] / C[k, k], and the edge found
by secant steps on h(x) = sqrt(P_k(x) - chi^2_min), linear in x where chi^2 is quadratic. An edge
not placed within the budget is put conservatively. The fit reports the union with the grid's
interval (docs/BENCHMARKS.md, "Coverage and RMSE against the Cramer-Rao bound").
"""

from dataclasses import dataclass

import numpy as np

from .levenberg_marquardt import polish


@dataclass(frozen=True)
class ProfileOptions:
    """How :func:`profile_edges` searches for each edge.

    ``rtol``: an edge is placed when P_k - chi2_min is within this of the threshold (relative,
    in h); ``max_fits``: most constrained fits per edge; ``iterations``: most Levenberg-Marquardt
    iterations per constrained fit.
    """

    rtol: float = 0.05
    max_fits: int = 10
    iterations: int = 5


def profile_edges(problem, theta, chi2_min, k, thresholds, lower, upper, cov, options=None):
    """Edges of {x : P_k(x) - chi2_min <= thr} for each threshold (ascending chi^2 rises).

    ``cov`` is (J^T J)^-1 at ``theta`` (unscaled), for first guesses and starts; ``options`` a
    :class:`ProfileOptions`. Returns ([(lo, hi)] per threshold, None for an edge no fit could
    approach, e.g. singular curvature), the number of fits, every fit's (parameters, chi^2)
    (for :func:`ridge_intervals`), and where the search gave up: {(threshold index, side 0 or
    1): the farthest x a fit reached inside} for each edge taken to the bound because the fits
    beyond that x failed (the search's limit, not the data's).
    """
    opts = options or ProfileOptions()
    theta = np.asarray(theta, dtype=float)
    x0 = float(theta[k])
    ckk = float(cov[k, k]) if np.isfinite(cov[k, k]) else 0.0
    sd = np.sqrt(ckk) if ckk > 0 else 0.05 * (upper[k] - lower[k])
    usable = ckk > 0 and np.all(np.isfinite(cov[:, k]))
    direction = cov[:, k] / ckk if usable else np.zeros(len(theta))
    fits = 0

    path = {x0: theta}                       # x -> the constrained fit's parameters
    visited = []                             # (parameters, chi^2) of every constrained fit

    def h(x):
        """sqrt(P_k(x) - chi2_min), and whether it is exact (not just an upper bound)."""
        nonlocal fits
        fits += 1
        # a start stepped into a singular corner (rho_s clipped to 0 beside sigma_alpha 0)
        # fails: then from the nearest fit itself, x in its place
        nearest = path[min(path, key=lambda v: abs(v - x))].copy()
        nearest[k] = x
        starts = (start_at(x), nearest)
        for start in starts:
            res = polish(problem, start, lower, upper, max_iterations=opts.iterations,
                         fixed=(k,))
            if res["status"] != "failed":
                break
        exact = res["status"] != "failed"
        chi2 = res["chi2"] if exact else problem.chi2(starts[0])
        if exact:
            path[x] = np.asarray(res["theta"], dtype=float)
            visited.append((path[x], float(chi2)))
        return float(np.sqrt(max(chi2 - chi2_min, 0.0))), exact

    def start_at(x):
        """The start of the fit at x, continued along the profile's path: the nearest fit
        stepped along the secant of the two nearest on x's side (else the conditional mean), so
        that a fit far along a curved ridge does not land on another branch."""
        side = [v for v in path if (v - x0) * (x - x0) >= 0]
        near = sorted(side, key=lambda v: abs(v - x))[:2]
        a = near[0]
        step = direction
        if len(near) == 2 and near[1] != a:
            step = (path[near[1]] - path[a]) / (near[1] - a)
        start = np.clip(path[a] + (x - a) * step, lower, upper)
        start[k] = x
        return start

    def guess(pts, t, side, bound):
        """Next x: interpolate a bracket of t, else extrapolate outward."""
        above = [p for p in pts if p[1] >= t]
        below = [p for p in pts if p[1] < t]
        b = below[-1]
        if above:
            a = above[0]
            # secant; halving where the outside point is far outside (the secant barely moves)
            x = b[0] + (t - b[1]) * (a[0] - b[0]) / (a[1] - b[1]) if a[1] < 3 * t \
                else (a[0] + b[0]) / 2
        elif len(below) == 1:
            x = x0 + side * t * sd
        else:
            (x1, h1), (x2, h2) = below[-2], below[-1]
            far = x0 + 2 * (x2 - x0)             # at most twice as far: the path's steps
            x = x2 + (t - h2) * (x2 - x1) / (h2 - h1) if h2 > h1 else far
            x = min(x, far) if side > 0 else max(x, far)
        return float(np.clip(x, min(x0, bound), max(x0, bound)))

    edges, gave_up = [[None, None] for _ in thresholds], {}
    for j, (side, bound) in enumerate(((-1, lower[k]), (1, upper[k]))):
        if x0 == bound:
            for e in edges:
                e[j] = float(bound)
            continue
        found = {x0: (0.0, True)}              # x -> (h, exact): a failed fit's h a bound
        for i, (e, thr) in enumerate(zip(edges, thresholds)):
            t = np.sqrt(thr)

            def at(x):
                # no fit at x (singular curvature): outside unless its bound says inside t,
                # so that the next guess halves the step
                hx, exact = found[x]
                return hx if exact or hx < t else np.inf

            def points():
                return sorted(((x, at(x)) for x in found), key=lambda p: abs(p[0] - x0))
            pts = points()
            for _ in range(opts.max_fits):
                x = guess(pts, t, side, bound)
                if x in found:                          # no new point to try
                    break
                found[x] = h(x)
                pts, hx = points(), at(x)
                # an edge where a fit lands on t; a failed fit's bound there says only inside
                if found[x][1] and abs(hx - t) <= opts.rtol * t:
                    e[j] = x
                    break
                if hx < t and x == bound:
                    e[j] = float(bound)
                    break
            if e[j] is None and len(pts) > 1:
                # the fits ran out: the nearest point known outside, else the bound
                outside = [p[0] for p in pts if t <= p[1] < np.inf]
                e[j] = float(outside[0]) if outside else float(bound)
                if not outside and any(p[1] == np.inf for p in pts):
                    gave_up[i, j] = max((p[0] for p in pts if p[1] < t),
                                        key=lambda x: abs(x - x0))
    return [tuple(e) for e in edges], fits, visited, gave_up


def ridge_intervals(points, chi2_min, threshold):
    """Per parameter, the (min, max) over ``points`` [(theta, chi2)] with chi2 - chi2_min <=
    ``threshold``, or None when there is none: inner bounds of every profile interval at that
    level, reaching along a curved ridge where constrained fits started off it do not."""
    inside = [t for t, c in points if c - chi2_min <= threshold]
    if not inside:
        return None
    inside = np.array(inside)
    return inside.min(axis=0), inside.max(axis=0)
