"""Model selection: lobe families and parameter counts ranked by held-out frames.

Every candidate is a lobe (a ``normalisation``: Ward's, Duer's, the balanced one or a microfacet
lobe of :mod:`~skyfit_mi.physics.microfacet`) with a parameterisation (2, 3 or 5 parameters). The
light is traced once per lobe and each candidate judged by K-fold cross-validation over
interleaved frame folds: each fold's chi-square (thesis eq. 6.2) at the other folds' minimum,
summed, which rewards predicting unseen light, not following noise. AIC (chi2 + 2 k) and BIC
(chi2 + k ln n) of the full fit are reported beside it.
"""

import time
from dataclasses import replace

import numpy as np

from ..pipeline.manifest import is_table
from ..pipeline.observation_table import relative_scale
from ..render.basis_table import TableModel
from ..render.fit_model import PARAMETERS, bounds
from .chi2 import LuminanceModel, Problem, subsample_region, usable_values
from .fit import (FitCache, FitSession, fit_sessions, prepare_sessions, resolve_light,
                  trace_sessions)
from .held_out import frame_folds
from .light import SPEC_LIGHT, LightOptions
from .sky_fit import skies_at_level
from ..errors import SkyfitError
from .methods.global_search import global_search
from .methods.levenberg_marquardt import polish

#: The candidates of ``--model auto``: the thesis's Ward lobe, the balanced one, and the four
#: microfacet lobes; every parameterisation of each.
FAMILIES = ("ward", "balanced", "beckmann_plastic", "ggx_plastic", "beckmann_metal",
            "ggx_metal")
MODELS = tuple(PARAMETERS)
#: Folds of the cross-validation over frames.
FOLDS = 4
#: Fewest frames with values a ranking by held-out frames takes: with two, each fold fits on one
#: frame's light and the ranking says little (a 3-parameter model 350x worse in chi-square won).
RANK_FRAMES = 3
#: The ranking's cheaper light cache: most positions per pixel and the sky plan
#: (:data:`~skyfit_mi.render.light_cache.SKY_PLANS`); the chosen candidate is traced again at
#: the fit's own (docs/BENCHMARKS.md, "Lobe families").
RANK_POSITIONS, RANK_PLAN = 8, "anchors"
#: Most pixels of an image region the ranking takes (a seeded subset of the fit's pixels), most
#: points of a table's region (each lit by every light), and the grid minima it polishes
#: (docs/BENCHMARKS.md, "Lobe families").
RANK_PIXELS, RANK_POINTS, RANK_CANDIDATES = 16, 32, 1


def cross_validate(session, model, folds=FOLDS, scale=1.0):
    """One candidate on a traced :class:`~.fit.FitSession`: summed held-out chi-square over
    ``folds``, the full fit's chi-square, parameters and dof, AIC and BIC; chi-squares and
    counts times ``scale``, the fit's data over the session's (:func:`information`)."""
    obs, table = session.obs, session.table
    wm = TableModel(table, model)
    wm = LuminanceModel(wm) if obs.luminance else wm
    full = Problem(obs, wm, valid=table.hit)
    lo, hi = bounds(model)
    # the global minimum, its grid on the table's lobes (the same for any model)
    res = global_search(full, 0.5 * (lo + hi), lo, hi, candidates=RANK_CANDIDATES,
                        profile=False, grid_basis=session.grid_bases()[0])
    theta, chi2 = np.asarray(res["theta"], dtype=float), float(res["chi2"])
    held_out, n_held = 0.0, 0
    for train, test in frame_folds(full.valid, folds):
        try:                                  # a fold too small to fit on is left out
            train = Problem(obs, wm, valid=train)
        except SkyfitError:
            continue
        # each fold's minimum polished from the whole data's (a global search per fold is
        # slower for the same choices); its held-out values however few
        r = Problem(obs, wm, valid=test, held_out=True).residuals(
            polish(train, theta, lo, hi)["theta"])
        held_out += float(r @ r)
        n_held += r.size
    if not n_held:
        raise SkyfitError(f"--model auto: no fold of frames leaves enough values to fit the "
                          f"{model} model on ({full.n_data} values in all); give --model.")
    n, p = round(full.n_data * scale), full.n_params
    held_out, n_held, chi2 = held_out * scale, round(n_held * scale), chi2 * scale
    return {"normalisation": table.normalisation, "model": model, "parameters": p,
            "held_out_chi2": held_out, "held_out_values": n_held,
            "held_out_chi2_per_value": held_out / max(n_held, 1),
            "chi2": chi2, "dof": n - p, "aic": chi2 + 2 * p, "bic": chi2 + p * np.log(n),
            "theta": dict(zip(PARAMETERS[model], theta.tolist()))}


def information(obs):
    """Sum of (y / sigma)^2 over a region's usable values: what chi-square differences of
    relative misfits grow with (errors that JPEG blocks share counted through sigma)."""
    ok = np.isfinite(obs.sigma) & (obs.sigma > 0)
    return float(np.sum((obs.y[ok] / obs.sigma[ok]) ** 2))


def rank(sessions, models=MODELS, folds=FOLDS, log=print, scale=1.0):
    """Every candidate of ``sessions`` (one per lobe) and ``models``, best held-out first
    (``scale``: :func:`cross_validate`'s)."""
    rows = []
    for s in sessions:
        for m in models:
            t0 = time.perf_counter()
            row = cross_validate(s, m, folds, scale)
            row["wall_time_s"] = time.perf_counter() - t0
            rows.append(row)
            log(f"{s.name}: {row['normalisation']} {m}: held-out chi2 "
                f"{row['held_out_chi2']:.5g}, AIC {row['aic']:.5g}, BIC {row['bic']:.5g}")
    rows.sort(key=lambda r: r["held_out_chi2"])
    for i, r in enumerate(rows):
        r["rank"] = i + 1
    return rows


def choose(rows):
    """The one-standard-error rule's choice of a ranking (best first): the fewest parameters
    within c sqrt(2 n) (n held-out values) of the best held-out chi-square, then the best among
    those; c = max(1, the best's held-out chi-square per value) counts what the noise model
    leaves out (model error, quantisation) as the variance inflation factor c-hat does
    in QAIC (Burnham & Anderson 2002, *Model Selection and Multimodel Inference*, 2nd ed.).
    Returns (the choice, c)."""
    best = rows[0]
    c = max(1.0, best["held_out_chi2_per_value"])
    near = [r for r in rows if r["held_out_chi2"] <= best["held_out_chi2"]
            + c * np.sqrt(2.0 * max(r["held_out_values"], 1))]
    return min(near, key=lambda r: (r["parameters"], r["held_out_chi2"])), c


def candidate_models(doc, models, luminance):
    """(The parameterisations of ``models`` the sequence ``doc`` can take, why others are left
    out): no white 2-parameter model at unknown scale, no colour model on ``luminance``."""
    why = {}
    if is_table(doc) and relative_scale(doc):
        why["two"] = ("the table's scale is unknown (ingest --unknown-scale), and the "
                      "2-parameter model's surface is white (rho_d + rho_s = 1), which needs it")
    if luminance:
        why["colour"] = "the regions are measured as luminance, which cannot tell colour"
    kept = tuple(m for m in models if m not in why)
    if not kept:
        raise SkyfitError(f"no model of {', '.join(models)} suits this sequence: "
                          + "; ".join(why.values()) + ".")
    return kept, {m: why[m] for m in models if m in why}


def fit_auto(manifest_path, regions, families=FAMILIES, models=MODELS, folds=FOLDS, seed=0,
             log=print, light=LightOptions(), **options):
    """``fit --model auto``: rank every region's candidates (:func:`rank`, on a smaller cache for
    images), then fit the chosen one by the global method; under a fitted sky, ranked at the
    level a Ward fit finds first. Yields each region's result dict with ``model_selection``."""
    options["cache"] = replace(options.get("cache", FitCache()), seed=seed)

    def sessions_of(pixels=None, **kw):
        return {name: FitSession(manifest_path, name, px if pixels is None else pixels[name],
                                 light=None, **{**options, **kw}) for name, px in regions}
    t_start = time.perf_counter()
    first = FitSession(manifest_path, *regions[0], light=None,
                       **{"model": "achromatic", **options})
    frames = int(np.sum(usable_values(first.obs).any(axis=(0, 2))))
    if frames < RANK_FRAMES:
        raise SkyfitError(f"--model auto ranks the models by frames held out, and "
                          f"{regions[0][0]} has values in {frames} frame(s) (at least "
                          f"{RANK_FRAMES}): give --model 2, 3 or 5, or more frames.")
    folds = min(folds, frames)
    models, skipped = candidate_models(first.doc, models, first.obs.luminance)
    for m, why in skipped.items():
        log(f"model selection leaves out the {m} model: {why}")
    plan = resolve_light({regions[0][0]: first}, light, log)        # checked once
    # the ranking's light: image regions on a smaller cache; a table's points as the fit's
    given, table = options["cache"], is_table(first.doc)
    ranking_cache = given if table else replace(
        given, positions=min(RANK_POSITIONS, given.positions or RANK_POSITIONS), plan=RANK_PLAN)
    # the regions at the fit's pixels, with Ward's lobe: the ranking takes a seeded subset of
    # the pixels (a table's points) they can use, its chi-squares scaled by their data over the
    # subset's (information); under a fitted sky they find the level first
    ward = sessions_of(model="achromatic" if first.obs.luminance else "colour")
    usable = {name: s.obs.pixels[np.isfinite(s.obs.sigma).any(axis=(1, 2))]
              for name, s in ward.items()}
    # a table's region of no more usable points than RANK_POINTS is ranked on all its points
    # (None), at the fit's cache: the fit takes its trace
    ranked = {name: None if table and len(px) <= RANK_POINTS else
              list(subsample_region(px, RANK_POINTS, seed)) if table else
              subsample_region(px, RANK_PIXELS, seed) for name, px in usable.items()}
    reuse = {name for name, px in ranked.items() if table and not plan.split and px is None}
    fit_information = {name: information(s.obs) for name, s in ward.items()}
    level = None
    if plan.split:
        # rank in the spec's sky at a Ward fit's level (a wrong level favours lobes that bend);
        # a region that chooses Ward's lobe fits on these sessions' light
        level = prepare_sessions(ward, plan, seed, lambda *a: None).record
    else:
        ward = {}
    ranked_in = ("the spec's light as it is" if level is None else "the spec's sky at the level "
                 f"a fit of Ward's lobe found first (k = {level['k']:.3g})")
    log(f"model selection ranks in {ranked_in}; the chosen models are fitted "
        + ("in it too (fit the chosen model again with --sky to add the sky's level)"
           if not plan.split else f"with the sky's level (--sky {plan.sky})"))
    sessions, trace_s, at_level = {}, {}, {}
    for fam in families:
        t0 = time.perf_counter()
        sessions[fam] = sessions_of(ranked, model=models[0], normalisation=fam,
                                    cache=ranking_cache)
        if level is not None:                     # the spec's light at the level, before tracing
            for name, s in sessions[fam].items():  # (a region's frames alike for every family)
                if name not in at_level:
                    at_level[name] = skies_at_level(s.skies, level, s.obs.times)
                s.skies = list(at_level[name])
        trace_sessions(list(sessions[fam].values()), SPEC_LIGHT)
        trace_s[fam] = time.perf_counter() - t0
    ranking_light = {"positions": next(iter(sessions[families[0]].values()))
                     .cache_settings["positions"],
                     "directions": ranking_cache.directions, "sky_plan": ranking_cache.plan,
                     "most_pixels": None if table else RANK_PIXELS,
                     "most_points": RANK_POINTS if table else None}
    chosen, selection = {}, {}
    shared_s = (time.perf_counter() - t_start) / len(regions)   # the level and the traces
    for name, pixels in regions:
        t_region = time.perf_counter()
        traced = {fam: sessions[fam].pop(name) for fam in families}
        scale = fit_information[name] / information(traced[families[0]].obs)
        rows = rank(list(traced.values()), models, folds, log, scale)
        pick, overdispersion = choose(rows)
        log(f"{name}: chose {pick['normalisation']} {pick['model']} (rank {pick['rank']} of "
            f"{len(rows)} by held-out chi2 over {folds} folds of frames, overdispersion "
            f"{overdispersion:.3g})")
        s = FitSession(manifest_path, name, pixels, model=pick["model"],
                       normalisation=pick["normalisation"], light=None, **options)
        own = s.cache_time
        if name in reuse:          # the table is the same for any parameterisation
            s.take_light(traced[pick["normalisation"]])
        level_light = ward.pop(name, None)
        if level_light is not None and pick["normalisation"] == level_light.normalisation:
            s.take_light(level_light)                 # the level's light, traced for the fit
        reused = s.cache_time - own                   # the traces the fit takes over
        del traced
        chosen[name] = s
        selection[name] = {
            "criterion": f"held-out chi2, {folds}-fold over frames (frame t in fold t mod "
                         f"{folds}), on the ranking light's pixels and scaled to the fit's "
                         f"data (ranking_scale: the sum of (y / sigma)^2 over theirs); "
                         f"the fewest parameters within c sqrt(2 n) of the best (c the best's "
                         f"held-out chi2 per value, at least 1), ranked in {ranked_in}",
            "overdispersion": overdispersion, "ranking_scale": scale,
            "ranked_at_sky": None if level is None else {
                k: level[k] for k in ("k", "interval95", "terms")},
            "ranking_light": ranking_light,
            "folds": int(folds), "chosen": {"normalisation": pick["normalisation"],
                                            "model": pick["model"], "rank": pick["rank"]},
            "left_out": skipped, "trace_time_s": trace_s, "ranking": rows,
            "reused_trace_time_s": reused,
            # the session's setup and the traces it took are in the fit's time
            "wall_time_s": shared_s + time.perf_counter() - t_region - s.cache_time}
    if plan.split:
        for out in fit_sessions(chosen, "global", seed, log=log, light=plan):
            yield _with_selection(out, selection[out["region"]])
        return
    untraced = [s for name, s in chosen.items() if name not in reuse]
    if untraced:               # the chosen lobes at the fit's cache, each lobe's regions together
        trace_sessions(untraced, SPEC_LIGHT)
    for name in list(chosen):
        yield _with_selection(chosen.pop(name).run("global", None, seed, None, log),
                              selection.pop(name))


def _with_selection(out, selection):
    """A chosen model's fit with its selection, its wall time including the selection's."""
    out["model_selection"] = selection
    out["fit_wall_time_s"] = out["wall_time_s"]
    out["wall_time_s"] = out["wall_time_s"] + selection["wall_time_s"]
    return out
