"""The ``sun_sky_path`` integrator: a path tracer that samples the sun and the sky separately.

Mitsuba's ``path`` draws one light sample per vertex from the ``cie_sky`` emitter, which picks
the sun or the sky at random: on a sunlit surface that coin flip is most of a frame's noise
(relative deviation about sqrt((1 - p_sun) / p_sun) per sample).  Here the sun and the sky each
get their own light sample at every vertex, combined with the BSDF's by multiple importance
sampling (E. Veach, PhD thesis, Stanford 1997, ch. 9, the balance heuristic), treating the
emitter's radiance as the sum of its two parts,

    L_e(w) = h(w) + L_sun 1[w in the solar disc]          [W m^-2 sr^-1]

with h the sky function (:meth:`~skyfit_mi.render.plugins.cie_sky.CIESkyEmitter.sky_eval`,
thesis eqs. 4.12-4.18).  Each part has two techniques (its own and the BSDF's) whose balance
weights sum to one, so the estimate is unbiased.  An ideal mirror sees both parts through its
sampled direction only, and area emitters are found by BSDF sampling alone (weight one).

The scene's environment must be a ``cie_sky`` emitter.  Only surface scattering: no media.

Parameters:

=============  =======  ========  =======  ====================================================
name           type     range     default  meaning
=============  =======  ========  =======  ====================================================
``max_depth``  integer  >= 1      4        path vertices, as Mitsuba's ``path``: 1 shows the
                                           emitters seen directly, 2 adds direct light, ...
=============  =======  ========  =======  ====================================================

None differentiable (the integrator renders frames; fitting has its own model).
"""

import drjit as dr
import mitsuba as mi

from ...errors import SkyfitError


def _balance(p, q):
    """Balance heuristic weight p / (p + q) of the technique with density p [unitless]."""
    return dr.select(p > 0, p / dr.maximum(p + q, 1e-30), 0.0)


class SunSkyPathIntegrator(mi.SamplingIntegrator):
    """Path tracer with separate sun and sky light samples (see the module docstring)."""

    def __init__(self, props):
        mi.SamplingIntegrator.__init__(self, props)
        self.max_depth = int(props.get("max_depth", 4))
        if self.max_depth < 1:
            raise SkyfitError(f"sun_sky_path: max_depth = {self.max_depth}; give 1 or more.")

    @dr.syntax
    def sample(self, scene, sampler, ray, medium=None, active=True):
        sky = scene.environment()
        ctx = mi.BSDFContext()
        ray = mi.Ray3f(ray)
        L = mi.Spectrum(0.0)
        beta = mi.Spectrum(1.0)
        depth = mi.UInt32(0)
        # the previous vertex's BSDF density toward this ray [sr^-1]; the camera's ray, like
        # an ideal mirror's, takes the emitter at weight one
        prev_pdf = mi.Float(0.0)
        prev_delta = mi.Bool(True)
        active = mi.Bool(active)
        valid = mi.Bool(active)                   # an environment is always there to be seen

        # the emitter is read-only in the loop: excluded from its state (its map's table,
        # another size than the loop, would be refused)
        while dr.hint(active, max_iterations=self.max_depth, label="sun_sky_path",
                      exclude=[sky]):
            si = scene.ray_intersect(ray, active)
            miss = active & ~si.is_valid()
            # the environment along the ray, each part with its own MIS weight
            d = ray.d
            w_sky = dr.select(prev_delta, 1.0, _balance(prev_pdf, sky.pdf_sky(d)))
            w_sun = dr.select(prev_delta, 1.0, _balance(prev_pdf, sky.pdf_sun(d)))
            env = sky.sky_eval(d) * w_sky + dr.select(sky.pdf_sun(d) > 0, sky.sun_radiance,
                                                     0.0) * w_sun
            L[miss] += beta * env
            hit = active & si.is_valid()
            L[hit] += beta * si.emitter(scene, hit).eval(si, hit)

            go_on = hit & (depth + 1 < self.max_depth)
            bsdf = si.bsdf(ray)
            # light samples: the solar disc and the sky table, each with its shadow ray
            smooth = go_on & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
            for sample_dir, pdf_dir, radiance in (
                    (sky.sample_sun, sky.pdf_sun, lambda w: sky.sun_radiance),
                    (sky.sample_sky, sky.pdf_sky, sky.sky_eval)):
                wl = sample_dir(sampler.next_2d(smooth))
                p_light = pdf_dir(wl)
                seen = smooth & (p_light > 0) & ~scene.ray_test(si.spawn_ray(wl), smooth)
                f, p_bsdf = bsdf.eval_pdf(ctx, si, si.to_local(wl), seen)
                L[seen] += beta * f * radiance(wl) * dr.rcp(dr.maximum(p_light + p_bsdf, 1e-30))

            bs, weight = bsdf.sample(ctx, si, sampler.next_1d(go_on), sampler.next_2d(go_on),
                                     go_on)
            beta *= weight
            ray = si.spawn_ray(si.to_world(bs.wo))
            prev_pdf = bs.pdf
            prev_delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
            depth += 1
            active = go_on & (bs.pdf > 0) & dr.any(beta != 0.0)
        return L, valid, []

    def aov_names(self):
        return []

    def to_string(self):
        return f"SunSkyPathIntegrator[max_depth={self.max_depth}]"
