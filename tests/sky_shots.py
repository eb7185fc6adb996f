"""Bracketed fisheye JPEGs of a known sky, and a grey card's shots, as a camera would take them.

A camera whose speed meets its saturation definition (``gain`` 1:
:data:`~skyfit_mi.pipeline.sky_series.SATURATION_LUMINANCE`) photographs a
:class:`~skyfit_mi.physics.sky.Sky` through an upward equidistant fisheye: linear value
v = gain L H EFFICACY / SATURATION_LUMINANCE, shot noise of ``noise`` (relative, at full
scale), sRGB, 8-bit JPEG with the EXIF time and exposure (f/8, ISO 100).  The sun and its flare
(within ``flare_deg``) are far brighter than any exposure holds.  :func:`photographed_day`:
a day rendered under measured skies and the same day lit by its skies as photographed.  Used by
tests/test_sky_series.py and scripts/sky_series_fit.py.
"""
import datetime as dt
import json
import shutil
from pathlib import Path

import numpy as np
from PIL import Image

from skyfit_mi.physics.camera import SensorModel
from skyfit_mi.physics.sky import EFFICACY_CLEAR
from skyfit_mi.pipeline.sky_series import (
    SATURATION_LUMINANCE,
    SERIES_NAME,
    CardOptions,
    ShotOptions,
    fisheye_directions,
    sky_series,
)
from skyfit_testkit.photo_sim import SIM_F_NUMBER, SIM_ISO, _exif

#: Exposure times of a bracket [s]: four stops apart, two each way of 1/500.
BRACKET_S = (1 / 125, 1 / 500, 1 / 2000, 1 / 8000)
#: The sun's flare in the fisheye [degrees]: clipped in every shot.
FLARE_DEG = 2.0
#: The card's pixels in its shots (x0, y0, x1, y1).
CARD_BOX = (4, 4, 28, 28)
#: The fisheye's north rotation in the photographed day [degrees].
NORTH_DEG = 20.0


def fisheye_radiance(sky, size, north_rotation_deg=0.0, flare_deg=FLARE_DEG):
    """The sky's radiance (size, size, 3) [W m^-2 sr^-1] in an upward equidistant fisheye, 0
    outside the horizon's circle, the sun's flare 1e7 (clipped in any shot)."""
    d, inside = fisheye_directions(size, size, north_rotation_deg)
    up = inside & (d[..., 2] > 0)
    image = np.zeros((size, size, 3))
    image[up] = sky.sky_radiance(d[up])
    near = up & (d @ sky.sun_direction > np.cos(np.radians(flare_deg)))
    image[near] = 1e7
    return image


def _jpeg(path, radiance, exposure_s, time, gain, noise, rng, gamma=None):
    """One 8-bit JPEG of ``radiance`` at ``exposure_s`` (sRGB, or a pure ``gamma`` curve: a
    camera's own tone curve), with EXIF."""
    h = exposure_s * SIM_ISO / SIM_F_NUMBER ** 2
    v = gain * radiance * h * EFFICACY_CLEAR / SATURATION_LUMINANCE
    v = v + rng.normal(size=v.shape) * noise * np.sqrt(np.clip(v, 0.0, 1.0))
    sensor = SensorModel(1.0, response="srgb", bits=8) if gamma is None else \
        SensorModel(1.0, response="gamma", gamma=gamma, bits=8)
    codes = sensor.respond(v) * 255.0
    Image.fromarray(np.round(codes).astype(np.uint8)).save(
        path, quality=95, exif=_exif(time, True, exposure_s))


def photograph_sky(sky, time, folder, *, size=128, gain=1.0, noise=0.005, seed=0,
                   north_rotation_deg=0.0, falloff=1.0, spacing_s=1, gamma=None,
                   flare_deg=FLARE_DEG):
    """The bracket (:data:`BRACKET_S`) of ``sky`` at ``time`` (aware), ``spacing_s`` apart, as
    JPEGs in ``folder``, through a lens whose relative response is ``falloff`` (size, size);
    returns their paths; ``gamma`` encodes them with a pure gamma curve instead of sRGB;
    ``flare_deg`` 0: the sun behind cloud (no flare)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    radiance = fisheye_radiance(sky, size, north_rotation_deg, flare_deg) \
        * np.asarray(falloff)[..., None]
    out = []
    for i, t in enumerate(BRACKET_S):
        when = time + dt.timedelta(seconds=i * spacing_s)
        path = folder / f"sky_{when:%H%M%S}_{i}.jpg"
        _jpeg(path, radiance, t, when, gain, noise, rng, gamma)
        out.append(path)
    return out


def photograph_card(sky, time, folder, *, reflectance=0.18, size=32, gain=1.0, noise=0.005,
                    seed=0, shade=False, shaded_columns=0, shade_share=0.5, gamma=None):
    """A horizontal Lambertian grey card lit by ``sky`` (by ``shade_share`` of its sky alone
    where in ``shade``, or in its first ``shaded_columns``), filling a ``size``-pixel JPEG
    exposed to put it near a third of full scale (``gamma``: :func:`photograph_sky`'s), in
    ``folder``; returns its path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    shaded = reflectance / np.pi * shade_share * sky.sky_horizontal_irradiance()
    lit = shaded if shade else reflectance / np.pi * sky.horizontal_irradiance()
    radiance = np.array(np.broadcast_to(lit, (size, size, 3)))
    radiance[:, :shaded_columns] = shaded
    h = 0.35 / (gain * float(radiance.max()) * EFFICACY_CLEAR / SATURATION_LUMINANCE)
    exposure_s = float(h * SIM_F_NUMBER ** 2 / SIM_ISO)
    path = folder / f"card_{time:%H%M%S}.jpg"
    _jpeg(path, radiance, exposure_s, time, gain, noise, np.random.default_rng(seed), gamma)
    return path


def series(folder, **kw):
    """``sky_series`` of ``folder``/shots with the card of ``folder``/card, into ``folder``/sky;
    told the shots' codes are sRGB's exactly, as this camera writes them (``exact_curve``)."""
    return sky_series([folder / "shots"], folder / "sky",
                      card=CardOptions((str(folder / "card"),), CARD_BOX), log=lambda *a: None,
                      **{"shots": ShotOptions(exact_curve=True), **kw})


def photographed_day(folder, scans, size=16, noise_percent=1.0, spp=128, gamma=None,
                     exact_curve=None):
    """The disc rendered under ``scans`` (:func:`measured_light.measured_disc_day`), each
    frame's sky photographed (a bracket 2 s before the frame, north turned :data:`NORTH_DEG`;
    ``gamma``: the camera's own curve, :func:`photograph_sky`) and its card 30 s after, merged by
    ``skyfit sky-series`` (``exact_curve``: told the codes are sRGB's; default so for an sRGB
    camera, else the curve measured), and the day relabelled with the light a spec naming the
    series gives: (the day, the relabelled day, the relabelled frames' skies by time)."""
    from measured_light import measured_disc_day, relabelled

    from skyfit_mi.pipeline.manifest import frame_sky, load_manifest
    from skyfit_mi.pipeline.spec import load_spec

    folder = Path(folder)
    exact = gamma is None if exact_curve is None else exact_curve
    tag = "" if gamma is None and exact else f"_g{gamma}_{'exact' if exact else 'measured'}"
    day = measured_disc_day(folder, scans, size=size, noise_percent=noise_percent, spp=spp)
    doc, _ = load_manifest(day)
    shots, card = (folder / (k if gamma is None else f"{k}_g{gamma}") for k in ("shots", "card"))
    for old in (shots, card):                   # the shots of this day only
        shutil.rmtree(old, ignore_errors=True)
    for k, f in enumerate(doc["frames"]):
        t = dt.datetime.fromisoformat(f["time"])
        sky = frame_sky(f, day)
        photograph_sky(sky, t - dt.timedelta(seconds=2), shots, seed=k,
                       north_rotation_deg=NORTH_DEG, gamma=gamma)
        photograph_card(sky, t + dt.timedelta(seconds=30), card, seed=10 + k, gamma=gamma)
    sky_series([shots], folder / f"sky{tag}", card=CardOptions((str(card),), CARD_BOX),
               shots=ShotOptions(exact_curve=exact), overwrite=True, log=lambda *a: None)
    spec = json.loads((folder / "measured_sky.json").read_text())
    spec["sky"] = {"type": "envmap", "file": f"sky{tag}/{SERIES_NAME}",
                   "north_rotation_deg": NORTH_DEG, "ground_albedo": 0.2}
    (folder / f"series{tag}.json").write_text(json.dumps(spec))
    skies = {f.time: f.sky for f in load_spec(folder / f"series{tag}.json").frames}
    photographed = relabelled(day, folder / f"photographed{tag}",
                              lambda f, _: skies[dt.datetime.fromisoformat(f["time"])])
    return day, photographed, skies


def fit_disc(light, sun_sd):
    """The colour-model fit of the disc of the day ``light`` with the sky's level under its
    prior and the sun's level to ``sun_sd``: (each parameter's 95% interval holds its truth,
    C's median 95% half-width over the truth, the fit's result)."""
    from measured_light import TRUTH

    from skyfit_mi.fitting.chi2 import parse_region
    from skyfit_mi.fitting.fit import fit_regions
    from skyfit_mi.fitting.light import LightOptions

    names = ("C_r", "C_g", "C_b", "rho_s", "sigma_alpha")
    r = next(fit_regions(light, [("disc", parse_region("rect:3,3,12,12"))], model="colour",
                         light=LightOptions(sky="prior", sun_sd=sun_sd), log=lambda *a: None))
    iv = r["intervals"]
    held = {n: iv[n]["95"][0] <= v <= iv[n]["95"][1] for n, v in zip(names, TRUTH)}
    half = float(np.median([np.diff(iv[n]["95"])[0] / 2 / v for n, v in zip(names[:3], TRUTH)]))
    return held, half, r
