"""A camera's own tone curve (skyfit_mi.physics.tone_curve) and its prior's script."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from skyfit_mi.errors import SkyfitError
from skyfit_mi.physics import tone_curve as tc
from skyfit_testkit.photo_sim import camera_tone

ROOT = Path(__file__).resolve().parents[1]


def test_the_error_is_nil_at_the_anchor_and_at_full_scale_and_grows_away_from_them():
    t = np.log(np.geomspace(np.exp(tc.T_MIN), 1.0, 40))
    assert np.allclose(tc.basis(0.0), 0.0)                      # the curves meet at full scale
    assert np.allclose(tc.moves(t, t), 0.0)                     # calibrated where it is read
    a = np.log(0.18)
    sd = tc.relative_sd(t, a)
    i = int(np.argmin(np.abs(t - a)))
    # a grey card's codes: nil there, rising on both sides (a white's and a dark's codes)
    assert sd[i] < 0.02 and sd[0] > 0.5 and sd[-1] > 0.3
    assert np.all(np.diff(sd[i:i + 6]) > 0) and np.all(np.diff(sd[i - 8:i + 1]) < 0)
    # darker than T_MIN takes T_MIN's
    assert np.allclose(tc.basis(tc.T_MIN - 3.0), tc.basis(tc.T_MIN))


def test_a_curve_none_of_the_measured_cameras_holds_lies_within_the_prior():
    """The test set's simulated camera (photo_sim.camera_tone, a bump in ln signal) is no
    measured camera's curve; its departure lies within 1.96 sd of the prior wherever read and
    wherever calibrated (measured: the largest |z| 1.3)."""
    x = np.geomspace(2e-3, 0.95, 60)
    y = camera_tone(x, 0.6)
    t, d = np.log(y), np.log(y / x)                             # d as a function of the value read
    for a in np.log([0.05, 0.18, 0.5]):
        da = np.interp(a, t, d)
        z = np.abs(d - da) / np.maximum(tc.relative_sd(t, a), 1e-9)
        assert z.max() < 1.96, (a, z.max())


def _fake_basecurve(path):
    """A basecurve.c of darktable's layout: measured cameras' presets (the simulated camera's
    curve at several strengths, one repeated as a twin) and two makers' generic ones."""
    def line(name, strength, maker='"X"'):
        x = np.r_[0.0, np.geomspace(0.002, 1.0, 14)]
        y = np.r_[0.0, camera_tone(x[1:], strength)]
        nodes = ", ".join(f"{{ {a:.6f}, {b:.6f} }}" for a, b in zip(x, y))
        return f'  {{ {name}, {maker}, "", 0, 51200, {{ {{ {{ {nodes} }} }}, {{ 15 }}, {{ m }} }}, 0, 1 }},'
    rows = ["static const basecurve_preset_t basecurve_camera_presets[] = {",
            "  // a comment line",
            *[line(f'"Cam {k}"', s) for k, s in enumerate((0.2, 0.4, 0.6, 0.8, 1.0, -0.3))],
            line('"Cam twin"', 0.6),
            "};",
            "static const basecurve_preset_t basecurve_presets[] = {",
            line('N_("cubic spline")', 0.0, '""'),
            line("neutral", 0.0, '""'),
            line("maker_a", 0.5, '"A"'), line("maker_b", 0.7, '"B"'),
            "};"]
    path.write_text("\n".join(rows) + "\n")


def test_the_prior_script_reads_darktable_s_presets_and_checks_its_prior(tmp_path):
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import tone_curve_prior as script
    finally:
        sys.path.pop(0)
    path = tmp_path / "basecurve.c"
    _fake_basecurve(path)
    presets = script.read_presets(path)
    assert len(presets["measured"]) == 6                          # the twin once
    assert set(presets["makers"]) == {"maker_a", "maker_b"}       # spline and neutral left out
    b, res = script.weights(presets["measured"])
    assert b.shape == (6, tc.DEGREE) and res.max() < 0.05        # the basis follows such curves
    r = script.root(b)
    np.testing.assert_allclose(r @ r.T, b.T @ b / len(b), atol=1e-12)
    share, _ = script.held(presets["makers"], r)
    assert share > 0.9
    done = subprocess.run([sys.executable, str(ROOT / "scripts" / "tone_curve_prior.py"),
                           str(path)], capture_output=True, text=True, check=True)
    assert "PRIOR_ROOT = np.array(" in done.stdout and "left out" in done.stdout


@pytest.mark.parametrize("strength", [0.3, 1.0])
def test_the_simulated_camera_s_curve_is_monotone_and_meets_full_scale(strength):
    x = np.geomspace(1e-4, 1.0, 200)
    y = camera_tone(x, strength)
    assert np.all(np.diff(y) > 0) and y[-1] == pytest.approx(1.0)
    assert camera_tone(x, 0.0) is x


def test_a_map_s_fits_take_the_curve_s_error_by_their_own_codes():
    """Per-pixel maps (fitting.tone.tone_level_rows): a group read at its frames' anchor moves
    by nothing, one 4x brighter by the prior's sd there, on every channel's C at once."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.tone import curve_reading, region_tone, tone_level_rows
    from skyfit_mi.fitting.uncertainty import rows_sd
    from skyfit_mi.physics.camera import SensorModel

    sensor = SensorModel(1.0, response="srgb", bits=8)
    anchor = 0.1
    code = sensor.respond(np.array([anchor, 4 * anchor])) * sensor.max_code
    y = np.empty((4, 3, 3))
    y[:2], y[2:] = code[0], code[1]                  # two pixels at the anchor, two 4x brighter
    obs = SimpleNamespace(rays=None, y=y, sigma=np.ones_like(y), sensor=sensor, frames=[0, 1, 2])
    phi = tc.basis(np.full(3, np.log(anchor))).tolist()
    doc = {"ingest": {"tone_curve": {"anchor_basis": {str(i): phi for i in range(3)}}}}
    names = ("C_r", "C_g", "C_b", "rho_s", "sigma_alpha")
    theta = np.tile([0.5, 0.4, 0.3, 0.02, 0.1], (2, 1))
    rows = tone_level_rows(doc, obs, np.array([0, 0, 1, 1]), 2, names, theta)
    sd = rows_sd(rows)
    t = np.log(sensor.linearise(code))
    want = float(tc.relative_sd(t[1], t[0]))
    np.testing.assert_allclose(sd[0], 0.0, atol=1e-9)
    np.testing.assert_allclose(sd[1, :3] / theta[1, :3], want, rtol=1e-6)
    assert sd[1, 4] == 0.0                            # a roughness does not move with a level
    # a region's values move by its median code in each frame (fitting.tone.region_tone); one
    # grey measures no curve, by which to read the values (curve_reading)
    move = region_tone(SimpleNamespace(doc=doc, obs=obs))
    assert move.shape == (4, 3, 3, tc.PRIOR_ROOT.shape[1])
    assert region_tone(SimpleNamespace(doc={"ingest": {}}, obs=obs)) is None
    assert curve_reading(doc, obs) is None
    # greys of several levels measured one: each value is read at its own code, relative to
    # its frame's anchor (a frame whose references read none takes the others' mean)
    w = np.array([1.5, -0.5, 0.3, 0.2, -0.4])
    rec = doc["ingest"]["tone_curve"]
    rec.update(weights=w.tolist(), root=(0.5 * np.eye(5)).tolist())
    rec["anchor_basis"]["2"] = [[None] * tc.DEGREE] * 3
    with pytest.raises(SkyfitError, match="ingest the photographs again"):
        curve_reading(doc, obs)                  # ingested before values were read through it
    rec["measured_ln_signal"] = [tc.T_MIN, 0.0]
    read, slope = curve_reading(doc, obs)
    np.testing.assert_allclose(read[:2], 0.0, atol=1e-12)
    np.testing.assert_allclose(read[2:], tc.moves(t[1], t[0]) @ w, rtol=1e-9)
    np.testing.assert_allclose(slope[2:], tc.basis_slope(t[1]) @ tc.PRIOR_ROOT @ w, rtol=1e-9)
    # within the measured levels, every value moves by the posterior at the region's median
    inside = region_tone(SimpleNamespace(doc=doc, obs=obs))
    t_median = np.log(sensor.linearise(code.mean()))
    np.testing.assert_allclose(inside, np.broadcast_to(0.5 * tc.moves(t_median, t[0]),
                                                       inside.shape), rtol=1e-9)
    # measured only about the anchor's level: the brighter values take the curve's value at
    # the highest measured level, no slope, and the prior's error at their own codes, not the
    # posterior's at the region's (whose median lies within)
    rec["measured_ln_signal"] = [t[0] - 0.1, t[0] + 0.1]
    read, slope = curve_reading(doc, obs)
    np.testing.assert_allclose(read[2:], tc.moves(t[0] + 0.1, t[0]) @ w, rtol=1e-9)
    assert not slope[2:].any()
    y3 = y.copy()
    y3[2] = code[0]                          # three pixels at the anchor's code, the median's
    obs3 = SimpleNamespace(**{**vars(obs), "y": y3})
    move = region_tone(SimpleNamespace(doc=doc, obs=obs3))
    np.testing.assert_allclose(move[:3], 0.0, atol=1e-12)
    np.testing.assert_allclose(move[3], np.broadcast_to(tc.moves(t[1], t[0]), move[3].shape),
                               rtol=1e-9)


def test_a_measured_curves_reading_and_its_slope():
    """physics.tone_curve.reading: the factor is (phi(t) - phi(anchor)) PRIOR_ROOT w within the
    measured levels and held at their ends beyond; its slope is the factor's derivative in t
    there (by which a value's noise moves its own reading) and 0 beyond."""
    w = np.array([1.5, -0.5, 0.3, 0.2, -0.4])
    anchor = tc.basis(np.log(0.18))
    t = np.linspace(-4.5, -0.3, 9)
    span = (-4.0, -0.5)
    factor, slope = tc.reading(t, anchor, w, span)
    np.testing.assert_allclose(factor, tc.moves_from(np.clip(t, *span), anchor) @ w, rtol=1e-12)
    h = 1e-6
    numeric = (tc.reading(t + h, anchor, w, (-9, 0))[0] - tc.reading(t, anchor, w, (-9, 0))[0]) / h
    inside = (t >= span[0]) & (t <= span[1])
    np.testing.assert_allclose(slope[inside], numeric[inside], rtol=1e-4)
    assert not slope[~inside].any()


def test_greys_at_several_levels_measure_the_curve_and_one_grey_measures_none():
    """physics.tone_curve.fit_references: six greys (a ColorChecker's 3-90%) photographed
    through the simulated camera's curve over 13 frames of changing exposure, read at 1%:
    the curve they give between 3% and 90% lies within 2 sd of its posterior and nearer the
    truth than the prior's 0; one grey leaves the prior (weights 0, root I)."""
    rng = np.random.default_rng(7)
    rho = np.array([0.031, 0.09, 0.19, 0.36, 0.59, 0.9])
    exposure = np.exp(rng.uniform(np.log(0.4), np.log(0.9), size=(13, 1)))
    x = exposure * rho                                    # the true linear signal
    y = camera_tone(x, 0.6)                               # read through sRGB's curve
    ratio = np.log(y / rho) + rng.normal(0.0, 0.01, y.shape)
    weights, root, anchors, chi2 = tc.fit_references(np.log(y), ratio, np.full(y.shape, 0.01))
    assert 0.3 < chi2 < 3.0 and anchors.shape == (13, tc.DEGREE)
    cov = root @ root.T
    assert np.all(np.linalg.eigvalsh(cov) <= 1.0 + 1e-9)   # the data only narrow the prior
    grid = np.log(np.geomspace(0.03, 0.9, 25))
    a = np.log(0.2)
    truth = np.log(camera_tone(np.exp(grid), 0.6) / np.exp(grid))
    x_grid = np.interp(grid, np.log(camera_tone(np.geomspace(1e-3, 1, 400), 0.6)),
                       np.log(np.geomspace(1e-3, 1, 400)))
    truth = (grid - x_grid) - np.interp(a, grid, grid - x_grid)   # d(ln y) - d(a)
    est = tc.moves(grid, a) @ weights
    sd = tc.relative_sd(grid, a, tc.PRIOR_ROOT @ root)
    assert np.all(np.abs(est - truth) <= 2.0 * sd + 1e-3), np.c_[truth, est, sd]
    assert np.sqrt(np.mean((est - truth) ** 2)) < 0.5 * np.sqrt(np.mean(truth ** 2))
    w1, r1, a1, _ = tc.fit_references(np.log(y[:, 2:3]), ratio[:, 2:3], np.full((13, 1), 0.01))
    np.testing.assert_allclose(w1, 0.0)
    np.testing.assert_allclose(r1 @ r1.T, np.eye(len(w1)), atol=1e-12)
    np.testing.assert_allclose(a1, tc.basis(np.log(y[:, 2])))
