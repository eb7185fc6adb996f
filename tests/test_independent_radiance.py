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
#: Frames' width and height [pixels]: the disc fills them; the fit takes the central 4 x 4.
SIZE = 8


def _spec(skies):
    return {
        "name": "radiance-disc",
        "location": {"latitude_deg": 40.0, "longitude_deg": 0.0, "timezone": "UTC"},
        "time": {"date": "2026-06-21", "times": [f"{int(h):02d}:00" for h in HOURS]},
        "sky": skies,
        "scene": {"file": "disc.xml"},
        "materials": {"disc": {"model": "colour", "C": list(C), "rho_s": SPEC,
                               "sigma_alpha": ROUGH, "normalisation": "balanced"}},
        "camera": {"azimuth_deg": 90.0, "angle_deg": 45.0, "distance": 5.0, "fov_deg": 16.0 / 3,
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

    s = FitSession(radiance_day, "disc", parse_region("rect:2,2,5,5"), model="colour",
                   normalisation="balanced")
    return s, np.array([*C, SPEC, ROUGH]), frame_values(radiance_day, s.obs.pixels, s.obs.frames)


def test_radiance_rendered_day_is_modelled_and_fitted_consistently_with_the_truth(radiance_day):
    """The fit model at the truth reproduces Radiance's frames (measured: 0.13% at most per
    frame and channel), and the fit agrees with the truth: within the parameters' joint
    confidence region, and every parameter's 95% interval holds it or a warning names the
    parameter.  Five frames: rho_s and sigma_alpha trade off with C along a ridge, so C's
    intervals come from profiles (measured: C_r 0.438-0.770, rho_s 0.014-0.24, sigma_alpha
    0.075-0.142, every one holding the truth)."""
    from independent import held_or_warned

    s, truth, traced = _session(radiance_day)
    ratio = (s.wm.radiance(truth) / traced).mean(axis=0)              # per frame and channel
    print("model / Radiance per frame and channel:", ratio.round(4).tolist())
    np.testing.assert_allclose(ratio, 1.0, atol=0.003)
    r = s.run("global", log=print)
    print("95% intervals:", {p: tuple(round(v, 3) for v in r["intervals"][p]["95"])
                             for p in s.names})
    # one realisation: the truth lies in the parameters' joint 99.9% confidence region (chi^2
    # at the truth within chi2_5(0.999) s^2 + the model's noise of the minimum); each
    # parameter's 95% interval is judged by its coverage over replicates (the slow test)
    rise = s.problem.chi2(truth) - r["chi2"]
    assert 0.0 <= rise <= chi2_dist.ppf(0.999, 5) * r["interval_scale_s2"] \
        + r["cache_noise_chi2"], rise
    verdict = held_or_warned(s.names, r["intervals"], r["warnings"], truth)
    assert "MISSED" not in verdict.values(), (verdict, r["warnings"])
    assert r["chi2_per_dof"] < 1.3


@pytest.mark.slow
def test_intervals_cover_the_truth_over_replicates_of_the_radiance_day(radiance_day):
    """Over 40 noise replicates of the Radiance-traced frames (``pytest -m slow``) each
    parameter's 95% interval contains the truth in at least 90% of them (issue 13's goal).
    Measured (8 x 8 frames, 2026-11-27): C_r 0.925, C_g 0.95, C_b 0.95, rho_s 1.0,
    sigma_alpha 1.0."""
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
