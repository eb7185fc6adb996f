"""Profile chi-square intervals on the true chi-square, by constrained fits (thesis 6.3).

The profile of parameter k is P_k(x) = the minimum of chi^2 over the other parameters with
theta_k held at x; its interval at level Delta is {x : P_k(x) - chi^2_min <= Delta} (Press
et al., Numerical Recipes 15.6).  The global method's grid gives P_k cheaply, but on
linearised data (:mod:`.global_search`), whose minimum lies off the fit's wherever the
sensor clips: a value at code 0 enters chi^2 as a censored term, but the linear solve takes
it as an exact 0.  On table 7.7's dark disc at 10% noise that shifted the rho_s profile by
half a standard deviation and its 95% interval missed the truth in 8 of 50 replicates.

So each edge is placed on the true chi^2: P_k(x) is a Levenberg-Marquardt fit with theta_k
held at x, started on the covariance's conditional mean theta + (x - theta_k) C[:, k] /
C[k, k] (the exact minimiser where chi^2 is quadratic, so five iterations at most), and the
edge is found by secant steps on h(x) = sqrt(P_k(x) - chi^2_min), which is linear in x where
chi^2 is quadratic, so two or three fits place an edge.  Along a curved ridge each fit starts
from the profile's path so far (continuation), and an edge the fits do not place within their
budget is put conservatively: at the nearest point found outside, or at the bound.

The fit reports the union of this interval and the grid's: the true chi^2 is that of the
light cache, whose narrow lobes carry an error of their own (for a mirror fit, sigma_alpha
just above 0 can look excluded when it is not), and the grid's profile was measured to cover
there (docs/BENCHMARKS.md, "Coverage and RMSE against the Cramer-Rao bound").
"""

from dataclasses import dataclass

import numpy as np

from .levenberg_marquardt import polish


@dataclass(frozen=True)
class ProfileOptions:
    """How :func:`profile_edges` searches for each edge.

    ``rtol``: an edge is placed when P_k - chi2_min is within this of the threshold (relative,
    in h); ``max_fits``: constrained fits per edge at most; ``iterations``: Levenberg-Marquardt
    iterations of each constrained fit at most (5 where chi^2 is near quadratic; more along a
    curved ridge, where the conditional mean is a poor start).
    """

    rtol: float = 0.05
    max_fits: int = 10
    iterations: int = 5


def profile_edges(problem, theta, chi2_min, k, thresholds, lower, upper, cov, options=None):
    """Edges of {x : P_k(x) - chi2_min <= thr} for each threshold (ascending chi^2 rises).

    ``cov`` is (J^T J)^-1 at ``theta`` (unscaled), for the first guesses and the fits'
    starts; ``options`` a :class:`ProfileOptions` (default its defaults).  Returns ([(lo, hi)]
    per threshold, with None for an edge no fit could be made toward, e.g. where the
    constrained fit's curvature is singular), the number of fits, and every fit's
    (parameters, chi^2): points of the ridge, whose other parameters are admissible where
    their chi^2 is (:func:`ridge_intervals`).
    An edge is placed when P_k - chi2_min is within ``options.rtol`` of the threshold
    (relative, in h), or at the bound if the profile stays below the threshold there.
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
        res = polish(problem, start_at(x), lower, upper, max_iterations=opts.iterations,
                     fixed=(k,))
        exact = res["status"] != "failed"
        chi2 = res["chi2"] if exact else problem.chi2(start_at(x))
        if exact:
            path[x] = np.asarray(res["theta"], dtype=float)
            visited.append((path[x], float(chi2)))
        return float(np.sqrt(max(chi2 - chi2_min, 0.0))), exact

    def start_at(x):
        """The start of the fit at x, continued along the profile's path: from the fit nearest
        to x, stepped along the secant of the two nearest on x's side (the covariance's
        conditional mean while there is one).  Started from theta far along a curved ridge,
        a fit can land on another branch: on a Radiance-traced day the fit at rho_s = 0.13
        found sigma_alpha 0.04 and chi^2 + 52 where the ridge continues at + 0.8."""
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
        """Next x: interpolate a bracket of t, else extrapolate outward (pts sorted by
        distance from x0, with (x0, 0) first)."""
        above = [p for p in pts if p[1] >= t]
        below = [p for p in pts if p[1] < t]
        b = below[-1]
        if above:
            a = above[0]
            # secant; halving where the outside point is far outside (a failed fit, or the
            # profile far from quadratic), where the secant would barely move
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

    edges = [[None, None] for _ in thresholds]
    for j, (side, bound) in enumerate(((-1, lower[k]), (1, upper[k]))):
        if x0 == bound:
            for e in edges:
                e[j] = float(bound)
            continue
        pts = [(x0, 0.0)]
        for e, thr in zip(edges, thresholds):
            t = np.sqrt(thr)
            for _ in range(opts.max_fits):
                x = guess(pts, t, side, bound)
                if any(x == p[0] for p in pts):         # no new point to try
                    break
                hx, exact = h(x)
                if not exact:
                    # no fit there (singular curvature): the next guess halves the step
                    hx = np.inf if hx >= t else hx
                pts = sorted(pts + [(x, hx)], key=lambda p: abs(p[0] - x0))
                if abs(hx - t) <= opts.rtol * t:
                    e[j] = x
                    break
                if hx < t and x == bound:
                    e[j] = float(bound)
                    break
            if e[j] is None and len(pts) > 1:
                # the fits ran out: the nearest point known to lie outside, or, when the
                # profile stayed inside as far as they went, the bound (not determined)
                outside = [p[0] for p in pts if t <= p[1] < np.inf]
                e[j] = float(outside[0]) if outside else float(bound)
    return [tuple(e) for e in edges], fits, visited


def ridge_intervals(points, chi2_min, threshold):
    """Per parameter, the (min, max) over ``points`` [(theta, chi2)] with chi2 - chi2_min <=
    ``threshold``, or None when there is none.  Each such point lies inside every parameter's
    profile interval at that level (the profile at its value is at most its chi^2), so these
    ranges are inner bounds of the profile intervals: along a curved ridge the profile of
    rho_s walks where a constrained fit of C, started off the ridge, does not reach (on a
    Radiance-traced day C_r's fits from the covariance's start stopped at 0.598, while the
    rho_s profile passed C_r = 0.60 at a chi^2 rise under 1)."""
    inside = [t for t, c in points if c - chi2_min <= threshold]
    if not inside:
        return None
    inside = np.array(inside)
    return inside.min(axis=0), inside.max(axis=0)
