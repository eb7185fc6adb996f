"""Fit Ward parameters to a region of a rendered or photographed sequence (thesis ch. 6-7).

:func:`fit_region` loads the region's values and sigmas, caches the light at its pixels (one
Mitsuba pass), builds chi-square (eq. 6.2) and runs the chosen method; it returns parameters,
68%/95% intervals and warnings (:mod:`~.report` writes them).
"""

import functools
import time
import weakref
from dataclasses import dataclass, replace

import numpy as np

from . import uncertainty as unc
from .draws import draws_scale, interval_covariance, likelihood_draws
from .chi2 import LuminanceModel, Problem, load_observations, load_table_observations
from .fit_record import fit_record
from .fit_warnings import fit_warnings
from .geometry import highlight_geometry
from .held_out import held_out_error
from .intervals import (calibration_rows, fit_intervals, frame_calibration_sd, jpeg_shared_sd,
                        matrix_rows)
from .tone import region_tone, tone_rows
from .light import SPEC_LIGHT, LightOptions, LightParts, LightPlan
from .methods import METHODS, global_search
from .methods.global_search import SIGMA_GRID
from .methods.levenberg_marquardt import levenberg_marquardt
from .pose import pose_share, pose_through_sky
from ..errors import SkyfitError, check_choice
from .sky_fit import (SkyFit, SkyShare, fit_sky_scale, fitted_mix, light_level_at, photographed,
                      reference_light_factor, reference_slope, shape_variants, share_at,
                      sky_level_at)
from ..render import setup
from ..render.basis_table import (TableModel, available_memory, block_budget, memory_estimate,
                                  shared_budget, trace_basis)
from ..render.fit_model import (BY_COUNT, PARAMETERS, bounds, check_fit_normalisation,
                                check_start, other_readings)
from ..render.scene import POSE_ANGLES, camera_at, load_xml, pose_sd, turn_camera, view_centre
from ..render.light_cache import (CACHE_SHARE, DIRECTIONS, POINT_POSITIONS, POSITIONS,
                                  SKY_PLANS, CacheOptions, PointRays, anchors_pay,
                                  build_light_cache)
from ..pipeline.manifest import frame_sky, is_table, load_manifest
from ..pipeline.observation_table import relative_scale
from ..physics.colour import SRGB_LUMINANCE
from ..physics.sky_departure import departure_parts
from ..physics.turbid_sky import level_factors
from ..physics.ward import METAL_THRESHOLD


#: Largest spread of C's channels for which the colour rule's two readings count as one BRDF
#: (:meth:`FitSession._same_reading`).
GREY_SPREAD = 0.02


#: Roughness values at which the model's own noise is reported [rms slope].
NOISE_SIGMAS = (0.01, 0.02, 0.05, 0.1, 0.2, 0.35, 0.5)
#: Largest growth of an automatically sized cache's positions, and the time budget of a grown
#: cache's trace [s] (estimated from the first trace's).
CACHE_GROWTH_MAX, CACHE_TIME_BUDGET = 32, 20.0
#: Most rounds of the model error's fit, and the relative change of kappa that stops them
#: (:meth:`FitSession._fit_model_error`).
MODEL_ERROR_ROUNDS, MODEL_ERROR_RTOL = 8, 0.02


@dataclass
class FitState:
    """A region's fit while its intervals and warnings are worked out (:meth:`FitSession.run`).

    method, theta, chi2 : the method, its minimum and ``problem``'s chi-square there
    problem : the chi-square minimised, sigmas widened by the model's error where fitted
    model_error, model_error_rounds, misfit : the fitted :class:`~.uncertainty.ModelError` (None
        without significant misfit), its rounds, and the :class:`~.uncertainty.MisfitTest`
    interval_scale : s^2 (1 unless the model still misses the data)
    curvature_inverse : (J^T J)^-1 at the minimum
    channel_factors, channel_correlation : by :func:`~.uncertainty.channel_factors`
    covariance : the parameters' covariance (curvature, scale and channel factors)
    method_result, global_result : the method's and the global search's result dicts
    model_noise_by_sigma, noise_chi2 : the cache's own chi-square by roughness; the mean and
        variance of noise's chi-square
    intervals, rise, cache_noise_chi2, cache_sd, sun_level_rows : by
        :func:`~.intervals.fit_intervals` (sun_level_rows: signed rows, as calibration_rows)
    data_intervals : (n, 2) the 95% intervals of the data's chi-square alone, before the errors
        the sequence shares (light, calibration, pose, ...) widen them: the draws' first proposal
    search_open : {parameter: [(end, x)]} ends of 95% intervals taken to the bound where the
        profile's fits beyond x failed (:func:`~.intervals.fit_intervals`)
    jpeg_shared_sd : the JPEG blocks' rounding's standard errors (:mod:`~.intervals`)
    calibration_rows, matrix_rows : signed rows (E, n), one per independent error of the
        calibration (a camera's own tone curve's among them) and the colour matrix
        (:mod:`~.intervals`); their standard errors calibration_sd, matrix_sd
    tone_sd : the standard errors (n,) of a camera's tone curve's share: of calibration_rows, or
        of the fitted light's where its fit took the curve (:attr:`~.sky_fit.SkyShare.tone_sd`)
    sky, pose : the light's and the camera pose's shares (:class:`~.sky_fit.SkyShare`,
        :class:`~.pose.PoseShare`)
    draws : the likelihood's draws (:class:`~.draws.Draws`)
    held_out : :func:`~.held_out.held_out_error`'s result, None with too few frames
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
    calibration_rows: np.ndarray = None
    sun_level_rows: np.ndarray = None
    jpeg_shared_sd: np.ndarray = None
    matrix_rows: np.ndarray = None
    tone_sd: np.ndarray = None
    pose: object = None
    held_out: dict = None
    draws: object = None
    data_intervals: np.ndarray = None
    search_open: dict = None

    @property
    def calibration_sd(self):
        """The calibration's standard errors (n,)."""
        return unc.rows_sd(self.calibration_rows)

    @property
    def sun_level_sd(self):
        """The sun level's standard errors (n,)."""
        return unc.rows_sd(self.sun_level_rows)

    @property
    def matrix_sd(self):
        """The colour matrix's standard errors (n,)."""
        return unc.rows_sd(self.matrix_rows)

    @property
    def delta_scale(self):
        """Each parameter's Delta chi^2 scale: s^2 times its channel factor."""
        return self.interval_scale * self.channel_factors


@dataclass(frozen=True)
class FitCache:
    """The light cache a fit traces (recorded in the fit JSON's ``light_cache``).

    positions, directions, seed : samples over each pixel's area (None: sized from the data,
        :meth:`FitSession.cache_growth`), light directions at each, and their seed
    plan : a name of :data:`~skyfit_mi.render.light_cache.SKY_PLANS`
    pose_sd_deg : the camera pose's 1-sd [deg] (:mod:`~.pose`; None: the manifest's, or 0)
    """

    positions: int = None
    directions: int = DIRECTIONS
    seed: int = 0
    plan: str = "fit"
    pose_sd_deg: object = None


class FitSession:
    """One region of one sequence, ready to fit: observations, light cache, models, chi-square.

    Building it traces the light at the region's pixels once (or :func:`trace_sessions` for
    several regions); :meth:`run` then fits by any method and start without tracing again.

    Parameters
    ----------
    manifest_path : folder written by ``skyfit render`` (or its manifest.json)
    name : the region's material id in the manifest's scene
    pixels : (P, 2) pixel (x, y) coordinates on that material
    model : 'two', 'achromatic', 'colour' (or 2, 3, 5)
    normalisation : Ward normalisation of the model ('ward' = thesis eq. 3.19)
    cache : the light cache to trace (:class:`FitCache`)
    min_frames : rendered frames the sequence must hold (1 to predict a single frame)
    frames : manifest frame indices to use (None: every rendered frame)
    variant : the Mitsuba variant to fit with (default the sequence's), e.g. 'cuda_ad_rgb'
    light : the :class:`~.light.LightPlan` traced now (default the spec's light; None: the
        caller traces, :func:`trace_sessions`)
    """

    def __init__(self, manifest_path, name, pixels, model="two", normalisation="ward",
                 cache=FitCache(), frames=None, min_frames=2, variant=None, light=SPEC_LIGHT):
        model = BY_COUNT.get(model, model)
        check_choice("model", model, tuple(PARAMETERS))
        check_fit_normalisation(normalisation)          # before the light is traced
        t0 = time.perf_counter()
        doc, root = load_manifest(manifest_path)
        self.run_id = doc.get("run_id")
        self.pose_sd = pose_sd(doc["camera"].get("pose_sd_deg") if cache.pose_sd_deg is None
                               else cache.pose_sd_deg)
        if is_table(doc):
            self.obs = load_table_observations(manifest_path, name, pixels, frames, min_frames)
            if self.obs.luminance and model == "colour":
                raise SkyfitError(f"region {name!r} is measured as luminance, which cannot tell "
                                  "colour; fit it with --model 2 or 3.")
            if relative_scale(doc) and model == "two":
                raise SkyfitError("the table's scale is unknown (ingest --unknown-scale), and the "
                                  "2-parameter model's surface is white (rho_d + rho_s = 1), "
                                  "which needs the scale; fit it with --model 3"
                                  + ("." if self.obs.luminance else " or 5."))
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
        # only rendered frames' materials are the truth; an ingested spec's are placeholders
        self.truth = None if photographed(doc) else mats[name]
        given = cache.positions is not None
        self.cache_settings = {"positions": int(cache.positions) if given
                               else self.first_positions,
                               "directions": int(cache.directions), "seed": cache.seed,
                               "sized": "given" if given else "from the data",
                               "sky_plan": check_choice("sky plan", cache.plan, tuple(SKY_PLANS))}
        self._variant = variant or doc["render"]["variant"]
        setup(self._variant)
        # the light traced (LightPlan), its parts (LightParts) and their mix (set_sky)
        self.light, self.sky_scale, self.parts = light or SPEC_LIGHT, 1.0, None
        self.sky_shape_mix = None
        self.light_level = 1.0                      # the whole light's, by frame (set_sky)
        self.tone = region_tone(self)               # a camera's tone curve's moves
        self.tone_weights = None                    # its weights, in a fit of the light (set_sky)
        self.light_factor = None                    # per channel, by a reference (reference_factor)
        self._turned = {}                           # the light with the camera turned
        self.cache_time = time.perf_counter() - t0
        if light is not None:
            self.trace_light(light)

    @classmethod
    def from_fit(cls, result, manifest_path, pixels=None, **options):
        """The session of the region a fit ``result`` (a checked fit JSON) measured, in its model
        and normalisation, on ``manifest_path`` (its own sequence or a target); ``pixels``
        default to the fit's; ``options`` as the constructor's (``light=None`` leaves the trace
        to the caller; else the fit's light, :meth:`fitted_light`)."""
        if pixels is None:                 # a fit of an observation table lists its points
            pixels = result["points"] if "points" in result else result.get("pixels")
            if "points" not in result and not (isinstance(pixels, list) and pixels):
                raise SkyfitError(f"the fit of region {result['region']!r} lists no pixels; "
                                  "give the fit_NAME.json that `skyfit fit` wrote.")
        trace = options.pop("light", True) is not None
        s = cls(manifest_path, result["region"], pixels, model=result["model"],
                normalisation=result.get("normalisation", "ward"), light=None, **options)
        if trace:
            s.trace_as_fitted(result)
        return s

    def fitted_light(self, result):
        """The :class:`~.light.LightPlan` of a fit ``result`` on this sequence."""
        sky = result.get("sky")
        if sky is None or result.get("sequence_run_id") != self.run_id:
            return SPEC_LIGHT
        return LightPlan("fit", shape=sky.get("shape") is not None,
                         departure=sky.get("departure") is not None)

    def trace_as_fitted(self, result):
        """Trace the light as ``result`` saw it and set its fitted sky (:meth:`use_fitted_sky`)."""
        self.trace_light(self.fitted_light(result))
        self.use_fitted_sky(result)

    def use_fitted_sky(self, result):
        """Light the sequence (traced with :meth:`fitted_light`) at ``result``'s fitted sky."""
        sky = result.get("sky")
        if self.light.split:
            self.light_factor = reference_light_factor(sky)
            k = sky_level_at(sky, self.obs.times)
            self.set_sky(float(k[0]) if np.ptp(k) == 0 else k, fitted_mix(sky),
                         light_level_at(sky, self.obs.times))

    def trace_light(self, light=None):
        """(Re)trace ``light`` (None: the last) and rebuild everything from its table."""
        trace_sessions([self], self.light if light is None else light)

    def take_parts(self, parts, light, seconds, blocks):
        """Fit on ``light`` traced as ``parts`` (this session's rows)."""
        self.light, self._turned = light, {}
        self.cache_time += seconds
        self.cache_settings["blocks"] = blocks
        self._use_parts(parts)

    def _trace(self, at, bsdf_id, light):
        """(:class:`~.light.LightParts`, blocks) of the light at ``at`` (pixels or rays) on
        material(s) ``bsdf_id``, traced in blocks of bounded memory; a split ``light``'s sun on
        its own samples, the rest with its variants on shared ones. Raises SkyfitError where the
        estimate exceeds the available memory."""
        c = self.cache_settings
        # the light's parts by name, each a list of the frames' skies
        named = self._sky_parts(light) if light.split else {"light": self.skies}
        lights = list(named.values())
        # a table per part, and the rest's group's covariances about one more
        need = (len(lights) + (len(lights) > 2)) * memory_estimate(
            len(at), len(self.skies), c["positions"], c["directions"])
        have = available_memory()
        if have is not None and need > have:
            raise SkyfitError(
                f"fitting {len(at)} points in {len(self.skies)} frames needs up to "
                f"{need / 2**30:.1f} GB, but this machine has {have / 2**30:.1f} GB available; "
                "fit fewer pixels (--max-pixels) or frames (--frames), or a region at a time.")
        options = CacheOptions(**self._cache_options())
        if not light.split:
            tables, _, blocks = trace_basis(self.scene, self.params, lights, at, bsdf_id, options,
                                            model=self.model)
            return LightParts(tuple(named), tuple(tables)), blocks
        seeds = np.random.SeedSequence(options.seed).generate_state(2).tolist()
        # the sun's part in the blocks of the rest's group (shared_budget), whose series mix
        budget = block_budget(len(at), len(self.skies), c["positions"])
        parts = []
        for group, seed, b in zip((lights[:1], lights[1:]), seeds,
                                  (shared_budget(budget, len(lights[1:])), budget)):
            tables, cov, blocks = trace_basis(self.scene, self.params, group, at, bsdf_id,
                                              replace(options, seed=int(seed)), b, self.model)
            parts += tables
        # the rest's group's covariances' pairs as indices into all the parts (the sun first)
        cov = None if cov is None else replace(cov, pairs=[(j + 1, k + 1) for j, k in cov.pairs])
        return LightParts(tuple(named), tuple(parts), cov), blocks

    def _sky_parts(self, light):
        """{part name: the frames' skies}: sun, rest, shape variants and departure parts."""
        sun, rest = zip(*(sky.split() for sky in self.skies))
        lights = {"sun": list(sun), "sky": list(rest)}
        if light.shape:
            for j, (_, first) in enumerate(self._variants[0]):
                lights[f"shape:{first.info['of']}"] = [v[j][1] for v in self._variants]
        if light.departure:
            parts = [departure_parts(sky) for sky in self.skies]
            for j, (name, _) in enumerate(parts[0]):
                lights[f"departure:{name}"] = [p[j][1] for p in parts]
        return lights

    @functools.cached_property
    def _variants(self):
        """Each frame's shape variants (:func:`~.sky_fit.shape_variants`), made once."""
        return shape_variants(self.skies)

    def light_levels(self, mix):
        """(sun, sky) factors (T,) the shape's ``mix`` brings: a turbid sky's turbidity sets both
        (:func:`~skyfit_mi.physics.turbid_sky.level_factors`); 1 otherwise."""
        if mix is None or not (self.parts and self.parts.shapes) \
                or not all(s.info.get("kind") == "turbid" for s in self.skies):
            return 1.0, 1.0
        return level_factors([s.info for s in self.skies],
                             [v[0][1].info for v in self._variants], mix[0])

    def _cache_options(self):
        """build_light_cache's options at ``cache_settings``."""
        c = self.cache_settings
        return dict(positions=c["positions"], directions=c["directions"], seed=c["seed"],
                    max_depth=max(1, int(self.doc["render"]["max_depth"]) - 1),
                    normalisation=self.normalisation, plan=c["sky_plan"])

    @property
    def first_positions(self):
        """An auto-sized cache's first positions: POSITIONS (pixels) or POINT_POSITIONS (points)."""
        return POSITIONS if self.obs.rays is None else POINT_POSITIONS

    @property
    def scene(self):
        """The sequence's Mitsuba scene, loaded when first needed and shared by the sessions of
        one sequence (:func:`_loaded_scene`)."""
        return self._loaded.scene

    @property
    def params(self):
        """The scene's parameters (``mi.traverse``)."""
        return self._loaded.params

    @functools.cached_property
    def _loaded(self):
        return _loaded_scene(self._variant, self.doc["scene"]["xml"])

    def light_cache(self):
        """The region's raw :class:`~skyfit_mi.render.light_cache.LightCache` (for diagnostics)."""
        return build_light_cache(self.scene, self.params, self.skies,
                                 self.obs.pixels if self.obs.rays is None else self.obs.rays,
                                 self.name, **self._cache_options())

    def _use_parts(self, parts):
        """Take the light's ``parts`` and make the models and chi-square on their mix at the sky
        as set (:meth:`set_sky`)."""
        changed, self.parts = parts is not self.parts, parts
        table = self._mixed(parts)
        if not table.hit.any():
            raise SkyfitError(f"none of the region's pixels shows material {self.name!r}; check "
                              "the region.")
        if changed:                         # the sun's geometry: the same at any weights
            self.geometry = highlight_geometry(np.where(table.hit[..., None, None],
                                                        table.sun_cos, np.nan))
        self.table = table
        self.wm = self.model_on(table)
        obs = self.obs
        if self.tone is not None and self.tone_weights is not None:   # the curve moved
            obs = replace(obs, gain=obs.gain * np.exp(self.tone @ self.tone_weights))
        self.problem = Problem(obs, self.wm, valid=table.hit)
        self._halves = self._bases = None

    def _mixed(self, parts):
        """The table of the light's ``parts`` at the sky's level and shape."""
        sun, sky = (self.light_level * v for v in self.light_levels(self.sky_shape_mix))
        return parts.table(self.sky_scale * sky, self.sky_shape_mix, sun, self.light_factor)

    @property
    def pose_angles(self):
        """The pose's angles (of POSE_ANGLES) with sd > 0; none for a table (world rays)."""
        if self.obs.rays is not None:
            return []
        return [k for k in POSE_ANGLES if self.pose_sd[k] > 0]

    def table_turned(self, angle):
        """The light's table with the camera turned by the pose's sd in ``angle``, traced once
        on the fit's samples so the difference is the turn's (:func:`trace_turned`)."""
        if (angle, self.pose_sd[angle]) not in self._turned:
            trace_turned([self])
        return self._mixed(self._turned[angle, self.pose_sd[angle]][0])

    @property
    def turn_time(self):
        """The wall time of the traces with the camera turned [s]."""
        return sum(seconds for _, seconds in self._turned.values())

    def set_sky(self, k, mix=None, level=None, tone=None):
        """Scale the split light's sky (all but the sun) by ``k`` (scalar or per frame), mix
        ``mix[j]`` of shape variant j with (1 - sum(mix)) of its own pattern, scale the whole
        light by ``level`` (per frame; None: 1), read the values through a camera's tone curve
        at the weights ``tone`` of its prior's errors (:func:`~.tone.region_tone`; None:
        as ingested), and rebuild the models and chi-square. Raises ValueError on a session not
        traced with the needed parts."""
        if self.parts is None or "sky" not in self.parts.names \
                or len(self.parts.variants) < (0 if mix is None else len(mix)):
            raise ValueError("the sky's level needs a session traced with a fitted sky's light, "
                             "its shape one traced with the sky's shape variants")
        self.sky_scale = float(k) if np.ndim(k) == 0 else np.asarray(k, dtype=float)
        self.sky_shape_mix = None if mix is None else np.asarray(mix, dtype=float)
        self.light_level = 1.0 if level is None else np.asarray(level, dtype=float)
        self.tone_weights = None if tone is None else np.asarray(tone, dtype=float)
        self._use_parts(self.parts)

    def take_light(self, other):
        """Fit on the light traced by ``other`` (same region, sequence and lobe; any model)."""
        self.cache_settings = dict(other.cache_settings)
        self.take_parts(other.parts, other.light, other.cache_time,
                        other.cache_settings.get("blocks"))

    def model_on(self, table, part=0):
        """The radiance model on ``table`` (whole, or half ``part`` 1, 2), luminance if observed."""
        wm = TableModel(table, self.model, part)
        return LuminanceModel(wm) if self.obs.luminance else wm

    def cache_growth(self, noise_by_sigma, s2=1.0):
        """The power-of-two growth of an auto-sized cache that brings the largest model noise
        (``noise_by_sigma``; variance ~ 1 / positions) under CACHE_SHARE of dof times ``s2``,
        within CACHE_GROWTH_MAX and CACHE_TIME_BUDGET; 1 for a cache of given size."""
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
        """Standard error each parameter owes to the light cache's Monte Carlo samples: the fit
        repeated on two independent half caches differs by twice a half's error, so the whole's
        is |theta_A - theta_B| / 2 (both on theta's side of the colour rule). Rough (one degree
        of freedom), but it keeps intervals honest for precise data."""
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
        # a half on the other reading of a grey C (same BRDF) is read on theta's side: that
        # ambiguity is warned of, not cache error
        fits = [self._same_reading(p, np.asarray(f, dtype=float), theta)
                for p, f in zip(self._halves, fits)]
        return np.abs(fits[0] - fits[1]) / 2

    def _same_reading(self, problem, fit, theta):
        """A half cache's ``fit`` on ``theta``'s side of the colour rule: for a grey C (within
        GREY_SPREAD) across it, polished from the fit's twin reading; else the fit itself."""
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
        """The global search's lazy basis for the whole cache and each half, made once."""
        if self._bases is None:
            self._bases = self.wm.lobes(SIGMA_GRID, halves=True)
        return self._bases

    def random_start(self, rng):
        return self.lower + rng.random(len(self.lower)) * (self.upper - self.lower)

    def run(self, method="global", start=None, seed=0, method_options=None, log=print,
            sky=None):
        """Fit by ``method`` from ``start`` (None: seeded random within bounds); returns the
        result dict. ``sky``: the light's :class:`~.sky_fit.SkyShare` (None: none). Stages: the
        minimum (the cache grown if needed), the model's error, the covariance, the global
        minimum, intervals, warnings and the record."""
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
                       SkyShare() if sky is None else share_at(self, sky, theta))
        fit.jpeg_shared_sd = jpeg_shared_sd(self, J_all, measured, problem.obs.sigma, curv_inv)
        # a camera's own tone curve (tone_rows) is the calibration's too: its rows among them
        tone = tone_rows(self, J_all, problem, measured, theta, curv_inv)
        fit.tone_sd = unc.rows_sd(tone) if len(tone) else fit.sky.tone_sd
        fit.calibration_rows = np.concatenate(
            [calibration_rows(self, J_all, problem, measured, theta, curv_inv), tone])
        fit.matrix_rows = matrix_rows(self, J_all, problem, measured, theta, curv_inv)
        fit.pose = pose_share(self, fit, J_all)
        fit_intervals(self, fit)
        iv95 = np.array([fit.intervals[p]["95"] for p in self.names])
        fit.draws = likelihood_draws(
            problem, theta, chi2, draws_scale(s2, f2, fit.cache_noise_chi2),
            interval_covariance(fit.data_intervals, fit.covariance), (self.lower, self.upper),
            seed, local=fit.covariance, centre=fit.data_intervals.mean(axis=1))
        fit.held_out = held_out_error(
            problem, theta, self.lower, self.upper,
            within=lambda th: bool(np.all((th >= iv95[:, 0]) & (th <= iv95[:, 1]))),
            frame_sd=frame_calibration_sd(self))
        warnings = fit_warnings(self, fit)
        wall = time.perf_counter() - t0 + self.cache_time
        out = fit_record(self, fit, warnings, start, seed, evaluations, wall, t_method)
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
        """Fit the model's error where ``misfit`` is significant: kappa from the residuals, then
        the parameters with sigmas widened by it, alternately until kappa settles to
        MODEL_ERROR_RTOL (each step lowers the same restricted likelihood). Returns (result,
        chi-square minimised, :class:`~.uncertainty.ModelError` or None, {rounds, settled,
        evaluations}); unchanged without significant misfit or at kappa 0."""
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

    def _model_noise_by_sigma(self, theta, problem=None):
        """The model's own Monte Carlo share of chi-square at the fitted reflectances, by
        roughness (NOISE_SIGMAS); where sizeable it pulls fits toward where it is small."""
        problem = problem or self.problem
        return {f"{v:g}": problem.model_noise_chi2(np.r_[theta[:-1], v])
                for v in NOISE_SIGMAS}


@dataclass
class _Scene:
    """A loaded Mitsuba scene and its parameters (``mi.traverse``)."""

    scene: object
    params: object


#: The scenes live sessions hold, by (variant, scene XML): each freed with its last session.
_SCENES = weakref.WeakValueDictionary()


def _loaded_scene(variant, xml):
    """The :class:`_Scene` of a scene ``xml`` in ``variant``, shared by every live session of
    that XML: each live scene's materials join every trace's virtual calls, so each scene more
    slows every trace's kernels (`fit --model auto` with a scene for each of its six lobes: its
    ranking traces 30 -> 20 s). A trace sets the sky of each frame it traces, and the pose's
    traces put the camera back, so sessions traced one after another can share one; sessions
    traced in threads at once could not."""
    loaded = _SCENES.get((variant, xml))
    if loaded is None:
        mi = setup(variant)
        scene = load_xml(xml)
        loaded = _SCENES[variant, xml] = _Scene(scene, mi.traverse(scene))
    return loaded


def trace_sessions(sessions, light):
    """Trace ``light`` (a plan, or {region: plan}) for ``sessions`` of one sequence, one pass per
    group that can share it; each session takes its rows and an equal share of the time."""
    for plan, group in _trace_groups(sessions, light):
        t0 = time.perf_counter()
        parts, blocks = _trace_together(group, plan)
        share = (time.perf_counter() - t0) / len(group)
        for s, own in zip(group, parts):
            s.take_parts(own, plan, share, blocks)


def trace_turned(sessions):
    """Trace ``sessions``' light again with the camera turned by each pose angle's sd."""
    for plan, group in _trace_groups(sessions, {s.name: s.light for s in sessions}):
        first = group[0]
        to_world = np.asarray(first.doc["camera"]["to_world"], dtype=float)
        pivot = view_centre(first.scene) if first.pose_angles else None
        for angle in first.pose_angles:
            key = (angle, first.pose_sd[angle])
            t0 = time.perf_counter()
            with camera_at(first.scene, turn_camera(to_world, pivot, *key)):
                parts, _ = _trace_together(group, plan)
            share = (time.perf_counter() - t0) / len(group)
            for s, own in zip(group, parts):
                s._turned[key] = (own, share)


def _trace_groups(sessions, light):
    """[(plan, sessions)]: ``sessions`` grouped as :func:`trace_sessions` traces them."""
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
    return [(key[-1], group) for key, group in groups.items()]


def _trace_together(group, plan):
    """(Each session's :class:`~.light.LightParts`, blocks) of ``plan`` traced at all the points
    of ``group`` at once."""
    if group[0].obs.rays is None:
        at = np.concatenate([s.obs.pixels for s in group])
    else:
        at = PointRays(*(np.concatenate([getattr(s.obs.rays, k) for s in group])
                         for k in ("origins", "directions")))
    sizes = [len(s.obs.pixels) for s in group]
    parts, blocks = group[0]._trace(at, np.repeat([s.name for s in group], sizes), plan)
    ends = np.cumsum(sizes).tolist()
    return [parts.subset(slice(e - n, e)) for e, n in zip(ends, sizes)], blocks


def fit_region(manifest_path, name, pixels, **options):
    """Fit one material region (``options`` as :func:`fit_regions`'); returns a result dict."""
    return next(fit_regions(manifest_path, [(name, pixels)], **options))


def fit_regions(manifest_path, regions, model="two", method="global", seed=0, start=None,
                method_options=None, log=print, light=LightOptions(), **options):
    """Fit several regions of one sequence (``regions`` [(name, pixels)]), their light traced
    together; yields each region's result dict in turn.

    ``light``: :class:`~.light.LightOptions` or a resolved :class:`~.light.LightPlan` (sky
    'spec', or 'fit'/'prior': :func:`~.sky_fit.fit_sky_scale`). ``options`` as
    :class:`FitSession`'s; ``seed`` seeds the method and the light cache."""
    cache = replace(options.pop("cache", FitCache()), seed=seed)
    sessions = {name: FitSession(manifest_path, name, px, model=model, cache=cache, light=None,
                                 **options)
                for name, px in regions}
    yield from fit_sessions(sessions, method, seed, start, method_options, log, light)


def resolve_light(sessions, light, log=print):
    """The :class:`~.light.LightPlan` of ``light`` (options or a plan) on ``sessions``' sequence."""
    first = next(iter(sessions.values()))
    return light.resolve(first.doc, first.skies, len(first.obs.frames), log)


def fit_sessions(sessions, method="global", seed=0, start=None, method_options=None, log=print,
                 light=LightOptions()):
    """Trace and fit untraced ``sessions`` ({region: FitSession}) as :func:`fit_regions` does
    (one sky fit and one pose trace for all); yields each region's result dict in order."""
    sky = prepare_sessions(sessions, light, seed, log)
    day = list(sessions.values())
    trace_turned(day)                       # the pose's turns, where it has an sd
    sky = pose_through_sky(day, sky)
    reference_factor(sessions, sky, lambda s: s.run(method, start, seed, method_options,
                                                    lambda *a: None, sky.shares.get(s.name)),
                     log)
    for name in list(sessions):
        yield sessions.pop(name).run(method, start, seed, method_options, log,
                                     sky.shares.get(name))


def reference_factor(sessions, sky, fit, log=print):
    """Calibrate the fitted light again on the scene's reference (``ingest --calibrate``), since
    a fitted ``sky`` moves what it reads: where the reference is a region, it is fitted (``fit``:
    session -> result) and its radiance over a Lambertian's of its known reflectance, per
    channel, becomes a factor on every region's light; its slope in the sky's coefficients
    (:func:`~.sky_fit.reference_slope`) enters every sky share (docs/BENCHMARKS.md, "The sample
    board photographed")."""
    if sky.record is None:
        return
    first = next(iter(sessions.values()))
    refs = (((first.doc.get("ingest") or {}).get("calibration") or {}).get("references") or {})
    name = next((n for n in refs if n in sessions), None)
    if name is None:
        return
    s, rho = sessions[name], np.asarray(refs[name], dtype=float)
    if "C_r" in s.names:
        known = {"C_r": rho[0], "C_g": rho[1], "C_b": rho[2]}
    elif "R" in s.names:                    # one grey reflectance: the luminance's
        known = {"R": float(rho @ SRGB_LUMINANCE)}
    else:                                   # the white model: no reflectance to read
        return
    result = fit(s)
    theta = np.array([result["parameters"][n] for n in s.names])
    lambertian = np.array([known.get(n, 0.0 if n == "rho_s" else theta[i])
                           for i, n in enumerate(s.names)])
    factor = (np.sum(s.wm.radiance(theta), axis=(0, 1))
              / np.sum(s.wm.radiance(lambertian), axis=(0, 1)))
    light = getattr(sky.shares.get(name), "light", None)
    slope = None if light is None else reference_slope(s, light, theta, lambertian)
    if slope is not None:
        sky.shares.update({n: replace(share, reference_slope=slope)
                           for n, share in sky.shares.items()})
    sky.record["reference"] = {
        "region": name, "reflectance": rho.tolist(), "read": (rho * factor).tolist(),
        "light_factor": factor.tolist(),
        "meaning": "the fitted light calibrated again on the reference, as ingest calibrated "
                   "the frames on it under the spec's: the radiance of the reference's fit at "
                   "the fitted light over that of a Lambertian surface of its known "
                   "reflectance (read: that reflectance times it), per channel over the day, "
                   "a factor on the light of every region, so that the reference reads its "
                   "own reflectance; slope: d ln light_factor / d the sky's coefficients "
                   "(correlation.names, or log k alone; per channel), through which every "
                   "region's share of the sky's uncertainty is taken (a diffuse surface facing "
                   "as the reference does reads its reflectance against the reference's "
                   "whatever the sky)",
        "slope": None if slope is None else slope.tolist()}
    for each in sessions.values():
        each.light_factor = factor
        each._use_parts(each.parts)
    log(f"sky: the light calibrated again on {name}, which reads "
        + ", ".join(f"{v:.4g}" for v in rho * factor) + " at the fitted sky for "
        + ", ".join(f"{v:.4g}" for v in rho) + ": every region's light times "
        + ", ".join(f"{v:.4f}" for v in factor))


def prepare_sessions(sessions, light=LightOptions(), seed=0, log=print):
    """Trace ``sessions`` ({region: FitSession}) under the resolved ``light`` (those that took it
    traced already, :meth:`FitSession.take_light`, as they are) and fit the sky where it is not
    the spec's; returns the :class:`~.sky_fit.SkyFit` (empty for the spec's)."""
    plan = resolve_light(sessions, light, log)
    todo = [s for s in sessions.values() if s.parts is None or s.light is not plan]
    if todo:                                    # the fit's longest silence (a minute or more)
        log(f"tracing the light of {len(todo)} region(s), "
            f"{sum(len(s.obs.pixels) for s in todo)} "
            f"{'pixels' if todo[0].obs.rays is None else 'points'} over "
            f"{len(todo[0].obs.frames)} frames ...")
    trace_sessions(todo, plan)
    return fit_sky_scale(list(sessions.values()), plan, seed, log) if plan.split else SkyFit(None)
