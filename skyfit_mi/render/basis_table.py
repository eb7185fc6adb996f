"""A region's fitting model as a table: L = rho_d D + s G(sigma) with G tabulated in sigma.

Ward's model is linear in its reflectances (thesis eq. 3.19), with D the diffuse basis and G
the lobe of rho_s = 1 (:class:`~.fit_model.WardModel`); only sigma_alpha enters non-linearly.
:func:`tabulate` evaluates D and G once on the cached samples and keeps G as Chebyshev series
in log sigma on each smooth piece of the sigma range (PIECES end where the model's form
changes: below SIGMA_RESOLVED, and at the lobe control variate's CONTROL_FULL, CONTROL_SIGMA).
The samples can then be dropped, so a sequence is traced in blocks of bounded memory.

The table keeps the two halves of every pixel's positions apart (as mean M and half difference
Delta; halves M +- Delta): independent estimates whose fits give the cache's own error.  The
model's Monte Carlo variance is the positions' spread, kept as covariances of D and G at a few
roughness values (the variance of rho_d D + s G is bilinear in the reflectances).
"""

from dataclasses import dataclass, replace

import numpy as np

from .fit_model import PARAMETERS, WardModel, reflectance_sets, reflectances
from .light_cache import (CONTROL_FULL, CONTROL_SIGMA, SIGMA_LARGEST, SIGMA_RESOLVED,
                          CacheOptions, PointRays, light_caches)
from .sky_control import chebyshev_x

#: The smooth pieces of G(sigma) above SIGMA_RESOLVED and the first degree of each piece's
#: Chebyshev series: doubled (nested Lobatto nodes keep every value) until it agrees with the
#: model within TABLE_RTOL of the piece's largest value at CHECKS points between nodes, or stops
#: improving, up to MAX_DEGREE.  TABLE_RTOL is far under a cache's Monte Carlo error.
PIECES = ((SIGMA_RESOLVED, CONTROL_FULL), (CONTROL_FULL, CONTROL_SIGMA),
          (CONTROL_SIGMA, SIGMA_LARGEST))
DEGREES, MAX_DEGREE, TABLE_RTOL, CHECKS = (16, 6, 32), 64, 1e-5, 3
#: Degrees of the Lobatto nodes (among each piece's first DEGREES') at which the table keeps
#: the positions' spread: it changes slowly with sigma, except where a lobe starts to take in
#: the sun (the narrow piece, kept denser).
VARIANCE_DEGREES = (16, 3, 8)
#: Light-cache samples traced and tabulated at once (:func:`trace_basis`), and their peak bytes
#: each (the cache's arrays, the model's Dr.Jit copies and the tracer's; tests/test_memory.py).
CHUNK_SAMPLES, BYTES_PER_SAMPLE = 1 << 22, 140
#: The peak a fit aims at [bytes]: a large table's blocks shrink down to MIN_CHUNK_SAMPLES.
MEMORY_TARGET, MIN_CHUNK_SAMPLES = 2 << 30, 1 << 19


def _lobatto(n):
    """The n + 1 Chebyshev-Lobatto points cos(pi k / n), ends included (pieces share them)."""
    return np.cos(np.pi * np.arange(n + 1) / n)


def _sigma(x, lo, hi):
    """The roughness at coordinates ``x`` of the piece [lo, hi] (its ends exactly)."""
    a, b = np.log(lo), np.log(hi)
    s = np.exp(0.5 * (a + b) + 0.5 * (b - a) * np.asarray(x, dtype=float))
    return np.where(x <= -1, lo, np.where(x >= 1, hi, s))


def _chebyshev_rows(x, n, derivative=False):
    """T_k(x) for k = 0..n at ``x`` (K,), (K, n + 1), and with ``derivative`` dT_k/dx =
    k U_{k-1}(x) too (U of the second kind, by recurrence)."""
    x = np.atleast_1d(np.asarray(x, dtype=float))
    T = np.polynomial.chebyshev.chebvander(x, n)
    if not derivative:
        return T
    U = np.zeros_like(T)
    U[:, 0] = 1.0
    if n > 0:
        U[:, 1] = 2.0 * x
    for k in range(2, n + 1):
        U[:, k] = 2.0 * x * U[:, k - 1] - U[:, k - 2]
    dT = np.zeros_like(T)
    dT[:, 1:] = np.arange(1, n + 1) * U[:, :n]
    return T, dT


def _cut(x, axis, rows, frames):
    """A view of ``x`` at slices ``rows``, ``frames`` of its pixel ``axis`` and the next one."""
    if isinstance(x, _Mixed):
        return x.cut(axis, rows, frames)
    where = [slice(None)] * x.ndim
    where[axis], where[axis + 1] = rows, frames
    return x[tuple(where)]


def _within(part, whole):
    """Where slices ``part`` and ``whole`` (step 1) meet, as (slice within ``whole``, slice
    within ``part``), or None."""
    lo, hi = max(part.start, whole.start), min(part.stop, whole.stop)
    if lo >= hi:
        return None
    return slice(lo - whole.start, hi - whole.start), slice(lo - part.start, hi - part.start)


@dataclass
class Series:
    """One piece's Chebyshev coefficients of G in log sigma, in the blocks they were traced in,
    each at its own degree (never padded nor copied into one array).

    ``blocks``: [(rows, frames, coef)] with ``rows``, ``frames`` slices of the table and
    ``coef`` (2, n + 1, p, t, 3) the stored mean and half difference (:attr:`BasisTable.PARTS`).
    """

    blocks: list

    def subset(self, rows, frames):
        """The series of pixels ``rows`` and frames ``frames`` (slices of step 1), as views."""
        out = []
        for r, f, c in self.blocks:
            rr, ff = _within(rows, r), _within(frames, f)
            if rr is not None and ff is not None:
                out.append((rr[1], ff[1], _cut(c, 2, rr[0], ff[0])))
        return Series(out)

    def map(self, f):
        """The series with ``f`` applied to every block's coefficients."""
        return Series([(r, fr, f(c)) for r, fr, c in self.blocks])

    def places(self):
        """Each block's (rows, frames)."""
        return [(r, f) for r, f, _ in self.blocks]

    def coefficients(self, i, h):
        """Block ``i``'s coefficients (n + 1, p, t, 3) of the stored mean (``h`` = 0) or half
        difference (1)."""
        return self.blocks[i][2][h]

    def evaluate(self, x, h, shape, derivative=False):
        """The stored mean (``h`` = 0) or half difference (1) at the coordinates ``x`` (K,)
        of the piece: (K,) + ``shape`` float64, and its derivative in x."""
        out = np.empty((len(x),) + tuple(shape))
        dout = np.empty_like(out) if derivative else None
        rows_of = {}
        for i, (r, f) in enumerate(self.places()):
            c = self.coefficients(i, h)
            n = c.shape[0] - 1
            if n not in rows_of:
                rows_of[n] = _chebyshev_rows(x, n, True) if derivative else \
                    (_chebyshev_rows(x, n), None)
            T, dT = rows_of[n]
            flat = c.reshape(n + 1, -1)
            size = (len(x),) + c.shape[1:]
            out[:, r, f] = (T.astype(flat.dtype) @ flat).reshape(size)
            if derivative:
                dout[:, r, f] = (dT.astype(flat.dtype) @ flat).reshape(size)
        return (out, dout) if derivative else out


@dataclass
class BasisTable:
    """D and G(sigma) of P pixels in T frames, for each half of the cache's positions (as mean
    and half difference, an axis of length 2), and the positions' spread.

    Attributes
    ----------
    D : (2, P, T, 3)  the diffuse basis [W m^-2 sr^-1]
    G0 : (2, P, T, 3)  G at sigma = 0, the ideal mirror
    G1 : (2, P, T, 3)  G at SIGMA_RESOLVED (the model is linear in sigma between)
    coef : one :class:`Series` per piece of PIECES, float32 Chebyshev coefficients of G in log
        sigma [W m^-2 sr^-1]
    VDD : (P, T, 3)  var(D) over the positions' estimates / S [(W m^-2 sr^-1)^2]
    VDG, VGG : (V, P, T, 3)  cov(D, G) and var(G) likewise at the V roughness values
        ``var_sigmas`` (:func:`variance_sigmas`)
    hit : (P, T) bool  every position of the pixel lands on the material
    sun_cos : (P, T, S, 3) float32  the light cache's, per position (NaN without sun)
    normalisation : the Ward normalisation of the lobe
    """

    D: np.ndarray
    G0: np.ndarray
    G1: np.ndarray
    coef: list
    VDD: np.ndarray
    VDG: np.ndarray
    VGG: np.ndarray
    hit: np.ndarray
    sun_cos: np.ndarray
    normalisation: str = "ward"

    #: The pixel axis of each array field (the frame axis follows it).
    AXES = {"D": 1, "G0": 1, "G1": 1, "VDD": 0, "VDG": 1, "VGG": 1, "hit": 0,
            "sun_cos": 0}

    @property
    def shape(self):
        """(P, T)."""
        return self.D.shape[1:3]

    @property
    def var_sigmas(self):
        return variance_sigmas()

    def subset(self, rows=slice(None), frames=slice(None)):
        """The table of pixels ``rows`` and frames ``frames`` (slices of step 1), as views."""
        rows = slice(*rows.indices(self.shape[0]))
        frames = slice(*frames.indices(self.shape[1]))
        return BasisTable(**{k: _cut(getattr(self, k), a, rows, frames)
                             for k, a in self.AXES.items()},
                          coef=[c.subset(rows, frames) for c in self.coef],
                          normalisation=self.normalisation)

    def tinted(self, factor):
        """The table of this light times ``factor`` (3,) per channel (None: itself)."""
        if factor is None:
            return self
        f = np.asarray(factor, dtype=np.float32)
        return replace(self, D=self.D * f, G0=self.G0 * f, G1=self.G1 * f,
                       coef=[c.map(lambda x: x * f) for c in self.coef], VDD=self.VDD * f * f,
                       VDG=self.VDG * f * f, VGG=self.VGG * f * f)

    @classmethod
    def empty(cls, P, T, S, normalisation):
        """A zero table of P pixels, T frames, S positions, to fill with :meth:`place`."""
        f32 = np.float32
        V = len(variance_sigmas())
        return cls(np.zeros((2, P, T, 3), f32), np.zeros((2, P, T, 3), f32),
                   np.zeros((2, P, T, 3), f32), [Series([]) for _ in PIECES],
                   np.zeros((P, T, 3), f32), np.zeros((V, P, T, 3), f32),
                   np.zeros((V, P, T, 3), f32), np.zeros((P, T), bool),
                   np.zeros((P, T, S, 3), f32), normalisation)

    def place(self, block, rows, frames):
        """Copy the table ``block`` into pixels ``rows`` and frames ``frames`` (slices)."""
        for k, a in self.AXES.items():
            _cut(getattr(self, k), a, rows, frames)[...] = getattr(block, k)
        for mine, theirs in zip(self.coef, block.coef):
            mine.blocks += [(rows, frames, c) for _, _, c in theirs.blocks]

    #: The whole cache (part 0), its first (1) or second (2) half, and the halves' half
    #: difference ('delta'), as weights of the stored (mean, half difference).
    PARTS = {0: (1.0, 0.0), 1: (1.0, 1.0), 2: (1.0, -1.0), "delta": (0.0, 1.0)}

    def diffuse(self, part=0):
        """D of ``part`` (PARTS), (P, T, 3) float64."""
        return sum(w * self.D[h].astype(float) for h, w in enumerate(self.PARTS[part]) if w)

    def variance(self, rho_d, spec, sigma):
        """The whole cache's Monte Carlo variance of L = rho_d D + s G(sigma), (P, T, 3),
        interpolated between ``var_sigmas`` (in sigma below SIGMA_RESOLVED, log sigma above)."""
        v = self.var_sigmas
        k = int(np.clip(np.searchsorted(v, sigma, side="right") - 1, 0, len(v) - 2))
        lo, hi = v[k], v[k + 1]
        if k == 0:
            t = np.clip((sigma - lo) / (hi - lo), 0.0, 1.0)
        else:
            t = np.clip(np.log(max(sigma, lo) / lo) / np.log(hi / lo), 0.0, 1.0)
        # var(G) geometrically (it grows like exp(-c / sigma^2) where a lobe starts to take in
        # the sun), the correlation of D and G linearly
        tiny = 1e-30
        ends = [np.maximum(self.VGG[i].astype(float), tiny) for i in (k, k + 1)]
        VGG = ends[0] ** (1 - t) * ends[1] ** t
        r = [self.VDG[i] / np.sqrt(np.maximum(self.VDD, tiny) * e)
             for i, e in zip((k, k + 1), ends)]
        VDG = np.clip((1 - t) * r[0] + t * r[1], -1, 1) * np.sqrt(np.maximum(self.VDD, tiny)
                                                                 * VGG)
        return np.maximum(rho_d**2 * self.VDD + 2 * rho_d * spec * VDG + spec**2 * VGG, 0.0)

    def lobe(self, sigma, derivative=False, part=0):
        """G of ``part`` (PARTS) at the roughness values ``sigma`` (K,): (K, P, T, 3) float64,
        and with ``derivative`` dG/dsigma too."""
        terms = [self._series(sigma, derivative, h) for h, w in enumerate(self.PARTS[part]) if w]
        weights = [w for w in self.PARTS[part] if w]
        if derivative:
            return tuple(sum(w * t[k] for w, t in zip(weights, terms)) for k in (0, 1))
        return sum(w * t for w, t in zip(weights, terms))

    def _series(self, sigma, derivative, h):
        """G's stored mean (h = 0) or half difference (1) at ``sigma``, and dG/dsigma."""
        sigma = np.atleast_1d(np.asarray(sigma, dtype=float))
        out = np.empty((len(sigma),) + self.D.shape[1:])
        dout = np.empty_like(out) if derivative else None
        low = sigma < SIGMA_RESOLVED
        if low.any():
            G0, G1 = self.G0[h].astype(float), self.G1[h].astype(float)
            t = (sigma[low] / SIGMA_RESOLVED)[:, None, None, None]
            out[low] = G0 + t * (G1 - G0)
            if derivative:
                dout[low] = (G1 - G0) / SIGMA_RESOLVED
        piece = np.searchsorted([p[1] for p in PIECES], sigma, side="left")
        piece = np.minimum(piece, len(PIECES) - 1)
        for i, (lo, hi) in enumerate(PIECES):
            at = np.flatnonzero(~low & (piece == i))
            if not len(at):
                continue
            x = chebyshev_x(sigma[at], lo, hi, np.log, np.clip)
            got = self.coef[i].evaluate(x, h, out.shape[1:], derivative)
            if derivative:
                # dx/dsigma = 2 / (sigma (log hi - log lo))
                scale = 2.0 / (sigma[at] * (np.log(hi) - np.log(lo)))
                out[at], dout[at] = got[0], got[1] * scale[:, None, None, None]
            else:
                out[at] = got
        return (out, dout) if derivative else out


def _spread(x, y, S):
    """The covariance of the positions' estimates (S times each share (P, T, S, ...)) / S:
    that of their mean."""
    if S < 2:
        return np.zeros(x.shape[:2] + x.shape[3:])
    xs, ys = x * S, y * S
    return np.sum((xs - xs.mean(axis=2, keepdims=True)) * (ys - ys.mean(axis=2, keepdims=True)),
                  axis=2) / ((S - 1) * S)


def tabulate(cache, wm, keep=None):
    """The :class:`BasisTable` of ``cache`` through its :class:`~.fit_model.WardModel` ``wm``
    (of several lights: one table, stacked by pixel).  ``keep``, a dict, receives the positions'
    shares of D ('D') and of G at each :func:`variance_sigmas` value."""
    S = wm.S
    lights = len(wm.lights)
    h = S // 2
    if h < 1:
        raise ValueError("a light cache with one position per pixel cannot be tabulated")

    def halves(shares):
        # each half as an estimate of the whole; a last odd position is in neither
        a = shares[:, :, :h].sum(axis=2) * (S / h)
        b = shares[:, :, h:2 * h].sum(axis=2) * (S / h)
        return np.stack([(a + b) / 2, (a - b) / 2])

    d_shares = wm._diffuse_shares()
    if keep is not None:
        keep["D"] = d_shares
    want = set(variance_sigmas().tolist())
    known, moments = {}, {}

    def lobe(sigma):
        if sigma not in known:
            shares = wm._shares(1.0, sigma)
            wm.basis_evaluations += 1
            known[sigma] = halves(shares)
            if sigma in want:
                moments[sigma] = (_spread(d_shares, shares, S), _spread(shares, shares, S))
                if keep is not None:
                    keep[sigma] = shares
        return known[sigma]
    D = halves(d_shares)
    G0, G1 = lobe(0.0), lobe(SIGMA_RESOLVED)
    P, T = D.shape[1:3]
    coef = [Series([(slice(0, P), slice(0, T), _piece(lobe, lo, hi, n))])
            for (lo, hi), n in zip(PIECES, DEGREES)]
    f32 = np.float32
    VDG, VGG = (np.stack([moments[float(v)][i] for v in variance_sigmas()]).astype(f32)
                for i in (0, 1))
    return BasisTable(D.astype(f32), G0.astype(f32), G1.astype(f32), coef,
                      _spread(d_shares, d_shares, S).astype(f32), VDG, VGG,
                      np.tile(cache.hit, (lights, 1)),
                      np.tile(cache.sun_cos.astype(f32), (lights, 1, 1, 1)), wm.normalisation)


@dataclass
class Covariances:
    """Covariances between the tables of lights traced on shared samples, for :func:`mixed`;
    for each pair j < k of ``pairs`` (indices into the lights), as a table's VDD, VDG, VGG:

    DD : (n, P, T, 3)  cov(D_j, D_k)
    DG : (n, V, P, T, 3)  cov(D_j, G_k) + cov(D_k, G_j) at the V ``variance_sigmas``
    GG : (n, V, P, T, 3)  cov(G_j, G_k)
    """

    pairs: list
    DD: np.ndarray
    DG: np.ndarray
    GG: np.ndarray

    #: The pixel axis of each array field (the frame axis follows it).
    AXES = {"DD": 1, "DG": 2, "GG": 2}

    @classmethod
    def empty(cls, n_lights, P, T):
        """Zero covariances of ``n_lights`` lights, P pixels, T frames, to fill by :meth:`place`."""
        pairs = [(j, k) for j in range(n_lights) for k in range(j + 1, n_lights)]
        V, n = len(variance_sigmas()), len(pairs)
        return cls(pairs, np.zeros((n, P, T, 3), np.float32),
                   np.zeros((n, V, P, T, 3), np.float32), np.zeros((n, V, P, T, 3), np.float32))

    def subset(self, rows=slice(None), frames=slice(None)):
        """Pixels ``rows`` and frames ``frames`` (slices of step 1), as views."""
        return Covariances(self.pairs, **{k: _cut(getattr(self, k), a, rows, frames)
                                          for k, a in self.AXES.items()})

    def place(self, block, rows, frames):
        """Copy the covariances ``block`` into pixels ``rows`` and frames ``frames``."""
        for k, a in self.AXES.items():
            _cut(getattr(self, k), a, rows, frames)[...] = getattr(block, k)


def tabulate_group(caches, model, normalisation="ward"):
    """The :class:`BasisTable` of each of ``caches`` (of one trace's samples), tabulated through
    one :class:`~.fit_model.WardModel`, and the :class:`Covariances` between them."""
    keep = {}
    whole = tabulate(caches[0], WardModel(caches[0], model, normalisation, caches[1:]), keep)
    P, T = caches[0].hit.shape
    M, S = len(caches), keep["D"].shape[2]
    cov = Covariances.empty(M, P, T)
    if S > 1 and cov.pairs:
        def centred(key):           # each light's positions' estimates less their mean
            x = np.moveaxis(keep[key].reshape(M, P, T, S, 3) * S, (0, 3), (3, 4))
            return x - x.mean(axis=4, keepdims=True)                    # (P, T, 3, M, S)

        def spreads(x, y):          # _spread of every pair of lights, [j, k] (P, T, 3)
            return np.moveaxis(x @ np.swapaxes(y, 3, 4) / ((S - 1) * S), (3, 4), (0, 1))
        j, k = np.array(cov.pairs).T
        d = centred("D")
        cov.DD[:] = spreads(d, d)[j, k]
        for v, sigma in enumerate(float(v) for v in variance_sigmas()):
            g = centred(sigma)
            DG = spreads(d, g)
            cov.DG[:, v] = DG[j, k] + DG[k, j]
            cov.GG[:, v] = spreads(g, g)[j, k]
    return [whole.subset(slice(m * P, (m + 1) * P)) for m in range(M)], cov


def variance_sigmas():
    """The roughness values at which a table keeps its positions' spread, ascending: the
    mirror, then each piece's Lobatto nodes of degree VARIANCE_DEGREES."""
    out = {0.0}
    for (lo, hi), n, m in zip(PIECES, DEGREES, VARIANCE_DEGREES):
        out |= set(_sigma(_lobatto(n)[::n // m], lo, hi).tolist())
    return np.array(sorted(out))


def _piece(lobe, lo, hi, n):
    """Chebyshev coefficients (2, n + 1, P, T, 3) of ``lobe(sigma)`` on [lo, hi] in log sigma,
    n doubled until TABLE_RTOL holds, the error stops improving (float32 rounding of a tiny
    light), or MAX_DEGREE."""
    C = np.polynomial.chebyshev
    last = np.inf
    while True:
        x = _lobatto(n)
        values = np.stack([lobe(float(s)) for s in _sigma(x, lo, hi)])     # (n + 1, 2, ...)
        flat = np.linalg.solve(C.chebvander(x, n), values.reshape(n + 1, -1))
        if n >= MAX_DEGREE:
            break
        # between nodes: the midpoints of CHECKS of the widest gaps, spread over the piece
        mid = np.cos(np.pi * (np.linspace(0, n - 1, CHECKS).round() + 0.5) / n)
        worst = max(np.max(np.abs(C.chebvander([m], n) @ flat - _lobe_at(lobe, m, lo, hi)))
                    for m in mid) / max(np.max(np.abs(values[:, 0])), 1e-30)
        if worst <= TABLE_RTOL or worst > 0.5 * last:
            break
        last, n = worst, 2 * n
    return np.moveaxis(flat.reshape(values.shape), 0, 1).astype(np.float32)


def _lobe_at(lobe, x, lo, hi):
    """``lobe`` at the coordinate ``x`` of the piece [lo, hi], flattened."""
    return lobe(float(_sigma(x, lo, hi))).reshape(1, -1)


#: Bytes a fit takes per value (pixel or point, frame and channel) beside its table (the
#: observations, the model's and search's arrays), and the process's base [bytes].
FIT_BYTES_PER_VALUE, BASE_BYTES = 1024, 300 << 20


def _bytes_per_value(degrees, positions):
    """A fit's bytes per value with series of ``degrees``: its table's arrays and its own."""
    arrays = 2 * sum(n + 1 for n in degrees) + 2 * len(variance_sigmas()) + 7
    return 4 * arrays + 4 * positions / 3 + FIT_BYTES_PER_VALUE


def block_budget(P, T, positions):
    """Samples per block of a fit of P points in T frames: CHUNK_SAMPLES, or fewer (down to
    MIN_CHUNK_SAMPLES) where the table leaves less of MEMORY_TARGET."""
    room = MEMORY_TARGET - BASE_BYTES - P * T * 3 * _bytes_per_value(DEGREES, positions)
    return int(np.clip(room / BYTES_PER_SAMPLE, MIN_CHUNK_SAMPLES, CHUNK_SAMPLES))


def shared_budget(budget, lights):
    """A block's samples where ``lights`` lights share one trace's samples, for a ``budget``
    of one light's: each light's own arrays take about a light's memory again."""
    return int(budget // lights)


def memory_estimate(P, T, positions, directions):
    """The most a fit of P points in T frames takes [bytes]: its table at MAX_DEGREE, its own
    arrays, one block of the light and the base."""
    per_value = _bytes_per_value([MAX_DEGREE] * len(PIECES), positions)
    block = min(block_budget(P, T, positions), P * T * positions * directions)
    return int(P * T * 3 * per_value + block * BYTES_PER_SAMPLE + BASE_BYTES)


def available_memory():
    """Linux's MemAvailable [bytes], or None elsewhere."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def chunks(P, T, per_value, budget):
    """(rows, frames) slices splitting P points x T frames of ``per_value`` samples into blocks
    of at most ``budget`` samples (at least one): as many points as fit, then frames."""
    rows = int(min(P, max(1, budget // per_value)))
    frames = int(min(T, max(1, budget // (per_value * rows))))
    return [(slice(r, min(r + rows, P)), slice(f, min(f + frames, T)))
            for f in range(0, T, frames) for r in range(0, P, rows)]


def mixed(a, others, weights, a_weight=1.0, covariances=None, tint=None):
    """The table of the light w_a a + sum_j w_j b_j from tables ``a`` and ``others`` [b_j] of
    parts of one light (:meth:`~skyfit_mi.physics.sky.Sky.split`,
    :func:`~skyfit_mi.physics.sky_shape.shape_variants`) traced in the same blocks: bases add
    linearly, variances with w^2, plus 2 w_j w_k ``covariances`` (:class:`Covariances`, indices
    into ``[a, *others]``) for shared samples.  Each weight (``a_weight``, ``weights``) is a
    factor or one per frame (T,), and may be negative; ``tint`` (3,) multiplies them all per
    channel (:meth:`BasisTable.tinted`).  The lobe's series and the variances at ``var_sigmas``
    are mixed where first used (a fit at one roughness needs one piece and two of them)."""
    parts = [a, *others]
    T = a.shape[1]
    tint = np.ones(3, np.float32) if tint is None else np.asarray(tint, np.float32)
    # every weight as (T, 3): per frame and channel, against (..., T, 3)
    wt = [np.broadcast_to(np.reshape(np.asarray(w, np.float32), (-1, 1)), (T, 1)) * tint
          for w in [a_weight, *weights]]
    # the variances' terms: (array, weight) of each part (w^2), then each pair (w_j w_k)
    pairs = [] if covariances is None else [(i, wt[j] * wt[k])
                                             for i, (j, k) in enumerate(covariances.pairs)]

    def add(name):
        return sum(w * getattr(b, name) for b, w in zip(parts, wt))

    def variance(name, pair_name, factor):
        return [(getattr(b, name), w * w) for b, w in zip(parts, wt)] + [
            (getattr(covariances, pair_name)[i], factor * w) for i, w in pairs]
    VDD = sum(w * x for x, w in variance("VDD", "DD", 2.0))
    hit = a.hit
    for b in others:
        hit = hit & b.hit
    coef = [_MixedSeries([b.coef[n] for b in parts], wt) for n in range(len(a.coef))]
    return BasisTable(add("D"), add("G0"), add("G1"), coef, VDD,
                      _Mixed(variance("VDG", "DG", 1.0)), _Mixed(variance("VGG", "GG", 2.0)),
                      hit, a.sun_cos, a.normalisation)


class _Mixed:
    """sum_j w_j X_j of arrays X_j (V, P, T, 3) with weights w_j (T, 3), each X[i] (one
    roughness's) mixed when first asked for; other indices take the whole mix."""

    def __init__(self, terms):
        self.terms, self.done, self.whole = terms, {}, None
        self.shape = terms[0][0].shape

    def __getitem__(self, key):
        if isinstance(key, (int, np.integer)):
            if key not in self.done:
                self.done[key] = sum(w * x[key] for x, w in self.terms)
            return self.done[key]
        return self.__array__()[key]

    def __len__(self):
        return self.shape[0]

    def cut(self, axis, rows, frames):
        """The mix at pixels ``rows`` and frames ``frames`` (:func:`_cut`), still unmixed."""
        return _Mixed([(_cut(x, axis, rows, frames), w[frames]) for x, w in self.terms])

    def __array__(self, dtype=None, copy=None):
        if self.whole is None:
            self.whole = sum(w * x for x, w in self.terms)
        return self.whole.astype(dtype or self.whole.dtype, copy=bool(copy))


class _MixedSeries(Series):
    """The series sum_j w_j s_j of the parts' series ``series`` (traced in the same blocks) with
    weights ``wt`` [(T, 3)], each block's mean or half difference mixed when first used (a light
    remixed at each step of the sky's fit is evaluated at its mean alone)."""

    def __init__(self, series, wt):
        self._series, self._wt, self._mixed = series, wt, {}
        places = series[0].places()
        if any(s.places() != places for s in series[1:]):
            raise ValueError("the parts' tables were traced in different blocks")

    @property
    def blocks(self):
        return [(r, f, np.stack([self.coefficients(i, h) for h in (0, 1)]))
                for i, (r, f) in enumerate(self.places())]

    def places(self):
        return self._series[0].places()

    def subset(self, rows, frames):
        return _MixedSeries([s.subset(rows, frames) for s in self._series],
                            [w[frames] for w in self._wt])

    def map(self, f):
        return Series(self.blocks).map(f)

    def coefficients(self, i, h):
        if (i, h) not in self._mixed:
            f = self.places()[i][1]
            cs = [s.coefficients(i, h) for s in self._series]
            c = np.zeros((max(len(cb) for cb in cs),) + cs[0].shape[1:], np.float32)
            for cb, w in zip(cs, self._wt):
                c[:len(cb)] += w[f] * cb
            self._mixed[i, h] = c
        return self._mixed[i, h]


def trace_basis(scene, params, lights, at, bsdf_id, options=CacheOptions(), budget=None,
                model="two", diffuse_only=False):
    """The tables of points ``at`` (pixels (P, 2) or :class:`~.light_cache.PointRays`) on
    material(s) ``bsdf_id`` under ``lights`` (each a list of skies, one per frame; later lights
    on the first's samples): light caches traced with ``options`` and tabulated block by block
    (:func:`chunks` of ``budget`` samples, :func:`block_budget` by default), so memory stays
    bounded.  One block takes ``options.seed`` itself; several take seeds drawn from it.

    Returns (tables, covariances, blocks): each light's :class:`BasisTable`, the
    :class:`Covariances` between them (None for one light) and the number of blocks.  With
    ``diffuse_only``, each light's (D, its Monte Carlo variance) instead, (P, T, 3)
    [W m^-2 sr^-1] and [(W m^-2 sr^-1)^2] (thesis eq. 3.19's rho_d term at rho_d = 1).
    """
    import drjit as dr

    P, T = len(at), len(lights[0])
    ids = np.broadcast_to(np.asarray(bsdf_id, dtype=object), (P,))
    budget = shared_budget(budget or block_budget(P, T, options.positions), len(lights))
    blocks = chunks(P, T, int(options.positions) * int(options.directions), budget)
    seeds = [options.seed] if len(blocks) == 1 else \
        np.random.SeedSequence(options.seed).generate_state(len(blocks)).tolist()
    tables = cov = None
    for (rows, frames), seed in zip(blocks, seeds):
        caches = light_caches(scene, params, [light[frames] for light in lights],
                              _block_points(at, rows, frames), ids[rows],
                              replace(options, seed=int(seed)))
        if diffuse_only:
            parts, part_cov = _diffuse_parts(caches, model, options.normalisation), None
        elif len(caches) > 1:
            parts, part_cov = tabulate_group(caches, model, options.normalisation)
        else:
            parts = [tabulate(caches[0], WardModel(caches[0], model, options.normalisation))]
            part_cov = None
        del caches
        if tables is None:
            tables = [(np.zeros((P, T, 3)), np.zeros((P, T, 3))) if diffuse_only else
                      BasisTable.empty(P, T, b.sun_cos.shape[2], b.normalisation)
                      for b in parts]
            cov = None if part_cov is None else Covariances.empty(len(lights), P, T)
        for table, part in zip(tables, parts):
            if diffuse_only:
                for whole, block in zip(table, part):
                    whole[rows, frames] = block
            else:
                table.place(part, rows, frames)
        if cov is not None:
            cov.place(part_cov, rows, frames)
    # Dr.Jit keeps freed buffers for reuse; the last block's are no longer needed
    dr.flush_malloc_cache()
    return tables, cov, len(blocks)


def _block_points(at, rows, frames):
    """The points ``at`` of a block's ``rows`` and ``frames`` (rays are per frame)."""
    if isinstance(at, PointRays):
        return PointRays(at.origins[rows, frames], at.directions[rows, frames])
    return np.asarray(at)[rows]


def _diffuse_parts(caches, model, normalisation):
    """Each light's diffuse basis D and its Monte Carlo variance, (P, T, 3) each, from
    ``caches`` of one trace's samples."""
    wm = WardModel(caches[0], model, normalisation, caches[1:])
    shares = wm._diffuse_shares()
    P, S = len(caches[0].hit), shares.shape[2]
    D = shares.sum(axis=2)
    var = np.var(shares * S, axis=2, ddof=1) / S if S > 1 else np.zeros_like(D)
    return [(D[m * P:(m + 1) * P], var[m * P:(m + 1) * P]) for m in range(len(caches))]


#: The most roughness values whose lobe arrays (P, T, 3) a search takes at once, and the most
#: bytes of such a chunk (float64).
SIGMA_CHUNK, CHUNK_BYTES = 8, 64 << 20


def sigma_chunk(shape):
    """Roughness values per chunk of lobe arrays of ``shape`` (P, T, 3)."""
    return int(np.clip(CHUNK_BYTES // (8 * int(np.prod(shape))), 1, SIGMA_CHUNK))


class Lobes:
    """The lobe basis G at ``sigmas``, made ``chunk`` values at a time so the grid's
    (K, P, T, 3) never exists at once: ``lobe(sigmas)`` gives (k, P, T, 3); ``chunks()`` yields
    (slice, values); ``map(f)`` applies f to every chunk's values."""

    def __init__(self, lobe, sigmas, chunk=SIGMA_CHUNK):
        self.lobe, self.sigmas, self.chunk = lobe, np.asarray(sigmas, dtype=float), int(chunk)

    def __len__(self):
        return len(self.sigmas)

    def chunks(self):
        for k in range(0, len(self), self.chunk):
            yield slice(k, k + self.chunk), self.lobe(self.sigmas[k:k + self.chunk])

    def map(self, f):
        return Lobes(lambda s: f(self.lobe(s)), self.sigmas, self.chunk)


class TableModel:
    """The fitting model of a region on its :class:`BasisTable`: :class:`~.fit_model.WardModel`'s
    interface in NumPy, exact to the table's interpolation (``model``: 'two', 'achromatic' or
    'colour')."""

    def __init__(self, table, model, part=0):
        self.table, self.model, self.part = table, model, part
        self.normalisation = table.normalisation
        self.names = PARAMETERS[model]
        self.shape = table.shape
        self.evaluations = self.basis_evaluations = 0

    def half(self, j):
        """The model of the first (j = 1) or second (j = 2) half of the cache's positions."""
        return TableModel(self.table, self.model, j)

    def _parts(self, theta, derivative=False):
        rho_d, spec, d_rho_d, d_spec = reflectances(self.model, theta)
        G = self.table.lobe(theta[-1], derivative, self.part)
        return rho_d, spec, d_rho_d, d_spec, G

    def radiance(self, theta):
        """L [W m^-2 sr^-1] for parameters ``theta``, shape (P, T, 3)."""
        self.evaluations += 1
        rho_d, spec, _, _, G = self._parts(theta)
        return rho_d * self.table.diffuse(self.part) + spec * G[0]

    def radiance_and_variance(self, theta):
        """``radiance(theta)`` and its Monte Carlo variance [(W m^-2 sr^-1)^2], (P, T, 3)."""
        rho_d, spec, _, _ = reflectances(self.model, theta)
        return self.radiance(theta), self.table.variance(rho_d, spec, float(theta[-1]))

    def jacobian(self, theta):
        """(L, dL/dtheta) with shapes (P, T, 3) and (P, T, 3, n_params)."""
        self.evaluations += 1
        rho_d, spec, d_rho_d, d_spec, (G, dG) = self._parts(theta, derivative=True)
        D = self.table.diffuse(self.part)
        J = D[..., None] * d_rho_d + G[0][..., None] * d_spec
        J[..., -1] = spec * dG[0]
        return rho_d * D + spec * G[0], J

    def gradient(self, theta, dloss_dL):
        """d(loss)/d(theta) given dloss/dL (P, T, 3)."""
        _, J = self.jacobian(theta)
        return np.einsum("ptc,ptcn->n", dloss_dL, J)

    def basis(self, sigmas, halves=False):
        """D (P, T, 3) and G (K, P, T, 3) at the K ``sigmas``; with ``halves`` a list of them
        for the whole cache and each half (as :meth:`~.fit_model.WardModel.basis`)."""
        return self._bases(sigmas, halves, lambda s, j: self.table.lobe(s, part=j))

    def lobes(self, sigmas, halves=False):
        """As :meth:`basis`, with each G a lazy :class:`Lobes`."""
        chunk = sigma_chunk(self.table.D.shape[1:])
        return self._bases(sigmas, halves, lambda s, j: Lobes(
            lambda x: self.table.lobe(x, part=j), s, chunk))

    def _bases(self, sigmas, halves, lobe):
        """(D, ``lobe(sigmas, part)``) of this part, or a list of them for parts 0, 1, 2."""
        sigmas = np.asarray(sigmas, dtype=float)
        self.basis_evaluations += len(sigmas)
        out = [(self.table.diffuse(j), lobe(sigmas, j))
               for j in ((0, 1, 2) if halves else (self.part,))]
        return out if halves else out[0]

    def radiances(self, thetas, reduce=None):
        """L at parameter sets ``thetas`` (n, n_params): (n, P, T, 3), or ``reduce`` of each (a
        linear map of a (P, T, 3) radiance, applied to the basis)."""
        thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
        reduce = reduce or (lambda x: x)
        uniq, inverse = np.unique(thetas[:, -1], return_inverse=True)
        D = np.asarray(reduce(self.table.diffuse(self.part)))
        lobes = Lobes(lambda s: self.table.lobe(s, part=self.part), uniq,
                      sigma_chunk(self.table.D.shape[1:]))
        G = np.concatenate([np.stack([np.asarray(reduce(g)) for g in chunk])
                            for _, chunk in lobes.chunks()])[inverse.ravel()]
        refl = reflectance_sets(self.model, thetas)                            # (n, 2, 3)
        shape = (len(thetas),) + (1,) * (D.ndim - 1) + (3,)
        return refl[:, 0].reshape(shape) * D + refl[:, 1].reshape(shape) * G
