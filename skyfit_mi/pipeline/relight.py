"""Re-lit reconstructions (thesis 7.4): a target day rendered with fitted materials.

The target is a spec file (another date, times, site, sky or camera) or a sequence folder (its
manifest's spec: the same times, skies and camera).  Each fit replaces the scene material its
region measured; every other material keeps the target's value, and the manifest's
``scene.materials.ID.source`` says which is which.  The output is a sequence folder like
``render``'s, so ``pixels``, ``labels`` and ``fit`` work on it.  When the target folder holds
frames, they are the observations: ``relight.json`` and ``relight.csv`` give the relative RMS
error of the relit radiance at each fit's pixels, per region and frame, per region, and
overall (thesis fig. 7.14's comparison, as numbers).
"""

import csv
import io
from pathlib import Path

import numpy as np

from ..errors import SkyfitError
from ..files import write_json, write_text
from ..fitting.report import fit_files, read_fit
from .manifest import load_manifest, manifest_file, rendered_frames
from .pixels import frame_values
from .spec import read_spec, validate_spec


def load_fits(paths):
    """{region: (path, fit result)} from fit JSONs, a fit folder's ``fits.csv`` (the
    ``fit_*.json`` beside it), or a folder of fits; a region given twice is refused."""
    out = {}
    for p in map(Path, paths):
        if p.is_dir() or p.name == "fits.csv":
            found = fit_files(p if p.is_dir() else p.parent)
            if not found:
                raise SkyfitError(f"no fit_*.json beside {p}; give the folder `skyfit fit` wrote.")
        elif p.is_file():
            r = read_fit(p)
            if r is None:
                raise SkyfitError(f"{p} is not a fit result of `skyfit fit` (fit_NAME.json).")
            found = {r["region"]: (p, r)}
        else:
            raise SkyfitError(f"fit {str(p)!r} does not exist; give fit_NAME.json files, a "
                              "fits.csv or the folder `skyfit fit` wrote.")
        for region in found:
            if region in out:
                raise SkyfitError(f"region {region!r} is fitted twice ({out[region][0]} and "
                                  f"{found[region][0]}); give one fit per region.")
        out.update(found)
    return out


def target_spec(target, fits):
    """The validated spec of ``target`` (a spec file or a sequence folder) with each fitted
    region's material taken from its fit; returns (spec, target manifest or None)."""
    target = Path(target)
    if target.is_dir() or target.name == "manifest.json":
        doc, _ = load_manifest(target)
        raw, base = doc["spec"], Path(doc.get("spec_dir", "."))
    else:
        doc, raw, base = None, read_spec(target), target.parent
    raw = dict(raw)
    raw["materials"] = {**raw.get("materials", {}),
                        **{region: {"fit": str(Path(p).resolve())}
                           for region, (p, _) in fits.items()}}
    return validate_spec(raw, base), doc


def relight(fits, target, out, log=print, progress=True, overwrite=False):
    """Render ``target`` with the fitted materials into ``out``; with observations in the
    target, write and return the prediction errors (:func:`prediction_errors`)."""
    from .sequence import render_sequence

    spec, doc = target_spec(target, fits)
    if doc is not None and Path(out).resolve() == manifest_file(target).parent.resolve():
        raise SkyfitError("the output folder is the target's; give another with -o.")
    render_sequence(spec, out, overwrite=overwrite, progress=progress, log=log)
    if doc is None or not rendered_frames(doc):
        return None
    errors = prediction_errors(fits, target, out)
    write_errors(errors, out)
    for region, e in errors["regions"].items():
        log(f"{region}: relit radiance differs from the observed by {e['rel_rms']:.2%} rms "
            f"({e['frames']} frames, {e['pixels']} pixels)")
    log(f"overall: {errors['rel_rms']:.2%} rms")
    return errors


def _rel_rms(pred, obs, axis=None):
    return np.sqrt(np.mean((pred - obs) ** 2, axis=axis)) / np.sqrt(np.mean(obs**2, axis=axis))


def prediction_errors(fits, observed, relit):
    """Relative RMS error of the relit radiance against the observed, at each fit's pixels
    (fit_NAME.json's ``pixels``), over the frames both sequences hold:
    {"regions": {region: {rel_rms, per_frame, frames, pixels, fit}}, "rel_rms", "times"}.
    Unitless; radiance is compared in W m^-2 sr^-1, all channels together."""
    obs_doc, _ = load_manifest(observed)
    new_doc, _ = load_manifest(relit)
    both = sorted({f["index"] for f in rendered_frames(obs_doc)}
                  & {f["index"] for f in rendered_frames(new_doc)})
    if not both:
        raise SkyfitError("the target and the relit sequence share no rendered frame.")
    times = [f["time"] for f in obs_doc["frames"] if f["index"] in both]
    regions, all_pred, all_obs = {}, [], []
    for region, (path, r) in sorted(fits.items()):
        px = np.asarray(r["pixels"], dtype=int)
        o = frame_values(observed, px, both)
        p = frame_values(relit, px, both)
        regions[region] = {"fit": str(path), "pixels": len(px), "frames": len(both),
                           "rel_rms": float(_rel_rms(p, o)),
                           "per_frame": _rel_rms(p, o, axis=(0, 2)).tolist()}
        all_pred.append(p.ravel())
        all_obs.append(o.ravel())
    return {"regions": regions, "times": times, "frames": both,
            "rel_rms": float(_rel_rms(np.concatenate(all_pred), np.concatenate(all_obs))),
            "unit": "relative RMS of radiance (unitless)"}


def write_errors(errors, out):
    """``relight.json`` and ``relight.csv`` (region, frame, time, relative RMS error; 'all' rows
    per region and overall) in ``out``."""
    write_json(Path(out) / "relight.json", errors)
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["region", "frame", "time", "rel_rms_error"])
    for region, e in errors["regions"].items():
        for i, t, v in zip(errors["frames"], errors["times"], e["per_frame"]):
            w.writerow([region, i, t, f"{v:.6f}"])
        w.writerow([region, "all", "", f"{e['rel_rms']:.6f}"])
    w.writerow(["all", "all", "", f"{errors['rel_rms']:.6f}"])
    write_text(Path(out) / "relight.csv", buf.getvalue())
