"""The sky's own share of a surface point's radiance, integrated deterministically.

The sky's radiance h(w) is a known function: the ``cie_sky`` emitter's pattern sum without the
solar disc (:meth:`~skyfit_mi.render.plugins.cie_sky.CIESkyEmitter.sky_eval`, thesis eqs.
4.12-4.18).  Taking it as the light cache's control variate,

    L = sum_k f_r cos(theta_k) (L_i(w_k) - h(w_k)) / (p(w_k) N)  +  integral f_r cos(theta) h dw

is still unbiased for any f_r, its samples carrying only the sun, the scene's geometry and its
shadows.  With f_r = rho_d / pi + s lobe(sigma) (thesis eq. 3.19) the integral is
rho_d I_d + s I_s(sigma), two deterministic integrals per surface point:

* I_d = integral cos(theta)/pi h dw over the hemisphere [W m^-2 sr^-1] (:func:`diffuse_directions`)
* I_s(sigma) = integral lobe(wi, wo; sigma) cos(theta_i) h(wi) dwi [W m^-2 sr^-1]
  (:func:`lobe_directions`), kept as a Chebyshev series in log sigma (:func:`chebyshev_eval`)
  that Dr.Jit differentiates.

Both quadratures split their rays where the integrand is not smooth (the world's horizon,
where the sky may jump to the ground).  The lobe's rays of the half vector's slope use the
radial variable tau = exp(-tan^2 delta / sigma^2), in which the lobe is constant, with
Gauss-Legendre nodes through a smoothstep map whose zero end slopes absorb Ward's
1/sqrt(cos_i cos_o) at the horizon.  Accuracy against brute force: tests/test_sky_control.py.
"""

import numpy as np

from .daylight import DEPARTURE_KEYS, RGB_KEYS, float_parameters, jit_array, opaque_value

#: Roughness values at which I_s is integrated: the Chebyshev series' degree + 1.
CHEBYSHEV_NODES = 16
#: The lobe quadrature's resolution by roughness: (largest sigma, rays of the half vector's
#: slope, Gauss-Legendre nodes per piece of a ray); a wide lobe sees more of the sky's structure.
LOBE_RESOLUTION = ((0.12, 16, 6), (0.25, 32, 8), (float("inf"), 64, 12))
#: The same for GGX lobes, whose long tails see the whole sky (the circumsolar peak from any view).
GGX_RESOLUTION = ((0.12, 32, 24), (float("inf"), 64, 24))
#: The diffuse quadrature's rays of azimuth and Gauss-Legendre nodes per piece.
DIFFUSE_AZIMUTHS, DIFFUSE_POLAR = 64, 24
#: Where the lobe's rays end: tan delta = TRUNCATION sigma, exp(-TRUNCATION^2) of the peak.
TRUNCATION = 4.0


def _smoothstep_legendre(n):
    """Nodes y in (0, 1) and weights of n-point Gauss-Legendre through y = 3x^2 - 2x^3."""
    x, w = np.polynomial.legendre.leggauss(int(n))
    x, w = 0.5 * (x + 1.0), 0.5 * w
    return x * x * (3.0 - 2.0 * x), w * 6.0 * x * (1.0 - x)


def _tables(n_rays, n, smoothstep):
    """Per node of one surface point: its ray's azimuth, its piece (two per ray), y and weight
    (Gauss-Legendre on (0, 1), optionally through the smoothstep map)."""
    if smoothstep:
        y, wy = _smoothstep_legendre(n)
    else:
        x, w = np.polynomial.legendre.leggauss(int(n))
        y, wy = 0.5 * (x + 1.0), 0.5 * w
    phi = (np.arange(n_rays) + 0.5) * 2.0 * np.pi / n_rays
    grid = np.meshgrid(phi, np.arange(2), np.arange(n), indexing="ij")
    return grid[0].ravel(), grid[1].ravel(), y[grid[2].ravel()], wy[grid[2].ravel()]


def _table_arrays(mi, n_rays, n, smoothstep):
    """:func:`_tables` as Dr.Jit arrays."""
    return [jit_array(mi.Float, t) for t in _tables(n_rays, n, smoothstep)]


def _per_node(mi, dr, Q, tables):
    """Each node's surface point index, and its :func:`_table_arrays` values."""
    J = dr.width(tables[0])
    i = dr.arange(mi.UInt32, Q * J)
    q, j = i // J, i % J
    phi, piece, y, wy = (dr.gather(mi.Float, t, j) for t in tables)
    return q, J, phi, piece, y, wy


def _pieces(dr, piece, y, wy, mid, end, start=0.0):
    """The node's position along its ray, in two pieces between breakpoints start, mid, end
    (monotone), and its signed weight."""
    first = piece < 0.5
    lo, hi = dr.select(first, start, mid), dr.select(first, mid, end)
    return lo + (hi - lo) * y, (hi - lo) * wy


def lobe_resolution(sigma, distribution="beckmann"):
    """(rays, nodes per piece) of the lobe quadrature at roughness ``sigma``."""
    table = GGX_RESOLUTION if distribution == "ggx" else LOBE_RESOLUTION
    return next((n, k) for top, n, k in table if sigma <= top)


def lobe_directions(wo, up, sigma, n_rays, n_radial, tables=None, distribution="beckmann"):
    """Light directions and solid-angle weights of the lobe quadrature.

    Parameters
    ----------
    wo : mi.Vector3f (Q)  view directions, local frame (normal +Z)
    up : mi.Vector3f (Q)  the world's zenith in each local frame
    sigma : mi.Float (1)  the lobe's roughness
    n_rays, n_radial : its resolution (:func:`lobe_resolution`)
    tables : that resolution's :func:`_table_arrays` (made here if None)
    distribution : 'beckmann' (Ward's lobes and Beckmann's) or 'ggx': the radial variable

    Returns wi (Q J) local light directions, weights (Q J) [sr], each node's point index q and
    J, nodes per point: integral g(wi) dwi ~ sum over each point's J nodes of g(wi) weight
    (Walter's change of variables to the half vector h, dwi = 4 (wo.h) cos^3 delta d(slope
    area)).  For GGX tau = sigma^2 / (sigma^2 + tan^2 delta), in which D cos^4 delta is
    constant, and the rays end at the surface's horizon only (its tails are long).
    """
    import drjit as dr
    import mitsuba as mi

    if tables is None:
        tables = _table_arrays(mi, n_rays, n_radial, True)
    q, J, phi, piece, y, wy = _per_node(mi, dr, dr.width(wo), tables)
    wo, up = dr.gather(mi.Vector3f, wo, q), dr.gather(mi.Vector3f, up, q)
    s, c = dr.sincos(phi)
    ko, ku, uo = wo.x * c + wo.y * s, up.x * c + up.y * s, dr.dot(up, wo)
    ggx = distribution == "ggx"
    # the surface's horizon along the ray (wi.z = 0), and the lobe's truncation
    end = (ko + dr.sqrt(ko * ko + wo.z * wo.z)) / dr.maximum(wo.z, 1e-12)
    if not ggx:
        end = dr.minimum(end, TRUNCATION * sigma)
    # the world's horizon: up.wi = 0 where A r^2 + B r + C = 0
    A, B, C = 2.0 * ko * ku - uo, 2.0 * (wo.z * ku + up.z * ko), 2.0 * wo.z * up.z - uo
    disc = B * B - 4.0 * A * C
    root = -0.5 * (B + dr.copysign(dr.safe_sqrt(disc), B))
    r1, r2 = root / A, C / root

    def inside(r):
        return dr.select((disc >= 0) & dr.isfinite(r) & (r > 0) & (r < end), r, end)
    cross = dr.minimum(inside(r1), inside(r2))        # a second crossing is rare: left inside
    s2 = sigma * sigma
    if ggx:
        # tau = sigma^2 / (sigma^2 + r^2): r dr = sigma^2 dtau / (2 tau^2)
        def tau(r):
            return s2 / (s2 + r * r)
        t, wt = _pieces(dr, piece, y, wy, tau(cross), tau(end), start=1.0)
        r = sigma * dr.safe_sqrt((1.0 - t) / t)
        jac = s2 / (2.0 * t * t)
    else:
        # nodes in tau = exp(-r^2 / sigma^2), in which the lobe is constant: r dr = sigma^2 dtau
        # / (2 tau)
        def tau(r):
            return dr.exp(-r * r / s2)
        t, wt = _pieces(dr, piece, y, wy, tau(cross), tau(end), start=1.0)
        r = dr.sqrt(dr.maximum(-dr.log(t), 0.0) * s2)
        jac = s2 / (2.0 * t)
    h = dr.normalize(mi.Vector3f(r * c, r * s, 1.0))
    oh = dr.dot(wo, h)
    wi = 2.0 * oh * h - wo
    area = jac * dr.abs(wt) * (2.0 * np.pi / n_rays)
    return wi, 4.0 * oh * h.z * h.z * h.z * area, q, J


def diffuse_directions(up, n_rays=DIFFUSE_AZIMUTHS, n_polar=DIFFUSE_POLAR, tables=None):
    """Light directions and cosine-weighted solid-angle weights of the diffuse quadrature.

    ``up`` (Q) the world's zenith in each local frame; ``tables`` as :func:`lobe_directions`.
    Returns wi (Q J), weights (Q J), q and J: integral g(wi) cos(theta_i) / pi dwi ~ sum of
    g(wi) weight [unitless].
    """
    import drjit as dr
    import mitsuba as mi

    if tables is None:
        tables = _table_arrays(mi, n_rays, n_polar, False)
    q, J, phi, piece, y, wy = _per_node(mi, dr, dr.width(up), tables)
    up = dr.gather(mi.Vector3f, up, q)
    s, c = dr.sincos(phi)
    ku = up.x * c + up.y * s
    # up.wi = up.z cos(theta) + ku sin(theta) = 0 at tan(theta) = -up.z / ku
    t = -up.z / ku
    edge = dr.select(dr.isfinite(t) & (t > 0), dr.atan(t), 0.5 * dr.pi)
    theta, wt = _pieces(dr, piece, y, wy, edge, 0.5 * dr.pi)
    st, ct = dr.sincos(theta)
    wi = mi.Vector3f(st * c, st * s, ct)
    return wi, ct * st * wt * (2.0 / n_rays), q, J


def _sky_sum(mi, dr, emitter, si, wi, w, q, J, f=1.0):
    """Sum over each point's J nodes of f h(wi) w [W m^-2 sr^-1], (Q) Dr.Jit colours, h the sky
    function of ``emitter`` (a ``cie_sky`` emitter or :class:`FrameSkies`); for a list of
    emitters a list of sums over the same nodes, the FrameSkies that differ in their departure
    weights alone sharing one evaluation of the patterns."""
    frame = dr.gather(mi.Frame3f, si.sh_frame, q)
    d, fw = frame.to_world(wi), f * w
    skies = emitter if isinstance(emitter, list) else [emitter]
    patterns, terms = {}, []
    for e in skies:
        if not isinstance(e, FrameSkies):
            terms.append(fw * e.sky_eval(d))
            continue
        lanes = e.at(q)
        # skies that differ in their departure weights alone (the departure's parts) share
        # the patterns, each then times its own field
        if e.patterns_key not in patterns:
            patterns[e.patterns_key] = lanes.sky_pattern(d)
        terms.append(fw * lanes.sky_eval(d, patterns[e.patterns_key]))
    if len(terms) > 1:
        dr.eval(*terms)        # one kernel: the nodes and lobe once for every sky
    sums = [dr.block_sum(t, J) for t in terms]
    return sums if isinstance(emitter, list) else sums[0]


class FrameSkies:
    """The sky functions of several frames, for one pass of :func:`sky_integrals` over all their
    points: ``skies`` the frames' map-free :class:`~skyfit_mi.physics.sky.Sky`, ``frame`` (Q,)
    each point's frame."""

    def __init__(self, skies, frame):
        import mitsuba as mi

        if any(sky.envmap is not None for sky in skies):
            raise ValueError("FrameSkies takes skies without environment maps")
        self.frame = jit_array(mi.UInt32, np.asarray(frame, dtype=np.uint32))
        col = {k: np.array([getattr(sky, k) for sky in skies], dtype=float) for k in RGB_KEYS}
        self.values = {k: jit_array(mi.Color3f, *v.T) for k, v in col.items()}
        self.values["sun_direction"] = jit_array(
            mi.Vector3f, *np.array([sky.sun_direction for sky in skies], dtype=float).T)
        floats = [float_parameters(sky) | {"blend_weight": float(sky.horizon_blend)}
                  for sky in skies]
        self.values.update({k: jit_array(mi.Float, np.array([f[k] for f in floats]))
                            for k in floats[0]})
        # equal for FrameSkies that differ in their departure weights alone (:func:`_sky_sum`)
        kept = [k for k in floats[0] if k not in DEPARTURE_KEYS]
        self.patterns_key = b"".join(
            [np.array([len(frame), len(skies)], dtype=np.int64).tobytes(),
             np.asarray(frame, dtype=np.uint32).tobytes(), *(v.tobytes() for v in col.values()),
             np.array([sky.sun_direction for sky in skies], dtype=float).tobytes(),
             np.array([[f[k] for k in kept] for f in floats], dtype=float).tobytes()])

    def at(self, q):
        """The parameters of the frame of each point ``q`` (a lane each), with ``sky_eval`` and
        ``sky_pattern``."""
        import drjit as dr
        import mitsuba as mi

        index = dr.gather(mi.UInt32, self.frame, q)
        return _SkyLanes({k: dr.gather(type(v), v, index) for k, v in self.values.items()})


class _SkyLanes:
    """A sky's parameters, one per lane, with the emitter's ``sky_eval`` (:class:`FrameSkies`)."""

    def __init__(self, values):
        self.__dict__.update(values)

    def sky_eval(self, d, pattern=None):
        from .plugins.cie_sky import sky_function      # a plugin: needs the variant set

        return sky_function(self, d, pattern)

    def sky_pattern(self, d):
        from .plugins.cie_sky import sky_pattern       # a plugin: needs the variant set

        return sky_pattern(self, d)


def _lobe_sum(mi, dr, emitter, si, up, sigma, resolution, normalisation, tables=None):
    """I_s of every interaction of ``si`` through the rho_s = 1 lobe at Dr.Jit ``sigma``: (Q)
    Dr.Jit colours (a list for a list of emitters)."""
    from .plugins.ward import lobe, lobe_distribution      # a plugin: needs the variant set

    wi, w, q, J = lobe_directions(si.wi, up, sigma, *resolution, tables=tables,
                                  distribution=lobe_distribution(normalisation))
    f = lobe(dr.gather(mi.Vector3f, si.wi, q), wi, sigma, normalisation) * wi.z
    return _sky_sum(mi, dr, emitter, si, wi, w, q, J, f)


def to_numpy(colours):
    """Dr.Jit colours (Q) as a (Q, 3) float64 array."""
    return np.array(colours, dtype=np.float64).T


def diffuse_integral(emitter, si, up):
    """I_d of every surface interaction in ``si`` (Q) under the ``cie_sky`` ``emitter``'s
    current sky, ``up`` the world's zenith in each local frame: (Q, 3) [W m^-2 sr^-1]."""
    import drjit as dr
    import mitsuba as mi

    return to_numpy(_sky_sum(mi, dr, emitter, si, *diffuse_directions(up)))


def lobe_integral(emitter, si, up, sigma, normalisation="ward"):
    """I_s(sigma) of every surface interaction in ``si`` (Q): the sky function through the
    rho_s = 1 lobe times cos(theta_i); (Q, 3) [W m^-2 sr^-1]."""
    import drjit as dr
    import mitsuba as mi

    from .plugins.ward import lobe_distribution      # a plugin: needs the variant set

    return to_numpy(_lobe_sum(mi, dr, emitter, si, up, opaque_value(mi.Float, sigma),
                              lobe_resolution(sigma, lobe_distribution(normalisation)),
                              normalisation))


def quadrature(lo, hi, normalisation):
    """The fixed inputs of :func:`sky_integrals` for the Chebyshev series on [lo, hi]: the
    quadratures' tables and, per node, its roughness (opaque: one kernel for all) and resolution."""
    import mitsuba as mi

    from .plugins.ward import lobe_distribution      # a plugin: needs the variant set

    distribution = lobe_distribution(normalisation)
    tables = {}

    def table(res, smoothstep):
        key = f"{res[0]}x{res[1]}{'s' if smoothstep else ''}"
        if key not in tables:
            tables[key] = _table_arrays(mi, *res, smoothstep)
        return key
    nodes = [{"sigma": opaque_value(mi.Float, sigma),
              "resolution": lobe_resolution(sigma, distribution),
              "table": table(lobe_resolution(sigma, distribution), True)}
             for sigma in chebyshev_nodes(lo, hi)]
    diffuse = table((DIFFUSE_AZIMUTHS, DIFFUSE_POLAR), False)
    return {"tables": tables, "diffuse": diffuse, "nodes": nodes, "normalisation": normalisation}


def sky_integrals(emitter, si, quad):
    """I_d and I_s at each Chebyshev node of ``quad`` for every interaction of ``si`` (Q) under
    ``emitter`` (or a :class:`FrameSkies`): unevaluated Dr.Jit colours (Q) and a list of them
    [W m^-2 sr^-1] (I_d None where ``quad['diffuse']`` is); for a list of emitters, lists."""
    import drjit as dr
    import mitsuba as mi

    up = si.to_local(mi.Vector3f(0.0, 0.0, 1.0))
    tables = quad["tables"]
    diffuse = None if quad["diffuse"] is None else _sky_sum(
        mi, dr, emitter, si, *diffuse_directions(up, DIFFUSE_AZIMUTHS, DIFFUSE_POLAR,
                                                 tables[quad["diffuse"]]))
    return diffuse, [_lobe_sum(mi, dr, emitter, si, up, n["sigma"], n["resolution"],
                               quad["normalisation"], tables[n["table"]])
                     for n in quad["nodes"]]


def chebyshev_nodes(lo, hi, n=CHEBYSHEV_NODES):
    """The n roughness values of the Chebyshev series on [lo, hi] (nodes in log sigma)."""
    x = np.cos(np.pi * (np.arange(n) + 0.5) / n)
    return np.exp(0.5 * (np.log(lo) + np.log(hi)) + 0.5 * (np.log(hi) - np.log(lo)) * x)


def chebyshev_coefficients(values, axis=0):
    """Chebyshev coefficients of ``values`` given at :func:`chebyshev_nodes` along ``axis``."""
    v = np.moveaxis(np.asarray(values, dtype=float), axis, 0)
    n = v.shape[0]
    k = np.arange(n)
    T = np.cos(np.pi * np.outer(k, k + 0.5) / n) * (2.0 / n)
    T[0] *= 0.5
    return np.moveaxis(np.tensordot(T, v, axes=1), 0, axis)


def chebyshev_x(sigma, lo, hi, log, clip):
    """sigma's coordinate in [-1, 1] on [lo, hi] in log sigma (``log``, ``clip``: NumPy's or
    Dr.Jit's)."""
    a, b = np.log(lo), np.log(hi)
    return clip((2.0 * log(sigma) - (a + b)) / (b - a), -1.0, 1.0)


def chebyshev_eval(coefficients, x):
    """sum_k c_k T_k(x) by Clenshaw's recurrence (NumPy or Dr.Jit arrays broadcasting with x;
    arithmetic only, so Dr.Jit differentiates it)."""
    b1 = b2 = 0.0
    for c in reversed(coefficients[1:]):
        b1, b2 = c + 2.0 * x * b1 - b2, b1
    return coefficients[0] + x * b1 - b2
