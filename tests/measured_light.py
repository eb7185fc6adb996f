"""A day rendered under measured skies, fitted under the measured light and under the models.

The thesis disc (``scenes/disc.xml``) in a known Ward colour-model material, seen from the
west-north-west (the camera on the sun's side: the highlight crosses the disc over the
morning), at the site and times of the shared measured clear day (Kider et al. 2014), lit
by each scan's envmap (:func:`skyfit_testkit.sky_scans.measured_day`).  Its frames are
then fitted with the light the manifest names, or with another light put in its place
(:func:`relabelled`): what a user who photographed the day and assumed a model sky would fit.

Used by tests/test_measured_sky.py and scripts/measured_sky_fit.py.
"""
import datetime as dt
import shutil
from pathlib import Path

import numpy as np

#: The material's truth (colour model) and its parameters in the fit's order.
MATERIAL = {"model": "colour", "C": [0.6, 0.4, 0.2], "rho_s": 0.08, "sigma_alpha": 0.08}
TRUTH = np.array([*MATERIAL["C"], MATERIAL["rho_s"], MATERIAL["sigma_alpha"]])
#: Camera azimuth [degrees]: west-north-west, facing the morning sun across the disc.
CAMERA_AZIMUTH_DEG = 300.0


def measured_disc_day(folder, scans, size=12, noise_percent=2.0, spp=256, rows=None, seed=3):
    """Render the disc under the envmaps of ``scans`` into ``folder``/day (its maps and spec
    beside it); returns the day's folder."""
    from skyfit_testkit.measured_sky import ROWS
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_testkit.sky_scans import measured_day
    from skyfit_mi.pipeline.spec import load_spec, thesis_disc_spec

    template = thesis_disc_spec("measured-sky-disc", MATERIAL,
                                camera_azimuth_deg=CAMERA_AZIMUTH_DEG, size=size,
                                noise_percent=noise_percent, spp=spp, seed=seed)
    spec = measured_day(scans, folder, template, rows=rows or ROWS)
    out = Path(folder) / "day"
    render_sequence(load_spec(spec), out, progress=False, log=lambda *a: None)
    return out


def relabelled(day, out, light):
    """A copy of the sequence ``day`` in ``out`` whose frames name ``light(frame, sky)`` (a
    Sky, from the manifest frame and the frame's own Sky) instead of their own light."""
    from skyfit_mi.pipeline.manifest import (
        frame_sky,
        illumination_record,
        load_manifest,
        write_manifest,
    )

    out = Path(out)
    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(day, out)
    doc, root = load_manifest(out)
    for f in doc["frames"]:
        f["illumination"] = illumination_record(light(f, frame_sky(f, Path(day))), root)
    write_manifest(out, doc)
    return out


def thesis_clear(frame, measured):
    """The thesis's CIE clear sky at the frame's sun (eqs. 4.10-4.15, sun of eq. 4.7)."""
    from skyfit_mi.physics.sky import cie_sky

    return cie_sky("clear", frame["sun_zenith_deg"], frame["sun_azimuth_deg"],
                   day=dt.datetime.fromisoformat(frame["time"]).timetuple().tm_yday)


def thesis_clear_scaled(frame, measured):
    """The thesis's CIE clear sky scaled to the measured sky's diffuse horizontal irradiance
    and direct normal irradiance: the model's shape and colour, the measured levels."""
    from skyfit_mi.physics.colour import SRGB_LUMINANCE

    return thesis_clear(frame, measured).scaled(
        diffuse_horizontal=float(measured.sky_horizontal_irradiance() @ SRGB_LUMINANCE),
        direct_normal=measured.info["direct_normal_W_m2"])


#: The lights a day is fitted with: its own (the measured envmaps) and the model skies.
LIGHTS = {"measured envmap": None, "thesis CIE clear": thesis_clear,
          "CIE clear at measured DHI, DNI": thesis_clear_scaled}


def fit(day, region="rect:4,4,7,7", positions=2, directions=512):
    """The colour-model fit of the disc region of ``day`` (light cache of ``positions`` and
    ``directions`` a pixel; ``positions=None`` sizes it from the data): (result dict,
    chi-square rise at the truth over the minimum, its joint 99.9% bound chi2_5(0.999) s^2 +
    the cache's noise)."""
    from scipy.stats import chi2 as chi2_dist

    from skyfit_mi.fitting.chi2 import parse_region
    from skyfit_mi.fitting.fit import FitCache, FitSession

    s = FitSession(day, "disc", parse_region(region), model="colour",
                   cache=FitCache(positions=positions, directions=directions))
    r = s.run("global", log=lambda *a: None)
    rise = float(s.problem.chi2(TRUTH) - r["chi2"])
    bound = float(chi2_dist.ppf(0.999, len(TRUTH)) * r["interval_scale_s2"]
                  + r["cache_noise_chi2"])
    return r, rise, bound
