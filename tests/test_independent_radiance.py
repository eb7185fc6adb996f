"""Fits of a day the project did not render: every frame traced by Radiance (rtrace, from the
pyradiance wheel) with gensky's own skies and a Radiance ``plastic`` disc, put into a sequence
folder in place of the Mitsuba frames; the fit (Mitsuba light cache, 'balanced' normalisation,
Radiance 6's lobe) must find the material within its intervals.

Only the folder's manifest comes from the project's render (camera, sky per frame, sensor):
the radiance of each pixel is Radiance's, the mean of 16 rays over the pixel (the render's
box filter), so the fit meets another renderer's sampling, sky evaluation and sun handling.
"""
import numpy as np
import pytest
from scipy.stats import chi2 as chi2_dist

from skyfit_mi.fitting.chi2 import parse_region

HOURS = (8.0, 10.0, 12.0, 14.0, 16.0)
#: The disc's Radiance plastic: colour C, specularity, roughness (the truth).
C, SPEC, ROUGH = (0.6, 0.4, 0.2), 0.08, 0.1
SIZE = 12


def _spec(skies):
    return {
        "name": "radiance-disc",
        "location": {"latitude_deg": 40.0, "longitude_deg": 0.0, "timezone": "UTC"},
        "time": {"date": "2026-06-21", "times": [f"{int(h):02d}:00" for h in HOURS]},
        "sky": skies,
        "scene": {"file": "disc.xml"},
        "materials": {"disc": {"model": "colour", "C": list(C), "rho_s": SPEC,
                               "sigma_alpha": ROUGH, "normalisation": "balanced"}},
        "camera": {"azimuth_deg": 90.0, "angle_deg": 45.0, "distance": 5.0, "fov_deg": 8.0,
                   "width": SIZE, "height": SIZE},
        "sensor": {"exposure": "auto", "bits": 12, "noise_percent": 2.0},
        "render": {"spp": 4, "seed": 1},
    }


@pytest.fixture(scope="module")
def radiance_day(radiance, tmp_path_factory, mi):
    """A sequence folder whose frames Radiance traced (see the module docstring)."""
    from independent import gensky_entries, radiance_frames
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import validate_spec

    tmp = tmp_path_factory.mktemp("radiance_day")
    out = tmp / "day"
    skies = gensky_entries(radiance, "2026-06-21", HOURS, 40.0, 0.0, "+s")
    render_sequence(validate_spec(_spec(skies), tmp), out, progress=False, log=lambda *a: None)
    radiance_frames(radiance, out, [s["gensky"] for s in skies],
                    f"void plastic mat 0 0 5 {C[0]} {C[1]} {C[2]} {SPEC} {ROUGH}")
    return out


def _session(radiance_day):
    """The fit session of the disc's central 4x4 (colour model, 'balanced'), the truth, and
    Radiance's radiance there (P, T, 3)."""
    from skyfit_mi.fitting.fit import FitSession
    from skyfit_mi.pipeline.pixels import frame_values

    s = FitSession(radiance_day, "disc", parse_region("rect:4,4,7,7"), model="colour",
                   normalisation="balanced")
    return s, np.array([*C, SPEC, ROUGH]), frame_values(radiance_day, s.obs.pixels, s.obs.frames)


def test_radiance_rendered_day_is_modelled_and_fitted_consistently_with_the_truth(radiance_day):
    """The fit model at the truth reproduces Radiance's frames (measured: 0.1% per frame and
    channel), and the fit agrees with the truth. Here rho_s and sigma_alpha trade off with C
    along a ridge (five frames, sigma_alpha undetermined and warned of), so C's intervals come
    from profiles (C_r from 0.597, C_g 0.401, C_b 0.199: the covariance's from 0.610, 0.409,
    0.202)."""
    s, truth, traced = _session(radiance_day)
    ratio = (s.wm.radiance(truth) / traced).mean(axis=0)              # per frame and channel
    print("model / Radiance per frame and channel:", ratio.round(4).tolist())
    np.testing.assert_allclose(ratio, 1.0, atol=0.003)
    r = s.run("global", log=print)
    print("95% intervals:", {p: tuple(round(v, 3) for v in r["intervals"][p]["95"])
                             for p in s.names})
    # one realisation: the truth lies in the parameters' joint 99.9% confidence region (chi^2
    # at the truth within chi2_5(0.999) s^2 + the model's noise of the minimum); each
    # parameter's 95% interval is judged by its coverage over replicates (the slow test). On
    # this realisation the truth is inside every 95% interval but C_g's, 0.2% below its edge
    # 0.401 (since the clipped values' expected chi^2 sets s^2 = 1.05, not chi^2/dof = 1.10).
    rise = s.problem.chi2(truth) - r["chi2"]
    assert 0.0 <= rise <= chi2_dist.ppf(0.999, 5) * r["interval_scale_s2"] \
        + r["cache_noise_chi2"], rise
    assert any(w.startswith("sigma_alpha is not determined") for w in r["warnings"])
    assert r["chi2_per_dof"] < 1.3


@pytest.mark.slow
def test_intervals_cover_the_truth_over_replicates_of_the_radiance_day(radiance_day):
    """Over 40 noise replicates of the Radiance-traced frames (``pytest -m slow``) each
    parameter's 95% interval contains the truth in at least 90% of them (issue 13's goal).
    Measured 2026-11-23: C_r 0.95, C_g 0.975, C_b 0.975, rho_s 1.0, sigma_alpha 1.0 (C_r 0.925
    once s^2 came from the expected chi^2 of clipped values, at 499d051); before the
    profiles walked the ridge (continuation) and lent their points to every interval, C_r
    0.775-0.825 and rho_s 0.925."""
    s, truth, traced = _session(radiance_day)
    covered = []
    for r in range(40):
        s.obs.recapture(traced, np.random.default_rng([31, r]))
        res = s.run("global", seed=r, log=lambda *a: None)
        covered.append([res["intervals"][p]["95"][0] <= t <= res["intervals"][p]["95"][1]
                        for p, t in zip(s.names, truth)])
    coverage = np.mean(covered, axis=0)
    print("95% coverage over 40 replicates:", dict(zip(s.names, coverage.round(3).tolist())))
    assert np.all(coverage >= 0.9), dict(zip(s.names, coverage))


def test_a_per_pixel_map_of_the_radiance_day_is_right_or_says_it_cannot_tell(radiance_day):
    """Every disc pixel its own fit (the maps' grid and cache, 'balanced' normalisation) on
    Radiance's frames: each pixel either holds the truth in its 95% intervals or flags the
    parameter as undetermined, in at least 85% of (pixel, parameter) pairs; the pixels'
    median C lies within the median half-width of the truth (five frames: sigma_alpha is
    undetermined pixel by pixel, as it is for the 16-pixel region)."""
    from skyfit_mi.fitting.pixel_fit import UNDETERMINED, WARNINGS, fit_pixels
    from skyfit_mi.pipeline.pixels import material_regions

    px = dict(material_regions(radiance_day))["disc"]
    res = fit_pixels(radiance_day, "disc", px, model="colour", normalisation="balanced")
    truth = np.array([*C, SPEC, ROUGH])
    inside = (res["lo"] <= truth) & (truth <= res["hi"])
    bits = res["warnings"][:, None]
    flagged = np.concatenate([np.repeat(bits & WARNINGS["reflectance undetermined"], 3, 1),
                              bits & WARNINGS["rho_s undetermined"],
                              bits & WARNINGS["sigma_alpha undetermined"]], axis=1) > 0
    flagged |= (bits & UNDETERMINED & ~(WARNINGS["reflectance undetermined"]
                                        | WARNINGS["rho_s undetermined"]
                                        | WARNINGS["sigma_alpha undetermined"])) > 0
    honest = (inside | flagged).mean()
    print(f"{len(px)} pixels; right or flagged: {honest:.3f}; truth inside: "
          f"{inside.mean(axis=0).round(3).tolist()}; flagged: {flagged.mean(axis=0).round(3).tolist()}")
    assert honest >= 0.85
    half = np.median(res["hi"] - res["lo"], axis=0)[:3] / 2
    assert np.all(np.abs(np.median(res["theta"], axis=0)[:3] - truth[:3]) <= half)
