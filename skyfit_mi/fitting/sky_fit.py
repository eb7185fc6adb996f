"""The sky's level fitted with the materials: one sun-to-sky scale shared by every region of a day.

A fit takes the light from the sequence's spec, whose sky is never the real one: the CIE and
Perez skies put 20-30% too much light in the sky and too little in the sun on a measured clear
day (docs/BENCHMARKS.md, "Measured light"), and the materials absorb the difference silently
("Fits under skies other than the spec's").  The thesis names joint estimation of the light as
future work (ch. 8.2).  Here the light is split into the sun's disc and the rest of the sky
(patterns, map and ground, :meth:`~skyfit_mi.physics.sky.Sky.split`), traced apart, and the
rest is scaled by a factor k shared by all regions: radiance is linear in the light, so every
k's table is the sun's plus k times the sky's (:func:`~skyfit_mi.render.basis_table.mixed`), and
no k needs a trace of its own.  k is first one level for the day, then (by default,
:data:`DEFAULT_TERMS`) a smooth curve over it: the sky's share against the sun's follows the
sun's height and the weather, which no model sky knows.

k is found by profiling: the sum over regions of each one's least chi-square (the global
search), first on a geometric grid (:data:`SCALE_GRID`), then by a parabola in log k about its
least point.  Its 95% interval is where that sum rises by 3.84 s^2 (s^2 the regions' pooled
Birge ratio).  Each region's parameters move with k; their slope at k (the Gauss-Newton response
to the residuals' change) times k's standard error is the sky's share of their error, added to the data's and the cache's (every interval
includes it), and a parameter whose interval the sky at least doubles is warned
(:data:`SKY_DOMINATES`).  With one
region the frames alone tell k, through how the sun's share of the light changes over the
day; more materials and a grey card tell it better.

Two things the data cannot tell well are stated as priors:

* the sky's level against the sun's (``fit --sky prior``, the default for photographs under the
  sun): log k ~ N(0, sd^2) with sd :data:`~skyfit_mi.physics.sky.SKY_LEVEL_SD`, whose penalty
  (log k / sd)^2 joins the regions' chi-square, so that the profile is the posterior's and k
  stays near the spec's where the data alone would leave it open;
* the sun's own level, with ``--sky fit`` or ``prior`` on photographs (``--sun-sd``, default
  :data:`~skyfit_mi.physics.sky.SUN_LEVEL_SD`): the light's absolute scale trades exactly
  with the reflectances (every reflectance times a fits the light times 1/a), so no data tell
  it, and each reflectance's relative error gains it in quadrature (:func:`light_level_sd`),
  the roughness none.  A reference in the scene (``ingest --calibrate``, ``--colorchecker``)
  or a relative scale (``--unknown-scale``) ties the reflectances to the data instead, and a
  measured direct normal irradiance in the spec tells it to a pyrheliometer's accuracy
  (:data:`~skyfit_mi.physics.sky.MEASURED_SUN_SD`, :func:`sun_source`).  A sequence skyfit
  rendered was lit by its spec's sun: 0 unless given.  A modelled sun's (not given) widens as
  the fitted sky departs from the spec's (:data:`~skyfit_mi.physics.sky.SUN_SKY_COUPLING`):
  air that is not the model's changes the sun's light too.  A manifest written before skies
  recorded ``sun_measured`` reads its sun as modelled until ingested again.
"""

import datetime as dt
import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import chdtrc

from . import uncertainty as unc
from ..errors import SkyfitError
from .methods.levenberg_marquardt import levenberg_marquardt
from ..pipeline.manifest import RENDERED_SOURCES
from ..physics.colour import SRGB_LUMINANCE
from ..physics import sky_shape
from ..physics.sky_departure import BASIS, PRIOR_SD as DEPARTURE_SD, conflict
from ..physics.sky import MEASURED_SUN_SD, SUN_LEVEL_SD, SUN_SKY_COUPLING
from ..physics.turbid_sky import TURBIDITY_RANGE
from .methods import global_search

#: Sky scales k searched first: a geometric grid from a quarter to four times the spec's sky.
SCALE_GRID = np.geomspace(0.25, 4.0, 9)
#: The sky's share of a parameter's standard error, against the data's own, from which the
#: fit warns that the parameter depends on the sky: sqrt(3) doubles its interval.
SKY_DOMINATES = 3 ** 0.5
#: Half the spacing in log k of the points that refine the profile's least point.
REFINE_STEP = 0.1
#: The most terms of the sky's level over the day (``fit --sky-terms``), and the frames beyond
#: the terms a curve needs at least (every term past the level is held by its prior).
MAX_TERMS, FRAMES_BEYOND_TERMS = 4, 2
#: The terms of the sky's level over the day when not told (:func:`default_terms`): the day's
#: level, its drift (P_1) and its curve (P_2), the last two under the prior :data:`DRIFT_SD`.
#: The sky's share of the light against the sun's is not the model's, nor constant: it moves
#: with the sun's height (the air the sun's light crosses: in Ineichen and Perez's clear-sky
#: model the slope of log(DHI / DNI) in log air mass ranges from -0.4 to +0.17 over Linke
#: turbidities 2.5-7, tests/test_sky_fit.py) and with the weather, and a clear sky's change
#: with the sun's height is about even about noon (P_2).  One level for the day let a sky
#: other than the spec's bend the roughness instead: a disc under a Perez sky of clearness 4,
#: its sky-to-sun ratio 1.2-2.0 times the CIE clear sky's over the day, read sigma_alpha 0.092
#: (0.086-0.097) for 0.08 with no warning (docs/BENCHMARKS.md, "the sky test set").
DEFAULT_TERMS = 3
#: The terms of the whole light's level over the day beyond its mean (Legendre P_1, P_2 in
#: time, each under the prior :data:`DRIFT_SD`) fitted with the sky where the frames keep their
#: cameras' relative exposures and the reference saw the light drift (:func:`default_level_terms`).
#: The sun's light crosses more air
#: as it sinks, and how much of it the air takes is not the model's: under a turbid sky (T 5)
#: the board's grey card drifted 4.5% over the day against the spec's CIE clear light, and the
#: sky's level alone, against the sun, could follow that only by bending the sky's share that
#: each material sees otherwise (docs/BENCHMARKS.md, "The sample board photographed").  Its
#: mean is the exposure's, which the scene's reference sets.
LEVEL_TERMS = 2
#: The most frames whose sky level the log lists one by one (more: its ends and range).
CURVE_LISTED = 8
#: The prior's standard deviation of each term of log k beyond the day's level (Legendre
#: polynomials in time over the fitted frames, :func:`time_basis`): its change between the
#: day's middle and its ends.  Passing haze and cloud change the sky's share of the light by
#: tens of percent within hours; 0.35 is the level's own prior (:data:`SKY_LEVEL_SD`).
DRIFT_SD = 0.35
#: The prior's standard deviation of the mix of each of the sky's shape variants (``fit
#: --sky-shape``, :func:`~skyfit_mi.physics.sky_shape.shape_variants`): 1 is one CIE group of
#: gradation or indicatrix, one Perez clearness bin, or one step of the Perez brightness
#: (:data:`~skyfit_mi.physics.perez.BRIGHTNESS_STEP`, itself one sd of the sky's level).  The
#: shape fitted to the shared measured clear day's scans lies one gradation group from the
#: thesis's clear sky (5.98 against 5, indicatrix 4: BENCHMARKS, "Sky models against a
#: measured clear sky").
SHAPE_SD = 1.0
#: The p-value of the fitted departure's chi-square under its prior below which the fit warns
#: that the sky departs from the spec's model more than real clear skies do
#: (:func:`_departure_warnings`).
DEPARTURE_CONFLICT_P = 0.001
#: Step in each term's coefficient of the finite differences of the residuals.
DRIFT_STEP = 1e-3
#: Gauss-Newton iterations of the terms at most.
DRIFT_ITERATIONS = 8
#: The parameters that scale with the light's absolute level (the reflectances); the
#: roughness does not.
LEVEL_SCALED = ("C_r", "C_g", "C_b", "R", "rho_s")


@dataclass(frozen=True)
class SkyShare:
    """What the light adds to one region's parameters' errors.

    record : the sky fit's record (:func:`~.sky_fit.fit_sky_scale`), shared by the day's
        regions; None where the spec's sky is taken as it is
    sd : the fitted sky's share of each parameter's standard error (None: none)
    span : where the sky's level is not determined, each parameter's (lowest, highest) over the
        levels the data could not tell apart (None where it is)
    sun_widening : what a modelled sun's level gains from the fitted sky's departure from the
        spec's (:data:`~skyfit_mi.physics.sky.SUN_SKY_COUPLING`)
    light : the sky's coefficients as fitted (:class:`FittedLight`), from which the shares are
        taken again at the region's own fit (:func:`share_at`); None where the sky's level is
        not determined
    response : (n, coefficients) the parameters' response to them at that fit (None before)
    reference_slope : (3, coefficients) d ln f / d coefficients of the light's factor per
        channel f that a reference in the scene sets (:func:`reference_slope`; None: no
        reference): the light as calibrated again on it moves with the coefficients
    pose_shift : {angle: (coefficients,) their shift were the camera turned by the pose's sd
        in that angle} (:func:`~.pose.pose_through_sky`; empty: none)
    """

    record: dict = None
    sd: np.ndarray = None
    span: tuple = None
    sun_widening: float = 0.0
    light: "FittedLight" = None
    response: np.ndarray = None
    pose_shift: dict = field(default_factory=dict)
    reference_slope: np.ndarray = None

    def sun_level_sd(self, plan):
        """The sun's level's relative uncertainty in the reflectances' intervals: the
        :class:`~.light.LightPlan` ``plan``'s ``sun_sd`` widened by ``sun_widening``."""
        return float(np.hypot(plan.sun_sd, self.sun_widening))

    @property
    def shape_known(self):
        """Whether the sky's shape is known to the fit: the spec's taken as it is (no sky fit),
        or fitted with the materials (--sky-shape); not where only its level was fitted."""
        return self.record is None or self.record.get("shape") is not None

@dataclass(frozen=True)
class SkyFit:
    """The sky fit's result (:func:`fit_sky_scale`): its ``record`` (the fit JSON's ``sky``) and
    each region's :class:`SkyShare` (``shares`` {region: share})."""

    record: dict
    shares: dict = field(default_factory=dict)


def _sunlit(skies):
    """Those of ``skies`` whose sun's disc lights the scene from above the horizon."""
    return [k for k in skies if np.any(k.sun_radiance > 0) and k.sun_direction[2] > 0]


def sun_up(skies):
    """Whether the sun's disc lights any of ``skies`` from above the horizon (a fitted sky is
    scaled against it)."""
    return bool(_sunlit(skies))


def photographed(doc):
    """Whether a manifest's frames were not rendered by skyfit (their light is the real one,
    the spec's a model of it)."""
    return doc.get("source", "render") not in RENDERED_SOURCES


def default_sky(doc, skies):
    """How a fit takes the sky when not told (``fit --sky``): with its prior ('prior') where
    the frames were photographed under a sky with the sun (the spec's light is then a model of
    the real one), else the spec's ('spec': skyfit rendered the frames under that very light,
    or no sun lights them to scale the sky against)."""
    sunny = sun_up(skies) and any(k.lit_by_sky for k in skies)
    return "prior" if sunny and photographed(doc) else "spec"


def default_departure(doc):
    """Whether a fitted sky's departure from its model is fitted when not told (``fit
    --sky-departure``): for photographs (their sky is the real one, whose shape no model
    holds), not for a sequence skyfit rendered under the spec's very sky."""
    return photographed(doc)


def sun_source(skies):
    """Where the level of the sun of ``skies`` comes from, when ``fit --sun-sd`` does not give
    it: 'measured' where every sky with the sun up carries a measured direct normal irradiance
    (its ``info["sun_measured"]``), else 'modelled' (the thesis's eq. 4.7, a clear-sky model,
    or a split of the global irradiance)."""
    lit = _sunlit(skies)
    return "measured" if lit and all(k.info.get("sun_measured") for k in lit) else "modelled"


def default_sun_sd(doc, skies):
    """The relative uncertainty of the sun's level a fitted sky counts when not told (``fit
    --sun-sd``): for photographs a measured sun's (where every sunlit sky states its own, a grey
    card's ``info["sun_sd"]``: their mean weighted by the sun's horizontal irradiance, the
    relative error of the day's sunlight when the frames' errors are one (the card's
    reflectance), so a frame whose sun is faint weighs little; else
    :data:`~skyfit_mi.physics.sky.MEASURED_SUN_SD`) or a modelled one's
    (:data:`~skyfit_mi.physics.sky.SUN_LEVEL_SD`, :func:`sun_source`); 0 for a sequence
    skyfit rendered under that very sun."""
    if not photographed(doc):
        return 0.0
    if sun_source(skies) != "measured":
        return SUN_LEVEL_SD
    lit = _sunlit(skies)
    stated = [k.info.get("sun_sd") for k in lit]
    if None in stated:
        return MEASURED_SUN_SD
    sun = np.array([float(k.sun_horizontal_irradiance() @ SRGB_LUMINANCE) for k in lit])
    return float(np.dot(stated, sun) / sun.sum())


def light_level_sd(doc, names, sun_sd):
    """Each parameter's relative error (``names``) from the sun's level known to a relative
    ``sun_sd`` (a standard deviation of its log): the reflectances', the roughness none; zeros
    where a reference in the scene (a calibration) or a relative scale ties the reflectances to
    the data (the manifest ``doc``), and for the white 2-parameter model (rho_d + rho_s = 1
    fixes the scale, so a wrong level shows as misfit instead)."""
    scale = (doc.get("ingest") or {}).get("scale") or {}
    anchored = _referenced(doc) or scale.get("known") is False
    if anchored or not sun_sd or "C_r" not in names and "R" not in names:
        return np.zeros(len(names))
    return np.array([float(sun_sd) if p in LEVEL_SCALED else 0.0 for p in names])


def _seconds(times):
    """Seconds since the epoch of ISO ``times``."""
    return np.array([dt.datetime.fromisoformat(t).timestamp() for t in times])


def time_basis(times, span, terms):
    """(T, ``terms``) Legendre polynomials P_0 .. P_terms-1 of the frames' ``times`` (ISO)
    mapped onto [-1, 1] over ``span`` (first, last) [s since the epoch], held at the ends
    outside it: log k(t) = basis @ coefficients."""
    t0, t1 = span
    x = np.clip(2.0 * (_seconds(times) - t0) / max(t1 - t0, 1.0) - 1.0, -1.0, 1.0)
    return np.polynomial.legendre.legvander(x, terms - 1)


def _curve_at(curve, times):
    """A curve's record (:func:`_curve_record`) at the frames' ``times`` (ISO; held at the
    fitted span's ends)."""
    return np.exp(time_basis(times, curve["span_s"], len(curve["coefficients"]))
                  @ np.asarray(curve["coefficients"]))


def sky_level_at(record, times):
    """The sky's level k at the frames' ``times`` (ISO) by a sky fit's ``record``: the day's
    one level, or its smooth curve over the day (``terms``)."""
    terms = record.get("terms")
    return np.full(len(times), float(record["k"])) if terms is None else _curve_at(terms, times)


def light_level_at(record, times):
    """The whole light's level at the frames' ``times`` (ISO) by a sky fit's ``record`` (its
    ``light_level`` curve, :data:`LEVEL_TERMS`), or None where it fitted none."""
    curve = (record or {}).get("light_level")
    return None if curve is None else _curve_at(curve, times)


def skies_at_level(skies, record, times):
    """The frames' ``skies`` (at ISO ``times``) with their sky at a sky fit's level (``record``,
    :func:`sky_level_at`) against the sun: the spec's light as a fit of the day found it,
    calibrated again on the scene's reference where the fit did so (its ``reference``,
    :func:`~.fit.reference_factor`), and at the whole light's level over the day where it
    fitted one (:func:`light_level_at`)."""
    return [sky.sky_scaled(k).tinted(tint)
            for sky, k, tint in zip(skies, sky_level_at(record, times), light_tints(record, times))]


def light_tints(record, times):
    """The factor per channel (3,) on the whole light at each of the frames' ``times`` (ISO) by
    a sky fit's ``record``: the reference's (:func:`reference_light_factor`) times the light's
    level over the day (:func:`light_level_at`); None each where the fit set neither."""
    factor = reference_light_factor(record)
    level = light_level_at(record, times)
    if factor is None and level is None:
        return [None] * len(times)
    factor = np.ones(3) if factor is None else factor
    return [factor * v for v in (np.ones(len(times)) if level is None else level)]


def reference_light_factor(record):
    """The factor per channel (3,) that a sky fit's ``record`` puts on the light where it
    calibrated the light again on the scene's reference (:func:`~.fit.reference_factor`);
    None where it did not."""
    factor = ((record or {}).get("reference") or {}).get("light_factor")
    return None if factor is None else np.asarray(factor, dtype=float)


def _least(sessions, k, starts):
    """Every region's least chi-square and its parameters at sky scale ``k``."""
    out = []
    for s, start in zip(sessions, starts):
        s.set_sky(k)
        g = global_search(s.problem, start, s.lower, s.upper, candidates=2, profile=False,
                          grid_basis=s.grid_bases()[0])
        out.append((float(g["chi2"]), np.asarray(g["theta"], dtype=float)))
    return out


def _parabola(u, chi2):
    """(vertex, curvature b of chi2 = a + b (u - vertex)^2) through three points."""
    c2, c1, _ = np.polyfit(u, chi2, 2)
    return (-c1 / (2 * c2), c2) if c2 > 0 else (None, c2)


def shape_variants(skies):
    """Each frame's shape variants (:func:`~skyfit_mi.physics.sky_shape.shape_variants`) of
    ``skies``, for a fit of the sky's shape (``--sky-shape``), every frame's index moved the
    same way (the fit shares each variant's mix over the frames): +1 where every frame can,
    else -1.  Refused where some frame's spec sky has none (not a CIE, Perez or turbid sky),
    where the frames' skies move different indices, or where no way suits every frame."""
    variants = [sky_shape.shape_variants(sky) for sky in skies]
    if not all(variants):
        kinds = sorted({str(sky.info.get("kind")) for sky, v in zip(skies, variants) if not v})
        raise SkyfitError("--sky-shape moves a CIE sky's gradation and indicatrix, a Perez "
                          "sky's clearness and brightness or a turbid sky's turbidity, and the "
                          f"spec's sky of some frames ({', '.join(kinds)}) is none of these "
                          "(type clear, cie_general, perez or turbid) or is black above the "
                          "horizon; leave out --sky-shape, or those frames (--frames).")
    kinds = {tuple(v.info["of"] for _, v in vs) for vs in variants}
    if len(kinds) > 1:
        kinds = sorted({str(sky.info.get("kind")) for sky in skies})
        raise SkyfitError("--sky-shape needs one kind of spec sky over the fitted frames, and "
                          f"they mix {', '.join(kinds)} skies; fit them apart (--frames) or "
                          "leave out --sky-shape.")
    back = {v.info["of"]: -1 for vs in variants for _, v in vs if v.info["to"] < v.info["from"]}
    if back and any(v.info["of"] in back and v.info["to"] > v.info["from"]
                    for vs in variants for _, v in vs):
        variants = [sky_shape.shape_variants(sky, toward=back) for sky in skies]
    return variants


def _shape_record(session, mix, mix_sd):
    """The JSON record of the sky's fitted shape, and the indices' names for the log: the
    ``mix`` of the shape variants of ``session``'s frames (:func:`shape_variants`) with its
    standard deviations ``mix_sd``, and each variant's index, from + mix (to - from), with its
    95% half-width: the frames' mean, and each frame's where the spec's index differs between
    frames (a Perez sky)."""
    infos = [[v.info for _, v in vs] for vs in shape_variants(session.skies)]
    ends = np.array([[[v["from"], v["to"]] for v in row] for row in infos], dtype=float)
    mean = ends.mean(axis=0)                                          # (J, 2)
    first = infos[0]

    def index(e):
        return {v["of"]: [float(a + m * (b - a)), float(unc.Z["95"] * sd_m * abs(b - a))]
                for v, (a, b), m, sd_m in zip(first, e, mix, mix_sd)}

    record = {"meaning": "the sky other than the sun is (1 - sum(mix)) times the spec's pattern "
                         "plus mix[j] times variant j (the spec's pattern with one index moved: "
                         "a CIE gradation or indicatrix one group on, a Perez clearness one bin "
                         "on or its brightness Delta one step, a turbid sky's turbidity one "
                         "step, at the same horizontal irradiance; a turbid sky's fitted "
                         "turbidity also sets both levels: levels_by_frame): mix 1 is the "
                         "variant's index; index = from + mix (to - from), linear between the "
                         "patterns, the frames' mean; toward: the way each index moved (+1 up)",
              "variants": [f"{v['of']} {v['index']} {a:.4g} -> {b:.4g}"
                           for v, (a, b) in zip(first, mean)],
              "toward": {v["of"]: 1 if v["to"] > v["from"] else -1 for v in first},
              "mix": np.asarray(mix).tolist(), "mix_sd": np.asarray(mix_sd).tolist(),
              "prior_sd": SHAPE_SD, "index": index(mean)}
    if np.ptp(ends, axis=0).any():
        record["index_by_frame"] = {int(i): index(e) for i, e in zip(session.obs.frames, ends)}
    sun, sky = session.light_levels(mix)
    if np.ndim(sun):                      # a turbid sky: its turbidity moved both levels
        record["levels_by_frame"] = {
            "meaning": "the fitted turbidity's direct normal (sun) and diffuse horizontal (sky) "
                       "irradiance over the spec's, frame by frame (Ineichen and Perez); the "
                       "sky's level k multiplies the sky's",
            "frames": {int(i): {"sun": float(a), "sky": float(b)}
                       for i, a, b in zip(session.obs.frames, sun, sky)}}
    # the log's names of the indices: a CIE group's, as the index it is; epsilon, Delta
    return record, [v["index"] if v["index"] != "group" else "index" for v in first]


def _ranges(levels_by_frame):
    """(least, most) of the sun's factor, then of the sky's, over a turbid shape's frames."""
    by = levels_by_frame["frames"].values()
    sun, sky = [v["sun"] for v in by], [v["sky"] for v in by]
    return min(sun), max(sun), min(sky), max(sky)


def default_terms(frames, referenced=False):
    """The terms of the sky's level over ``frames`` frames when not told: :data:`DEFAULT_TERMS`,
    fewer where the frames are fewer than two more than that (one level for up to 3 frames);
    one level where a reference of known reflectance calibrates the frames (``referenced``,
    :func:`_referenced`).  There the reflectances' scale is the reference's, seen under the
    same light, and on a scene of one normal the curve is nearly collinear with a scale on
    the reflectances (a sky whose share follows the sun's height, as the sun's own light does),
    so it adds a valley, not information: a calibrated JPEG board at quality 85 (sky level 1)
    took a curve at k 0.65-0.76 and read every C 3-15% high, its chi-square 7 lower than one
    level's, while one level held every C within 3%; its half-widths were 2-3 times one
    level's on PNG (scripts/jpeg_colour_coverage.py, docs/BENCHMARKS.md).  The reference itself
    in the sky's fit would tell the curve (its reflectance is known); that is not done yet."""
    if referenced:
        return 1
    return int(max(1, min(DEFAULT_TERMS, int(frames) - FRAMES_BEYOND_TERMS)))


def default_level_terms(doc, frames):
    """The terms of the whole light's level over ``frames`` frames beyond its mean
    (:data:`LEVEL_TERMS`) for photographs whose frames keep their exposures' level from EXIF
    where a reference of known reflectance saw the light drift from the spec's over the day
    (ingest's ``calibration.light_drift``).  None where it saw the spec's curve, or calibrated
    each frame's level on its own (the spec's light's, by construction), where no reference
    tells the curve (a given exposure: the level's curve then trades with the materials'
    lobes, and a one-region ranking of lobes chose Ward's for a GGX plastic), for frames skyfit
    rendered (the spec's light is theirs), and for too few frames."""
    cal = (doc.get("ingest") or {}).get("calibration") or {}
    if not photographed(doc) or frames < LEVEL_TERMS + 1 + FRAMES_BEYOND_TERMS:
        return 0
    return LEVEL_TERMS if cal.get("light_drift") else 0


def _data_beyond_search(data, grid):
    """Where the data alone put the sky's level: ``data`` {log k: the regions' summed least
    chi-square} (the profile without the prior), ``grid`` the search's log k (:data:`SCALE_GRID`);
    -1 or +1 where the data's least point lies at or beyond the search's lower or upper end, 0
    within it.  Under ``--sky prior`` the profile's least point may lie well inside while the
    data's own runs to an end: the prior then holds a level the data do not show, a light
    further from the spec's than the prior allows (a hazy day's sky fitted with a clear
    spec: docs/BENCHMARKS.md, "the sky test set").  :func:`fit_sky_scale` warns where the
    prior's hold is also significant: the data's rise from their least point to the fitted
    level plus the prior's penalty there, over s^2 as the profile's intervals take it (the
    prior-data conflict, chi-square with one degree of freedom where the prior holds), above
    its 95% point (data that hardly tell the level are held by the prior quietly, wherever
    their least point lies)."""
    u = min(data, key=data.get)
    return -1 if u <= grid[0] else 1 if u >= grid[-1] else 0


def _referenced(doc):
    """Whether a reference of known reflectance in the scene calibrates a manifest's frames
    (``ingest --calibrate``, ``--colorchecker``)."""
    return bool((doc.get("ingest") or {}).get("calibration"))


def _curve_text(k):
    """The log's words for the sky's level ``k`` at each frame, in order: every value for a
    few frames, else its ends and range."""
    if len(k) <= CURVE_LISTED:
        return "k = " + ", ".join(f"{v:.2f}" for v in k) + " by frame"
    return (f"k = {k[0]:.2f} at the first frame, {k[-1]:.2f} at the last, {min(k):.2f}-"
            f"{max(k):.2f} over the {len(k)} frames")


def check_terms(terms, frames):
    """Refuse ``terms`` of the sky's level over ``frames`` frames that they cannot carry."""
    if not 1 <= int(terms) <= MAX_TERMS:
        raise SkyfitError(f"--sky-terms {terms}: give 1 (one sky level for the day) to "
                          f"{MAX_TERMS}.")
    if int(terms) > 1 and frames < int(terms) + FRAMES_BEYOND_TERMS:
        raise SkyfitError(f"--sky-terms {terms} needs at least {int(terms) + FRAMES_BEYOND_TERMS}"
                          f" frames, and the fit has {frames}; give fewer terms.")


@dataclass(frozen=True)
class SkyCoefficients:
    """The sky's coefficients fitted with the materials, each under a Gaussian prior N(0, sd^2)
    about the spec's sky: log k over the day as ``terms`` Legendre polynomials in time (the
    day's level under ``level_sd``, None for none; each further term under :data:`DRIFT_SD`),
    and the mix of each of the light's ``variants`` (their parts' names): the sky's shape
    variants (:data:`SHAPE_SD`) and its departure field's weights
    (:data:`~skyfit_mi.physics.sky_departure.PRIOR_SD`), then the whole light's level over the
    day as ``light_terms`` Legendre polynomials P_1.. in time (:data:`DRIFT_SD`; its mean is the
    exposure's).  They set the weights of the light's traced parts
    (:meth:`~.light.LightParts.table`): the sky's k(t) = exp(B(t) u[:terms]) against the sun,
    the variants' mix after it, and the level's factor on both, sun and sky, last."""

    terms: int
    variants: tuple = ()
    level_sd: float = None
    light_terms: int = 0

    @property
    def names(self):
        """Each coefficient's name, in order."""
        return (["log k"] + [f"log k term {j}" for j in range(1, self.terms)]
                + [f"mix {v.removeprefix('shape:')}" if v.startswith("shape:") else
                   v.replace(":", " ", 1) for v in self.variants]
                + [f"log light term {j}" for j in range(1, self.light_terms + 1)])

    @property
    def columns(self):
        """The Legendre polynomials in time (:func:`time_basis`) the coefficients need."""
        return max(self.terms, self.light_terms + 1)

    @property
    def precision(self):
        """The priors' precision matrix (1 / sd^2 on the diagonal; 0 for no prior)."""
        sd = [self.level_sd] + [DRIFT_SD] * (self.terms - 1) + [
            SHAPE_SD if v.startswith("shape:") else DEPARTURE_SD for v in self.variants] + [
            DRIFT_SD] * self.light_terms
        return np.diag([0.0 if v is None else v ** -2 for v in sd])

    def light(self, session, basis, u):
        """Light ``session`` (its frames' time ``basis``, :func:`time_basis`) at the
        coefficients ``u``: the sky's level k(t) against the sun, its variants' mix, and the
        whole light's level exp(P_1..(t) u) about its mean (:data:`LEVEL_TERMS`)."""
        J = self.terms + len(self.variants)
        session.set_sky(np.exp(basis[:, :self.terms] @ u[:self.terms]),
                        u[self.terms:J] if self.variants else None,
                        np.exp(basis[:, 1:self.light_terms + 1] @ u[J:])
                        if self.light_terms else None)


def _fit_curve(sessions, thetas, u0, coefficients, s2, scale=1.0):
    """The sky's ``coefficients`` (:class:`SkyCoefficients`) fitted with the regions'
    parameters, from the day's level ``u0`` (log k) and each region's ``thetas`` there.
    Gauss-Newton on the coefficients with every region's parameters profiled out (each
    region's Jacobian in the coefficients projected off its parameters' own; the parameters
    then polished by Levenberg-Marquardt), under their priors.  Leaves each session at the
    fit; returns (coefficients, their covariance, the profiled normal matrix's inverse, the
    span [s], each region's time basis, its
    parameters there and their response to the coefficients (n, coefficients), the regions'
    summed chi-square there); the covariance takes the data's information over ``scale`` (the
    regions' disagreement, :func:`_regions_agree`), the priors' as it is."""
    terms = coefficients.terms
    times = [t for s in sessions for t in s.obs.times]
    span = (float(_seconds(times).min()), float(_seconds(times).max()))
    bases = [time_basis(s.obs.times, span, coefficients.columns) for s in sessions]
    P = coefficients.precision
    n = len(P)
    u = np.r_[u0, np.zeros(n - 1)]
    thetas = [np.asarray(t, dtype=float) for t in thetas]
    put = coefficients.light

    def objective(u, thetas):
        for s, B in zip(sessions, bases):
            put(s, B, u)
        return sum(s.problem.chi2(t) for s, t in zip(sessions, thetas)) + u @ P @ u

    def linearised(u, thetas):
        """The profiled normal equations (H, g) at (u, thetas) and each region's response."""
        H, g, responses = P.copy(), P @ u, []
        for s, B, theta in zip(sessions, bases, thetas):
            Jp, r, Jt, response = light_response(s, FittedLight(coefficients, B, u), theta)
            rp = r - Jt @ np.linalg.lstsq(Jt, r, rcond=None)[0]
            H += Jp.T @ Jp
            g += Jp.T @ rp
            responses.append(response)
        return H, g, responses

    current = objective(u, thetas)
    for _ in range(DRIFT_ITERATIONS):
        H, g, _ = linearised(u, thetas)
        step = -np.linalg.solve(H, g)
        for _ in range(6):                              # halved until chi-square falls
            for s, B in zip(sessions, bases):
                put(s, B, u + step)
            moved = [levenberg_marquardt(s.problem, t, s.lower, s.upper)["theta"]
                     for s, t in zip(sessions, thetas)]
            new = objective(u + step, moved)
            if new < current:
                break
            step = step / 2
        else:
            break
        u, thetas, gain, current = u + step, moved, current - new, new
        if gain < 1e-3 * max(1.0, s2) or np.max(np.abs(step)) < 1e-4:
            break
    chi2 = objective(u, thetas) - u @ P @ u
    H, _, responses = linearised(u, thetas)
    return (u, s2 * np.linalg.inv((H - P) / scale + P), np.linalg.inv(H), span, bases, thetas,
            responses, float(chi2))


@dataclass(frozen=True)
class FittedLight:
    """The sky's coefficients as fitted for one region: their kind (:class:`SkyCoefficients`),
    the region's frames' time ``basis`` (:func:`time_basis`), their values ``u``, their
    ``covariance`` (the regions' pooled Birge ratio s^2 times the inverse of the profiled
    normal matrix, the data's part divided by the regions' disagreement), the region's
    parameters ``theta`` there (None while fitting), and ``inverse_normal`` H^-1, the inverse of
    the profiled normal matrix as it is: the coefficients' response to the data
    (:func:`~.pose.pose_through_sky`)."""

    coefficients: SkyCoefficients
    basis: np.ndarray
    u: np.ndarray
    covariance: np.ndarray = None
    theta: np.ndarray = None
    inverse_normal: np.ndarray = None

    def put(self, session, u=None):
        """Light ``session`` at the coefficients ``u`` (default the fitted)."""
        self.coefficients.light(session, self.basis, self.u if u is None else u)


def light_response(s, light, theta):
    """(the residuals' derivatives in the coefficients that the parameters cannot absorb,
    residuals, d residuals / d theta, the parameters' least-squares response to the
    coefficients (n, coefficients)) of session ``s`` at its parameters ``theta`` and the
    :class:`FittedLight` ``light`` (central differences of :data:`DRIFT_STEP`); leaves ``s``
    lit at it."""
    u = light.u
    eye = np.eye(len(u))
    Ju = []
    for j in range(len(u)):
        r = []
        for sign in (1, -1):
            light.put(s, u + sign * DRIFT_STEP * eye[j])
            r.append(s.problem.residuals(theta))
        Ju.append((r[0] - r[1]) / (2 * DRIFT_STEP))
    light.put(s)
    Ju = np.column_stack(Ju)
    r, Jt = s.problem.jacobian(theta)
    response = -np.linalg.lstsq(Jt, Ju, rcond=None)[0]
    return Ju + Jt @ response, r, Jt, response


def _residual_slope(problem, theta):
    """(the model's radiance (P, T, 3) at ``theta``, each value's residual's derivative in it)
    of ``problem`` (a :class:`~.chi2.Problem`)."""
    L = problem.model.radiance(theta)
    return L, problem.residual_terms(L)[1] * problem.slope(L)


def reference_slope(s, light, theta, lambertian):
    """d ln f / d u (3, coefficients): how the light's factor per channel f that a reference
    sets (:func:`~.fit.reference_factor`: the radiance of its fit ``theta`` over that of a
    Lambertian surface of its known reflectance, ``lambertian``, summed over the day) moves with
    the sky's coefficients u of its :class:`FittedLight` ``light``; session ``s`` (the
    reference's) is left lit at the fitted u.  The fit's radiance follows the data, its
    parameters taking up what they can of the light's change: it moves by what they cannot
    (:func:`light_response`'s residuals' derivatives, linear: a grey card's roughness, which its
    nil gloss leaves free, responds without bound); the Lambertian's by the light's.  Where
    the sky is brighter than fitted, the reference reads less, and so every region lit by the
    light times f: a diffuse surface facing as the reference does reads its reflectance against
    the reference's whatever the sky's level, and only the light it sees otherwise (its lobe's
    sky) carries the sky's uncertainty (:func:`share_at`)."""
    unabsorbed = light_response(s, light, theta)[0]
    problem = s.problem
    L, per_radiance = (a[problem.mask] for a in _residual_slope(problem, theta))
    channel = np.broadcast_to(np.arange(problem.mask.shape[-1]), problem.mask.shape)[problem.mask]
    moved = np.divide(unabsorbed, per_radiance[:, None], out=np.zeros_like(unabsorbed),
                      where=per_radiance[:, None] != 0)
    fitted = np.array([moved[channel == c].sum(axis=0) / L[channel == c].sum()
                       for c in range(problem.mask.shape[-1])])
    eye, columns = np.eye(len(light.u)), []
    for j in range(len(light.u)):
        ln_lambertian = []
        for sign in (1, -1):
            light.put(s, light.u + sign * DRIFT_STEP * eye[j])
            ln_lambertian.append(np.log(np.sum(s.wm.radiance(lambertian), axis=(0, 1))))
        columns.append((ln_lambertian[0] - ln_lambertian[1]) / (2 * DRIFT_STEP))
    light.put(s)
    return fitted - np.column_stack(columns)


def share_at(s, share, theta):
    """The region's ``share`` of the fitted light (:class:`SkyShare`) taken again at its own
    fit ``theta`` (session ``s`` lit at the fitted sky): the sky fit found each region's
    response at the parameters of its search, and a region whose final fit lies elsewhere (a
    metal's roughness at its bound, where its C and rho_s trade) responds otherwise.  Where a
    reference calibrated the light again (``share.reference_slope``), the response includes
    the factor's: the parameters' response to the light's level per channel (d r / d ln f_c,
    the model's value times the residual's slope in it) through its slope."""
    if share.light is None:
        return share
    _, _, Jt, response = light_response(s, share.light, theta)
    if share.reference_slope is not None:
        problem = s.problem
        L, dr = _residual_slope(problem, theta)
        dr = dr * L
        J_f = np.stack([np.where(np.arange(dr.shape[-1]) == c, dr, 0.0)[problem.mask]
                        for c in range(dr.shape[-1])], axis=1)
        response = response - np.linalg.lstsq(Jt, J_f, rcond=None)[0] @ share.reference_slope
    return replace(share, sd=_carried_sd(response, share.light.covariance), response=response)


def _carried_sd(response, covariance):
    """The standard errors (n,) the coefficients' ``covariance`` gives the parameters that
    respond to them by ``response`` (n, coefficients)."""
    return np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", response, covariance, response), 0.0))


@dataclass
class _Level:
    """The day's one sky level profiled over log k (:func:`_profile_level`): ``profile``
    {log k: [(least chi-square, parameters) per region]}, the search's ``grid`` (log k), the
    prior's sd on log k (None: none), the least point ``u0``, log k's standard error ``sd_u``
    (inf where not determined), whether the least point lies at the grid's ``edge``, s^2
    (the regions' pooled Birge ratio there), whether the regions ``agree`` on the level
    (:func:`_regions_agree`), and the profile's ``curvature`` b there (chi2 = a + b u^2)."""

    profile: dict
    grid: np.ndarray
    prior_sd: float
    u0: float = 0.0
    sd_u: float = np.inf
    edge: bool = False
    s2: float = 1.0
    agree: dict = None
    curvature: float = None

    def data(self, u):
        """The regions' summed least chi-square at log k = ``u``."""
        return sum(c for c, _ in self.profile[u])

    def total(self, u):
        """The profile: the data's chi-square and the prior's penalty at log k = ``u``."""
        return self.data(u) + (0.0 if self.prior_sd is None else (float(u) / self.prior_sd) ** 2)

    @property
    def determined(self):
        return bool(np.isfinite(self.sd_u))

    @property
    def within(self):
        """The log k the profile cannot tell from the least point (95%)."""
        return [u for u in self.profile
                if self.total(u) <= self.total(self.u0) + unc.LEVELS["95"] * self.s2]

    @property
    def interval(self):
        """k's 95% interval: from the curvature, or what the profile saw where k is not
        determined (open where it reached the grid's end)."""
        if self.determined:
            return [float(np.exp(self.u0 - unc.Z["95"] * self.sd_u)),
                    float(np.exp(self.u0 + unc.Z["95"] * self.sd_u))]
        within = self.within
        return [None if min(within) <= self.grid[0] else float(np.exp(min(within))),
                None if max(within) >= self.grid[-1] else float(np.exp(max(within)))]


def _profile_level(sessions, prior_sd, seed):
    """The day's one sky level (:class:`_Level`): the regions' summed least chi-square (the
    global search from seeded starts) on :data:`SCALE_GRID`, then a parabola in log k about
    its least point; log k's standard error from the curvature (Delta chi^2 = s^2 at 1 sd)."""
    rng = np.random.default_rng(seed)
    starts = [s.random_start(rng) for s in sessions]
    level = _Level({}, np.log(SCALE_GRID), prior_sd)

    def total(u):
        u = float(u)
        if u not in level.profile:
            level.profile[u] = _least(sessions, float(np.exp(u)), starts)
        return level.total(u)

    grid = level.grid
    chi2 = np.array([total(u) for u in grid])
    i = int(np.argmin(chi2))
    edge = i in (0, len(grid) - 1)
    j = min(max(i, 1), len(grid) - 2)
    u0, b_grid = _parabola(grid[j - 1:j + 2], chi2[j - 1:j + 2])
    u0 = float(grid[i] if u0 is None or edge else np.clip(u0, grid[j - 1], grid[j + 1]))
    near = np.array([u0 - REFINE_STEP, u0, u0 + REFINE_STEP])
    vertex, b = _parabola(near, [total(u) for u in near])
    if vertex is not None and abs(vertex - u0) < 2 * REFINE_STEP and not edge:
        total(float(vertex))
    # the least point evaluated; the curvature near it, or the grid's where the near points'
    # search jitter leaves none
    level.u0 = min(level.profile, key=level.total)
    b = b if b is not None and b > 0 else b_grid
    noise = sum(s.problem.noise_chi2(th)[0]
                for s, (_, th) in zip(sessions, level.profile[level.u0]))
    level.s2 = unc.scale(level.data(level.u0), noise)
    level.edge = edge
    level.agree = _regions_agree(level)
    # at the grid's end the minimum may lie beyond it: k is not determined; the data's
    # curvature (the prior's, 1 / sd^2, apart) over the regions' disagreement
    if b is not None and b > 0 and not edge:
        prior = 0.0 if prior_sd is None else min(1.0 / prior_sd ** 2, b)
        level.sd_u = float(np.sqrt(level.s2 / ((b - prior) / level.agree["scale"] + prior)))
        level.curvature = float(b)
    else:
        level.sd_u = np.inf
    return level


def _regions_agree(level):
    """Whether the regions agree on the day's one sky level (``level``'s profile): Q, the sum
    over regions of how far each region's chi-square at the pooled level lies above its own
    least (a parabola through its three points about the least it saw), over s^2, is
    chi-square with R - 1 degrees of freedom when one light lights them all as the model
    says.  Where it is significant (p < MISFIT_P) the sky's model does not hold the light the
    regions see (a sky of another shape: each material reads it through its own lobe), and
    the data's information on the sky's coefficients is divided by ``scale`` = Q / (R - 1),
    the Birge ratio between regions (the Particle Data Group's scale factor, squared); else
    ``scale`` 1.  Returns {chi2, dof, p, scale, by_region: each region's own least level k}."""
    us = np.array(sorted(level.profile))
    chi2 = np.array([[c for c, _ in level.profile[u]] for u in us])          # (U, R)
    R = chi2.shape[1]
    at = chi2[int(np.searchsorted(us, level.u0))]
    least, own = chi2.min(axis=0), us[np.argmin(chi2, axis=0)]
    for r in range(R):
        i = int(np.argmin(chi2[:, r]))
        if 0 < i < len(us) - 1:
            vertex, b = _parabola(us[i - 1:i + 2], chi2[i - 1:i + 2, r])
            if vertex is not None and us[i - 1] < vertex < us[i + 1]:
                own[r] = vertex
                least[r] = min(least[r], chi2[i, r] - b * (us[i] - vertex) ** 2)
    q = float(np.sum(at - least) / level.s2)
    dof = R - 1
    if not np.isfinite(q):                   # a region's search failed somewhere: no test
        q, dof = 0.0, 0
    p = float(chdtrc(dof, q)) if dof else 1.0
    return {"chi2": q, "dof": dof, "p": p,
            "scale": q / dof if dof and p < unc.MISFIT_P else 1.0,
            "by_region": [float(np.exp(u)) for u in own]}


def _level_warnings(level, terms):
    """What the day's one level says of itself: not determined, or held by its prior where the
    data alone put it beyond the search (:func:`_data_beyond_search`)."""
    warnings, k, within = [], float(np.exp(level.u0)), level.within
    if not level.determined:
        warnings.append(
            f"the data do not determine the sky's level (k = {k:.3g}, chi-square "
            f"{'at the search' + chr(39) + 's end' if level.edge else 'flat'} over k = "
            f"{np.exp(min(within)):.3g}-{np.exp(max(within)):.3g}): every parameter's interval "
            "takes in its values over that range of k"
            + (", at least: the level may lie beyond the search (the spec's sky may be far "
               "from the light the data show), so the parameters and their intervals are not "
               "reliable" if level.edge else "")
            + "; fit several materials with different normals, or a grey card, together.")
    agree = level.agree
    if agree and agree["scale"] > 1:
        own = agree["by_region"]
        warnings.append(
            f"the regions disagree about the sky's level (chi-square {agree['chi2']:.1f} for "
            f"{agree['dof']}, p = {agree['p']:.2g}; each region alone puts it at "
            f"{min(own):.3g}-{max(own):.3g} times the spec's): the spec's sky does not hold "
            "the light they see (a sky of another shape, which each material reads through its "
            "own lobe), so every interval takes the sky's uncertainty widened by that "
            f"disagreement (the data's information on it divided by {agree['scale']:.3g}); "
            "an error in the sky's shape may still move glossy materials beyond their "
            "intervals: give the spec a measured sky (envmap, or perez with measured "
            "irradiance) or photograph it (skyfit sky-series).")
    alone = {u: level.data(u) for u in level.profile}   # the profile without the prior
    side = _data_beyond_search(alone, level.grid)
    # the prior-data conflict, over s^2 as the profile's intervals take it
    conflict = (level.total(level.u0) - min(alone.values())) / level.s2
    if level.prior_sd is not None and side and not level.edge and conflict > unc.LEVELS["95"]:
        end = level.grid[-1 if side > 0 else 0]
        warnings.append(
            f"the data alone put the sky's level at the search's {'upper' if side > 0 else 'lower'}"
            f" end (k near {np.exp(end):.3g} times the spec's or beyond, "
            f"{abs(end) / level.prior_sd:.1f} sd of its prior) as one level for the day, and the "
            f"prior holds that level at k = {k:.3g}: the light the data show departs from the "
            "spec's more than the prior allows, so the parameters and their intervals are not "
            "reliable" + (" unless the level's change over the day takes that up" if terms > 1
                          else "")
            + "; give the spec a sky nearer the day's (a measured one: perez with measured "
            "irradiance, or envmap), or fit several materials with different normals, or a grey "
            "card, together.")
    return warnings


def _level_spans(sessions, level):
    """Each region's parameters' (lowest, highest) over the levels the profile could not tell
    apart where the day's one ``level`` is not determined, else None."""
    if level.determined:
        return [None] * len(sessions)
    return [(np.min(v, axis=0), np.max(v, axis=0))
            for v in (np.array([level.profile[u][n][1] for u in level.within])
                      for n in range(len(sessions)))]


@dataclass
class _Fitted:
    """The sky as fitted (:func:`fit_sky_scale`): its level k with its 95% interval and log
    k's sd, each region's share of its errors (``sd``), the curve's and the shape's records
    (None where not fitted), each region's parameters' span over the levels the profile could not
    tell apart where k is not determined (:func:`_level_spans`), the coefficients' correlation, the regions' chi-square there, log
    k by frame of a curve (else None), and the log's names of the shape's indices."""

    k: float
    interval: list
    sd_u: float
    sd: list
    span: list
    chi2: float
    curve: dict = None
    shape: dict = None
    correlation: dict = None
    log_k: np.ndarray = None
    index_names: list = None
    departure: dict = None
    lights: list = None
    light_curve: dict = None


def _fit_terms(sessions, level, terms, told, warnings, light_terms=0):
    """The sky's level over the day (``terms``, ``told`` by ``--sky-terms``), its shape
    (the shape variants traced) and the whole light's level over the day (``light_terms``,
    :func:`default_level_terms`) fitted from the day's ``level`` (:func:`_fit_curve`) where
    that is determined; a :class:`_Fitted` (the level's own where they are not fitted).
    Appends what the data hardly tell to ``warnings``."""
    thetas = [theta for _, theta in level.profile[level.u0]]
    fitted = _Fitted(float(np.exp(level.u0)), level.interval, level.sd_u,
                     [np.zeros(len(theta)) for theta in thetas], _level_spans(sessions, level),
                     level.data(level.u0))
    J = len(sessions[0].parts.variants)                  # the shape variants traced
    if not (terms > 1 or J or light_terms):
        if level.determined:
            light = SkyCoefficients(1, (), level.prior_sd)
            fitted.lights = [FittedLight(light, np.ones((len(s.obs.times), 1)),
                                         np.array([level.u0]), np.array([[level.sd_u ** 2]]),
                                         theta, np.array([[1.0 / level.curvature]]))
                             for s, theta in zip(sessions, thetas)]
            fitted.sd = [_carried_sd(light_response(s, light, light.theta)[3], light.covariance)
                         for s, light in zip(sessions, fitted.lights)]
        return fitted
    if not level.determined:
        if told and terms > 1 or J:
            parts = (["change over the day"] * (told and terms > 1)
                     + ["shape"] * bool(sessions[0].parts.shapes)
                     + ["departure from its model"] * (J > sessions[0].parts.shapes))
            warnings.append(f"the sky's {' and its '.join(parts)} "
                            f"{'are' if len(parts) > 1 else 'is'} not fitted: its level is not "
                            "determined.")
        return fitted
    coefficients = SkyCoefficients(terms, tuple(sessions[0].parts.variants), level.prior_sd,
                                   light_terms)
    u, C, H_inv, span, bases, thetas, responses, fitted.chi2 = _fit_curve(
        sessions, thetas, level.u0, coefficients, level.s2, level.agree["scale"])
    sd = np.sqrt(np.diag(C))
    fitted.lights = [FittedLight(coefficients, B, u, C, theta, H_inv)
                     for B, theta in zip(bases, thetas)]
    fitted.sd = [_carried_sd(R, C) for R in responses]
    fitted.k, fitted.sd_u = float(np.exp(u[0])), float(sd[0])
    fitted.interval = [float(np.exp(u[0] - unc.Z["95"] * sd[0])),
                       float(np.exp(u[0] + unc.Z["95"] * sd[0]))]
    if terms > 1:
        fitted.curve, fitted.log_k = _curve_record(sessions, u[:terms], C[:terms, :terms], span)
        vague = [j for j in range(1, terms) if sd[j] > 0.7 * DRIFT_SD]
        if vague and told:
            warnings.append(f"the data hardly tell how the sky changes over the day (terms "
                            f"{', '.join(map(str, vague))} of --sky-terms {terms}): their "
                            "prior holds them, and the intervals include that.")
    S = sessions[0].parts.shapes                         # shape variants first, then departure
    if S:
        fitted.shape, fitted.index_names = _shape_record(sessions[0], u[terms:terms + S],
                                                         sd[terms:terms + S])
        warnings += _shape_warnings(fitted.shape, sd[terms:terms + S])
    if light_terms:
        w, Cw = np.zeros(light_terms + 1), np.zeros((light_terms + 1,) * 2)
        w[1:], Cw[1:, 1:] = u[terms + J:], C[terms + J:, terms + J:]
        fitted.light_curve = _curve_record(sessions, w, Cw, span, of="level")[0]
    if J > S:
        a, Ca = u[terms + S:terms + J], C[terms + S:terms + J, terms + S:terms + J]
        fitted.departure = _departure_record(a, Ca)
        warnings += _departure_warnings(fitted.departure)
    fitted.correlation = {"names": coefficients.names,
                          "matrix": (C / np.outer(sd, sd)).tolist()}
    return fitted


def _curve_record(sessions, coefficients, covariance, span, of="k"):
    """The JSON record of a curve over the day of the sky's level k against the sun (or of the
    whole light's level, ``of`` 'level'): its Legendre ``coefficients`` with their
    ``covariance`` over ``span`` [s], and its log at each frame."""
    frames = sorted({(i, t) for s in sessions for i, t in zip(s.obs.frames, s.obs.times)})
    B = time_basis([t for _, t in frames], span, len(coefficients))
    log_k = B @ coefficients
    half = unc.Z["95"] * np.sqrt(np.einsum("ij,jk,ik->i", B, covariance, B))
    return {"meaning": f"log {of}(t) = sum_j coefficients[j] P_j(x), P_j Legendre polynomials, "
                       "x = -1 at span_s[0] and 1 at span_s[1] (held beyond)"
                       + ("; the whole light's, sun and sky, against the spec's, about its "
                          "mean (P_0's coefficient 0: the exposure's)" if of == "level" else ""),
            "coefficients": coefficients.tolist(), "covariance": covariance.tolist(),
            "span_s": list(span), "drift_prior_sd": DRIFT_SD,
            f"{of}_by_frame": {int(i): [float(np.exp(v)), float(np.exp(v - h)),
                                        float(np.exp(v + h))]
                               for (i, _), v, h in zip(frames, log_k, half)}}, log_k


def _shape_warnings(shape, mix_sd):
    """What the fitted shape (``shape``'s record, its mix's sd ``mix_sd``) cannot say."""
    warnings = []
    vague = [of for of, sd_m in zip(shape["index"], mix_sd) if sd_m > 0.7 * SHAPE_SD]
    if vague:
        warnings.append(f"the data hardly tell the sky's {' and '.join(vague)} (its "
                        "shape): the prior holds it, and the intervals include that; "
                        "regions with other normals, or a grey card, tell it better.")
    t = shape["index"].get("turbidity")
    if t is not None and not TURBIDITY_RANGE[0] <= t[0] <= TURBIDITY_RANGE[1]:
        warnings.append(f"the fitted turbidity {t[0]:.3g} lies beyond the turbid sky's "
                        f"{TURBIDITY_RANGE[0]:g}-{TURBIDITY_RANGE[1]:g}, where its "
                        "levels are held at the edge: the light is not a turbid clear "
                        "sky's, so the parameters and their intervals are not "
                        "reliable; give the spec a sky nearer the day's (a measured "
                        "one: perez with measured irradiance, or envmap).")
    return warnings


def _departure_record(a, covariance):
    """The JSON record of the sky's fitted departure from its model: the field's weights ``a``
    with their ``covariance`` (:mod:`~skyfit_mi.physics.sky_departure`)."""
    sd = np.sqrt(np.diag(covariance))
    chi2 = conflict(a)
    return {"meaning": "the sky other than the sun is the spec's (its level and shape as fitted) "
                       "times 1 + sum_j weights[j] B_j above the horizon, B_j the basis of the "
                       "zenith angle theta and the angle gamma from the sun (u = 2 cos theta - 1, "
                       "y = cos gamma; P1, P2 Legendre), each weight under the prior N(0, "
                       "prior_sd^2) measured from real clear skies; the fit marginalises it "
                       "into every interval; conflict: sum (weights / prior_sd)^2, chi-square "
                       "with len(basis) degrees of freedom under the prior, and its p-value",
            "basis": list(BASIS), "weights": np.asarray(a).tolist(), "sd": sd.tolist(),
            "covariance": np.asarray(covariance).tolist(), "prior_sd": DEPARTURE_SD,
            "conflict": chi2, "conflict_p": float(chdtrc(len(a), chi2))}


def _departure_warnings(departure):
    """What the fitted departure says of the spec's sky: a departure beyond what real clear
    skies show (its conflict with the prior significant at :data:`DEPARTURE_CONFLICT_P`)."""
    if departure["conflict_p"] >= DEPARTURE_CONFLICT_P:
        return []
    return [f"the sky departs from the spec's model more than measured clear skies depart from "
            f"theirs (its field's weights {', '.join(f'{v:+.2f}' for v in departure['weights'])}"
            f" against a prior sd of {DEPARTURE_SD:g}; chi-square {departure['conflict']:.1f} "
            f"for {len(departure['weights'])}): the prior holds the field back, so the "
            "parameters and their intervals may not be reliable; give the spec a sky nearer the "
            "day's (a measured one: perez with measured irradiance, or envmap, or a sky "
            "photographed), or fit its shape too (--sky-shape)."]


def fitted_mix(record):
    """The mix of the light's variants (:class:`~.light.LightParts`) at a sky fit's
    ``record``: its shape's mix, then its departure's weights; None where neither was fitted."""
    mix = list((record.get("shape") or {}).get("mix", [])) \
        + list((record.get("departure") or {}).get("weights", []))
    return mix or None


def _sun_coupling(plan, level, fitted):
    """(What a modelled sun's level's sd gains from the fitted sky's departure from the
    spec's, its record or None): log k's rms over the frames of a curve, its level's, or the
    largest over the levels the profile could not tell apart where k is not determined."""
    if fitted.sd_u is not None and np.isfinite(fitted.sd_u):
        log_k = fitted.log_k if fitted.curve is not None else np.log(fitted.k)
        departure = float(np.sqrt(np.mean(log_k ** 2)))
    else:
        departure = float(max(abs(u) for u in level.within))
    widening = (SUN_SKY_COUPLING * departure if plan.sun_source == "modelled" and plan.sun_sd
                else 0.0)
    if not widening:
        return 0.0, None
    return widening, {"given_sd": plan.sun_sd, "coupling": SUN_SKY_COUPLING,
                      "sd": float(np.hypot(plan.sun_sd, widening)),
                      "meaning": "the modelled sun's level's sd (of its log) in the "
                                 "reflectances' intervals: hypot(given_sd, coupling |log k|; "
                                 "log k's rms over the frames), a sky fitted brighter or "
                                 "dimmer against the sun than the spec's saying that the air "
                                 "is not the model's, nor then its sun"}


def fit_sky_scale(sessions, plan, seed=0, log=print):
    """Fit the sky scale k of ``sessions`` (FitSessions of one day, traced with the split
    light of ``plan``, a :class:`~.light.LightPlan`) and leave each lit at the fitted k;
    returns the :class:`SkyFit`: its record and each region's :class:`SkyShare` (the sky's
    share of each parameter's standard error, the sun level's sd).
    ``plan.prior_sd``: the standard deviation of a normal prior on log k about the spec's level
    (:data:`~skyfit_mi.physics.sky.SKY_LEVEL_SD`), None for none (k from the data alone).
    ``plan.terms`` > 1: log k changes smoothly over the day (the sun's height, changing
    weather), as that many Legendre polynomials in time; None: :func:`default_terms` of the
    frames, and no warning where the data hardly tell the terms beyond the level (their prior
    holds them, as it does the intervals); sessions traced with ``plan.shape`` also fit the
    mix of the sky's shape variants (:func:`_fit_curve`), both from the day's level found
    first (:func:`_profile_level`)."""
    t0 = time.perf_counter()
    terms, told = plan.terms, plan.terms is not None
    if not told:
        terms = default_terms(len({i for s in sessions for i in s.obs.frames}),
                              _referenced(sessions[0].doc))
    level = _profile_level(sessions, plan.prior_sd, seed)
    warnings = _level_warnings(level, terms)
    light_terms = default_level_terms(sessions[0].doc,
                                      len({i for s in sessions for i in s.obs.frames}))
    fitted = _fit_terms(sessions, level, terms, told, warnings, light_terms)
    widening, coupling = _sun_coupling(plan, level, fitted)
    profile = sorted(level.profile)
    record = {"fitted": "the sky's level (all but the sun's disc) against the spec's, relative "
                        "to the sun: k, shared by every region"
                        + (" and frame of the fit" if fitted.curve is None else
                           ", smooth over the day (terms)"),
              "k": fitted.k, "interval95": fitted.interval, "determined": level.determined,
              "regions": [s.name for s in sessions], "chi2": fitted.chi2,
              "dof": sum(s.problem.dof for s in sessions)
              - (len(fitted.correlation["names"]) if fitted.correlation else 1),
              "interval_scale_s2": level.s2,
              "regions_agree": None if level.agree is None else {
                  **level.agree, "meaning": "Q: the sum over regions of each one's chi-square "
                  "at the pooled level above its own least, over s^2 (chi-square with dof "
                  "R - 1 where one light lights them all as the model says); where p < "
                  f"{unc.MISFIT_P:g} the data's information on the sky is divided by scale = "
                  "Q / dof in every interval; by_region: each region's own least level k"},
              "prior": None if plan.prior_sd is None else {
                  "log_k_sd": plan.prior_sd, "meaning": "log k ~ N(0, sd^2) about the spec's "
                  "sky, from how measured skies scatter about the models; its penalty (log k / "
                  "sd)^2 is in the profile"},
              "profile": {"meaning": "the regions' least chi-square over one level k for "
                                     "the day, the search's first stage (chi2 above: at the "
                                     "fitted sky, its curve and shape included)",
                          "k": [float(np.exp(u)) for u in profile],
                          "chi2": [level.data(u) for u in profile]},
              "terms": fitted.curve, "light_level": fitted.light_curve,
              "shape": fitted.shape, "departure": fitted.departure,
              "correlation": fitted.correlation,
              "sun_coupling": coupling,
              "warnings": warnings, "time_s": time.perf_counter() - t0}
    log(_sky_log(record, fitted, len(sessions), plan.prior_sd, terms))
    return SkyFit(record, {s.name: SkyShare(record, sd, sp, widening, light)
                           for s, sd, sp, light in zip(sessions, fitted.sd, fitted.span,
                                                       fitted.lights or [None] * len(sessions))})


def _sky_log(record, fitted, regions, prior_sd, terms):
    """The log's lines on the fitted sky (``record``, ``fitted``)."""
    ends = [f"{v:.3f}" if v is not None else "open" for v in record["interval95"]]
    curve, shape = fitted.curve, fitted.shape
    return (f"sky: the sky's level fitted with {regions} region(s)"
            + ("" if prior_sd is None else f" and its prior (sd {prior_sd:g} in log k)")
            + f": k = {fitted.k:.3f} (95%: {ends[0]}-{ends[1]}) times the spec's, against the sun"
            + ("" if curve is None else f", changing over the day as {terms} terms: "
               + _curve_text([v[0] for v in curve["k_by_frame"].values()]))
            + ("" if fitted.light_curve is None else
               "; the whole light's level over the day {:.3f}-{:.3f} times the spec's".format(
                   *(f([v[0] for v in fitted.light_curve["level_by_frame"].values()])
                     for f in (min, max))))
            + ("" if shape is None else "; its shape: " + ", ".join(
                f"{of} {name} {v[0]:.{2 if abs(v[0]) >= 1 else 3}f} +- "
                f"{v[1]:.{2 if abs(v[0]) >= 1 else 3}f}"
                for (of, v), name in zip(shape["index"].items(), fitted.index_names)))
            + ("" if shape is None or "levels_by_frame" not in shape else
               ", which puts the sun's light at {:.2f}-{:.2f} and the sky's at {:.2f}-{:.2f} of "
               "the spec's over the frames".format(*_ranges(shape["levels_by_frame"])))
            + ("" if fitted.departure is None else
               "; its departure from the model: " + ", ".join(
                   f"{b} {a:+.3f} +- {e:.3f}" for b, a, e in zip(
                       BASIS, fitted.departure["weights"], fitted.departure["sd"]))
               + f" (prior sd {DEPARTURE_SD:g})")
            + f" ({record['time_s']:.1f} s)"
            + "".join(f"\n  warning: {w}" for w in record["warnings"]))
