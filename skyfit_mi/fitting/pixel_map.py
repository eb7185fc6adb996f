"""Material maps over whole images: per-pixel fits in chunks, on Dask, into a Zarr store.

``skyfit fit DIR --per-pixel`` maps every pixel (or ``--patch``) of the chosen regions with
:func:`~.pixel_fit.fit_pixels`, in chunks that are self-contained Dask tasks on a local or given
cluster. Results go into ``pixel_map.zarr`` as each chunk finishes, so an interrupted map resumes;
a chunk's seed depends only on the map's seed and its index, so any number of workers gives the
same map. Outputs: EXRs of each parameter, its 95% width, chi^2/dof and warning bits
(:data:`~.pixel_fit.WARNINGS`), PNG previews and ``map_summary.json``.
"""

import hashlib
import json
import logging
import os
import shutil
import signal
import sys
import threading
import time
import warnings
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import SkyfitError
from ..files import FolderLock, check_dir, ensure_dir, save_figure, write_json
from ..pipeline.fit_result import MAP_SUMMARY
from ..pipeline.manifest import frame_sky, load_manifest
from ..pipeline.photos import exif_scaled
from ..render.fit_model import PARAMETER_ORDER, PARAMETERS
from ..render.image import write_exr
from ..render.scene import pose_sd
from ..render.light_cache import SKY_SPACING
from .chi2 import REGION_PIXELS, check_regions, subsample_region
from .fit import fit_regions
from .light import SPEC_LIGHT, LightOptions
from .selection import fit_auto
from .pixel_fit import (MAP_CACHE, UNDETERMINED, WARNINGS, check_map_region, fit_pixels,
                        patch_groups, undetermined_bits)
from .sky_fit import default_sky, light_level_sd
from . import uncertainty as unc

#: The Zarr store of a map, in the map folder.
STORE = "pixel_map.zarr"
#: A worker's peak memory [bytes]: a fixed part and a part per fit of its chunk
#: (docs/BENCHMARKS.md, "Per-pixel maps: speed and memory").
WORKER_BYTES, FIT_BYTES = 0.25e9, 0.8e6
#: Fits per chunk: a worker near 1.1 GB, the chunk's fixed cost a tenth of its time.
CHUNK = 1024
#: How :func:`plan_chunks` lays fits into chunks (a store laid out otherwise is not resumed).
LAYOUT = "tiles"
#: Most pixels of each region (a seeded subset) in a map's first fits (:func:`first_fits`).
LIGHT_PIXELS = REGION_PIXELS
#: The Dask setting that gives workers MALLOC_TRIM_THRESHOLD_ (unset for the local cluster).
TRIM = "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_"
#: Seconds to wait for a given scheduler to answer.
SCHEDULER_TIMEOUT_S = 10
#: The store's arrays of a value per parameter and pixel (parameters, H, W), and per pixel (H, W).
PLANES, IMAGES = ("theta", "lo", "hi", "cache_error_sd"), ("chi2", "dof", "warnings")


def plan_chunks(regions, patch, chunk):
    """The map's chunks: dicts of ``pixels`` (P, 2), ``materials`` (P,) and ``groups`` (P,) (each
    pixel's fit, 0..G-1), at most ``chunk`` whole fits each; within a region fits go by square
    tiles, so a chunk is compact and shares the sky integrals' anchors."""
    px, mats, keys = [], [], []
    side = int(patch) * max(1, int(np.ceil(np.sqrt(int(chunk)))))
    for r, (name, pixels) in enumerate(regions):
        pixels = np.asarray(pixels, dtype=int).reshape(-1, 2)
        g, corners = patch_groups(pixels, patch)
        tile = corners[g] // side
        px.append(pixels)
        mats += [name] * len(pixels)
        keys.append(np.stack([np.full(len(g), r), tile[:, 1], tile[:, 0], g], axis=1))
    px, mats, keys = np.concatenate(px), np.array(mats, dtype=object), np.concatenate(keys)
    fits, index = np.unique(keys, axis=0, return_inverse=True)
    index = index.ravel()
    out = []
    for start in range(0, len(fits), int(chunk)):
        sel = (index >= start) & (index < start + int(chunk))
        out.append({"pixels": px[sel], "materials": mats[sel], "groups": index[sel] - start})
    return out


def chunk_seed(seed, index):
    """The seed of chunk ``index`` of a map of ``seed`` (independent of workers and order)."""
    return int(np.random.SeedSequence([int(seed), int(index)]).generate_state(1)[0])


def _settings(doc, regions, o, sky, first):
    """What a stored map was made with (a resume needs the same): :class:`MapOptions` ``o``, the
    light's ``sky`` plan, whether the regions' fits come ``first``, and whether the pixels take
    the regions' shares of the EXIF labels' error."""
    digest = [(n, np.asarray(p).tolist()) for n, p in regions]
    settings = {
        "sequence_run_id": doc.get("run_id"), "model": o.model, "normalisation": o.normalisation,
        "seed": int(o.seed), "patch": int(o.patch), "chunk": int(o.chunk), "cache": list(o.cache),
        "sky_spacing": SKY_SPACING, "layout": LAYOUT, "undetermined_bits": UNDETERMINED,
        "regions": hashlib.sha256(json.dumps(digest).encode()).hexdigest()[:16],
        "sky": {"sky": sky, "sun_sd": o.light.sun_sd, "sky_terms": o.light.terms}
        if sky != "spec" else "spec"}
    if first:
        settings["first_fits_pixels"] = o.light_pixels
    if exif_scaled(doc) is not None:              # the regions' shares of the labels' error
        settings["exif_labels_error"] = True
    return settings


def _labels_share(doc, result, pixels):
    """A region fit's ``result`` share of the EXIF labels' error per parameter: its
    ``calibration_error_sd`` without the errors of the level every frame shares
    (:func:`~.uncertainty.shared_level_rows`) and a camera's tone curve's where they are among
    them (its light not fitted; each pixel takes its own, :func:`~.tone.tone_level_rows`), taken
    out in quadrature, which each pixel of a map takes at its own place."""
    cal = result.get("calibration_error_sd") or {}
    names = [p for p in result["parameters"] if p in cal]
    theta = np.array([result["parameters"][p] for p in names])
    shared = unc.rows_sd(unc.shared_level_rows(doc, names, theta,
                                               unc.region_vignetting(doc, pixels)))
    if not (result.get("sky") or {}).get("tone_curve"):
        tone = result.get("tone_curve_error_sd") or {}
        shared = np.hypot(shared, [tone.get(p, 0.0) for p in names])
    return {p: float(np.sqrt(max(cal[p] ** 2 - v ** 2, 0.0))) for p, v in zip(names, shared)}


def first_fits(manifest_path, regions, model="colour", normalisation="ward", seed=0,
               light=SPEC_LIGHT, max_pixels=LIGHT_PIXELS, variant=None,
               log=print):
    """Fit each of ``regions`` ([(material, pixels)]) first on up to ``max_pixels``, since one
    pixel hardly tells the sky, the model or what shared errors do: each region's (model,
    normalisation) (ranked where ``model`` is 'auto'), and the light for
    :func:`~.pixel_fit.fit_pixels`: under a fitted sky its level and each region's share of
    its error; where EXIF labels scale a given exposure
    (:func:`~skyfit_mi.pipeline.photos.exif_scaled`), each region's share of their error
    (``labels_sd``, its ``calibration_error_sd``); else None. Returns (choices {region: (model,
    normalisation)}, light)."""
    sky = light.sky                                     # named: a plan, or options that say it
    doc = load_manifest(manifest_path)[0]
    labelled = exif_scaled(doc) is not None
    kept = [(name, subsample_region(px, max_pixels or None, seed)) for name, px in regions]
    what = " and ".join((["every lobe and parameter count ranked"] if model == "auto" else [])
                        + ([] if sky == "spec" else ["the sky's level fitted"])
                        + (["the EXIF labels' error measured"] if labelled else []))
    log(f"map: {what} first with {len(kept)} region(s) ("
        + (f"up to {max_pixels} pixels each, seed {seed}" if max_pixels else "every pixel")
        + "); the map takes " + " and ".join(
            (["each region's choice"] if model == "auto" else [])
            + ([] if sky == "spec" else ["that light"])
            + (["each region's share of the labels' error"] if labelled else [])))

    def shown(line):
        """The first fits' own lines on the sky and the choices, not the regions' results."""
        if line.startswith("sky:") or ": chose " in line:
            log(line)
    if model == "auto":
        results = fit_auto(manifest_path, kept, seed=seed, variant=variant, light=light,
                           log=shown)
    else:
        results = fit_regions(manifest_path, kept, model=model, normalisation=normalisation,
                              seed=seed, variant=variant, light=light, log=shown)
    try:
        fits = list(zip(kept, results))
    except SkyfitError as exc:
        raise SkyfitError(f"{str(exc).rstrip('.')}; the map has {what} first with every "
                          "region: leave that region out"
                          + (", or map with --sky spec" if sky != "spec" else "")
                          + (" and a model (--model 2, 3 or 5)" if model == "auto" else "")
                          + ".") from None
    choices = {name: (r["model"], r["normalisation"]) for (name, _), r in fits}
    if sky == "spec" and not labelled:
        return choices, None
    regions = {}
    for (name, px), r in fits:
        regions[name] = {"value": r["parameters"], "sd": None, "span": None}
        if labelled:
            regions[name]["labels_sd"] = _labels_share(doc, r, px)
        if sky != "spec":
            span = r["sky"].get("undetermined_span")
            regions[name].update(sd=r["sky"]["error_sd"], span=None if span is None else [
                {p: v[i] for p, v in span.items()} for i in (0, 1)])
    if sky == "spec":
        return choices, {"fitted": sky, "regions": regions}
    rec = fits[-1][1]["sky"]                      # one sky record, shared by every region
    return choices, {"fitted": sky, "regions": regions,
                     "sky": {k: rec.get(k) for k in ("k", "interval95", "determined", "terms",
                                                     "regions", "prior", "warnings",
                                                     "tone_curve")},
                     "sun_level_sd": rec["sun_level_sd"], "sun_source": rec["sun_source"]}


def plan_map(regions, choices, patch, chunk):
    """The map's chunks per (model, normalisation) of ``choices``, one lobe per chunk."""
    out = []
    for kind in dict.fromkeys(choices[name] for name, _ in regions):
        for c in plan_chunks([r for r in regions if choices[r[0]] == kind], patch, chunk):
            out.append({**c, "model": kind[0], "normalisation": kind[1]})
    return out


def map_parameters(choices):
    """The map's parameter planes: every parameter some region's model has, in one order."""
    used = {p for m, _ in choices.values() for p in PARAMETERS[m]}
    return [p for p in PARAMETER_ORDER if p in used]


def _check_store(path, settings, overwrite):
    """Refuse another map's store unless ``overwrite``; (done, first fits) to resume, or None."""
    import zarr

    if not path.exists() or overwrite:
        return None
    try:
        g = zarr.open_group(str(path), mode="r")
        old, done = dict(g.attrs.get("settings", {})), g["done"][:]
        first = g.attrs.get("first_fits")
    except Exception:                                          # damaged or not a store
        old = done = first = None
    if old != settings:
        _another_map(path, old, settings)
    return done, first


def _another_map(path, old=None, settings=None):
    """SkyfitError for another map's (or a damaged) store at ``path``, naming the settings in
    which ``old`` (that map's) differs from ``settings`` (this run's)."""
    differ = sorted(k for k in set(old or {}) | set(settings or {})
                    if (old or {}).get(k) != (settings or {}).get(k)) if old else []
    raise SkyfitError(f"{path} holds another map"
                      + (f" (its {', '.join(differ[:4])} differ from this run's)" if differ
                         else " (or a damaged one)")
                      + "; give another -o, or pass --overwrite to replace it.")


def _open_store(path, settings, shape, n_par, n_chunks, resume, first=None):
    """The map's Zarr group: the one at ``path`` if ``resume``, else a new one (replacing what
    :func:`_check_store` allowed) holding the ``first`` fits' findings, which a resume reuses."""
    import zarr

    if resume:
        return zarr.open_group(str(path), mode="r+")
    if path.exists():
        shutil.rmtree(path)
    g = zarr.open_group(str(path), mode="w")
    for name in PLANES + IMAGES:
        whole = name in ("dof", "warnings")
        dims = ((n_par,) if name in PLANES else ()) + shape
        g.create_array(name, shape=dims, dtype="i4" if whole else "f4",
                       fill_value=-1 if whole else np.nan,
                       chunks=dims[:-2] + tuple(min(n, 256) for n in shape))
    g.create_array("done", shape=(n_chunks,), dtype="bool", fill_value=False)
    g.attrs["settings"] = settings
    g.attrs["first_fits"] = first
    return g


def _write_chunk(store, chunk, res, names):
    """Scatter one chunk's fits onto its pixels in the store, each parameter on its plane."""
    pixels, groups = chunk["pixels"], chunk["groups"]
    x, y = pixels[:, 0], pixels[:, 1]
    box = (Ellipsis, slice(y.min(), y.max() + 1), slice(x.min(), x.max() + 1))
    planes = np.array([names.index(p) for p in res["names"]])[:, None]
    for key in PLANES + IMAGES:
        arr = store[key][box]
        if key in PLANES:                         # res[key] (fits, parameters)
            arr[planes, y - y.min(), x - x.min()] = res[key][groups].T
        else:
            arr[y - y.min(), x - x.min()] = res[key][groups]
        store[key][box] = arr


def worker_count(workers, chunk, log=print):
    """(Worker processes, note): ``workers`` (default per core), capped by cores and memory."""
    import psutil

    cores = os.cpu_count() or 1
    need = WORKER_BYTES + int(chunk) * FIT_BYTES
    free = psutil.virtual_memory().available
    cap = max(1, min(cores, int(free // need)))
    n = int(workers or cores)
    if n > cap:
        log(f"starting {cap} worker(s), not {n}: this machine has {cores} core(s) and "
            f"{free / 2**30:.1f} GiB free, about {need / 2**30:.2f} GiB a worker at --chunk "
            f"{chunk} (more workers than that only wait for a core, or for memory)")
    return min(n, cap)


@contextmanager
def _ctrl_c_deferred():
    """Defer a Ctrl-C or SIGTERM during the block to its end (a half-started or half-closed Dask
    cluster prints tracebacks), then deliver it to the handler it was kept from; no effect
    outside the main thread."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pressed = []
    handlers = {s: signal.signal(s, lambda signum, frame: pressed.append(signum))
                for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:          # also after an error, e.g. of a worker that the Ctrl-C ended as it started
        for s, handler in handlers.items():
            signal.signal(s, handler)
        if pressed:
            signal.raise_signal(pressed[0])


@contextmanager
def _stderr_to_null():
    """Send started processes' standard error to /dev/null during the block, so workers do not
    each print a Ctrl-C's traceback."""
    sys.stderr.flush()
    saved, null = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 2)
    os.close(null)
    try:
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _client(workers, scheduler, memory_per_worker, dask_logs=False):
    """A Dask client of the cluster at ``scheduler`` or of a new LocalCluster (logs only with
    ``dask_logs``); start it within :func:`_ctrl_c_deferred`."""
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout=f"{SCHEDULER_TIMEOUT_S}s"), None
        except (OSError, TimeoutError, ValueError) as exc:
            raise SkyfitError(f"the Dask scheduler at {scheduler} does not answer "
                              f"({str(exc).splitlines()[0] if str(exc) else type(exc).__name__});"
                              " start it (`dask scheduler`), check the address, or leave out "
                              "--scheduler for a cluster on this machine.") from None
    import dask

    # MALLOC_TRIM_THRESHOLD_ (Dask's default) slows chunks: left unset (docs/BENCHMARKS.md)
    with dask.config.set({TRIM: None}), nullcontext() if dask_logs else _stderr_to_null(), \
            warnings.catch_warnings():
        if not dask_logs:                     # e.g. its own web server's port taken
            warnings.simplefilter("ignore")
        cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                               memory_limit=memory_per_worker, dashboard_address=None,
                               silence_logs=logging.WARNING if dask_logs else logging.CRITICAL)
    return Client(cluster), cluster


def _dask_logs_quiet(keep=False):
    """Show Dask's log lines in this process only at CRITICAL during the block, unless ``keep``."""
    if keep:
        return nullcontext()
    from distributed.utils import silence_logging_cmgr

    return silence_logging_cmgr(logging.CRITICAL)


def _close(client, cluster):
    """Close a Dask client and its local cluster (a Ctrl-C meanwhile deferred until they are)."""
    with _ctrl_c_deferred():
        for x in (client, cluster):
            if x is not None:
                x.close()


@dataclass(frozen=True)
class MapOptions:
    """How a map fits its pixels (:func:`run_map`).

    model, normalisation : every region's model and lobe (``model`` 'auto': :func:`first_fits`)
    seed : the first fits' subsets and each chunk's seed (:func:`chunk_seed`)
    patch, chunk : pixels a side of a patch fitted as one, and fits a chunk
    cache, variant : the light cache's (positions, directions) a pixel; the Mitsuba variant
    light, light_pixels : :class:`~.light.LightOptions`; the most pixels a region's first fit takes
    """

    model: str = "colour"
    normalisation: str = "ward"
    seed: int = 0
    patch: int = 1
    chunk: int = CHUNK
    cache: tuple = MAP_CACHE
    variant: str = None
    light: LightOptions = field(default_factory=LightOptions)
    light_pixels: int = LIGHT_PIXELS


@dataclass(frozen=True)
class ClusterOptions:
    """Where a map runs (:func:`run_map`): ``workers`` local processes (:func:`worker_count`) or
    a ``scheduler``'s cluster, the worker memory limit, and Dask's logs (``--debug``)."""

    workers: int = None
    scheduler: str = None
    memory_per_worker: str = "4GiB"
    dask_logs: bool = False


def run_map(manifest_path, regions, out_dir, options=MapOptions(), cluster=ClusterOptions(),
            overwrite=False, progress=True, log=print):
    """Map ``regions`` ([(material, pixels (P, 2))]) into ``out_dir`` per ``options`` on
    ``cluster``, inputs checked first; returns the summary."""
    o, c = options, cluster
    doc, root = load_manifest(manifest_path)
    skies = [frame_sky(f, root) for f in doc["frames"] if "illumination" in f]
    plan = o.light.resolve(doc, skies, len(skies), log=log)
    shape = (doc["camera"]["height"], doc["camera"]["width"])
    for _, px in regions:
        check_map_region(px, shape)
    if int(o.patch) < 1 or int(o.chunk) < 1:
        raise SkyfitError("--patch and --chunk take whole numbers of at least 1.")
    if c.scheduler and c.workers is not None:
        raise SkyfitError("--workers sizes the cluster on this machine; with --scheduler the "
                          "cluster's own workers run the map: leave out --workers.")
    # fits of the regions come first: the model, the sky's level, the EXIF labels' error
    first = o.model == "auto" or plan.sky != "spec" or exif_scaled(doc) is not None
    settings = _settings(doc, regions, o, plan.sky, first)
    out = check_dir(Path(out_dir))
    with FolderLock(out):                  # one run at a time: check, store and maps
        stored = _check_store(out / STORE, settings, overwrite)
        n_workers = None if c.scheduler else worker_count(c.workers, o.chunk, log)
        t0 = time.perf_counter()
        client = local = None
        with _dask_logs_quiet(keep=c.dask_logs):
            try:
                check_regions(manifest_path, regions)          # the frames and their light
                resume = stored is not None
                if not (resume and np.all(stored[0])):  # a given scheduler answers before any fit
                    with _ctrl_c_deferred():
                        client, local = _client(n_workers, c.scheduler, c.memory_per_worker,
                                                c.dask_logs)
                if resume and first and stored[1] is not None:     # what the store's map took
                    choices = {n: tuple(c) for n, c in stored[1]["choices"].items()}
                    light = stored[1]["light"]
                elif first:
                    choices, light = first_fits(manifest_path, regions, o.model, o.normalisation,
                                                o.seed, plan, o.light_pixels, o.variant, log)
                else:
                    choices, light = {name: (o.model, o.normalisation) for name, _ in regions}, None
                names = map_parameters(choices)
                chunks = plan_map(regions, choices, o.patch, o.chunk)
                if resume and len(stored[0]) != len(chunks):
                    _another_map(out / STORE)
                pending = [i for i in range(len(chunks)) if not resume or not stored[0][i]]
                store = _open_store(ensure_dir(out) / STORE, settings, shape, len(names),
                                    len(chunks), resume, {"choices": choices, "light": light}
                                    if first else None)
                if len(pending) < len(chunks):
                    log(f"resuming: {len(chunks) - len(pending)} of {len(chunks)} chunks already "
                        "mapped")
                if pending:
                    _map_pending(client, manifest_path, chunks, pending, store, names, o,
                                 progress, light)
            finally:
                _close(client, local)
        summary = write_map_outputs(out, store, names, regions, settings, choices)
        for name, _ in regions:
            summary["regions"][name].update(model=choices[name][0], normalisation=choices[name][1])
        summary.update(widths_include=_widths_include(doc, skies, names, light),
                       sky=_sky_summary(light),
                       models=("each region's ranked best by held-out frames (fit --model auto) on "
                               + (f"up to {o.light_pixels} of its pixels" if o.light_pixels else
                                  "every pixel") if o.model == "auto" else "as given"),
                       wall_time_s=time.perf_counter() - t0, chunks=len(chunks),
                       chunks_this_run=len(pending), workers=n_workers,
                       scheduler=c.scheduler or "LocalCluster",
                       memory_per_worker=c.memory_per_worker,
                       chunk_seeds="numpy SeedSequence([seed, chunk index])")
        write_json(out / MAP_SUMMARY, summary)
        return summary


def _map_pending(client, manifest_path, chunks, pending, store, names, options, progress,
                 light):
    """Submit every pending chunk and write each result as it comes."""
    from distributed import as_completed
    from tqdm import tqdm

    futures = {client.submit(fit_pixels, str(manifest_path), chunks[i]["materials"],
                             chunks[i]["pixels"], model=chunks[i]["model"],
                             normalisation=chunks[i]["normalisation"],
                             seed=chunk_seed(options.seed, i), cache=options.cache,
                             groups=chunks[i]["groups"], variant=options.variant, light=light,
                             pure=False): i
               for i in pending}
    with tqdm(total=sum(len(chunks[i]["pixels"]) for i in pending), desc="map", unit="px",
              disable=not progress) as bar:     # closed on Ctrl-C too: the message's own line
        for fut in as_completed(futures):
            i = futures[fut]
            try:
                res = fut.result()
            except SkyfitError:
                for f in futures:
                    f.cancel()
                raise
            _write_chunk(store, chunks[i], res, names)
            store["done"][i] = True             # after the chunk's values: a resume redoes it
            bar.update(len(chunks[i]["pixels"]))


def write_map_outputs(out, store, names, regions, settings, choices):
    """Write the map's EXRs and PNG previews from the store; returns the summary."""
    theta, lo, hi = (store[k][:] for k in ("theta", "lo", "hi"))
    chi2, dof, bits = store["chi2"][:], store["dof"][:], store["warnings"][:]
    mapped = bits >= 0
    determined = mapped & ((bits & UNDETERMINED) == 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        per_dof = np.where(mapped & (dof > 0), chi2 / dof, np.nan)
    images = {"chi2_per_dof": per_dof, "warnings": np.where(mapped, bits, np.nan)}
    for i, n in enumerate(names):
        images[n] = theta[i]
        images[f"{n}_width95"] = hi[i] - lo[i]
    for key, img in images.items():
        write_exr(out / f"{key}.exr", img.astype(np.float32))
    for n in set(PARAMETER_ORDER) - set(names):      # another map's planes (--overwrite)
        for f in (f"{n}.exr", f"{n}_width95.exr", f"{n}.png"):
            (out / f).unlink(missing_ok=True)
    # each region's pixels and the planes of its model: a plane's preview shows the pixels of
    # the regions whose model has it, and names the others
    within = {name: np.zeros(mapped.shape, bool) for name, _ in regions}
    for name, px in regions:
        px = np.asarray(px).reshape(-1, 2)
        within[name][px[:, 1], px[:, 0]] = True
    own = {name: [(i, n) for i, n in enumerate(names) if n in PARAMETERS[choices[name][0]]]
           for name in within}
    # a parameter is determined where neither the pixel nor that parameter is flagged
    known = {n: mapped & ((bits & undetermined_bits(n)) == 0) for n in names}
    for i, n in enumerate(names):
        has = np.any([within[name] for name in within if (i, n) in own[name]], axis=0)
        _preview(out / f"{n}.png", theta[i], mapped & has, known[n] & has, n,
                 [name for name in within if (i, n) not in own[name]])
    _preview(out / "chi2_per_dof.png", per_dof, mapped, mapped, "chi^2 / dof")
    summary = {"settings": settings, "parameters": names, "store": STORE,
               "warning_bits": WARNINGS, "undetermined_bits": UNDETERMINED,
               "units": "reflectances unitless, sigma_alpha rms slope; widths of 95% intervals; "
               "EXR maps NaN outside the regions; each parameter's statistics over the pixels "
               "where it is determined (determined_by_parameter)",
               "regions": {}}
    for name, sel in within.items():
        ok = {n: sel & known[n] for _, n in own[name]}
        summary["regions"][name] = {
            "pixels": int(sel.sum()), "mapped": int((sel & mapped).sum()),
            "determined": int((sel & determined).sum()),
            "determined_by_parameter": {n: int(ok[n].sum()) for _, n in own[name]},
            "warnings": {w: int(((bits & b) > 0)[sel & mapped].sum()) for w, b in WARNINGS.items()},
            "median": {n: _stat(np.median, theta[i][ok[n]]) for i, n in own[name]},
            "iqr": {n: _stat(lambda v: float(np.subtract(*np.percentile(v, [75, 25]))),
                             theta[i][ok[n]]) for i, n in own[name]},
            "median_width95": {n: _stat(np.median, (hi[i] - lo[i])[ok[n]])
                               for i, n in own[name]}}
    return summary


def _sky_summary(light):
    """The map summary's record of the sky the map took (``light``: :func:`first_fits`')."""
    if light is None or light["fitted"] == "spec":
        return {"source": "the spec's, taken as exact (--sky spec)"}
    return {"source": f"the spec's, its level fitted first with the regions' materials (--sky "
                      f"{light['fitted']}; its shape is the spec's)", **light["sky"],
            "sun_level_sd": light["sun_level_sd"], "sun_source": light["sun_source"],
            "error_sd_by_region": {n: r["sd"] for n, r in light["regions"].items()},
            "meaning": "each frame lit by the spec's sky at level k (against the sun; a curve "
                       "over the day where terms); a pixel's interval takes in its region's "
                       "error_sd (a reflectance's in proportion to its value), or its range "
                       "over the levels a fit could not tell apart"}


def _widths_include(doc, skies, names, light=None):
    """What the maps' 95% widths include beyond the data's noise."""
    ingest = doc.get("ingest") or {}
    out = ["the light cache's Monte Carlo error (from its two halves)"]
    if light is not None and light["fitted"] != "spec":
        out.append("the fitted sky level's error, each pixel its region's share (a "
                   "reflectance's in proportion to its value; over the levels the fit could "
                   "not tell apart where it did not determine the level); the sky's shape is "
                   "the spec's")
        if light_level_sd(doc, names, light["sun_level_sd"]).any():
            out.append(f"the sun's level, known to +-{100 * light['sun_level_sd']:.0f}% (1 sd, "
                       f"a {light['sun_source']} sun), on the reflectances")
    elif default_sky(doc, skies) != "spec":
        out.append("no error of the light's: the spec's sky and sun are taken as exact "
                   "(--sky spec)")
    cal = ingest.get("calibration") or {}
    if cal.get("scale_relative_sd"):
        out.append("the exposure calibration's error (ingest.calibration)")
    if cal.get("references"):
        out.append("the references' reflectances' error, "
                   f"{100 * max(cal.get('reference_relative_sd') or [0]):.3g}% "
                   "(ingest.calibration.reference_relative_sd), on the reflectances"
                   + ("" if any(cal.get("reference_relative_sd") or []) else
                      ": none, they were given as exact"))
    if light is not None and any(r.get("labels_sd") for r in light["regions"].values()):
        out.append("the error of the EXIF labels that scale the given exposure, each pixel its "
                   "region's share (calibration_error_sd of its fit; a reflectance's in "
                   "proportion to its value)")
    if (ingest.get("options") or {}).get("vignetting") == "none" and "photos" in ingest:
        out.append("the uncorrected lens falloff's error (ingest --vignetting none): half the "
                   "cos^4 falloff between the reference's place and each pixel's")
    if any(pose_sd((doc.get("camera") or {}).get("pose_sd_deg")).values()):
        out.append("not the camera pose's uncertainty (camera.pose_sd_deg), which region fits "
                   "take in")
    rel = (ingest.get("colour_matrix") or {}).get("relative_sd")
    if rel:
        out.append(f"the camera colour matrix's error, {100 * rel:.3g}% per entry "
                   "(ingest.colour_matrix), on C")
    return out


def _stat(f, v):
    return float(f(v)) if len(v) else None


def _preview(path, image, mapped, determined, label, lacking=()):
    """A PNG of ``image`` with a colour bar; undetermined pixels grey, unmapped white, the title
    naming the regions ``lacking`` the parameter."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.2, 4.2))
    unsure = mapped & ~determined
    im = ax.imshow(np.where(determined, image, np.nan), cmap="viridis", interpolation="nearest")
    ax.imshow(np.where(unsure, 0.6, np.nan), cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    fig.colorbar(im, ax=ax, fraction=0.046, label=label)
    n_u = int(unsure.sum())
    notes = ([f"{n_u} undetermined pixels grey"] if n_u else []) + (
        [f"not in the model of {', '.join(lacking)}"] if lacking else [])
    ax.set_title(label + (f" ({'; '.join(notes)})" if notes else ""), fontsize=9)
    ax.set(xticks=[], yticks=[])
    fig.tight_layout()                              # the colour bar's label kept whole
    save_figure(fig, path)
