"""Simulated annealing: the downhill simplex with thermal fluctuations (thesis 6.4.4, 7.3).

After Press et al., Numerical Recipes 2nd ed. 10.9: Nelder-Mead moves with a thermal fluctuation
-T ln(u) added to the vertices' values and subtracted from every trial (trials leaving the box
are mirrored back). The thesis's schedule (7.3.1): m iterations per temperature from T0, then T *=
alpha (scaled by the region's pixels); below t_min the simplex runs cold until its values agree to
ftol. Seeded; the walk is recorded (thesis fig. 7.10).

End-game additions to the thesis's method (tested on its tables 7.4-7.12, docs/THESIS_TABLES.md):

* at the first cold convergence, the best point tried on every face, edge and corner of the box
  (mirrored trials rarely reach a bound, where truths often lie in narrow wells);
* at every freeze, a cold descent from each untried ``alternatives`` reading (the colour model's
  plastic/metal twin, which no simplex move crosses);
* after the first freeze, a further cooling cycle from the best point at T = its chi^2;
* later convergences restart around the best point (Press et al. 10.4), after trying each bound.
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

    ``schedule`` (T0, alpha, m) per pixel (default :data:`SCHEDULES`); ``t_min``: cold below
    it, per pixel; ``step``: starting simplex size per range; ``ftol``: relative spread at
    convergence; ``reanneal``: the module docstring's end game.
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
        """``options`` (default the defaults) with the keys of ``settings`` it names replaced."""
        known = {f.name for f in fields(cls)}
        return replace(options or cls(), **{k: v for k, v in dict(settings).items() if k in known})


def simulated_annealing(problem, start, lower, upper, seed=0, alternatives=None, options=None,
                        **settings):
    """Minimise chi^2 by annealing from ``start``; returns a result dict with the walk.

    ``options`` an :class:`AnnealingOptions`, whose settings keywords may replace (other
    methods' keywords are ignored). ``alternatives(x)``: other readings of a best point x for
    the end game's cold descents.
    """
    run = _Annealing(problem, start, lower, upper, seed, AnnealingOptions.of(options, settings),
                     alternatives)
    return run.result(run.cool())


class _Annealing:
    """One annealing run's state."""

    def __init__(self, problem, start, lower, upper, seed, opts, alternatives):
        self.problem, self.lower, self.upper, self.opts = problem, lower, upper, opts
        self.alternatives = alternatives if opts.reanneal else None
        self.seed, self.rng = seed, np.random.default_rng(seed)
        self.n = n = len(start)
        self.t0, self.alpha, self.m = opts.schedule or SCHEDULES.get(n, (1e6, 0.8, 10))
        # the thesis's temperatures are one pixel's chi^2; a region of P pixels sums P of them
        self.pixels = max(1, int(problem.obs.y.shape[0]))
        self.t0, self.t_min = self.t0 * self.pixels, opts.t_min * self.pixels
        self.span = np.asarray(upper) - np.asarray(lower)
        self.simplex, self.f = self._simplex(np.clip(np.asarray(start, dtype=float), lower, upper),
                                             opts.step)
        self.evals = n + 1
        self.restarts = self.reanneals = self.descents = 0
        self.cycles = None  # queued (start or None for the best point, hot?), from 1st freeze
        self.tried = []      # alternative readings already descended from
        # the thesis's T0 began as a random walk; keep that for larger chi^2 (more pixels, less
        # noise) by starting at least at 10x the initial simplex's largest chi^2
        self.t0_used = max(self.t0, 10.0 * float(np.max(self.f)))
        best_i = int(np.argmin(self.f))
        self.best_x, self.best_f = self.simplex[best_i].copy(), float(self.f[best_i])
        self.walk = [self.best_x.tolist()]
        self.temp = self.t0_used
        self.frozen = False

    def _simplex(self, x0, size):
        """A simplex of x0 and x0 moved by ``size`` of the range along each axis (inwards at the
        upper bound), and their chi^2 (not counted in ``evals``)."""
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
        """One simplex iteration at the temperature."""
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
        """Queue cold descents from the best point's alternatives not within 1% of one tried."""
        out = []
        for x in (self.alternatives(self.best_x) if self.alternatives else []):
            x = np.clip(np.asarray(x, dtype=float), self.lower, self.upper)
            if not any(np.all(np.abs(x - t) <= 0.01 * self.span) for t in self.tried):
                self.tried.append(x)
                out.append((x, False))
        return out

    def _next_cycle(self):
        """At a freeze run the end game (first freeze: box faces and a further cooling cycle;
        every freeze: alternatives) and start the next queued cycle; False if none is left."""
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
        # a further cycle starts at its start's chi^2 (Press et al. 10.9); an alternative, cold
        self.temp = max(float(self.f[0]), self.t_min / self.alpha) if hot else 0.0
        self.frozen = False
        self.reanneals += hot
        self.descents += not hot
        return True

    def cool(self):
        """Anneal until converged for good (True) or out of evaluations (False)."""
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
            # restart a possibly degenerate simplex until that no longer improves (Press 10.4)
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
