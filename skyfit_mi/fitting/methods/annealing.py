"""Simulated annealing: the downhill simplex with thermal fluctuations (thesis 6.4.4, 7.3).

After Press et al., Numerical Recipes 2nd ed. section 10.9: the Nelder-Mead simplex moves
(reflect, expand, contract, shrink), with a positive thermal fluctuation -T ln(u) added
to the values kept at the vertices and subtracted from every new trial, so that uphill
moves are accepted with a probability that falls with the temperature T.  Trial points
that leave the parameter box are mirrored back into it.  The cooling schedule of the thesis
(7.3.1): start at T0, run m simplex iterations at each temperature, then multiply T by alpha
(temperatures scale with the number of region pixels, since the thesis's chi^2 was one
pixel's, and start no lower than 10x the initial chi^2); below t_min (0.1 per pixel:
fluctuations far below a chi^2 change of 1, which moves a parameter by its standard error)
the simplex runs cold (T = 0) until its chi^2 values agree to ftol.  Seeded; the walk (the
simplex's lowest vertex after each iteration) is recorded (thesis fig. 7.10).

Additions to the thesis's method, for the end game, all measured on its tables 7.4-7.12
(docs/THESIS_TABLES.md):

* When the cold simplex first converges, it tries the best point on every face, edge and
  corner of the parameter box.  Mirrored trial points almost never land on a bound, yet
  truths often lie there (an ideal mirror: sigma_alpha = 0, rho_s = R = 1) at the bottom
  of a well too narrow for the hot random walk to find (table 7.9 failed from half the
  starts without this).
* At every freeze a cold simplex descends from each point the caller names for the best
  point (``alternatives``), unless it lies near one already descended from: for the colour
  model the reading across the plastic/metal rule, where chi^2 jumps and no simplex move
  crosses (a metal reading of a plastic surface is a local minimum at rho_s = 0.5).  Cold,
  because the twin lies in the other rule's basin and a hot walk from it may leave that
  basin again; and at every freeze, because the first freeze's best point may be in neither
  basin of the truth's pair (table 7.10 failed from one start of 30 so).
* After the first freeze it also anneals again from the best point (a further cooling
  cycle, Press et al. 10.9), starting at T = the chi^2 there, which frees simplices stuck
  on a ridge.
* Later convergences restart around the best point, first with a full-size simplex and
  then small ones (Press et al. 10.4), each after trying every parameter on each bound.
"""

import itertools

import numpy as np

#: The thesis's cooling schedules (T0, alpha, m) by number of parameters (tables 7.4-7.12).
SCHEDULES = {2: (1e6, 0.7, 10), 3: (1e6, 0.8, 10), 5: (1e7, 0.8, 20)}


def reflect_into(x, lower, upper):
    """Mirror a point back into the box (keeps a simplex from collapsing onto a bound)."""
    span = np.asarray(upper) - np.asarray(lower)
    y = np.mod(np.asarray(x) - lower, 2 * span)
    return lower + np.where(y > span, 2 * span - y, y)


def on_bounds(x, lower, upper, every_face=False):
    """``x`` with each parameter moved onto each of its bounds (2 n points), or with
    ``every_face`` onto every face, edge and corner of the box through x (3^n - 1 points)."""
    n = len(x)
    cols = np.stack([np.asarray(x, dtype=float), lower, upper])        # (3, n): keep, low, high
    if every_face:
        picks = [p for p in itertools.product(range(3), repeat=n) if any(p)]
    else:
        picks = [tuple(k if j == i else 0 for j in range(n)) for i in range(n) for k in (1, 2)]
    return [cols[list(p), range(n)] for p in picks]


def simulated_annealing(problem, start, lower, upper, seed=0, schedule=None, max_evaluations=15000,
                        t_min=0.1, step=0.25, ftol=1e-7, max_restarts=4, reanneal=True,
                        alternatives=None, **_):
    """Minimise chi^2 by annealing from ``start``; returns a result dict with the walk.

    With ``reanneal`` the end game of the module's docstring follows the first cooling cycle:
    a further cycle from its best point, and cold descents from ``alternatives(x)`` of every
    new best point x (each distinct point once).
    """
    rng = np.random.default_rng(seed)
    n = len(start)
    t0, alpha, m = schedule or SCHEDULES.get(n, (1e6, 0.8, 10))
    # The thesis's temperatures are chi^2 values of one pixel's sequence; a region of P
    # pixels sums P such chi^2, so its temperatures are P times higher.
    pixels = max(1, int(problem.obs.y.shape[0]))
    t0, t_min = t0 * pixels, t_min * pixels
    span = np.asarray(upper) - np.asarray(lower)

    def make_simplex(x0, size):
        pts = [x0]
        for i in range(n):
            v = x0.copy()
            v[i] = v[i] + size * span[i] if v[i] + size * span[i] <= upper[i] else v[i] - size * span[i]
            pts.append(np.clip(v, lower, upper))
        return np.array(pts), np.array([problem.chi2(v) for v in pts])

    simplex, f = make_simplex(np.clip(np.asarray(start, dtype=float), lower, upper), step)
    evals = n + 1
    restarts = reanneals = descents = 0
    cycles = None        # queued (start or None for the best point, hot?), from the first freeze
    tried = []           # alternative readings already descended from
    finished = False
    # The thesis's T0 (1e6, 1e7) exceeded its sequences' chi^2 many times over, so annealing
    # began as a random walk.  Sequences with more pixels or less noise have larger chi^2:
    # then start at 10x the initial simplex's largest chi^2 to keep that first phase.
    t0_used = max(t0, 10.0 * float(np.max(f)))
    best_i = int(np.argmin(f))
    best_x, best_f = simplex[best_i].copy(), float(f[best_i])
    walk = [best_x.tolist()]
    temp = t0_used

    def trial(fac):
        nonlocal evals, best_x, best_f
        centroid = (simplex.sum(axis=0) - simplex[hi]) / n
        x = reflect_into(centroid * (1 - fac) + simplex[hi] * fac, lower, upper)
        y = problem.chi2(x)
        evals += 1
        if y < best_f:
            best_x, best_f = x.copy(), y
        yflu = y + temp * np.log(rng.random())         # trials get a negative fluctuation
        if yflu < fluct[hi]:
            simplex[hi], f[hi], fluct[hi] = x, y, yflu
        return yflu

    def untried_alternatives():
        """Cold descents from the alternatives to the best point, except near (within 1% of
        the box) one already descended from."""
        out = []
        for x in (alternatives(best_x) if reanneal and alternatives else []):
            x = np.clip(np.asarray(x, dtype=float), lower, upper)
            if not any(np.all(np.abs(x - t) <= 0.01 * span) for t in tried):
                tried.append(x)
                out.append((x, False))
        return out

    def converged():
        # relative, and absolute for a minimum at chi^2 = 0 (data made by the model itself)
        return 2 * abs(f.max() - f.min()) <= ftol * (abs(f.max()) + abs(f.min())) + 1e-10

    frozen = False
    while evals < max_evaluations:
        if temp <= t_min:                   # frozen: plain downhill simplex until it converges
            temp, frozen = 0.0, True
        for _ in range(m):
            fluct = f - temp * np.log(rng.random(n + 1))            # vertices get +T|ln u|
            order = np.argsort(fluct)
            lo, hi, nhi = order[0], order[-1], order[-2]
            y = trial(-1.0)                                  # reflect
            if y <= fluct[lo]:
                trial(2.0)                                   # expand
            elif y >= fluct[nhi]:
                ysave = fluct[hi]
                y = trial(0.5)                               # contract
                if y >= ysave:                               # shrink toward the best
                    for i in range(n + 1):
                        if i != lo:
                            simplex[i] = np.clip(0.5 * (simplex[i] + simplex[lo]), lower, upper)
                            f[i] = problem.chi2(simplex[i])
                            evals += 1
                            if f[i] < best_f:
                                best_x, best_f = simplex[i].copy(), float(f[i])
            walk.append(simplex[int(np.argmin(f))].tolist())
            if evals >= max_evaluations or (frozen and converged()):
                break
        if frozen and converged():
            if evals >= max_evaluations:
                finished = True
                break
            before = best_f
            if cycles is None:
                # first freeze: try points the simplex's mirrored moves rarely reach, the best
                # point on every face, edge and corner of the box; then queue a further cooling
                # cycle from the best point
                for x in on_bounds(best_x, lower, upper, every_face=True):
                    y = problem.chi2(x)
                    evals += 1
                    if y < best_f:
                        best_x, best_f = x, y
                cycles = [(None, True)] if reanneal else []
            cycles[:0] = untried_alternatives()
            if cycles:
                x, hot = cycles.pop(0)
                simplex, f = make_simplex(best_x.copy() if x is None else x, step)
                evals += n + 1
                best_i = int(np.argmin(f))
                if f[best_i] < best_f:
                    best_x, best_f = simplex[best_i].copy(), float(f[best_i])
                # a further cooling cycle starts hot enough to leave a basin as deep as its
                # start's chi^2 (Press et al. 10.9); a descent from an alternative, cold
                temp, frozen = (max(float(f[0]), t_min / alpha) if hot else 0.0), False
                reanneals += hot
                descents += not hot
                continue
            if restarts >= max_restarts:
                finished = True
                break
            for x in on_bounds(best_x, lower, upper):
                y = problem.chi2(x)
                evals += 1
                if y < best_f:
                    best_x, best_f = x, y
            # Nelder-Mead can stall on a degenerate simplex: restart around the best point
            # until a restart no longer improves (Press et al. 10.4); the first is full-size
            simplex, f = make_simplex(best_x.copy(), step if restarts == 0 else 0.05)
            evals += n + 1
            restarts += 1
            if restarts > 1 and before - best_f <= ftol * abs(before):
                finished = True
                break
            continue
        temp *= alpha
    return {"theta": best_x, "chi2": float(best_f),
            "status": "converged" if finished else "max_evaluations",
            "message": f"cooled to T = 0 in {1 + reanneals} cycles and {descents} cold descents "
            f"from alternative readings; the simplex converged ({restarts} restarts)" if finished
            else f"stopped at {evals} evaluations (temperature {temp:.3g})",
            "trace": walk, "schedule": {"T0": t0 / pixels, "alpha": alpha, "m": m, "seed": seed,
                                        "temperature_scale_pixels": pixels,
                                        "T0_used": t0_used, "reanneals": reanneals,
                                        "descents": descents,
                                        "evaluations": evals}}
