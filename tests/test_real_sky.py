"""Sky models against a measured clear sky (issue 15): the CIE general sky's known values, the
figure of merit, and the Kider et al. (2014) scans of 2013-05-27 (Apache-2.0; data in
../shared/data/ beside the repository)."""
import numpy as np
import pytest

from skyfit_mi.conventions import angles_from_direction, direction_from_angles
from skyfit_mi.errors import SkyfitError
from skyfit_mi.physics import cie_general as cg
from skyfit_mi.physics.sky import clear_pattern, overcast_pattern
from skyfit_testkit import sky_measurement as sm

# --------------------------------------------------------------------------
# The CIE general sky (CIE S 011/E:2003)
# --------------------------------------------------------------------------

#: CIE S 011/E:2003, Table 1, typed from the standard (a, b, c, d, e per type 1-15).
TABLE_1 = [
    (4.0, -0.70, 0, -1.0, 0.00), (4.0, -0.70, 2, -1.5, 0.15), (1.1, -0.80, 0, -1.0, 0.00),
    (1.1, -0.80, 2, -1.5, 0.15), (0.0, -1.00, 0, -1.0, 0.00), (0.0, -1.00, 2, -1.5, 0.15),
    (0.0, -1.00, 5, -2.5, 0.30), (0.0, -1.00, 10, -3.0, 0.45), (-1.0, -0.55, 2, -1.5, 0.15),
    (-1.0, -0.55, 5, -2.5, 0.30), (-1.0, -0.55, 10, -3.0, 0.45), (-1.0, -0.32, 10, -3.0, 0.45),
    (-1.0, -0.32, 16, -3.0, 0.30), (-1.0, -0.15, 16, -3.0, 0.30), (-1.0, -0.15, 24, -2.8, 0.15),
]


def test_standard_types_from_their_groups_match_table_1():
    np.testing.assert_array_equal(cg.STANDARD_PARAMETERS, np.array(TABLE_1))
    for t in range(1, 16):
        np.testing.assert_array_equal(cg.standard_parameters(t), TABLE_1[t - 1])


@pytest.mark.parametrize("bad", [0, 16, 12.5, True])
def test_unknown_standard_type_is_refused(bad):
    with pytest.raises(SkyfitError, match="give an integer from 1"):
        cg.standard_parameters(bad)


@pytest.mark.parametrize("sky_type", range(1, 16))
@pytest.mark.parametrize("sun_zenith_deg", [0.0, 30.0, 60.0, 89.0])
def test_relative_luminance_is_one_at_the_zenith(sky_type, sun_zenith_deg):
    sun = direction_from_angles(np.radians(sun_zenith_deg), 1.0)
    value = cg.pattern(np.array([[0.0, 0.0, 1.0]]), sun, cg.standard_parameters(sky_type))
    assert value == pytest.approx([1.0], abs=1e-12)


def test_hand_derived_values():
    # Type 12, sun at the zenith, element 60 deg from it (so zeta = 60 deg):
    # f(pi/3) = 1 + 10 (e^-pi - e^-3pi/2) + 0.45/4 = 1.4548063, f(0) = 11.3601671,
    # phi(60) = 1 - e^-0.64 = 0.4727076, phi(0) = 1 - e^-0.32 = 0.2738510,
    # L/Lz = 1.4548063 * 0.4727076 / (11.3601671 * 0.2738510) = 0.2210542.
    d = direction_from_angles(np.radians(60.0), 0.3)
    assert cg.pattern(d[None], np.array([0.0, 0.0, 1.0]), cg.standard_parameters(12)) \
        == pytest.approx([0.2210542], abs=1e-7)
    # Type 1 (c = e = 0, so f = 1) at zenith 60 deg: (1 + 4 e^-1.4) / (1 + 4 e^-0.7) = 0.6651577,
    # close to the CIE overcast sky's (1 + 2 cos 60) / 3 = 0.6667, as the standard intends.
    sun = direction_from_angles(np.radians(40.0), 2.0)
    assert cg.pattern(d[None], sun, cg.standard_parameters(1)) == pytest.approx([0.6651577],
                                                                                abs=1e-7)
    assert overcast_pattern(d) / overcast_pattern(np.array([0.0, 0.0, 1.0])) \
        == pytest.approx(0.6651577, abs=2e-3)
    # Type 5 is the uniform sky.
    dirs = direction_from_angles(np.radians([5.0, 45.0, 89.0]), np.radians([0.0, 120.0, 300.0]))
    np.testing.assert_allclose(cg.pattern(dirs, sun, cg.standard_parameters(5)), 1.0, atol=1e-12)


def test_edges_horizon_and_nan():
    # phi -> 1 at the horizon and is held there below it; f(pi/2) = 1 for every type.
    a, b, c, d, e = cg.STANDARD_PARAMETERS.T
    np.testing.assert_allclose(cg.gradation(0.0, a, b), 1.0)
    np.testing.assert_allclose(cg.gradation(-0.5, a, b), 1.0)
    np.testing.assert_allclose(cg.gradation(1e-6, a, b), 1.0, atol=1e-12)
    np.testing.assert_allclose(cg.indicatrix(np.pi / 2, c, d, e), 1.0, atol=1e-12)
    assert np.isnan(cg.gradation(np.nan, -1.0, -0.32))
    assert np.isnan(cg.relative_luminance(0.5, np.nan, 0.3, cg.standard_parameters(12)))


def test_type_12_is_the_thesis_clear_sky():
    # gamma (eq. 4.12) is phi of gradation V; f (eq. 4.13) has 0.91 for 1 - 10 e^(-3 pi/2)
    # = 0.9101671, so the normalised patterns differ by less than 2 * 1.7e-4 relative.
    rng = np.random.default_rng(7)
    dirs = direction_from_angles(np.arccos(rng.uniform(0.02, 1.0, 500)),
                                 rng.uniform(0, 2 * np.pi, 500))
    for zs in (10.0, 35.0, 70.0):
        sun = direction_from_angles(np.radians(zs), np.radians(150.0))
        thesis = clear_pattern(dirs, sun) / clear_pattern(np.array([0.0, 0.0, 1.0]), sun)
        np.testing.assert_allclose(cg.pattern(dirs, sun, cg.standard_parameters(12)), thesis,
                                   rtol=4e-4)


def test_continuous_indices():
    np.testing.assert_array_equal(cg.clear_parameters([11, 12, 15]),
                                  cg.STANDARD_PARAMETERS[[10, 11, 14]])
    np.testing.assert_allclose(cg.clear_parameters(12.5),
                               (cg.standard_parameters(12) + cg.standard_parameters(13)) / 2)
    np.testing.assert_array_equal(cg.group_parameters(5, 4), cg.standard_parameters(12))
    np.testing.assert_array_equal(cg.group_parameters(6, 6), cg.standard_parameters(15))
    np.testing.assert_allclose(cg.group_parameters(5.5, 4),
                               [-1.0, -0.235, 10.0, -3.0, 0.45])
    assert cg.group_parameters([4.0, 6.0], [4.0, 5.0]).shape == (2, 5)
    with pytest.raises(SkyfitError, match="clear-sky type index t"):
        cg.clear_parameters(10.5)
    with pytest.raises(SkyfitError, match="gradation group"):
        cg.group_parameters(6.5, 4)


# --------------------------------------------------------------------------
# The figure of merit and the frame
# --------------------------------------------------------------------------

def test_relative_rms_hand_value_and_invariance():
    # k = exp(mean(ln 2, ln 1)) = sqrt 2; residuals (sqrt2 - 2)/2, (2 sqrt2 - 2)/2;
    # rms = sqrt((0.0857864 + 0.1715729) / 2) = 0.3587195.
    assert sm.scale_factor([1.0, 2.0], [2.0, 2.0]) == pytest.approx(np.sqrt(2.0))
    assert sm.relative_rms([1.0, 2.0], [2.0, 2.0]) == pytest.approx(0.3587195, abs=1e-7)
    y = np.array([3.0, 5.0, 11.0, 2.0])
    m = np.array([1.0, 2.0, 3.0, 1.5])
    assert sm.relative_rms(7.3 * m, y) == pytest.approx(sm.relative_rms(m, y), rel=1e-12)
    assert sm.relative_rms(y / 4.0, y) == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(sm.relative_rms(np.stack([m, y]), y),
                               [sm.relative_rms(m, y), 0.0], atol=1e-12)
    with pytest.raises(SkyfitError, match="positive"):
        sm.relative_rms([1.0, 0.0], [1.0, 1.0])


def test_scanner_rotation_matches_scipy_and_turns_azimuth_east():
    from scipy.spatial.transform import Rotation

    r = sm.rotation_matrix(sm.SCANNER_ROTATION_DEG)
    np.testing.assert_allclose(
        r, Rotation.from_rotvec(np.radians(sm.SCANNER_ROTATION_DEG)).as_matrix(), atol=1e-14)
    np.testing.assert_array_equal(sm.rotation_matrix([0, 0, 0]), np.eye(3))
    # README: true azimuth ~ nominal + 11.5 deg (a rotation of -11.5 deg about up).
    _, phi = angles_from_direction(r @ direction_from_angles(np.radians(60.0), np.radians(90.0)))
    assert np.degrees(phi) == pytest.approx(90.0 + 11.5, abs=1.0)


def test_missing_data_folder_says_how_to_fix(tmp_path, monkeypatch):
    monkeypatch.setenv(sm.DATA_ENV, str(tmp_path))
    with pytest.raises(SkyfitError, match="SKYFIT_SKY_DATA"):
        sm.data_dir()


# --------------------------------------------------------------------------
# The measured sky (Kider et al. 2014)
# --------------------------------------------------------------------------

def _data_present():
    try:
        sm.data_dir()
    except SkyfitError:
        return False
    return True


needs_data = pytest.mark.skipif(not _data_present(), reason=(
    "Kider et al. 2014 sky data not found: ../shared/data/sky-measurements-2014-05-27 beside "
    "the repository, or $SKYFIT_SKY_DATA"))


@pytest.fixture(scope="module")
def scans():
    return sm.load_scans()


@pytest.fixture(scope="module")
def results(scans):
    return sm.run_comparison(scans)


def _errors(results, model, rotated):
    sub = results[(results["model"] == model) & (results["rotated"] == rotated)]
    return sub["relative_rms"].to_numpy()


@needs_data
def test_scans_and_sun_as_the_readme(scans):
    assert len(scans) == 15 and all(len(s.luminance) == 81 for s in scans)
    assert (scans[0].label, scans[-1].label) == ("09:30", "13:30")
    # README table (pvlib, NREL SPA): 09:30 sun 98.2 / 41.1, 13:30 197.1 / 68.2 (az / el).
    assert (scans[0].sun_azimuth_deg, 90 - scans[0].sun_zenith_deg) == pytest.approx(
        (98.2, 41.1), abs=0.1)
    assert (scans[-1].sun_azimuth_deg, 90 - scans[-1].sun_zenith_deg) == pytest.approx(
        (197.1, 68.2), abs=0.1)
    assert scans[0].ghi == pytest.approx(656.13) and scans[0].dhi_scan == pytest.approx(80.3)
    assert scans[-1].ghi_time.strftime("%H:%M:%S") == "13:00:30"   # its log starts 13:00


@needs_data
def test_points_near_the_sun_are_left_out(scans):
    s = scans[5]                                       # 10:45: a point 1.9 deg from the sun
    r = sm.compare(s, sm.MODELS[-1])
    zeta = sm.angle_to_sun_deg(s.directions(), s.sun_direction)
    assert r["n_points"] == int((zeta >= sm.SUN_EXCLUSION_DEG).sum()) < 81


@needs_data
def test_issue_figures_for_the_thesis_clear_sky_and_a_uniform_sky(results):
    # Issue 15: CIE clear misses by 13-20 % per scan, day mean 0.164 (0.131 with the
    # README's scanner rotation); a uniform sky by 43-68 %.
    clear, clear_rot = (_errors(results, "cie_clear_thesis", r) for r in (False, True))
    assert clear.mean() == pytest.approx(0.164, abs=0.005)
    assert clear_rot.mean() == pytest.approx(0.131, abs=0.005)
    assert 0.125 <= clear.min() and clear.max() <= 0.205
    uniform = _errors(results, "uniform", False)
    assert (round(uniform.min(), 2), round(uniform.max(), 2)) == (0.43, 0.68)


#: Per-scan relative rms error of the best sky plus 0.01, 09:30 ... 13:30, from
#: `.venv/bin/python scripts/real_sky.py -o out/real_sky` (errors.csv): fitted to each scan
#: (cie_groups_fit, 2026-11-23) and predicted, its shape fitted to the other 14 scans
#: (cie_groups_fit_heldout, 2026-11-25).
BEST_UPPER_BOUNDS = {
    ("cie_groups_fit", False): [0.098, 0.109, 0.129, 0.125, 0.146, 0.136, 0.145, 0.143, 0.130,
                                0.142, 0.125, 0.146, 0.145, 0.139, 0.173],
    ("cie_groups_fit", True): [0.099, 0.089, 0.103, 0.075, 0.086, 0.065, 0.084, 0.090, 0.072,
                               0.085, 0.069, 0.101, 0.105, 0.078, 0.119],
    ("cie_groups_fit_heldout", False): [0.098, 0.109, 0.131, 0.127, 0.148, 0.136, 0.146, 0.144,
                                        0.130, 0.142, 0.126, 0.147, 0.145, 0.139, 0.173],
    ("cie_groups_fit_heldout", True): [0.099, 0.090, 0.106, 0.079, 0.090, 0.067, 0.086, 0.091,
                                       0.072, 0.086, 0.071, 0.103, 0.107, 0.080, 0.120],
}


@needs_data
@pytest.mark.parametrize("rotated", [False, True])
def test_best_sky_beats_the_thesis_and_does_not_get_worse(results, rotated):
    sub = results[results["rotated"] == rotated]
    best = sm.best_models(sub)
    assert (best["margin"] > 0.02).all()
    assert set(best["best"]) == {"cie_groups_fit"}
    for model in ("cie_groups_fit", "cie_groups_fit_heldout"):
        assert np.all(_errors(results, model, rotated) <= BEST_UPPER_BOUNDS[model, rotated])
    with pytest.raises(SkyfitError, match="not in the results"):
        sm.best_models(sub, reference="no_such_sky")


@needs_data
@pytest.mark.parametrize("rotated", [False, True])
def test_a_predicted_sky_beats_the_thesis_on_every_scan(results, rotated):
    # The goal held to a prediction: the CIE general sky's shape fitted to the other 14 scans
    # (leave one out), never to the scan it is scored on, still beats the thesis's clear sky.
    sub = results[(results["rotated"] == rotated) & ~results["model"].isin(
        [m.name for m in sm.MODELS if m.held_out])]
    held = sub[sub["held_out"]]
    assert set(held["model"]) == {"cie_type_fit_heldout", "cie_groups_fit_heldout",
                                  "perez_fit_heldout", "turbid_fit_heldout"}
    best = sm.best_models(sub)
    assert set(best["best"]) == {"cie_groups_fit_heldout"}
    assert (best["margin"] > 0.02).all()
    # Held out it cannot beat its own fit to the scan.
    assert np.all(_errors(results, "cie_groups_fit_heldout", rotated)
                  >= _errors(results, "cie_groups_fit", rotated) - 1e-12)


def _day_mean(results, model, rotated):
    return float(_errors(results, model, rotated).mean())


@needs_data
def test_perez_from_irradiance_and_its_fitted_shape(results, scans):
    # Issue 36: Perez from the pyranometer's GHI split by Erbs loses to the thesis's sky
    # (0.197 / 0.161 against 0.164 / 0.130, nominal / rotated); from the scan's own DHI it
    # ties (0.170 / 0.128).  Its shape fitted on the other 14 scans (clearness bin 2.8-4.5,
    # Delta 0.11 on every fold) beats both, but not the CIE general sky's.
    for model, expected in (("perez_erbs", (0.197, 0.161)), ("perez_scan", (0.170, 0.128)),
                            ("perez_fit_heldout", (0.155, 0.114))):
        assert (_day_mean(results, model, False), _day_mean(results, model, True)) \
            == pytest.approx(expected, abs=0.002)
    for rotated in (False, True):
        held = _day_mean(results, "perez_fit_heldout", rotated)
        assert held < _day_mean(results, "cie_clear_thesis", rotated) - 0.005
        assert held > _day_mean(results, "cie_groups_fit_heldout", rotated) + 0.02
        assert np.all(_errors(results, "perez_fit_heldout", rotated)
                      >= _errors(results, "perez_fit", rotated) - 1e-12)
        sub = results[(results["model"] == "perez_fit_heldout") & (results["rotated"] == rotated)]
        assert set(sub["parameter"]) == {"2.8 0.11"}
    # The rest of the gap is the circumsolar region: 15 deg about the sun left out instead
    # of 10, Perez from the scan's DHI beats the thesis's sky (0.148 against 0.157).
    models = {m.name: m for m in sm.MODELS}
    wide = {name: np.mean([sm.compare(s, models[name], exclude_deg=15.0)["relative_rms"]
                           for s in scans]) for name in ("perez_scan", "cie_clear_thesis")}
    assert wide["perez_scan"] < wide["cie_clear_thesis"] - 0.005


@needs_data
def test_the_turbid_skys_pattern_fitted_to_other_scans(results, scans):
    # Preetham's pattern with the turbidity fitted on the other 14 scans (2.2 on every fold)
    # misses the measured day by 0.159 / 0.134 (nominal / rotated): about the thesis's clear
    # sky and Mitsuba's Hosek-Wilkie sunsky (0.169 / 0.132, BENCHMARKS), far from the CIE
    # general sky's fitted groups.  The scans' own diffuse irradiance reads a Linke turbidity
    # of 2.7-2.9 through Ineichen and Perez's model: Preetham's scale runs below Linke's.
    for rotated, expected in ((False, 0.159), (True, 0.134)):
        held = _day_mean(results, "turbid_fit_heldout", rotated)
        assert held == pytest.approx(expected, abs=0.002)
        assert abs(held - _day_mean(results, "cie_clear_thesis", rotated)) < 0.01
        assert held > _day_mean(results, "cie_groups_fit_heldout", rotated) + 0.02
        sub = results[(results["model"] == "turbid_fit_heldout") & (results["rotated"] == rotated)]
        assert set(sub["parameter"].astype(float)) == {2.2}
    from scipy.optimize import brentq

    from skyfit_mi.physics.turbid_sky import levels
    linke = [brentq(lambda t: levels(t, s.sun_zenith_deg, s.day_of_year)[1] - s.dhi_scan, 2, 10)
             for s in scans]
    assert 2.6 < min(linke) and max(linke) < 3.0, linke


def test_perez_shape_is_the_pattern_of_its_indices():
    # The fitted Perez shape at an (epsilon, Delta) pair is perez_sky's pattern at the same
    # indices, up to its scale; a pair with b > 0 (epsilon 2.8-4.5, Delta 0.01, sun 21.5 deg
    # from the zenith: b = 0.2875 - 0.5328 Z + 0.01 (-3.85 + 3.375 Z) = 0.0614) is NaN.
    from types import SimpleNamespace

    from skyfit_mi.physics.perez import perez_sky

    z, az = 21.5, 150.0
    scan = SimpleNamespace(sun_zenith_deg=z,
                           sun_direction=direction_from_angles(np.radians(z), np.radians(az)))
    sky = perez_sky(z, az, 147, dhi=90.0, dni=960.0)
    d = direction_from_angles(np.radians([80.0, 60.0, 30.0, 5.0]),
                              np.radians([0.0, 100.0, 200.0, 300.0]))
    v = sm.perez_shape_luminance(d, scan, [(sky.info["epsilon"], sky.info["delta"]),
                                           (2.8, 0.01)])
    np.testing.assert_allclose(v[0] / sky.luminance(d), v[0][0] / sky.luminance(d)[0],
                               rtol=1e-12)
    assert np.all(np.isnan(v[1]))


def test_parameter_values_whose_model_is_not_positive_are_passed_over():
    class Scan:
        label = "noon"
        sun_direction = np.array([0.0, 0.0, 1.0])
        luminance = np.array([1.0, 2.0, 3.0])

        def directions(self, rotated=False):
            return direction_from_angles(np.radians([80.0, 60.0, 40.0]), 0.0)

    def luminance(d, scan, parameters):
        p = np.asarray(parameters, dtype=float)[:, None]
        return np.where(p > 0, np.array([[1.0, 2.0, 3.0]]) ** p, np.nan)

    # The exact pattern (p = 1) is beaten by nothing; p = 0 and NaN rows are no candidates.
    r = sm.compare(Scan(), sm.SkyModel("power", luminance, parameters=(-1.0, 1.0, 2.0)),
                   exclude_deg=0.0)
    assert r["parameter"] == 1.0 and r["relative_rms"] == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(SkyfitError, match="not positive at every compared point"):
        sm.compare(Scan(), sm.SkyModel("power", luminance, parameters=(-1.0,)), exclude_deg=0.0)


def test_held_out_choice_leaves_the_scored_scan_out():
    # Three "scans" whose best parameter differs: scan j must be scored at the parameter
    # best on the other two, not at its own.
    class Scan:
        def __init__(self, k):
            self.k = k
            self.sun_direction = np.array([0.0, 0.0, 1.0])
            self.luminance = np.array([1.0, 2.0, 3.0, 4.0]) ** k

        def directions(self, rotated=False):
            return direction_from_angles(np.radians([80.0, 70.0, 60.0, 50.0]), 0.0)

    def luminance(d, scan, parameters):
        return np.array([[1.0, 2.0, 3.0, 4.0]]) ** np.asarray(parameters, dtype=float)[:, None]

    model = sm.SkyModel("power_fit", luminance, parameters=(1.0, 2.0), held_out=True)
    scans = [Scan(1.0), Scan(2.0), Scan(2.0)]
    held = sm.compare_held_out(scans, model, exclude_deg=0.0)
    own = [sm.compare(s, model, exclude_deg=0.0) for s in scans]
    assert [r["parameter"] for r in own] == [1.0, 2.0, 2.0]
    assert [r["parameter"] for r in held] == [2.0, 2.0, 2.0]
    assert own[0]["relative_rms"] == pytest.approx(0.0, abs=1e-12)
    assert held[0]["relative_rms"] > 0.1
    with pytest.raises(SkyfitError, match="at least two scans"):
        sm.compare_held_out(scans[:1], model)


@needs_data
def test_irradiance_comparison(scans):
    rows = [sm.irradiance_comparison(s) for s in scans]
    ratio = np.array([r["cie_ghi_ratio"] for r in rows])
    assert 0.85 < ratio.min() and ratio.max() < 0.92      # the thesis's sun is too weak
    for s, r in zip(scans, rows):
        cos_z = np.cos(np.radians(s.ghi_sun_zenith_deg))
        # Erbs splits the measured GHI: DHI + DNI cos Z gives it back.
        assert r["perez_dhi"] + r["perez_dni"] * cos_z == pytest.approx(s.ghi, rel=1e-9)
        assert r["cie_ghi"] == pytest.approx(r["cie_sky_dhi"] + r["cie_sun_horizontal"])


@needs_data
def test_sunsky_frame_puts_the_sky_around_the_sun(scans):
    pytest.importorskip("mitsuba")
    from skyfit_testkit.sunsky_reference import sunsky_luminance

    s = scans[0]
    zen, az = np.radians(s.sun_zenith_deg), np.radians(s.sun_azimuth_deg)
    # Mirror pairs about the sun's vertical plane, and the opposite azimuth, at the sun's height.
    offsets = np.radians([30.0, -30.0, 180.0])
    v = sunsky_luminance(direction_from_angles(zen, az + offsets), s.sun_direction, [3.0])[0]
    assert v[0] == pytest.approx(v[1], rel=1e-4)
    assert v[0] > 1.5 * v[2]
    # Among the scan's points, at the per-scan fitted turbidity, the brightest is the nearest
    # to the sun.
    d = s.directions()
    v = sunsky_luminance(d, s.sun_direction, [5.25])[0]
    zeta = sm.angle_to_sun_deg(d, s.sun_direction)
    assert np.argmax(v) == np.argmin(zeta)
