"""The fit result file (``fit_NAME.json``, written by ``skyfit fit``): its one reader.

It is the inverse half's output and, as a spec material (``{ fit = "fit_NAME.json" }``), an
input of the forward half, so it is read here, below both.
"""

import json
from pathlib import Path

import numpy as np

from ..errors import SkyfitError
from ..render.fit_model import PARAMETERS, bounds
from .manifest import FILENAME, is_table, rendered_frames

#: Name of the summary CSV in a fit output folder.
SUMMARY_NAME = "fits.csv"
#: The summary of a per-pixel map (`skyfit fit --per-pixel`), beside its parameters' EXR planes.
MAP_SUMMARY = "map_summary.json"


def read_fit_result(path):
    """The fit result in ``path``, checked: region, a model of
    :data:`~skyfit_mi.render.fit_model.PARAMETERS`, its parameters finite, within bounds and with
    95% intervals [lo, hi], pixels as [x, y] pairs, and any frames, kappa, measured range, draws
    and covariance well formed (the ``_is_*`` checks); SkyfitError saying what is wrong."""
    path = Path(path)
    if path.is_dir():
        raise SkyfitError(f"{path} is a folder; give a fit_NAME.json that `skyfit fit` wrote.")
    try:
        r = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SkyfitError(f"fit file {path} does not exist; give a fit_NAME.json that "
                          "`skyfit fit` wrote.") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SkyfitError(f"fit file {path} is not readable JSON ({exc}); fit the region again "
                          "with `skyfit fit`, or leave the file out.") from None
    if not _is_fit_result(r, PARAMETERS):
        raise SkyfitError(f"{path} is not a fit result of `skyfit fit` (fit_NAME.json: a "
                          f"region, a model of {', '.join(PARAMETERS)}, its parameters and "
                          "their intervals).")
    params = r["parameters"]
    if not all(isinstance(v, (int, float)) and np.isfinite(v) for v in params.values()):
        raise SkyfitError(f"{path} has parameters that are not finite numbers.")
    names = PARAMETERS[r["model"]]
    for k, lo, hi in zip(names, *bounds(r["model"])):
        if not lo <= params[k] <= hi:
            raise SkyfitError(f"{path}: {k} = {params[k]:g} is outside its bounds [{lo:g}, "
                              f"{hi:g}]; give a fit_NAME.json that `skyfit fit` wrote.")
        a, b = r["intervals"][k]["95"]
        if a > b:
            raise SkyfitError(f"{path}: the 95% interval of {k}, [{a:g}, {b:g}], runs backwards "
                              "(lo > hi); give a fit_NAME.json that `skyfit fit` wrote.")
    frames = r.get("frames", [])
    if not (isinstance(frames, list) and all(isinstance(i, int) and not isinstance(i, bool)
                                             and i >= 0 for i in frames)):
        raise SkyfitError(f"{path}: frames must be a list of manifest frame indices (whole "
                          "numbers from 0).")
    me = r.get("model_error")
    held = me.get("held_out") if isinstance(me, dict) else None
    if me is not None and not (_is_kappa(me) and (held is None or _is_kappa(held))):
        raise SkyfitError(f"{path}: model_error must be {{\"kappa\": a finite number >= 0, "
                          "\"held_out\": {\"kappa\": the same, ...}, ...}; give a "
                          "fit_NAME.json that `skyfit fit` wrote.")
    if r.get("sky") is not None and not _is_sky(r["sky"]):
        raise SkyfitError(f"{path}: sky must be {{\"k\": a finite number > 0, \"terms\": null or "
                          "{\"coefficients\": [numbers], \"span_s\": [start, end]}, \"shape\": "
                          "null or {\"mix\": [numbers], \"toward\": {index: 1 or -1}}, ...}; give "
                          "a fit_NAME.json that `skyfit fit` wrote.")
    if r.get("measured_range") is not None and not _is_measured_range(r["measured_range"]):
        raise SkyfitError(f"{path}: measured_range must be {{\"by_channel\": {{channel: null or "
                          "[lo, hi] radiance, lo <= hi}, ...}; give a fit_NAME.json that "
                          "`skyfit fit` wrote.")
    draws = r.get("draws")
    if draws is not None and not _is_draws(draws, len(names)):
        raise SkyfitError(f"{path}: draws must be {{\"values\": a list of [{', '.join(names)}] "
                          "sets of finite numbers, \"added_sd\": one number >= 0 each, "
                          "\"shared_rows\" (where given): a list of such sets, ...}; give a "
                          "fit_NAME.json that `skyfit fit` wrote, or leave out draws.")
    cov = r.get("covariance")
    if cov is not None and not _is_covariance(cov):
        raise SkyfitError(f"{path}: covariance must be {{\"names\": [{', '.join(names)}], "
                          "\"matrix\": a square list of lists of numbers, one row each, no "
                          "variance below 0}.")
    return r


def load_fits(paths):
    """{region: (path, fit result)} from fit JSONs, a ``fits.csv`` (its ``fit_*.json``) or a
    folder of fits; a damaged fit JSON is named, a region given twice refused, and so is a fit
    in a sequence's folder that another run of it made (``render --overwrite`` since)."""
    out = {}
    for p in map(Path, paths):
        if p.is_dir() or p.name == SUMMARY_NAME:
            folder = p if p.is_dir() else p.parent
            files = sorted(folder.glob("fit_*.json"))
            if not files and (folder / MAP_SUMMARY).is_file():
                raise SkyfitError(f"{folder} holds a per-pixel map ({MAP_SUMMARY}), which takes "
                                  "no part in a prediction: give the region fits of its "
                                  "sequence (`skyfit fit SEQUENCE --all`) instead; `skyfit "
                                  "export` takes a map.")
            if not files:
                raise SkyfitError(f"no fit_*.json in {folder}; give the folder `skyfit fit` "
                                  "wrote.")
        elif p.is_file():
            files = [p]
        else:
            raise SkyfitError(f"fit {str(p)!r} does not exist; give fit_NAME.json files, a "
                              "fits.csv or the folder `skyfit fit` wrote.")
        run = _folder_run(p) if p.is_dir() or p.name == SUMMARY_NAME else None
        for f in files:
            r = read_fit_result(f)
            if run is not None and r.get("sequence_run_id") not in (None, run):
                raise SkyfitError(f"{f} was fitted to another run of the sequence in its folder "
                                  f"(run {r['sequence_run_id']}; the folder's frames are run "
                                  f"{run}, rendered or ingested again since): fit again, or name "
                                  "that run's fit files.")
            if r["region"] in out:
                raise SkyfitError(f"region {r['region']!r} is fitted twice ({out[r['region']][0]} "
                                  f"and {f}); give one fit per region.")
            out[r["region"]] = (f, r)
    return out


def check_fit_folder(folder, run_id, regions):
    """Refuse to fit ``regions`` of the sequence run ``run_id`` into ``folder`` where it holds a
    fit of another region of another run (another sequence, or this one rendered or ingested
    again since): its ``fits.csv`` and any relight of the folder would mix the two."""
    if run_id is None:                  # a manifest from before run ids: nothing to tell apart
        return
    for f in sorted(Path(folder).glob("fit_*.json")):
        try:
            r = json.loads(f.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            continue
        other = r.get("sequence_run_id") if isinstance(r, dict) else None
        if other not in (None, run_id) and r.get("region") not in regions:
            raise SkyfitError(f"{folder} holds {f.name}, a fit of another sequence or run "
                              f"(run {other}; this one is run {run_id}), which its {SUMMARY_NAME} "
                              "and a relight of the folder would mix with these: fit every "
                              "region it holds again, fit into another folder (-o), or move "
                              "that fit away.")


def _folder_run(path):
    """The run id of the sequence whose folder holds the fits at ``path`` (a folder or its
    ``fits.csv``); None where it holds no sequence."""
    folder = path if path.is_dir() else path.parent
    try:
        return json.loads((folder / FILENAME).read_text()).get("run_id")
    except (OSError, ValueError, AttributeError):
        return None


def _numbers(v, n=None, kind=(int, float)):
    """Whether ``v`` is a list of finite numbers (``n`` of them, if given; of ``kind``)."""
    return isinstance(v, list) and (n is None or len(v) == n) and all(
        isinstance(x, kind) and not isinstance(x, bool) and np.isfinite(x) for x in v)


def _is_sky(sky):
    """Whether ``sky`` is a sky fit's record as relight and chi2map read it: level k, day curve
    (``terms``) and ``shape`` (the variants' mix and each index's move)."""
    if not (isinstance(sky, dict) and _numbers([sky.get("k")]) and sky["k"] > 0):
        return False
    terms, shape = sky.get("terms"), sky.get("shape")
    if terms is not None and not (isinstance(terms, dict) and _numbers(terms.get("coefficients"))
                                  and terms["coefficients"] and _numbers(terms.get("span_s"), 2)):
        return False
    return shape is None or (isinstance(shape, dict) and _numbers(shape.get("mix"))
                             and isinstance(shape.get("toward", {}), dict)
                             and all(v in (1, -1) and not isinstance(v, bool)
                                     for v in shape.get("toward", {}).values()))


def _is_measured_range(record):
    """Whether ``record`` is the radiance range a fit's data measured, as relight reads it:
    {"by_channel": {channel: null or [lo, hi] (lo <= hi)}}."""
    ranges = record.get("by_channel") if isinstance(record, dict) else None
    return isinstance(ranges, dict) and all(
        v is None or (_numbers(v, 2) and v[0] <= v[1]) for v in ranges.values())


def _is_kappa(record):
    """Whether ``record`` is a dict whose kappa is a finite number >= 0."""
    k = record.get("kappa") if isinstance(record, dict) else None
    return _numbers([k]) and k >= 0


def _is_draws(draws, n):
    """Whether ``draws`` is a fit's draws from its likelihood as relight reads them: a
    non-empty list of sets of ``n`` finite numbers, ``n`` standard errors >= 0 (added_sd), and
    where given a list of ``n`` finite numbers per shared error (shared_rows; relight draws from
    the intervals without them)."""
    if not isinstance(draws, dict):
        return False
    values, rows = draws.get("values"), draws.get("shared_rows", [])
    return (isinstance(values, list) and len(values) > 0
            and all(_numbers(v, n) for v in values)
            and _numbers(draws.get("added_sd"), n) and min(draws["added_sd"]) >= 0
            and isinstance(rows, list) and all(_numbers(r, n) for r in rows))


def _is_covariance(cov):
    """Whether ``cov`` is {"names": [parameter names], "matrix": a row of numbers (or null) per
    name, no variance negative}; another model's names are allowed (relight then takes the
    intervals alone)."""
    if not isinstance(cov, dict) or not isinstance(cov.get("names"), list) \
            or not isinstance(cov.get("matrix"), list):
        return False
    n = len(cov["names"])
    return (all(isinstance(k, str) for k in cov["names"]) and len(cov["matrix"]) == n
            and all(isinstance(row, list) and len(row) == n
                    and all(v is None or (isinstance(v, (int, float)) and not isinstance(v, bool))
                            for v in row) for row in cov["matrix"])
            and all(row[i] is None or row[i] >= 0 for i, row in enumerate(cov["matrix"])))


def _is_fit_result(r, parameters):
    """Whether the JSON value ``r`` has a fit result's keys: region, model (of
    ``parameters``), its parameters, and each one's 95% interval."""
    if not isinstance(r, dict) or not isinstance(r.get("region"), str) \
            or r.get("model") not in parameters:
        return False
    params, intervals, pixels = r.get("parameters"), r.get("intervals"), r.get("pixels", [])
    return (isinstance(params, dict) and set(params) == set(parameters[r["model"]])
            and isinstance(intervals, dict)
            and all(isinstance(intervals.get(k), dict) and _numbers(intervals[k].get("95"), 2)
                    for k in params)
            and isinstance(pixels, list) and all(_numbers(p, 2, int) for p in pixels))


def check_fit_sequence(result, path, doc, where, own=True):
    """SkyfitError unless fit ``result`` (from ``path``) suits the sequence ``doc`` at ``where``:
    with ``own`` (e.g. chi2map) the fitted sequence itself (run, kind, frames rendered); else (a
    relight's target) its frames, checked only on the fit's own sequence."""
    same_run = result.get("sequence_run_id") == doc.get("run_id")
    if own:
        table, of_points = is_table(doc), "points" in result
        if table != of_points:
            fitted = "an observation table's points" if of_points else "image pixels"
            held = "an observation table" if table else "a sequence of images"
            raise SkyfitError(f"{path} is a fit of {fitted}, but {where} is {held}; give the "
                              "sequence the fit was made on.")
        if "sequence_run_id" in result and not same_run:
            raise SkyfitError(f"{path} was fitted to another sequence (run "
                              f"{result['sequence_run_id']}), not to {where} (run "
                              f"{doc.get('run_id')}); give the sequence the fit was made on.")
    rendered = sorted(f["index"] for f in rendered_frames(doc))
    if own or (same_run and rendered):
        missing = sorted(set(result.get("frames", [])) - set(rendered))
        if missing:
            raise SkyfitError(f"{path} lists frame {missing[0]}, which {where} has not rendered "
                              f"(its rendered frames: {rendered}); give the fit JSON that "
                              "`skyfit fit` wrote on this sequence.")
