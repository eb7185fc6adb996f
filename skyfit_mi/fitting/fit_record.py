"""A fit's JSON-ready record, the layout of ``fit_NAME.json`` (docs/cli.md), from the region's
:class:`~.fit.FitSession` ``s`` and its :class:`~.fit.FitState` ``fit``."""

import numpy as np

from . import uncertainty as unc
from .chi2 import MEASURED_SE
from .draws import root_of
from .held_out import HELD_OUT_FRAMES
from .intervals import matrix_note
from .pose import pose_record
from .tone import TONE_NOTE
from ..pipeline.manifest import photo_cameras
from ..pipeline.observation_table import relative_scale


def fit_record(s, fit, warnings, start, seed, evaluations, wall, t_method):
    """The JSON-ready result of ``fit`` (the layout of ``fit_NAME.json``)."""
    names, theta, dof, sky = s.names, fit.theta, s.problem.dof, fit.sky
    res = fit.method_result
    L = s.wm.radiance(theta)
    chi2 = fit.chi2 if fit.model_error is None else s.problem.chi2(theta)
    return {
        "region": s.name, **({"pixels": s.obs.pixels.tolist()} if s.obs.rays is None
                                else {"points": list(s.obs.pixels)}),
        "model": s.model,
        "normalisation": s.normalisation,
        "method": fit.method, "seed": seed, "start": start.tolist(),
        "parameters": dict(zip(names, theta.tolist())),
        "chi2": chi2, "dof": dof, "chi2_per_dof": chi2 / dof,
        "chi2_expected_from_noise": fit.noise_chi2[0] if fit.model_error is None
        else s.problem.noise_chi2(theta)[0],
        "model_error": model_error_record(s, fit),
        "interval_scale_s2": fit.interval_scale,
        "interval_scale_channels": dict(zip(names, fit.channel_factors.tolist())),
        "channel_correlation": fit.channel_correlation.tolist(),
        "intervals": fit.intervals,
        "readings": [unc.reading(p, theta[i], fit.intervals[p]["95"], s.lower[i],
                                 s.upper[i]) for i, p in enumerate(names)],
        "cache_error_sd": dict(zip(names, fit.cache_sd.tolist())),
        **({"calibration_error_sd": dict(zip(names, fit.calibration_sd.tolist()))}
           if np.any(fit.calibration_sd > 0) else {}),
        "interval_shares": interval_shares(fit, names),
        "interval_shares_meaning": SHARES_NOTE,
        **({"jpeg_shared_error_sd": dict(zip(names, fit.jpeg_shared_sd.tolist())),
            "jpeg_shared_error": "the standard error each parameter takes from the JPEG "
            "frames' rounding of their blocks' means (Y, Cb, Cr), which every pixel of "
            "the region shares in a frame; added in quadrature to the intervals"}
           if np.any(fit.jpeg_shared_sd > 0) else {}),
        **({"tone_curve_error_sd": dict(zip(names, fit.tone_sd.tolist())),
            "tone_curve_error": TONE_NOTE, "tone_curve_cameras": photo_cameras(s.doc),
            "tone_curve_measured": bool(s.doc["ingest"]["tone_curve"].get("weights"))}
           if fit.tone_sd is not None and np.any(fit.tone_sd > 0) else {}),
        **({"colour_matrix_error_sd": dict(zip(names, fit.matrix_sd.tolist())),
            "colour_matrix_error": matrix_note(s)}
           if np.any(fit.matrix_sd > 0) else {}),
        **({"sky": {**sky.record, "error_sd": dict(zip(names, (
            sky.sd if sky.sd is not None else np.zeros(len(names))).tolist())),
            **({} if sky.span is None else {"undetermined_span": {
                p: [float(lo), float(hi)] for p, lo, hi in zip(names, *sky.span)}}),
            "sun_level_sd": sky.sun_level_sd(s.light), "sun_source": s.light.sun_source,
            "sun_level_error_sd": dict(zip(names, fit.sun_level_sd.tolist()))}}
           if sky.record is not None else {}),
        **({"pose": pose} if (pose := pose_record(s, fit.pose)) is not None else {}),
        "cache_noise_chi2": fit.cache_noise_chi2,
        "cache_noise_chi2_by_sigma": fit.model_noise_by_sigma,
        "covariance": {"names": list(names), "matrix": fit.covariance.tolist()},
        **({"draws": draws_record(fit, names)} if fit.draws is not None else {}),
        "evaluations": evaluations, "status": res.get("status"),
        "message": res.get("message"), "warnings": warnings,
        "wall_time_s": wall, "light_cache_time_s": s.cache_time, "method_time_s": t_method,
        "light_cache": s.cache_settings, "geometry": s.geometry,
        "trace": res.get("trace", []), "schedule": res.get("schedule"),
        "truth": s.truth, "units": "reflectances unitless" + (
            " and relative (the table's scale is unknown: radiometric_scale)"
            if relative_scale(s.doc) else "") + ", sigma_alpha rms slope; chi2 in "
        "(DN/DN)^2; observed/model values in DN",
        **({"radiometric_scale": s.doc["ingest"]["scale"]} if relative_scale(s.doc)
           else {}),
        "sequence_run_id": s.run_id, "frames": [int(i) for i in s.obs.frames],
        "series": {"times": s.obs.times, "observed_DN": s.obs.y.tolist(),
                   "model_DN": s.problem.predict(L).tolist()},
        "measured_range": measured_range(s, L),
    }


#: What a fit JSON's ``interval_shares`` are.
SHARES_NOTE = (
    "each parameter's 95% interval as shares of its squared half-width (the wider side): "
    "each error the fit adds to what its data tell, (1.96 sd)^2 over it -- calibration (the "
    "grey card, chart or exposure the frames were calibrated by), sky and sun_level (the "
    "light's level), pose, jpeg_rounding, colour_matrix, light_cache -- and data the rest "
    "(the values' noise and the model's error, by chi-square's profile)")


def interval_shares(fit, names):
    """{parameter: {source: share}} of :data:`SHARES_NOTE`, rounded to 0.001."""
    sources, rows = shared_rows(fit, len(names))
    sources = np.array(sources)
    shared = {k: unc.rows_sd(rows[sources == k]) for k in dict.fromkeys(sources)}
    added = {**{k: shared.get(k) for k in ("calibration", "sky", "sun_level", "pose")},
             "jpeg_rounding": fit.jpeg_shared_sd, "colour_matrix": shared.get("colour_matrix"),
             "light_cache": fit.cache_sd}
    out = {}
    for i, p in enumerate(names):
        lo, hi = fit.intervals[p]["95"]
        half2 = max(hi - fit.theta[i], fit.theta[i] - lo) ** 2
        if not half2 > 0:
            continue
        shares = {k: min(1.0, float((unc.Z["95"] * sd[i]) ** 2 / half2))
                  for k, sd in added.items() if sd is not None and sd[i] > 0}
        shares["data"] = max(0.0, 1.0 - sum(shares.values()))
        out[p] = {k: round(v, 3) for k, v in shares.items()}
    return out


def shared_rows(fit, n):
    """(sources, rows (E, n)): the errors the sequence's light, calibration and pose share, one
    signed row per independent error, its effect on the parameters at one sd of it
    (:func:`~.uncertainty.rows_sd` gives each source's standard errors in the intervals):
    the calibration's and colour matrix's (:mod:`~.intervals`), the fitted light's coefficients
    (each an eigen-direction of their covariance, through the parameters' response to them:
    the sky's level against the sun's moves a lobe's C and rho_s as the fit found), the sun's
    level (a factor on the reflectances) and the camera pose's angles."""
    sky = fit.sky
    parts = {"calibration": fit.calibration_rows, "colour_matrix": fit.matrix_rows,
             "sun_level": fit.sun_level_rows,
             "pose": np.array(list(fit.pose.shifts.values())).reshape(-1, n)}
    if sky.response is not None:
        parts["sky"] = (sky.response @ root_of(sky.light.covariance)).T
    sources, rows = [], []
    for k, r in parts.items():
        r = np.asarray(r, dtype=float).reshape(-1, n)
        r = r[np.any(r != 0, axis=1)]
        sources += [k] * len(r)
        rows.append(r)
    return sources, np.concatenate(rows)


def draws_record(fit, names):
    """The fit's draws (:mod:`~.draws`) as relight reads them, with the shared errors relight
    adds to them: always the light cache's and JPEG block rounding's standard errors
    (added_sd); under other light, those the sequence's light, calibration and pose share
    too, as signed rows (:func:`shared_rows`: one normal each moves every parameter along its
    row). Each parameter's column scaled to at most its 95% interval's Gaussian sd (a linear
    share at a bound, a roughness at 0.5, can exceed the parameter's whole range)."""
    d, n = fit.draws, len(names)
    sources, rows = shared_rows(fit, n)
    iv = np.array([fit.intervals[p]["95"] for p in names], dtype=float)
    cap = (iv[:, 1] - iv[:, 0]) / (2 * unc.Z["95"])
    sd = unc.rows_sd(rows)
    rows = rows * np.divide(np.minimum(sd, cap), sd, out=np.ones(n), where=sd > 0)
    return {"values": d.values.tolist(), "effective_size": d.effective_size,
            "proposals": d.proposals, "rounds": d.rounds,
            "added_sd": np.hypot(fit.cache_sd, fit.jpeg_shared_sd).tolist(),
            "shared_rows": rows.tolist(), "shared_sources": sources,
            "about": DRAWS_NOTE}


#: What a fit JSON's ``draws`` are.
DRAWS_NOTE = (
    "parameter sets (columns in the order of parameters) drawn from the likelihood of the "
    "region's values, exp(-(chi2 - chi2_min) / 2 s), by importance sampling; a relight of "
    "this very sequence draws its bands from them, each widened by added_sd (the light "
    "cache's error and the JPEG blocks' rounding); a relight of other light or another view "
    "widens them by the errors the sequence's light, calibration and pose share too: "
    "shared_rows, one per independent error (its source in shared_sources), each the "
    "parameters' change at one sd of it, each drawn as one normal; each parameter's column "
    "scaled to at most its 95% interval's Gaussian sd")


def measured_range(s, L):
    """The fit JSON's ``measured_range``: per channel, the radiance range the data measured
    (:meth:`~.chi2.Problem.measured_range`); relight flags predictions beyond it."""
    channels = "Y" if s.obs.luminance else "RGB"
    ranges = s.problem.measured_range(L, means=s.obs.rays is None)
    return {"unit": "W m^-2 sr^-1",
            "meaning": "from the least " + ("region mean over the fitted frames"
                                             if s.obs.rays is None else "value")
                       + f" that the data measured (none of its values at the top code, "
                       f"its standard error at most {MEASURED_SE:g} of it) to the greatest "
                       "value below the top code; null: none. A prediction beyond this "
                       "rests on the model alone",
            "by_channel": dict(zip(channels, ranges))}


def model_error_record(s, fit):
    """The fit JSON's ``model_error``: kappa (0 where noise explains chi-square), its meaning
    and, when fitted, its 95% interval and the chi-square with it."""
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
            "a model error"), "held_out": held_out_record(fit)}
    return {"kappa": me.kappa, "interval95": list(me.interval95), "meaning": me.meaning,
            "form": form, "chi2": fit.chi2, "chi2_per_dof": fit.chi2 / fit.problem.dof,
            "values": me.values, **{k: fit.model_error_rounds[k]
                                    for k in ("rounds", "settled")},
            "held_out": held_out_record(fit)}


def held_out_record(fit):
    """The fit JSON's ``model_error.held_out``: the relative error predicting frames left out
    of the fit (:func:`~.held_out.held_out_error`), in-sample kappa included."""
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
