"""The warnings a fit must give its user (method status, sky, sun level, pose, bounds, misfit,
held-out frames, identifiability, geometry, cache noise, colour ambiguity). Each function takes
the region's :class:`~.fit.FitSession` ``s`` and its :class:`~.fit.FitState` ``fit``."""

import numpy as np

from . import uncertainty as unc
from .fit_record import held_out_record
from .geometry import geometry_warnings
from .intervals import matrix_note
from .pose import pose_warnings
from .sky_fit import doubles_interval, photographed
from ..physics.sky import MEASURED_SUN_SD
from ..physics.ward import METAL_THRESHOLD
from ..pipeline.manifest import is_table
from ..pipeline.observation_table import relative_scale

#: Held-out relative error warned of once its 95% interval lies above it; below, relight's
#: bands carry it and it changes no conclusion.
HELD_OUT_NOTE = 0.005
#: The fall of chi-square per unit of a reflectance past its bound of 1 below which the data
#: do not pull past it (a minimum on the bound).
BOUND_PULL = 1e-3
#: Share of the degrees of freedom above which the model's own noise is warned of.
NOISE_SHARE = 0.25
#: Variance widening by correlated channels (:func:`~.uncertainty.channel_factors`) warned of.
CHANNEL_NOTE = 1.1
#: An uncorrected cos^4 falloff between the reference and a region warned of above this.
VIGNETTING_NOTE = 0.01


def beyond_upper_bound(s, fit):
    """The reflectances of ``fit`` (C, R) at their upper bound of 1 whose chi-square still falls
    beyond it (the data brighter than the model allows); one at the bound where chi-square
    rises past it (a white or mirror surface, the truth on the bound) is not named, nor rho_s,
    the specular share of the reflectance (1: all specular, a metal without a diffuse part)."""
    at = [i for i, p in enumerate(s.names)
          if p not in ("sigma_alpha", "rho_s") and fit.theta[i] >= s.upper[i] - 1e-3]
    if not at or fit.problem is None:
        return [s.names[i] for i in at]
    r, J = fit.problem.jacobian(np.asarray(fit.theta, dtype=float))
    # d chi^2 / d theta; a censored value far past its clip has r = 0, dr 0/0: its limit, 0
    slope = 2.0 * np.nansum(r[:, None] * J, axis=0)
    return [s.names[i] for i in at if slope[i] < -BOUND_PULL]


def search_warnings(search_open):
    """A warning for each end of a 95% interval that its profile took to the bound because the
    constrained fits failed beyond some x (``search_open`` {parameter: [(end, x)]})."""
    return [f"{p}: the profile's constrained fits failed on its {end} side beyond the "
            f"farthest point found inside, {p} = {x:.4g} (a singular curvature there), so the "
            f"{end} end of its 95% interval is taken to the bound: the search, not the data, "
            "leaves that end open, and the data may determine it."
            for p, ends in search_open.items() for end, x in ends]


def tone_warnings(s, fit, names):
    """The warning naming the parameters whose interval a camera's own tone curve (measured by
    greys of several levels, or not) at least doubles; none where it counted no curve."""
    if fit.tone_sd is None:
        return []
    led = [p for p, big in zip(names, doubles_interval(fit, fit.tone_sd)) if big]
    if not led:
        return []
    if ((s.doc.get("ingest") or {}).get("tone_curve") or {}).get("weights"):
        return [f"{', '.join(led)}: the camera's own JPEG tone curve, measured by the grey "
                "references' levels and read through, but not exactly (its four terms cannot "
                "follow a camera's curve everywhere), more than the data sets their intervals: "
                "this surface's codes lie far from where the greys calibrate the exposure, or "
                "beyond the greys' levels, where the curve keeps its prior's error; RAW files, "
                "or greys spanning this surface's brightness, narrow it."]
    return [f"{', '.join(led)}: the camera's own JPEG tone curve, not known (read as "
            f"{s.doc['sensor'].get('response', 'srgb')}'s), more than the data sets their "
            "intervals: this surface's codes lie far from the grey references', where "
            "cameras' curves depart most; RAW files, greys of several reflectances in the "
            "frames (a ColorChecker's, or several --calibrate greys at ingest), which "
            "measure the curve, or ingest --exact-curve (codes written from linear values "
            "by software) narrow it."]


def fit_warnings(s, fit):
    """All warnings of ``fit``, in the order the user should read them."""
    names, method, theta, chi2 = s.names, fit.method, fit.theta, fit.chi2
    res, g, intervals = fit.method_result, fit.global_result, fit.intervals
    iv95 = {p: intervals[p]["95"] for p in names}
    warnings = []
    if res.get("status") == "failed":
        warnings.append(f"{method} failed: {res['message']}")
    elif res.get("status") not in (None, "converged"):
        warnings.append(f"{method} did not converge (status {res['status']}): "
                        f"{res['message']}")
    warnings += s.obs.warnings                       # what loading the frames noticed
    if relative_scale(s.doc):
        warnings.append(s.doc["ingest"]["scale"]["meaning"])
    warnings += sky_warnings(s, fit)
    warnings += pose_warnings(s, fit)
    falloff = 2 * unc.region_vignetting(s.doc, s.obs.pixels)
    if falloff > VIGNETTING_NOTE:
        warnings.append(
            "the photographs' lens falloff was not corrected (ingest --vignetting none): this "
            f"region lies where a cos^4 falloff differs by {falloff:.1%} from the reference's "
            "place (or the image's centre), which every reflectance's interval counts as an "
            f"error of {falloff / 2:.1%} (1 sd); ingest with --vignetting cos4, or a flat field "
            "of this lens (--vignetting FLAT), to correct it, or --vignetting corrected if the "
            "camera did.")
    warnings += tone_warnings(s, fit, names)
    led = [p for p, big in zip(names, doubles_interval(fit, fit.matrix_sd)) if big]
    if led:
        warnings.append(f"{', '.join(led)}: {matrix_note(s)}; it, more than the "
                        "data, sets their intervals.")
    top = beyond_upper_bound(s, fit)
    if top:
        fix = ("if its values are not radiances in W m^-2 sr^-1 (an instrument's DN), "
               "ingest the table with --calibrate MATERIAL=REFLECTANCE or --unknown-scale"
               if is_table(s.doc) else "check the exposure (--exposure, --calibrate or "
               "--colorchecker at ingest)" if photographed(s.doc) else None)
        model = ("another lobe or parameter count may (--model auto ranks them)")
        cause = (f"the exposure of these rendered frames is exact, so the model cannot "
                 f"describe them: {model}" if fix is None else
                 f"the model does not describe these data (a misfit beyond their noise): "
                 f"{model}, or {fix}" if fit.model_error is not None else
                 f"{fix}, or, if it is right, {model}")
        warnings.append(f"{', '.join(top)} at the upper bound of 1: the data are brighter "
                        f"than any surface of this model ({s.model}, {s.normalisation} lobe) "
                        "under the frames' light, so the bound, not the data, decides the "
                        f"fit; {cause}.")
    if method != "global" and g["chi2"] < chi2 - max(1.0, 1e-3 * chi2):
        # compare with the global minimum: explains local failures (thesis 7.2)
        warnings.insert(0, f"{method} stopped at chi2 = {chi2:.6g}, but the global search finds "
                        f"chi2 = {g['chi2']:.6g} at " + ", ".join(
                            f"{k} = {v:.4f}" for k, v in zip(names, g["theta"]))
                        + f": {method} ended in a local minimum or on a flat region of "
                        "chi-square from this start (thesis 6.3, 7.2)")
    if fit.model_error is not None:
        warnings.append(unc.model_error_warning(fit.misfit, fit.model_error))
    held = held_out_record(fit)
    if held.get("interval95") is not None and fit.held_out["interval95"][0] > HELD_OUT_NOTE:
        warnings.append(
            f"frames left out of the fit are predicted worse than noise and the "
            f"parameters' spread explain (held-out chi-square {held['chi2_per_value']:.3g} "
            f"per value, p = {held['p']:.2g}, {held['folds']} folds of frames): the model "
            f"misses light it was not fitted to by about {100 * held['kappa']:.2g}% of each "
            f"value (95%: {100 * held['interval95'][0]:.2g}-"
            f"{100 * held['interval95'][1]:.2g}%), which "
            "predictions (relight) include; the parameters describe these frames' "
            "light, not necessarily the surface's: they may not carry to other light, "
            "and their intervals may not hold (not reliable as the surface's own). "
            "Another model (--model auto ranks them by held-out frames) or, under a sky, "
            "its shape fitted with the materials (--sky-shape) may predict better.")
    warnings += search_warnings(fit.search_open or {})
    warnings += unc.misfit(chi2, fit.problem.dof, fit.interval_scale, fit.cache_noise_chi2,
                           fit.noise_chi2, model_error=fit.model_error is not None)
    warnings += unc.identifiability(names, iv95, s.lower, s.upper, fit.rise,
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
        s.geometry, float(theta[-1]), sky_shape_known=fit.sky.shape_known,
        lowest=iv95[names[-1]][0])
    worst = max(fit.model_noise_by_sigma, key=fit.model_noise_by_sigma.get)
    if fit.model_noise_by_sigma[worst] > NOISE_SHARE * fit.problem.dof:
        warnings.append(
            f"the light cache's own Monte Carlo error adds up to "
            f"{fit.model_noise_by_sigma[worst]:.3g} to chi-square (at sigma_alpha = {worst}), "
            f"over {NOISE_SHARE:.0%} of the {fit.problem.dof} degrees of freedom: the data "
            "are more precise than the model, which pulls fits toward the roughness where "
            "its error is small (intervals allow for it); use more --directions and "
            "--positions.")
    if s.model == "colour":
        other = unc.colour_rule_ambiguity(theta, iv95)
        if other is not None:
            kind = "metal" if other[1] >= METAL_THRESHOLD else "plastic"
            warnings.append(
                f"C is grey, so the colour model's plastic and metal readings give the same "
                f"BRDF: the {kind} reading C = {other[0]:.3f} (all channels), rho_s = "
                f"{other[1]:.3f} fits equally well; only rho_d and the specular reflectance "
                "are determined.")
    return warnings


def sky_warnings(s, fit):
    """The fitted sky's warnings, and those of parameters the light sets more than the data."""
    sky, names, plan = fit.sky, s.names, s.light
    if sky.record is None:
        return []
    k = sky.record
    warnings = list(k["warnings"])
    led = [] if sky.sd is None else np.flatnonzero(doubles_interval(fit, sky.sd)).tolist()
    if led:
        parts = [part for part, told in ((", its change over the day", k["terms"]),
                                          (", its shape", k["shape"]),
                                          (", its departure from its model",
                                           k.get("departure"))) if told]
        ref = (k.get("reference") or {}).get("region")
        one = len(led) == 1
        warnings.append(
            f"{', '.join(names[i] for i in led)} depend{'s' if one else ''} on the sky: the "
            f"uncertainty of the fitted sky (its level k = {k['k']:.3g}, 95%: "
            f"{k['interval95'][0]:.3g}-{k['interval95'][1]:.3g}{''.join(parts)}) moves "
            f"{'it' if one else 'them'} by "
            + ", ".join(f"+-{unc.Z['95'] * sky.sd[i]:.3g}" for i in led)
            + f" (95%), at least doubling {'its interval' if one else 'their intervals'}, "
            f"which include{'s' if one else ''} that; "
            + ("more materials or a grey card in the fit would narrow " if ref is None
               else f"that is the light the region sees otherwise than {ref}, which "
                    "calibrates the light (the sky in its lobe's reflection): more materials "
                    "with other normals, or the sky photographed (skyfit sky-series), would "
                    "narrow ")
            + ("it." if one else "them."))
    level = [p for p, big in zip(names, doubles_interval(fit, fit.sun_level_sd)) if big]
    if level:
        warnings.append(
            f"{', '.join(level)} scale with the sun's level, which no data tell (the "
            f"light's absolute scale trades exactly with the reflectances) and which "
            f"is known to +-{100 * sky.sun_level_sd(plan):.0f}% (1 sd, "
            + {"given": "--sun-sd",
               "measured": "the spec's measured direct normal irradiance",
               "modelled": f"the modelled sun's {100 * plan.sun_sd:.0f}%"
               + (" widened as the fitted sky departs from the spec's"
                  if sky.sun_widening else "")}.get(plan.sun_source, "--sun-sd")
            + "): that, more than the data, sets their intervals; their ratios and "
            "sigma_alpha do not depend on it. A reference of known reflectance in the "
            "scene (ingest --calibrate or --colorchecker)"
            + {"measured": "",
               "given": " or a smaller --sun-sd where the sun's level is known better "
                        f"(a measured direct normal irradiance: {MEASURED_SUN_SD:g})"
               }.get(plan.sun_source, " or a measured direct normal irradiance in the "
                     "spec (direct_normal_W_m2, or a dni column)")
            + " narrows them.")
    return warnings
