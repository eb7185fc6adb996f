"""The sky's level fitted with the materials: one sun-to-sky scale shared by every region of a day.

The spec's model sky is never the real one (docs/BENCHMARKS.md, "Measured light"); the thesis
names joint estimation of the light as future work (ch. 8.2). The light is split into the sun's
disc and the rest (:meth:`~skyfit_mi.physics.sky.Sky.split`), traced apart, and the rest scaled by
a factor k shared by all regions (radiance is linear in the light,
:func:`~skyfit_mi.render.basis_table.mixed`): one level for the day, then by default a smooth
curve over it (:data:`DEFAULT_TERMS`). k is profiled over the regions' summed least chi-square;
its error, carried by each region's Gauss-Newton response, widens every interval.

Priors hold what the data cannot tell well: the sky's level against the sun's (``--sky prior``,
log k ~ N(0, :data:`~skyfit_mi.physics.sky.SKY_LEVEL_SD` ^2)), and the sun's own level
(``--sun-sd``), which trades exactly with the reflectances and so widens their intervals in
quadrature (:func:`light_level_sd`) unless a scene reference or ``--unknown-scale`` ties them to
the data; its sd comes from :func:`default_sun_sd` and widens with the sky's departure from the
spec's (:data:`~skyfit_mi.physics.sky.SUN_SKY_COUPLING`).
"""

import datetime as dt
import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import chdtrc

from . import uncertainty as unc
from ..conventions import angles_from_direction, time_legendre
from ..errors import SkyfitError
from .methods.levenberg_marquardt import levenberg_marquardt
from ..pipeline.manifest import RENDERED_SOURCES
from ..physics.colour import SRGB_LUMINANCE
from ..physics import sky_shape
from ..physics.sky_departure import BASIS, PRIOR_SD as DEPARTURE_SD, conflict, least_field
from ..physics.sky import MEASURED_SUN_SD, SUN_LEVEL_SD, SUN_SKY_COUPLING
from ..physics.turbid_sky import TURBIDITY_RANGE
from .methods import global_search
from .tone import tone_count

#: Sky scales k searched first: a geometric grid from a quarter to four times the spec's sky.
SCALE_GRID = np.geomspace(0.25, 4.0, 9)
#: Where the least of chi-square and the prior's penalty lies at the grid's end, the search goes
#: on in the grid's steps up to these scales: a very clear sky (Perez clearness 10) gives 0.1-0.7
#: times the diffuse light of the thesis's CIE clear sky (eqs. 4.13, 4.15) over a day, a hazy or
#: broken-cloud sky with the sun out several times it.
SCALE_LIMITS = (1.0 / 16.0, 16.0)
#: The sky's share of a parameter's sd, against the data's, above which the fit warns: sqrt(3)
#: doubles the interval.
SKY_DOMINATES = 3 ** 0.5
#: Half the spacing in log k of the points that refine the profile's least point.
REFINE_STEP = 0.1
#: Most terms of the sky's level over the day (``--sky-terms``), and frames needed beyond them.
MAX_TERMS, FRAMES_BEYOND_TERMS = 4, 2
#: Default terms of the sky's level over the day (:func:`default_terms`): level, drift (P_1) and
#: curve (P_2), the last two under :data:`DRIFT_SD`. The sky-to-sun ratio moves with the sun's
#: height (Ineichen and Perez's clear-sky model, tests/test_sky_fit.py) and the weather; one level
#: lets a sky other than the spec's bend the roughness (docs/BENCHMARKS.md, "the sky test set").
DEFAULT_TERMS = 3
#: Terms of the whole light's level over the day beyond its mean (Legendre P_1, P_2, under
#: :data:`DRIFT_SD`), fitted where a reference saw the light drift (:func:`default_level_terms`):
#: how much sunlight the air takes as the sun sinks is not the model's (docs/BENCHMARKS.md, "The
#: sample board photographed"). Its mean is the exposure's.
LEVEL_TERMS = 2
#: The most frames whose sky level the log lists one by one (more: its ends and range).
CURVE_LISTED = 8
#: Prior sd of each term of log k beyond the day's level (:func:`time_basis`): haze and cloud move
#: the sky's share by tens of percent within hours (the level's own prior is the same).
DRIFT_SD = 0.35
#: Prior sd of the mix of each sky shape variant (``--sky-shape``): 1 is one CIE gradation or
#: indicatrix group, one Perez clearness bin or brightness step
#: (:data:`~skyfit_mi.physics.perez.BRIGHTNESS_STEP`; docs/BENCHMARKS.md, "Sky models against a
#: measured clear sky").
SHAPE_SD = 1.0
#: p-value of the fitted departure under its prior below which the sky is warned to depart from
#: its model more than real skies and published sky models do (:func:`_departure_warnings`).
DEPARTURE_CONFLICT_P = 0.001
#: Step in each term's coefficient of the finite differences of the residuals.
DRIFT_STEP = 1e-3
#: Gauss-Newton iterations of the terms at most.
DRIFT_ITERATIONS = 8
#: A fitted level more than this many prior sds from the spec's (log k = 0) is warned of.
PRIOR_FAR = 3.0
#: The parameters that scale with the light's absolute level (the reflectances).
LEVEL_SCALED = ("C_r", "C_g", "C_b", "R", "rho_s")


@dataclass(frozen=True)
class SkyShare:
    """What the light adds to one region's parameters' errors.

    record : the sky fit's record (:func:`fit_sky_scale`); None where the spec's sky is taken
    sd : the fitted sky's share of each parameter's standard error (None: none)
    span : each parameter's (lowest, highest) over the levels the data cannot tell apart, where
        the sky's level is not determined (else None)
    sun_widening : a modelled sun level's widening from the sky's departure from the spec's
        (:data:`~skyfit_mi.physics.sky.SUN_SKY_COUPLING`)
    light : the fitted coefficients (:class:`FittedLight`), to retake the shares at the region's
        own fit (:func:`share_at`); None where the level is not determined
    response : (n, coefficients) the parameters' response to them at that fit (None before)
    reference_slope : (3, coefficients) d ln f / d coefficients of the per-channel light factor
        f a scene reference sets (:func:`reference_slope`; None: no reference)
    pose_shift : {angle: (coefficients,) their shift for a camera turn of the pose's sd}
        (:func:`~.pose.pose_through_sky`)
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
        """The sun level's relative sd: ``plan.sun_sd`` widened by ``sun_widening``."""
        return float(np.hypot(plan.sun_sd, self.sun_widening))

    @property
    def tone_sd(self):
        """The tone curve's share (n,) of each parameter's standard error, directly and through
        the light's fit (the free coefficients' regression G on the held weights,
        :func:`_held_covariance`), None where the light's fit took none."""
        tone = 0 if self.light is None else self.light.coefficients.tone
        if not tone or self.response is None:
            return None
        C = self.light.covariance                        # _held_covariance's
        held = np.arange(len(C)) >= len(C) - tone
        R = self.response[:, held] + self.response[:, ~held] @ _regression(C, held)
        return _carried_sd(R, C[np.ix_(held, held)])

    @property
    def shape_known(self):
        """Whether the sky's shape is known: the spec's taken as is, or fitted (--sky-shape)."""
        return self.record is None or self.record.get("shape") is not None

@dataclass(frozen=True)
class SkyFit:
    """The sky fit's ``record`` (the fit JSON's ``sky``) and ``shares`` {region: SkyShare}."""

    record: dict
    shares: dict = field(default_factory=dict)


def doubles_interval(fit, sd):
    """Whether another error's share ``sd`` (n,) at least doubles each of ``fit``'s intervals."""
    return np.asarray(sd) > SKY_DOMINATES * np.sqrt(np.maximum(np.diag(fit.covariance), 0.0))


def sunlit(skies):
    """Those of ``skies`` whose sun's disc lights the scene from above the horizon."""
    return [k for k in skies if np.any(k.sun_radiance > 0) and k.sun_direction[2] > 0]


def photographed(doc):
    """Whether a manifest's frames were not rendered by skyfit (the spec's light a model)."""
    return doc.get("source", "render") not in RENDERED_SOURCES


def default_sky(doc, skies):
    """``fit --sky``'s default: 'prior' for photographs under a sky with the sun up, else 'spec'
    (frames rendered under that very light, or no sun to scale the sky against)."""
    sunny = sunlit(skies) and any(k.lit_by_sky for k in skies)
    return "prior" if sunny and photographed(doc) else "spec"


def sun_source(skies):
    """'measured' where every sunlit sky of ``skies`` has ``info["sun_measured"]``, else
    'modelled' (thesis eq. 4.7, a clear-sky model, or a split of the global irradiance)."""
    lit = sunlit(skies)
    return "measured" if lit and all(k.info.get("sun_measured") for k in lit) else "modelled"


def default_sun_sd(doc, skies):
    """``fit --sun-sd``'s default, the sun level's relative sd: for photographs with a measured
    sun, the sunlit skies' stated ``info["sun_sd"]`` (a grey card's) weighted by the sun's
    horizontal irradiance, else :data:`~skyfit_mi.physics.sky.MEASURED_SUN_SD`; with a modelled
    sun :data:`~skyfit_mi.physics.sky.SUN_LEVEL_SD`; 0 for rendered sequences."""
    if not photographed(doc):
        return 0.0
    if sun_source(skies) != "measured":
        return SUN_LEVEL_SD
    lit = sunlit(skies)
    stated = [k.info.get("sun_sd") for k in lit]
    if None in stated:
        return MEASURED_SUN_SD
    sun = np.array([float(k.sun_horizontal_irradiance() @ SRGB_LUMINANCE) for k in lit])
    return float(np.dot(stated, sun) / sun.sum())


def light_level_sd(doc, names, sun_sd):
    """Each parameter's relative error from the sun's level known to ``sun_sd`` (sd of its log):
    the reflectances', the roughness none. Zeros where a scene reference or a relative scale in
    ``doc`` ties the reflectances to the data, and for the white 2-parameter model (rho_d + rho_s
    = 1 fixes the scale: a wrong level shows as misfit)."""
    scale = (doc.get("ingest") or {}).get("scale") or {}
    anchored = _referenced(doc) or scale.get("known") is False
    if anchored or not sun_sd or "C_r" not in names and "R" not in names:
        return np.zeros(len(names))
    return np.array([float(sun_sd) if p in LEVEL_SCALED else 0.0 for p in names])


def _seconds(times):
    """Seconds since the epoch of ISO ``times``."""
    return np.array([dt.datetime.fromisoformat(t).timestamp() for t in times])


def time_basis(times, span, terms):
    """(T, ``terms``) Legendre polynomials of the ISO ``times`` mapped onto [-1, 1] over ``span``
    [s since the epoch], held beyond it: log k(t) = basis @ coefficients."""
    return time_legendre(_seconds(times), span, terms)


def _curve_at(curve, times):
    """A curve's record (:func:`_curve_record`) at the frames' ISO ``times``."""
    return np.exp(time_basis(times, curve["span_s"], len(curve["coefficients"]))
                  @ np.asarray(curve["coefficients"]))


def sky_level_at(record, times):
    """The sky's level k at ISO ``times`` by a sky fit's ``record``: one level, or its curve."""
    terms = record.get("terms")
    return np.full(len(times), float(record["k"])) if terms is None else _curve_at(terms, times)


def light_level_at(record, times):
    """The whole light's level at ISO ``times`` by a sky fit's ``record``, or None."""
    curve = (record or {}).get("light_level")
    return None if curve is None else _curve_at(curve, times)


def skies_at_level(skies, record, times):
    """The frames' ``skies`` (at ISO ``times``) at a sky fit's ``record``'s level and tint."""
    return [sky.sky_scaled(k).tinted(tint)
            for sky, k, tint in zip(skies, sky_level_at(record, times), light_tints(record, times))]


def light_tints(record, times):
    """The per-channel factor (3,) on the light at each ISO ``times`` by a sky fit's ``record``:
    :func:`reference_light_factor` times :func:`light_level_at`; None each where neither is set."""
    factor = reference_light_factor(record)
    level = light_level_at(record, times)
    if factor is None and level is None:
        return [None] * len(times)
    factor = np.ones(3) if factor is None else factor
    return [factor * v for v in (np.ones(len(times)) if level is None else level)]


def reference_light_factor(record):
    """The per-channel light factor (3,) from ``record``'s reference, or None."""
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
    ``skies`` for ``--sky-shape``, every frame's index moved the same way (the mix is shared):
    +1 where every frame can, else -1. Raises SkyfitError where some frame's sky has none (not
    CIE, Perez or turbid) or the frames' skies move different indices."""
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
    """(JSON record of the fitted shape: ``mix``, ``mix_sd`` and each index from + mix (to -
    from) with its 95% half-width; the indices' names for the log)."""
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
    fewer for few frames (one level up to 3). One level where a reference calibrates the frames
    (``referenced``): on a scene of one normal the curve is then nearly collinear with the
    reflectances' scale and adds a valley, not information (scripts/jpeg_colour_coverage.py,
    docs/BENCHMARKS.md). Fitting the reference with the sky would tell the curve: not done yet."""
    if referenced:
        return 1
    return int(max(1, min(DEFAULT_TERMS, int(frames) - FRAMES_BEYOND_TERMS)))


def default_level_terms(doc, frames):
    """The terms of the whole light's level over ``frames`` frames beyond its mean
    (:data:`LEVEL_TERMS`): for photographs whose reference saw the light drift from the spec's
    (ingest's ``calibration.light_drift``), with enough frames; else 0 (without a reference the
    level's curve trades with the materials' lobes)."""
    cal = (doc.get("ingest") or {}).get("calibration") or {}
    if not photographed(doc) or frames < LEVEL_TERMS + 1 + FRAMES_BEYOND_TERMS:
        return 0
    return LEVEL_TERMS if cal.get("light_drift") else 0


def _data_beyond_search(data, grid):
    """-1, +1 or 0 as the data alone (``data`` {log k: summed least chi-square, no prior}) put the
    level at or beyond the lower or upper end of ``grid``, or within it."""
    u = min(data, key=data.get)
    return -1 if u <= grid[0] else 1 if u >= grid[-1] else 0


def _referenced(doc):
    """Whether a scene reference calibrates the frames (``--calibrate``, ``--colorchecker``)."""
    return bool((doc.get("ingest") or {}).get("calibration"))


def _curve_text(k):
    """The log's words for the sky's level ``k`` by frame: each value, or for many its range."""
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
    """The sky's coefficients fitted with the materials, each under a prior N(0, sd^2) about the
    spec's sky: log k over the day as ``terms`` Legendre polynomials in time (the level under
    ``level_sd``, None for none; further terms under :data:`DRIFT_SD`), the mix of the light's
    ``variants`` (shape: :data:`SHAPE_SD`; departure:
    :data:`~skyfit_mi.physics.sky_departure.PRIOR_SD`), then the whole light's level as
    ``light_terms`` polynomials P_1.. (:data:`DRIFT_SD`). They weight the light's traced parts
    (:meth:`~.light.LightParts.table`): k(t) = exp(B(t) u[:terms]), the mix, the level. Last,
    ``tone`` weights of a camera's own tone curve's independent errors (each N(0, 1);
    :func:`~.tone.region_tone`), which scale each value's gain: the camera's, not the light's,
    but told by the same regions and frames (:func:`_fit_curve` holds them at 0)."""

    terms: int
    variants: tuple = ()
    level_sd: float = None
    light_terms: int = 0
    tone: int = 0

    @property
    def names(self):
        """Each coefficient's name, in order."""
        return (["log k"] + [f"log k term {j}" for j in range(1, self.terms)]
                + [f"mix {v.removeprefix('shape:')}" if v.startswith("shape:") else
                   v.replace(":", " ", 1) for v in self.variants]
                + [f"log light term {j}" for j in range(1, self.light_terms + 1)]
                + [f"tone curve {e}" for e in range(1, self.tone + 1)])

    @property
    def columns(self):
        """The Legendre polynomials in time (:func:`time_basis`) the coefficients need."""
        return max(self.terms, self.light_terms + 1)

    @property
    def precision(self):
        """The priors' precision matrix (1 / sd^2 on the diagonal; 0 for no prior)."""
        sd = [self.level_sd] + [DRIFT_SD] * (self.terms - 1) + [
            SHAPE_SD if v.startswith("shape:")
            else DEPARTURE_SD[BASIS.index(v.removeprefix("departure:"))] for v in self.variants] + [
            DRIFT_SD] * self.light_terms + [1.0] * self.tone
        return np.diag([0.0 if v is None else v ** -2 for v in sd])

    def light(self, session, basis, u):
        """Light ``session`` (its frames' time ``basis``, :func:`time_basis`) at coefficients
        ``u``: k(t), the variants' mix, and the whole light's level exp(P_1..(t) u)."""
        J = self.terms + len(self.variants)
        K = J + self.light_terms
        session.set_sky(np.exp(basis[:, :self.terms] @ u[:self.terms]),
                        u[self.terms:J] if self.variants else None,
                        np.exp(basis[:, 1:self.light_terms + 1] @ u[J:K])
                        if self.light_terms else None,
                        u[K:] if self.tone else None)


def _fit_curve(sessions, thetas, u0, coefficients, s2, scale=1.0):
    """Fit the sky's ``coefficients`` (:class:`SkyCoefficients`) with the regions' parameters
    from log k ``u0`` and ``thetas`` there: Gauss-Newton under the priors, each region's
    parameters profiled out (its Jacobian projected off theirs, then polished by
    Levenberg-Marquardt). A camera's tone curve's weights are held at 0, not fitted, their
    error about 0 in the covariance (:func:`_held_covariance`): the day's values hardly tell
    the curve (auto-exposure keeps each surface's codes alike), and fitted they took up what
    the light's model misses (the board photographed through a curved camera: whites 41% low,
    7 gross misses). Leaves each session at the fit. Returns (u, covariance, inverse profiled
    normal matrix (nil on the held weights), span [s], each region's time basis, parameters
    and response (n, coefficients), summed chi-square, the held coefficients' step from 0 the
    data ask for); the covariance divides the data's information (not the priors') by
    ``scale`` (:func:`_regions_agree`)."""
    times = [t for s in sessions for t in s.obs.times]
    span = (float(_seconds(times).min()), float(_seconds(times).max()))
    bases = [time_basis(s.obs.times, span, coefficients.columns) for s in sessions]
    P = coefficients.precision
    u = np.r_[u0, np.zeros(len(P) - 1)]
    thetas = [np.asarray(t, dtype=float) for t in thetas]
    put = coefficients.light

    def objective(u, thetas):
        for s, B in zip(sessions, bases):
            put(s, B, u)
        return sum(s.problem.chi2(t) for s, t in zip(sessions, thetas)) + u @ P @ u

    def linearised(u, thetas, which=None):
        """The profiled normal equations (H, g) at (u, thetas) and each region's response, of
        the coefficients ``which`` (default all; the others' columns 0)."""
        H, g, responses = P.copy(), P @ u, []
        for s, B, theta in zip(sessions, bases, thetas):
            Jp, r, Jt, response = light_response(s, FittedLight(coefficients, B, u), theta,
                                                 which)
            rp = r - Jt @ np.linalg.lstsq(Jt, r, rcond=None)[0]
            H += Jp.T @ Jp
            g += Jp.T @ rp
            responses.append(response)
        return H, g, responses

    current = objective(u, thetas)
    free = np.arange(len(u)) < len(u) - coefficients.tone    # the tone curve's held at 0
    for _ in range(DRIFT_ITERATIONS):
        H, g, _ = linearised(u, thetas, free)           # the held: only at the end
        step = np.zeros_like(u)
        step[free] = -np.linalg.solve(H[np.ix_(free, free)], g[free])
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
    H, g, responses = linearised(u, thetas)
    C = s2 * np.linalg.inv((H - P) / scale + P)
    shift = -np.linalg.solve(H, g)[~free]                # where the data would put the held
    inverse = np.zeros_like(H)                            # the held weights do not move
    inverse[np.ix_(free, free)] = np.linalg.inv(H[np.ix_(free, free)])
    return (u, _held_covariance(C, free, shift), inverse, span, bases, thetas, responses,
            float(chi2), shift)


def _held_covariance(C, free, shift):
    """The coefficients' covariance with those not ``free`` (a tone curve's weights, held at 0:
    :func:`_fit_curve`) taken at their posterior widened by the ``shift`` (the held ones' least-
    squares step from 0 that the data ask for): their error about 0, not about where the data
    would put them, is C_hh + shift shift^T. The free ones: their covariance with the held
    fixed, C_ff - G C_hf (G = C_fh C_hh^-1, their response to the held ones' errors), plus
    G (C_hh + shift shift^T) G^T; so a region's response R = (R_f, R_h) carries the held ones'
    error directly and through the light's fit."""
    held = ~free
    if not held.any():
        return C
    f, h = np.ix_(free, free), np.ix_(held, held)
    G = _regression(C, held)
    Ch = C[h] + np.outer(shift, shift)
    out = np.empty_like(C)
    out[f] = C[f] - G @ C[np.ix_(held, free)] + G @ Ch @ G.T
    out[np.ix_(free, held)], out[np.ix_(held, free)], out[h] = G @ Ch, (G @ Ch).T, Ch
    return out


def _regression(C, held):
    """G (free, held): the free coefficients' regression on the ``held`` ones under covariance
    ``C``, C_fh C_hh^-1."""
    return C[np.ix_(~held, held)] @ np.linalg.inv(C[np.ix_(held, held)])


@dataclass(frozen=True)
class FittedLight:
    """The sky's coefficients as fitted for one region: kind, frames' time ``basis``, values
    ``u``, their ``covariance``, the region's ``theta`` (None while fitting) and the inverse
    profiled normal matrix ``inverse_normal`` (:func:`~.pose.pose_through_sky`)."""

    coefficients: SkyCoefficients
    basis: np.ndarray
    u: np.ndarray
    covariance: np.ndarray = None
    theta: np.ndarray = None
    inverse_normal: np.ndarray = None

    def put(self, session, u=None):
        """Light ``session`` at the coefficients ``u`` (default the fitted)."""
        self.coefficients.light(session, self.basis, self.u if u is None else u)

    def derivative(self, session, value, which=None):
        """d value(session) / d u (..., coefficients) by central differences of
        :data:`DRIFT_STEP`, of the coefficients ``which`` (a mask; default all, the others'
        columns 0); leaves ``session`` lit at the fitted u."""
        columns = []
        for j, step in enumerate(DRIFT_STEP * np.eye(len(self.u))):
            if which is not None and not which[j]:
                columns.append(None)
                continue
            ends = []
            for sign in (1, -1):
                self.put(session, self.u + sign * step)
                ends.append(value(session))
            columns.append((ends[0] - ends[1]) / (2 * DRIFT_STEP))
        self.put(session)
        zero = np.zeros_like(next(c for c in columns if c is not None))
        return np.stack([zero if c is None else c for c in columns], axis=-1)


def light_response(s, light, theta, which=None):
    """(d residuals / d u that the parameters cannot absorb, residuals, d residuals / d theta,
    the parameters' least-squares response (n, coefficients)) of session ``s`` at ``theta`` and
    :class:`FittedLight` ``light``, by central differences of :data:`DRIFT_STEP` (of the
    coefficients ``which``, default all); leaves ``s`` lit at it."""
    Ju = light.derivative(s, lambda s: s.problem.residuals(theta), which)
    r, Jt = s.problem.jacobian(theta)
    response = -np.linalg.lstsq(Jt, Ju, rcond=None)[0]
    return Ju + Jt @ response, r, Jt, response


def _residual_slope(problem, theta):
    """(Model radiance (P, T, 3) at ``theta``, each residual's derivative in it) of ``problem``."""
    L = problem.model.radiance(theta)
    return L, problem.residual_terms(L)[1] * problem.slope(L)


def reference_slope(s, light, theta, lambertian):
    """d ln f / d u (3, coefficients): how the per-channel light factor f a reference sets
    (:func:`~.fit.reference_factor`: its fit ``theta``'s radiance over that of a ``lambertian``
    surface of its known reflectance, summed over the day) moves with ``light``'s coefficients
    u; leaves ``s`` (the reference's session) lit at the fitted u. The fit moves by what its
    parameters cannot absorb (linearised: a grey card's free roughness would respond without
    bound), the Lambertian by the light's change; so a diffuse surface facing as the reference
    reads its reflectance whatever the sky's level (:func:`share_at`)."""
    unabsorbed = light_response(s, light, theta)[0]
    problem = s.problem
    L, per_radiance = (a[problem.mask] for a in _residual_slope(problem, theta))
    channel = np.broadcast_to(np.arange(problem.mask.shape[-1]), problem.mask.shape)[problem.mask]
    moved = np.divide(unabsorbed, per_radiance[:, None], out=np.zeros_like(unabsorbed),
                      where=per_radiance[:, None] != 0)
    fitted = np.array([moved[channel == c].sum(axis=0) / L[channel == c].sum()
                       for c in range(problem.mask.shape[-1])])
    return fitted - light.derivative(
        s, lambda s: np.log(np.sum(s.wm.radiance(lambertian), axis=(0, 1))))


def share_at(s, share, theta):
    """``share`` (:class:`SkyShare`) retaken at the region's own fit ``theta`` (``s`` lit at the
    fitted sky): a final fit away from the search's (a metal's roughness at its bound) responds
    otherwise. With a ``reference_slope`` the response includes the reference factor's
    (d r / d ln f_c through that slope)."""
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
    """Standard errors (n,) carried by ``response`` (n, coefficients) from ``covariance``."""
    return np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", response, covariance, response), 0.0))


@dataclass
class _Level:
    """The day's one sky level profiled over log k (:func:`_profile_level`): ``profile`` {log k:
    [(least chi-square, parameters) per region]}; ``sd_u`` inf where not determined; ``s2`` the
    pooled Birge ratio; ``curvature`` b of chi2 = a + b u^2 at ``u0``."""

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
        """k's 95% interval: from the curvature, else the profile's (None: open at the grid)."""
        if self.determined:
            return [float(np.exp(self.u0 - unc.Z["95"] * self.sd_u)),
                    float(np.exp(self.u0 + unc.Z["95"] * self.sd_u))]
        within = self.within
        return [None if min(within) <= self.grid[0] else float(np.exp(min(within))),
                None if max(within) >= self.grid[-1] else float(np.exp(max(within)))]


def _profile_level(sessions, prior_sd, seed):
    """The day's one sky level (:class:`_Level`): the regions' summed least chi-square on
    :data:`SCALE_GRID`, stepped on beyond its end towards :data:`SCALE_LIMITS` while the least
    lies there, then a parabola in log k; log k's sd from its curvature (Dchi2 = s^2)."""
    rng = np.random.default_rng(seed)
    starts = [s.random_start(rng) for s in sessions]
    level = _Level({}, np.log(SCALE_GRID), prior_sd)

    def total(u):
        u = float(u)
        if u not in level.profile:
            level.profile[u] = _least(sessions, float(np.exp(u)), starts)
        return level.total(u)

    grid = level.grid
    chi2 = [total(u) for u in grid]
    step, (lo, hi) = grid[1] - grid[0], np.log(SCALE_LIMITS)
    while True:
        i = int(np.argmin(chi2))
        if i == 0 and grid[0] - step >= lo - 1e-9:
            grid = np.r_[grid[0] - step, grid]
            chi2.insert(0, total(grid[0]))
        elif i == len(grid) - 1 and grid[-1] + step <= hi + 1e-9:
            grid = np.r_[grid, grid[-1] + step]
            chi2.append(total(grid[-1]))
        else:
            break
    level.grid, chi2 = grid, np.array(chi2)
    edge = i in (0, len(grid) - 1)
    j = min(max(i, 1), len(grid) - 2)
    u0, b_grid = _parabola(grid[j - 1:j + 2], chi2[j - 1:j + 2])
    u0 = float(grid[i] if u0 is None or edge else np.clip(u0, grid[j - 1], grid[j + 1]))
    b = None
    if not edge:                                 # at SCALE_LIMITS no level beyond is fitted
        near = np.array([u0 - REFINE_STEP, u0, u0 + REFINE_STEP])
        vertex, b = _parabola(near, [total(u) for u in near])
        if vertex is not None and abs(vertex - u0) < 2 * REFINE_STEP:
            total(float(vertex))
    # the curvature near the least point, or the grid's where search jitter leaves none
    level.u0 = min(level.profile, key=level.total)
    b = b if b is not None and b > 0 else b_grid
    noise = sum(s.problem.noise_chi2(th)[0]
                for s, (_, th) in zip(sessions, level.profile[level.u0]))
    level.s2 = unc.scale(level.data(level.u0), noise)
    level.edge = edge
    level.agree = _regions_agree(level)
    # at SCALE_LIMITS k is not determined; else the data's curvature (the prior's 1 / sd^2
    # apart) over the regions' disagreement
    if b is not None and b > 0 and not edge:
        prior = 0.0 if prior_sd is None else min(1.0 / prior_sd ** 2, b)
        level.sd_u = float(np.sqrt(level.s2 / ((b - prior) / level.agree["scale"] + prior)))
        level.curvature = float(b)
    else:
        level.sd_u = np.inf
    return level


def _regions_agree(level):
    """Whether the regions agree on the day's one level: Q, the sum over regions of their
    chi-square at the pooled level above their own least (a parabola about it), over s^2, is
    chi-square with R - 1 dof if one light lights them all. Where p < MISFIT_P the data's
    information on the sky is divided by ``scale`` = Q / (R - 1), the Birge ratio between regions
    (the Particle Data Group's scale factor, squared); else 1. Returns {chi2, dof, p, scale,
    by_region: each region's own least k}."""
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


def _level_warnings(level, terms, tone=False):
    """Warnings on the day's one level: not determined, regions disagreeing (``tone``: the
    regions' values read through a camera's own tone curve not exactly known, another cause),
    or held by its prior where the data alone put it beyond the search (a significant
    prior-data conflict)."""
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
            "own lobe)"
            + (", or the camera's own tone curve, not exactly known, reads the brighter and "
               "darker surfaces' codes otherwise than the grey references' (its error is counted in every "
               "interval)" if tone else "")
            + ", so every interval takes the sky's uncertainty widened by that "
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
            "the data alone put the sky's level at or beyond the "
            f"{'highest' if side > 0 else 'lowest'} searched (k = {np.exp(end):.3g} times the "
            "spec's, "
            f"{abs(end) / level.prior_sd:.1f} sd of its prior) as one level for the day, and the "
            f"prior holds that level at k = {k:.3g}: the light the data show departs from the "
            "spec's more than the prior allows, so the parameters and their intervals are not "
            "reliable" + (" unless the level's change over the day takes that up" if terms > 1
                          else "")
            + "; give the spec a sky nearer the day's (a measured one: perez with measured "
            "irradiance, or envmap), or fit several materials with different normals, or a grey "
            "card, together.")
    elif level.prior_sd is not None and level.determined and \
            abs(level.u0) > PRIOR_FAR * level.prior_sd:
        warnings.append(
            f"the sky's fitted level k = {k:.3g} lies {abs(level.u0) / level.prior_sd:.1f} sd of "
            "its prior from the spec's light: the light the data show is far from the spec's "
            "(for a measured sky: its map's orientation, card or scale; for a model sky: its "
            "type or irradiance; else the exposure), and the materials' values rest on the fitted "
            "level.")
    return warnings


def _level_spans(sessions, level):
    """Each region's parameters' (lowest, highest) over an undetermined level's range, or None."""
    if level.determined:
        return [None] * len(sessions)
    return [(np.min(v, axis=0), np.max(v, axis=0))
            for v in (np.array([level.profile[u][n][1] for u in level.within])
                      for n in range(len(sessions)))]


@dataclass
class _Fitted:
    """The sky as fitted (:func:`fit_sky_scale`); records are None where not fitted."""

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
    tone_curve: dict = None
    lights: list = None
    light_curve: dict = None


def _fit_terms(sessions, level, terms, told, warnings, light_terms=0):
    """Fit the sky's level over the day (``terms``, ``told`` by ``--sky-terms``), its shape and
    departure (the variants traced) and the light's level curve (``light_terms``) from the day's
    ``level`` (:func:`_fit_curve`) where that is determined; returns a :class:`_Fitted` and
    appends what the data hardly tell to ``warnings``."""
    thetas = [theta for _, theta in level.profile[level.u0]]
    fitted = _Fitted(float(np.exp(level.u0)), level.interval, level.sd_u,
                     [np.zeros(len(theta)) for theta in thetas], _level_spans(sessions, level),
                     level.data(level.u0))
    J = len(sessions[0].parts.variants)                  # the shape variants traced
    tone = tone_count(sessions)
    if not (terms > 1 or J or light_terms or tone):
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
                                   light_terms, tone)
    u, C, H_inv, span, bases, thetas, responses, fitted.chi2, asked = _fit_curve(
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
    K = terms + J + light_terms
    if light_terms:
        w, Cw = np.zeros(light_terms + 1), np.zeros((light_terms + 1,) * 2)
        w[1:], Cw[1:, 1:] = u[terms + J:K], C[terms + J:K, terms + J:K]
        fitted.light_curve = _curve_record(sessions, w, Cw, span, of="level")[0]
    if J > S:
        a, Ca = u[terms + S:terms + J], C[terms + S:terms + J, terms + S:terms + J]
        suns = np.unique([sky.sun_direction for s in sessions for sky in s.skies], axis=0)
        fitted.departure = _departure_record(a, Ca, suns)
        warnings += _departure_warnings(fitted.departure)
    if tone:
        fitted.tone_curve = {
            "weights": u[K:].tolist(), "sd": sd[K:].tolist(), "asked": asked.tolist(),
            "meaning": "the weights of a camera's own JPEG tone curve's independent errors "
                       "(skyfit_mi.physics.tone_curve.PRIOR_ROOT's columns, each N(0, 1); "
                       "where grey references measured the curve, its posterior's within "
                       "their levels), held at 0 (the codes read through the response's "
                       "curve, or the curve the references measured); asked: the "
                       "step from 0 the regions' values ask for (linearised); sd: their error "
                       "about 0 (what the values leave of the prior, widened by that step), "
                       "through the light's fit and directly in the light's share of every "
                       "interval"}
    fitted.correlation = {"names": coefficients.names,
                          "matrix": (C / np.outer(sd, sd)).tolist()}
    return fitted


def _curve_record(sessions, coefficients, covariance, span, of="k"):
    """(JSON record, log by frame) of a curve over the day of the sky's level k (``of`` 'level':
    the whole light's): Legendre ``coefficients``, ``covariance``, ``span`` [s]."""
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


def _departure_record(a, covariance, suns):
    """The JSON record of the sky's departure weights ``a``, the frames' unit ``suns`` (n, 3)."""
    sd = np.sqrt(np.diag(covariance))
    chi2 = conflict(a)
    least = least_field(a, suns)
    worst = int(np.argmin(least))
    return {"meaning": "the sky other than the sun is the spec's (its level and shape as fitted) "
                       "times 1 + sum_j weights[j] B_j above the horizon, B_j the basis of the "
                       "zenith angle theta and the angle gamma from the sun (u = 2 cos theta - 1, "
                       "y = cos gamma; P1, P2 Legendre), each weight under the prior N(0, "
                       "prior_sd^2) measured from a clear day's scans and published sky models; "
                       "the fit marginalises it "
                       "into every interval; conflict: sum (weights / prior_sd)^2, chi-square "
                       "with len(basis) degrees of freedom under the prior, and its p-value; "
                       "least_field: the field's least value above the horizon over the day's "
                       "suns (below 0 the sky's radiance is negative there), and that sun's "
                       "zenith angle [degrees]",
            "basis": list(BASIS), "weights": np.asarray(a).tolist(), "sd": sd.tolist(),
            "covariance": np.asarray(covariance).tolist(), "prior_sd": DEPARTURE_SD.tolist(),
            "conflict": chi2, "conflict_p": float(chdtrc(len(a), chi2)),
            "least_field": float(least[worst]),
            "least_field_sun_zenith_deg": float(np.degrees(angles_from_direction(suns[worst])[0]))}


def _departure_warnings(departure):
    """Warnings where the departure conflicts with its prior (:data:`DEPARTURE_CONFLICT_P`) and
    where it makes the sky's radiance negative somewhere above the horizon."""
    warnings = []
    least = departure.get("least_field")
    if least is not None and least < 0:
        warnings.append(
            f"the fitted departure makes the sky's radiance negative above the horizon (the "
            f"field, the factor on the model's radiance, reaches {least:+.2f} with the sun "
            f"{departure['least_field_sun_zenith_deg']:.0f} degrees from the zenith): no sky is "
            "like that, so the field stands in for what the spec's sky misses in these "
            "materials' lobes rather than for the sky; parameters resting on that part of the "
            "sky, and relighting under other views or light, may not be reliable; give the spec "
            "a sky nearer the day's (a measured one: perez with measured irradiance, or envmap, "
            "or a sky photographed).")
    if departure["conflict_p"] >= DEPARTURE_CONFLICT_P:
        return warnings
    return warnings + [
        f"the sky departs from the spec's model more than measured skies and published "
        f"models depart from it (its field's weights "
        f"{', '.join(f'{v:+.2f}' for v in departure['weights'])} against prior sds of "
        f"{', '.join(f'{v:g}' for v in DEPARTURE_SD)}; chi-square "
        f"{departure['conflict']:.1f} for {len(departure['weights'])}): the prior holds the "
        "field back, so the parameters and their intervals may not be reliable; give the "
        "spec a sky nearer the day's (a measured one: perez with measured irradiance, or "
        "envmap, or a sky photographed), or fit its shape too (--sky-shape)."]


def fitted_mix(record):
    """The light variants' mix at a sky fit's ``record`` (shape, then departure), or None."""
    mix = list((record.get("shape") or {}).get("mix", [])) \
        + list((record.get("departure") or {}).get("weights", []))
    return mix or None


def _sun_coupling(plan, level, fitted):
    """(A modelled sun level's sd widening by log k's rms over the frames, its record or None)."""
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
    """Fit the sky of ``sessions`` (one day's FitSessions, traced with the split light of
    ``plan``, a :class:`~.light.LightPlan`) and leave each lit at the fit; returns the
    :class:`SkyFit`. ``plan.prior_sd``: sd of log k's prior (None: data alone). ``plan.terms``:
    Legendre terms of log k over the day (None: :func:`default_terms`, with no warning where the
    data hardly tell them); a ``plan.shape`` also fits the sky's shape variants
    (:func:`_fit_curve`), from the day's level found first (:func:`_profile_level`)."""
    t0 = time.perf_counter()
    frames = len({i for s in sessions for i in s.obs.frames})
    terms, told = plan.terms, plan.terms is not None
    if not told:
        terms = default_terms(frames, _referenced(sessions[0].doc))
    level = _profile_level(sessions, plan.prior_sd, seed)
    warnings = _level_warnings(level, terms, tone=bool(tone_count(sessions)))
    light_terms = default_level_terms(sessions[0].doc, frames)
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
              - (len(fitted.correlation["names"]) - len((fitted.tone_curve or {}).get(
                  "weights", [])) if fitted.correlation else 1),
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
              "tone_curve": fitted.tone_curve, "correlation": fitted.correlation,
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
               + f" (prior sds {', '.join(f'{v:g}' for v in DEPARTURE_SD)})")
            + f" ({record['time_s']:.1f} s)"
            + "".join(f"\n  warning: {w}" for w in record["warnings"]))
