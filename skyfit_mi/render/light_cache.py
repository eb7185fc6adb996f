"""The fitting model's renderer: light arriving at exactly the region's pixels, cached once.

Everything in a pixel's radiance but the fitted BRDF is independent of the parameters.
:func:`build_light_cache` traces it once per region pixel and frame with Mitsuba (primary rays
jittered over the pixel, incident light by the scene's path integrator where the scene hides the
emitter, the emitter's own elsewhere) along fixed directions
drawn from a parameter-independent mixture (sun disc, sky, cosine, and Ward lobes at several
roughnesses), weighted by the mixture density (multi-sample MIS, balance heuristic).  Then

    L = sum_k f_r(w_o, w_k) cos(theta_k) L_i(w_k) / (p_mix(w_k) N)  +  rho_s m(cos) L_i(mirror)

(the last term only for an ideal mirror, sigma_alpha <= 1e-4) is an unbiased estimate and, with
fixed samples, a smooth deterministic function of the parameters (common random numbers),
evaluated by the ``ward`` plugin in Dr.Jit or split into the basis L = rho_d D + rho_s G(sigma).

Two control variates cut its noise: the sky function h, integrated deterministically
(:mod:`.sky_control`), and for narrow lobes the radiance c along the mirror direction (without
the solar disc, less h), with A the lobe's directional albedo
(:func:`~skyfit_mi.physics.ward.lobe_albedo`):

    L_lobe = sum_k f_s(w_k) cos(theta_k) (L_i(w_k) - beta c) / (p_mix(w_k) N)  +  beta c A

unbiased since c is independent of the directions; beta (:func:`control_weight`) fades to 0 by
CONTROL_SIGMA, where A's quadrature loses accuracy at grazing views (docs/BENCHMARKS.md, "The
light cache's accuracy at every roughness").

Below SIGMA_RESOLVED (the narrowest sampling lobe, under the sun's angular radius) the variance
grows as (SIGMA_RESOLVED / sigma)^2, so the model interpolates linearly in sigma to the mirror.
"""

from dataclasses import dataclass, replace

import numpy as np

from ..errors import SkyfitError, check_choice
from ..physics.ward import (NORMALISATIONS, SIGMA_MIRROR, lobe_albedo, mirror_reflectance,
                            specular_lobe)
from .daylight import jit_array, opaque_value, update_sky
from .scene import pixel_rays, shape_index
from .sky_control import (FrameSkies, chebyshev_coefficients, chebyshev_eval, chebyshev_nodes,
                          chebyshev_x, quadrature, sky_integrals, to_numpy)

#: Roughnesses of the Ward sampling lobes in the direction mixture.
LOBE_SIGMAS = (0.002, 0.006, 0.02, 0.06, 0.15, 0.3)
#: The narrowest lobe the cache resolves; the model interpolates to the mirror below it.
SIGMA_RESOLVED = LOBE_SIGMAS[0]
#: The largest roughness the model represents [rms slope]: the fits' upper bound.
SIGMA_LARGEST = 0.5
#: The roughness range of the sky's integral through the lobe (:mod:`.sky_control`).
SIGMA_TABLE = (SIGMA_RESOLVED, SIGMA_LARGEST)
#: Samples per pixel by default: positions over its area (a highlight varies across a pixel)
#: and light directions at each; an automatically sized cache starts at POSITIONS and grows
#: (docs/BENCHMARKS.md, "A fit's first positions").
POSITIONS, DIRECTIONS = 16, 128
#: Positions of a measured point by default: a point has no area, so they only repeat the
#: directions' sampling (two halves for the cache's own error).
POINT_POSITIONS = 4
#: Share of a fit's degrees of freedom that an automatically sized cache's largest noise over
#: the roughness range must stay under (:meth:`~skyfit_mi.fitting.fit.FitSession.run`).
CACHE_SHARE = 0.1
#: Pixels between the anchors at which predictions' and maps' caches integrate the sky (the
#: ``anchors`` :class:`SkyPlan`); the error is second order in the spacing.
SKY_SPACING = 4
#: A pixel interpolates the four anchors around it only when they lie on its shape, their
#: normals and mirror directions within SHARE_ANGLE_DEG of its own, and every mirror direction
#: at least SHARE_HORIZON_DEG from the horizon (where the sky steps to the ground) and
#: SHARE_SUN_DEG from the sun (the circumsolar cusp); never under an environment map.
SHARE_ANGLE_DEG, SHARE_HORIZON_DEG, SHARE_SUN_DEG = 2.0, 5.0, 5.0
#: The ``fit`` :class:`SkyPlan`: I_d and the nodes of roughness >= WIDE_SIGMA [rad] change little
#: across a pixel and cost most, so they are taken at WIDE_SHARE of each pixel's positions (at
#: least one per half, so LightCache.halves stay independent), each half's mean given to all;
#: only where every pixel's normals and mirror directions lie within WIDE_SPREAD_DEG of their
#: mean (docs/BENCHMARKS.md, "Sky integrals: wide nodes at a few positions ...").
WIDE_SIGMA, WIDE_SHARE, WIDE_SPREAD_DEG = 0.15, 1 / 8, 1.0
#: Points whose sky integrals one pass takes (several frames' together, each under its own sky);
#: bounds the quadratures' memory.
SKY_PASS_POINTS = 2048
#: Share of directions from the solar disc, the sky table, cosine, and all lobes together; fixed
#: counts, so the sun's share does not fluctuate from pixel to pixel.
MIX = {"sun": 0.25, "sky": 0.20, "cosine": 0.15, "lobes": 0.40}
#: Roughness up to which the lobe's control variate has full weight, and from which it is off:
#: the albedo quadrature is exact to 1e-6 below CONTROL_SIGMA up to 70 degrees from the normal.
CONTROL_FULL, CONTROL_SIGMA = 0.035, 0.05


def check_fit_normalisation(normalisation):
    """``normalisation``, or SkyfitError unless the fitting model can represent it: any but
    ``'radiance'``, whose mirror Fresnel term is outside the basis L = rho_d D + rho_s G(sigma)."""
    check_choice("Ward normalisation", normalisation, NORMALISATIONS)
    if normalisation == "radiance":
        raise SkyfitError("normalisation 'radiance' cannot be fitted: its Fresnel term at "
                          f"sigma_alpha <= {SIGMA_MIRROR:g} adds light independent of rho_s and "
                          "scales the diffuse part, outside the light cache's basis L = rho_d D "
                          "+ rho_s G(sigma); fit with 'balanced' (the same BRDF for sigma_alpha "
                          f"> {SIGMA_MIRROR:g}) or use 'radiance' only to render.")
    return normalisation


#: A light cache's arrays that are each light's own where several lights share one trace's
#: samples (:func:`build_light_cache`'s ``others``).
OWN_ARRAYS = ("weight", "mirror", "mirror_sky", "diffuse_sky", "lobe_sky")


@dataclass(frozen=True)
class SkyPlan:
    """Where a light cache takes the sky's integrals (:mod:`.sky_control`), most of its cost.

    spacing : None (at every position), or n > 1: at the pixels' centres (pixels only), at
        anchors every n pixels where interpolating is accurate (SHARE_*)
    wide_share : None, or the share of positions taking the diffuse integral and the nodes of
        roughness >= WIDE_SIGMA (all nodes for a ground-only sky) where footprints are small
    """

    name: str
    spacing: int = None
    wide_share: float = None


#: The sky plans: ``every`` position (the reference); ``fit`` (wide parts at a share of the
#: positions); ``anchors`` (predictions and maps: pixel centres, interpolated between anchors).
SKY_PLANS = {p.name: p for p in (SkyPlan("every"), SkyPlan("fit", wide_share=WIDE_SHARE),
                                 SkyPlan("anchors", spacing=SKY_SPACING))}


@dataclass
class LightCache:
    """Cached light at region pixels: P pixels, T frames, S positions, N = S x directions.

    Attributes
    ----------
    wo : (P, T, N, 3)  view direction, local frame [unitless]
    wi : (P, T, N, 3)  light direction, local frame
    weight : (P, T, N, 3)  L_i / (p_mix N) [W m^-2 sr^-1 sr]; multiply by f_r cos
    mirror : (P, T, S, 3)  L_i along the mirror direction / S, per position
    mirror_cos : (P, T, S)  cos(theta_o) at each position
    hit : (P, T) bool  every position of the pixel lands on the material
    inv_pdf : (P, T, N)  1 / (p_mix N) [sr]: weight without L_i
    mirror_sky : (P, T, S, 3)  L_i along the mirror direction without the solar disc
        [W m^-2 sr^-1]: the control variate's constant
    sun_cos : (P, T, S, 3)  cos(theta_h), cos(theta_d), cos(theta_i) of the sun and view
        (:func:`_sun_cos`); NaN where the frame's sun gives no light
    diffuse_sky : (P, T, S, 3)  I_d, the sky function's cosine-weighted integral / pi
        [W m^-2 sr^-1] (:mod:`.sky_control`)
    lobe_sky : (P, T, S, M, 3)  Chebyshev coefficients in log sigma of I_s(sigma), the sky
        function through the lobe of rho_s = 1 [W m^-2 sr^-1]
    normalisation : the Ward normalisation of that lobe

    ``weight`` and ``mirror_sky`` hold L_i - h, the light less the sky function h.
    """

    wo: np.ndarray
    wi: np.ndarray
    weight: np.ndarray
    mirror: np.ndarray
    mirror_cos: np.ndarray
    hit: np.ndarray
    inv_pdf: np.ndarray
    mirror_sky: np.ndarray
    sun_cos: np.ndarray
    diffuse_sky: np.ndarray
    lobe_sky: np.ndarray
    normalisation: str = "ward"

    def halves(self):
        """Two independent caches, each from half of every pixel's positions (weights doubled):
        fits on each estimate the Monte Carlo error the cache adds."""
        S = self.mirror.shape[2]
        if S < 2:
            raise ValueError("a cache with one position per pixel cannot be halved")
        K = self.weight.shape[2] // S
        h = S // 2
        out = []
        for sl in (slice(0, h), slice(h, 2 * h)):
            n = slice(sl.start * K, sl.stop * K)
            out.append(replace(
                self, wo=self.wo[:, :, n], wi=self.wi[:, :, n], weight=self.weight[:, :, n] * (S / h),
                mirror=self.mirror[:, :, sl] * (S / h), mirror_cos=self.mirror_cos[:, :, sl],
                inv_pdf=self.inv_pdf[:, :, n] * (S / h), mirror_sky=self.mirror_sky[:, :, sl],
                sun_cos=self.sun_cos[:, :, sl], diffuse_sky=self.diffuse_sky[:, :, sl],
                lobe_sky=self.lobe_sky[:, :, sl]))
        return out

    def check_normalisation(self, normalisation):
        """ValueError unless the cache's sky integrals are for the lobe of ``normalisation``."""
        if normalisation != self.normalisation:
            raise ValueError(f"the light cache integrates the {self.normalisation!r} lobe, "
                             f"not {normalisation!r}")

    # ---- the basis (NumPy, for the global search) ------------------------
    def diffuse_basis(self):
        """D with L = rho_d * D + ...: sum cos/pi * weight, shape (P, T, 3)."""
        cos = np.clip(self.wi[..., 2], 0, None) * (self.wo[..., 2] > 0)
        return np.einsum("ptn,ptnc->ptc", cos / np.pi, self.weight) + self.diffuse_sky.mean(axis=2)

    def lobe_sky_integral(self, sigma_alpha):
        """I_s(sigma) per position (P, T, S, 3): the sky function through the lobe."""
        x = chebyshev_x(sigma_alpha, *SIGMA_TABLE, np.log, np.clip)
        return chebyshev_eval(np.moveaxis(self.lobe_sky, 3, 0), x)

    def specular_basis(self, sigma_alpha, normalisation="ward"):
        """G(sigma) with L = ... + rho_s * G: shape (P, T, 3); the mirror term for sigma <= 1e-4,
        interpolated linearly up to SIGMA_RESOLVED (as the Dr.Jit model does)."""
        check_fit_normalisation(normalisation)
        self.check_normalisation(normalisation)
        if sigma_alpha <= SIGMA_MIRROR:
            frac = mirror_reflectance(self.mirror_cos, normalisation)
            return np.einsum("pts,ptsc->ptc", frac, self.mirror)
        if sigma_alpha < SIGMA_RESOLVED:
            t = sigma_alpha / SIGMA_RESOLVED
            return (1 - t) * self.specular_basis(0.0, normalisation) \
                + t * self.specular_basis(SIGMA_RESOLVED, normalisation)
        lobe = specular_lobe(self.wi, self.wo, sigma_alpha, normalisation) \
            * np.clip(self.wi[..., 2], 0, None)
        G = np.einsum("ptn,ptnc->ptc", lobe, self.weight) \
            + self.lobe_sky_integral(sigma_alpha).mean(axis=2)
        beta = float(control_weight(sigma_alpha))
        if beta == 0:
            return G
        P, T, S = self.mirror_cos.shape
        wo = self.wo.reshape(P, T, S, -1, 3)[:, :, :, 0]
        albedo = lobe_albedo(wo, sigma_alpha, normalisation)
        estimate = (lobe * self.inv_pdf).reshape(P, T, S, -1).sum(axis=-1)
        return G + beta * np.einsum("pts,ptsc->ptc", albedo / S - estimate, self.mirror_sky)


@dataclass
class PointRays:
    """Rays to measured points, one per point and frame: ``origins`` and unit ``directions``
    (P, T, 3), world frame [scene units], starting just off the surface on the instrument's side."""

    origins: np.ndarray
    directions: np.ndarray

    def __len__(self):
        return len(self.origins)


def point_rays(positions, views, offset):
    """:class:`PointRays` to ``positions`` (P, 3) seen from unit directions ``views`` (P, T, 3)
    (surface toward instrument), starting ``offset`` scene units off the surface."""
    views = np.asarray(views, dtype=float)
    return PointRays(np.asarray(positions, dtype=float)[:, None, :] + offset * views, -views)


def _has_sun(sky):
    """Whether the frame's sun gives any light (shining, and above the horizon)."""
    return bool(np.max(sky.sun_radiance) > 0 and sky.sun_direction[2] > 0)


def _components(K, has_sun):
    """The component of each of K directions, fixed counts: 0 sun, 1 sky, 2 cosine, 3 + j the
    j-th lobe (MIX's shares); without a sun its share goes to the sky."""
    n_sun, n_sky, n_cos = (max(1, int(round(MIX[k] * K))) for k in ("sun", "sky", "cosine"))
    n_l = K - n_sun - n_sky - n_cos
    if not has_sun:
        n_sun, n_sky = 0, n_sky + n_sun
    return np.concatenate([np.zeros(n_sun, int), np.ones(n_sky, int), np.full(n_cos, 2),
                           3 + np.sort(np.arange(n_l) % len(LOBE_SIGMAS))])


def _sun_cos(sun, view, sky):
    """cos(theta_h), cos(theta_d), cos(theta_i) (Q, 3) from local directions ``sun``, ``view``
    (Q, 3): theta_h from the normal to the half vector h (thesis eq. 3.19), theta_d from the sun
    to h (Rusinkiewicz's difference angle), theta_i the sun's from the normal
    (:func:`~skyfit_mi.fitting.geometry.sun_view_angles`); NaN where the sun gives no light."""
    h = sun + view
    h = h / np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-12)
    cos = np.stack([h[:, 2], np.sum(sun * h, axis=1), sun[:, 2]], axis=1)
    lit = _has_sun(sky) & (sun[:, 2] > 0) & (view[:, 2] > 0)
    return np.where(lit[:, None], cos, np.nan).astype(np.float32)


def control_weight(sigma_alpha, clip=np.clip):
    """Weight beta of the control variate at ``sigma_alpha``: 1 up to CONTROL_FULL, a
    smoothstep (zero slope at both ends) down to 0 at CONTROL_SIGMA, and 0 beyond.
    ``clip`` lets Dr.Jit values through (``dr.clip``)."""
    x = clip((sigma_alpha - CONTROL_FULL) / (CONTROL_SIGMA - CONTROL_FULL), 0.0, 1.0)
    return 1.0 - x * x * (3.0 - 2.0 * x)


def _stratified(rng, n, count=None):
    """n stratified 2D samples in [0, 1)^2, in random order: (n, 2), or (count, n, 2).

    One jittered sample in each of n cells of an a x b grid (a b >= n); when n < a b the cells
    are a random subset, so every sample stays uniform and the estimate unbiased.
    """
    m = 1 if count is None else int(count)
    if n == 0:
        return np.zeros((0, 2)) if count is None else np.zeros((m, 0, 2))
    a = int(np.ceil(np.sqrt(n)))
    b = int(np.ceil(n / a))
    cells = np.argsort(rng.random((m, a * b)), axis=1)[:, :n]        # random subsets, orders
    ij = np.stack([cells // b, cells % b], axis=-1)
    u = (ij + rng.random((m, n, 2))) / [a, b]
    return u[0] if count is None else u


def _sky_values(emitter, si, quad):
    """I_d (Q, 3) or None (``quad['diffuse']`` None) and I_s at the nodes of ``quad`` (Q, n, 3)
    at interactions ``si`` under ``emitter`` (or a :class:`~.sky_control.FrameSkies`); given a
    list of emitters, a list of pairs, each node's directions and lobe evaluated once for all."""
    emitters = emitter if isinstance(emitter, list) else [emitter]
    diffuse, values = sky_integrals(emitters, si, quad)
    d = [None] * len(emitters) if diffuse is None else [to_numpy(x) for x in diffuse]
    v = [[to_numpy(x) for x in sums] for sums in values]
    out = [(d[i], np.stack([node[i] for node in v], axis=1)) for i in range(len(emitters))]
    return out if isinstance(emitter, list) else out[0]


def _interaction_arrays(si):
    """The view direction and shading frame s, t, n of interactions ``si``, NumPy (Q, 3) each."""
    return [np.array(v, dtype=np.float32).T
            for v in (si.wi, si.sh_frame.s, si.sh_frame.t, si.sh_frame.n)]


def _interactions(mi, dr, wi, s, t, n):
    """Surface interactions from :func:`_interaction_arrays`' view directions and frames."""
    si = dr.zeros(mi.SurfaceInteraction3f, len(wi))
    si.wi = jit_array(mi.Vector3f, *wi.T)
    si.sh_frame = mi.Frame3f(*(jit_array(mi.Vector3f, *a.T) for a in (s, t, n)))
    return si


def _anchor_plan(pixels, spacing, width, height):
    """Anchors every ``spacing`` pixels (clamped to the image) and each pixel's bilinear
    interpolation: the anchors (A, 2), each pixel's corner indices (P, 4) and weights (P, 4)."""
    xy = np.asarray(pixels, dtype=int)
    lo = (xy // spacing) * spacing
    hi = np.minimum(lo + spacing, [width - 1, height - 1])
    t = np.where(hi > lo, (xy - lo) / np.maximum(hi - lo, 1), 0.0)           # (P, 2)
    corners = np.stack([np.stack([np.where(i, hi[:, 0], lo[:, 0]),
                                  np.where(j, hi[:, 1], lo[:, 1])], axis=1)
                        for j in (0, 1) for i in (0, 1)], axis=1)          # (P, 4, 2)
    weights = np.stack([(t[:, 0] if i else 1 - t[:, 0]) * (t[:, 1] if j else 1 - t[:, 1])
                        for j in (0, 1) for i in (0, 1)], axis=1)
    anchors, index = np.unique(corners.reshape(-1, 2), axis=0, return_inverse=True)
    return anchors, index.reshape(-1, 4), weights


def anchors_pay(pixels, spacing, width, height):
    """Whether anchors every ``spacing`` pixels are fewer than the ``pixels`` (P, 2) of a
    ``width`` x ``height`` image (a compact region's are, a scattered subset's not)."""
    return spacing is not None and int(spacing) > 1 \
        and len(_anchor_plan(pixels, int(spacing), width, height)[0]) < len(pixels)


class _SharedSky:
    """The pixels' centres and, where anchors pay (:func:`anchors_pay`), the anchors and which
    pixels may interpolate between them: traced once from the geometry, the same in every frame."""

    def __init__(self, mi, scene, sensor, pixels, spacing, size, target, want=None):
        if anchors_pay(pixels, spacing, *size):
            anchors, self.corner, self.weight = _anchor_plan(pixels, spacing, *size)
        else:                                           # every pixel its own centre's
            anchors = np.zeros((0, 2), dtype=int)
            self.corner, self.weight = np.zeros((2, len(pixels), 4), dtype=int)
        # one trace: the anchors (first A points), then the pixels
        self.A = A = len(anchors)
        self.si, sid, n, m = self._trace(mi, scene, sensor, np.concatenate([anchors, pixels]),
                                         target)
        sid_a, n_a, self.m_a = sid[:A], n[:A], m[:A]
        sid_p, n_p, self.m_p = sid[A:], n[A:], m[A:]
        self.arrays = _interaction_arrays(self.si)
        cos_tol = np.cos(np.radians(SHARE_ANGLE_DEG))
        horizon = np.sin(np.radians(SHARE_HORIZON_DEG))
        # a pixel whose centre misses its material (an edge) is no pixel of it (LightCache.hit)
        self.centred = sid_p >= 0
        if want is not None:
            ids = np.array([shape.bsdf().id() for shape in target], dtype=object)
            self.centred &= ids[np.maximum(sid_p, 0)] == want
        ok = self.centred & (np.abs(self.m_p[:, 2]) >= horizon) & (A > 0)
        for a in self.corner.T if A else ():
            ok &= (sid_a[a] == sid_p) & (np.abs(self.m_a[a, 2]) >= horizon) \
                & (np.sum(n_a[a] * n_p, axis=1) >= cos_tol) \
                & (np.sum(self.m_a[a] * self.m_p, axis=1) >= cos_tol)
        self.ok = ok

    @staticmethod
    def _trace(mi, scene, sensor, xy, target):
        """Interactions through the centres of pixels ``xy`` (Q, 2), their shapes' indices
        into ``target`` (-1 elsewhere), world normals and mirror directions (Q, 3)."""
        si = scene.ray_intersect(pixel_rays(sensor, np.asarray(xy) + 0.5))
        n = np.array(si.sh_frame.n, dtype=float).T
        m = np.array(si.to_world(mi.reflect(si.wi)), dtype=float).T
        return si, shape_index(si, target), n, m

    def plan(self, sky):
        """Which pixels interpolate under ``sky`` (no map, mirror directions SHARE_SUN_DEG from
        the sun): (ok (P,), anchors used, pixels taking their own, both's traced indices)."""
        cos_sun = np.cos(np.radians(SHARE_SUN_DEG))
        sun = np.asarray(sky.sun_direction, dtype=float)
        ok = self.ok & (sky.envmap is None) & (self.m_p @ sun < cos_sun)
        if ok.any():
            ok &= np.all(self.m_a[self.corner] @ sun < cos_sun, axis=1)
        used = np.unique(self.corner[ok])
        own = np.flatnonzero(~ok)
        return ok, used, own, np.concatenate([used, self.A + own])

    def combine(self, plan, d, c):
        """Each pixel's I_d (P, 3) and I_s coefficients (P, M, 3) from ``d``, ``c`` at the
        points of ``plan`` (:meth:`plan`), and the number interpolated."""
        ok, used, own, _ = plan
        diffuse, lobe_c = np.zeros((len(ok), 3)), np.zeros((len(ok),) + c.shape[1:])
        at = np.full(self.A, -1)
        at[used] = np.arange(used.size)
        k = at[self.corner[ok]]                                             # (n, 4)
        diffuse[ok] = np.einsum("nc,nck->nk", self.weight[ok], d[k])
        lobe_c[ok] = np.einsum("nc,nc...->n...", self.weight[ok], c[k])
        diffuse[own], lobe_c[own] = d[used.size:], c[used.size:]
        return diffuse, lobe_c, int(ok.sum())

    def points(self, index):
        """The traced interactions at ``index`` as :func:`_interaction_arrays`."""
        return [a[index] for a in self.arrays]


@dataclass(frozen=True)
class CacheOptions:
    """How a light cache is traced (:func:`light_caches`); the same options, points and lights
    give the same cache.

    positions, directions : positions over each pixel's area, and light directions at each
    seed : int, the seed of every random choice
    max_depth : path depth for light from the rest of the scene
    normalisation : the Ward normalisation the sky integrals (and basis table) are for
    plan : a :class:`SkyPlan` or its name in SKY_PLANS (measured points take theirs once)
    """

    positions: int = POSITIONS
    directions: int = DIRECTIONS
    seed: int = 0
    max_depth: int = 3
    normalisation: str = "ward"
    plan: object = "fit"

    @property
    def sky_plan(self):
        """The :class:`SkyPlan` of ``plan``."""
        return SKY_PLANS[self.plan] if isinstance(self.plan, str) else self.plan


def build_light_cache(scene, params, skies, pixels, bsdf_id, *settings, stats=None, others=(),
                      **options):
    """Trace the light arriving at ``pixels`` for every sky in ``skies`` (:func:`light_caches`).

    Parameters
    ----------
    scene, params : a loaded spec scene and its ``mi.traverse`` parameters
    skies : list of :class:`~skyfit_mi.physics.sky.Sky`, one per frame
    pixels : (P, 2) int array of (x, y) pixel coordinates, or :class:`PointRays`
    bsdf_id : str, the material the pixels must show, or one per pixel (P,)
    settings, options : the fields of :class:`CacheOptions`, in order or by name
    stats : None, or a dict receiving ``shared``, the (pixel, frame) pairs interpolated
    others : lights traced on this light's samples (each a list of map-free skies with each
        frame's sun and ground, :func:`~skyfit_mi.physics.sky_shape.shape_variants`): cheap,
        but correlated (:func:`~.basis_table.trace_basis` keeps the covariances)

    Returns
    -------
    LightCache, or with ``others`` a list of them: this light's, then each of theirs
    """
    caches = light_caches(scene, params, [skies, *others], pixels, bsdf_id,
                          CacheOptions(*settings, **options), stats)
    return caches if others else caches[0]


def light_caches(scene, params, lights, at, bsdf_id, options=CacheOptions(), stats=None):
    """A :class:`LightCache` per light of ``lights`` (each a list of skies, one per frame) at
    points ``at`` (pixels (P, 2) or :class:`PointRays`) on material ``bsdf_id``, traced with
    ``options``; later lights on the first's samples (:func:`build_light_cache`).

    Per frame (a) :func:`sample_frame` draws positions and directions and (c)
    :func:`trace_samples` traces each light along them; after the frames (b)
    :func:`sky_plan_integrals` takes the sky function's integrals where the plan says.
    """
    import drjit as dr

    skies, others = lights[0], lights[1:]
    _check_shared(skies, others)
    tr = _tracer(scene, at, bsdf_id, options)
    layout = _sky_layout(tr, skies, options)
    if stats is not None:
        stats["shared"] = 0
    rng = np.random.default_rng(options.seed)
    outs = [{k: [] for k in ("wo", "wi", "weight", "inv_pdf", "mirror", "mirror_sky",
                             "mirror_cos", "hit", "sun_cos", "diffuse_sky", "lobe_sky")}]
    # each other light's own arrays (outs[0] holds the shared ones)
    outs += [{k: [] for k in OWN_ARRAYS} for _ in others]
    pending = []                      # per frame: (points, the shared sky's plan or None)
    for t, sky in enumerate(skies):
        update_sky(params, sky, "sky.")
        samples = sample_frame(tr, sky, t, rng)
        traced = [trace_samples(tr, samples)] + [trace_samples(tr, samples, light[t], params)
                                                 for light in others]
        shared, own, few = _frame_points(tr, layout, samples.si, sky, t)
        weight, lm, lm_sky = traced[0]
        dr.eval(samples.si.wi, samples.wl, weight, samples.inv_pdf, lm, lm_sky,  # together:
                samples.sun, traced[1:],                                 # shared parts once
                None if shared else (own.wi, own.sh_frame),
                None if few is None else (few.wi, few.sh_frame))
        _keep_frame(tr, outs, samples, traced, sky)
        pending.append(_pending(layout, shared, own, few, sky))
    sky_plan_integrals(tr, params, lights, layout, pending, outs, stats)
    # each list freed once stacked
    common = {k: np.stack(outs[0].pop(k), axis=1) for k in list(outs[0]) if k not in OWN_ARRAYS}
    if layout.share is not None:
        common["hit"] &= layout.share.centred[:, None]
    return [LightCache(**common, **{k: np.stack(o.pop(k), axis=1) for k in OWN_ARRAYS},
                       normalisation=options.normalisation) for o in outs]


def _check_shared(skies, others):
    """ValueError unless every light of ``others`` can be traced on the samples of ``skies``."""
    if others and any(len(light) != len(skies) or any(
            sky.envmap is not None or k.envmap is not None or _has_sun(sky) != _has_sun(k)
            or sky.ground_only != k.ground_only
            or not np.allclose(sky.sun_direction, k.sun_direction) for sky, k in zip(light, skies))
            for light in others):
        raise ValueError("the lights traced with a light's samples need one sky without a "
                         "map per frame of its, each with that frame's sun and ground")


@dataclass
class _Tracer:
    """What every frame of one cache's trace shares: the points (``pixels`` (P, 2) of a film of
    ``size``, or ``rays``), S positions and K directions each, the material ``want`` (P,) each
    must show (on ``target`` shapes with materials ``ids``); ``repeat`` each position K times."""

    mi: object
    dr: object
    scene: object
    emitter: object
    integrator: object
    sampler: object
    pixels: np.ndarray
    rays: PointRays
    sensor: object
    size: tuple
    S: int
    K: int
    want: np.ndarray
    target: list
    ids: np.ndarray
    repeat: object

    @property
    def P(self):
        return len(self.want)


def _tracer(scene, at, bsdf_id, options):
    """The :class:`_Tracer` of points ``at`` on material(s) ``bsdf_id`` with ``options``."""
    import drjit as dr
    import mitsuba as mi

    rays = at if isinstance(at, PointRays) else None
    pixels = sensor = size = None
    if rays is None:
        pixels = np.asarray(at, dtype=int)
        sensor = scene.sensors()[0]
        w, h = sensor.film().crop_size()
        size = (w, h)
    P, S, K = len(at), int(options.positions), int(options.directions)
    integrator = mi.load_dict({"type": "path", "max_depth": int(options.max_depth)})
    # the material each pixel must show (one for all, or one per pixel: a map's chunk)
    want = np.broadcast_to(np.asarray(bsdf_id, dtype=object), (P,))
    target = [s for s in scene.shapes() if s.bsdf().id() in set(want)]
    missing = sorted(set(want) - {s.bsdf().id() for s in target})
    if missing:
        raise ValueError(f"no shape of the scene uses material {missing[0]!r}")
    if K - sum(max(1, int(round(MIX[k] * K))) for k in ("sun", "sky", "cosine")) \
            < len(LOBE_SIGMAS):
        raise ValueError(f"directions = {K} is too few; use at least 32")
    return _Tracer(mi, dr, scene, scene.environment(), integrator,
                   mi.load_dict({"type": "independent"}), pixels, rays, sensor, size, S, K,
                   want, target, np.array([shape.bsdf().id() for shape in target], dtype=object),
                   jit_array(mi.UInt32, np.repeat(np.arange(P * S), K)))


@dataclass
class _Samples:
    """One frame's samples (:func:`sample_frame`), Dr.Jit values: interactions ``si`` (P S),
    each repeated K times ``sik``, directions ``d`` (world) and ``wl`` (local), ``inv_pdf``
    1 / (p_mix N) [sr], their rays ``ray`` and whether the scene hides the emitter along them
    (``hidden``: toward the surface's back, none), mirror rays ``ray_m`` and ``hidden_m``, the
    local sun direction ``sun``, the paths' sampler ``seeds``, and whether any ray is hidden
    (``any_hidden``; else no path is traced)."""

    si: object
    sik: object
    d: object
    wl: object
    inv_pdf: object
    ray: object
    hidden: object
    ray_m: object
    hidden_m: object
    sun: object
    seeds: list
    any_hidden: bool


def sample_frame(tr, sky, t, rng):
    """Step (a) of :func:`light_caches`: frame ``t``'s positions and light directions under
    ``sky`` (the emitter's current sky), from ``rng``, as :class:`_Samples`.

    S stratified positions per pixel (a measured point's are its one ray); at each, K directions
    in fixed counts per mixture component (:func:`_components`), stratified within each.
    """
    from .plugins.ward import glossy_pdf, sample_glossy     # a plugin: needs the variant set

    mi, dr, emitter = tr.mi, tr.dr, tr.emitter
    P, S, K = tr.P, tr.S, tr.K
    n_comp = 3 + len(LOBE_SIGMAS)
    comp = _components(K, _has_sun(sky))
    # opaque: one kernel with and without a sun
    frac = [opaque_value(mi.Float, np.sum(comp == c) / K) for c in range(n_comp)]
    seeds = [opaque_value(mi.UInt32, int(rng.integers(2**31))) for _ in range(2)]
    if tr.rays is None:
        ray = pixel_rays(tr.sensor, tr.pixels[:, None, :] + _stratified(rng, S)[None])
    else:
        o, d = (np.repeat(a[:, t], S, axis=0) for a in (tr.rays.origins, tr.rays.directions))
        ray = mi.Ray3f(jit_array(mi.Point3f, *o.T), jit_array(mi.Vector3f, *d.T))
    si = tr.scene.ray_intersect(ray)
    sik = dr.gather(mi.SurfaceInteraction3f, si, tr.repeat)
    u = np.concatenate([_stratified(rng, int(np.sum(comp == c)), P * S)
                        for c in range(n_comp)], axis=1).reshape(P * S * K, 2)
    u2 = jit_array(mi.Point2f, u[:, 0], u[:, 1])
    # candidates from every component, then each sample's own (lobes as functions, not
    # plugins: each registered BSDF adds a virtual-call target to the path integrator)
    cands = [emitter.sample_sun(u2), emitter.sample_sky(u2),
             sik.to_world(mi.warp.square_to_cosine_hemisphere(u2))]
    cands += [sik.to_world(sample_glossy(sik.wi, u2, s)) for s in LOBE_SIGMAS]
    cmask = jit_array(mi.UInt32, np.tile(comp, P * S))
    d = cands[0]
    for c in range(1, n_comp):
        d = dr.select(cmask == c, cands[c], d)
    # mixture density of each chosen direction under every component (balance heuristic)
    wl = sik.to_local(d)
    p_mix = frac[0] * emitter.pdf_sun(d) + frac[1] * emitter.pdf_sky(d) \
        + frac[2] * dr.maximum(mi.Frame3f.cos_theta(wl), 0.0) * dr.inv_pi
    facing = (mi.Frame3f.cos_theta(sik.wi) > 0) & (mi.Frame3f.cos_theta(wl) > 0)
    for j, s in enumerate(LOBE_SIGMAS):
        p_mix += frac[3 + j] * dr.select(facing, glossy_pdf(sik.wi, wl, s), 0.0)
    ok = (p_mix > 0) & (mi.Frame3f.cos_theta(wl) > 0)
    inv_pdf = dr.select(ok, dr.rcp(dr.maximum(p_mix, 1e-30)) / (K * S), 0.0)
    ray = mi.RayDifferential3f(sik.spawn_ray(d))
    # mirror direction at each position
    ray_m = mi.RayDifferential3f(si.spawn_ray(si.to_world(mi.reflect(si.wi))))
    # a direction into the surface (weight 0) needs no path either
    hidden, hidden_m = ok & tr.scene.ray_test(ray), tr.scene.ray_test(ray_m)
    sun = si.to_local(opaque_value(mi.Vector3f, sky.sun_direction))
    dr.eval(d, wl, inv_pdf, hidden, hidden_m)
    return _Samples(si, sik, d, wl, inv_pdf, ray, hidden, ray_m, hidden_m, sun, seeds,
                    bool(dr.any(hidden)) or bool(dr.any(hidden_m)))


def _paths(tr, ray, hidden, seed):
    """The path integrator's L_i [W m^-2 sr^-1] along ``ray`` where ``hidden`` (its sampler
    seeded with ``seed``; the other lanes idle)."""
    tr.sampler.seed(seed, tr.dr.width(ray))
    li, _, _ = tr.integrator.sample(tr.scene, tr.sampler, ray, active=hidden)
    return li


def trace_samples(tr, samples, sky=None, params=None):
    """Step (c) of :func:`light_caches`: the light along ``samples``, Dr.Jit values: weights
    (L_i - h) / (p_mix N) [W m^-2 sr^-1 sr], the mirror rays' L_i, and their L_i less the solar
    disc and h [W m^-2 sr^-1]; under the emitter's current sky, or ``sky`` set in ``params``
    (another light on the same samples and random numbers)."""
    mi, dr, emitter = tr.mi, tr.dr, tr.emitter
    if sky is not None:
        update_sky(params, sky, "sky.")
    # a path only where the scene hides the emitter: along an escaping direction L_i is the
    # emitter's own, h and the solar disc
    def disc(d):
        return dr.select(emitter.pdf_sun(d) > 0, emitter.sun_radiance, 0.0)
    h_m = emitter.sky_eval(samples.ray_m.d)
    weight, lm = disc(samples.d), h_m + disc(samples.ray_m.d)
    lm_sky = dr.zeros(mi.Color3f, dr.width(lm))
    if samples.any_hidden:
        li = _paths(tr, samples.ray, samples.hidden, samples.seeds[0])
        weight = dr.select(samples.hidden, li - emitter.sky_eval(samples.d), weight)
        li_m = _paths(tr, samples.ray_m, samples.hidden_m, samples.seeds[1])
        lm = dr.select(samples.hidden_m, li_m, lm)
        lm_sky = dr.select(samples.hidden_m, li_m - h_m, lm_sky)     # no sun seen there
    weight = weight * samples.inv_pdf
    return weight, lm, lm_sky


def _keep_frame(tr, outs, samples, traced, sky):
    """Append one frame's ``samples`` and each light's ``traced`` light, evaluated, to the
    caches' lists ``outs`` (the shared arrays in the first's)."""
    P, S, K = tr.P, tr.S, tr.K

    def np3(v, n):
        return np.array(v, dtype=np.float32).T.reshape(P, n, 3)
    sid = shape_index(samples.si, tr.target)
    on = (sid >= 0) & (np.repeat(tr.want, S) == tr.ids[np.maximum(sid, 0)])
    view = np.array(samples.si.wi, dtype=float).T
    out = outs[0]
    out["wo"].append(np.repeat(view.astype(np.float32).reshape(P, S, 3), K, axis=1))
    out["wi"].append(np3(samples.wl, S * K))
    out["inv_pdf"].append(np.array(samples.inv_pdf, dtype=np.float32).reshape(P, S * K))
    for o, (weight, lm, lm_sky) in zip(outs, traced):
        o["weight"].append(np3(weight, S * K))
        o["mirror_sky"].append(np3(lm_sky, S))
        o["mirror"].append(np3(lm, S) / S)
    out["mirror_cos"].append(view[:, 2].astype(np.float32).reshape(P, S))
    out["hit"].append(on.reshape(P, S).all(axis=1))
    out["sun_cos"].append(_sun_cos(np.array(samples.sun, dtype=float).T, view,
                                   sky).reshape(P, S, 3))


@dataclass
class _SkyLayout:
    """A :class:`SkyPlan` made concrete for one cache's points (:func:`_sky_layout`).

    quad : the quadrature on SIGMA_TABLE (:func:`~.sky_control.quadrature`)
    is_wide : (M,) bool, the Chebyshev nodes a fit's plan takes at a few positions
    share : a :class:`_SharedSky` where the plan takes the pixels' centres, else None
    subset : None (every position), or Dr.Jit indices of the positions taking them
    wide : whether the wide nodes and I_d are taken at ``kw`` positions per half (``wide_index``,
        ``quads[0]``), the rest at every one (``quads[1]``); settled by the first frame
    """

    quad: dict
    is_wide: np.ndarray
    share: object = None
    subset: object = None
    wide: bool = False
    kw: int = 0
    wide_index: object = None
    quads: tuple = None


def _sky_layout(tr, skies, options):
    """The :class:`_SkyLayout` of ``options``' plan for the points of ``tr`` under ``skies``."""
    mi, P, S = tr.mi, tr.P, tr.S
    plan = options.sky_plan
    share = None
    if tr.rays is None and plan.spacing is not None:
        share = _SharedSky(mi, tr.scene, tr.sensor, tr.pixels, int(plan.spacing), tr.size,
                           tr.target, tr.want)
    quad = quadrature(*SIGMA_TABLE, options.normalisation)
    # a measured point's positions are one ray: one integral
    subset = None if tr.rays is None or S == 1 else jit_array(mi.UInt32, np.arange(P) * S)
    # a fit's: the wide nodes and the diffuse integral at kw positions of each half
    half = S // 2
    kw = 0 if plan.wide_share is None else max(1, int(S * float(plan.wide_share)) // 2)
    is_wide = chebyshev_nodes(*SIGMA_TABLE) >= WIDE_SIGMA
    if all(sky.ground_only for sky in skies):
        # the sun's part of a split light (Sky.split): the ground alone, uniform, changes
        # across a small footprint only for lobes straddling the horizon: all nodes are wide
        is_wide[:] = True
    layout = _SkyLayout(quad, is_wide, share, subset, kw=kw,
                        wide=tr.rays is None and share is None and 1 <= kw < half
                        and 0 < is_wide.sum())
    if layout.wide:
        cols = np.concatenate([np.arange(kw), half + np.arange(kw)])
        layout.wide_index = jit_array(mi.UInt32,
                                      (np.arange(P)[:, None] * S + cols[None, :]).ravel())
        layout.quads = (dict(quad, nodes=[n for n, w in zip(quad["nodes"], is_wide) if w]),
                        dict(quad, nodes=[n for n, w in zip(quad["nodes"], is_wide) if not w],
                             diffuse=None))
    return layout


def _frame_points(tr, layout, si, sky, t):
    """Frame ``t``'s interactions whose sky integrals ``layout`` takes: (shared, whether the
    pixels' centres' are; own, at the plan's positions, or None; few, at the wide nodes'
    positions, or None); the first frame settles ``layout.wide``."""
    mi, dr = tr.mi, tr.dr
    shared = layout.share is not None
    own = None if shared else \
        si if layout.subset is None else dr.gather(mi.SurfaceInteraction3f, si, layout.subset)
    if layout.wide and t == 0:
        layout.wide = _small_footprints(
            np.array(si.sh_frame.n, dtype=float).T,
            np.array(si.to_world(mi.reflect(si.wi)), dtype=float).T, tr.P, tr.S)
    few = dr.gather(mi.SurfaceInteraction3f, si, layout.wide_index) if layout.wide else None
    return shared, own, few


def _pending(layout, shared, own, few, sky):
    """A frame's points for :func:`sky_plan_integrals`: (their :func:`_interaction_arrays`, or
    with ``layout.wide`` the few positions' and all; the shared sky's plan or None)."""
    if shared:
        plan = layout.share.plan(sky)
        return layout.share.points(plan[3]), plan
    if layout.wide:
        return (_interaction_arrays(few), _interaction_arrays(own)), None
    return _interaction_arrays(own), None


def sky_plan_integrals(tr, params, lights, layout, pending, outs, stats=None):
    """Step (b) of :func:`light_caches`: every light's I_d and I_s coefficients at each frame's
    ``pending`` points, appended to ``outs``; ``stats['shared']`` counts interpolated pairs."""
    P, S = tr.P, tr.S
    # the sun alone (Sky.split's first part) has a zero sky function
    lit = [i for i, light in enumerate(lights) if any(sky.lit_by_sky for sky in light)]
    for i in set(range(len(lights))) - set(lit):
        for _ in pending:
            _add_sky(outs[i], np.zeros((P, 3)), np.zeros((P, len(layout.is_wide), 3)), P, S)
    if lit and layout.wide:
        _wide_integrals(tr, params, lights, layout, pending, outs, lit)
    elif lit:
        for i, each in zip(lit, _integrate(tr, params, lights, [p for p, _ in pending],
                                           layout.quad, lit)):
            for (_, plan), (d, v) in zip(pending, each):
                c = chebyshev_coefficients(v, axis=1)
                if plan is not None:
                    d, c, n_shared = layout.share.combine(plan, d, c)
                    if stats is not None and i == 0:
                        stats["shared"] += n_shared
                _add_sky(outs[i], d, c, P, S)


def _wide_integrals(tr, params, lights, layout, pending, outs, lit):
    """:func:`sky_plan_integrals` under a fit's plan (``layout.wide``) for the lights ``lit``."""
    P, S, is_wide, kw = tr.P, tr.S, layout.is_wide, layout.kw
    half = S // 2
    narrow = _integrate(tr, params, lights, [p[1] for p, _ in pending], layout.quads[1], lit) \
        if not is_wide.all() else [[(None, None)] * len(pending)] * len(lit)
    wide = _integrate(tr, params, lights, [p[0] for p, _ in pending], layout.quads[0], lit)
    for i, wides, narrows in zip(lit, wide, narrow):
        for (d, v_wide), (_, v_narrow) in zip(wides, narrows):
            d, v_wide = (np.repeat(a.reshape(P, 2, kw, *a.shape[1:]).mean(axis=2),
                                   [half, S - half], axis=1) for a in (d, v_wide))
            values = np.empty((P, S, len(is_wide), 3))
            values[:, :, is_wide] = v_wide
            if v_narrow is not None:
                values[:, :, ~is_wide] = v_narrow.reshape(P, S, -1, 3)
            _add_sky(outs[i], d.reshape(P * S, 3),
                     chebyshev_coefficients(values, axis=2).reshape(P * S, len(is_wide), 3),
                     P, S)


def _integrate(tr, params, lights, points, q, which):
    """Per frame, :func:`_sky_values` under quadrature ``q`` at its ``points``, for each light
    of ``which``: a list per light.  Passes of up to SKY_PASS_POINTS points (at least a frame),
    each under its frame's sky; a sky with a map alone.  A pass goes in as many pieces as lights,
    so its memory is one light's."""
    skies = lights[0]
    res, first = [[] for _ in which], 0
    while first < len(points):
        last, count = first + 1, len(points[first][0])
        while last < len(points) and skies[first].envmap is None \
                and skies[last].envmap is None \
                and count + len(points[last][0]) <= SKY_PASS_POINTS:
            count += len(points[last][0])
            last += 1
        sizes = [len(p[0]) for p in points[first:last]]
        cols = [np.concatenate(a) for a in zip(*points[first:last])]
        frame = np.repeat(np.arange(last - first), sizes)
        got = [[] for _ in which]
        for piece in np.array_split(np.arange(len(frame)), min(len(which), len(frame))):
            at = _interactions(tr.mi, tr.dr, *(c[piece] for c in cols))
            if skies[first].envmap is None:
                light = [FrameSkies(lights[i][first:last], frame[piece]) for i in which]
            else:                               # one light (others take no maps)
                update_sky(params, skies[first], "sky.")
                light = [tr.emitter]
            for g, values in zip(got, _sky_values(light, at, q)):
                g.append(values)
        cut = np.cumsum(sizes)[:-1]
        for r, pieces in zip(res, got):
            d, v = ([p[i] for p in pieces] for i in (0, 1))
            r += zip([None] * len(sizes) if d[0] is None else np.split(np.concatenate(d), cut),
                     np.split(np.concatenate(v), cut))
        first = last
    return res


def _small_footprints(normals, mirrors, P, S):
    """Whether every pixel's ``normals`` and ``mirrors`` (P S, 3) lie within WIDE_SPREAD_DEG of
    their pixel's mean (NaN fails)."""
    cos_max = np.cos(np.radians(WIDE_SPREAD_DEG))
    for d in (normals, mirrors):
        d = d.reshape(P, S, 3)
        mean = d.sum(axis=1, keepdims=True)
        mean = mean / np.maximum(np.linalg.norm(mean, axis=2, keepdims=True), 1e-30)
        with np.errstate(invalid="ignore"):
            cos = np.sum(d * mean, axis=2) / np.linalg.norm(d, axis=2)
        if not np.all(cos >= cos_max):
            return False
    return True


def _add_sky(out, diffuse, lobe, P, S):
    """Append one frame's I_d (P k, 3) and I_s coefficients (P k, M, 3) at k of each pixel's S
    positions (their mean to all S when k < S) to ``out``."""
    diffuse, lobe = (a.reshape(P, -1, *a.shape[1:]) for a in (diffuse, lobe))
    if diffuse.shape[1] < S:
        diffuse, lobe = (a.mean(axis=1, keepdims=True) for a in (diffuse, lobe))
    out["diffuse_sky"].append(np.broadcast_to(diffuse, (P, S, 3)))
    out["lobe_sky"].append(np.broadcast_to(lobe, (P, S) + lobe.shape[2:]))
