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
from dataclasses import dataclass, fields, replace

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


@dataclass(frozen=True)
class AnnealingOptions:
    """The settings of :func:`simulated_annealing`; ``method_options`` of a fit name them.

    ``schedule`` (T0, alpha, m): the starting temperature (a chi^2 of one pixel's sequence),
    the cooling factor per step and the simplex iterations at each temperature (default the
    thesis's, :data:`SCHEDULES`, by number of parameters).  ``t_min``: the temperature (per
    pixel) below which the simplex runs cold.  ``step``: the starting simplex's size, a
    fraction of each parameter's range.  ``ftol``: the relative spread of the simplex's
    chi^2 values at which it has converged.  ``max_restarts``: restarts of a converged
    simplex.  ``reanneal``: the end game of the module's docstring (a further cooling cycle,
    cold descents from the alternative readings).
    """

    schedule: tuple | None = None
    max_evaluations: int = 15000
    t_min: float = 0.1
    step: float = 0.25
    ftol: float = 1e-7
    max_restarts: int = 4
    reanneal: bool = True

    @classmethod
    def of(cls, options=None, settings=()):
        """``options`` (default the defaults) with those of ``settings`` (a dict of keyword
        options) it names replaced; other keys (another method's options) are ignored."""
        known = {f.name for f in fields(cls)}
        return replace(options or cls(), **{k: v for k, v in dict(settings).items() if k in known})


def simulated_annealing(problem, start, lower, upper, seed=0, alternatives=None, options=None,
                        **settings):
    """Minimise chi^2 by annealing from ``start``; returns a result dict with the walk.

    ``options`` an :class:`AnnealingOptions`; its settings may also be given as keywords
    (``schedule=``, ``max_evaluations=``, ...: a fit's ``method_options``), which replace
    those of ``options``; keywords of other methods (``grid_basis``) are ignored.  With
    ``reanneal`` the end game of the module's docstring follows the first cooling cycle: a
    further cycle from its best point, and cold descents from ``alternatives(x)`` of every
    new best point x (each distinct point once).
    """
    run = _Annealing(problem, start, lower, upper, seed, AnnealingOptions.of(options, settings),
                     alternatives)
    return run.result(run.cool())


class _Annealing:
    """One annealing run's state: the simplex and its chi^2 values, the temperature, the best
    point, the walk and the counts of the end game."""

    def __init__(self, problem, start, lower, upper, seed, opts, alternatives):
        self.problem, self.lower, self.upper, self.opts = problem, lower, upper, opts
        self.alternatives = alternatives if opts.reanneal else None
        self.seed, self.rng = seed, np.random.default_rng(seed)
        self.n = n = len(start)
        self.t0, self.alpha, self.m = opts.schedule or SCHEDULES.get(n, (1e6, 0.8, 10))
        # The thesis's temperatures are chi^2 values of one pixel's sequence; a region of P
        # pixels sums P such chi^2, so its temperatures are P times higher.
        self.pixels = max(1, int(problem.obs.y.shape[0]))
        self.t0, self.t_min = self.t0 * self.pixels, opts.t_min * self.pixels
        self.span = np.asarray(upper) - np.asarray(lower)
        self.simplex, self.f = self._simplex(np.clip(np.asarray(start, dtype=float), lower, upper),
                                             opts.step)
        self.evals = n + 1
        self.restarts = self.reanneals = self.descents = 0
        self.cycles = None  # queued (start or None for the best point, hot?), from 1st freeze
        self.tried = []      # alternative readings already descended from
        # The thesis's T0 (1e6, 1e7) exceeded its sequences' chi^2 many times over, so annealing
        # began as a random walk.  Sequences with more pixels or less noise have larger chi^2:
        # then start at 10x the initial simplex's largest chi^2 to keep that first phase.
        self.t0_used = max(self.t0, 10.0 * float(np.max(self.f)))
        best_i = int(np.argmin(self.f))
        self.best_x, self.best_f = self.simplex[best_i].copy(), float(self.f[best_i])
        self.walk = [self.best_x.tolist()]
        self.temp = self.t0_used
        self.frozen = False

    def _simplex(self, x0, size):
        """A simplex of n + 1 points (x0, and x0 moved by ``size`` of the range along each
        axis, inwards at the upper bound) and their chi^2 (not counted in ``evals``)."""
        pts = [x0]
        for i in range(self.n):
            v, d = x0.copy(), size * self.span[i]
            v[i] = v[i] + d if v[i] + d <= self.upper[i] else v[i] - d
            pts.append(np.clip(v, self.lower, self.upper))
        return np.array(pts), np.array([self.problem.chi2(v) for v in pts])

    def _try(self, points):
        """chi^2 at each point; the best point becomes the lowest of them if lower."""
        for x in points:
            y = self.problem.chi2(x)
            self.evals += 1
            if y < self.best_f:
                self.best_x, self.best_f = x, y

    def _trial(self, fac):
        """The worst vertex moved through the others' centroid by ``fac`` (mirrored into the
        box), replacing it if better after a negative thermal fluctuation; that value."""
        simplex, hi = self.simplex, self.hi
        centroid = (simplex.sum(axis=0) - simplex[hi]) / self.n
        x = reflect_into(centroid * (1 - fac) + simplex[hi] * fac, self.lower, self.upper)
        y = self.problem.chi2(x)
        self.evals += 1
        if y < self.best_f:
            self.best_x, self.best_f = x.copy(), y
        yflu = y + self.temp * np.log(self.rng.random())       # trials get a negative fluctuation
        if yflu < self.fluct[hi]:
            simplex[hi], self.f[hi], self.fluct[hi] = x, y, yflu
        return yflu

    def _move(self):
        """One simplex iteration at the temperature: reflect, then expand, or contract and
        if that fails shrink toward the best vertex."""
        n, simplex, f = self.n, self.simplex, self.f
        self.fluct = f - self.temp * np.log(self.rng.random(n + 1))   # vertices get +T|ln u|
        order = np.argsort(self.fluct)
        lo, self.hi, nhi = order[0], order[-1], order[-2]
        y = self._trial(-1.0)                                # reflect
        if y <= self.fluct[lo]:
            self._trial(2.0)                                 # expand
        elif y >= self.fluct[nhi]:
            ysave = self.fluct[self.hi]
            y = self._trial(0.5)                             # contract
            if y >= ysave:                                   # shrink toward the best
                for i in range(n + 1):
                    if i != lo:
                        simplex[i] = np.clip(0.5 * (simplex[i] + simplex[lo]), self.lower,
                                             self.upper)
                        f[i] = self.problem.chi2(simplex[i])
                        self.evals += 1
                        if f[i] < self.best_f:
                            self.best_x, self.best_f = simplex[i].copy(), float(f[i])

    def _converged(self):
        # relative, and absolute for a minimum at chi^2 = 0 (data made by the model itself)
        f = self.f
        return 2 * abs(f.max() - f.min()) <= self.opts.ftol * (abs(f.max()) + abs(f.min())) + 1e-10

    def _untried_alternatives(self):
        """Cold descents from the alternatives to the best point, except near (within 1% of
        the box) one already descended from."""
        out = []
        for x in (self.alternatives(self.best_x) if self.alternatives else []):
            x = np.clip(np.asarray(x, dtype=float), self.lower, self.upper)
            if not any(np.all(np.abs(x - t) <= 0.01 * self.span) for t in self.tried):
                self.tried.append(x)
                out.append((x, False))
        return out

    def _next_cycle(self):
        """At a freeze: on the first, try the best point on every face, edge and corner of the
        box (points the simplex's mirrored moves rarely reach) and queue a further cooling
        cycle from the best point; on every one, queue cold descents from the untried
        alternatives.  Starts the next queued cycle; False if none is left."""
        if self.cycles is None:
            self._try(on_bounds(self.best_x, self.lower, self.upper, every_face=True))
            self.cycles = [(None, True)] if self.opts.reanneal else []
        self.cycles[:0] = self._untried_alternatives()
        if not self.cycles:
            return False
        x, hot = self.cycles.pop(0)
        self.simplex, self.f = self._simplex(self.best_x.copy() if x is None else x,
                                             self.opts.step)
        self.evals += self.n + 1
        best_i = int(np.argmin(self.f))
        if self.f[best_i] < self.best_f:
            self.best_x, self.best_f = self.simplex[best_i].copy(), float(self.f[best_i])
        # a further cooling cycle starts hot enough to leave a basin as deep as its start's
        # chi^2 (Press et al. 10.9); a descent from an alternative, cold
        self.temp = max(float(self.f[0]), self.t_min / self.alpha) if hot else 0.0
        self.frozen = False
        self.reanneals += hot
        self.descents += not hot
        return True

    def cool(self):
        """Anneal, with the end game at each freeze, until the simplex has converged for good
        (True) or the evaluations run out (False)."""
        opts = self.opts
        while self.evals < opts.max_evaluations:
            if self.temp <= self.t_min:     # frozen: plain downhill simplex until it converges
                self.temp, self.frozen = 0.0, True
            for _ in range(self.m):
                self._move()
                self.walk.append(self.simplex[int(np.argmin(self.f))].tolist())
                if self.evals >= opts.max_evaluations or (self.frozen and self._converged()):
                    break
            if not (self.frozen and self._converged()):
                self.temp *= self.alpha
                continue
            if self.evals >= opts.max_evaluations:
                return True
            before = self.best_f
            if self._next_cycle():
                continue
            if self.restarts >= opts.max_restarts:
                return True
            self._try(on_bounds(self.best_x, self.lower, self.upper))
            # Nelder-Mead can stall on a degenerate simplex: restart around the best point
            # until a restart no longer improves (Press et al. 10.4); the first is full-size
            self.simplex, self.f = self._simplex(self.best_x.copy(),
                                                 opts.step if self.restarts == 0 else 0.05)
            self.evals += self.n + 1
            self.restarts += 1
            if self.restarts > 1 and before - self.best_f <= opts.ftol * abs(before):
                return True
        return False

    def result(self, finished):
        """The result dict: the best point, its chi^2, the status and the walk."""
        return {"theta": self.best_x, "chi2": float(self.best_f),
                "status": "converged" if finished else "max_evaluations",
                "message": f"cooled to T = 0 in {1 + self.reanneals} cycles and {self.descents} "
                f"cold descents from alternative readings; the simplex converged "
                f"({self.restarts} restarts)" if finished
                else f"stopped at {self.evals} evaluations (temperature {self.temp:.3g})",
                "trace": self.walk,
                "schedule": {"T0": self.t0 / self.pixels, "alpha": self.alpha, "m": self.m,
                             "seed": self.seed, "temperature_scale_pixels": self.pixels,
                             "T0_used": self.t0_used, "reanneals": self.reanneals,
                             "descents": self.descents, "evaluations": self.evals}}
