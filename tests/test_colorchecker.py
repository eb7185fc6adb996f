"""`skyfit ingest --colorchecker`: a ColorChecker in the photographs found and used (issue 15).

A day of the example board with a ColorChecker Classic lying on it (24 Lambertian swatches of
the chart's reference reflectances on a black chart body, written by this test) is rendered
and photographed (8-bit JPEG, auto-exposure, vignetting, noise).  The chart is found in the
photographs by colour-checker-detection's segmentation and this project's grid fit; its
neutral swatches fit the response and the exposure, its chromatic ones check them.
"""

import json
import re

import numpy as np
import pytest

from skyfit_mi.errors import SkyfitError
from skyfit_mi.pipeline.spec import SCENES_DIR, validate_spec

pytest.importorskip("colour_checker_detection")
from skyfit_mi.pipeline import colorchecker as cc  # noqa: E402

QUIET = {"log": lambda *a: None}
PITCH, SWATCH = 0.1, 0.08            # swatch pitch and side on the chart [m]


def _chart_xml(cx, cy):
    """The chart lying on the board: a black body (ward material 'chart') and 24 swatches."""
    body = ('<bsdf type="ward" id="chart"><string name="model" value="raw"/>'
            '<rgb name="rho_d" value="0.03, 0.03, 0.03"/><rgb name="rho_s" value="0, 0, 0"/>'
            '<float name="sigma_alpha" value="0.1"/></bsdf>'
            '<shape type="rectangle" id="chart_body"><transform name="to_world">'
            f'<scale x="{3 * PITCH + 0.02}" y="{2 * PITCH + 0.02}" z="1"/>'
            f'<translate x="{cx}" y="{cy}" z="0.002"/></transform><ref id="chart"/></shape>')
    swatches = []
    for k, rgb in enumerate(np.clip(cc.reference_rgb(), 0.002, None)):
        r, c = divmod(k, cc.COLUMNS)
        x, y = cx + (c - 2.5) * PITCH, cy + (1.5 - r) * PITCH     # row 1 to the north
        value = ", ".join(f"{v:.5f}" for v in rgb)
        swatches.append(
            f'<bsdf type="diffuse" id="swatch_{k + 1:02d}"><rgb name="reflectance" '
            f'value="{value}"/></bsdf><shape type="rectangle" id="swatch_shape_{k + 1:02d}">'
            f'<transform name="to_world"><scale value="{SWATCH / 2}"/><translate x="{x}" '
            f'y="{y}" z="0.003"/></transform><ref id="swatch_{k + 1:02d}"/></shape>')
    return body + "\n".join(swatches)


def _spec(scene, width=240, height=180):
    return {"name": "chart", "location": {"latitude_deg": 52.0, "longitude_deg": 0.1,
                                          "timezone": "Europe/London"},
            "time": {"date": "2026-08-16", "start": "11:00", "end": "17:00",
                     "step_minutes": 60},
            "sky": {"type": "clear"}, "scene": {"file": str(scene)},
            "camera": {"azimuth_deg": 170.0, "angle_deg": 35.0, "distance": 3.3,
                       "fov_deg": 32.0, "width": width, "height": height},
            "render": {"spp": 32, "seed": 7}}


@pytest.fixture(scope="module")
def chart_day(tmp_path_factory):
    """The day rendered with the chart (the truth), and the ingest's spec: the same board and
    chart body without the swatches (a user models the chart's surface, not its print)."""
    from skyfit_mi.pipeline.sequence import render_sequence

    tmp = tmp_path_factory.mktemp("chart")
    xml = (SCENES_DIR / "photo_board.xml").read_text()
    xml = xml.replace('<scale x="0.6" y="0.4" z="1"/>', '<scale x="0.6" y="0.7" z="1"/>')
    truth_xml = xml.replace("</scene>", _chart_xml(0.0, -0.42) + "\n</scene>")
    (tmp / "truth.xml").write_text(truth_xml)
    bare = re.sub(r'<bsdf type="diffuse" id="swatch_\d+">.*?</shape>', "", truth_xml, flags=re.S)
    (tmp / "scene.xml").write_text(bare)
    render_sequence(validate_spec(_spec(tmp / "truth.xml"), tmp), tmp / "truth",
                    progress=False, **QUIET)
    spec = tmp / "spec.json"
    spec.write_text(json.dumps(_spec(tmp / "scene.xml")))
    return {"tmp": tmp, "truth": tmp / "truth", "spec": spec}


def _frames(day):
    from skyfit_mi.pipeline.manifest import load_manifest, read_frame_image
    doc, root = load_manifest(day)
    h, w = doc["camera"]["height"], doc["camera"]["width"]
    return [read_frame_image(root, f, "radiance", (h, w, 3)) for f in doc["frames"]]


def test_the_chart_is_found_and_every_sampled_pixel_lies_on_its_swatch(chart_day):
    from skyfit_mi.pipeline.pixels import scene_labels

    _, _, labels, ids = scene_labels(chart_day["truth"])
    frames = _frames(chart_day["truth"])
    found = cc.find_chart(frames, **QUIET)
    assert found["match"] < 0.15
    for k in range(24):
        sel = found["labels"] == k + 1
        assert sel.sum() >= 20, cc.NAMES[k]
        assert np.all(labels[sel] == ids.index(f"swatch_{k + 1:02d}") + 1), cc.NAMES[k]
    # A portrait frame (the camera turned a quarter) is turned back by the detection's
    # working image: the same swatches are found, turned with the frame.
    turned = cc.find_chart([np.rot90(f) for f in frames], **QUIET)
    np.testing.assert_array_equal(turned["labels"], np.rot90(found["labels"]))


def test_no_chart_is_refused(chart_day):
    from skyfit_mi.pipeline.pixels import scene_labels

    _, _, labels, ids = scene_labels(chart_day["truth"])
    frames = _frames(chart_day["truth"])
    chart = np.isin(labels, [i + 1 for i, n in enumerate(ids) if n.startswith("swatch")
                             or n == "chart"])
    board = np.median(frames[0][labels == ids.index("grey_card") + 1], axis=0)
    blank = [np.where(chart[..., None], board, f) for f in frames]
    with pytest.raises(SkyfitError, match="no ColorChecker was found"):
        cc.find_chart(blank, **QUIET)


@pytest.mark.parametrize("response, gamma", [("srgb", 2.2), ("gamma", 1.8)])
def test_ingest_calibrates_from_the_chart(chart_day, response, gamma):
    """The neutral swatches choose the response and set the exposures (sRGB within 1%; a
    fitted gamma within 0.05, its exposures within 3%: the gamma's error moves them); the
    calibrated chromatic swatches agree with their rendered reference within 3% rms."""
    from skyfit_mi.pipeline.ingest import ingest
    from skyfit_testkit.photo_sim import PhotoSettings, photograph_day

    tmp = chart_day["tmp"]
    photos = tmp / f"photos_{response}"
    photograph_day(chart_day["truth"], photos,
                   PhotoSettings(response=response, gamma=gamma, quality=100), seed=6)
    doc = ingest([photos], chart_day["spec"], tmp / f"seq_{response}", colorchecker="chart",
                 response="fit", vignetting="cos4", progress=False, **QUIET)
    cal = doc["ingest"]["calibration"]
    assert cal["response_fit"]["chosen"] == response
    if response == "gamma":
        assert abs(doc["sensor"]["gamma"] - gamma) < 0.05
    sim = json.loads((photos / "photos.json").read_text())
    got = np.array([f["exposure"]["exposure"] for f in doc["frames"]])
    want = np.array([f["exposure_sr_m2_W"] for f in sim["frames"]])
    np.testing.assert_allclose(got, want,
                               rtol=0.01 if response == "srgb" else 0.03)
    chart = cal["colorchecker"]
    assert chart["material"] == "chart" and len(chart["swatches_used"]) == 6
    assert chart["chromatic_check"]["rms"] < 0.03, chart["chromatic_check"]
    assert doc["ingest"]["options"]["colorchecker"] == "chart"


def test_bad_chart_options_are_refused_before_any_output(chart_day):
    from skyfit_mi.pipeline.ingest import ingest
    from skyfit_testkit.photo_sim import PhotoSettings, photograph_day

    tmp = chart_day["tmp"]
    photos = tmp / "photos_bad"
    photograph_day(chart_day["truth"], photos, PhotoSettings(quality=100), seed=1)
    for kw, message in (({"colorchecker": "no_such"}, "'no_such' is not a ward material"),
                        ({"colorchecker": "grey_card"}, "lie off material 'grey_card'"),
                        ({"colorchecker": "chart", "calibrate": {"chart": (0.2,) * 3}},
                         "named by both")):
        out = tmp / "refused"
        with pytest.raises(SkyfitError, match=message):
            ingest([photos], chart_day["spec"], out, progress=False, **QUIET, **kw)
        assert not out.exists()


def test_matrix_error_recovers_a_white_preserving_mixing():
    """Swatches read through (I + G), G's rows summing to 0: the chromatic swatches' ratios
    give G back exactly, with no residual; a grey is left alone by it."""
    rng = np.random.default_rng(1)
    G = rng.normal(0.0, 0.03, (3, 3))
    G -= np.diag(G.sum(axis=1))                            # rows sum to 0
    L = cc.reference_rgb() * [1.0, 0.9, 0.8]               # a slightly warm light
    ratio = (L @ (np.eye(3) + G).T) / L
    got = cc.matrix_error(ratio, L)
    np.testing.assert_allclose(got["mixing"], G, atol=1e-9)
    assert got["residual_rms"] < 1e-9
    np.testing.assert_allclose((np.eye(3) + G) @ np.ones(3), np.ones(3))
    assert cc.matrix_error(np.full((24, 3), np.nan), L) is None


def test_a_raws_colour_matrix_error_is_measured_on_the_chart_and_corrected(chart_day):
    """RAWs developed with a colour matrix off by 3% (photo_sim's matrix_error): the chart's
    chromatic swatches measure the channels' mixing (within 0.01 of the simulated one per
    entry), the frames are corrected by it, and the fits' matrix error is its standard error,
    not the 3% prior."""
    from skyfit_mi.pipeline.ingest import RAW_MATRIX_ERROR, ingest
    from skyfit_testkit.photo_sim import PhotoSettings, matrix_error_mix, photograph_day

    pytest.importorskip("rawpy")
    tmp = chart_day["tmp"]
    photos = tmp / "photos_dng"
    photograph_day(chart_day["truth"], photos, PhotoSettings(fmt="dng", matrix_error=0.03),
                   seed=6)
    doc = ingest([photos], chart_day["spec"], tmp / "seq_dng", colorchecker="chart",
                 vignetting="cos4", progress=False, **QUIET)
    measured = doc["ingest"]["calibration"]["colorchecker"]["colour_matrix"]
    want = matrix_error_mix(0.03, 6) - np.eye(3)
    np.testing.assert_allclose(measured["mixing"], want, atol=0.01)
    record = doc["ingest"]["colour_matrix"]
    assert record["source"].startswith("measured on the ColorChecker")
    assert record["relative_sd"] < RAW_MATRIX_ERROR / 2


def test_a_chart_whose_channels_are_mixed_still_matches_and_a_shuffled_one_does_not():
    """A camera whose colour matrix errs mixes its channels: the reference mixed by I plus 0.15
    off the diagonal (a white-preserving mixing, rows summing to 1) misses the per-channel
    match (above MATCH_MAX) but matches once mixed, to rounding; the swatches shuffled match
    neither way."""
    from skyfit_mi.pipeline.colorchecker import MATCH_MAX, _match, reference_rgb

    ref = reference_rgb()
    g = np.array([[0.0, 0.15, -0.15], [-0.15, 0.0, 0.15], [0.15, -0.15, 0.0]])
    sampled = ref @ (np.eye(3) + g).T * np.array([2.0, 1.5, 1.2])
    assert _match(sampled, ref) > MATCH_MAX
    assert _match(sampled, ref, mixing=True) < 1e-6
    shuffled = sampled[np.random.default_rng(0).permutation(len(sampled))]
    assert min(_match(shuffled, ref), _match(shuffled, ref, mixing=True)) > MATCH_MAX


def test_the_charts_greys_measure_a_cameras_own_tone_curve(chart_day):
    """A camera with its own tone curve (photo_sim.camera_tone), the chart's six greys at 3-90%:
    ingest reads the curve from their exposures' disagreement (physics.tone_curve.
    fit_references) and records it with its posterior; between the greys' levels the curve it
    gives lies within 2 sd of the truth and nearer it than sRGB's."""
    from skyfit_mi.physics import tone_curve as tc
    from skyfit_mi.pipeline.ingest import ingest
    from skyfit_testkit.photo_sim import PhotoSettings, camera_tone, photograph_day

    tmp = chart_day["tmp"]
    photos = tmp / "photos_curved"
    photograph_day(chart_day["truth"], photos, PhotoSettings(quality=100, tone_curve=0.6), seed=6)
    doc = ingest([photos], chart_day["spec"], tmp / "seq_curved", colorchecker="chart",
                 vignetting="cos4", progress=False, **QUIET)
    rec = doc["ingest"]["tone_curve"]
    assert rec["anchored_at"] == "references" and rec["weights"] is not None
    w, root = np.array(rec["weights"]), np.array(rec["root"])
    phi = np.array(next(iter(rec["anchor_basis"].values())))[1]           # green's anchor
    x = np.geomspace(1e-3, 1.0, 400)
    t = np.log(np.geomspace(0.03, 0.8, 20))                                # read signals
    d = t - np.interp(t, np.log(camera_tone(x, 0.6)), np.log(x))           # the true departure
    est = tc.moves_from(t, phi) @ w
    sd = np.sqrt(np.sum(np.square(tc.moves_from(t, phi, tc.PRIOR_ROOT @ root)), axis=-1))
    # the anchor's own departure is free (it sets the exposure): compare about their means
    err, ref = (est - est.mean()) - (d - d.mean()), d - d.mean()
    assert np.all(np.abs(err) <= 2.0 * sd + 0.02), np.c_[d, est, sd]
    assert np.sqrt(np.mean(err ** 2)) < 0.5 * np.sqrt(np.mean(ref ** 2))
    # the values are read through it (ingest's radiance frames; the fit's gains,
    # fitting.tone.curve_reading): the greys' radiance over the truth's is one exposure's, where
    # sRGB's curve read them tens of per cent apart
    from scipy.ndimage import binary_erosion

    from skyfit_mi.pipeline.pixels import scene_labels

    _, _, labels, ids = scene_labels(chart_day["truth"])
    read, true = _frames(tmp / "seq_curved"), _frames(chart_day["truth"])
    ratio = []
    for k in range(18, 24):                                        # the six greys
        sel = binary_erosion(labels == ids.index(f"swatch_{k + 1:02d}") + 1)
        ratio.append([np.median(np.log(r[sel, 1] / t[sel, 1])) for r, t in zip(read, true)])
    ratio = np.array(ratio)                                        # (6 greys, frames)
    # the five greys of 9-90% within 3% in every frame; the black's (3%, noisier) on average
    assert np.all(np.ptp(ratio[:5], axis=0) < 0.03), ratio
    assert abs(np.median(ratio[5] - ratio[:5].mean(axis=0))) < 0.03, ratio
    # the fit reads its values alike (chi2.load_observations: each value's gain through it)
    from skyfit_mi.fitting.chi2 import load_observations
    from skyfit_mi.pipeline.pixels import frame_values

    fitted = []
    for k in range(18, 23):
        ys, xs = np.nonzero(binary_erosion(labels == ids.index(f"swatch_{k + 1:02d}") + 1))
        obs = load_observations(tmp / "seq_curved", np.c_[xs, ys])
        truth = frame_values(chart_day["truth"], obs.pixels, obs.frames)
        fitted.append(np.median(np.log(obs.sensor.linearise(obs.y[..., 1])
                                       / obs.gain[..., 1] / truth[..., 1])))
    assert np.ptp(fitted) < 0.03, fitted
