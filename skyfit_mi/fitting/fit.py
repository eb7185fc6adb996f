"""Fit Ward parameters to a region of a rendered or photographed sequence (thesis ch. 6-7).

:func:`fit_region` loads the region's pixel values and sigmas from a manifest, caches
the light arriving at those pixels (one Mitsuba pass), builds chi-square (eq. 6.2) over
the Dr.Jit model, runs the chosen method, and reports parameters, chi-square,
chi-square per degree of freedom, evaluations, wall time, seed, 68%/95% intervals and
identifiability warnings.  :func:`write_fit` writes the JSON and the observed-vs-model
plot (thesis fig. 7.14).
"""

import time
from dataclasses import dataclass, replace

import numpy as np

from . import uncertainty as unc
from .chi2 import (MEASURED_SE, LuminanceModel, Problem, load_observations,
                   load_table_observations)
from .geometry import geometry_warnings, highlight_geometry
from ..errors import SkyfitError, check_choice
from .methods import METHODS, global_search
from .methods.global_search import SIGMA_GRID
from .methods.levenberg_marquardt import SINGULAR_CONDITION, levenberg_marquardt
from .methods.profile import profile_edges, ridge_intervals
from .selection import HELD_OUT_FRAMES, held_out_error
from .light import SPEC_LIGHT, LightOptions, LightPlan
from .sky_fit import (SKY_DOMINATES, SkyFit, SkyShare, fit_sky_scale, light_level_sd,
                      shape_variants, skies_at_level, sky_level_at)
from ..render import setup
from ..render.basis_table import (TableModel, available_memory, block_budget, memory_estimate,
                                  mixed, shared_budget, trace_basis)
from ..render.fit_model import (BY_COUNT, PARAMETERS, bounds, check_fit_normalisation,
                                check_start, other_readings)
from ..render.light_cache import (CACHE_SHARE, DIRECTIONS, POINT_POSITIONS, POSITIONS,
                                  SIGMA_RESOLVED, SKY_PLANS, CacheOptions, PointRays,
                                  anchors_pay, build_light_cache)
from ..pipeline.ingest import pixel_sigma
from ..pipeline.jpeg_noise import YCC_TO_RGB, shared_error_sd
from ..pipeline.manifest import RENDERED_SOURCES, frame_sky, load_manifest
from ..pipeline.observation_table import is_table, relative_scale
from ..physics.sky import MEASURED_SUN_SD
from ..physics.turbid_sky import level_factors
from ..physics.ward import METAL_THRESHOLD


#: Largest spread of C's channels for which the cache-error estimate treats the colour rule's
#: two readings as one BRDF (:meth:`FitSession._same_reading`).
GREY_SPREAD = 0.02


#: Roughness values at which the model's own noise is reported [rms slope].
NOISE_SIGMAS = (0.01, 0.02, 0.05, 0.1, 0.2, 0.35, 0.5)
#: Share of the degrees of freedom above which the model's own noise is warned of.
NOISE_SHARE = 0.25
#: Largest growth of an automatically sized cache's positions, and the time a grown cache's
#: trace may take [s] (estimated from the first trace's): the data's need, within a budget.
CACHE_GROWTH_MAX, CACHE_TIME_BUDGET = 16, 20.0
#: Iterations of each constrained fit that profiles a parameter along a ridge (another
#: parameter poorly determined): the conditional-mean start is poor there.
PROFILE_RIDGE_ITERATIONS = 40
#: The widening of a variance by correlated channels (:func:`~.uncertainty.channel_factors`)
#: above which the fit says so.
CHANNEL_NOTE = 1.1
#: Rounds of the model error's fit (kappa from the residuals, the parameters again at it) at
#: most, and the relative change of kappa at which they stop (:meth:`FitSession._fit_model_error`).
MODEL_ERROR_ROUNDS, MODEL_ERROR_RTOL = 8, 0.02


@dataclass
class FitState:
    """A region's fit while its intervals and warnings are worked out (:meth:`FitSession.run`).

    method, theta, chi2 : the method, its minimum and chi-square there (``problem``'s: with
        the model's error where fitted)
    problem : the chi-square the fit minimised (:class:`~.chi2.Problem`): the session's, or
        with each value's sigma widened by the model's error
    model_error : the model's error (:class:`~.uncertainty.ModelError`) where chi-square
        exceeded what noise explains significantly, else None; ``model_error_rounds`` its
        fit's (:meth:`FitSession._fit_model_error`), and ``misfit`` the
        :class:`~.uncertainty.MisfitTest` of the chi-square without it
    interval_scale : s^2, the scale of chi-square's rise for an interval (chi-square over what
        the noise and the model's error give, where the model still misses the data; else 1)
    curvature_inverse : (J^T J)^-1 at the minimum
    channel_factors : each parameter's widening of its variance by errors shared by a value's
        channels (:func:`~.uncertainty.channel_factors`), and ``channel_correlation`` theirs
    covariance : the parameters' covariance (curvature, scale and channel factors)
    method_result, global_result : the method's result dict and the global search's (the same
        for the global method): its grid gives the profiles
    model_noise_by_sigma : the light cache's own share of chi-square by roughness
    noise_chi2 : mean and variance of the chi-square noise alone gives at the fit
    intervals, rise, cache_noise_chi2, cache_sd, sun_level_sd : set by
        :meth:`FitSession._intervals`: every parameter's 68%/95% intervals, the profiles' rise,
        the chi-square the cache's noise may add (the intervals allow for it), the standard
        errors from the cache's samples and from the sun's level
        (:func:`~.sky_fit.light_level_sd`)
    jpeg_shared_sd, calibration_sd : the standard errors from the rounding a JPEG frame's
        blocks share over the region and from a photographed sequence's calibration, errors
        every value of a frame shares (:func:`~.uncertainty.shared_error_sd`; zeros without
        JPEG frames, or calibration)
    matrix_sd : the standard errors from the camera's colour matrix, an error every value of
        the day shares (:meth:`FitSession._matrix_sd`; zeros without its prior)
    sky : what the light adds to the parameters' errors (:class:`~.sky_fit.SkyShare`)
    held_out : how well the fit predicts frames it was not fitted to
        (:func:`~.selection.held_out_error`, on ``problem``: its kappa is the error beyond the
        in-sample model error's), None with too few frames
    """

    method: str
    theta: np.ndarray
    chi2: float
    interval_scale: float
    curvature_inverse: np.ndarray
    channel_factors: np.ndarray
    channel_correlation: np.ndarray
    covariance: np.ndarray
    method_result: dict
    global_result: dict
    model_noise_by_sigma: dict
    noise_chi2: tuple
    problem: object = None
    model_error: object = None
    model_error_rounds: dict = None
    misfit: object = None
    sky: object = None
    intervals: dict = None
    rise: dict = None
    cache_noise_chi2: float = None
    cache_sd: np.ndarray = None
    calibration_sd: np.ndarray = None
    sun_level_sd: np.ndarray = None
    jpeg_shared_sd: np.ndarray = None
    matrix_sd: np.ndarray = None
    held_out: dict = None

    @property
    def delta_scale(self):
        """Each parameter's scale of Delta chi^2 for its interval: s^2 times its channel
        factor."""
        return self.interval_scale * self.channel_factors


class FitSession:
    """One region of one sequence, ready to fit: observations, light cache, models, chi-square.

    Building it traces the light at the region's pixels once (or :func:`trace_sessions`, for
    several regions at once); :meth:`run` then fits by any method and start without tracing
    again.

    Parameters
    ----------
    manifest_path : folder written by ``skyfit render`` (or its manifest.json)
    name : the region's material id in the manifest's scene
    pixels : (P, 2) pixel (x, y) coordinates on that material
    model : 'two', 'achromatic', 'colour' (or 2, 3, 5)
    normalisation : Ward normalisation of the model ('ward' = thesis eq. 3.19)
    seed : seeds the light cache
    positions, directions : samples per pixel of the light cache; ``positions=None`` sizes
        it from the data (:meth:`run`): POSITIONS (POINT_POSITIONS for a table's points),
        grown after a fit whose cache noise exceeds CACHE_SHARE of the chi-square the data's
        scatter gives (:meth:`cache_growth`)
    min_frames : rendered frames the sequence must hold (1 to predict a single frame)
    frames : manifest frame indices to use (None: every rendered frame), e.g. to hold some
        out for a prediction test
    variant : the Mitsuba variant to fit with (default the sequence's), e.g. 'cuda_ad_rgb'
    sky_plan : where the light cache takes the sky's integrals, a name of
        :data:`~skyfit_mi.render.light_cache.SKY_PLANS` (recorded in the fit JSON's
        ``light_cache``): ``fit`` by default, ``anchors`` for predictions of compact regions
    trace : False leaves the light cache to the caller (:func:`trace_sessions`)
    light : the :class:`~.light.LightPlan` traced when ``trace`` (default the spec's light as
        it is); a fitted sky's splits the sun's light from the rest of the sky's, so that the
        fit can scale them against each other (:meth:`set_sky`), and with ``shape`` traces the
        sky's shape variants (:meth:`~skyfit_mi.physics.sky.Sky.shape_variants`) too
    """

    def __init__(self, manifest_path, name, pixels, model="two", normalisation="ward", seed=0,
                 positions=None, directions=DIRECTIONS, min_frames=2, frames=None, variant=None,
                 sky_plan="fit", trace=True, light=SPEC_LIGHT):
        model = BY_COUNT.get(model, model)
        check_choice("model", model, tuple(PARAMETERS))
        check_fit_normalisation(normalisation)          # before the light is traced
        t0 = time.perf_counter()
        doc, root = load_manifest(manifest_path)
        self.run_id = doc.get("run_id")
        if is_table(doc):
            self.obs = load_table_observations(manifest_path, name, pixels, frames, min_frames)
            if self.obs.luminance and model == "colour":
                raise SkyfitError(f"region {name!r} is measured as luminance, which cannot tell "
                                  "colour; fit it with --model 2 or 3.")
            if relative_scale(doc) and model == "two":
                raise SkyfitError("the table's scale is unknown (ingest --unknown-scale), and the "
                                  "2-parameter model's surface is white (rho_d + rho_s = 1), "
                                  "which needs the scale; fit it with --model 3 or 5.")
        else:
            self.obs = load_observations(manifest_path, pixels, frames, min_frames)
        mats = doc["scene"]["materials"]
        if name not in mats:
            raise SkyfitError(f"region {name!r} names no material of the scene; its materials are: "
                              f"{', '.join(mats)}.")
        frames = {f["index"]: f for f in doc["frames"]}
        self.skies = [frame_sky(frames[i], root) for i in self.obs.frames]
        self.doc, self.name, self.model, self.normalisation = doc, name, model, normalisation
        self.names = PARAMETERS[model]
        self.lower, self.upper = bounds(model)
        # a material is the truth only where skyfit rendered the frames with it; an ingested
        # sequence's spec materials are placeholders for the unknown photographed surface
        self.truth = mats[name] if doc.get("source", "render") in RENDERED_SOURCES else None
        self.cache_settings = {"positions": self.first_positions if positions is None
                               else int(positions),
                               "directions": int(directions), "seed": seed,
                               "sized": "from the data" if positions is None else "given",
                               "sky_plan": check_choice("sky plan", sky_plan, tuple(SKY_PLANS))}
        self._mi = setup(variant or doc["render"]["variant"])
        self._loaded = None                         # the scene and its parameters (scene)
        # the light traced (a LightPlan) and its tables: one, or the sun's, the rest's (a
        # fitted sky) and the rest's shape variants, mixed at sky_scale and the shape's mix
        # sky_shape_mix (set_sky)
        self.light, self.sky_scale, self.parts = light, 1.0, None
        self.parts_cov = None           # the covariances of parts traced with shared samples
        self.sky_shape_mix = None
        self._variants = None                       # the shape variants (_shape_variants)
        self.cache_time = time.perf_counter() - t0
        if trace:
            self.trace_light(light)

    @classmethod
    def from_fit(cls, result, manifest_path, pixels=None, **options):
        """The session of the region that a fit ``result`` (a fit JSON, checked by
        :func:`~skyfit_mi.pipeline.fit_result.read_fit_result`) measured, in its model and
        normalisation, on the sequence ``manifest_path`` (its own, or a target's); ``pixels``
        default to the fit's own; ``options`` as the constructor's.  A fit of the sky's level
        (``fit --sky fit``) lights its own sequence with that level; another sequence's sky is
        its spec's (the level belongs to the fitted day's sky)."""
        if pixels is None and "points" in result:           # a fit of an observation table
            pixels = result["points"]
        elif pixels is None:
            if not isinstance(result.get("pixels"), list) or not result["pixels"]:
                raise SkyfitError(f"the fit of region {result['region']!r} lists no pixels; "
                                  "give the fit_NAME.json that `skyfit fit` wrote.")
            pixels = result["pixels"]
        trace = options.pop("trace", True)
        s = cls(manifest_path, result["region"], pixels, model=result["model"],
                normalisation=result.get("normalisation", "ward"), trace=False, **options)
        if trace:
            s.trace_light(s.fitted_light(result))
            s.use_fitted_sky(result)
        return s

    def fitted_light(self, result):
        """The :class:`~.light.LightPlan` that lights this sequence as a fit ``result`` saw it:
        a sky fit's (``fit --sky fit``) split light, with its shape variants where it fitted
        the shape, where the fit measured this very sequence (its run_id); else the spec's
        (the fitted level belongs to the fitted day's sky)."""
        sky = result.get("sky")
        if sky is None or result.get("sequence_run_id") != self.run_id:
            return SPEC_LIGHT
        return LightPlan("fit", shape=sky.get("shape") is not None)

    def light_at_level(self, record):
        """Take the frames' skies at a sky fit's level (``record``,
        :func:`~.sky_fit.skies_at_level`) as the spec's light, before the light is traced: the
        light a lobe is ranked in (:func:`~.selection.fit_auto`)."""
        self.skies = skies_at_level(self.skies, record, self.obs.times)

    def use_fitted_sky(self, result):
        """Light the sequence, traced with :meth:`fitted_light`, at a sky fit's level and shape
        (``fit --sky fit``, in ``result``)."""
        sky = result.get("sky")
        if self.light.split:
            k = sky_level_at(sky, self.obs.times)
            mix = None if sky.get("shape") is None else sky["shape"]["mix"]
            self.set_sky(float(k[0]) if np.ptp(k) == 0 else k, mix)

    def trace_light(self, light=None):
        """(Re)trace the light (a :class:`~.light.LightPlan`; None: the one traced last) at
        ``cache_settings`` and make everything from its table."""
        trace_sessions([self], self.light if light is None else light)

    def take_parts(self, parts, cov, light, seconds):
        """Fit on the light ``light`` traced as ``parts`` (:meth:`_trace`, this session's rows)
        with their covariances ``cov``, its trace having taken ``seconds``."""
        self.light = light
        self.cache_time += seconds
        self._use_parts(parts, cov)

    def _trace(self, at, bsdf_id, light):
        """The :class:`~skyfit_mi.render.basis_table.BasisTable` of the light at
        ``cache_settings`` of the sequence's scene and frames at ``at`` (pixels or rays) on
        material ``bsdf_id`` (one, or one per pixel), traced in blocks of bounded memory: a
        list of one table, or under ``light`` (a :class:`~.light.LightPlan`) that splits the sky
        the sun's and the rest's (their samples independent) and with its ``shape`` the rest's
        shape variants (traced with the rest's samples); and the :class:`~skyfit_mi.render.basis_table.Covariances` of the parts
        traced together (None where there are none)."""
        c = self.cache_settings
        # the split light's tables and their mix
        lights = self._sky_parts(light.shape) if light.split else None
        # a table per part, and the shape group's covariances about one more
        need = (len(lights) + 1 + light.shape if lights else 1) * memory_estimate(
            len(at), len(self.skies), c["positions"], c["directions"])
        have = available_memory()
        if have is not None and need > have:
            raise SkyfitError(
                f"fitting {len(at)} points in {len(self.skies)} frames needs up to "
                f"{need / 2**30:.1f} GB, but this machine has {have / 2**30:.1f} GB available; "
                "fit fewer pixels (--max-pixels) or frames (--frames), or a region at a time.")
        options = CacheOptions(**self._cache_options())
        if not light.split:
            tables, _, c["blocks"] = trace_basis(self.scene, self.params, [self.skies], at,
                                                 bsdf_id, options, model=self.model)
            return tables, None
        seeds = np.random.SeedSequence(options.seed).generate_state(2).tolist()
        # the sun's part in the blocks of the rest's group (shared_budget), whose series mix
        budget = block_budget(len(at), len(self.skies), c["positions"])
        parts = []
        for group, seed, b in zip((lights[:1], lights[1:]), seeds,
                                  (shared_budget(budget, len(lights[1:])), budget)):
            tables, cov, c["blocks"] = trace_basis(self.scene, self.params, group, at, bsdf_id,
                                                   replace(options, seed=int(seed)), b,
                                                   self.model)
            parts += tables
        # the covariances' pairs as indices into the parts (the sun's first)
        return parts, None if cov is None else replace(cov, pairs=[(j + 1, k + 1)
                                                                   for j, k in cov.pairs])

    def _sky_parts(self, shape):
        """The light's parts, each a list of the frames' skies: the sun's and the rest's
        (:meth:`~skyfit_mi.physics.sky.Sky.split`), and with ``shape`` the rest's shape
        variants (:meth:`~skyfit_mi.physics.sky.Sky.shape_variants`)."""
        sun, rest = zip(*(sky.split() for sky in self.skies))
        lights = [list(sun), list(rest)]
        if shape:
            variants = self._shape_variants()
            lights += [[v[j][1] for v in variants] for j in range(len(variants[0]))]
        return lights

    def _shape_variants(self):
        """Each frame's shape variants of the spec's sky (:func:`~.sky_fit.shape_variants`),
        made once."""
        if self._variants is None:
            self._variants = shape_variants(self.skies)
        return self._variants

    def light_levels(self, mix):
        """(sun, sky): the factors on each frame's sun and sky (T,) that the shape's ``mix``
        brings with it: a turbid sky's turbidity sets both levels
        (:func:`~skyfit_mi.physics.turbid_sky.level_factors`); 1 for other skies, or no mix."""
        if mix is None or not all(s.info.get("kind") == "turbid" for s in self.skies):
            return 1.0, 1.0
        return level_factors([s.info for s in self.skies],
                             [v[0][1].info for v in self._shape_variants()], mix[0])

    def _cache_options(self):
        """build_light_cache's options at ``cache_settings``."""
        c = self.cache_settings
        return dict(positions=c["positions"], directions=c["directions"], seed=c["seed"],
                    max_depth=max(1, int(self.doc["render"]["max_depth"]) - 1),
                    normalisation=self.normalisation, plan=c["sky_plan"])

    @property
    def first_positions(self):
        """An automatically sized cache's first positions: POSITIONS a pixel, POINT_POSITIONS a
        measured point."""
        return POSITIONS if self.obs.rays is None else POINT_POSITIONS

    @property
    def scene(self):
        """The sequence's Mitsuba scene, loaded when first needed (to trace the light): every
        live scene's materials are targets of the path tracer's virtual calls, traced in each
        frame, so sessions that share one trace (:func:`trace_sessions`) load one."""
        return self._scene_and_params()[0]

    @property
    def params(self):
        """The scene's parameters (``mi.traverse``)."""
        return self._scene_and_params()[1]

    def _scene_and_params(self):
        if self._loaded is None:
            scene = self._mi.load_string(self.doc["scene"]["xml"])
            self._loaded = scene, self._mi.traverse(scene)
        return self._loaded

    def light_cache(self):
        """The region's raw :class:`~skyfit_mi.render.light_cache.LightCache` at
        ``cache_settings`` in one block, its samples kept (for diagnostics and tests of the
        Dr.Jit model: a fit keeps only their table)."""
        return build_light_cache(self.scene, self.params, self.skies,
                                 self.obs.pixels if self.obs.rays is None else self.obs.rays,
                                 self.name, **self._cache_options())

    def _use_parts(self, parts, cov=None):
        """Take the light's tables ``parts`` and their covariances ``cov`` (:meth:`_trace`) and
        fit on their mix."""
        self.parts, self.parts_cov = list(parts), cov
        if len(self.parts) == 1:
            self._use_table(self.parts[0])
            return
        sun, sky = self.light_levels(self.sky_shape_mix)
        k = self.sky_scale * sky
        mix = np.zeros(len(self.parts) - 2) if self.sky_shape_mix is None else self.sky_shape_mix
        self._use_table(mixed(self.parts[0], self.parts[1:],
                              [k * (1.0 - mix.sum())] + [k * m for m in mix], sun, cov))

    def set_sky(self, k, mix=None):
        """Scale the split light's sky (all but the sun) by ``k`` against the spec's, relative
        to the sun (one factor, or one per frame of the session), in the spec's shape or with
        ``mix[j]`` of its shape variant j and (1 - sum(mix)) of its own pattern
        (:meth:`~skyfit_mi.physics.sky.Sky.shape_variants`), and make the models and
        chi-square on it."""
        if len(self.parts or ()) < 2 + (0 if mix is None else len(mix)):
            raise ValueError("the sky's level needs a session traced with a fitted sky's light, "
                             "its shape one traced with the sky's shape variants")
        self.sky_scale = float(k) if np.ndim(k) == 0 else np.asarray(k, dtype=float)
        self.sky_shape_mix = None if mix is None else np.asarray(mix, dtype=float)
        self._use_parts(self.parts, self.parts_cov)

    def take_light(self, other):
        """Fit on the light ``other`` (a traced session of the same region, sequence and
        lobe, in any parameterisation: the table does not depend on it) traced."""
        self.cache_settings = dict(other.cache_settings)
        self.take_parts(other.parts, other.parts_cov, other.light, other.cache_time)

    def _use_table(self, table):
        """Take ``table`` (of the region's pixels) and make the models and chi-square on it."""
        if not table.hit.any():
            raise SkyfitError(f"none of the region's pixels shows material {self.name!r}; check "
                              "the region.")
        self.table = table
        self.geometry = highlight_geometry(np.where(table.hit[..., None], table.sun_half_cos,
                                                    np.nan))
        self.wm = self.model_on(table)
        self.problem = Problem(self.obs, self.wm, valid=table.hit)
        self._halves = self._bases = None

    def model_on(self, table, part=0):
        """The fit's radiance model on ``table`` (its whole cache, or a half: ``part`` 1, 2):
        Ward's, through the luminance where the observations are luminances."""
        wm = TableModel(table, self.model, part)
        return LuminanceModel(wm) if self.obs.luminance else wm

    def cache_growth(self, noise_by_sigma, s2=1.0):
        """The factor by which an automatically sized cache's positions must grow so that the
        largest model noise over the roughness range (``noise_by_sigma``, chi-square) falls
        under CACHE_SHARE of the chi-square the data's own scatter gives (the degrees of
        freedom, times the interval scale ``s2`` where the model misses the data: a misfit's
        residuals dwarf the cache's noise, which then needs no more samples); its variance
        falls as 1 / positions.  A power of two within CACHE_GROWTH_MAX whose trace, estimated
        from this one's, takes at most CACHE_TIME_BUDGET; 1 for a cache of given size."""
        if self.cache_settings["sized"] == "given":
            return 1
        need = max(noise_by_sigma.values()) / (CACHE_SHARE * self.problem.dof * max(1.0, s2))
        room = min(CACHE_GROWTH_MAX * self.first_positions / self.cache_settings["positions"],
                   CACHE_TIME_BUDGET / max(self.cache_time, 1e-3))
        factor = 1
        while factor < need and 2 * factor <= room:
            factor *= 2
        return factor

    def cache_error(self, theta, method, problem=None):
        """Standard error each parameter owes to the light cache's Monte Carlo samples (on the
        chi-square of ``problem``'s observations, default the session's).

        The fit is repeated on each of two independent half caches (by the global method
        when that found ``theta``, else by Levenberg-Marquardt from ``theta``, which finds
        the same local minimum); their estimates differ by the cache error of a half twice
        over, so the whole cache's error is |theta_A - theta_B| / 2 (each on theta's side of
        the colour rule, see :meth:`_same_reading`).  One degree of freedom makes it rough,
        but it keeps intervals honest when the data are precise enough for the cache's noise
        to ripple chi-square by more than the 95% threshold.
        """
        obs = (problem or self.problem).obs
        if self._halves is None or self._halves[0].obs is not obs:
            self._halves = [Problem(obs, self.model_on(self.table, part=j),
                                    valid=self.table.hit) for j in (1, 2)]
        if method == "global":
            fits = [global_search(p, theta, self.lower, self.upper, candidates=1, profile=False,
                                  grid_basis=b)["theta"]
                    for p, b in zip(self._halves, self.grid_bases()[1:])]
        else:
            fits = [levenberg_marquardt(p, theta, self.lower, self.upper)["theta"]
                    for p in self._halves]
        # a half that lands on the other reading of a grey C (across the colour rule, the
        # same BRDF to within the data) is read at its minimum on theta's side: the
        # difference between readings is the ambiguity warned of, not cache error
        fits = [self._same_reading(p, np.asarray(f, dtype=float), theta)
                for p, f in zip(self._halves, fits)]
        return np.abs(fits[0] - fits[1]) / 2

    def _same_reading(self, problem, fit, theta):
        """A half cache's ``fit`` on ``theta``'s side of the colour rule: when C is grey (within
        GREY_SPREAD) and the fit is across the rule, Levenberg-Marquardt on that half from the
        fit's twin reading; otherwise the fit itself."""
        def side(x):
            return x[3] >= METAL_THRESHOLD
        if np.ptp(fit[:3]) > GREY_SPREAD:
            return fit
        for twin in other_readings(self.model, fit):
            if side(twin) == side(theta) != side(fit):
                polished = np.asarray(levenberg_marquardt(problem, twin, self.lower,
                                                          self.upper)["theta"])
                if side(polished) == side(theta):
                    return polished
        return fit

    def grid_bases(self):
        """The global search's basis on its sigma grid for the whole cache and each half, made
        once per session (it does not depend on the data); its lobes lazy
        (:class:`~skyfit_mi.render.basis_table.Lobes`), a few roughness values at a time."""
        if self._bases is None:
            self._bases = self.wm.lobes(SIGMA_GRID, halves=True)
        return self._bases

    def random_start(self, rng):
        return self.lower + rng.random(len(self.lower)) * (self.upper - self.lower)

    def run(self, method="global", start=None, seed=0, method_options=None, log=print,
            sky=None):
        """Fit by ``method`` from ``start`` (random within bounds, seeded, if None); a result dict.
        ``sky``: what the light adds to the parameters' errors (a :class:`~.sky_fit.SkyShare`:
        the sky fit's, :func:`fit_sessions`; None: the traced light's sun level alone).

        The steps: the method's minimum, the model's error where the model cannot reproduce
        the data (:meth:`_fit_model_error`), the covariance, the global minimum (whose grid
        gives the profiles and judges a local method), intervals (:meth:`_intervals`),
        warnings (:meth:`_warnings`), and the JSON-ready record (:meth:`_record`).
        """
        check_choice("fit method", method, tuple(METHODS))
        problem, wm = self.problem, self.wm
        problem.evaluations = wm.evaluations = wm.basis_evaluations = 0
        t0 = time.perf_counter()
        if start is None:
            start = self.random_start(np.random.default_rng(seed))
        start = check_start(self.model, start)      # one value per parameter, within bounds
        grid_basis = self.grid_bases()[0]
        res = METHODS[method](problem, start, self.lower, self.upper, seed=seed,
                              grid_basis=grid_basis,
                              alternatives=lambda th: other_readings(self.model, th),
                              **dict(method_options or {}))
        theta = np.asarray(res["theta"], dtype=float)
        noise = self._model_noise_by_sigma(theta)
        growth = self.cache_growth(noise, unc.scale(problem.chi2(theta),
                                                    problem.noise_chi2(theta)[0]))
        if growth > 1:
            # the data are more precise than the cache: grow it and fit again
            c = self.cache_settings
            c.setdefault("grown_from", []).append(
                {"positions": c["positions"], "largest_noise_chi2": max(noise.values()),
                 "dof": self.problem.dof})
            log(f"{self.name}: the light cache's noise adds up to {max(noise.values()):.3g} to "
                f"chi-square ({self.problem.dof} degrees of freedom); tracing it again with "
                f"{growth * c['positions']} positions per pixel")
            c["positions"] *= growth
            self.trace_light()
            return self.run(method, start, seed, method_options, log, sky)
        # where the model cannot reproduce the data, its error is fitted with the parameters
        misfit = unc.misfit_test(problem.chi2(theta), problem.dof,
                                 problem.model_noise_chi2(theta), problem.noise_chi2(theta))
        res, problem, merr, rounds = self._fit_model_error(method, res, misfit, seed,
                                                           method_options)
        theta = np.asarray(res["theta"], dtype=float)
        if merr is not None:
            noise = self._model_noise_by_sigma(theta, problem)
        evaluations = self.problem.evaluations + wm.basis_evaluations + rounds["evaluations"]
        t_method = time.perf_counter() - t0
        # uncertainty: covariance at the optimum
        r_all, J_all = problem.jacobian(theta, full=True)
        r, J = r_all[problem.mask], J_all[problem.mask]
        chi2 = float(r @ r)
        noise_chi2 = problem.noise_chi2(theta)           # what noise alone gives (clipping)
        s2 = unc.scale(chi2, noise_chi2[0])
        curv_inv = unc.covariance(J)
        # errors shared by a value's channels widen each parameter's variance by f2
        measured = problem.measured()
        f2, channels = unc.channel_factors(r_all, J_all, measured, problem.mask)
        # the global minimum: its grid gives the profiles; a local method is judged against it
        g = res if method == "global" else global_search(problem, start, self.lower, self.upper,
                                                        candidates=2, grid_basis=grid_basis)
        fit = FitState(method, theta, chi2, s2, curv_inv, f2, channels,
                       curv_inv * s2 * np.sqrt(np.outer(f2, f2)), res, g, noise, noise_chi2,
                       problem, merr, rounds, misfit,
                       sky or SkyShare(sun_sd=self.light.sun_sd, sun_source=self.light.sun_source))
        fit.jpeg_shared_sd = self._jpeg_shared_sd(J_all, measured, problem.obs.sigma, curv_inv)
        fit.calibration_sd = self._calibration_sd(J_all, problem, measured, theta, curv_inv)
        fit.matrix_sd = self._matrix_sd(J_all, problem, measured, theta, curv_inv)
        self._intervals(fit)
        iv95 = np.array([fit.intervals[p]["95"] for p in self.names])
        fit.held_out = held_out_error(
            problem, theta, self.lower, self.upper,
            within=lambda th: bool(np.all((th >= iv95[:, 0]) & (th <= iv95[:, 1]))),
            frame_sd=self._frame_calibration_sd())
        warnings = self._warnings(fit)
        wall = time.perf_counter() - t0 + self.cache_time
        out = self._record(fit, warnings, start, seed, evaluations, wall, t_method)
        log(f"{self.name}: {self.model} fit by {method}: "
            + ", ".join(f"{k} = {v:.4f}" for k, v in out["parameters"].items())
            + f"; chi2/dof = {out['chi2_per_dof']:.3g}"
            + (f"; model error kappa = {merr.kappa:.3g} (95%: {merr.interval95[0]:.3g}-"
               f"{merr.interval95[1]:.3g}): {merr.meaning}" if merr is not None else "")
            + f"; {evaluations} evaluations; {wall:.1f} s"
            + "".join(f"\n  {r}" for r in out["readings"] if "=" not in r)
            + "".join(f"\n  warning: {w}" for w in warnings))
        return out

    def _fit_model_error(self, method, res, misfit, seed, method_options):
        """The model's error fitted with the parameters, where chi-square exceeds what noise
        explains beyond chance (``misfit``, a :class:`~.uncertainty.MisfitTest` at the
        method's minimum ``res``): kappa from the residuals at the parameters
        (:meth:`~.chi2.Problem.model_error`), then the parameters again with every sigma
        widened by it (:meth:`~.chi2.Problem.with_model_error`), in turn, until kappa changes
        by less than MODEL_ERROR_RTOL (at most MODEL_ERROR_ROUNDS): each step lowers the same
        restricted likelihood.  The global method searches again each round (the weights can
        move its minimum), the others polish by Levenberg-Marquardt.

        Returns (the method's result, the chi-square it minimised, the
        :class:`~.uncertainty.ModelError` or None, {rounds, settled, evaluations}); without
        significant misfit, or at a kappa of 0, the method's result on the session's
        chi-square, unchanged."""
        rounds = {"rounds": 0, "settled": True, "evaluations": 0}
        base, theta = self.problem, np.asarray(res["theta"], dtype=float)
        if not misfit.significant:
            return res, base, None, rounds
        est = base.model_error(theta)
        if est.kappa == 0.0:
            return res, base, None, rounds
        rounds["settled"] = False
        for _ in range(MODEL_ERROR_ROUNDS):
            problem = base.with_model_error(est.kappa, theta)
            if method == "global":
                res = global_search(problem, theta, self.lower, self.upper, seed=seed,
                                    grid_basis=self.grid_bases()[0],
                                    **dict(method_options or {}))
            else:
                polish = levenberg_marquardt(problem, theta, self.lower, self.upper)
                res = {**res, "theta": polish["theta"], "chi2": polish["chi2"],
                       "message": f"{res.get('message')}; then polished by "
                                  f"Levenberg-Marquardt with the model's error: "
                                  f"{polish['message']}"}
            theta = np.asarray(res["theta"], dtype=float)
            rounds["rounds"] += 1
            rounds["evaluations"] += problem.evaluations
            before, est = est.kappa, base.model_error(theta)
            if abs(est.kappa - before) <= MODEL_ERROR_RTOL * before:
                rounds["settled"] = True
                break
        return res, base.with_model_error(est.kappa, theta), est, rounds

    def _intervals(self, fit):
        """68% and 95% intervals of every parameter into the :class:`FitState` ``fit`` (its
        intervals, rise, cache_noise_chi2, cache_sd, sun_level_sd): the covariance's, or for
        rho_s and sigma_alpha of a global fit the profile's; each widened by the light cache's
        own Monte Carlo error, the calibration's (``calibration_sd``), the fitted sky's and, a
        factor on the reflectances, the sun's level's; by the rounding a JPEG frame's blocks
        share over the region (``jpeg_shared_sd``) and the camera's colour matrix's error
        (``matrix_sd``)."""
        problem, theta, names = fit.problem, fit.theta, self.names
        lower, upper = self.lower, self.upper
        s2k = fit.delta_scale                             # each parameter's scale of Delta chi^2
        cov_iv = unc.covariance_intervals(theta, fit.covariance, lower, upper)
        grid = fit.global_result["profile_linearised"]
        prof = {"sigma_alpha": (grid["sigma_alpha"], grid["chi2_sigma"]),
                "rho_s": (grid["rho_s"], grid["chi2_rho"])}
        ripple = self._model_noise_allowance(problem, theta, *prof["sigma_alpha"], s2k[-1])
        # the profiles describe the global minimum; a local method is judged against it
        glob = fit.method == "global"
        intervals, rise, walked = {}, {}, []
        for i, p in enumerate(names):
            iv = {lv: (float(cov_iv[lv][0][i]), float(cov_iv[lv][1][i])) for lv in ("68", "95")}
            source = "covariance"
            if p in prof:
                rise[p] = float(np.max(prof[p][1]) - np.min(prof[p][1]))
                if glob:
                    # the union of the grid's (linearised) profile interval and the true
                    # chi^2's (see methods/profile.py): the first is offset where the sensor
                    # clips, the second inherits the cache's narrow-lobe error (a mirror fit
                    # of the board's polished steel, truth sigma_alpha 0.02: 95% edge 0.002)
                    iv = unc.profile_interval(*prof[p], s2k[i], ripple)
                    levels = list(iv)
                    exact, _, points = profile_edges(
                        problem, theta, fit.chi2, i,
                        [unc.LEVELS[lv] * s2k[i] + ripple for lv in levels], lower, upper,
                        fit.curvature_inverse)
                    walked += points
                    iv = {lv: (min(iv[lv][0], e[0] if e[0] is not None else np.inf),
                               max(iv[lv][1], e[1] if e[1] is not None else -np.inf))
                          for lv, e in zip(levels, exact)}
                    source = "profile"
            intervals[p] = {"68": iv["68"], "95": iv["95"], "from": source}
        if glob and self._poorly_determined(theta, intervals, prof, fit.covariance):
            walked += self._profile_the_rest(fit, intervals, ripple)
        for lv in ("68", "95"):
            # every point the profiles walked within the level lies inside every interval
            for i, p in enumerate(names):
                ridge = ridge_intervals(walked, fit.chi2, unc.LEVELS[lv] * s2k[i] + ripple)
                if ridge is not None:
                    lo, hi = intervals[p][lv]
                    intervals[p][lv] = (min(lo, float(ridge[0][i])), max(hi, float(ridge[1][i])))
        mc_sd = self.cache_error(theta, fit.method, problem)
        cal_sd = fit.calibration_sd
        sky = fit.sky
        sky_sd = np.zeros(len(names)) if sky.sd is None else sky.sd
        sun_rel = light_level_sd(self.doc, names, sky.sun_level_sd)
        for i, p in enumerate(names):
            for lv in ("68", "95"):
                intervals[p][lv] = unc.widen(theta[i], intervals[p][lv], unc.Z[lv] * np.sqrt(
                    mc_sd[i] ** 2 + cal_sd[i] ** 2 + sky_sd[i] ** 2
                    + fit.jpeg_shared_sd[i] ** 2 + fit.matrix_sd[i] ** 2), lower[i], upper[i])
                # the sun's level: a factor on every reflectance, lopsided
                intervals[p][lv] = unc.widen_relative(theta[i], intervals[p][lv],
                                                      unc.Z[lv] * sun_rel[i], lower[i], upper[i])
                if sky.span is not None:      # the sky's level is not determined
                    lo, hi = intervals[p][lv]
                    intervals[p][lv] = (min(lo, float(sky.span[0][i])),
                                        max(hi, float(sky.span[1][i])))
                    if lv == "95":
                        intervals[p]["from"] += ", and over the undetermined sky level"
        fit.intervals, fit.rise, fit.cache_noise_chi2 = intervals, rise, ripple
        fit.cache_sd = mc_sd
        fit.sun_level_sd = sun_rel * np.abs(theta)

    def _calibration_sd(self, J, problem, usable, theta, curvature_inverse):
        """Each parameter's standard error (n,) from a photographed sequence's calibration on
        patches of known reflectance (ingest's ``calibration`` record): each frame's exposure
        errs per channel by ``frame_relative_sd`` where the frames take their own
        (``per_frame``), or the day's by ``scale_relative_sd`` where they share one.  An
        error e moves every value of its frame and channel by e times the value
        (:meth:`~.chi2.Problem.value_scale`), carried to the parameters by
        :func:`~.uncertainty.shared_error_sd`: not a mere scale on the reflectances, since
        frames erring apart bend the day's curve, which the specular share and the roughness
        follow (a board's yellow paint, its sun's highlight never seen, frames calibrated
        each on its own: C_b's standard error from the calibration 0.21%, where a scale gave
        0.07%).  A table's, without frames photographed, is
        :func:`~.uncertainty.calibration_sd`."""
        cal = (self.doc.get("ingest") or {}).get("calibration") or {}
        if self.obs.rays is not None or not cal.get("scale_relative_sd"):
            return unc.calibration_sd(self.doc, self.names, theta)
        Js = J * problem.value_scale(theta)[..., None]          # per relative error of a value
        sigma = problem.obs.sigma
        if cal.get("per_frame"):
            shared = np.tile(np.asarray(self._frame_calibration_sd(), dtype=float),
                             (J.shape[1], 1))
        else:                                         # one error per channel for every frame
            P, T, C, n = J.shape
            Js, usable, sigma = (a.reshape((P * T, 1) + a.shape[2:]) for a in (Js, usable, sigma))
            shared = np.asarray(cal["scale_relative_sd"], dtype=float)[None, :]
        return unc.shared_error_sd(Js, usable, sigma, shared, np.eye(3), curvature_inverse)

    def _frame_calibration_sd(self):
        """The relative error (3,) every value of a photographed frame and channel shares from
        its own calibration (ingest's ``calibration.frame_relative_sd`` where each frame took
        its own), else None."""
        cal = (self.doc.get("ingest") or {}).get("calibration") or {}
        return cal["frame_relative_sd"] if cal.get("per_frame") else None

    def _matrix_sd(self, J, problem, usable, theta, curvature_inverse):
        """Each parameter's standard error (n,) from the camera's colour matrix (ingest's
        ``colour_matrix`` record: each entry of its error E, in linear sRGB, relative_sd): a
        developed value of channel c reads L_c + sum_j E_cj L_j, whose grey-card calibration
        (which scales each channel to the grey's truth) leaves L_c + sum_(j != c) E_cj (L_j -
        L_c), nothing on a grey and most on a saturated colour's weak channels.  Each of the
        six E_cj is one error for the whole day (one camera, one matrix), carried to the
        parameters by :func:`~.uncertainty.shared_error_sd` with the ratios L_j / L_c of the
        model at ``theta``; zeros without the record or for a table."""
        rel = ((self.doc.get("ingest") or {}).get("colour_matrix") or {}).get("relative_sd")
        n = len(self.names)
        if self.obs.rays is not None or not rel:
            return np.zeros(n)
        L = problem.model.radiance(theta)
        value = problem.value_scale(theta)
        P, T, C, _ = J.shape
        flat = (P * T, 1, C, n)
        var = np.zeros(n)
        for c in range(C):
            for j in range(C):
                if j == c:
                    continue
                with np.errstate(all="ignore"):
                    move = np.nan_to_num(value[..., c] * (L[..., j] / L[..., c] - 1.0))
                Jk = np.zeros_like(J)
                Jk[..., c, :] = J[..., c, :] * move[..., None]
                var += unc.shared_error_sd(Jk.reshape(flat), usable.reshape(flat[:3]),
                                           problem.obs.sigma.reshape(flat[:3]), [[rel]],
                                           np.ones((C, 1)), curvature_inverse) ** 2
        return np.sqrt(var)

    def _matrix_note(self):
        """What the colour matrix's error in a fit's intervals is and where it came from."""
        rec = self.doc["ingest"]["colour_matrix"]
        return (f"the camera's colour matrix is taken to err by {100 * rec['relative_sd']:.3g}% "
                f"per entry ({rec['source']}), an error a grey card cannot see (it calibrates "
                "each channel on a grey, whose channels the error mixes alike) and that moves "
                "a saturated colour's weak channels most; the intervals include it")

    def _jpeg_shared_sd(self, J, usable, sigma, curvature_inverse):
        """Each parameter's standard error (n,) from the rounding of the block means that the
        region's pixels share in each JPEG frame (Y, Cb, Cr; ingest's ``jpeg_dc`` record,
        :func:`~skyfit_mi.pipeline.jpeg_noise.shared_error_sd`, with the sensor's noise before
        compression from the manifest's noise model), carried to the parameters by
        :func:`~.uncertainty.shared_error_sd`, ``sigma`` the values' in chi-square); zeros
        without JPEG frames."""
        n = len(self.names)
        by_index = {f["index"]: f for f in self.doc["frames"]}
        records = [by_index.get(i, {}).get("jpeg_dc") for i in self.obs.frames]
        model = self.doc["sensor"].get("noise_model") or {}
        if self.obs.rays is not None or not any(records) or "read_DN2" not in model:
            return np.zeros(n)
        noise = (model["read_DN2"], model["shot_DN"])
        shared = np.zeros((len(records), 3))
        for t, rec in enumerate(records):
            ok = np.all(np.isfinite(self.obs.sigma[:, t]), axis=1)
            if rec and ok.any():
                y = self.obs.y[ok, t]
                shared[t] = shared_error_sd(y, pixel_sigma(y, self.obs.sensor, noise) ** 2, rec)
        return unc.shared_error_sd(J, usable, sigma, shared, YCC_TO_RGB, curvature_inverse)

    def _model_noise_by_sigma(self, theta, problem=None):
        """The model's own Monte Carlo share of chi-square (``problem``'s, default the
        session's) at the fitted reflectances over the roughness range (NOISE_SIGMAS): where
        it is a sizeable share of the degrees of freedom it pulls fits toward the roughness
        where it is small."""
        problem = problem or self.problem
        return {f"{v:g}": problem.model_noise_chi2(np.r_[theta[:-1], v])
                for v in NOISE_SIGMAS}

    def _poorly_determined(self, theta, intervals, profiled, cov):
        """Whether a profiled parameter's 95% interval runs into a bound of its range, covers
        over half of it, or is not the covariance's (either side under a third or over three times
        its covariance half-width: chi-square far from quadratic; on a Radiance-traced day rho_s's
        profile was a cliff on one side and flat on the other): then the others trade off along
        a ridge that their covariance intervals (a quadratic at the fit) miss."""
        for i, p in enumerate(self.names):
            if p in profiled:
                lo, hi = intervals[p]["95"]
                span = self.upper[i] - self.lower[i]
                half = unc.Z["95"] * np.sqrt(max(cov[i, i], 0.0))
                sides = np.array([theta[i] - lo, hi - theta[i]]) / max(half, 1e-12)
                if lo <= self.lower[i] + 1e-6 * span or hi >= self.upper[i] - 1e-6 * span \
                        or hi - lo > 0.5 * span or np.any((sides < 1 / 3) | (sides > 3)):
                    return True
        return False

    def _profile_the_rest(self, fit, intervals, ripple):
        """Profile intervals, on the true chi-square by constrained fits, for the parameters
        that have only covariance intervals; each the union with its covariance interval (an
        edge the fits cannot place keeps the covariance's), unless the fit lies on a bound of
        its range or the curvature is singular there: the covariance's quadratic then runs
        into the excluded side (rho_s < 0) and means nothing (an overcast day fitted at
        rho_s = 0: R's covariance interval 0-1, its profile 0.83-1).  Returns the points the
        constrained fits walked [(theta, chi2)]."""
        levels, walked = ("68", "95"), []
        theta = fit.theta
        span = self.upper - self.lower
        quadratic = bool(np.all(np.isfinite(fit.curvature_inverse))
                         and np.all(theta > self.lower + 1e-9 * span)
                         and np.all(theta < self.upper - 1e-9 * span)
                         and np.linalg.cond(fit.curvature_inverse) < SINGULAR_CONDITION)
        for i, p in enumerate(self.names):
            if intervals[p]["from"] != "covariance":
                continue
            exact, _, points = profile_edges(
                fit.problem, fit.theta, fit.chi2, i,
                [unc.LEVELS[lv] * fit.delta_scale[i] + ripple for lv in levels],
                self.lower, self.upper,
                fit.curvature_inverse, rtol=0.01, iterations=PROFILE_RIDGE_ITERATIONS)
            walked += points
            for lv, e in zip(levels, exact):
                lo, hi = intervals[p][lv]
                keep_lo, keep_hi = (lo, hi) if quadratic else (np.inf, -np.inf)
                intervals[p][lv] = (min(keep_lo, e[0]) if e[0] is not None else lo,
                                    max(keep_hi, e[1]) if e[1] is not None else hi)
            intervals[p]["from"] = "profile (another parameter is poorly determined)"
        return walked

    def _model_noise_allowance(self, problem, theta, sigmas, profile, s2):
        """The chi-square the model's own Monte Carlo error may add, as the largest over the
        sigma_alpha profile's 95% region (not only at the fit: the cache's error grows with
        sigma_alpha, and the truth may lie where it is larger).  At each roughness the model
        noise of the larger of two estimators compared (near the mirror, the mirror rays'
        and the narrowest resolved lobe's); the region widens with the allowance, so it is
        found again until it stops growing."""
        def at(sigma):
            return problem.model_noise_chi2(np.r_[theta[:-1], sigma])

        def noise(sigma):
            return at(sigma) if sigma >= SIGMA_RESOLVED else max(at(sigma), at(SIGMA_RESOLVED))
        sigmas, profile = np.asarray(sigmas, dtype=float), np.asarray(profile, dtype=float)
        ripple, seen = noise(theta[-1]), {float(theta[-1])}
        for _ in range(4):
            inside = sigmas[profile <= profile.min() + unc.LEVELS["95"] * s2 + ripple]
            points = {float(v) for v in np.quantile(inside, [0, 0.25, 0.5, 0.75, 1])} - seen
            if not points:
                break
            seen |= points
            grown = max(ripple, max(noise(v) for v in points))
            if grown <= 1.05 * ripple:
                ripple = grown
                break
            ripple = grown
        return ripple

    def _warnings(self, fit):
        """What the user must know about ``fit``: loading, the method's status, a local method's
        distance from the global minimum, misfit, identifiability, the day's geometry, and the
        colour rule's ambiguity."""
        names, method, theta, chi2 = self.names, fit.method, fit.theta, fit.chi2
        res, g, intervals = fit.method_result, fit.global_result, fit.intervals
        iv95 = {p: intervals[p]["95"] for p in names}
        warnings = []
        if res.get("status") == "failed":
            warnings.append(f"{method} failed: {res['message']}")
        elif res.get("status") not in (None, "converged"):
            warnings.append(f"{method} did not converge (status {res['status']}): "
                            f"{res['message']}")
        warnings += self.obs.warnings                       # what loading the frames noticed
        if relative_scale(self.doc):
            warnings.append(self.doc["ingest"]["scale"]["meaning"])
        warnings += self._sky_warnings(fit)
        own = np.sqrt(np.maximum(np.diag(fit.covariance), 0.0))
        led = [p for i, p in enumerate(names) if fit.matrix_sd[i] > SKY_DOMINATES * own[i]]
        if led:
            warnings.append(f"{', '.join(led)}: {self._matrix_note()}; it, more than the "
                            "data, sets their intervals.")
        top = [p for i, p in enumerate(names)
               if p != "sigma_alpha" and theta[i] >= self.upper[i] - 1e-3]
        if top:
            fix = ("if its values are not radiances in W m^-2 sr^-1 (an instrument's DN), "
                   "ingest the table with --calibrate MATERIAL=REFLECTANCE or --unknown-scale"
                   if is_table(self.doc) else "check the exposure (--exposure, --calibrate or "
                   "--colorchecker at ingest)")
            warnings.append(f"{', '.join(top)} at the upper bound of 1: the data are brighter "
                            "than any such surface under the frames' light, so the bound, not "
                            f"the data, decides the fit; {fix}.")
        if method != "global" and g["chi2"] < chi2 - max(1.0, 1e-3 * chi2):
            # compare with the global minimum: explains local failures (thesis 7.2)
            warnings.insert(0, f"{method} stopped at chi2 = {chi2:.6g}, but the global search finds "
                            f"chi2 = {g['chi2']:.6g} at " + ", ".join(
                                f"{k} = {v:.4f}" for k, v in zip(names, g["theta"]))
                            + f": {method} ended in a local minimum or on a flat region of "
                            "chi-square from this start (thesis 6.3, 7.2)")
        if fit.model_error is not None:
            warnings.append(unc.model_error_warning(fit.misfit, fit.model_error))
        held = self._held_out_record(fit)
        if held.get("interval95") is not None:
            warnings.append(
                f"frames left out of the fit are predicted worse than noise and the "
                f"parameters' spread explain (held-out chi-square {held['chi2_per_value']:.3g} "
                f"per value, p = {held['p']:.2g}, {held['folds']} folds of frames): the model "
                f"misses light it was not fitted to by about {held['kappa']:.1%} of each value "
                f"(95%: {held['interval95'][0]:.1%}-{held['interval95'][1]:.1%}), which "
                "predictions (relight) include; the parameters describe these frames' "
                "light, not necessarily the surface's: they may not carry to other light, "
                "and their intervals may not hold (not reliable as the surface's own). "
                "Another model (--model auto ranks them by held-out frames) or, under a sky, "
                "its shape fitted with the materials (--sky-shape) may predict better.")
        warnings += unc.misfit(chi2, fit.problem.dof, fit.interval_scale, fit.cache_noise_chi2,
                               fit.noise_chi2, model_error=fit.model_error is not None)
        warnings += unc.identifiability(names, iv95, self.lower, self.upper, fit.rise,
                                        fit.delta_scale, fit.cache_noise_chi2)
        if np.max(fit.channel_factors) > CHANNEL_NOTE:
            R = fit.channel_correlation
            off = R[np.triu_indices(len(R), 1)]
            warnings.append(
                f"the errors of a value's R, G and B are correlated (correlation "
                f"{off.min():.2f} to {off.max():.2f} between channels, as in a JPEG, a "
                "demosaiced raw or a render's Monte Carlo noise, or where the model misses "
                "the brightness): the data tell less than as many independent values, and the "
                "intervals are widened for it, by up to "
                f"{np.sqrt(np.max(fit.channel_factors)):.2f}x.")
        warnings += geometry_warnings(
            self.geometry, float(theta[-1]), sky_shape_known=fit.sky.record is None
            or fit.sky.record.get("shape") is not None)
        worst = max(fit.model_noise_by_sigma, key=fit.model_noise_by_sigma.get)
        if fit.model_noise_by_sigma[worst] > NOISE_SHARE * fit.problem.dof:
            warnings.append(
                f"the light cache's own Monte Carlo error adds up to "
                f"{fit.model_noise_by_sigma[worst]:.3g} to chi-square (at sigma_alpha = {worst}), "
                f"over {NOISE_SHARE:.0%} of the {fit.problem.dof} degrees of freedom: the data "
                "are more precise than the model, which pulls fits toward the roughness where "
                "its error is small (intervals allow for it); use more --directions and "
                "--positions.")
        if self.model == "colour":
            other = unc.colour_rule_ambiguity(theta, iv95)
            if other is not None:
                kind = "metal" if other[1] >= METAL_THRESHOLD else "plastic"
                warnings.append(
                    f"C is grey, so the colour model's plastic and metal readings give the same "
                    f"BRDF: the {kind} reading C = {other[0]:.3f} (all channels), rho_s = "
                    f"{other[1]:.3f} fits equally well; only rho_d and the specular reflectance "
                    "are determined.")
        return warnings

    def _sky_warnings(self, fit):
        """The fitted sky's warnings (its record's) and those of parameters the sky's or the
        sun's level, more than the data, sets (:data:`~.sky_fit.SKY_DOMINATES`)."""
        sky, names = fit.sky, self.names
        if sky.record is None:
            return []
        k = sky.record
        warnings = list(k["warnings"])
        own = np.sqrt(np.maximum(np.diag(fit.covariance), 0.0))
        for i, p in enumerate(names):
            if sky.sd is not None and sky.sd[i] > SKY_DOMINATES * own[i]:
                parts = [part for part, told in ((", its change over the day",
                                                   k["terms"]),
                                                  (", its shape", k["shape"])) if told]
                warnings.append(
                    f"{p} depends on the sky: the uncertainty of the fitted sky (its level "
                    f"k = {k['k']:.3g}, 95%: {k['interval95'][0]:.3g}-"
                    f"{k['interval95'][1]:.3g}{''.join(parts)}) moves it by "
                    f"+-{unc.Z['95'] * sky.sd[i]:.3g} (95%), at least doubling its "
                    "interval, which includes that; more materials or a grey card in the "
                    "fit would narrow it.")
        level = [p for i, p in enumerate(names)
                 if fit.sun_level_sd[i] > SKY_DOMINATES * own[i]]
        if level:
            warnings.append(
                f"{', '.join(level)} scale with the sun's level, which no data tell (the "
                f"light's absolute scale trades exactly with the reflectances) and which "
                f"is known to +-{100 * sky.sun_level_sd:.0f}% (1 sd, "
                + {"given": "--sun-sd",
                   "measured": "the spec's measured direct normal irradiance",
                   "modelled": f"the modelled sun's {100 * sky.sun_sd:.0f}%"
                   + (" widened as the fitted sky departs from the spec's"
                      if sky.sun_widening else "")}.get(sky.sun_source, "--sun-sd")
                + "): that, more than the data, sets their intervals; their ratios and "
                "sigma_alpha do not depend on it. A reference of known reflectance in the "
                "scene (ingest --calibrate or --colorchecker)"
                + {"measured": "",
                   "given": " or a smaller --sun-sd where the sun's level is known better "
                            f"(a measured direct normal irradiance: {MEASURED_SUN_SD:g})"
                   }.get(sky.sun_source, " or a measured direct normal irradiance in the "
                         "spec (direct_normal_W_m2, or a dni column)")
                + " narrows them.")
        return warnings

    def _record(self, fit, warnings, start, seed, evaluations, wall, t_method):
        """The JSON-ready result of ``fit`` (the layout of ``fit_NAME.json``)."""
        names, theta, dof, sky = self.names, fit.theta, self.problem.dof, fit.sky
        res = fit.method_result
        L = self.wm.radiance(theta)
        chi2 = fit.chi2 if fit.model_error is None else self.problem.chi2(theta)
        return {
            "region": self.name, **({"pixels": self.obs.pixels.tolist()} if self.obs.rays is None
                                    else {"points": list(self.obs.pixels)}),
            "model": self.model,
            "normalisation": self.normalisation,
            "method": fit.method, "seed": seed, "start": start.tolist(),
            "parameters": dict(zip(names, theta.tolist())),
            "chi2": chi2, "dof": dof, "chi2_per_dof": chi2 / dof,
            "chi2_expected_from_noise": fit.noise_chi2[0] if fit.model_error is None
            else self.problem.noise_chi2(theta)[0],
            "model_error": self._model_error_record(fit),
            "interval_scale_s2": fit.interval_scale,
            "interval_scale_channels": dict(zip(names, fit.channel_factors.tolist())),
            "channel_correlation": fit.channel_correlation.tolist(),
            "intervals": fit.intervals,
            "readings": [unc.reading(p, theta[i], fit.intervals[p]["95"], self.lower[i],
                                     self.upper[i]) for i, p in enumerate(names)],
            "cache_error_sd": dict(zip(names, fit.cache_sd.tolist())),
            **({"calibration_error_sd": dict(zip(names, fit.calibration_sd.tolist()))}
               if np.any(fit.calibration_sd > 0) else {}),
            **({"jpeg_shared_error_sd": dict(zip(names, fit.jpeg_shared_sd.tolist())),
                "jpeg_shared_error": "the standard error each parameter takes from the JPEG "
                "frames' rounding of their blocks' means (Y, Cb, Cr), which every pixel of "
                "the region shares in a frame; added in quadrature to the intervals"}
               if np.any(fit.jpeg_shared_sd > 0) else {}),
            **({"colour_matrix_error_sd": dict(zip(names, fit.matrix_sd.tolist())),
                "colour_matrix_error": self._matrix_note()}
               if np.any(fit.matrix_sd > 0) else {}),
            **({"sky": {**sky.record, "error_sd": dict(zip(names, (
                sky.sd if sky.sd is not None else np.zeros(len(names))).tolist())),
                **({} if sky.span is None else {"undetermined_span": {
                    p: [float(lo), float(hi)] for p, lo, hi in zip(names, *sky.span)}}),
                "sun_level_sd": sky.sun_level_sd, "sun_source": sky.sun_source,
                "sun_level_error_sd": dict(zip(names, fit.sun_level_sd.tolist()))}}
               if sky.record is not None else {}),
            "cache_noise_chi2": fit.cache_noise_chi2,
            "cache_noise_chi2_by_sigma": fit.model_noise_by_sigma,
            "covariance": {"names": list(names), "matrix": fit.covariance.tolist()},
            "evaluations": evaluations, "status": res.get("status"),
            "message": res.get("message"), "warnings": warnings,
            "wall_time_s": wall, "light_cache_time_s": self.cache_time, "method_time_s": t_method,
            "light_cache": self.cache_settings, "geometry": self.geometry,
            "trace": res.get("trace", []), "schedule": res.get("schedule"),
            "truth": self.truth, "units": "reflectances unitless" + (
                " and relative (the table's scale is unknown: radiometric_scale)"
                if relative_scale(self.doc) else "") + ", sigma_alpha rms slope; chi2 in "
            "(DN/DN)^2; observed/model values in DN",
            **({"radiometric_scale": self.doc["ingest"]["scale"]} if relative_scale(self.doc)
               else {}),
            "sequence_run_id": self.run_id, "frames": [int(i) for i in self.obs.frames],
            "series": {"times": self.obs.times, "observed_DN": self.obs.y.tolist(),
                       "model_DN": self.problem.predict(L).tolist()},
            "measured_range": self._measured_range(L),
        }

    def _measured_range(self, L):
        """The fit JSON's ``measured_range``: per channel, the radiance the fit's data measured
        (:meth:`~.chi2.Problem.measured_range` at the model's ``L``: region means, a table's
        values on their own), against which relight flags predictions that rest on the model
        alone."""
        channels = "Y" if self.obs.luminance else "RGB"
        ranges = self.problem.measured_range(L, means=self.obs.rays is None)
        return {"unit": "W m^-2 sr^-1",
                "meaning": "from the least " + ("region mean over the fitted frames"
                                                 if self.obs.rays is None else "value")
                           + f" that the data measured (none of its values at the top code, "
                           f"its standard error at most {MEASURED_SE:g} of it) to the greatest "
                           "value below the top code; null: none. A prediction beyond this "
                           "rests on the model alone",
                "by_channel": dict(zip(channels, ranges))}

    def _model_error_record(self, fit):
        """The fit JSON's ``model_error``: kappa (0 where chi-square is within what noise
        explains), what it means, and with a fitted kappa its 95% interval and the
        chi-square with it (the fit's, whose intervals include the model's error)."""
        me, test = fit.model_error, fit.misfit
        form = ("each value's variance is its noise's plus (kappa x the value)^2 (a clipped "
                "value's: the model's); kappa by restricted maximum likelihood with the "
                f"parameters, where chi-square exceeds what noise explains (p < {unc.MISFIT_P:g})"
                "; a prediction's band adds held_out.kappa x the predicted value, the error "
                "with which frames left out of the fit are predicted")
        if me is None:
            return {"kappa": 0.0, "form": form, "meaning": (
                "not fitted: chi-square is within what noise explains (p = "
                f"{test.p:.2g}), so the model reproduces the data to their noise"
                if not test.significant else "fitted as 0: the likelihood is largest without "
                "a model error"), "held_out": self._held_out_record(fit)}
        return {"kappa": me.kappa, "interval95": list(me.interval95), "meaning": me.meaning,
                "form": form, "chi2": fit.chi2, "chi2_per_dof": fit.chi2 / fit.problem.dof,
                "values": me.values, **{k: fit.model_error_rounds[k]
                                        for k in ("rounds", "settled")},
                "held_out": self._held_out_record(fit)}

    @staticmethod
    def _held_out_record(fit):
        """The fit JSON's ``model_error.held_out``: the relative error with which the fit
        predicts frames it was not fitted to (:func:`~.selection.held_out_error`), the
        in-sample model error's and any beyond it together; what predictions add."""
        held, kappa = fit.held_out, 0.0 if fit.model_error is None else fit.model_error.kappa
        if held is None:
            return {"kappa": kappa, "meaning": "not tested: fewer than "
                    f"{HELD_OUT_FRAMES} frames; predictions take the in-sample kappa"}
        out = {**held, "kappa": float(np.hypot(kappa, held["kappa"]))}
        if "interval95" in held:
            out["interval95"] = [float(np.hypot(kappa, k)) for k in held["interval95"]]
            out["meaning"] = (f"each held-out value missed by about {out['kappa']:.2g} of itself "
                              "beyond its noise and the prediction's spread: predictions "
                              "(relight) add this kappa x the value, averaged over its "
                              "interval")
        elif not held["values"]:
            out["meaning"] = ("not tested: every fold either moved the parameters out of "
                              "their 95% intervals or held too few values (folds_outside, "
                              "folds_too_small); predictions take the in-sample kappa")
        else:
            out["meaning"] = ("held-out frames are predicted within their noise and the "
                              "prediction's spread" + (" and the in-sample model error"
                                                       if kappa else ""))
        return out


def trace_sessions(sessions, light):
    """Trace the light ``light`` (a :class:`~.light.LightPlan`, or {region: plan}) of
    ``sessions`` (FitSessions of one sequence): in one pass over all the points of the sessions
    that share normalisation, frames, kind of point (pixels or rays), sky plan, whether that
    plan's anchors pay (as each region alone would take them) and light, each point under its
    own region's material: each frame's kernels are traced once instead of once a region; each
    session takes its rows and an equal share of the time."""
    groups = {}
    for s in sessions:
        plan = light[s.name] if isinstance(light, dict) else light
        c, cam = s.cache_settings, s.doc["camera"]
        anchored = s.obs.rays is None and anchors_pay(s.obs.pixels,
                                                      SKY_PLANS[c["sky_plan"]].spacing,
                                                      cam["width"], cam["height"])
        key = (s.normalisation, tuple(s.obs.frames), s.obs.rays is None, c["sky_plan"],
               anchored, plan)
        groups.setdefault(key, []).append(s)
    for key, group in groups.items():
        t0 = time.perf_counter()
        if group[0].obs.rays is None:
            at = np.concatenate([s.obs.pixels for s in group])
        else:
            at = PointRays(*(np.concatenate([getattr(s.obs.rays, k) for s in group])
                             for k in ("origins", "directions")))
        parts, cov = group[0]._trace(at, np.repeat([s.name for s in group],
                                                   [len(s.obs.pixels) for s in group]), key[-1])
        share = (time.perf_counter() - t0) / len(group)
        start = 0
        for s in group:
            n = len(s.obs.pixels)
            s.cache_settings["blocks"] = group[0].cache_settings["blocks"]
            rows = slice(start, start + n)
            s.take_parts([t.subset(rows) for t in parts],
                         None if cov is None else cov.subset(rows), key[-1], share)
            start += n


def fit_region(manifest_path, name, pixels, **options):
    """Fit one material region (see :class:`FitSession`, ``options`` as
    :func:`fit_regions`'); returns a JSON-ready result dict."""
    return next(fit_regions(manifest_path, [(name, pixels)], **options))


def fit_regions(manifest_path, regions, model="two", method="global", seed=0, start=None,
                method_options=None, log=print, light=LightOptions(), **options):
    """Fit several regions of one sequence (``regions`` [(name, pixels)]), their light traced
    together (:func:`trace_sessions`); yields each region's result dict in turn.
    ``light``: the :class:`~.light.LightOptions` (or a :class:`~.light.LightPlan` already
    resolved for the sequence): the sky None chooses (:func:`~.sky_fit.default_sky`); 'spec'
    takes the spec's light as it is; 'fit' fits the sky's level against the sun's with the
    materials, one for all regions (:func:`~.sky_fit.fit_sky_scale`), and 'prior' the same
    with the level's prior (:data:`~skyfit_mi.physics.sky.SKY_LEVEL_SD`); both count the sun's
    own level, known to a relative ``sun_sd`` (None: :func:`~.sky_fit.default_sun_sd`), in
    the reflectances' intervals (:func:`~.sky_fit.light_level_sd`; not given, a modelled sun's
    is widened where the fitted sky departs from the spec's,
    :data:`~skyfit_mi.physics.sky.SUN_SKY_COUPLING`, a measured one's is not); ``terms`` > 1
    lets the sky's level change smoothly over the day, 1 holds it (None:
    :func:`~.sky_fit.default_terms` of the frames), and ``shape`` fits the sky's shape too (a
    CIE sky's gradation and indicatrix, a Perez sky's clearness and brightness).  ``options``
    as :class:`FitSession`'s (normalisation, cache, frames, variant)."""
    sessions = {name: FitSession(manifest_path, name, px, model=model, seed=seed, trace=False,
                                 **options)
                for name, px in regions}
    yield from fit_sessions(sessions, method, seed, start, method_options, log, light)


def resolve_light(sessions, light, log=print):
    """The :class:`~.light.LightPlan` of ``light`` (options, or a plan already resolved) on
    the sequence of ``sessions`` (its first's manifest, skies and frames)."""
    if isinstance(light, LightPlan):
        return light
    first = next(iter(sessions.values()))
    return light.resolve(first.doc, first.skies, len(first.obs.frames), log)


def fit_sessions(sessions, method="global", seed=0, start=None, method_options=None, log=print,
                 light=LightOptions()):
    """Trace and fit ``sessions`` ({region: FitSession} of one sequence, not yet traced; each
    its own model and lobe) under ``light`` as :func:`fit_regions` describes (the sky's level
    fitted once for all of them); yields each region's result dict in turn, in the order of
    ``sessions``."""
    sky = prepare_sessions(sessions, light, seed, log)
    for name in list(sessions):
        yield sessions.pop(name).run(method, start, seed, method_options, log,
                                     sky.shares.get(name))


def prepare_sessions(sessions, light=LightOptions(), seed=0, log=print):
    """Trace the light of ``sessions`` ({region: FitSession}, not yet traced) as ``light``
    resolves (:meth:`~.light.LightOptions.resolve`) and fit the sky's level with them where it
    is not the spec's, ready to run (:func:`fit_sessions`); returns the
    :class:`~.sky_fit.SkyFit` (no record nor shares where the sky is the spec's)."""
    plan = resolve_light(sessions, light, log)
    trace_sessions(list(sessions.values()), plan)
    if not plan.split:
        return SkyFit(None)
    return fit_sky_scale(list(sessions.values()), plan, seed, log)
