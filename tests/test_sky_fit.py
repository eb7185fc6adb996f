"""The sky's level fitted with the materials (fitting/sky_fit.py, ``fit --sky fit``): its level
and its curve over the day.  The sun's level and the sky's shape fitted with them are in
tests/test_sky_fit_sun_shape.py (a file of its own, so that the two run on two workers)."""

import json
import pickle
from contextlib import contextmanager
from dataclasses import replace

import numpy as np
import pytest

from skyfit_mi.cli import main
from skyfit_mi.fitting.chi2 import parse_region
from skyfit_mi.fitting.light import LightOptions

REGION = parse_region("rect:2,2,9,9")        # 64 pixels of the disc
HALF = parse_region("rect:2,2,9,5")          # 32 of them
TRUTH = {"C_r": 1.0, "C_g": 1.0, "C_b": 1.0, "rho_s": 0.3, "sigma_alpha": 0.1}
DIMMER = 1.5                                 # the spec's sky is this much too dim


@contextmanager
def traced_once():
    """Within it, fit.py's and relight.py's ``trace_sessions`` trace a region's light once and
    hand a later session asking for the same light the same parts (and the first trace's
    time, so that the cache's sizing sees what it saw): the same scene, model, normalisation,
    pixels, frames, cache (positions, directions, seed, plan) and light's parts (split, shape,
    departure) of skies that differ at most in their ``info`` where no part reads it (no
    shape, no departure).  A trace is a function of these alone, so a fit on it is the fit
    that traces again, to the last digit; a session asking for any other light traces it."""
    from skyfit_mi.fitting import fit, relight

    real, traced = fit.trace_sessions, {}

    def key(s, plan):
        skies = s.skies if plan.shape or plan.departure else [replace(k, info={})
                                                                 for k in s.skies]
        return (s.doc["scene"]["xml"], s.name, s.model, s.normalisation,
                np.asarray(s.obs.pixels).tobytes(), tuple(s.obs.frames),
                tuple(sorted(s._cache_options().items())), plan.split, plan.shape,
                plan.departure, pickle.dumps(skies))

    def trace_sessions(sessions, light):
        plan = light[sessions[0].name] if isinstance(light, dict) and len(sessions) == 1 \
            else light
        if len(sessions) != 1 or isinstance(plan, dict) or sessions[0].obs.rays is not None:
            return real(sessions, light)
        s, = sessions
        k = key(s, plan)
        if k not in traced:
            before = s.cache_time
            real(sessions, light)
            traced[k] = (s.parts, s.cache_time - before, s.cache_settings["blocks"])
        else:
            parts, seconds, blocks = traced[k]
            s.take_parts(parts, plan, seconds, blocks)

    with pytest.MonkeyPatch.context() as m:
        m.setattr(fit, "trace_sessions", trace_sessions)
        m.setattr(relight, "trace_sessions", trace_sessions)
        yield



def test_the_sun_and_the_rest_of_a_sky_add_up_to_it():
    from skyfit_mi.physics.sky import Sky

    sky = Sky(np.array([0.3, -0.2, 0.8]), clear=[30.0, 38.0, 66.0], overcast=[5.0, 5.0, 6.0],
              ground=[40.0, 41.0, 39.0], sun_radiance=[1.5e7, 1.2e7, 1e7])
    sun, rest = sky.split()
    d = np.random.default_rng(0).normal(size=(500, 3))
    d = np.vstack([d / np.linalg.norm(d, axis=1, keepdims=True), sky.sun_direction])
    np.testing.assert_allclose(sun.radiance(d) + rest.radiance(d), sky.radiance(d), rtol=1e-12)
    assert np.all(rest.sun_radiance == 0) and not sun.clear.any() and not sun.overcast.any()
    assert sun.radiance(sky.sun_direction[None])[0, 0] > 1e6
    # the ground's shares as the sun's and the sky's horizontal irradiance
    e_sun, e_sky = sky.sun_horizontal_irradiance(), sky.sky_horizontal_irradiance()
    np.testing.assert_allclose(sun.ground / rest.ground, e_sun / e_sky, rtol=1e-12)


def test_the_fitted_light_is_calibrated_again_on_the_scenes_reference():
    """Ingest set each frame's exposure so that the grey card reads its reflectance under the
    spec's light; a fitted sky moves what the card reads.  The fit calibrates the light again
    on it (fit.reference_factor): the radiance of the card's fit at the fitted sky over that of
    a Lambertian card of its known reflectance is a factor per channel on every region's light,
    recorded in the sky record, which relight and maps take with the level (Sky.tinted: every
    part of the light times it).  No reference among the fit's regions, a white model without
    C, or the spec's light: nothing changes."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.fit import reference_factor
    from skyfit_mi.fitting.sky_fit import SkyFit, skies_at_level
    from skyfit_mi.physics.sky import Sky

    doc = {"ingest": {"calibration": {"references": {"card": [0.18, 0.18, 0.18]}}}}
    colour = ["C_r", "C_g", "C_b", "rho_s", "sigma_alpha"]
    light = np.array([[[2.0, 3.0, 4.0]], [[1.0, 1.5, 2.5]]])           # (P, T, 3): a day

    class Region:
        def __init__(self, name, names):
            self.name, self.doc, self.names, self.parts = name, doc, names, "p"
            self.light_factor, self.made = None, 0
            # a lobe that adds rho_s (white) to the diffuse C (1 - rho_s)
            self.wm = SimpleNamespace(radiance=lambda th: light * (
                np.asarray(th[:3]) * (1 - th[3]) + th[3] if len(th) == 5 else th[1]))

        def _use_parts(self, parts):
            self.made += 1

    read = {"card": [0.189, 0.18, 0.171, 0.0, 0.3], "paint": [0.6, 0.2, 0.1, 0.05, 0.1]}

    def fit(s):
        return {"parameters": dict(zip(s.names, read[s.name]))}

    sessions = {"paint": Region("paint", colour), "card": Region("card", colour)}
    sky = SkyFit({"k": 1.2})
    reference_factor(sessions, sky, fit, log=lambda *a: None)
    factor = np.array([1.05, 1.0, 0.95])
    np.testing.assert_allclose(sky.record["reference"]["light_factor"], factor)
    np.testing.assert_allclose(sky.record["reference"]["read"], read["card"][:3])
    assert sky.record["reference"]["region"] == "card"
    for s in sessions.values():
        np.testing.assert_allclose(s.light_factor, factor)
        assert s.made == 1
    # relight's and maps' light: the level, then the factor
    day = Sky(np.array([0.3, -0.2, 0.8]), clear=[30.0, 38.0, 66.0], ground=[40.0, 41.0, 39.0],
              sun_radiance=[1.5e7, 1.2e7, 1e7])
    lit, = skies_at_level([day], {**sky.record, "terms": None}, ["2026-08-16T12:00:00+00:00"])
    d = np.random.default_rng(1).normal(size=(200, 3))
    d = np.vstack([d / np.linalg.norm(d, axis=1, keepdims=True), day.sun_direction])
    np.testing.assert_allclose(lit.radiance(d), day.sky_scaled(1.2).radiance(d) * factor,
                               rtol=1e-12)
    # nothing to calibrate on
    for regions in ({"paint": Region("paint", colour)},
                    {"paint": Region("paint", ["rho_s", "sigma_alpha"]),
                     "card": Region("card", ["rho_s", "sigma_alpha"])}):
        other = SkyFit({"k": 1.2})
        reference_factor(regions, other, fit, log=lambda *a: None)
        assert "reference" not in other.record
        assert all(s.light_factor is None and s.made == 0 for s in regions.values())
    reference_factor(sessions, SkyFit(None), fit, log=lambda *a: None)


def test_a_parameter_the_sky_sets_is_warned_with_what_would_narrow_it():
    """A parameter whose interval the fitted sky's uncertainty at least doubles is warned,
    naming the parts of the light fitted; without a reference a grey card would narrow it,
    with one (the light calibrated again on it) what is left is the sky the region sees
    otherwise than the reference does, which other normals or the sky photographed tell."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.fit_warnings import sky_warnings
    from skyfit_mi.fitting.sky_fit import SkyShare

    record = {"k": 1.2, "interval95": [1.1, 1.3], "terms": None, "shape": None,
              "departure": {"weights": [0.1]}, "warnings": []}
    s = SimpleNamespace(names=["C_r", "rho_s"], light=SimpleNamespace(sun_sd=0.0))

    def warned(record):
        fit = SimpleNamespace(sky=SkyShare(record, sd=np.array([0.01, 1e-5])),
                              covariance=np.diag([1e-6, 1e-6]), sun_level_sd=np.zeros(2))
        return sky_warnings(s, fit)

    alone, = warned(record)
    assert alone.startswith("C_r depends on the sky: ") and "its departure from its model" in alone
    assert "+-0.0196 (95%)" in alone
    assert "or a grey card in the fit would narrow it" in alone
    calibrated, = warned({**record, "reference": {"region": "grey_card"}})
    assert "otherwise than grey_card" in calibrated and "grey card in the fit" not in calibrated
    both = sky_warnings(s, SimpleNamespace(sky=SkyShare(record, sd=np.array([0.01, 0.02])),
                                           covariance=np.diag([1e-6, 1e-6]),
                                           sun_level_sd=np.zeros(2)))
    assert len(both) == 1 and both[0].startswith("C_r, rho_s depend on the sky: "), both
    assert "+-0.0196, +-0.0392 (95%)" in both[0]


def test_the_whole_lights_level_over_the_day_is_fitted_where_the_frames_keep_exif():
    """Frames that keep their relative exposures from EXIF carry the real light's curve over the
    day, which the spec's sun follows only as far as its air is the model's: where the
    reference saw it drift, the fit of the sky takes the whole
    light's level, sun and sky, as LEVEL_TERMS Legendre terms about its mean (the exposure's),
    under the drift prior.  The coefficients light a session with it
    (set_sky's level, exp(P_1.. u) by frame), relight and maps take it from the record with k
    and the reference's factor (skies_at_level: every part of the light times it).  Frames
    calibrated one by one, days without a reference, rendered days and short days fit none."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.sky_fit import (DRIFT_SD, LEVEL_TERMS, SkyCoefficients,
                                           _curve_record, default_level_terms, light_level_at,
                                           skies_at_level, time_basis)
    from skyfit_mi.physics.sky import Sky
    from skyfit_mi.physics.sky_departure import PRIOR_SD

    photos = {"source": "photographs", "ingest": {"calibration": {"light_drift": True}}}
    assert default_level_terms(photos, 13) == LEVEL_TERMS == 2
    assert default_level_terms(photos, 4) == 0
    # the reference saw the spec's curve, or each frame was calibrated on it
    assert default_level_terms({**photos, "ingest": {"calibration": {"light_drift": False}}},
                               13) == 0
    assert default_level_terms({**photos, "ingest": {"calibration": {"per_frame": True}}},
                               13) == 0
    assert default_level_terms({"source": "photographs", "ingest": {}}, 13) == 0
    assert default_level_terms({"source": "render"}, 13) == 0

    c = SkyCoefficients(1, ("departure:sun P2",), 0.35, LEVEL_TERMS)
    assert c.names == ["log k", "departure sun P2", "log light term 1", "log light term 2"]
    assert c.columns == 3
    np.testing.assert_allclose(np.diag(c.precision)[1:], [PRIOR_SD[3] ** -2] + [DRIFT_SD ** -2] * 2)
    times = [f"2026-08-16T{h:02d}:00:00+00:00" for h in (9, 12, 15)]
    span = (1786870800.0, 1786892400.0)
    basis = time_basis(times, span, c.columns)
    np.testing.assert_allclose(basis[:, 1], [-1.0, 0.0, 1.0])

    class Session:
        def set_sky(self, k, mix=None, level=None, tone=None):
            self.k, self.mix, self.level, self.tone = k, mix, level, tone

    s, u = Session(), np.array([np.log(1.3), 0.1, 0.2, -0.05])
    c.light(s, basis, u)
    np.testing.assert_allclose(s.k, 1.3)
    np.testing.assert_allclose(s.mix, [0.1])
    np.testing.assert_allclose(s.level, np.exp(0.2 * basis[:, 1] - 0.05 * basis[:, 2]))
    assert s.tone is None
    plain = SkyCoefficients(1, ("departure:sun P2",), 0.35)
    plain.light(s, basis[:, :1], u[:2])
    assert s.level is None
    # a camera's tone curve's weights last, each under N(0, 1) (tone.tone_count)
    toned = SkyCoefficients(1, ("departure:sun P2",), 0.35, LEVEL_TERMS, 2)
    assert toned.names[-2:] == ["tone curve 1", "tone curve 2"]
    np.testing.assert_allclose(np.diag(toned.precision)[-2:], 1.0)
    toned.light(s, basis, np.r_[u, 0.3, -0.4])
    np.testing.assert_allclose(s.tone, [0.3, -0.4])
    np.testing.assert_allclose(s.level, np.exp(0.2 * basis[:, 1] - 0.05 * basis[:, 2]))

    # the record, read back by relight and maps
    w, cov = np.array([0.0, 0.2, -0.05]), np.diag([0.0, 0.01, 0.01])

    one = SimpleNamespace(obs=SimpleNamespace(frames=[0, 1, 2], times=times))
    record, log_level = _curve_record([one], w, cov, span, of="level")
    assert set(record["level_by_frame"]) == {0, 1, 2}
    sky = {"k": 1.3, "terms": None, "light_level": record}
    level = light_level_at(sky, times)
    np.testing.assert_allclose(level, np.exp(log_level))
    assert light_level_at({"k": 1.3}, times) is None
    day = Sky(np.array([0.3, -0.2, 0.8]), clear=[30.0, 38.0, 66.0], ground=[40.0, 41.0, 39.0],
              sun_radiance=[1.5e7, 1.2e7, 1e7])
    d = np.random.default_rng(2).normal(size=(100, 3))
    d = np.vstack([d / np.linalg.norm(d, axis=1, keepdims=True), day.sun_direction])
    for lit, v in zip(skies_at_level([day] * 3, sky, times), level):
        np.testing.assert_allclose(lit.radiance(d), day.sky_scaled(1.3).radiance(d) * v,
                                   rtol=1e-12)


def test_the_split_lights_mix_is_the_whole_lights_table(days):
    """The sun's table plus k = 1 times the rest's (independent samples) gives the whole
    light's radiance within their Monte Carlo errors; k scales only the sky's share, the
    light's level by frame both."""
    from skyfit_mi.fitting.fit import FitCache, FitSession
    from skyfit_mi.fitting.light import LightPlan
    from skyfit_mi.render.basis_table import TableModel, mixed

    # 16 positions: the spread of 4 understates the error of the low sun's frames; every
    # other frame, the lowest suns (the first and last, 75 degrees from the zenith) among them
    # (a z of each frame and channel: measured max |z| 1.8 and rms 0.96 on these 7, 2.7 and 1.4
    # on all 13, and above 1000 with the rest's weight 1.02 instead of 1)
    opts = dict(model="colour", cache=FitCache(16, 128, seed=3), frames=list(range(0, 13, 2)))
    whole = FitSession(days["clean"], "disc", REGION, **opts)
    split = FitSession(days["clean"], "disc", REGION, light=LightPlan("fit"), **opts)
    assert split.parts.names == ("sun", "sky")
    sun, rest = split.parts.tables
    theta = np.array([0.8, 0.7, 0.6, 0.2, 0.1])
    (a, va), (b, vb) = (TableModel(t, "colour").radiance_and_variance(theta)
                        for t in (whole.table, mixed(sun, [rest], [1.0])))
    z = (a.mean(axis=0) - b.mean(axis=0)) / np.sqrt((va.sum(axis=0) + vb.sum(axis=0))
                                                    / len(a) ** 2)
    assert np.all(np.abs(z) < 5) and np.sqrt(np.mean(z ** 2)) < 2.5, z
    L_sun, L_rest = (TableModel(t, "colour").radiance(theta) for t in (sun, rest))
    np.testing.assert_allclose(TableModel(mixed(sun, [rest], [2.0]), "colour").radiance(theta),
                               L_sun + 2.0 * L_rest, rtol=1e-5)
    w = np.linspace(0.6, 1.0, L_sun.shape[1])             # a weight on the sun, frame by frame
    np.testing.assert_allclose(
        TableModel(mixed(sun, [rest], [2.0], w), "colour").radiance(theta),
        w[:, None] * L_sun + 2.0 * L_rest, rtol=1e-5)
    # the whole light's level by frame (set_sky's level): sun and sky alike
    split.set_sky(2.0, None, w)
    np.testing.assert_allclose(split.wm.radiance(theta), w[:, None] * (L_sun + 2.0 * L_rest),
                               rtol=1e-5)


def rescaled_sky(day, out, factor):
    """A copy of ``day`` in ``out`` whose manifest's sky (all but the sun: the patterns and
    the sky-lit ground, :meth:`~skyfit_mi.physics.sky.Sky.sky_scaled`) is ``factor(frame)``
    times its own."""
    from measured_light import relabelled

    return relabelled(day, out, lambda frame, sky: sky.sky_scaled(factor(frame)))


@pytest.fixture(scope="module")
def dim_sky(days, tmp_path_factory):
    """The noisy disc day whose manifest's sky (all but the sun) is DIMMER times too dim."""
    return rescaled_sky(days["noisy"], tmp_path_factory.mktemp("dim") / "day",
                        lambda frame: 1.0 / DIMMER)


@pytest.fixture(scope="module")
def once():
    """The module's fits and sessions under :func:`traced_once`: a light traced once."""
    with traced_once():
        yield


@pytest.fixture(scope="module")
def dim_fit(dim_sky, once):
    """The dim-sky day fitted with its level (``fit --sky fit``): (result, log lines)."""
    from skyfit_mi.fitting.fit import fit_regions

    logs = []
    r = next(fit_regions(dim_sky, [("disc", REGION)], model="colour", light=LightOptions(sky="fit", terms=1),
                         log=logs.append))
    return r, logs


def test_a_sky_of_the_wrong_level_is_fitted_and_the_materials_held(dim_sky, dim_fit):
    """With the spec's sky too dim the materials absorb it (rho_s's interval misses the
    truth, the reflectances run to their bound); fitted with the materials, the sky's level
    holds the truth in its 95% interval, the spec's level outside it, and every parameter's
    interval holds the truth, the sky's share of its error included."""
    from skyfit_mi.fitting.fit import fit_regions

    logs = []
    spec = next(fit_regions(dim_sky, [("disc", REGION)], model="colour",
                            log=lambda *a: None))
    lo, hi = spec["intervals"]["rho_s"]["95"]
    assert not lo <= TRUTH["rho_s"] <= hi, spec["intervals"]["rho_s"]
    r, logs = dim_fit
    k = r["sky"]
    assert k["interval95"][0] < DIMMER < k["interval95"][1] and k["interval95"][0] > 1.0, k
    assert set(k["error_sd"]) == set(TRUTH) and k["regions"] == ["disc"]
    assert any("sky: the sky's level fitted" in x for x in logs)
    for p, v in TRUTH.items():
        lo, hi = r["intervals"][p]["95"]
        assert lo - 1e-9 <= v <= hi + 1e-9, (p, r["intervals"][p], r["parameters"])


def test_sky_shape_is_for_regions_not_maps(days, capsys):
    assert main(["fit", str(days["clean"]), "--region", "disc=rect:2,2,9,9", "--per-pixel",
                 "--sky", "fit", "--sky-shape"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--sky-shape" in err, err


@pytest.fixture(scope="module")
def again(dim_sky, dim_fit, once):
    """The dim-sky fit's session made again from its result (``FitSession.from_fit``), on the
    fit's own trace where it asks for the very light the fit traced (:func:`traced_once`)."""
    from skyfit_mi.fitting.fit import FitSession

    return FitSession.from_fit(dim_fit[0], dim_sky)


def test_the_fitted_sky_lights_its_own_day_again(dim_fit, again):
    """A session made again from a sky fit's result (chi2map, predictions) traces the split
    light at the fitted level, so that its chi-square is the fit's at the fit's parameters."""
    r = dim_fit[0]
    assert again.light.split and again.sky_scale == pytest.approx(r["sky"]["k"])
    theta = np.array(list(r["parameters"].values()))
    assert again.problem.chi2(theta) == pytest.approx(r["chi2"], rel=1e-6)


def test_a_sky_level_beyond_the_search_is_undetermined_and_widens_every_interval(days, tmp_path):
    """A spec's sky 40 times too dim (beyond SCALE_LIMITS' 16): k runs to the search's end, is
    recorded as not determined with its interval open there, and every parameter's interval
    takes in its values over the k the profile could not tell apart (half the region, at 16
    positions)."""
    from skyfit_mi.fitting.fit import FitCache, fit_regions
    from skyfit_mi.fitting.sky_fit import SCALE_LIMITS

    out = rescaled_sky(days["noisy"], tmp_path / "day", lambda frame: 1.0 / 40.0)
    r = next(fit_regions(out, [("disc", HALF)], model="colour", light=LightOptions(sky="fit"),
                         log=lambda *a: None, cache=FitCache(16)))
    sky = r["sky"]
    assert not sky["determined"] and sky["interval95"][1] is None
    assert sky["k"] == pytest.approx(SCALE_LIMITS[1]), sky
    assert any("do not determine the sky's level" in w for w in r["warnings"])
    assert all("undetermined sky level" in r["intervals"][p]["from"] for p in TRUTH)


def test_a_sky_level_beyond_the_first_grid_is_searched_for_and_determined(days, tmp_path):
    """A spec's sky 6 times too dim (k = 6, beyond the first grid's 4, within SCALE_LIMITS):
    the search steps on past the grid's end, finds the least inside and determines k there,
    its interval holding 6, and every parameter's interval the truth."""
    from skyfit_mi.fitting.fit import FitCache, fit_regions
    from skyfit_mi.fitting.sky_fit import SCALE_GRID, SCALE_LIMITS

    assert SCALE_GRID[-1] < 6.0 < SCALE_LIMITS[1]
    out = rescaled_sky(days["noisy"], tmp_path / "day", lambda frame: 1.0 / 6.0)
    r = next(fit_regions(out, [("disc", HALF)], model="colour", light=LightOptions(sky="fit"),
                         log=lambda *a: None, cache=FitCache(16)))
    sky = r["sky"]
    assert sky["determined"] and sky["interval95"][0] < 6.0 < sky["interval95"][1], sky
    assert not any("do not determine the sky's level" in w for w in r["warnings"])
    for p, v in TRUTH.items():
        lo, hi = r["intervals"][p]["95"]
        assert lo - 1e-9 <= v <= hi + 1e-9, (p, r["intervals"][p], r["parameters"])


def test_where_the_data_alone_put_the_skys_level_is_read_from_their_profile():
    from skyfit_mi.fitting.sky_fit import SCALE_GRID, _data_beyond_search

    grid = np.log(SCALE_GRID)
    assert _data_beyond_search({u: (u - 0.3) ** 2 for u in grid}, grid) == 0
    assert _data_beyond_search({u: -u for u in grid}, grid) == 1
    # a refining point below the grid's end is beyond it too
    assert _data_beyond_search({**{u: u for u in grid}, grid[0] - 0.1: grid[0] - 0.1},
                               grid) == -1


def test_regions_that_disagree_on_the_skys_level_widen_its_uncertainty():
    """_regions_agree: regions whose own levels agree within their curvature leave the sky's
    information as it is; regions each reading the light at another level (a sky of another
    shape, seen through each material's own lobe) give Q = the sum of each one's chi-square at
    the pooled level above its own least (exact here: parabolas in log k), p < MISFIT_P, and the
    data's information on the sky divided by Q / (R - 1); each region's own level is read from
    its parabola between the grid's points."""
    from skyfit_mi.fitting.sky_fit import SCALE_GRID, _Level, _regions_agree
    from skyfit_mi.fitting.uncertainty import MISFIT_P

    grid = np.log(SCALE_GRID)
    us = np.sort(np.r_[grid, 0.05, 0.15])

    def level(own, b):
        profile = {u: [(1000.0 + b_r * (u - m) ** 2, None) for m, b_r in zip(own, b)]
                   for u in us}
        lv = _Level(profile, grid, None)
        lv.u0 = min(profile, key=lv.total)
        return lv

    same = _regions_agree(level([0.1, 0.1, 0.1], [50.0, 100.0, 200.0]))
    assert same["scale"] == 1.0 and same["dof"] == 2 and same["chi2"] < 1.0
    assert np.allclose(same["by_region"], np.exp(0.1), rtol=1e-9)
    own = [0.0, 0.3, -0.25]
    lv = level(own, [100.0, 100.0, 100.0])
    apart = _regions_agree(lv)
    q = sum(100.0 * (lv.u0 - m) ** 2 for m in own)
    assert apart["chi2"] == pytest.approx(q, rel=1e-6) and apart["p"] < MISFIT_P
    assert apart["scale"] == pytest.approx(q / 2, rel=1e-6)
    assert np.allclose(np.log(apart["by_region"]), own, atol=1e-9)
    # one region alone has nothing to disagree with
    assert _regions_agree(level([0.3], [100.0]))["scale"] == 1.0


def test_a_level_far_from_its_prior_is_warned():
    """A determined level within the search but over PRIOR_FAR prior sds from the spec's (a sky
    map turned the wrong way read k 0.25, 4 sd) is warned of; one within it is not."""
    from skyfit_mi.fitting.sky_fit import PRIOR_FAR, SCALE_GRID, _Level, _level_warnings

    grid = np.log(SCALE_GRID)

    def warned(own, prior_sd=0.35):
        profile = {u: [(1000.0 + 400.0 * (u - own) ** 2, None)] for u in np.r_[grid, own]}
        lv = _Level(profile, grid, prior_sd, u0=own, sd_u=0.05)
        lv.agree = {"scale": 1.0}
        return [w for w in _level_warnings(lv, 1) if "sd of its prior from the spec" in w]

    far = warned(np.log(0.3))               # inside the search (its lowest end warns alone)
    assert abs(np.log(0.3)) > PRIOR_FAR * 0.35 and len(far) == 1 and "k = 0.3" in far[0]
    assert warned(np.log(0.8)) == [] and warned(np.log(0.3), prior_sd=None) == []


def test_a_prior_holding_a_level_the_data_put_beyond_the_search_is_warned(again, dim_fit,
                                                                           monkeypatch):
    """Under the prior the profile's least point can lie inside the search while the data's
    own runs to one of its ends (their chi-square falls gently beyond it, as a hazy day's under
    a clear spec did toward k = 0.25: Perez clearness 2 in the sky test set); the fit then says
    that no parameter is reliable.  Where the data's own least point lies inside, or the data
    hardly tell the level (the prior holds it without conflict), it does not."""
    from skyfit_mi.fitting import sky_fit

    theta = np.array(list(dim_fit[0]["parameters"].values()))
    base = float(again.problem.chi2(theta))
    from skyfit_mi.fitting.light import LightPlan

    kept = again.sky_scale
    try:
        for slope, warned in ((5.0, "highest"), (-5.0, "lowest"), (0.3, None), (None, None)):
            def least(sessions, k, starts):
                u = np.log(k)
                return [(base + (-slope * u if slope else 40.0 * u * u), theta)]
            monkeypatch.setattr(sky_fit, "_least", least)
            r = sky_fit.fit_sky_scale([again], LightPlan("prior", terms=1),
                                      log=lambda *a: None).record
            said = [w for w in r["warnings"] if "the data alone put the sky's level" in w]
            assert r["determined"]
            # the posterior's least point of -slope u + (u / 0.35)^2 (the bowl's: 0)
            assert np.log(r["k"]) == pytest.approx((slope or 0.0) * 0.35 ** 2 / 2, abs=0.05)
            assert bool(said) == bool(warned), r["warnings"]
            if warned:
                # the conflict (5 x 1.08 + 0.77) / s^2 is significant for s^2 below 1.6
                assert r["interval_scale_s2"] < 1.5
                assert f"or beyond the {warned} searched (k =" in said[0]
                assert "not reliable" in said[0]
                assert "unless" not in said[0]           # one level: no curve to take it up
    finally:
        again.set_sky(kept)                             # the fixture as it was


def test_the_skys_share_taken_at_a_regions_own_fit_is_the_sky_fits_there(again):
    """At the parameters the sky fit ended at, the sky's share taken again at a region's own
    fit (sky_fit.share_at: its response by central differences) is the sky fit's own (there,
    from the level's profile), and leaves the region lit as it was; elsewhere it differs."""
    from skyfit_mi.fitting import sky_fit
    from skyfit_mi.fitting.light import LightPlan

    kept = again.sky_scale
    try:
        share = sky_fit.fit_sky_scale([again], LightPlan("fit", terms=1),
                                      log=lambda *a: None).shares["disc"]
        theta = share.light.theta
        before = again.problem.chi2(theta)
        at = sky_fit.share_at(again, share, theta)
        # the level's slope from steps of 0.1 in log k against 0.001: within 13% (rho_s)
        np.testing.assert_allclose(at.sd, share.sd, rtol=0.2)
        assert at.response.shape == (len(theta), 1)
        assert again.problem.chi2(theta) == pytest.approx(before, rel=1e-9)
        moved = theta * np.r_[np.ones(len(theta) - 1), 1.5]     # another roughness
        assert not np.allclose(sky_fit.share_at(again, share, moved).sd, at.sd, rtol=0.05)
    finally:
        again.set_sky(kept)                             # the fixture as it was


def test_a_day_without_sun_cannot_fit_the_sky_against_it(days):
    from skyfit_mi.errors import SkyfitError
    from skyfit_mi.fitting.fit import fit_regions

    with pytest.raises(SkyfitError, match="no frame of the sequence has the sun"):
        next(fit_regions(days["overcast"], [("disc", REGION)], model="colour", light=LightOptions(sky="fit"),
                         log=lambda *a: None))


def test_another_days_prediction_says_its_sky_is_the_spec_s(dim_fit, days):
    """A sky fit relit onto another day (another run_id) takes that day's spec sky, and the
    prediction says so."""
    from skyfit_mi.fitting.relight import predict

    r = dim_fit[0]
    logs = []
    predict({"disc": (None, r)}, days["clean"], {"disc": np.asarray(r["pixels"])}, draws=8,
            seed=0, log=logs.append)
    assert any("under the target's spec sky" in x and "belongs to its own day" in x
               for x in logs), logs


def test_the_sky_scaled_is_the_sun_plus_k_times_the_rest():
    from skyfit_mi.physics.sky import Sky

    sky = Sky(np.array([0.3, -0.2, 0.8]), clear=[30.0, 38.0, 66.0], overcast=[5.0, 5.0, 6.0],
              ground=[40.0, 41.0, 39.0], sun_radiance=[1.5e7, 1.2e7, 1e7],
              envmap=np.full((4, 8, 3), 2.0, np.float32))
    sun, rest = sky.split()
    d = np.random.default_rng(1).normal(size=(300, 3))
    d = np.vstack([d / np.linalg.norm(d, axis=1, keepdims=True), sky.sun_direction])
    np.testing.assert_allclose(sky.sky_scaled(1.7).radiance(d),
                               sun.radiance(d) + 1.7 * rest.radiance(d), rtol=1e-6)
    assert np.all(sky.sky_scaled(1.7).ground < 1.7 * sky.ground)      # the sun-lit share stays


def test_the_sky_prior_holds_k_nearer_the_spec_and_no_wider(dim_fit, again):
    """The prior on the sky's level pulls k toward the spec's (log k = 0) and narrows its
    interval: a posterior is at most as wide as the data's alone.  (The level fitted under the
    prior on the dim-sky fit's own light, traced again from its result: the record is
    fit_regions' with --sky prior --sky-terms 1 to the last digit, without tracing the day a
    third time; test_by_default_... fits with the prior through fit_regions.)"""
    from skyfit_mi.fitting import sky_fit
    from skyfit_mi.fitting.light import LightPlan

    alone = dim_fit[0]["sky"]
    kept = again.sky_scale
    try:
        prior = sky_fit.fit_sky_scale([again], LightPlan("prior", terms=1),
                                      log=lambda *a: None).record
    finally:
        again.set_sky(kept)                             # the fixture as it was
    assert 1.0 < prior["k"] <= alone["k"] * 1.001
    assert (np.log(prior["interval95"][1] / prior["interval95"][0])
            <= np.log(alone["interval95"][1] / alone["interval95"][0]) * 1.001)
    assert prior["interval95"][0] < DIMMER < prior["interval95"][1]


def test_relit_images_take_the_fitted_sky_level_of_their_own_day():
    from skyfit_mi.fitting.relight import fitted_sky_level

    doc = {"run_id": "a"}
    fit = lambda k, run="a": {"sky": {"k": k}, "sequence_run_id": run}   # noqa: E731
    assert fitted_sky_level({"x": (None, fit(1.4)), "y": (None, fit(1.4))}, doc)["k"] == 1.4
    assert fitted_sky_level({"x": (None, fit(1.4, run="b"))}, doc) is None
    assert fitted_sky_level({"x": (None, {"sequence_run_id": "a"})}, doc) is None
    logs = []
    assert fitted_sky_level({"x": (None, fit(1.4)), "y": (None, fit(0.9))}, doc,
                            logs.append) is None
    assert "differ" in logs[0]


@pytest.mark.parametrize("argv, says", [
    (["--sky", "fit", "--sun-sd", "2"], "--sun-sd = 2"),
    (["--sky", "spec", "--sun-sd", "0.1"], "(--sky spec): give --sky fit or prior"),
    (["--sun-sd", "0.1"], "the default where skyfit rendered the frames"),
    (["--per-pixel", "--sky", "spec", "--sun-sd", "0.1"], "--sun-sd belongs to a fitted sky"),
    (["--model", "auto", "--sky-shape"], "--model auto ranks every lobe"),
    (["--per-pixel", "--directions", "64"], "--directions belongs to region fits")])
def test_a_sun_sd_or_option_a_fit_cannot_take_is_one_line(days, capsys, tmp_path, argv, says):
    assert main(["fit", str(days["clean"]), "--region", "disc=rect:2,2,9,9", *argv,
                 "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err, err
    assert not (tmp_path / "out").exists()


DRIFT = 0.4           # log k's true change from the day's middle to its ends


@pytest.fixture(scope="module")
def drifting_sky(days, tmp_path_factory):
    """The noisy disc day whose manifest's sky (all but the sun) is exp(-DRIFT x) times its
    own, x from -1 at the first frame to 1 at the last: the real sky's level against the
    spec's, k(t) = exp(DRIFT x), rises through the day."""
    frames = json.loads((days["noisy"] / "manifest.json").read_text())["frames"]
    x = dict(zip((f["index"] for f in frames), np.linspace(-1.0, 1.0, len(frames))))
    return rescaled_sky(days["noisy"], tmp_path_factory.mktemp("drift") / "day",
                        lambda frame: np.exp(-DRIFT * x[frame["index"]]))


@pytest.mark.slow       # 33 s; the default curve's test below fits a curve by default
def test_a_sky_that_changes_over_the_day_is_fitted_as_a_smooth_curve(drifting_sky):
    """With --sky-terms 2 the fit finds log k's slope over the day within its interval, the
    level's at the spec's, k per frame rising, and every parameter's interval holds the
    truth; the curve lights the day again in a session made from the fit."""
    from skyfit_mi.fitting.fit import FitSession, fit_regions

    r = next(fit_regions(drifting_sky, [("disc", REGION)], model="colour", light=LightOptions(sky="fit", terms=2),
                         log=lambda *a: None))
    terms = r["sky"]["terms"]
    u, sd = np.array(terms["coefficients"]), np.sqrt(np.diag(terms["covariance"]))
    for j, truth in enumerate((0.0, DRIFT)):
        assert abs(u[j] - truth) < 1.96 * sd[j] + 0.02, (j, u, sd)
    assert sd[1] < 0.5 * DRIFT
    k = [v[0] for v in terms["k_by_frame"].values()]
    assert np.all(np.diff(k) > 0)
    for p, v in TRUTH.items():
        lo, hi = r["intervals"][p]["95"]
        assert lo - 1e-9 <= v <= hi + 1e-9, (p, r["intervals"][p], r["parameters"])
    again = FitSession.from_fit(r, drifting_sky)
    np.testing.assert_allclose(again.sky_scale, k, rtol=1e-6)


def test_a_clear_skys_share_of_the_light_follows_the_suns_height_by_the_air():
    """DEFAULT_TERMS' grounds: in Ineichen and Perez's clear-sky model (pvlib) the slope of
    log(DHI / DNI) in log air mass (1-3) runs from about -0.4 at Linke turbidity 2.5 to +0.17
    at 7, rising with the turbidity: how the sky's share moves with the sun's height depends
    on the air, so one model sky's level cannot hold over a day."""
    import pvlib

    m = np.linspace(1.0, 3.0, 21)
    zenith = np.degrees(np.arccos(1.0 / m))
    am = pvlib.atmosphere.get_relative_airmass(zenith, "kastenyoung1989")
    slopes = []
    for t in (2.5, 4.0, 7.0):
        sky = pvlib.clearsky.ineichen(zenith, pvlib.atmosphere.get_absolute_airmass(am), t)
        slopes.append(np.polyfit(np.log(am), np.log(sky["dhi"] / sky["dni"]), 1)[0])
    assert -0.45 < slopes[0] < -0.35 and 0.12 < slopes[2] < 0.22, slopes
    assert np.all(np.diff(slopes) > 0), slopes


def test_a_modelled_suns_level_moves_with_the_skys_by_the_air():
    """SUN_SKY_COUPLING's grounds: over Linke turbidities 2-7 in Ineichen and Perez's model, at
    air mass 1.1-2, log DNI falls 0.29-0.39 per unit rise of log(DHI / DNI): a sky brighter
    against the sun than a model's comes with a sun dimmer than the model's."""
    import pvlib

    from skyfit_mi.physics.sky import SUN_SKY_COUPLING

    turbidity = np.array([2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.0, 7.0])
    slopes = []
    for m in (1.1, 1.5, 2.0):
        zenith = np.degrees(np.arccos(1.0 / m))
        am = pvlib.atmosphere.get_relative_airmass(zenith, "kastenyoung1989")
        sky = [pvlib.clearsky.ineichen(zenith, pvlib.atmosphere.get_absolute_airmass(am), t)
               for t in turbidity]
        dni, dhi = (np.array([float(x[c]) for x in sky]) for c in ("dni", "dhi"))
        slopes.append(-np.polyfit(np.log(dhi / dni), np.log(dni), 1)[0])
    assert 0.27 < min(slopes) and max(slopes) < 0.41, slopes
    assert min(slopes) <= SUN_SKY_COUPLING <= max(slopes)


#: log k's true slope in the log of the sun's air mass (the sky's share grows as the sun sinks)
HEIGHT = 0.3


@pytest.fixture(scope="module")
def height_sky(days, tmp_path_factory):
    """The noisy disc day whose manifest's sky (all but the sun) is m^-HEIGHT times its own
    (m the sun's air mass, 1 / cos z): the real sky's level against the spec's,
    k = m^HEIGHT, is least at noon and rises toward both ends of the day, as the sky's share of
    a clear day's light does against a model of another atmosphere."""
    return rescaled_sky(days["noisy"], tmp_path_factory.mktemp("height") / "day",
                        lambda frame: np.cos(np.radians(frame["sun_zenith_deg"])) ** HEIGHT)


def test_by_default_the_skys_level_follows_the_suns_height_and_weather(height_sky, once):
    """Not told, a fitted sky's level changes smoothly over the day (DEFAULT_TERMS: level,
    drift, curve), each term beyond the level under its prior: on a day whose sky-to-sun
    ratio follows the sun's height the curve bends up toward both ends, k at the frames holds
    the truth, every parameter's interval holds its truth, and the terms the data hardly tell
    raise no warning (the prior holds them, and the intervals include that); fewer frames take
    fewer terms.  One level for the day puts the diffuse colour outside its interval (fitted
    on the same traced light: the plan differs in its terms alone, :func:`traced_once`)."""
    from skyfit_mi.fitting.fit import fit_regions
    from skyfit_mi.fitting.sky_fit import DEFAULT_TERMS, default_terms

    logs = []
    r = next(fit_regions(height_sky, [("disc", REGION)], model="colour", light=LightOptions(sky="prior"),
                         log=logs.append))
    terms = r["sky"]["terms"]
    assert len(terms["coefficients"]) == DEFAULT_TERMS and terms["coefficients"][2] > 0
    assert any("changing over the day as 3 terms: k = " in x and "over the 13 frames" in x
               for x in logs), logs
    assert not any("hardly tell how the sky changes" in w for w in r["warnings"])
    frames = json.loads((height_sky / "manifest.json").read_text())["frames"]
    truth = {f["index"]: np.cos(np.radians(f["sun_zenith_deg"])) ** -HEIGHT for f in frames}
    held = [lo <= truth[int(i)] <= hi for i, (_, lo, hi) in terms["k_by_frame"].items()]
    assert np.mean(held) >= 0.8, (terms["k_by_frame"], truth)
    for p, v in TRUTH.items():
        lo, hi = r["intervals"][p]["95"]
        assert lo - 1e-9 <= v <= hi + 1e-9, (p, r["intervals"][p], r["parameters"])
    assert [default_terms(n) for n in (1, 3, 4, 5, 13)] == [1, 1, 2, 3, 3]
    assert default_terms(13, referenced=True) == 1       # a reference calibrates the frames
    # one level for the day (--sky-terms 1) puts the diffuse colour low, outside its interval
    one = next(fit_regions(height_sky, [("disc", REGION)], model="colour", light=LightOptions(sky="prior", terms=1),
                           log=lambda *a: None))
    lo, hi = one["intervals"]["C_b"]["95"]
    assert hi < TRUTH["C_b"], one["intervals"]["C_b"]
    # each record's chi2 and dof are its final fit's, less the coefficients it fitted; the
    # curve's chi-square is no higher (measured: 1.1 lower), the one level's the profile's at k
    assert r["sky"]["dof"] == r["dof"] - DEFAULT_TERMS and one["sky"]["dof"] == one["dof"] - 1
    assert r["sky"]["chi2"] <= one["sky"]["chi2"], (r["sky"]["chi2"], one["sky"]["chi2"])
    profile = dict(zip(one["sky"]["profile"]["k"], one["sky"]["profile"]["chi2"]))
    assert one["sky"]["chi2"] == pytest.approx(profile[one["sky"]["k"]], rel=1e-12)


def test_sky_terms_need_a_fitted_sky_and_frames(days):
    from skyfit_mi.errors import SkyfitError
    from skyfit_mi.fitting.fit import fit_regions

    with pytest.raises(SkyfitError, match="--sky spec"):
        next(fit_regions(days["clean"], [("disc", REGION)], model="colour", light=LightOptions(sky="spec", terms=2),
                         log=lambda *a: None))
    with pytest.raises(SkyfitError, match="give 1"):
        next(fit_regions(days["clean"], [("disc", REGION)], model="colour", light=LightOptions(sky="fit", terms=9),
                         log=lambda *a: None))




def test_a_references_calibration_carries_the_skys_coefficients_to_every_region(again):
    """Where a reference calibrates the fitted light again (fit.reference_factor: a factor per
    channel f on every region's light, its fit's radiance over a Lambertian surface's of its
    known reflectance), a region's parameters follow the sky's coefficients through f too: the
    response share_at takes with the factor's slope (sky_fit.reference_slope) is the slope of
    the whole procedure (the reference fitted at the sky's coefficients, f, the region fitted
    under the light times f) at steps of the sky's level, and it is not the response without
    the factor (a brighter sky lowers every reflectance, and the reference's reading with
    them, which f gives back)."""
    from skyfit_mi.fitting import sky_fit
    from skyfit_mi.fitting.light import LightPlan
    from skyfit_mi.fitting.methods.levenberg_marquardt import levenberg_marquardt

    kept = again.sky_scale
    try:
        share = sky_fit.fit_sky_scale([again], LightPlan("fit", terms=1),
                                      log=lambda *a: None).shares["disc"]
        light, theta = share.light, share.light.theta
        known = np.r_[0.9 * theta[:3], 0.0, theta[4]]          # a reference of its own
        slope = sky_fit.reference_slope(again, light, theta, known)

        def calibrated(u):
            """The region's fit under the light at ``u`` times the reference's factor there."""
            again.light_factor = None
            light.put(again, u)
            ref = levenberg_marquardt(again.problem, theta, again.lower, again.upper)["theta"]
            again.light_factor = (np.sum(again.wm.radiance(ref), axis=(0, 1))
                                  / np.sum(again.wm.radiance(known), axis=(0, 1)))
            light.put(again, u)
            return levenberg_marquardt(again.problem, ref, again.lower, again.upper)["theta"]

        h = 0.02
        slopes = (calibrated(light.u + h) - calibrated(light.u - h)) / (2 * h)
        at_u = calibrated(light.u)                         # lit at u times its factor
        with_factor = sky_fit.share_at(again, replace(share, reference_slope=slope), at_u)
        again.light_factor = None
        light.put(again)
        without = sky_fit.share_at(again, share, theta)
        scaled = slice(0, 4)                                   # C and rho_s
        np.testing.assert_allclose(with_factor.response[scaled, 0], slopes[scaled],
                                   rtol=0.2, atol=0.05 * np.abs(without.response[scaled, 0]).max())
        assert not np.allclose(with_factor.response[scaled, 0], without.response[scaled, 0],
                               rtol=0.5)
    finally:
        again.light_factor = None
        again.set_sky(kept)                             # the fixture as it was


def test_held_coefficients_carry_their_error_about_zero_directly_and_through_the_light():
    """A tone curve's weights held at 0 (sky_fit._held_covariance): with no step asked the
    covariance is the posterior's; with a step s, the held ones' error about 0 is C_hh + s s^T,
    and a region's response R = (R_f, R_h) carries R_f C_f|h R_f^T + (R_f G + R_h) (C_hh + s s^T)
    (R_f G + R_h)^T, G the free ones' regression on the held."""
    from skyfit_mi.fitting.sky_fit import _held_covariance

    rng = np.random.default_rng(4)
    A = rng.normal(size=(5, 5))
    C = A @ A.T + np.eye(5)
    free = np.array([True, True, True, False, False])
    np.testing.assert_allclose(_held_covariance(C, free, np.zeros(2)), C, atol=1e-12)
    np.testing.assert_array_equal(_held_covariance(C, np.ones(5, bool), np.ones(0)), C)
    s = np.array([0.7, -1.2])
    out = _held_covariance(C, free, s)
    assert np.all(np.linalg.eigvalsh(out) > -1e-12)
    f, h = np.ix_(free, free), np.ix_(~free, ~free)
    G = C[np.ix_(free, ~free)] @ np.linalg.inv(C[h])
    R = rng.normal(size=(3, 5))
    Rf, Rh = R[:, free], R[:, ~free]
    Ch = C[h] + np.outer(s, s)
    want = Rf @ (C[f] - G @ C[np.ix_(~free, free)]) @ Rf.T + (Rf @ G + Rh) @ Ch @ (Rf @ G + Rh).T
    np.testing.assert_allclose(R @ out @ R.T, want, rtol=1e-10)
