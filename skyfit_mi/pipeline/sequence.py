"""Render a day: spec -> linear EXR frames, sensor images, manifest, contact sheet.

The output folder holds::

    manifest.json            the contract with fitting (schema skyfit-manifest/2)
    frames/radiance_NNN.exr  linear RGB radiance [W m^-2 sr^-1]
    frames/sensor_NNN.exr    the sensor model's pixel values [DN] (integers stored as float)
    frames/sigma_NNN.exr     per-pixel standard deviation for chi-square [DN]
                             (sensor noise, quantisation and the render's Monte Carlo error)
    contact_sheet.png        the day at the sensor's exposure (sRGB preview)

Each frame is rendered as two half-spp passes with seeds ``seed + index`` and
``seed + index + 2^31`` (their difference estimates the Monte Carlo error), its noise drawn
from ``numpy.random.default_rng([seed, index])``: a frame does not depend on the frames before
it, so an interrupted run resumes to the same files.  The steps (:func:`prepare_folder`,
:class:`FrameRenderer`, :func:`capture_frame`, :func:`write_frame`, :func:`manifest_header`,
:func:`finish`) are separate for relight and ingest to reuse.
"""

import datetime as dt
import time
from pathlib import Path

import numpy as np

from ..errors import SkyfitError, listed
from ..files import FolderLock, ensure_dir
from ..physics.camera import SensorModel
from ..physics.colour import SRGB_LUMINANCE
from ..render import setup
from ..render.daylight import update_sky
from ..render.frame import render_with_error
from ..render.image import contact_sheet, read_exr_checked, write_exr, write_png
from ..render.scene_xml import load_scene, pass_spp
from .manifest import (SCHEMA, frame_label, illumination_record, keep_frame_image, load_manifest,
                       manifest_file, read_frame_image, sensor_record, versions,
                       write_manifest)

#: The files of one frame, by kind: the radiance, its standard error (Monte Carlo)
#: [W m^-2 sr^-1], the sensor's values and their sigma [DN].
FRAME_FILES = ("radiance", "radiance_sigma", "sensor", "sigma")
#: The units of each kind of frame file (its EXR header's ``skyfit/units``).
FRAME_UNITS = {"radiance": "W m^-2 sr^-1", "radiance_sigma": "W m^-2 sr^-1", "sensor": "DN",
               "sigma": "DN"}


def spec_sensor(spec):
    """The spec's :class:`SensorModel`, its exposure [sr m^2 W^-1] the spec's, or for 'auto' the
    one putting a white horizontal Lambertian under the day's highest global irradiance at 80%
    of full scale (E/pi * exposure = 0.8), known before rendering so every frame and a resume
    share it."""
    e = spec.sensor["exposure"]
    if e == "auto":
        lum = [float(f.sky.horizontal_irradiance() @ SRGB_LUMINANCE) for f in spec.frames
               if not f.skipped]
        peak = max(lum, default=0.0)
        if spec.frames and all(f.below_horizon for f in spec.frames):
            raise SkyfitError("the sun is below the horizon at every time of the spec (first "
                              f"{spec.frames[0].time}); check [time] (local times, its "
                              "timezone) and [location].")
        if peak <= 0:
            raise SkyfitError("every frame is dark, so sensor.exposure = 'auto' has nothing to go "
                              "by; give sensor.exposure [sr m^2 W^-1] explicitly.")
        e = 0.8 * np.pi / peak
    return SensorModel(exposure=float(e),
                       **{k: spec.sensor[k] for k in ("response", "gamma", "bits", "noise_percent",
                                                      "cos4")})


def clear_run(out):
    """Remove an earlier run's files (only the names a render writes) from ``out``."""
    for p in [out / "manifest.json", out / "contact_sheet.png",
              *(out / "frames").glob("*_[0-9][0-9][0-9]*.exr")]:
        if p.name.split("_")[0] in FRAME_FILES or p.parent == out:
            p.unlink(missing_ok=True)


def prepare_folder(out, run_id, shape, overwrite=False, log=print):
    """Make ``out`` ready for run ``run_id`` (lock held); returns the frame records a resume
    keeps, by index.  Another run's or a damaged manifest is refused unless ``overwrite``
    (which starts clean); a resume's kept frames are checked against ``shape``, a damaged one
    rendered again."""
    ensure_dir(out / "frames")
    if overwrite:
        clear_run(out)
        fits = sorted(p.name for p in out.glob("fit_*.json"))
        if fits:
            log(f"{out}: {listed(fits)} fitted the run this replaces; they stay, but relight and "
                "export refuse them, and a fit into this folder of some regions only: fit them "
                "all again")
        return {}
    if not manifest_file(out).exists():
        return {}
    old, _ = load_manifest(out)          # a damaged one: ManifestError says --overwrite
    if old.get("run_id") != run_id:
        raise SkyfitError(f"{out} holds another run ({old.get('name')!r}, run {old.get('run_id')});"
                          " write into an empty folder, or pass --overwrite to replace it.")
    kept = {}
    for f in old["frames"]:
        if f["status"] != "rendered":
            continue
        try:
            for k in FRAME_FILES:
                if k not in f:
                    raise SkyfitError(f"an older render without its {k} image")
                read_exr_checked(out / f[k], shape)
        except SkyfitError as exc:
            log(f"frame {f['index']}: {exc}; rendering it again")
            continue
        kept[f["index"]] = f
    return kept


class FrameRenderer:
    """A spec's scene in Mitsuba: the radiance of each frame's sky and its Monte Carlo error."""

    def __init__(self, spec):
        self.mi = setup(spec.render["variant"])
        self.scene, self.params, self.materials, self.to_world, self.xml = load_scene(spec)
        self.seed = int(spec.render["seed"])
        self.half = pass_spp(spec.render["spp"], spec.render["sampler"])

    def render(self, frame):
        """(radiance (H, W, 3) [W m^-2 sr^-1], its standard error) of a spec frame."""
        update_sky(self.params, frame.sky, "sky.")
        return render_with_error(self.mi, self.scene, self.params, self.seed + frame.index,
                                 self.half)


def capture_frame(sensor, radiance, radiance_sd, seed, index, fov_deg):
    """The sensor's values and sigmas [DN] for frame ``index`` (seeded), and whether it is dark."""
    values, sigma = sensor.capture(radiance, np.random.default_rng([seed, index]),
                                   fov_deg=fov_deg, radiance_sd=radiance_sd)
    return values, sigma, not np.any(values > 0)


def write_frame(out, index, radiance, radiance_sd, values, sigma, time=None):
    """Write one frame's EXRs (:data:`FRAME_FILES`) atomically, their headers giving kind, units,
    index and time (None for a lab light), caching the radiance and its error
    (:func:`~skyfit_mi.pipeline.manifest.keep_frame_image`); returns relative paths by kind."""
    names = {k: f"frames/{k}_{index:03d}.exr" for k in FRAME_FILES}
    images = (radiance, radiance_sd, values.astype(np.float32), sigma)
    for key, image in zip(FRAME_FILES, images):
        meta = {"kind": key, "units": FRAME_UNITS[key], "frame": int(index), "time": time}
        path = write_exr(out / names[key], image, meta)
        if key.startswith("radiance"):
            keep_frame_image(path, image)
    return names


def manifest_header(spec, sensor, scene, render, source="render", run_id=None):
    """The incomplete manifest, before any frame, of ``spec``'s sequence by command ``source``
    ('render', 'relight', 'ingest'); ``scene`` is (xml, materials, camera to_world), ``render``
    the record of how frames were made, ``run_id`` by default the spec's."""
    xml, materials, to_world = scene
    cam = spec.camera
    return {
        "schema": SCHEMA, "source": source, "run_id": run_id or spec.run_id(),
        "name": spec.raw.get("name"), "status": "incomplete",
        "created": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "spec": spec.raw, "spec_dir": spec.base_dir.resolve(),
        **({"location": spec.raw["location"]} if "location" in spec.raw else {}),
        "scene": {"file": spec.scene_file, "xml": xml, "materials": materials},
        "camera": {"to_world": to_world, "fov_deg": cam["fov_deg"], "fov_axis": "x",
                   "width": cam["width"], "height": cam["height"],
                   **({"pose_sd_deg": cam["pose_sd_deg"]} if "pose_sd_deg" in cam else {})},
        "sensor": sensor_record(sensor), "render": render, "versions": versions(), "frames": [],
    }


def frame_record(frame, seed, out):
    """A spec frame's manifest record (no files) for a manifest in folder ``out``."""
    when = {} if frame.time is None else {     # a lab light: by index alone
        "time": frame.time.isoformat(),
        "time_utc": frame.time.astimezone(dt.timezone.utc).isoformat()}
    return {"index": frame.index, **when,
            "sun_zenith_deg": frame.sun_zenith_deg, "sun_azimuth_deg": frame.sun_azimuth_deg,
            "below_horizon": frame.sun_zenith_deg >= 90.0,
            "illumination": illumination_record(frame.sky, out), "seed": seed + frame.index}


def finish(out, manifest, exposure):
    """Write the contact sheet and the complete manifest; returns the rendered frames' count."""
    manifest["status"] = "complete"
    rendered = [r for r in manifest["frames"] if r["status"] == "rendered" and "radiance" in r]
    if rendered:
        shape = (manifest["camera"]["height"], manifest["camera"]["width"], 3)
        rendered = [read_frame_image(out, r, "radiance", shape) for r in rendered]
        write_png(out / "contact_sheet.png", contact_sheet(rendered, exposure))
    write_manifest(out, manifest)
    return len(rendered)


def render_sequence(spec, out_dir, overwrite=False, progress=True, log=print, source="render"):
    """Render every frame of a validated spec into ``out_dir``; returns the manifest dict.
    The folder is locked for the run; another run's folder is refused unless ``overwrite``, and
    this run's is resumed."""
    out = Path(out_dir)
    sensor = spec_sensor(spec)                # its exposure checked before the folder is made
    with FolderLock(out) as lock:
        if lock.stale is not None:
            pid = lock.stale.get("pid")
            log(f"{out}: took over the lock of a run that no longer exists"
                + ("" if pid == "unknown" else f" (process {pid})") + "; resuming")
        return _render(spec, sensor, out, overwrite, progress, log, source)


#: Share of a frame's lit pixel values at the top code above which the render says so.
SATURATED_SHARE = 0.01
#: Fewer samples per pixel than this leave each pixel's Monte Carlo error heavy-tailed and its
#: estimate rough: fits of 16-spp days under a low sun missed their truth with narrow intervals
#: where 128 spp held it.
FEW_SPP = 64


def _render(spec, sensor, out, overwrite, progress, log, source):
    cam = spec.camera
    done = prepare_folder(out, spec.run_id(), (cam["height"], cam["width"], 3), overwrite, log)
    renderer = FrameRenderer(spec)
    if 2 * renderer.half < FEW_SPP:
        log(f"spp {2 * renderer.half}: with so few samples a pixel's Monte Carlo error is "
            "heavy-tailed and its estimate (from two half passes over 3x3 pixels) rough, so "
            f"fits of these frames may be surer than they should; {FEW_SPP} or more for fitting")
    render = {**spec.render, "spp_rendered": 2 * renderer.half,      # settings and seeds
              "seed_rule": "two half-spp passes with mitsuba seeds seed + index and seed + "
              "index + 2^31; noise rng = numpy.random.default_rng([seed, index])"}
    manifest = manifest_header(spec, sensor, (renderer.xml, renderer.materials,
                                              renderer.to_world), render, source)
    from tqdm import tqdm

    bar = tqdm(total=len(spec.frames), desc="render", unit="frame", initial=len(done),
               disable=not progress)
    saturated = []                                   # (frame, share of its lit values clipped)
    for f in spec.frames:
        rec = frame_record(f, renderer.seed, out)
        if f.skipped:
            rec["status"] = "skipped"
            log(f"{frame_label(f.index, f.time)}: sun below the horizon, skipped as the spec "
                "says")
        elif f.index in done:
            rec.update(status="rendered", **{k: done[f.index][k] for k in FRAME_FILES},
                       **({"dark": True} if done[f.index].get("dark") else {}))
        else:
            t0 = time.perf_counter()
            img, img_sd = renderer.render(f)
            rec["render_seconds"] = time.perf_counter() - t0
            values, sigma, dark = capture_frame(sensor, img, img_sd, renderer.seed, f.index,
                                                cam["fov_deg"])
            rec.update(status="rendered", **write_frame(out, f.index, img, img_sd, values, sigma,
                                                        f.time))
            if dark:
                rec["dark"] = True
                log(f"{frame_label(f.index, f.time)}: black at this exposure (no light reached "
                    "the camera); kept and marked dark in the manifest")
            lit = img > 0
            share = float(np.mean(values[lit] == sensor.max_code)) if lit.any() else 0.0
            if share > SATURATED_SHARE:
                saturated.append((frame_label(f.index, f.time), share))
            bar.update(1)
        manifest["frames"].append(rec)
        if "render_seconds" in rec:               # checkpoint: the frames so far, the rest pending
            pending = [{"index": g.index, "status": "pending"} for g in spec.frames[f.index + 1:]]
            write_manifest(out, {**manifest, "frames": manifest["frames"] + pending})
    bar.close()
    if saturated:
        log(f"{listed([name for name, _ in saturated])}: up to "
            f"{max(share for _, share in saturated):.0%} of the lit pixel values at the top code, "
            "which a fit takes only as 'at least this' (it tells less): a lower "
            "sensor.exposure keeps them (auto sets a white horizontal surface at 80% in "
            "luminance, which a surface facing a low sun, or a blue sky's blue, exceeds)")
    n = finish(out, manifest, sensor.exposure)
    skipped = sum(r["status"] == "skipped" for r in manifest["frames"])
    dark = sum(bool(r.get("dark")) for r in manifest["frames"])
    log(f"{n} frames rendered ({len(done)} kept from an earlier run), {skipped} skipped"
        + (f", {dark} dark" if dark else "")
        + f"; manifest, frames and contact sheet in {out.resolve()}")
    return manifest
