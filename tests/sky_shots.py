"""Bracketed fisheye JPEGs of a known sky, and a grey card's shots, as a camera would take them.

A camera whose speed meets its saturation definition (``gain`` 1:
:data:`~skyfit_mi.pipeline.sky_series.SATURATION_LUMINANCE`) photographs a
:class:`~skyfit_mi.physics.sky.Sky` through an upward equidistant fisheye: linear value
v = gain L H EFFICACY / SATURATION_LUMINANCE, shot noise of ``noise`` (relative, at full
scale), sRGB, 8-bit JPEG with the EXIF time and exposure (f/8, ISO 100).  The sun and its flare
(within ``flare_deg``) are far brighter than any exposure holds.  Used by
tests/test_sky_series.py and scripts/sky_series_example.py.
"""
import datetime as dt
from pathlib import Path

import numpy as np
from PIL import Image

from skyfit_mi.physics.camera import SensorModel
from skyfit_mi.physics.sky import EFFICACY_CLEAR
from skyfit_mi.pipeline.photo_sim import SIM_F_NUMBER, SIM_ISO, _exif
from skyfit_mi.pipeline.sky_series import SATURATION_LUMINANCE, fisheye_directions

#: Exposure times of a bracket [s]: four stops apart, two each way of 1/500.
BRACKET_S = (1 / 125, 1 / 500, 1 / 2000, 1 / 8000)
#: The sun's flare in the fisheye [degrees]: clipped in every shot.
FLARE_DEG = 2.0


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


def _jpeg(path, radiance, exposure_s, time, gain, noise, rng):
    """One 8-bit sRGB JPEG of ``radiance`` at ``exposure_s``, with EXIF."""
    h = exposure_s * SIM_ISO / SIM_F_NUMBER ** 2
    v = gain * radiance * h * EFFICACY_CLEAR / SATURATION_LUMINANCE
    v = v + rng.normal(size=v.shape) * noise * np.sqrt(np.clip(v, 0.0, 1.0))
    codes = SensorModel(1.0, response="srgb", bits=8).respond(v) * 255.0
    Image.fromarray(np.round(codes).astype(np.uint8)).save(
        path, quality=95, exif=_exif(time, True, exposure_s))


def photograph_sky(sky, time, folder, *, size=128, gain=1.0, noise=0.005, seed=0,
                   north_rotation_deg=0.0):
    """The bracket (:data:`BRACKET_S`) of ``sky`` at ``time`` (aware), a second apart, as JPEGs
    in ``folder``; returns their paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    radiance = fisheye_radiance(sky, size, north_rotation_deg)
    out = []
    for i, t in enumerate(BRACKET_S):
        when = time + dt.timedelta(seconds=i)
        path = folder / f"sky_{when:%H%M%S}_{i}.jpg"
        _jpeg(path, radiance, t, when, gain, noise, rng)
        out.append(path)
    return out


def photograph_card(sky, time, folder, *, reflectance=0.18, size=32, gain=1.0, noise=0.005,
                    seed=0):
    """A horizontal Lambertian grey card lit by ``sky``, filling a ``size``-pixel JPEG exposed
    to put it near a third of full scale, in ``folder``; returns its path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    radiance = reflectance / np.pi * sky.horizontal_irradiance()
    h = 0.35 / (gain * float(radiance.max()) * EFFICACY_CLEAR / SATURATION_LUMINANCE)
    exposure_s = float(h * SIM_F_NUMBER ** 2 / SIM_ISO)
    path = folder / f"card_{time:%H%M%S}.jpg"
    _jpeg(path, np.broadcast_to(radiance, (size, size, 3)), exposure_s, time, gain, noise,
          np.random.default_rng(seed))
    return path
