"""A fit's 68% and 95% intervals from the covariance or the profile of chi-square (thesis ch. 6),
widened by the errors the data share: light cache, calibration, colour matrix, JPEG block
rounding, fitted sky, camera pose (:mod:`~.pose`) and sun level. Functions take the region's
:class:`~.fit.FitSession` ``s`` and its :class:`~.fit.FitState` ``fit``."""

import numpy as np
from scipy.optimize import least_squares

from . import uncertainty as unc
from .geometry import sky_only_limit
from .held_out import predicted_residuals
from .methods.levenberg_marquardt import SINGULAR_CONDITION
from .methods.profile import ProfileOptions, profile_edges, ridge_intervals
from .sky_fit import light_level_sd, photographed
from ..pipeline.ingest import pixel_sigma
from ..pipeline.jpeg_noise import YCC_TO_RGB, shared_error_sd
from ..pipeline.photos import EXIF_LABEL_SD, exif_scaled
from ..render.light_cache import SIGMA_RESOLVED

#: Iterations of each constrained profile fit along a ridge (a poor conditional-mean start).
PROFILE_RIDGE_ITERATIONS = 40


def fit_intervals(s, fit):
    """Set ``fit``'s intervals, data_intervals, rise, cache_noise_chi2, cache_sd and
    sun_level_rows: the covariance's intervals, or the profile's for rho_s and sigma_alpha of a
    global fit (the data's, ``data_intervals`` at 95%), each widened by the cache's,
    calibration's, JPEG rounding's, colour matrix's, sky's and pose's errors and (a factor on
    the reflectances) the sun level's."""
    problem, theta, names = fit.problem, fit.theta, s.names
    lower, upper = s.lower, s.upper
    fit.search_open = {}
    s2k = fit.delta_scale                             # each parameter's scale of Delta chi^2
    cov_iv = unc.covariance_intervals(theta, fit.covariance, lower, upper)
    grid = fit.global_result["profile_linearised"]
    prof = {"sigma_alpha": (grid["sigma_alpha"], grid["chi2_sigma"]),
            "rho_s": (grid["rho_s"], grid["chi2_rho"])}
    ripple = model_noise_allowance(problem, theta, *prof["sigma_alpha"], s2k[-1])
    # the profiles describe the global minimum; a local method is judged against it
    glob = fit.method == "global"
    intervals, rise, walked = {}, {}, []
    for i, p in enumerate(names):
        iv = {lv: (float(cov_iv[lv][0][i]), float(cov_iv[lv][1][i])) for lv in ("68", "95")}
        source = "covariance"
        if p in prof:
            rise[p] = float(np.max(prof[p][1]) - np.min(prof[p][1]))
            if glob:
                # the union of the grid's linearised profile interval and the true chi^2's
                # (methods/profile.py): the first is offset where the sensor clips, the
                # second inherits the cache's narrow-lobe error
                iv = unc.profile_interval(*prof[p], s2k[i], ripple)
                levels = list(iv)
                exact, _, points, gave_up = profile_edges(
                    problem, theta, fit.chi2, i,
                    [unc.LEVELS[lv] * s2k[i] + ripple for lv in levels], lower, upper,
                    fit.curvature_inverse)
                walked += points
                _search_open(fit, p, levels, gave_up, iv["95"], lower[i], upper[i])
                iv = {lv: (min(iv[lv][0], e[0] if e[0] is not None else np.inf),
                           max(iv[lv][1], e[1] if e[1] is not None else -np.inf))
                      for lv, e in zip(levels, exact)}
                source = "profile"
        intervals[p] = {"68": iv["68"], "95": iv["95"], "from": source}
    if glob and poorly_determined(s, theta, intervals, prof, fit.covariance):
        walked += profile_the_rest(s, fit, intervals, ripple)
    for lv in ("68", "95"):
        # every point the profiles walked within the level lies inside every interval
        for i, p in enumerate(names):
            ridge = ridge_intervals(walked, fit.chi2, unc.LEVELS[lv] * s2k[i] + ripple)
            if ridge is not None:
                lo, hi = intervals[p][lv]
                intervals[p][lv] = (min(lo, float(ridge[0][i])), max(hi, float(ridge[1][i])))
    fit.data_intervals = np.array([intervals[p]["95"] for p in names])
    mc_sd = s.cache_error(theta, fit.method, problem)
    cal_sd = fit.calibration_sd
    sky = fit.sky
    sky_sd = np.zeros(len(names)) if sky.sd is None else sky.sd
    pose_sd = fit.pose.sd_of(len(names))
    sun_rel = light_level_sd(s.doc, names, sky.sun_level_sd(s.light))
    for i, p in enumerate(names):
        for lv in ("68", "95"):
            intervals[p][lv] = unc.widen(theta[i], intervals[p][lv], unc.Z[lv] * np.sqrt(
                mc_sd[i] ** 2 + cal_sd[i] ** 2 + sky_sd[i] ** 2 + pose_sd[i] ** 2
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
    why = sky_only_reach(s, sky.shape_known, intervals, fit)
    if why:
        # where the data's reach ended (before the other errors widened it): below it, any
        # lobe the sky's shape there allows
        intervals["sigma_alpha"]["open_below"] = float(
            fit.data_intervals[names.index("sigma_alpha")][0])
        for lv in ("68", "95"):
            intervals["sigma_alpha"][lv] = (float(lower[-1]), intervals["sigma_alpha"][lv][1])
        intervals["sigma_alpha"]["from"] += ", and down to its bound: " + why
        fit.search_open.pop("sigma_alpha", None)      # the lower end open for the data's reason
    fit.intervals, fit.rise, fit.cache_noise_chi2 = intervals, rise, ripple
    fit.cache_sd = mc_sd
    # the sun's level: one error on every reflectance (rho_s's share its own where a fraction)
    fit.sun_level_rows = unc.level_rows(np.full(3, np.max(sun_rel, initial=0.0)), names, theta,
                                        independent=False)


def sky_only_reach(s, shape_known, intervals, fit=None):
    """Why the roughness's lower end is not determined ('' where it is): in photographs or under
    a modelled sky shape, its 95% ``intervals`` reaches a lobe seen only in the sky's reflection
    (:func:`~.geometry.sky_only_limit`), where narrower lobes differ by less than those errors;
    in photographs also where the means per frame admit a lobe at the limit
    (:func:`frame_means_admit`; docs/BENCHMARKS.md, "The sample board photographed")."""
    shot = photographed(s.doc) and s.obs.rays is None          # photographs, not a table
    if s.names[-1] != "sigma_alpha" or not (shot or not shape_known):
        return ""
    limit = sky_only_limit(s.geometry)
    if intervals["sigma_alpha"]["95"][0] < limit:
        return "the sun's highlight never seen, " + (
            "the photographs' shared errors as large as what tells such lobes apart" if shot
            else "the sky's shape not fitted")
    if shot and fit is not None and limit > 0 and frame_means_admit(s, fit, limit):
        return ("the sun's highlight never seen, and the region's mean in each frame as near "
                f"a lobe of {limit:.3g}, which shows no sun, as its own errors: only the "
                "pattern across the region within a frame tells them apart, which the "
                "photograph's flat field, blocks and pose hold no better")
    return ""


def frame_means_admit(s, fit, sigma):
    """Whether the region's means per frame and channel admit roughness ``sigma`` at 95%: their
    least chi^2 with sigma held rises by under 3.84 times their own misfit (at least 1); each
    mean's variance as :func:`~.held_out.predicted_residuals` takes it plus the frame's JPEG
    block rounding (:func:`jpeg_frame_sd`)."""
    problem, theta = fit.problem, np.asarray(fit.theta, dtype=float)
    _, var, _, told = predicted_residuals(problem, theta, True, frame_calibration_sd(s))
    k = len(theta)
    if told.sum() <= k:
        return False
    ycc = jpeg_frame_sd(s)
    if ycc is not None:
        var = var + ycc ** 2 @ (YCC_TO_RGB ** 2).T
    sd = np.sqrt(np.where(told, var, 1.0))
    use = problem.measured()
    n = np.maximum(use.sum(axis=0), 1)[..., None]

    def misses(th):
        return (predicted_residuals(problem, th, True, None)[0] / sd)[told]

    def slopes(th):          # d misses / d theta: the residuals' own, in DN, over the pixels
        J = problem.jacobian(th, full=True)[1] * problem.obs.sigma[..., None]
        return (np.where(use[..., None], J, 0.0).sum(axis=0) / n / sd[..., None])[told]

    lower, upper = np.asarray(s.lower, dtype=float), np.asarray(s.upper, dtype=float)
    least = 2.0 * least_squares(misses, np.clip(theta, lower, upper), slopes,
                                bounds=(lower, upper)).cost
    held = 2.0 * least_squares(lambda x: misses(np.append(x, sigma)),
                               np.clip(theta[:-1], lower[:-1], upper[:-1]),
                               lambda x: slopes(np.append(x, sigma))[:, :-1],
                               bounds=(lower[:-1], upper[:-1])).cost
    return bool(held - least < unc.LEVELS["95"] * max(1.0, least / (told.sum() - k)))


def calibration_rows(s, J, problem, usable, theta, curvature_inverse):
    """Signed rows (E, n) (:func:`~.uncertainty.rows_sd`), one per independent error of a
    photographed sequence's calibration: each frame's (``per_frame``) or the day's exposure
    error per channel moves its values by e times them, carried by
    :func:`~.uncertainty.shared_error_rows` (frames erring apart bend the day's curve); without
    a reference, the errors of the EXIF labels that scale the given exposure
    (:func:`~skyfit_mi.pipeline.photos.exif_scaled`), each on every channel of the frames with
    that label. A table's are :func:`~.uncertainty.calibration_rows`. Each adds the errors of
    the level every frame shares (:func:`~.uncertainty.shared_level_rows`: the references'
    reflectances', and an uncorrected falloff's between the references and the region)."""
    cal = (s.doc.get("ingest") or {}).get("calibration") or {}
    loading = None if s.obs.rays is not None else exif_scaled(s.doc, s.obs.frames)
    vignetting = unc.region_vignetting(s.doc, s.obs.pixels)
    if loading is None and (s.obs.rays is not None or not cal.get("scale_relative_sd")):
        return unc.calibration_rows(s.doc, s.names, theta, vignetting)
    Js = J * problem.value_scale(theta)[..., None]          # per relative error of a value
    sigma = problem.obs.sigma
    if loading is not None:                       # every channel of a label's frames alike
        rows = unc.shared_error_rows(Js, usable, sigma,
                                     np.full((J.shape[1], 1), EXIF_LABEL_SD), np.ones((3, 1)),
                                     curvature_inverse, loading)
    elif cal.get("per_frame"):
        shared = np.tile(np.asarray(frame_calibration_sd(s), dtype=float),
                         (J.shape[1], 1))
        rows = unc.shared_error_rows(Js, usable, sigma, shared, np.eye(3), curvature_inverse)
    else:                                         # one error per channel for every frame
        P, T, C, n = J.shape
        Js, usable, sigma = (a.reshape((P * T, 1) + a.shape[2:]) for a in (Js, usable, sigma))
        shared = np.asarray(cal["scale_relative_sd"], dtype=float)[None, :]
        rows = unc.shared_error_rows(Js, usable, sigma, shared, np.eye(3), curvature_inverse)
    return np.concatenate([rows, unc.shared_level_rows(s.doc, s.names, theta, vignetting)])


def frame_calibration_sd(s):
    """The relative error (3,) a frame's values share from its own calibration, else None."""
    cal = (s.doc.get("ingest") or {}).get("calibration") or {}
    return cal["frame_relative_sd"] if cal.get("per_frame") else None


def matrix_rows(s, J, problem, usable, theta, curvature_inverse):
    """Signed rows (E, n) (:func:`~.uncertainty.rows_sd`) from the colour matrix (ingest's
    ``colour_matrix`` record, each entry of its error E relative_sd): after grey-card
    calibration channel c reads L_c + sum_(j != c) E_cj (L_j - L_c). Each of the six E_cj is one
    error for the day, carried by :func:`~.uncertainty.shared_error_rows` with the model's
    L_j / L_c at ``theta``; none without the record or for a table."""
    rel = ((s.doc.get("ingest") or {}).get("colour_matrix") or {}).get("relative_sd")
    n = len(s.names)
    if s.obs.rays is not None or not rel:
        return np.zeros((0, n))
    L = problem.model.radiance(theta)
    value = problem.value_scale(theta)
    C = J.shape[2]
    moves = []
    for c in range(C):
        for j in range(C):
            if j == c:
                continue
            with np.errstate(all="ignore"):
                move = np.nan_to_num(value[..., c] * (L[..., j] / L[..., c] - 1.0))
            moves.append(np.where(np.arange(C) == c, float(rel) * move[..., None], 0.0))
    return unc.moved_rows(J, usable, problem.obs.sigma, np.stack(moves, axis=-1),
                          curvature_inverse)


def matrix_note(s):
    """What the colour matrix's error in a fit's intervals is and where it came from."""
    rec = s.doc["ingest"]["colour_matrix"]
    return (f"the camera's colour matrix is taken to err by {100 * rec['relative_sd']:.3g}% "
            f"per entry ({rec['source']}), an error a grey card cannot see (it calibrates "
            "each channel on a grey, whose channels the error mixes alike) and that moves "
            "a saturated colour's weak channels most; the intervals include it")


def jpeg_shared_sd(s, J, usable, sigma, curvature_inverse):
    """Each parameter's standard error (n,) from the JPEG block-mean rounding the region's
    pixels share (:func:`jpeg_frame_sd`); zeros without JPEG frames."""
    shared = jpeg_frame_sd(s)
    if shared is None:
        return np.zeros(len(s.names))
    return unc.rows_sd(unc.shared_error_rows(J, usable, sigma, shared, YCC_TO_RGB,
                                             curvature_inverse))


def jpeg_frame_sd(s):
    """The standard error [DN] (T, 3) in Y, Cb, Cr the region's pixels share in each JPEG frame
    (:func:`~skyfit_mi.pipeline.jpeg_noise.shared_error_sd`); None without JPEG frames."""
    by_index = {f["index"]: f for f in s.doc["frames"]}
    records = [by_index.get(i, {}).get("jpeg_dc") for i in s.obs.frames]
    model = s.doc["sensor"].get("noise_model") or {}
    if s.obs.rays is not None or not any(records) or "read_DN2" not in model:
        return None
    noise = (model["read_DN2"], model["shot_DN"])
    shared = np.zeros((len(records), 3))
    for t, rec in enumerate(records):
        ok = np.all(np.isfinite(s.obs.sigma[:, t]), axis=1)
        if rec and ok.any():
            y = s.obs.y[ok, t]
            shared[t] = shared_error_sd(y, pixel_sigma(y, s.obs.sensor, noise)[0] ** 2, rec)
    return shared


def poorly_determined(s, theta, intervals, profiled, cov):
    """Whether a profiled 95% interval reaches a bound, covers over half the range, or departs
    from the covariance's (1/3x-3x): the others then trade off along a ridge."""
    for i, p in enumerate(s.names):
        if p in profiled:
            lo, hi = intervals[p]["95"]
            span = s.upper[i] - s.lower[i]
            half = unc.Z["95"] * np.sqrt(max(cov[i, i], 0.0))
            sides = np.array([theta[i] - lo, hi - theta[i]]) / max(half, 1e-12)
            if lo <= s.lower[i] + 1e-6 * span or hi >= s.upper[i] - 1e-6 * span \
                    or hi - lo > 0.5 * span or np.any((sides < 1 / 3) | (sides > 3)):
                return True
    return False


def profile_the_rest(s, fit, intervals, ripple):
    """Profile intervals by constrained fits on the true chi-square for the parameters with only
    covariance intervals, each united with its covariance interval, except at a bound or a
    singular curvature, where the quadratic means nothing. Returns the points walked
    [(theta, chi2)]."""
    levels, walked = ("68", "95"), []
    theta = fit.theta
    span = s.upper - s.lower
    quadratic = bool(np.all(np.isfinite(fit.curvature_inverse))
                     and np.all(theta > s.lower + 1e-9 * span)
                     and np.all(theta < s.upper - 1e-9 * span)
                     and np.linalg.cond(fit.curvature_inverse) < SINGULAR_CONDITION)
    for i, p in enumerate(s.names):
        if intervals[p]["from"] != "covariance":
            continue
        exact, _, points, gave_up = profile_edges(
            fit.problem, fit.theta, fit.chi2, i,
            [unc.LEVELS[lv] * fit.delta_scale[i] + ripple for lv in levels],
            s.lower, s.upper,
            fit.curvature_inverse,
            ProfileOptions(rtol=0.01, iterations=PROFILE_RIDGE_ITERATIONS))
        walked += points
        _search_open(fit, p, levels, gave_up,
                     intervals[p]["95"] if quadratic else (np.inf, -np.inf), s.lower[i],
                     s.upper[i])
        for lv, e in zip(levels, exact):
            lo, hi = intervals[p][lv]
            keep_lo, keep_hi = (lo, hi) if quadratic else (np.inf, -np.inf)
            intervals[p][lv] = (min(keep_lo, e[0]) if e[0] is not None else lo,
                                max(keep_hi, e[1]) if e[1] is not None else hi)
        intervals[p]["from"] = "profile (another parameter is poorly determined)"
    return walked


def _search_open(fit, name, levels, gave_up, other, lower, upper):
    """Record in ``fit.search_open`` {name: [(end, farthest x found inside)]} each end of
    ``name``'s 95% interval that its profile took to the bound because the fits beyond failed
    (:func:`~.methods.profile.profile_edges`' ``gave_up``), where the interval's ``other``
    source (lo, hi) puts that end inside the bound: else the data leave it open anyway."""
    for (level, side), x in gave_up.items():
        inside = other[0] > lower if side == 0 else other[1] < upper
        if levels[level] == "95" and inside:
            fit.search_open.setdefault(name, []).append((("lower", "upper")[side], float(x)))


def model_noise_allowance(problem, theta, sigmas, profile, s2):
    """The chi-square the model's Monte Carlo error may add: the largest over the sigma_alpha
    profile's 95% region (the cache's error grows with sigma_alpha), the larger of two
    estimators at each roughness; iterated, as the region widens with the allowance."""
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
