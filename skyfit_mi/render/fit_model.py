"""The fitting model in Dr.Jit: a region's pixel radiances from a :class:`LightCache` and the ``ward`` plugin.

:class:`WardModel` evaluates L(theta) with the plugin's ``eval`` (and its mirror ``sample`` for
sigma_alpha = 0) on the cached light; its Jacobian goes through the basis L = rho_d D + s G(sigma)
(thesis eq. 3.19) with dG/dsigma by forward mode, the gradient of a loss by reverse mode.
"""

import itertools
import xml.etree.ElementTree as ET

import numpy as np

from ..errors import SkyfitError
from ..physics.ward import (METAL_THRESHOLD, PLASTIC_MAX, SIGMA_MIRROR,
                            albedo_nodes_of, colour_rule_twin, raw_parameters,
                            raw_reflectances)
from .light_cache import (CONTROL_SIGMA, SIGMA_LARGEST, SIGMA_RESOLVED,
                          SIGMA_TABLE, check_fit_normalisation, control_weight)
from .daylight import jit_array, update_sky
from .scene import load_xml, pixel_rays
from .scene_xml import ward_element
from .sky_control import chebyshev_eval, chebyshev_x

#: Fitted parameters of each model (thesis 7.1), in order; C is three numbers.
PARAMETERS = {"two": ("rho_s", "sigma_alpha"),
              "achromatic": ("R", "rho_s", "sigma_alpha"),
              "colour": ("C_r", "C_g", "C_b", "rho_s", "sigma_alpha")}
#: Every model's parameters in one order (a map's planes).
PARAMETER_ORDER = ("C_r", "C_g", "C_b", "R", "rho_s", "sigma_alpha")
#: Models by their number of free parameters (the CLI's --model 2/3/5).
BY_COUNT = {2: "two", 3: "achromatic", 5: "colour"}
#: Bounds of every parameter: reflectances in [0, 1], sigma_alpha in [0, 0.5].
BOUNDS = {"rho_s": (0.0, 1.0), "sigma_alpha": (0.0, SIGMA_LARGEST), "R": (0.0, 1.0),
          "C_r": (0.0, 1.0), "C_g": (0.0, 1.0), "C_b": (0.0, 1.0)}


def bounds(model):
    """(lower, upper) arrays of the model's parameters."""
    lo, hi = zip(*(BOUNDS[p] for p in PARAMETERS[model]))
    return np.array(lo), np.array(hi)


def check_start(model, start):
    """``start`` as an array; SkyfitError unless it has one in-bounds value per parameter."""
    names, (lo, hi) = PARAMETERS[model], bounds(model)
    v = np.asarray(start, dtype=float).ravel()
    if v.size != len(names):
        raise SkyfitError(f"the start gives {v.size} value(s); model {model!r} has "
                          f"{len(names)}: {', '.join(names)}, in that order.")
    bad = ~((v >= lo) & (v <= hi))
    if bad.any():
        i = int(np.argmax(bad))
        raise SkyfitError(f"start {names[i]} = {v[i]:g} is outside its bounds "
                          f"[{lo[i]:g}, {hi[i]:g}].")
    return v


def material_values(model, theta, opaque=False):
    """The ``ward`` plugin's parameters for ``theta`` as Dr.Jit values, keyed like ``traverse``;
    ``opaque``: so that kernels compiled (or renders frozen) for one theta serve every theta."""
    import drjit as dr
    import mitsuba as mi

    d = material_dict(model, theta)
    v = {"rho_s": mi.Float(d["rho_s"]), "sigma_alpha": mi.Float(d["sigma_alpha"])}
    if "R" in d:
        v["R"] = mi.Float(d["R"])
    if "C" in d:
        v["C"] = mi.Color3f(*d["C"])
    if opaque:
        dr.make_opaque(*v.values())
    return v


def write_material(params, prefix, model, theta):
    """Set a ``ward`` plugin's parameters (keys ``prefix + name``) to ``theta``, opaque, and
    update."""
    for k, x in material_values(model, theta, opaque=True).items():
        params[prefix + k] = x
    params.update()


def other_readings(model, theta):
    """Parameter points chi^2 should also try because the model jumps between them and
    ``theta``: for the colour model the reading across the plastic/metal rule
    (:func:`~skyfit_mi.physics.ward.colour_rule_twin`), clipped to its side and the bounds."""
    if model != "colour":
        return []
    c2, rho2 = colour_rule_twin(theta[:3], theta[3])
    side = (0.0, PLASTIC_MAX) if theta[3] >= METAL_THRESHOLD \
        else (METAL_THRESHOLD, 1.0)
    return [np.r_[np.clip(c2, 0, 1), np.clip(rho2, *side), theta[4]]]


def reflectances(model, theta):
    """rho_d (3,), s (3,) for ``theta`` (:func:`~skyfit_mi.physics.ward.raw_parameters`, thesis
    7.1) and their derivatives d/dtheta (3, n), the sigma_alpha column zero; for the colour
    model that of the rule on theta's side of rho_s = 0.5."""
    th = np.asarray(theta, dtype=float)
    rho_d, spec, _ = raw_parameters(**{k: v for k, v in material_dict(model, th).items()
                                       if k != "normalisation"})
    rho = th[-2]
    d_rho_d, d_spec = np.zeros((3, len(th))), np.zeros((3, len(th)))
    if model == "two":
        d_rho_d[:, 0], d_spec[:, 0] = -1.0, 1.0
    elif model == "achromatic":
        d_rho_d[:, 0], d_spec[:, 0] = 1 - rho, rho
        d_rho_d[:, 1], d_spec[:, 1] = -th[0], th[0]
    else:
        ch = np.arange(3)
        d_rho_d[ch, ch], d_rho_d[:, 3] = 1 - rho, -th[:3]
        if rho >= METAL_THRESHOLD:
            d_spec[ch, ch], d_spec[:, 3] = rho, th[:3]
        else:
            d_spec[:, 3] = 1.0
    return rho_d, spec, d_rho_d, d_spec


def reflectance_sets(model, thetas):
    """:func:`reflectances`' rho_d and s, (n, 2, 3), of in-bounds ``thetas`` (n, k), at once
    and unchecked."""
    th = np.atleast_2d(np.asarray(thetas, dtype=float))
    rho = th[:, -2]
    if model == "colour":
        rho = np.where(rho < METAL_THRESHOLD, np.minimum(rho, PLASTIC_MAX), rho)
    first = {"two": None, "achromatic": th[:, 0], "colour": th[:, :3]}[model]
    return np.stack(raw_reflectances(model, rho, first), axis=1)


def material_dict(model, theta, normalisation="ward"):
    """The ``ward`` plugin dictionary (and spec material) for parameters ``theta``."""
    theta = [float(v) for v in theta]
    rho_s = theta[-2]
    if model == "colour" and rho_s < METAL_THRESHOLD:
        rho_s = min(rho_s, PLASTIC_MAX)           # a plastic stays one in single precision
    d = {"model": model, "normalisation": normalisation, "rho_s": rho_s, "sigma_alpha": theta[-1]}
    if model == "achromatic":
        d["R"] = theta[0]
    if model == "colour":
        d["C"] = theta[:3]
    return d


def _dr_array(cls, a, k=1):
    """NumPy ``a`` (..., k) as a Dr.Jit ``cls`` of its k columns (:func:`~.daylight.jit_array`)."""
    a = np.asarray(a).reshape(-1, k)
    return jit_array(cls, *(a[:, i] for i in range(k)))


class WardModel:
    """Radiance of region pixels as a differentiable function of Ward parameters.

    Parameters
    ----------
    cache, model : a LightCache; 'two', 'achromatic' or 'colour'
    normalisation : 'ward', 'duer', 'balanced' or a microfacet lobe (not 'radiance')
    others : caches of other lights traced on ``cache``'s samples: the basis's shares
        (:meth:`_shares`) are then every light's, stacked by pixel, from one lobe evaluation
    """

    def __init__(self, cache, model, normalisation="ward", others=()):
        import drjit as dr
        import mitsuba as mi

        check_fit_normalisation(normalisation)
        self.mi, self.dr = mi, dr
        self.model, self.normalisation = model, normalisation
        self.names = PARAMETERS[model]
        self.shape = cache.weight.shape[:2]                     # (P, T)
        self.n = cache.weight.shape[2]
        P, T, N, _ = cache.weight.shape
        S = cache.mirror.shape[2]
        self.si = dr.zeros(mi.SurfaceInteraction3f, P * T * N)
        self.si.wi = _dr_array(mi.Vector3f, cache.wo, 3)
        self.wi = _dr_array(mi.Vector3f, cache.wi, 3)
        self.si_m = dr.zeros(mi.SurfaceInteraction3f, P * T * S)
        # the mirror sample only needs the view direction
        wo_m = np.zeros((P, T, S, 3), np.float32)
        c = cache.mirror_cos
        wo_m[..., 0] = np.sqrt(np.clip(1 - c**2, 0, 1))
        wo_m[..., 2] = c
        self.si_m.wi = _dr_array(mi.Vector3f, wo_m, 3)
        self.S = S
        # the lobe's control variate (.light_cache): inverse densities, the diffuse albedo's
        # estimate per position, and (below) the albedo quadrature's nodes per view direction
        self.inv_pdf = _dr_array(mi.Float, cache.inv_pdf)
        up = (cache.wi[..., 2] > 0) & (cache.wo[..., 2] > 0)
        d_hat = (np.clip(cache.wi[..., 2], 0, None) / np.pi * up * cache.inv_pdf)
        self.d_hat = _dr_array(mi.Float, d_hat.reshape(P * T * S, -1).sum(axis=1))
        # each light's own arrays: this cache's, then the others'
        self.lights = [self._light_arrays(c, normalisation) for c in (cache, *others)]
        a, b, c = albedo_nodes_of(normalisation)
        self.J = len(a)
        self.si_q = dr.zeros(mi.SurfaceInteraction3f, P * T * S * self.J)
        self.si_q.wi = _dr_array(mi.Vector3f, np.repeat(wo_m, self.J, axis=2), 3)
        self.nodes = [_dr_array(mi.Float, np.tile(x, P * T * S)) for x in (a, b, c)]
        # the model's plugin and a two-parameter one for the basis (rho_s = 0: D; 1: G), each
        # with the literal values it keeps between evaluations
        self.plugins = {}
        for key, m in (("model", model), ("basis", "two")):
            mid = 0.5 * np.add(*bounds(m))
            bsdf = mi.load_dict({"type": "ward", **self._props(material_dict(m, mid, normalisation))})
            self.plugins[key] = (bsdf, mi.traverse(bsdf), material_values(m, mid))
        self.bsdf = self.plugins["model"][0]
        self._D_shares = None
        self.evaluations = self.basis_evaluations = 0

    def _light_arrays(self, cache, normalisation):
        """A light's own arrays (light_cache.OWN_ARRAYS) in Dr.Jit, the sky integrals per
        position's share; the weights and c None where all are zero (a scene hiding none of the
        sampled directions from a sunless light, none of the mirror rays: the sky function
        alone, whose integrals carry it all)."""
        mi, S = self.mi, self.S
        cache.check_normalisation(normalisation)

        def unless_zero(a):
            return _dr_array(mi.Color3f, a, 3) if a.any() else None
        return {"weight": unless_zero(cache.weight),
                "mirror": _dr_array(mi.Color3f, cache.mirror, 3),
                "c": unless_zero(cache.mirror_sky),
                "diffuse_sky": _dr_array(mi.Color3f, cache.diffuse_sky / S, 3),
                "lobe_sky": [_dr_array(mi.Color3f, cache.lobe_sky[:, :, :, m] / S, 3)
                             for m in range(cache.lobe_sky.shape[3])]}

    def _props(self, d):
        d = dict(d)
        if "C" in d:
            d["C"] = self.mi.ScalarColor3f(*d["C"])
        return d

    def _variables(self, theta, grad=(), model=None):
        """The parameters as opaque Dr.Jit values keyed like the plugin's (those in ``grad``
        track derivatives), and sigma_alpha as a float; ``model='two'`` for the basis plugin."""
        v = material_values(model or self.model, theta, opaque=True)
        for k in grad:
            self.dr.enable_grad(v[k])
        return v, float(theta[-1])

    def _eval(self, bsdf, sigma, per_position=False, every=False):
        """L for the plugin's current parameters (``sigma`` its sigma_alpha): the BRDF on the
        cached light with the lobe's control variate, plus the mirror; a list of the first
        light's, or with ``every`` each light's; ``per_position``: shares (P*T*S), not sums."""
        dr, mi = self.dr, self.mi
        ctx = mi.BSDFContext()
        lights = self.lights if every else self.lights[:1]
        K = self.n // self.S
        # the lobe's control variate, where some light's mirror rays see more than h
        control = SIGMA_MIRROR < sigma < CONTROL_SIGMA and any(x["c"] is not None
                                                                for x in lights)
        if control or any(x["weight"] is not None for x in lights):
            f = bsdf.eval(ctx, self.si, self.wi)                        # f_r cos(theta_i)
            # evaluated once, or each block sum's per-channel kernel would evaluate it anew
            dr.eval(f)
        bs, w = bsdf.sample(ctx, self.si_m, mi.Float(0.0), mi.Point2f(0.5, 0.5))
        delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.DeltaReflection)
        rho_d, spec, s = bsdf.raw()
        if sigma > SIGMA_MIRROR:
            x = chebyshev_x(s, *SIGMA_TABLE, dr.log, dr.clip)
        if control:
            # the lobe's albedo: its estimate from the samples, and the quadrature
            estimate = dr.block_sum(f * self.inv_pdf, K) - rho_d * self.d_hat
            a, b, c = self.nodes
            h = dr.normalize(mi.Vector3f(s * a, s * b, 1.0))
            oh = dr.dot(self.si_q.wi, h)
            glossy = mi.BSDFContext()
            glossy.component = 1
            g = bsdf.eval(glossy, self.si_q, 2.0 * oh * h - self.si_q.wi)
            dr.eval(g)
            albedo = dr.block_sum(g * (2.0 * dr.square(s) * oh * h.z * dr.square(h.z) * c), self.J)
        out = []
        for light in lights:
            L = dr.select(delta, w * bs.pdf, 0.0) * light["mirror"]
            if light["weight"] is not None:
                L += dr.block_sum(f * light["weight"], K)
            L += rho_d * light["diffuse_sky"]
            if sigma > SIGMA_MIRROR:
                L += spec * chebyshev_eval(light["lobe_sky"], x)
            if control and light["c"] is not None:
                L += control_weight(s, dr.clip) * light["c"] * (albedo / self.S - estimate)
            out.append(L if per_position else dr.block_sum(L, self.S))
        return out

    def radiance_and_variance(self, theta):
        """``radiance(theta)`` and its Monte Carlo variance [(W m^-2 sr^-1)^2], both (P, T, 3):
        the S positions' independent estimates' sample variance / S."""
        self.evaluations += 1
        shares = self._radiance_dr(*self._variables(theta), per_position=True)
        est = self._np(shares, per_position=True) * self.S
        return est.mean(axis=2), np.var(est, axis=2, ddof=1) / self.S

    def _radiance_dr(self, v, sigma, per_position=False, plugin="model", every=False):
        """L as a Dr.Jit Color3f of size P*T from values ``v`` of the model's or the basis
        ``plugin``; with ``every`` one per light.  Below SIGMA_RESOLVED, linear in sigma to the
        mirror (:mod:`.light_cache`)."""
        if not every and len(self.lights) > 1:
            raise ValueError("a model of several lights gives their basis's shares alone "
                             "(basis_table.tabulate_group)")
        bsdf, p, rest = self.plugins[plugin]
        for k, x in v.items():
            p[k] = x
        if sigma >= SIGMA_RESOLVED:
            p.update()
            L = self._eval(bsdf, sigma, per_position, every)
        else:
            p["sigma_alpha"] = self.mi.Float(SIGMA_RESOLVED)
            p.update()
            rough = self._eval(bsdf, SIGMA_RESOLVED, per_position, every)
            p["sigma_alpha"] = self.mi.Float(0.0)
            p.update()
            mirror = self._eval(bsdf, 0.0, per_position, every)
            L = [m + (v["sigma_alpha"] / SIGMA_RESOLVED) * (r - m) for r, m in zip(rough, mirror)]
        # literals back into the plugin: a frozen function (RegionRenderModel) dispatches over
        # every registered BSDF and cannot record foreign opaque state
        for k, x in rest.items():
            p[k] = x
        p.update()
        return L if every else L[0]

    def _np(self, v, per_position=False):
        """A Dr.Jit Color3f as (P, T, 3), or (P, T, S, 3) for per-position shares."""
        self.dr.eval(v)                                  # one kernel for all three channels
        return np.array(v, dtype=float).T.reshape(*self.shape, *((self.S,) if per_position
                                                                  else ()), 3)

    def radiance(self, theta):
        """L [W m^-2 sr^-1] for parameters ``theta``, shape (P, T, 3)."""
        self.evaluations += 1
        return self._np(self._radiance_dr(*self._variables(theta)))

    def jacobian(self, theta):
        """(L, dL/dtheta) with shapes (P, T, 3) and (P, T, 3, n_params), through the basis
        L = rho_d D + s G(sigma) (thesis eq. 3.19) with dG/dsigma by forward mode."""
        dr = self.dr
        v, sigma = self._variables([1.0, theta[-1]], grad=("sigma_alpha",), model="two")
        G_dr = self._radiance_dr(v, sigma, plugin="basis")
        dr.set_grad(v["sigma_alpha"], 1.0)
        dr.forward_to(G_dr, flags=dr.ADFlag.Default | dr.ADFlag.AllowNoGrad)
        G, dG = self._np(dr.detach(G_dr)), self._np(dr.grad(G_dr))
        rho_d, spec, d_rho_d, d_spec = reflectances(self.model, theta)
        D = self._diffuse_shares().sum(axis=2)
        J = D[..., None] * d_rho_d + G[..., None] * d_spec        # (P, T, 3, n)
        J[..., -1] = spec * dG
        self.evaluations += 1
        return rho_d * D + spec * G, J

    def basis(self, sigmas, halves=False):
        """The basis of L = rho_d D + s G(sigma) (thesis eq. 3.19): D (P, T, 3) and G
        (K, P, T, 3) at the K ``sigmas``; with ``halves`` a list [(D, G) of the whole cache,
        of its first half, of its second] (as :meth:`LightCache.halves`)."""
        S, h = self.S, self.S // 2
        parts = [(slice(0, S), 1.0)] + ([(slice(0, h), S / h), (slice(h, 2 * h), S / h)]
                                        if halves else [])
        acc = [[] for _ in parts]
        lobes = (self._shares(1.0, float(s)) for s in sigmas)
        for shares in itertools.chain([self._diffuse_shares()], lobes):
            for j, (sl, scale) in enumerate(parts):
                acc[j].append(shares[:, :, sl].sum(axis=2) * scale)
        self.basis_evaluations += len(sigmas)
        out = [(a[0], np.stack(a[1:])) for a in acc]
        return out if halves else out[0]

    lobes = basis       # its arrays serve wherever lazy lobes do

    def _shares(self, rho_s, sigma):
        """Each position's share (P, T, S, 3) of the basis plugin's L (rho_s = 0: D; 1: G at
        sigma); with ``others``, every light's, stacked (n P, T, S, 3)."""
        L = self._radiance_dr(*self._variables([rho_s, sigma], model="two"), per_position=True,
                              plugin="basis", every=True)
        self.dr.eval(*L)                                 # every light's shares together
        return np.concatenate([self._np(x, per_position=True) for x in L])

    def _diffuse_shares(self):
        """The diffuse basis's shares, computed once: they do not depend on theta."""
        if self._D_shares is None:
            self._D_shares = self._shares(0.0, 0.1)
            self.basis_evaluations += 1
        return self._D_shares


class RegionRenderModel:
    """The region's radiance by a full Mitsuba render of its pixels for every frame.

    The thesis's way (a render per chi-square evaluation), the baseline for :class:`WardModel`:
    one scene per frame, ``spp`` jittered rays per pixel with a fixed seed (common random
    numbers), each frame's render a ``dr.freeze`` function replayed with new parameters.
    """

    def __init__(self, scene_xml, material, skies, pixels, model, spp=256, seed=0, max_depth=4,
                 normalisation="ward"):
        import drjit as dr
        import mitsuba as mi

        root = ET.fromstring(scene_xml)
        for el in root.iter("bsdf"):
            if el.get("id") == material:
                ward_element(el, material, material_dict(model, 0.5 * sum(bounds(model)),
                                                          normalisation))
        xml = ET.tostring(root, encoding="unicode")
        self.mi = mi
        self.scenes, self.params = [], []
        for sky in skies:
            scene = load_xml(xml)
            params = mi.traverse(scene)
            update_sky(params, sky, "sky.")
            self.scenes.append(scene)
            self.params.append(params)
        self.key = material + "."
        self.model, self.names = model, PARAMETERS[model]
        self.spp, self.seed = int(spp), int(seed)
        self.pixels = np.asarray(pixels, dtype=int)
        self.shape = (len(self.pixels), len(skies))
        self.integrator = mi.load_dict({"type": "path", "max_depth": int(max_depth)})
        rng = np.random.default_rng(seed)
        pos = (np.repeat(self.pixels, self.spp, axis=0) + rng.random((len(self.pixels) * self.spp, 2)))
        self.rays = mi.RayDifferential3f(pixel_rays(self.scenes[0].sensors()[0], pos))
        self.evaluations = 0
        spp, n, integrator = self.spp, len(self.pixels) * self.spp, self.integrator

        def frame(scene, rays, seed):
            sampler = mi.load_dict({"type": "independent"})
            sampler.seed(seed, n)
            li, _, _ = integrator.sample(scene, sampler, rays)
            return dr.block_sum(li, spp) / spp
        # a few recordings per scene are expected (Dr.Jit re-records once inputs change)
        self._frame = dr.freeze(frame, warn_after=5 * len(skies))

    def radiance(self, theta):
        mi = self.mi
        out = np.zeros(self.shape + (3,))
        for t, (scene, params) in enumerate(zip(self.scenes, self.params)):
            write_material(params, self.key, self.model, theta)
            v = self._frame(scene, self.rays, mi.UInt32(self.seed + t))
            out[:, t] = np.array(v, dtype=float).T
        self.evaluations += 1
        return out
