"""Re-lit reconstructions (thesis 7.4): a target day rendered with fitted materials.

The target is a spec file or a sequence folder; each fit replaces the material its region
measured (``scene.materials.ID.source`` says which), and the output is a sequence folder like
``render``'s. Where the target holds frames, ``relight.json`` and ``relight.csv`` give the relative
RMS error of the relit radiance (thesis fig. 7.14's comparison, as numbers). :func:`predict`
gives each region's radiance per frame without images, with a 95% band from the fit's uncertainty.
"""

import csv
import io
import json
import os
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..conventions import angles_from_direction
from ..errors import SkyfitError
from ..files import FolderLock, ensure_dir, figure_png, write_bytes, write_json, write_text
from .chi2 import subsample_region
from .draws import interval_draws
from .fit import FitCache, FitSession, trace_sessions
from .geometry import ANGLES_BEYOND_DEG, angles_beyond, highlight_beyond
from .held_out import local_error_scale
from .intervals import frame_calibration_sd
from .tone import level_tone, median_codes
from .landscape import truth_parameters
from .sky_fit import light_tints, reference_light_factor, sky_level_at
from .uncertainty import band_half_width, widen
from ..physics.colour import SRGB_LUMINANCE
from ..physics.sky_shape import shape_variants, shaped
from ..pipeline.fit_result import check_fit_sequence
from ..pipeline.illumination import envmap_from_record
from ..pipeline.manifest import (FILENAME, RENDERED_SOURCES, check_frames, frame_axis, frame_label,
                                 frame_sky, is_table, load_manifest, manifest_file, photo_cameras,
                                 read_frame_image, rendered_frames)
from ..pipeline.pixels import frame_values, material_regions
from ..pipeline.observation_table import relative_scale, table_regions
from ..pipeline.sequence import clear_run, render_sequence
from ..pipeline.spec import read_spec, validate_spec
from ..render.image import to_srgb8, write_exr, write_png
from ..render.light_cache import DIRECTIONS

#: Seed offset of the reference render of a synthetic target (its own materials, other noise).
REFERENCE_SEED = 1_000_003
#: Light-cache samples per pixel of a prediction (positions, directions): region means average
#: Monte Carlo error over their pixels, so a sixteenth of a fit's cache; sky integrals by the
#: ``anchors`` plan (light_cache.SKY_PLANS; docs/BENCHMARKS.md, "Tried, not adopted").
PREDICTION_CACHE = (4, 64)


#: The files a relight writes beside its sequence's (and compare_NNNN.png, reference/).
RELIGHT_FILES = ("prediction.csv", "prediction.png", "relight.json", "relight.csv")
#: The folder of the relit frames' sky maps (:func:`light_as_fitted`).
SKY_MAPS = "sky_maps"


def check_output(out, images, overwrite):
    """Refuse an output folder ``out`` holding another run's output, unless ``overwrite``; a
    relit render left unfinished (its manifest, no prediction yet) resumes."""
    out = Path(out)
    held = [n for n in (FILENAME, *RELIGHT_FILES) if (out / n).exists()]
    if held and not overwrite and not (images and held == [FILENAME]):
        raise SkyfitError(f"{out} holds another run's output ({held[0]}); relight into another "
                          "folder, or pass --overwrite to replace it.")


def clear_output(out):
    """Remove an earlier relight's files from ``out`` (--overwrite), and nothing else."""
    out = Path(out)
    if not out.is_dir():
        return
    with FolderLock(out):
        for folder in (out, out / "reference"):
            clear_run(folder)
        for p in [*(out / n for n in RELIGHT_FILES), *out.glob("compare_[0-9]*.png"),
                  *(out / SKY_MAPS).glob("frame_[0-9]*.exr")]:
            p.unlink(missing_ok=True)
        for d in (out / "frames", out / "reference" / "frames", out / "reference",
                  out / SKY_MAPS):
            if d.is_dir() and not any(d.iterdir()):
                d.rmdir()


def target_spec(target, fits, doc=None):
    """(``target``'s validated spec with the fitted materials, its manifest or None)."""
    target = Path(target)
    if target.is_dir() or target.name == FILENAME:
        if doc is None:
            doc, _ = load_manifest(target)
        if not isinstance(doc.get("spec"), dict):
            raise SkyfitError(f"{target} was not rendered from a spec (source "
                              f"{doc.get('source', '?')}); give a spec file as --target.")
        raw, base = doc["spec"], Path(doc.get("spec_dir", "."))
        # the sun where the folder's render put it (lab lights' frames record their own)
        sun = {f["time"]: (f["sun_zenith_deg"], f["sun_azimuth_deg"]) for f in doc["frames"]
               if f.get("illumination", {}).get("kind") == "sky" and "sun_zenith_deg" in f}
    else:
        doc, raw, base, sun = None, read_spec(target), target.parent, None
    raw = dict(raw)
    raw["materials"] = {**raw.get("materials", {}),
                        **{region: {"fit": str(Path(p).resolve())}
                           for region, (p, _) in fits.items()}}
    return validate_spec(raw, base, sun=sun), doc


@dataclass(frozen=True)
class Plan:
    """What a relight makes of its target (:func:`plan_relight`)."""

    target: Path
    #: the target folder's manifest; None for a spec file
    doc: dict | None
    #: the relit images are rendered (else only the prediction)
    render: bool
    #: the target holds observations (frames, or a table's values): errors are reported
    observed: bool
    #: those observations are an observation table (values, no images)
    table: bool
    #: the target's own materials are rendered again with other seeds
    reference: bool


def plan_relight(fits, target, out, images=True, reference=False, overwrite=False):
    """The :class:`Plan` of relighting ``fits`` onto ``target`` into ``out``, inputs checked."""
    target = Path(target)
    is_folder = target.is_dir() or target.name == FILENAME
    if not images and not is_folder:
        raise SkyfitError("a prediction without images needs a sequence folder as --target "
                          "(its light is traced there); give one, or leave out --no-images.")
    doc = load_manifest(target)[0] if is_folder else None
    if doc is not None and Path(out).resolve() == manifest_file(target).parent.resolve():
        raise SkyfitError("the output folder is the target's; give another with -o.")
    for path, r in fits.values() if doc is not None else ():
        check_fit_sequence(r, path, doc, target, own=False)
    if not images and not rendered_frames(doc):
        raise SkyfitError(f"a prediction without images is made at the target's rendered frames, "
                          f"and {target} has none; render it, or leave out --no-images.")
    check_output(out, images, overwrite)
    observed = doc is not None and bool(rendered_frames(doc))
    table = doc is not None and is_table(doc)
    if reference and not (images and observed and not table
                          and doc.get("source") in RENDERED_SOURCES):
        raise SkyfitError("--reference renders a synthetic target's own materials again; it "
                          "needs a target folder that skyfit rendered, and images.")
    return Plan(target, doc, images, observed, table, reference)


def check_sun_up(plan, spec):
    """Refuse a target whose sun is below the horizon in every frame."""
    if spec is not None:
        frames = [(frame_label(f.index, f.time), f.below_horizon) for f in spec.frames]
    else:
        frames = [(frame_label(f["index"], f.get("time")), f.get("below_horizon", False))
                  for f in plan.doc["frames"]]
    if all(below for _, below in frames):
        raise SkyfitError(f"the target's sun is below the horizon in every frame "
                          f"({', '.join(t for t, _ in frames)}); give times of day with the "
                          "sun up (or lab lights above the horizon).")


def relight(fits, target, out, images=True, draws=200, seed=0, log=print, progress=True,
            overwrite=False, reference=False):
    """Render ``target`` with the fitted materials into ``out`` (``images``) and predict each
    region's radiance with its 95% band (``prediction.csv``, ``prediction.png``); with observations
    in the target, write and return the errors (:func:`prediction_errors`) beside the noise floor
    (:func:`noise_floor`). Without ``images`` the target must be a sequence folder and only the
    prediction is made. ``reference`` (a synthetic target) also renders the target's own
    materials with other seeds, to measure Monte Carlo noise."""
    plan = plan_relight(fits, target, out, images, reference, overwrite)
    if plan.doc is not None:            # the target's frames and light, before any writing
        check_frames(plan.doc, manifest_file(plan.target).parent)
    # a prediction alone takes the folder's light as recorded (no re-validation of its spec)
    spec = target_spec(plan.target, fits, plan.doc)[0] if plan.render else None
    check_sun_up(plan, spec)
    level = fitted_sky_level(fits, plan.doc, log)
    # the sequence the prediction takes light and images from: the target, or the relit render;
    # the target's pixels before the render (refusing early), the relit render's after
    predicted = Path(out) if plan.render and not plan.observed else plan.target
    pixels = target_pixels(fits, predicted, seed) if predicted == plan.target else None
    if overwrite:
        clear_output(out)
    if spec is not None and level is not None:
        light_as_fitted(spec, level, plan.target, out, log)
    if plan.render:
        render_sequence(spec, out, overwrite=overwrite, progress=progress, log=log,
                        source="relight")
    ensure_dir(Path(out))
    with FolderLock(out):                      # the render's lock ended with it
        return _predict_and_report(fits, plan, out, spec, predicted, pixels, draws, seed,
                                   overwrite, log)


def _predict_and_report(fits, plan, out, spec, predicted, pixels, draws, seed, overwrite, log):
    """:func:`relight`'s prediction, written with the errors where the target has observations."""
    if pixels is None:
        pixels = target_pixels(fits, predicted, seed)
    prediction = predict(fits, predicted, pixels, draws, seed, log)
    relative = [] if plan.table else sorted(
        region for region, (_, r) in fits.items() if r.get("radiometric_scale"))
    if relative:
        log(f"{', '.join(relative)}: fitted on a relative scale (ingest --unknown-scale), so "
            "their predicted radiances are the true ones times that table's unknown factor")
    write_prediction(prediction, out, "observed" if plan.observed else "relit render",
                     plot=plan.render)
    if not plan.observed:
        return None
    point_errors = None
    if plan.render and not plan.table:
        errors = image_errors(fits, plan, out, pixels, spec, log)
    else:                   # the predicted values against the table's or the frames' means
        errors, point_errors = observed_errors(fits, plan, prediction)
    errors["region_means"] = {region: asdict(m) for region, m in prediction.region_means.items()}
    errors["region_means_note"] = REGION_MEANS_NOTE
    if plan.reference:
        add_reference_errors(errors, fits, plan, out, pixels, overwrite)
    errors["band_coverage"] = band_coverage(prediction.rows)
    errors["bands_drawn"] = {"draws": int(draws), "seed": int(seed),
                             "from": prediction.draws_from}
    if prediction.scales:
        errors["target_scale"] = prediction.scales
    if relative:
        errors["relative_scale_fits"] = relative
    write_errors(errors, out, point_errors)
    log_errors(errors, plan, log)
    return errors


def light_as_fitted(spec, level, target, out, log=print):
    """Light each frame of ``spec`` (of the fitted sequence ``target``) as the sky fit ``level``
    saw it: level k(t), shape (:func:`~skyfit_mi.physics.sky_shape.shaped`), the reference's
    factor and the light's level. Mixed skies and map-lit frames become EXR maps in
    ``out``/SKY_MAPS; a sky that cannot move the fit's way keeps its pattern (logged)."""
    doc, root = load_manifest(target)
    seen = {g["index"]: g for g in doc["frames"] if "illumination" in g}
    shape = level.get("shape")
    departure = (level.get("departure") or {}).get("weights", [])
    factor = reference_light_factor(level)
    kept = []
    for f in spec.frames:
        if f.index in seen:
            f.sky = frame_sky(seen[f.index], root)
        k = sky_level_at(level, [f.time.isoformat()])[0] if f.time else level["k"]
        tint = light_tints(level, [f.time.isoformat()])[0] if f.time else factor
        variants = []
        if shape is not None:
            try:          # none for a sky black above the horizon (the sun down): nothing to mix
                variants = [v for _, v in shape_variants(f.sky, toward=shape.get("toward"))]
            except SkyfitError:
                kept.append(frame_label(f.index, f.time))
            if len(variants) != len(shape["mix"]):
                variants = []
        if variants or departure or f.sky.envmap is not None:
            # a mix no one Sky holds, or a map named by its file (unscaled): a map of its own
            f.sky = _sky_map(f, shaped(f.sky, k, shape["mix"] if variants else [], variants,
                                       departure).tinted(tint), out)
        else:
            f.sky = f.sky.sky_scaled(k).tinted(tint)
    if kept:
        log(f"{', '.join(kept)}: the spec's sky cannot take the fitted shape's moves there; "
            "the spec's pattern at the fitted level")


def _sky_map(frame, sky, out):
    """The shaped ``sky`` of ``frame`` as an ``envmap`` record, its map written to
    ``out``/SKY_MAPS, with the sun's direct normal irradiance (luminance-weighted)."""
    path = ensure_dir(Path(out) / SKY_MAPS) / f"frame_{frame.index:03d}.exr"
    write_exr(path, sky.envmap, {"kind": "sky_map", "units": "W m^-2 sr^-1",
                                 "frame": frame.index, "time": frame.time})
    zenith, azimuth = (float(np.degrees(a)) for a in angles_from_direction(sky.sun_direction))
    rec = {"file": os.path.relpath(path, Path(out)), "ground_albedo": 0.0,
           "sun_solid_angle_sr": sky.sun_solid_angle,
           "direct_normal_W_m2": float(sky.sun_radiance @ SRGB_LUMINANCE) * sky.sun_solid_angle,
           "sun_measured": bool(sky.info.get("sun_measured"))}
    made = envmap_from_record(rec, out, zenith, azimuth)
    made.info.update({k: sky.info[k] for k in ("shape_mix", "sky_level", "departure")
                      if k in sky.info})
    return made


def fitted_sky_level(fits, doc, log=print):
    """The sky fit's record of the fits on the target sequence ``doc`` itself; None for another
    day, the spec's sky, or fits whose levels differ (logged)."""
    if doc is None:
        return None
    levels = {json.dumps([r["sky"]["k"], r["sky"].get("terms")], sort_keys=True): r["sky"]
              for _, r in fits.values()
              if r.get("sky") is not None and r.get("sequence_run_id") == doc.get("run_id")}
    if len(levels) > 1:
        ks = sorted(f"{v['k']:.3g}" for v in levels.values())
        log(f"the fits' sky levels differ ({', '.join(ks)}: "
            "fitted in separate commands); the images take the spec's sky: fit the regions "
            "together (fit --all) for one level")
        return None
    if levels:
        level = levels.popitem()[1]
        log(f"the images take the fitted sky level: k = {level['k']:.3g} times the spec's sky "
            "against the sun" + (", changing over the day" if level.get("terms") else "")
            + ("; and its fitted shape (the images' sky an environment map of it)"
               if level.get("shape") else ""))
        return level
    return None


#: What relight.json's region_means are.
REGION_MEANS_NOTE = (
    "relative RMS error of each region's mean radiance per frame as predicted by the fit's "
    "cached model, at the fit and (a synthetic target in the fit's model and normalisation) "
    "at the true material, whose error is noise alone")


def image_errors(fits, plan, out, pixels, spec, log=print):
    """The relit images in ``out`` against the target's frames (:func:`prediction_errors`), with
    the noise floor (:func:`noise_floor`) and comparison images (:func:`write_comparisons`)."""
    errors = prediction_errors(fits, plan.target, out, pixels)
    errors["shares_target_seeds"] = plan.doc.get("source") in RENDERED_SOURCES and \
        int(plan.doc["render"]["seed"]) == int(spec.render["seed"])
    if errors["shares_target_seeds"]:
        errors["noise"] = ("common random numbers: the relit day is rendered with the "
                           "target's seeds, so their Monte Carlo noise largely cancels, the "
                           "true materials give zero error, and the relit error is the fitted "
                           "materials' difference")
    elif all("radiance_sigma" in f for f in rendered_frames(plan.doc)):
        floor = noise_floor(plan.target, out, pixels, errors["frames"])
        for region, e in errors["regions"].items():
            e["noise_floor_rel_rms"] = floor["regions"][region]
        errors["noise_floor_rel_rms"] = floor["all"]
        errors["noise"] = ("independent noise: noise_floor_rel_rms is the error the two "
                           "sequences' noise alone gives (their radiance_sigma images)")
    else:
        errors["noise"] = ("unknown: the target's frames have no radiance_sigma image, so the "
                           "error that noise alone gives is not known")
        log("the target's frames carry no radiance_sigma image: the error that noise alone "
            "gives is not reported")
    errors["comparison_images"] = write_comparisons(plan.target, out)
    return errors


@dataclass(frozen=True)
class PointError:
    """The relative RMS error of the prediction at one table point and frame (measured channels)."""

    region: str
    point: str
    frame: int
    time: str
    rel_rms: float
    #: whether the fit did not train on the frame (None: the table is not the fit's own)
    held_out: bool | None


def observed_errors(fits, plan, prediction):
    """(``relight.json``'s errors, a :class:`PointError` per point and frame or None) of the
    prediction's rows against the values they were predicted for: a table's points, or without
    images the observed frames' region means; saturated values left out."""
    def error(rows):
        return float(rel_rms(np.array([r.predicted for r in rows]),
                             np.array([r.image for r in rows])))

    compared = [row for row in prediction.rows if not row.saturated]
    times = {row.frame: row.time for row in compared}
    frames = sorted(times)
    regions, point_errors = {}, []
    for region, (path, r) in sorted(fits.items()):
        rows = [row for row in compared if row.region == region]
        trained = (set(r["frames"]) if r.get("sequence_run_id") == plan.doc.get("run_id")
                   and "frames" in r else None)
        by_value, by_frame, by_point = {}, {}, {}
        for row in rows:
            by_value.setdefault((row.point, row.frame), []).append(row)
            by_frame.setdefault(row.frame, []).append(row)
            by_point.setdefault(row.point, []).append(row)
        point_errors += [PointError(region, point, frame, times[frame], error(values),
                                    None if trained is None else frame not in trained)
                         for (point, frame), values in by_value.items()]
        e = regions[region] = {
            "fit": str(path), "frames": len(by_frame), "values": len(rows),
            "rel_rms": error(rows),
            "per_frame": [error(by_frame[f]) if f in by_frame else None for f in frames]}
        if plan.table:
            e.update(points=len(by_point),
                     per_point={point: error(values) for point, values in by_point.items()})
        if trained is not None:
            held = [row for row in rows if row.frame not in trained]
            e["trained_frames"] = [int(i) for i in r["frames"]]
            e["held_out_rel_rms"] = error(held) if held else None
    errors = {"regions": regions, "times": [times[f] for f in frames], "frames": frames,
              "rel_rms": error(compared),
              "unit": "relative RMS of radiance (unitless)",
              "observations": ("an observation table: each point's value predicted at the fit "
                               "(prediction.csv) against the table's; relight.csv per point "
                               "and frame" if plan.table else
                               "each region's mean radiance per frame and channel predicted at "
                               "the fit (prediction.csv) against the observed frames' mean over "
                               "the same pixels (no images rendered); relight.csv per frame")}
    return errors, point_errors if plan.table else None


def add_reference_errors(errors, fits, plan, out, pixels, overwrite=False):
    """Render the synthetic target's own materials again (seeds + REFERENCE_SEED) into
    ``out/reference`` and add their error, independent Monte Carlo noise alone, to ``errors``."""
    doc = plan.doc
    raw = {**doc["spec"], "render": {**doc["spec"].get("render", {}),
                                     "seed": int(doc["render"]["seed"]) + REFERENCE_SEED}}
    ref = Path(out) / "reference"
    render_sequence(validate_spec(raw, Path(doc.get("spec_dir", "."))), ref,
                    overwrite=overwrite, progress=False, log=lambda *a: None,
                    source=doc["source"])
    measured = prediction_errors(fits, plan.target, ref, pixels)
    for region, e in errors["regions"].items():
        e["reference_rel_rms"] = measured["regions"][region]["rel_rms"]
    errors["reference_rel_rms"] = measured["rel_rms"]
    errors["reference"] = ("the target's own materials rendered again with seed + "
                           f"{REFERENCE_SEED} (in reference/): its error is what "
                           "independent Monte Carlo noise alone gives")


#: Why a prediction lies beyond what a fit's data measured (:func:`beyond_data`), in words.
BEYOND_WORDS = {"below": "dimmer than their noise let them tell",
                "above": "brighter than the brightest value they measured below the top code",
                "unmeasured": "in a channel they never measured",
                "highlight": "in a sun highlight nearer the mirror direction than they saw",
                "angles": f"at sun and view angles over {ANGLES_BEYOND_DEG:.0f} degrees from "
                          "any they saw"}


def band_coverage(rows):
    """The share of ``rows``' image values inside their band (saturated left out), that share
    within the radiance the fits measured, and the number beyond it (:func:`beyond_data`)."""
    rows = [row for row in rows if not row.saturated]
    within = [row.inside for row in rows if not row.beyond]
    why = Counter(row.beyond for row in rows if row.beyond)
    return {"share": float(np.mean([row.inside for row in rows])), "values": len(rows),
            "within_measured": {"share": float(np.mean(within)) if within else None,
                                "values": len(within)},
            "beyond_measured": len(rows) - len(within),
            "beyond_measured_by": dict(sorted(why.items())),
            "band": "95%, from the fits' likelihood draws (under other light or from "
                    "another camera widened by the errors the fitted day's light, calibration "
                    "and pose share; from the intervals where a fit has no such draws); "
                    "beyond_measured: values predicted beyond what the fits' data "
                    "measured, where the band is the model's alone, by why ("
                    + "; ".join(f"{k}: {v}" for k, v in BEYOND_WORDS.items()) + ")"}


def log_errors(errors, plan, log=print):
    """Log the errors of :func:`relight` and the band's coverage."""
    compared = ("predicted values differ from the table's" if plan.table
                else "relit radiance differs from the observed" if plan.render
                else "predicted region means differ from the observed")
    for region, e in errors["regions"].items():
        held, floor = e.get("held_out_rel_rms"), e.get("noise_floor_rel_rms")
        where = (f"{e['points']} points" if plan.table else f"{e['pixels']} pixels" if plan.render
                 else f"{e['values']} values")
        log(f"{region}: {compared} by {e['rel_rms']:.2%} rms ({e['frames']} frames, {where})"
            + (f"; {held:.2%} on the frames the fit did not see" if held is not None else "")
            + (f"; noise alone gives {floor:.2%}" if floor is not None else "")
            + (f", a re-render of the truth {e['reference_rel_rms']:.2%}"
               if "reference_rel_rms" in e else ""))
    for region, m in errors["region_means"].items():
        if plan.render or plan.table:
            log(f"{region}: predicted region means differ from the observed by {m['fit']:.2%} "
                "rms" + ("" if m["truth"] is None else f" (the true material's: {m['truth']:.2%})"))
        elif m["truth"] is not None:                # the fit's own are the line above
            log(f"{region}: the true material's region means differ by {m['truth']:.2%} rms")
    if plan.render and not plan.table:
        log(f"overall: {errors['rel_rms']:.2%} rms" + (
            " (relit with the target's seeds: Monte Carlo noise largely cancels, so this is "
            "the materials' difference)" if errors["shares_target_seeds"] else ""))
    coverage = errors["band_coverage"]
    within, beyond = coverage["within_measured"], coverage["beyond_measured"]
    why = ", ".join(f"{n} {BEYOND_WORDS[k]}" for k, n in coverage["beyond_measured_by"].items())
    log(f"{'table values' if plan.table else 'observed region means'} inside the predicted "
        f"95% band: {coverage['share']:.0%} of {coverage['values']}"
        + (f" ({within['share']:.0%} of the {within['values']} within what the fit's data "
           f"measured; {beyond} beyond it rest on the model alone: {why})"
           if beyond and within["values"] else
           f" (all {beyond} beyond what the fit's data measured, the model's alone: {why})"
           if beyond else ""))


def target_pixels(fits, target, seed=0, max_pixels=64):
    """{region: (P, 2) pixels} at which each fit is compared in ``target``: its own on its own
    sequence, else the material's interior (at most ``max_pixels``); None for a table."""
    doc, root = load_manifest(target)
    out, seen = {}, None
    if is_table(doc):                       # an observation table: every point of the region
        measured = table_regions(root)
        for region in fits:
            if region not in measured:
                raise SkyfitError(f"the target's observation table measures no point of region "
                                  f"{region!r}; it measures: {', '.join(measured)}.")
        return {region: None for region in fits}
    for region, (_, r) in fits.items():
        if r.get("sequence_run_id") == doc.get("run_id"):
            out[region] = np.asarray(r["pixels"], dtype=int)
            continue
        if seen is None:
            try:
                seen = dict(material_regions(target))
            except SkyfitError:                   # it sees no material at all
                seen = {}
        if region not in seen:
            raise SkyfitError(f"the target's camera does not see region {region!r} away from "
                              "its edges; choose a target camera that sees it.")
        out[region] = subsample_region(seen[region], max_pixels, seed)
    return out


def rel_rms(pred, obs, axis=None):
    """rms(``pred`` - ``obs``) / rms(``obs``) over ``axis`` (default all)."""
    return np.sqrt(np.mean((pred - obs) ** 2, axis=axis)) / np.sqrt(np.mean(obs**2, axis=axis))


def prediction_errors(fits, observed, relit, pixels):
    """Relative RMS error of the relit radiance against the observed at each region's ``pixels``
    over the frames both hold: {"regions": {region: {...}}, "rel_rms", "times"}."""
    obs_doc, _ = load_manifest(observed)
    new_doc, _ = load_manifest(relit)
    both = sorted({f["index"] for f in rendered_frames(obs_doc)}
                  & {f["index"] for f in rendered_frames(new_doc)})
    if not both:
        raise SkyfitError("the target and the relit sequence share no rendered frame.")
    times = [f.get("time") for f in obs_doc["frames"] if f["index"] in both]
    regions, all_pred, all_obs = {}, [], []
    for region, (path, r) in sorted(fits.items()):
        px = pixels[region]
        o = frame_values(observed, px, both)
        p = frame_values(relit, px, both)
        regions[region] = {"fit": str(path), "pixels": len(px), "frames": len(both),
                           "rel_rms": float(rel_rms(p, o)),
                           "per_frame": rel_rms(p, o, axis=(0, 2)).tolist()}
        if r.get("sequence_run_id") == obs_doc.get("run_id") and "frames" in r:
            # the fit's own sequence: the frames it did not train on are held out
            held = np.array([i not in set(r["frames"]) for i in both])
            regions[region]["trained_frames"] = [int(i) for i in r["frames"]]
            regions[region]["held_out_rel_rms"] = (float(rel_rms(p[:, held], o[:, held]))
                                                   if held.any() else None)
        all_pred.append(p.ravel())
        all_obs.append(o.ravel())
    return {"regions": regions, "times": times, "frames": both,
            "rel_rms": float(rel_rms(np.concatenate(all_pred), np.concatenate(all_obs))),
            "unit": "relative RMS of radiance (unitless)"}


def noise_floor(observed, relit, pixels, frames):
    """The relative RMS error independent noise alone gives between two sequences at ``pixels``,
    sqrt(mean(sigma_o^2 + sigma_r^2)) / rms(observed): {"regions": {...}, "all": value}."""
    sq, ref, out = [], [], {}
    for region, px in sorted(pixels.items()):
        o = frame_values(observed, px, frames)
        var = (frame_values(observed, px, frames, "radiance_sigma") ** 2
               + frame_values(relit, px, frames, "radiance_sigma") ** 2)
        out[region] = float(np.sqrt(np.mean(var) / np.mean(o**2)))
        sq.append(var.ravel())
        ref.append((o**2).ravel())
    return {"regions": out, "all": float(np.sqrt(np.mean(np.concatenate(sq))
                                                 / np.mean(np.concatenate(ref))))}


def write_errors(errors, out, point_errors=None):
    """Write ``relight.json`` and ``relight.csv`` (relative RMS errors) in ``out``."""
    write_json(Path(out) / "relight.json", errors)
    if not errors["regions"]:
        return
    table = point_errors is not None
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["region", *(["point"] if table else []), "frame", "time", "rel_rms_error",
                "held_out"])

    def held(flag):
        return "" if flag is None else "yes" if flag else "no"

    def summary(region, label, value, flag=None):
        w.writerow([region, *(["all"] if table else []), label, "", f"{value:.6f}", held(flag)])
    for region, e in errors["regions"].items():
        if table:
            w.writerows([region, p.point, p.frame, p.time, f"{p.rel_rms:.6f}", held(p.held_out)]
                        for p in point_errors if p.region == region)
        else:
            trained = set(e.get("trained_frames", ()))
            w.writerows([region, i, t, f"{v:.6f}", held(i not in trained if trained else None)]
                        for i, t, v in zip(errors["frames"], errors["times"], e["per_frame"]))
        summary(region, "all", e["rel_rms"])
        if e.get("held_out_rel_rms") is not None:
            summary(region, "held out", e["held_out_rel_rms"], True)
    summary("all", "all", errors["rel_rms"])
    write_text(Path(out) / "relight.csv", buf.getvalue())


def write_comparisons(observed, relit):
    """Write ``compare_NNNN.png`` in ``relit`` per shared frame: observed | relit | signed error
    (over the observed 99th percentile), composed with Pillow; returns the file names."""
    obs_doc, obs_root = load_manifest(observed)
    new_doc, new_root = load_manifest(relit)
    shape = (obs_doc["camera"]["height"], obs_doc["camera"]["width"], 3)
    new = {f["index"]: f for f in rendered_frames(new_doc)}
    pairs = [(f, new[f["index"]]) for f in rendered_frames(obs_doc) if f["index"] in new]
    if not pairs:
        return []
    images = [(read_frame_image(obs_root, a, "radiance", shape),
               read_frame_image(new_root, b, "radiance", shape)) for a, b in pairs]
    scale = np.percentile(np.concatenate([o.ravel() for o, _ in images]), 99) or 1.0

    def compare(frame, o, r):
        err = (r - o).mean(axis=2) / scale
        lim = max(float(np.abs(err).max()), 1e-6)
        label = frame_label(frame["index"], frame.get("time"))
        panels = [(to_srgb8(o, 0.8 / scale), f"observed, {label}"),
                  (to_srgb8(r, 0.8 / scale), f"relit, {label}"),
                  (_diverging(err / lim), "relit - observed (/ observed 99th pct.)")]
        name = f"compare_{frame['index']:04d}.png"
        write_png(Path(relit) / name, _contact_row(panels, lim))
        return name
    # frames on threads (NumPy and Pillow release the GIL); _diverging copies its colour map
    with ThreadPoolExecutor(min(len(pairs), os.cpu_count() or 1)) as pool:
        return list(pool.map(compare, [a for a, _ in pairs], *zip(*images)))


#: Smallest panel width of a comparison image [pixels] (small frames are enlarged to it).
PANEL_MIN_WIDTH = 240


def _diverging(x):
    """x in [-1, 1] (H, W) -> 8-bit RGB (H, W, 3) on matplotlib's RdBu_r (blue below 0)."""
    import matplotlib

    rgba = matplotlib.colormaps["RdBu_r"](np.clip((np.nan_to_num(x) + 1.0) / 2.0, 0.0, 1.0))
    return np.round(rgba[..., :3] * 255).astype(np.uint8)


def _contact_row(panels, lim):
    """One 8-bit RGB image of titled ``panels`` side by side and a colour bar to +-``lim``."""
    from PIL import Image, ImageDraw

    h, w = panels[0][0].shape[:2]
    k = max(1, -(-PANEL_MIN_WIDTH // w))                   # whole-number enlargement
    ph, pw, pad, top, bar = h * k, w * k, 8, 16, 14
    width = len(panels) * (pw + pad) + pad + bar + 60
    canvas = Image.new("RGB", (width, ph + top + 2 * pad), "white")
    draw = ImageDraw.Draw(canvas)
    for i, (image, title) in enumerate(panels):
        x = pad + i * (pw + pad)
        canvas.paste(Image.fromarray(image).resize((pw, ph), Image.NEAREST), (x, top + pad))
        draw.text((x, 3), title, fill="black")
    x0, y0 = pad + len(panels) * (pw + pad), top + pad
    ramp = _diverging(np.linspace(1.0, -1.0, ph)[:, None] * np.ones((1, bar)))
    canvas.paste(Image.fromarray(ramp), (x0, y0))
    for v, y in ((lim, y0), (0.0, y0 + ph // 2), (-lim, y0 + ph - 10)):
        draw.text((x0 + bar + 4, y), f"{v:+.3g}", fill="black")
    return np.asarray(canvas)


@dataclass(frozen=True, slots=True)
class PredictionRow:
    """One predicted value [W m^-2 sr^-1]: a region's mean (or point's) in a frame and channel."""

    region: str
    frame: int
    #: the frame's time (ISO, local; None for a lab light's frame)
    time: str | None
    #: 'R', 'G', 'B', or a luminance table's 'Y'
    channel: str
    #: at the fit
    predicted: float
    #: the 95% band
    lo95: float
    hi95: float
    #: the image's value: observed (frames or table), or the relit render's
    image: float
    #: the table's point (None: the region's mean)
    point: str | None = None
    #: the table's value is saturated (a lower bound)
    saturated: bool = False
    #: beyond what the fit's data measured (:func:`beyond_data`): 'below', 'above',
    #: 'unmeasured', 'highlight', 'angles', or '' within
    beyond: str = ""

    @property
    def inside(self):
        """Whether the image's value lies in the band."""
        return self.lo95 <= self.image <= self.hi95


@dataclass(frozen=True)
class MeansError:
    """Relative RMS error of a region's predicted means: at the fit, and at the truth (or None)."""

    fit: float
    truth: float | None


@dataclass
class Prediction:
    """:func:`predict`'s result: its rows and, per region, the error of its means."""

    rows: list
    region_means: dict
    #: per region, the factor that put a table's values on the fit's scale (:func:`_on_fit_scale`)
    scales: dict = field(default_factory=dict)
    #: per region, where its bands' parameter draws came from (:func:`draws_source`)
    draws_from: dict = field(default_factory=dict)


def write_prediction(prediction, out, image_kind, plot=True):
    """Write ``prediction.csv`` in ``out``: a row per region (table: point), frame and channel
    [W m^-2 sr^-1], with the image's value (``image_kind``); with ``plot``, ``prediction.png``."""
    column = image_kind.replace(" ", "_")
    points = any(r.point is not None for r in prediction.rows)
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["region", *(["point"] if points else []), "frame", "time", "channel",
                "predicted [W m^-2 sr^-1]", "lo95 [W m^-2 sr^-1]", "hi95 [W m^-2 sr^-1]",
                f"{column} [W m^-2 sr^-1]", *(["saturated"] if points else []),
                "beyond_fit_data"])
    w.writerows([(r.region, *([r.point] if points else []), r.frame, r.time, r.channel,
                  *(f"{v:.6g}" for v in (r.predicted, r.lo95, r.hi95, r.image)),
                  *([("yes" if r.saturated else "no")] if points else []), r.beyond)
                 for r in prediction.rows])
    write_text(Path(out) / "prediction.csv", buf.getvalue())
    if plot:
        write_bytes(Path(out) / "prediction.png", (plot_points if points else plot_prediction)(
            prediction.rows, image_kind))


def _region_figure(rows, width, height, margin=0.0):
    """(Figure, [(axes, region)]) of a panel per region of ``rows``, one above another
    (``height`` each, ``margin`` beside), by matplotlib on the Agg back-end (files only)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    regions = sorted({row.region for row in rows})
    # constrained layout: default margins leave empty bands on a tall figure
    fig, axes = plt.subplots(len(regions), 1, figsize=(width, margin + height * len(regions)),
                             squeeze=False, layout="constrained")
    return fig, list(zip(axes[:, 0], regions))


def plot_points(rows, image_kind):
    """PNG bytes of a table's prediction ``rows`` and bands against its values."""
    fig, panels = _region_figure(rows, 5, 4.5)
    for ax, region in panels:
        mine = [row for row in rows if row.region == region]
        for ch, col in zip("RGBY", ("r", "g", "b", "k")):
            sel = [row for row in mine if row.channel == ch]
            if sel:
                ax.errorbar([row.image for row in sel], [row.predicted for row in sel],
                            yerr=[[row.predicted - row.lo95 for row in sel],
                                  [row.hi95 - row.predicted for row in sel]],
                            fmt="o", color=col, ms=3, lw=0.8, label=f"{ch} (95% band)")
        ends = [min(min(r.image, r.lo95) for r in mine), max(max(r.image, r.hi95) for r in mine)]
        ax.plot(ends, ends, ":", color="0.5", lw=0.8)
        ax.set_title(f"{region}: each point and frame", fontsize=9)
        ax.set_xlabel(f"{image_kind} [W m^-2 sr^-1]")
        ax.set_ylabel("predicted [W m^-2 sr^-1]")
        ax.legend(fontsize=6)
    return figure_png(fig)


def plot_prediction(rows, image_kind):
    """PNG bytes of the prediction ``rows``, bands and image values (thesis fig 7.14)."""
    fig, panels = _region_figure(rows, 7, 2.8, 0.5)
    for i, (ax, region) in enumerate(panels):
        for ch, col in zip("RGBY", ("r", "g", "b", "k")):
            sel = [row for row in rows if row.region == region and row.channel == ch]
            if not sel:
                continue
            t, t_label = frame_axis([row.frame for row in sel], [row.time for row in sel])
            ax.fill_between(t, [row.lo95 for row in sel], [row.hi95 for row in sel],
                            color=col, alpha=0.15, lw=0)
            ax.plot(t, [row.predicted for row in sel], "-", color=col,
                    label=f"predicted {ch} (95% band)")
            ax.plot(t, [row.image for row in sel], "o", color=col, ms=4,
                    label=f"{image_kind} {ch}")
        ax.set_title(f"{region}: region mean", fontsize=9)
        ax.set_ylabel("radiance [W m^-2 sr^-1]")
        ax.set_xlabel(t_label)
        if i == 0:                  # the same for every panel: once (a quarter of the plot)
            ax.legend(fontsize=6, ncol=2)
    fig.autofmt_xdate()
    return figure_png(fig)


def parameter_draws(result, s, n, rng):
    """``n`` parameter sets of the fit ``result`` for a prediction's bands on session ``s`` (the
    first the fit itself): the fit's likelihood draws (:mod:`~.draws`), which keep to the
    combinations its data allow (a grey plastic's metal twin, a lobe the sun never showed),
    each widened by the errors that do not cancel: on the fitted sequence the light cache's
    and JPEG rounding's (``added_sd``); elsewhere those the sequence's light, calibration and
    pose share as well, one normal for each of their signed ``shared_rows``
    (:func:`~.fit_record.shared_rows`), a parameter they carry past a bound held there
    (:func:`_held_at_bounds`); and a roughness whose interval reaches its bound beyond
    what the data told (``open_below``: the sky's shape near the mirror unknown) spread over
    that reach too (:func:`_open_below`). A fit without such draws (its sampling failed, or
    written before them), or whose intervals reach over an undetermined sky level, draws from
    its intervals (:func:`~.draws.interval_draws`). Clipped to the bounds."""
    names, lower, upper = s.names, s.lower, s.upper
    theta = np.array([result["parameters"][k] for k in names], dtype=float)
    own = result.get("draws")
    cov = result.get("covariance", {})
    cov = cov.get("matrix") if cov.get("names") == list(names) else None
    same = result.get("sequence_run_id") == s.run_id
    if draws_source(result, s).startswith("its likelihood"):
        sets = np.asarray(own["values"], dtype=float)[rng.integers(len(own["values"]),
                                                                   size=n - 1)]
        draws = sets + rng.standard_normal(sets.shape) * np.asarray(own["added_sd"])
        if not same:
            rows = np.asarray(own["shared_rows"], dtype=float).reshape(-1, len(names))
            draws += rng.standard_normal((n - 1, len(rows))) @ rows
            draws = _held_at_bounds(draws, cov, lower, upper)
            return np.vstack([theta, _open_below(result, names, np.clip(draws, lower, upper),
                                                 rng)])
    else:
        draws = interval_draws(theta, [result["intervals"][k]["95"] for k in names], cov,
                               n - 1, rng)
    return np.vstack([theta, np.clip(draws, lower, upper)])


def _held_at_bounds(draws, cov, lower, upper):
    """``draws`` (m, n) whose shared errors carried a parameter beyond a bound, that parameter
    held at it and the others moved as the data's covariance ``cov`` says they answer it held
    (the least-squares response with it fixed: minus its excess times cov[:, i] / cov[i, i]);
    so a lobe fitted on its bound keeps the trade its rows describe instead of a clip that
    moves the rest alone. Unchanged without a covariance."""
    if cov is None:
        return draws
    c = np.asarray(cov, dtype=float)                  # a None in the JSON reads as nan
    if not np.all(np.isfinite(c)):
        return draws
    draws = draws.copy()
    for i in range(draws.shape[1]):
        excess = draws[:, i] - np.clip(draws[:, i], lower[i], upper[i])
        if c[i, i] > 0 and excess.any():
            draws -= excess[:, None] * c[:, i] / c[i, i]
    return draws


def draws_source(result, s):
    """Where :func:`parameter_draws` takes ``result``'s sets for session ``s``, in words."""
    own = result.get("draws")
    if own is None:
        return "its intervals (its likelihood's sampling found too few draws)"
    if result.get("sequence_run_id") == s.run_id:
        return "its likelihood draws"
    if (result.get("sky") or {}).get("undetermined_span") is not None:
        return "its intervals (they reach over a sky level its data left undetermined)"
    if "shared_rows" not in own:
        return ("its intervals (a fit JSON written before its draws kept the day's shared "
                "errors as signed rows: fit again to draw from its likelihood)")
    return "its likelihood draws, widened by its day's light, calibration and pose errors"


def _open_below(result, names, draws, rng):
    """``draws`` (within the bounds) with the roughness of a share of them spread evenly over
    the reach of its interval below where the data's reach ended, where the interval is open
    below (``open_below``: the sun's highlight unseen, the sky's shape near the mirror not known
    to the data); the share that reach's of the interval, as if uniform over it."""
    iv = (result["intervals"].get("sigma_alpha") or {})
    if "sigma_alpha" not in names or iv.get("open_below") is None:
        return draws
    k = list(names).index("sigma_alpha")
    lo, hi = iv["95"]
    floor = min(float(iv["open_below"]), hi)
    if not hi > lo or floor <= lo:
        return draws
    spread = rng.random(len(draws)) < (floor - lo) / (hi - lo)
    draws[spread, k] = rng.uniform(lo, floor, int(spread.sum()))
    return draws


def predict(fits, target, pixels, draws=200, seed=0, log=print):
    """Radiance of each fitted region in the target's frames, without rendering images: its
    mean (a table: each point's value) per frame and channel at the fit, with a 95% band
    (percentiles over :func:`parameter_draws`, widened in quadrature by the image's noise, the
    model's Monte Carlo error and model error) and the image's value. Returns a
    :class:`Prediction`, with per region the error of its means at the fit and, for a
    synthetic target, at the truth (Monte Carlo noise alone).
    """
    rng = np.random.default_rng(seed)
    if is_table(load_manifest(target)[0]):
        # every point of the region in the target's table, at a fit's cache size for points
        predict_region = _predict_points
        sessions = ((region, _table_session(target, region, r, seed))
                    for region, (_, r) in sorted(fits.items()))
    else:
        # image regions: the light at all their pixels traced at once
        predict_region = _predict_means
        shared = fitted_sessions({region: r for region, (_, r) in fits.items()}, target, pixels,
                                 cache=FitCache(*PREDICTION_CACHE, seed, "anchors"), min_frames=1)
        sessions = ((region, shared.pop(region)) for region in sorted(fits))
    rows, means, scales, sources = [], {}, {}, {}
    for region, s in sessions:                          # each let go when done with
        region_rows, means[region], scale = predict_region(s, fits[region][1], target, draws,
                                                           rng)
        rows += region_rows
        if scale is not None:
            scales[region] = scale
            log(f"{region}: the table's values put on the fit's scale, times "
                f"{scale['factor']:.4g} (each frame's factor from the other frames')")
        sources[region] = draws_source(fits[region][1], s)
        log(f"{region}: predicted {len(s.obs.frames)} frames from {draws} parameter draws of "
            + sources[region]
            + (f" (under the target's spec sky: the fit's sky level k = "
               f"{fits[region][1]['sky']['k']:.3g} belongs to its own day)"
               if fits[region][1].get("sky") is not None and not s.light.split else ""))
    return Prediction(rows, means, scales, sources)


def _table_session(target, region, result, seed):
    """The session of every point of ``region`` in the target's table, lit as ``result`` saw it."""
    s = FitSession(target, region, None, model=result["model"],
                   normalisation=result.get("normalisation", "ward"),
                   cache=FitCache(directions=DIRECTIONS, seed=seed), min_frames=1, light=None)
    s.trace_as_fitted(result)
    return s


def fitted_sessions(results, manifest_path, pixels, **options):
    """{region: FitSession} of ``results`` at ``pixels``, lit as fitted and traced together."""
    sessions = {name: FitSession.from_fit(r, manifest_path, pixels[name], light=None, **options)
                for name, r in results.items()}
    trace_sessions(list(sessions.values()),
                   {name: s.fitted_light(results[name]) for name, s in sessions.items()})
    for name, s in sessions.items():
        s.use_fitted_sky(results[name])
    return sessions


#: Values (draws x points x frames x channels) of a table's prediction held at once (64 MB):
#: radiances are made a chunk of points at a time.
CHUNK_VALUES = 2**23


def _predict_means(s, result, target, draws, rng):
    """(Rows, :class:`MeansError`) of one image region's prediction from session ``s``."""
    sets = parameter_draws(result, s, draws, rng)
    region_mean = _region_mean(s)
    means = s.wm.radiances(sets, region_mean)                               # (draws, T, 3)
    lo, hi = np.percentile(means[1:], [2.5, 97.5], axis=0)
    # widened by the image's noise and the model's Monte Carlo error, both of the mean
    at_fit, model_var = s.wm.radiance_and_variance(sets[0])
    image = image_values(s, target)
    n = len(s.obs.pixels)
    # and by the model's error, kappa times the mean, scaled by local_error_scale
    kappa, interval = model_error_kappa(result)
    scale = local_error_scale(((result.get("model_error") or {}).get("held_out") or {})
                              .get("by_frame"),
                              (result.get("geometry") or {}).get("sun_angles_per_frame_deg"),
                              s.geometry["sun_angles_per_frame_deg"], kappa)
    extra = band_half_width((np.sum(image_noise_variance(s, image, at_fit, target), axis=0)
                             + np.sum(model_var, axis=0)) / n**2
                            + frame_calibration_variance(s, means[0])
                            + target_tone_variance(s, result, means[0]), means[0] * scale, kappa,
                            interval)
    observed = region_mean(image)
    names = _channels(s)
    means, observed = means[..., :len(names)], observed[..., :len(names)]
    rows = _prediction_rows(s, result, [a[None] for a in (means[0], lo, hi, extra, observed)],
                 np.ndindex(1, *means[0].shape), 0.0)
    return rows, _means_error(s, means[0], observed, region_mean), None


def _prediction_rows(s, result, values, where, lower, points=None, saturated=None):
    """The :class:`PredictionRow` of session ``s`` at each (point, frame, channel) of ``where``
    from ``values`` (at the fit, the band's lo and hi, its widening, the image's; each (P, T, C)),
    bands widened from ``lower`` up; ``points`` and ``saturated`` (P, T, C) a table's."""
    at_fit, lo, hi, extra, image = values
    names, unseen = _channels(s), unseen_light(result, s)
    rows = []
    for p, j, c in where:
        band = widen(at_fit[p, j, c], (lo[p, j, c], hi[p, j, c]), extra[p, j, c], lower, np.inf)
        rows.append(PredictionRow(
            region=s.name, frame=int(s.obs.frames[j]), time=s.obs.times[j], channel=names[c],
            predicted=float(at_fit[p, j, c]), lo95=float(band[0]), hi95=float(band[1]),
            image=float(image[p, j, c]), point=None if points is None else points[p],
            saturated=saturated is not None and bool(saturated[p, j, c]),
            beyond=beyond_data(result, names[c], at_fit[p, j, c], unseen[j])))
    return rows


def unseen_light(result, s):
    """Per frame of session ``s``, whether its sun's light lies beyond what ``result``'s data saw:
    'highlight', 'angles' (:mod:`~.geometry`) or ''."""
    geometry = result.get("geometry")
    geometry = geometry if isinstance(geometry, dict) else {}
    fitted = geometry.get("closest_highlight_half_angle_deg", False)
    closest_known = fitted is None or type(fitted) in (int, float)
    configs = geometry.get("sun_view_angles_per_frame_deg")
    configs_known = isinstance(configs, list) and all(
        a is None or isinstance(a, list) and len(a) == 3 for a in configs)
    sigma = sharpest_roughness(result)
    trained = (set(result.get("frames", [])) if result.get("sequence_run_id") == s.run_id
               else set())                                   # the frames it saw: measured
    return ["" if int(i) in trained else
            "highlight" if closest_known and highlight_beyond(fitted, d, sigma) else
            "angles" if configs_known and angles_beyond(configs, a) else ""
            for i, d, a in zip(s.obs.frames, s.geometry["closest_half_angle_per_frame_deg"],
                               s.geometry["sun_view_angles_per_frame_deg"])]


def beyond_data(result, channel, value, unseen=""):
    """Where a predicted ``value`` [W m^-2 sr^-1] of ``channel`` lies beyond what ``result``'s
    data measured: the frame's sun 'highlight' nearer the mirror than they saw (its lobe's peak
    is what such a prediction most misses, so this mark comes first), else against the fit's
    ``measured_range`` 'below', 'above', 'unmeasured', else the frame's new 'angles'
    (:func:`unseen_light`), or ''. Beyond, the prediction rests on the model alone."""
    if unseen == "highlight":
        return unseen
    ranges = (result.get("measured_range") or {}).get("by_channel")
    lo_hi = ranges.get(channel, ()) if ranges is not None else ()
    radiance = ("unmeasured" if lo_hi is None else "" if not lo_hi else
                "below" if value < lo_hi[0] else "above" if value > lo_hi[1] else "")
    return radiance or unseen


def sharpest_roughness(result):
    """The smallest sigma_alpha ``result``'s 95% interval allows (its best value where it has
    no interval; 0 for a model without a lobe): a highlight nearer the mirror than the data saw
    is beyond them if any lobe the data allow peaks there."""
    interval = ((result.get("intervals") or {}).get("sigma_alpha") or {}).get("95")
    best = result["parameters"].get("sigma_alpha", 0.0)
    return float(min(interval[0], best)) if isinstance(interval, list) and interval else best


def _predict_points(s, result, target, draws, rng):
    """(Rows, :class:`MeansError`) of one table region's prediction, per point, frame and
    measured channel (bands may reach below zero, as a table's values may)."""
    sets = parameter_draws(result, s, draws, rng)
    at_fit, lo, hi = (np.empty(s.obs.y.shape) for _ in range(3))
    P, T = s.obs.y.shape[:2]
    step = max(1, CHUNK_VALUES // (len(sets) * T * 3))
    for start in range(0, P, step):
        part = slice(start, start + step)
        values = s.model_on(s.table.subset(part)).radiances(sets)       # (draws, points, T, 3)
        at_fit[part] = values[0]
        lo[part], hi[part] = np.percentile(values[1:], [2.5, 97.5], axis=0)
    _, model_var = s.wm.radiance_and_variance(sets[0])
    scale = _on_fit_scale(s, result, at_fit, target)
    image = image_values(s, target)
    extra = band_half_width(image_noise_variance(s, image, at_fit, target) + model_var
                            + frame_calibration_variance(s, at_fit), at_fit,
                            *model_error_kappa(result))
    names = _channels(s)
    where = zip(*np.nonzero(np.isfinite(s.obs.sigma[..., :len(names)])))
    rows = _prediction_rows(s, result, (at_fit, lo, hi, extra, image), where, -np.inf,
                 [str(x) for x in s.obs.pixels], ~_measured(s))     # one string a point, shared
    region_mean = _region_mean(s)
    return rows, _means_error(s, region_mean(at_fit)[..., :len(names)],
                              region_mean(image)[..., :len(names)], region_mean), scale


def _on_fit_scale(s, result, at_fit, target):
    """Put table session ``s``'s values on the fit's radiometric scale where one of the two is
    relative (ingest --unknown-scale) and they come from different ingests: each frame's values
    times the factor the other frames' give (least squares in relative error, f = sum(o/p) /
    sum((o/p)^2), over measured, unsaturated values within the fit's measured range), so no
    frame is scored with its own. Scales the session's gain (values, noise and means alike);
    returns the factor's record, or None."""
    if result.get("sequence_run_id") == s.doc.get("run_id") or not (
            relative_scale(s.doc) or result.get("radiometric_scale")):
        return None
    image = image_values(s, target)
    measured = _measured(s) & (at_fit > 0) & (image > 0)
    use = measured.copy()
    ranges = (result.get("measured_range") or {}).get("by_channel") or {}
    for c, name in enumerate(_channels(s)):
        lo_hi = ranges.get(name)
        if lo_hi:
            use[..., c] &= (at_fit[..., c] >= lo_hi[0]) & (at_fit[..., c] <= lo_hi[1])
    use = use if use.any() else measured
    if not use.any():
        return None
    ratio = np.where(use, image / np.where(use, at_fit, 1.0), 0.0)
    a, b = ratio.sum(axis=(0, 2)), (ratio ** 2).sum(axis=(0, 2))          # per frame
    factor = float(a.sum() / b.sum())
    others = b.sum() - b
    by_frame = np.where(others > 0, (a.sum() - a) / np.where(others > 0, others, 1.0), factor)
    s.obs.gain = s.obs.gain / by_frame[None, :, None]
    return {"factor": factor, "by_frame": by_frame.tolist(), "values": int(use.sum()),
            "meaning": "the table's or the fit's scale is relative (ingest --unknown-scale): "
                       "each frame's values are put on the fit's by the factor the other "
                       "frames' values give against the predictions (factor: all frames'); "
                       "errors and coverage hold up to it"}


def model_error_kappa(result):
    """(kappa, its 95% interval or None): a fit ``result``'s relative model error for a
    prediction, held-out (``model_error.held_out``) else in-sample (0 without). Bands add kappa
    times the value, averaged over kappa's uncertainty (:func:`~.uncertainty.band_half_width`)."""
    me = result.get("model_error") or {}
    held = me.get("held_out") or {}
    if held.get("kappa", 0.0) >= me.get("kappa", 0.0):
        return float(held.get("kappa", 0.0)), held.get("interval95")
    return float(me["kappa"]), me.get("interval95")


def _measured(s):
    """Where session ``s``'s table or frames hold a value that is not saturated (P, T, 3)."""
    return np.isfinite(s.obs.sigma) & (s.obs.y < s.obs.sensor.max_code)


def _channels(s):
    """The channels session ``s`` predicts: Y for a luminance table, else R, G, B."""
    return "Y" if s.obs.luminance else "RGB"


def _region_mean(s):
    """Region mean (T, 3) of values (P, T, 3) over the measured, unsaturated points or pixels
    (a registered frame's pixels beyond its edge and clipped ones left out of both the
    prediction's mean and the observed)."""
    have = _measured(s)
    weight = have / np.maximum(have.sum(axis=0), 1.0)
    return lambda x: np.sum(np.where(have, x, 0.0) * weight, axis=0)


def _means_error(s, fit_means, observed, region_mean):
    """The :class:`MeansError` of ``fit_means`` (and the truth's) against ``observed`` (T, C)."""
    truth = truth_parameters(s.truth, s.model, s.names, s.normalisation)
    at_truth = None if truth is None else float(rel_rms(
        region_mean(s.wm.radiance(truth))[..., :observed.shape[-1]], observed))
    return MeansError(fit=float(rel_rms(fit_means, observed)), truth=at_truth)


def image_values(s, target):
    """The image's values at session ``s``'s points in ``target`` (P, T, 3) [W m^-2 sr^-1]."""
    if s.obs.rays is None:
        return frame_values(target, s.obs.pixels, s.obs.frames)
    return s.obs.y / (s.obs.gain * s.obs.sensor.max_code)


def frame_calibration_variance(s, radiance):
    """Variance [(W m^-2 sr^-1)^2] that the target's frames' own calibration (a grey card in
    each frame, ingest's ``per_frame``) gives ``radiance`` (..., 3): a relative error each frame
    shares over all its pixels, so a region mean keeps it whole; 0 without."""
    sd = frame_calibration_sd(s)
    return 0.0 if sd is None else (np.asarray(sd, dtype=float) * radiance) ** 2


def target_tone_variance(s, result, radiance):
    """Variance [(W m^-2 sr^-1)^2] a region mean of the target's values at ``radiance`` (T, 3)
    takes from the target's camera's own tone curve (its ingest's, :func:`~.tone.region_tone`:
    each independent error's move at the region's median codes), where that curve is not the
    one the fit counted: another camera (EXIF), a fit that counted none, or one of the two
    measured by greys and the other not. On the fit's own sequence, or another of its camera
    read alike (or where either's camera is unknown, taken as the same; a fit JSON without
    ``tone_curve_cameras``: unknown), the fit's parameters carry the same curve's error, which
    the target's largely cancels (the sample board's curved camera relit onto another of its
    days: counted twice, the median band 36% -> 71% for a median error of 2.7%). 0 where the
    target's ingest counted no curve."""
    if s.tone is None or result.get("sequence_run_id") == s.run_id:
        return 0.0
    counted = result.get("tone_curve_cameras",
                         [] if "tone_curve_error_sd" in result else None)   # [] unnamed
    measured = bool(((s.doc.get("ingest") or {}).get("tone_curve") or {}).get("weights"))
    if counted is not None and result.get("tone_curve_measured", False) == measured:
        mine = photo_cameras(s.doc)
        if not counted or not mine or set(counted) == set(mine):
            return 0.0
    move = level_tone(s.doc, s.obs, median_codes(s.obs))[0]            # (T, C, E) the region's
    return np.sum(np.square(move * np.asarray(radiance)[..., None]), axis=-1)


def image_noise_variance(s, image, radiance, target):
    """Variance [(W m^-2 sr^-1)^2] of ``image`` values (P, T, 3) where the model predicts
    ``radiance``: the sensor's sigma through the slope at the prediction (an observed value may
    sit at zero slope); 0 where saturated or left out. A render's radiance frames carry only its
    Monte Carlo error (``radiance_sigma``)."""
    if s.obs.rays is None and s.doc.get("source") == "render":
        sd = frame_values(target, s.obs.pixels, s.obs.frames, source="radiance_sigma")
        return np.where(np.isfinite(sd), sd, 0.0) ** 2
    slope = s.problem.slope(np.maximum(radiance, np.finfo(float).tiny))   # a dark prediction too
    slope = np.where(slope > 0, slope, s.problem.slope(image))
    usable = np.isfinite(s.obs.sigma) & (slope > 0) & ~s.problem.clipped()[1]
    return np.where(usable, s.obs.sigma / np.where(usable, slope, 1.0), 0.0) ** 2
