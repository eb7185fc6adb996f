"""Render a day: spec -> linear EXR frames, sensor images, manifest, contact sheet.

The output folder holds::

    manifest.json            the contract with fitting (schema skyfit-manifest/1)
    frames/radiance_NNN.exr  linear RGB radiance [W m^-2 sr^-1]
    frames/sensor_NNN.exr    the sensor model's pixel values [DN] (integers stored as float)
    frames/sigma_NNN.exr     per-pixel standard deviation for chi-square [DN]; inf = saturated
                             (sensor noise, quantisation and the render's Monte Carlo error)
    contact_sheet.png        the day at the sensor's exposure (sRGB preview)

Each frame is rendered as two half-spp passes with seeds ``seed + index`` and
``seed + index + 2^31`` (their difference estimates the Monte Carlo error) and its noise drawn from
``numpy.random.default_rng([seed, index])``, so a frame does not depend on
which frames were rendered before it: an interrupted run resumes where it
stopped and gives the same files as an uninterrupted one.
"""

import datetime as dt
import json
import time
from pathlib import Path

import numpy as np

from ..physics.camera import SensorModel
from ..physics.colour import SRGB_LUMINANCE
from ..errors import SkyfitError
from ..render.scene_xml import pass_spp
from .manifest import SCHEMA, illumination_record, sensor_record, versions, write_manifest


def resolve_exposure(spec):
    """The sensor exposure [sr m^2 W^-1]: the spec's, or 'auto'.

    'auto' puts a white Lambertian horizontal surface under the day's highest
    global horizontal irradiance at 80% of full scale (E/pi * exposure = 0.8),
    known before rendering so that every frame, and a resumed run, shares it.
    """
    e = spec.sensor["exposure"]
    if e != "auto":
        return float(e)
    lum = [float(f.sky.horizontal_irradiance(n=128) @ SRGB_LUMINANCE) for f in spec.frames
           if not f.skipped]
    peak = max(lum, default=0.0)
    if peak <= 0:
        raise SkyfitError("every frame is dark, so sensor.exposure = 'auto' has nothing to go by; "
                          "give sensor.exposure [sr m^2 W^-1] explicitly.")
    return 0.8 * np.pi / peak


def render_sequence(spec, out_dir, overwrite=False, progress=True, log=print):
    """Render every frame of a validated spec into ``out_dir``; returns the manifest dict.

    Refuses a folder that holds another run's manifest unless ``overwrite``;
    resumes a folder that holds this run's (complete frames are kept).
    """
    from ..render import setup
    from ..render.daylight import update_sky
    from ..render.frame import render_with_error
    from ..render.image import contact_sheet, read_exr, write_exr, write_png
    from ..render.scene_xml import load_scene

    out = Path(out_dir)
    run_id = spec.run_id()
    mpath = out / "manifest.json"
    done = {}
    if mpath.exists():
        old = json.loads(mpath.read_text())
        if old.get("run_id") != run_id and not overwrite:
            raise SkyfitError(f"{out} holds another run ({old.get('name')!r}, run {old.get('run_id')});"
                              " render into an empty folder, or pass --overwrite to replace it.")
        if old.get("run_id") == run_id:
            done = {f["index"]: f for f in old["frames"] if f["status"] == "rendered"
                    and all((out / f[k]).exists() for k in ("radiance", "sensor", "sigma"))}
    (out / "frames").mkdir(parents=True, exist_ok=True)

    mi = setup(spec.render["variant"])
    scene, params, mats, to_world, xml = load_scene(spec)
    sensor = SensorModel(exposure=resolve_exposure(spec),
                         **{k: spec.sensor[k] for k in ("response", "gamma", "bits", "noise_percent",
                                                        "cos4")})
    cam = spec.camera
    seed = int(spec.render["seed"])
    half = pass_spp(spec.render["spp"], spec.render["sampler"])
    manifest = {
        "schema": SCHEMA, "source": "render", "run_id": run_id, "name": spec.raw.get("name"),
        "status": "incomplete",
        "created": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "spec": spec.raw, "spec_dir": spec.base_dir.resolve(),
        "location": spec.raw["location"],
        "scene": {"file": spec.scene_file, "xml": xml, "materials": mats},
        "camera": {"to_world": to_world, "fov_deg": cam["fov_deg"], "fov_axis": "x",
                   "width": cam["width"], "height": cam["height"]},
        "sensor": sensor_record(sensor),
        "render": {**spec.render, "spp_rendered": 2 * half, "integrator": "path",
                   "seed_rule": "two half-spp passes with "
                   "mitsuba seeds seed + index and seed + index + 2^31; noise rng = "
                   "numpy.random.default_rng([seed, index])"},
        "versions": versions(), "frames": [],
    }
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(spec.frames), desc="render", unit="frame", initial=len(done))
    for f in spec.frames:
        rec = {"index": f.index, "time": f.time.isoformat(),
               "time_utc": f.time.astimezone(dt.timezone.utc).isoformat(),
               "sun_zenith_deg": f.sun_zenith_deg,
               "sun_azimuth_deg": f.sun_azimuth_deg, "below_horizon": f.sun_zenith_deg >= 90.0,
               "illumination": illumination_record(f.sky), "seed": seed + f.index}
        names = {k: f"frames/{k}_{f.index:03d}.exr" for k in ("radiance", "sensor", "sigma")}
        if f.skipped:
            rec["status"] = "skipped"
            log(f"frame {f.index} at {f.time:%H:%M}: sun below the horizon, skipped as the spec says")
        elif f.index in done:
            rec.update(status="rendered", **names)
        else:
            update_sky(params, f.sky, "sky.")
            t0 = time.perf_counter()
            img, img_sd = render_with_error(mi, scene, params, seed + f.index, half)
            rec["render_seconds"] = time.perf_counter() - t0
            values, sigma = sensor.capture(img, np.random.default_rng([seed, f.index]),
                                           fov_deg=cam["fov_deg"], radiance_sd=img_sd)
            write_exr(out / names["radiance"], img)
            write_exr(out / names["sensor"], values.astype(np.float32))
            write_exr(out / names["sigma"], sigma)
            rec.update(status="rendered", **names)
            if bar is not None:
                bar.update(1)
        manifest["frames"].append(rec)
        if "render_seconds" in rec:               # checkpoint: the frames so far, the rest pending
            pending = [{"index": g.index, "status": "pending"} for g in spec.frames[f.index + 1:]]
            write_manifest(mpath, {**manifest, "frames": manifest["frames"] + pending})
    if bar is not None:
        bar.close()
    manifest["status"] = "complete"
    rendered = [read_exr(out / r["radiance"]) for r in manifest["frames"] if r["status"] == "rendered"]
    if rendered:
        write_png(out / "contact_sheet.png", contact_sheet(rendered, sensor.exposure))
    write_manifest(mpath, manifest)
    skipped = sum(r["status"] == "skipped" for r in manifest["frames"])
    log(f"{len(rendered)} frames rendered ({len(done)} kept from an earlier run), {skipped} skipped;"
        f" manifest, frames and contact sheet in {out.resolve()}")
    return manifest
