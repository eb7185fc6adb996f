"""Fitting: recovery of known parameters, chi-square statistics, failures explained, identifiability."""
import json

import numpy as np
import pytest

from skyfit_mi.cli import main
from skyfit_mi.fitting.chi2 import parse_region
from skyfit_mi.fitting.fit import FitCache

REGION = parse_region("rect:4,4,7,7")          # 16 pixels, all on the disc
FAST = dict(cache=FitCache(positions=2, directions=512))


def fit(path, **kw):
    from skyfit_mi.fitting.fit import fit_region
    return fit_region(path, "disc", REGION, log=lambda *a: None, **{**FAST, **kw})


def test_global_recovers_noise_free_truth(days):
    r = fit(days["clean"])
    p = r["parameters"]
    assert p["rho_s"] == pytest.approx(0.3, abs=0.01)
    assert p["sigma_alpha"] == pytest.approx(0.1, abs=0.005)
    assert r["evaluations"] > 0 and r["wall_time_s"] > 0 and r["seed"] == 0
    assert r["status"] == "converged" and "polish of the best: converged" in r["message"]


def test_global_search_reports_a_failed_polish(days, monkeypatch):
    """When the polish cannot lower chi-square the grid point is kept and the status says so."""
    import importlib
    gs = importlib.import_module("skyfit_mi.fitting.methods.global_search")

    calls = {}

    def failing_lm(problem, theta, lower, upper, **kw):
        calls["n"] = calls.get("n", 0) + 1
        return {"theta": theta, "chi2": np.inf, "status": "failed", "message": "singular curvature",
                "trace": []}

    monkeypatch.setattr(gs, "polish", failing_lm)
    from skyfit_mi.fitting.fit import FitCache, FitSession
    s = FitSession(days["clean"], "disc", REGION, cache=FitCache(positions=2, directions=64))
    res = gs.global_search(s.problem, s.lower, s.lower, s.upper, candidates=1, profile=False)
    assert calls["n"] == 1 and res["status"] == "grid_point"
    assert "singular curvature" in res["message"] and "best grid point" in res["message"]


def test_a_polish_beside_its_grid_point_is_judged_on_one_evaluation_path(days, monkeypatch):
    """LM's chi-square comes from the derivative path, ~1e-7 relative from the plain one: a
    polish that stays at its grid point converged; one that ends worse keeps the grid point."""
    import importlib
    gs = importlib.import_module("skyfit_mi.fitting.methods.global_search")
    from skyfit_mi.fitting.fit import FitCache, FitSession
    s = FitSession(days["clean"], "disc", REGION, cache=FitCache(positions=2, directions=64))
    for move, status in ((0.0, "converged"), (0.05, "grid_point")):
        def lm(problem, theta, lower, upper, **kw):
            moved = np.clip(theta + move, lower, upper)
            return {"theta": moved, "chi2": problem.chi2(theta) * (1 + 1e-7),
                    "status": "converged", "message": "chi-square stopped decreasing",
                    "trace": [theta.tolist()]}
        monkeypatch.setattr(gs, "polish", lm)
        res = gs.global_search(s.problem, s.lower, s.lower, s.upper, candidates=1,
                               profile=False)
        assert res["status"] == status, (move, res["message"])


def _replicates(day, n, seed, noise_percent=5.0, saturate_quantile=None):
    """A fit session of ``day`` and a generator of ``n`` noise replicates of its noise-free
    radiance (the frames' EXRs), each set as the session's observations before it is yielded.
    ``saturate_quantile``: raise the exposure until that quantile of the values saturates
    (an 8-bit sensor then)."""
    import dataclasses

    from skyfit_mi.fitting.fit import FitSession
    from skyfit_mi.pipeline.pixels import frame_values

    s = FitSession(day, "disc", REGION, **FAST)
    obs = s.obs
    radiance = frame_values(day, obs.pixels, obs.frames)
    changes = {"noise_percent": noise_percent}
    if saturate_quantile is not None:
        signal = radiance * obs.gain
        factor = 1.0 / np.quantile(signal[signal > 0], saturate_quantile)
        obs.gain = obs.gain * factor
        changes.update(exposure=obs.sensor.exposure * factor, bits=8)
    obs.sensor = dataclasses.replace(obs.sensor, **changes)

    def draws():
        for r in range(n):
            obs.recapture(radiance, np.random.default_rng([seed, r]))
            yield r
    return s, draws()


def _coverage(day, n, noise_percent):
    """Over ``n`` noise replicates of ``day`` (truth rho_s 0.3, sigma_alpha 0.1): per parameter
    the count of 95% and 68% intervals containing the truth, RMSE / Cramer-Rao bound, median
    95% width / the bound's (2 x 1.96 x CRB), and the mean chi2/dof."""
    from skyfit_testkit import cramer_rao

    truth = np.array([0.3, 0.1])
    s, draws = _replicates(day, n, seed=21, noise_percent=noise_percent)
    crb = None
    est, cover95, cover68, width, chi2_dof = [], [], [], [], []
    for r in draws:
        if crb is None:
            crb = cramer_rao.bound(cramer_rao.fisher_jacobian(s, truth, s.obs.sigma))
        res = s.run("global", seed=r, log=lambda *a: None)
        iv = res["intervals"]
        est.append(list(res["parameters"].values()))
        cover95.append([iv[p]["95"][0] <= t <= iv[p]["95"][1] for p, t in zip(s.names, truth)])
        cover68.append([iv[p]["68"][0] <= t <= iv[p]["68"][1] for p, t in zip(s.names, truth)])
        width.append([iv[p]["95"][1] - iv[p]["95"][0] for p in s.names])
        chi2_dof.append(res["chi2_per_dof"])
        assert not any("not determined" in w for w in res["warnings"])
    rmse = np.sqrt(np.mean((np.array(est) - truth) ** 2, axis=0))
    return (np.sum(cover95, axis=0), np.sum(cover68, axis=0), rmse / crb,
            np.median(width, axis=0) / (2 * 1.96 * crb), float(np.mean(chi2_dof)))


def test_intervals_cover_the_truth_over_replicates_and_are_no_wider_than_needed(days):
    """Over 16 noise replicates of one day: the 95% intervals contain the truth in >= 14
    (P(X <= 13) = 4% for honest intervals), the 68% ones in 7-15, the scatter of the estimates
    is near the Cramer-Rao bound, the intervals are no wider than twice what the bound allows,
    and chi2/dof averages 1. (Measured: 15/16 and 12, 8 of 16; RMSE/CRB 0.98, 1.29; width
    ratio 1.12, 1.18; chi2/dof 1.07.)"""
    c95, c68, rmse_crb, width, chi2_dof = _coverage(days["clean"], 16, 5.0)
    assert np.all(c95 >= 14), c95
    assert np.all((c68 >= 7) & (c68 <= 15)), c68
    assert np.all(rmse_crb < 1.6), rmse_crb
    assert np.all(width < 2.0), width
    assert 0.9 < chi2_dof < 1.1


@pytest.mark.slow
@pytest.mark.parametrize("noise", [2.0, 5.0, 10.0])
def test_interval_coverage_sweep(days, noise):
    """The benchmark's goals as a sweep (``pytest -m slow``, 3.5 min), 100 replicates per noise
    level: the 95% intervals cover >= 90%, the 68% ones no less than 58% (not too narrow) and
    both no wider than twice the Cramer-Rao width; RMSE within 1.6 CRB.  Measured (2026-11-23,
    rho_s / sigma_alpha): 95% coverage 99/100, 93/99, 93/99; 68% 92/98, 81/79, 78/71 (wide at
    2%: the light cache's error allowance dominates there, width 1.36/1.72 CRB); RMSE/CRB
    1.07/1.02, 1.09/0.99, 1.17/1.51 (sigma_alpha at 10% on 16 pixels misses the benchmark's
    1.2, a finite-sample excess of the maximum-likelihood estimate, see docs/BENCHMARKS.md, "RMSE
    above the Cramer-Rao bound on 16 pixels: a finite-sample excess")."""
    c95, c68, rmse_crb, width, chi2_dof = _coverage(days["clean"], 100, noise)
    assert np.all(c95 >= 90), c95
    assert np.all(c68 >= 58), c68
    assert np.all(rmse_crb <= 1.6), rmse_crb
    assert np.all(width < 2.0), width
    assert 0.9 < chi2_dof < 1.15


def test_lm_failure_from_a_bad_start_is_explained(days):
    # from a lobe far narrower than the truth the model misses the highlight: LM stops at the
    # mirror edge (thesis 7.2's local minimum). From the rough edge it now succeeds: the
    # saturated highlight values enter as censored, not dropped, and point the way.
    r = fit(days["noisy"], method="lm", start=[0.6, 0.01])
    assert r["parameters"]["sigma_alpha"] < 0.01                # stuck at the mirror edge
    assert any("global search finds" in w and "local minimum" in w for w in r["warnings"])


def test_annealing_escapes_where_lm_is_stuck(days):
    # from the mirror edge LM stays in the local minimum; annealing (seed 0) reaches the truth.
    # Annealing is stochastic: scripts/reproduce_thesis.py measures its success rate.
    lm = fit(days["clean"], method="lm", start=[0.6, 0.01])
    r = fit(days["clean"], method="anneal", start=[0.6, 0.01], seed=0)
    assert r["chi2"] < 0.01 * lm["chi2"]
    assert r["parameters"]["rho_s"] == pytest.approx(0.3, abs=0.01)
    assert r["parameters"]["sigma_alpha"] == pytest.approx(0.1, abs=0.005)
    assert r["schedule"]["T0"] == 1e6 and r["schedule"]["seed"] == 0 and len(r["trace"]) > 10


@pytest.mark.parametrize("start", [[0.5, 0.15], [0.15, 0.05]])
def test_adam_reaches_the_global_minimum(days, start):
    """Gradient descent through the differentiable model ends where the global search does:
    chi-square within 0.1 of its minimum, the parameters well inside its 68% intervals."""
    g = fit(days["noisy"])
    r = fit(days["noisy"], method="adam", start=start, method_options={"iterations": 150})
    assert r["chi2"] <= g["chi2"] + 0.1
    for p, v in r["parameters"].items():
        lo, hi = g["intervals"][p]["68"]
        assert abs(v - g["parameters"][p]) < 0.1 * (hi - lo), (p, v, g["parameters"][p])
    assert not any("global search finds" in w for w in r["warnings"])


@pytest.mark.parametrize("day", ["south", "overcast"])
def test_undetermined_roughness_is_flagged(days, day):
    r = fit(days[day])
    assert any(w.startswith("sigma_alpha is not determined") for w in r["warnings"]), r["warnings"]


def test_the_days_geometry_is_reported_and_warned_from(days):
    """The fit JSON states the closest sun half-angle; a camera on the sun's side (south, the
    highlight 30 degrees away) is warned of, an east camera (3 degrees) is not, and an
    overcast day is warned to have no sun."""
    east, south, overcast = (fit(days[d]) for d in ("noisy", "south", "overcast"))
    assert east["geometry"]["frames_with_sun"] == east["geometry"]["frames"] == 13
    assert east["geometry"]["closest_highlight_half_angle_deg"] < 5
    assert not any("highlight never comes closer" in w for w in east["warnings"])
    assert south["geometry"]["closest_highlight_half_angle_deg"] > 20
    # the lobe the sun cannot show: chi-square is flat from 0 to beyond it
    assert south["intervals"]["sigma_alpha"]["95"][0] == 0.0
    assert any("highlight never comes closer" in w for w in south["warnings"])
    # its interval runs to sigma_alpha = 0: read as an upper limit, not a value
    assert south["readings"][1].startswith("sigma_alpha < ") and "lower end not determined" \
        in south["readings"][1]
    assert east["readings"][1].startswith("sigma_alpha = ")
    assert overcast["geometry"]["frames_with_sun"] == 0
    assert overcast["geometry"]["closest_highlight_half_angle_deg"] is None
    assert any(w.startswith("no frame has the sun") for w in overcast["warnings"])


def test_a_model_that_cannot_describe_the_data_is_called_unreliable(days):
    """The noisy day fits at chi2/dof ~ 1 without a misfit warning or model error; the same
    values with a tenth of their sigma (a wrong sensor model) are told the model does not
    describe them, with the model's error fitted and said."""
    from skyfit_mi.fitting.fit import FitSession

    s = FitSession(days["noisy"], "disc", REGION, **FAST)
    good = s.run("global", log=lambda *a: None)
    assert not any("misfit" in w or "does not describe" in w for w in good["warnings"])
    assert good["model_error"]["kappa"] == 0.0
    s.obs.sigma = s.obs.sigma / 10
    bad = s.run("global", log=lambda *a: None)
    assert bad["model_error"]["kappa"] > 0
    assert any(w.startswith("the model does not describe these data") and
               "the model misses the data by about" in w for w in bad["warnings"])


def test_the_sessions_of_one_scene_share_it_while_one_lives(days):
    """Sessions of one scene share its Mitsuba scene (each live scene's materials join every
    trace's virtual calls), and a trace of one after another's sees the same fit as alone; the
    scene goes with its last session."""
    import gc

    from skyfit_mi.fitting.fit import _SCENES, FitSession

    def session(**kw):
        return FitSession(days["clean"], "disc", REGION, model="two", light=None, **FAST, **kw)
    alone = fit(days["clean"])
    a, b = session(), session(normalisation="balanced")
    assert a.scene is b.scene and a.params is b.params
    b.light_cache()                                     # another lobe traced on the scene first
    assert fit(days["clean"])["parameters"] == alone["parameters"]
    del a, b
    gc.collect()
    assert not _SCENES


def test_region_errors(days):
    from skyfit_mi.errors import SkyfitError
    from skyfit_mi.fitting.fit import fit_region
    with pytest.raises(SkyfitError, match="outside the 12x12 frames"):
        fit_region(days["clean"], "disc", parse_region("rect:10,10,13,13"), log=lambda *a: None)
    with pytest.raises(SkyfitError, match="its materials are: disc"):
        fit_region(days["clean"], "plate", REGION, log=lambda *a: None)
    with pytest.raises(SkyfitError, match="rect:x0,y0,x1,y1"):
        parse_region("box:1,2")


def test_cli_fit_writes_json_and_plot(days, tmp_path):
    assert main(["fit", str(days["noisy"]), "--region", "disc=rect:4,4,7,7", "--model", "2",
                 "--positions", "2", "--directions", "512", "-o", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "fit_disc.json").read_text())
    for key in ("parameters", "chi2", "chi2_per_dof", "evaluations", "wall_time_s", "seed",
                "intervals", "warnings", "truth"):
        assert key in res
    assert res["truth"]["rho_s"] == 0.3
    assert (tmp_path / "fit_disc.png").stat().st_size > 10000
    summary = (tmp_path / "fits.csv").read_text().splitlines()
    assert summary[0].startswith("region,model,normalisation,method,pixels_fitted,pixels_total,rho_s,")
    assert summary[1].startswith("disc,two,ward,global,16,16,")
    assert main(["fit", str(days["noisy"]), "--region", "disc=box"]) == 2


def test_cli_fit_all_materials_subsamples_large_regions(days, tmp_path):
    assert main(["fit", str(days["noisy"]), "--all", "--max-pixels", "20", "--positions", "2",
                 "--directions", "512", "-o", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "fit_disc.json").read_text())
    assert len(res["pixels"]) == 20 and res["region_pixels_total"] == 144
    assert res["parameters"]["rho_s"] == pytest.approx(0.3, abs=0.05)


def test_subsample_region_is_seeded():
    from skyfit_mi.fitting.chi2 import subsample_region
    px = parse_region("rect:0,0,9,9")
    a, b = subsample_region(px, 10, seed=3), subsample_region(px, 10, seed=3)
    assert len(a) == 10 and (a == b).all() and len({tuple(p) for p in a}) == 10
    assert (subsample_region(px, None, 0) == px).all()


def test_labels_and_mask_regions(days, tmp_path):
    from skyfit_mi.fitting.chi2 import region_from_mask
    assert main(["labels", str(days["clean"]), "-o", str(tmp_path / "labels.png")]) == 0
    legend = json.loads((tmp_path / "labels.json").read_text())["labels"]
    assert legend == {"disc": 1}
    px = region_from_mask(tmp_path / "labels.png", legend["disc"])
    assert len(px) == 144                                  # the 6-degree view is all disc
    from skyfit_mi.errors import SkyfitError
    with pytest.raises(SkyfitError, match="label 7 does not occur"):
        region_from_mask(tmp_path / "labels.png", 7)


@pytest.mark.parametrize("rho", [0.0, 0.5])
def test_correlated_channels_widen_the_shared_parameters_by_the_design_effect(rho):
    # residuals of (P, T) values in 3 channels with correlation rho between channels; a
    # parameter per channel (an offset of its own channel) and a slope shared by all three
    # (its regressor the same in each): the slope's variance is (1 + 2 rho) times that of
    # independent channels, the offsets' unchanged
    from skyfit_mi.fitting.uncertainty import channel_factors
    rng = np.random.default_rng(5)
    cov = np.full((3, 3), rho) + (1 - rho) * np.eye(3)
    r = rng.standard_normal((400, 7, 3)) @ np.linalg.cholesky(cov).T
    J = np.zeros((400, 7, 3, 4))
    for c in range(3):
        J[..., c, c] = 1.0
    J[..., 3] = rng.standard_normal((400, 7, 1))
    usable = np.ones(r.shape, dtype=bool)
    f2, R = channel_factors(r, J, usable)
    assert np.allclose(R[np.triu_indices(3, 1)], rho, atol=0.05)
    assert f2 == pytest.approx([1.0, 1.0, 1.0, 1.0 + 2 * rho], abs=0.08)
    # clipped values stay in the curvature but share nothing: the shared slope's factor
    # falls toward that of independent values, never below it
    clipped = usable.copy()
    clipped[:200, :, 0] = False
    f2c, _ = channel_factors(r, J, clipped, usable)
    assert 1.0 <= f2c[3] <= f2[3] + 1e-9
    # a channel left out (clipped or missing) everywhere: no correlation with it
    usable[..., 2] = False
    f2, R = channel_factors(r, J, usable)
    assert R[0, 2] == R[1, 2] == 0.0 and f2 == pytest.approx([1.0, 1.0, 1.0, 1.0 + rho], abs=0.08)


def test_colour_model_plastic_metal_ambiguity_for_grey_c():
    from skyfit_mi.fitting.uncertainty import colour_rule_ambiguity
    grey = {k: (0.194, 0.196) for k in ("C_r", "C_g", "C_b")}
    c2, rho2 = colour_rule_ambiguity([0.195, 0.195, 0.195, 0.439, 0.08], grey)
    # the metal reading of the same raw BRDF: C' rho' = 0.439 and C'(1 - rho') = 0.195 * 0.561
    assert c2 * rho2 == pytest.approx(0.439) and c2 * (1 - rho2) == pytest.approx(0.195 * 0.561)
    assert rho2 >= 0.5
    coloured = {"C_r": (0.79, 0.81), "C_g": (0.49, 0.51), "C_b": (0.19, 0.21)}
    assert colour_rule_ambiguity([0.8, 0.5, 0.2, 0.3, 0.08], coloured) is None


@pytest.mark.parametrize("C, rho_s", [((0.9, 0.6, 0.3), 0.7), ((0.2, 0.3, 0.4), 0.4),
                                      ((0.4, 0.4, 0.4), 0.8), ((0.4, 0.4, 0.4), 0.3)])
def test_colour_rule_twin_keeps_diffuse_and_mean_specular(C, rho_s):
    import numpy as np

    from skyfit_mi.physics.ward import METAL_THRESHOLD, colour_rule_twin, raw_parameters
    c2, rho2 = colour_rule_twin(C, rho_s)
    assert (rho2 >= METAL_THRESHOLD) != (rho_s >= METAL_THRESHOLD)   # the other rule
    d, s, _ = raw_parameters("colour", C=C, rho_s=rho_s, sigma_alpha=0.7)
    d2, s2, _ = raw_parameters("colour", C=c2, rho_s=rho2, sigma_alpha=0.7)
    assert np.allclose(d2, d) and np.mean(s2) == pytest.approx(np.mean(s))
    if np.ptp(C) == 0:                                     # grey: the same BRDF
        assert np.allclose(s2, s)


@pytest.mark.parametrize("model", ["two", "achromatic", "colour"])
def test_reflectances_of_many_sets_at_once_are_each_sets(model):
    """reflectance_sets (radiances of many draws at once) gives reflectances' values exactly,
    about the colour model's plastic/metal rule too."""
    import numpy as np

    from skyfit_mi.render.fit_model import bounds, reflectance_sets, reflectances

    lo, hi = bounds(model)
    th = lo + (hi - lo) * np.random.default_rng(0).random((200, len(lo)))
    th[:4, -2] = [0.5, 0.49999999, 0.4999999999, 0.0]
    np.testing.assert_array_equal(reflectance_sets(model, th),
                                  [reflectances(model, t)[:2] for t in th])


class _RawBRDF:
    """A toy chi-square over the colour model whose data determine only the raw BRDF (rho_d,
    the specular reflectance, sigma): for a grey C both readings of the rule fit exactly."""

    def __init__(self, truth):
        from skyfit_mi.render.fit_model import reflectances
        self.reflectances = reflectances
        self.target = self._raw(truth)

    def _raw(self, theta):
        import numpy as np
        rho_d, spec, _, _ = self.reflectances("colour", theta)
        return np.r_[rho_d, spec, theta[-1]]

    def residuals(self, theta):
        return 100 * (self._raw(theta) - self.target)

    def jacobian(self, theta):
        import numpy as np
        _, _, d_rho_d, d_spec = self.reflectances("colour", theta)
        J = np.zeros((7, 5))
        J[:3], J[3:6], J[6, 4] = d_rho_d, d_spec, 1.0
        return self.residuals(theta), 100 * J

    def chi2(self, theta):
        r = self.residuals(theta)
        return float(r @ r)


def test_cache_error_compares_the_halves_on_the_same_reading():
    # a half whose fit lands on the plastic reading of a grey metal is read on the metal side:
    # the readings' difference (C 0.55 against 0.16) is not Monte Carlo error
    import numpy as np

    from skyfit_mi.fitting.fit import FitSession
    from skyfit_mi.render.fit_model import bounds, other_readings
    from skyfit_mi.physics.ward import METAL_THRESHOLD
    theta = np.array([0.55, 0.55, 0.55, 0.85, 0.03])
    minimum = theta + [0, 0, 0, 0, 0.002]                     # this half's minimum
    half = _RawBRDF(minimum)
    plastic = other_readings("colour", minimum)[0]
    assert plastic[3] < METAL_THRESHOLD and half.chi2(plastic) < 1e-6
    session = FitSession.__new__(FitSession)
    session.model = "colour"
    session.lower, session.upper = bounds("colour")
    read = session._same_reading(half, plastic, theta)
    assert np.allclose(read, minimum, atol=1e-4)
    coloured = np.array([0.2, 0.5, 0.8, 0.3, 0.03])           # not grey: another BRDF, kept
    assert session._same_reading(half, coloured, theta) is coloured


def test_a_start_out_of_bounds_or_of_the_wrong_length_is_refused_by_the_api(days):
    """FitSession.run checks a start as the CLI does: nothing is clipped or broadcast."""
    from skyfit_mi.errors import SkyfitError
    from skyfit_mi.fitting.fit import FitCache, FitSession

    s = FitSession(days["clean"], "disc", REGION, cache=FitCache(positions=2, directions=64))
    with pytest.raises(SkyfitError, match="sigma_alpha = 0.9 is outside its bounds"):
        s.run("lm", start=[0.3, 0.9], log=lambda *a: None)
    with pytest.raises(SkyfitError, match="gives 3 value"):
        s.run("lm", start=[0.3, 0.1, 0.2], log=lambda *a: None)


def test_global_search_finds_the_minimum_when_the_highlight_saturates(days):
    """A saturated highlight read down by noise misleads the linear grid (it cannot clip): the
    candidates are ranked by the true (censored) chi-square, so over noise replicates the
    global fit is never worse than the truth by more than the polish's tolerance. A fifth of
    the values would saturate without noise; with the old ranking by the linear grid,
    replicate 0 ended at sigma_alpha 0.044, chi2 909 against 653 at the truth."""
    truth = np.array([0.3, 0.1])
    s, draws = _replicates(days["clean"], 10, seed=12, saturate_quantile=0.8)
    saturated = []
    for r in draws:
        saturated.append(int((s.obs.y >= s.obs.sensor.max_code).sum()))
        res = s.run("global", seed=r, log=lambda *a: None)
        assert res["chi2"] <= s.problem.chi2(truth) + 1.0, (r, res["parameters"])
        assert res["parameters"]["sigma_alpha"] == pytest.approx(0.1, abs=0.02)
    assert min(saturated) > 0.03 * s.obs.y.size


def test_model_noise_allowance_is_the_largest_over_the_profiles_region():
    """The cache's error grows with sigma_alpha: the allowance is the model noise at the top
    of the profile's 95% region, found again as that region widens with it, not the (smaller)
    value at the fit."""
    from skyfit_mi.fitting.intervals import model_noise_allowance

    class Noise:                                   # model noise 200 sigma_alpha [chi2]
        def model_noise_chi2(self, theta):
            return 200.0 * theta[-1]
    sigmas = np.linspace(0.0, 0.5, 501)
    profile = 1e4 * (sigmas - 0.05) ** 2          # minimum at 0.05
    allowance = model_noise_allowance(Noise(), np.array([0.3, 0.05]), sigmas, profile, 1.0)
    # at the fit 10; the region (chi2 rise <= 3.84 + allowance) grows to the fixed point
    # 1e4 (s - 0.05)^2 = 3.84 + 200 s, s = 0.0985, where the noise is 19.7
    assert allowance == pytest.approx(19.7, rel=0.02)


def test_other_parameters_are_profiled_when_the_lobe_is_poorly_determined(days):
    """Under an overcast sky rho_s and sigma_alpha are poorly determined, and R trades off with
    them along a ridge: R's interval then comes from its profile on the true chi-square and
    contains the truth (R = 1: the day's two-parameter material, rho_d = 1 - rho_s).  The fit
    lies at rho_s = 0, where sigma_alpha changes nothing: the global search's polish and the
    profile's constrained fits hold sigma_alpha there instead of failing, and R's covariance
    interval (a quadratic running into rho_s < 0, 0-1 wide) is not taken: the true
    chi-square at R = 0.6 is over 100 above the minimum for every rho_s."""
    r = fit(days["overcast"], model="achromatic")
    iv = r["intervals"]["R"]
    assert iv["from"].startswith("profile")
    lo, hi = iv["95"]
    assert lo <= 1.0 <= hi + 1e-9
    assert lo > 0.6
    assert r["status"] == "converged", r["message"]
    # a sixth of the dark day's values read code 0: that is noise, not misfit
    assert r["chi2_per_dof"] > 1.1
    assert not any("misfit" in w or "does not describe" in w for w in r["warnings"])
    assert abs(r["chi2"] / r["chi2_expected_from_noise"] - 1) < 3 * np.sqrt(2 / r["dof"])


def test_the_models_own_noise_is_reported_over_roughness_and_warned_when_data_are_finer(days):
    """The fit JSON gives the light cache's share of chi-square at each roughness; the
    noise-free day (quantisation only) is more precise than the cache and is warned of,
    the 5%-noise day is not."""
    clean, noisy = fit(days["clean"]), fit(days["noisy"])
    by_sigma = clean["cache_noise_chi2_by_sigma"]
    assert set(by_sigma) == {"0.01", "0.02", "0.05", "0.1", "0.2", "0.35", "0.5"}
    assert max(by_sigma.values()) > 0.25 * clean["dof"]
    assert any(w.startswith("the light cache's own Monte Carlo error") for w in clean["warnings"])
    assert max(noisy["cache_noise_chi2_by_sigma"].values()) < 0.25 * noisy["dof"]
    assert not any("light cache's own" in w for w in noisy["warnings"])


@pytest.mark.slow
def test_an_automatically_sized_cache_grows_until_its_noise_is_a_small_share(days, monkeypatch):
    """With positions=None the cache is sized from the data: after a fit whose largest model
    noise over the roughness range exceeds CACHE_SHARE of the dof, the positions grow (powers
    of two, within CACHE_GROWTH_MAX) and the fit is repeated; the JSON records both sizes.
    Started small (2 positions) on the noise-free day, whose sigma is the quantisation's."""
    from skyfit_mi.fitting import fit as fit_module
    from skyfit_mi.fitting.fit import CACHE_SHARE, FitCache, FitSession

    monkeypatch.setattr(fit_module, "POSITIONS", 2)
    monkeypatch.setattr(fit_module, "CACHE_GROWTH_MAX", 8)
    s = FitSession(days["clean"], "disc", REGION, cache=FitCache(directions=64))
    small = s._model_noise_by_sigma(np.array([0.3, 0.1]))
    assert max(small.values()) > CACHE_SHARE * s.problem.dof     # the small cache is too noisy
    r = s.run("lm", start=[0.3, 0.1], log=lambda *a: None)
    c = r["light_cache"]
    assert c["sized"] == "from the data" and c["grown_from"][0]["positions"] == 2
    assert c["positions"] == 16 and s.light_cache().mirror.shape[2] == 16     # capped at 8x
    # 8x the positions: each roughness's noise falls about 8-fold; each is a heavy-tailed
    # estimate (measured 1.7-14x), so the median over the roughness range is compared
    grown = r["cache_noise_chi2_by_sigma"]
    assert np.median([small[k] / grown[k] for k in small]) > 4
    given = FitSession(days["clean"], "disc", REGION, cache=FitCache(positions=2, directions=64))
    r = given.run("lm", start=[0.3, 0.1], log=lambda *a: None)
    assert r["light_cache"]["positions"] == 2 and "grown_from" not in r["light_cache"]


def test_a_reflectance_on_its_bound_is_named_only_where_the_data_pull_past_it():
    """beyond_upper_bound names a reflectance at its bound of 1 only where chi-square still
    falls beyond it (the data brighter than the model allows), not a white or mirror surface
    whose minimum lies on the bound, nor rho_s (a share: 1 is a metal); sigma_alpha's bound is
    another warning's."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.fit_warnings import beyond_upper_bound

    target = np.array([1.2, 0.9, 0.5, 1.1, 0.6])          # the data's unconstrained optimum

    class Quadratic:
        def jacobian(self, theta):         # r = target - theta, and a censored value far past
            r = np.append(target - theta, 0.0)          # its clip: r = 0, dr / dtheta 0/0
            return r, np.vstack([-np.eye(len(theta)), np.full(len(theta), np.nan)])

    s = SimpleNamespace(names=("C_r", "C_g", "C_b", "rho_s", "sigma_alpha"),
                        upper=np.array([1.0, 1.0, 1.0, 1.0, 0.5]))
    theta = np.array([1.0, 1.0, 0.5, 1.0, 0.5])
    # rho_s, the specular share, at 1 is a metal without a diffuse part, not too bright
    assert beyond_upper_bound(s, SimpleNamespace(theta=theta, problem=Quadratic())) \
        == ["C_r"]
    assert beyond_upper_bound(s, SimpleNamespace(theta=theta, problem=None)) \
        == ["C_r", "C_g"]
