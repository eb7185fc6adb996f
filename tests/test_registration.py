"""Frames registered and the lens undone in `skyfit ingest` (issue 51: parts 4 and the lens).

A small rendered day (tests/test_ingest.py's: 64 x 44 px, hourly, 7 frames) is photographed by
:mod:`skyfit_testkit.photo_sim` (8-bit sRGB PNG, auto-exposure, cos^4, read and shot
noise) with the camera nudged between frames: known shifts of the image's centre from 0.5 to
2 px, one frame also turned by 0.3 degrees, the middle frame (the reference) still.  What is
measured is each frame's (dx, dy) at the image's centre and its rotation against the
reference, :mod:`skyfit_mi.pipeline.registration`'s convention, the same as the simulator's.
"""


import numpy as np
import pytest

from skyfit_mi.errors import SkyfitError
from skyfit_mi.pipeline.spec import read_spec, validate_spec

from test_ingest import QUIET, TRUTH, _small_spec, _toml

#: Each frame's motion (dx [px], dy [px], rotation [degrees]); frame 3 (14:00) is the middle.
MOTION = {0: (0.4, -0.3, 0.0), 1: (1.5, 0.8, 0.0), 2: (-1.6, 1.1, 0.0), 4: (0.7, 1.8, 0.3),
          5: (-0.25, -1.2, 0.0), 6: (1.0, -1.5, 0.0)}
GREY = {"grey_card": (0.18, 0.18, 0.18)}


@pytest.fixture(scope="module")
def shaken(tmp_path_factory):
    """The truth rendered, its photographs shaken (MOTION), ingested with and without
    registration."""
    from skyfit_mi.pipeline.ingest import ingest
    from skyfit_testkit.photo_sim import PhotoSettings, photograph_day
    from skyfit_mi.pipeline.sequence import render_sequence

    tmp = tmp_path_factory.mktemp("register")
    spec, raw = _small_spec(tmp)
    render_sequence(validate_spec(raw, spec.parent), tmp / "truth", progress=False, **QUIET)
    photos = tmp / "photos"
    photograph_day(tmp / "truth", photos, PhotoSettings(fmt="png", motion=MOTION), seed=5)
    logs = []
    docs = {on: ingest([photos], spec, tmp / f"seq_{on}", progress=False, calibrate=GREY,
                       vignetting="cos4", register=on, log=logs.append)
            for on in (True, False)}
    return {"tmp": tmp, "spec": spec, "photos": photos, "docs": docs, "logs": logs}


def test_the_measured_motion_is_the_cameras(shaken):
    """Shifts within 0.06 px of the truth (measured: 0.044 px at most), rotations within
    0.1 degrees (0.3 applied; measured error 0.067 at most, 0.05 px at the image's corner); the
    stated sd honest (each shift's error within 2.5 sd, measured 1.7) and not empty; the
    reference frame still; the regions eroded by the resampling's reach and 3 sd."""
    doc = shaken["docs"][True]
    reg = doc["ingest"]["registration"]
    assert reg["registered"] and reg["reference"] == "IMG_0003.png" and reg["erode_px"] == 2
    for f in doc["frames"]:
        got = f["registration"]
        want = MOTION.get(f["index"], (0.0, 0.0, 0.0))
        assert got["dx_px"] == pytest.approx(want[0], abs=0.06), f["index"]
        assert got["dy_px"] == pytest.approx(want[1], abs=0.06), f["index"]
        assert got["rotation_deg"] == pytest.approx(want[2], abs=0.1), f["index"]
        if not got.get("reference"):
            err = np.abs([got["dx_px"] - want[0], got["dy_px"] - want[1]])
            assert np.all(err <= 2.5 * got["sd_px"]) and 0.01 < got["sd_px"] < 0.05, got
    assert any("registration on IMG_0003.png" in m for m in shaken["logs"])
    off = shaken["docs"][False]["ingest"]["registration"]
    assert not off["registered"] and off["erode_px"] == 0
    assert all("registration" not in f for f in shaken["docs"][False]["frames"])


def test_a_still_day_is_neither_resampled_nor_eroded(shaken):
    """The same day photographed without motion: each frame's apparent motion (ECC finds a
    few hundredths of a pixel) is below STILL_PX, so no frame is resampled, the values are the
    photographs' own and no region is eroded."""
    from skyfit_mi.pipeline.ingest import ingest
    from skyfit_testkit.photo_sim import PhotoSettings, photograph_day
    from skyfit_mi.pipeline.registration import STILL_PX

    tmp = shaken["tmp"]
    photograph_day(tmp / "truth", tmp / "still", PhotoSettings(fmt="png"), seed=5)
    doc = ingest([tmp / "still"], shaken["spec"], tmp / "seq_still", progress=False,
                 calibrate=GREY, vignetting="cos4", log=lambda *a: None)
    moves = [f["registration"] for f in doc["frames"] if "registration" in f
             and not f["registration"].get("reference")]
    assert moves and all(not r["resampled"] for r in moves), moves
    assert all(np.hypot(r["dx_px"], r["dy_px"]) < STILL_PX for r in moves)
    assert doc["ingest"]["registration"]["erode_px"] == 0


def test_pixels_off_the_photograph_are_masked(shaken):
    """A shifted frame's pixels that fall off the photograph are NaN with infinite sigma,
    counted, and left out of a fit's observations."""
    from skyfit_mi.fitting.chi2 import load_observations
    from skyfit_mi.pipeline.manifest import load_manifest, read_frame_image

    doc, root = load_manifest(shaken["tmp"] / "seq_True")
    f = doc["frames"][2]                       # dx -1.6: the reference's left edge is off it
    values = read_frame_image(root, f, "sensor", (44, 64, 3))
    sigma = read_frame_image(root, f, "sigma", (44, 64, 3))
    lost = ~np.isfinite(values).all(axis=-1)
    assert lost.sum() == f["registration"]["off_photo_pixels"] > 0
    assert lost[:, 0].all() and np.isinf(sigma[lost]).all()
    obs = load_observations(root, np.array([[0, 20], [30, 20]]), one_fit=False)
    assert any("non-finite" in w or "left out" in w for w in obs.warnings)


def _fit(seq, regions, name="sample"):
    from skyfit_mi.fitting.chi2 import subsample_region
    from skyfit_mi.fitting.fit import fit_region
    from skyfit_mi.fitting.light import LightOptions

    pixels = subsample_region(dict(regions)[name], 64, 0)
    return fit_region(seq, name, pixels, model="colour", method="lm",
                      light=LightOptions(sky="spec"), **QUIET)


def test_a_fit_after_registration_recovers_the_material_and_without_it_does_not(shaken):
    """After registration a fit of the sample holds the truth as the still day's does
    (tests/test_ingest.py: within 1.5 half-widths of its 95% intervals' centres).  The same
    photographs taken as aligned put pixels of the board into the sample's edge: on the
    sample's pixels away from its edge by 1 px (the region without registration) the data
    disagree with the truth's render far beyond their noise, and the fit's chi^2 with them."""
    from skyfit_mi.pipeline.manifest import load_manifest, read_frame_pixels
    from skyfit_mi.pipeline.pixels import material_regions

    tmp = shaken["tmp"]
    regions = material_regions(tmp / "seq_True")             # eroded by erode_px
    fit = _fit(tmp / "seq_True", regions)
    for k, t in TRUTH.items():
        lo, hi = fit["intervals"][k]["95"]
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        assert abs(t - mid) <= 1.5 * half, f"{k}: truth {t} far outside the fit's [{lo}, {hi}]"

    # each pixel of the sample against the truth's rendered radiance, in its own sigmas
    pixels = dict(material_regions(tmp / "truth"))["sample"]
    z = {}
    for on in (True, False):
        doc, root = load_manifest(tmp / f"seq_{on}")
        truth_doc, truth_root = load_manifest(tmp / "truth")
        d = []
        for f, g in zip(doc["frames"], truth_doc["frames"]):
            got = read_frame_pixels(root, f, "radiance", (44, 64, 3), pixels)
            sd = read_frame_pixels(root, f, "radiance_sigma", (44, 64, 3), pixels)
            true = read_frame_pixels(truth_root, g, "radiance", (44, 64, 3), pixels)
            d.append((got - true) / sd)
        z[on] = float(np.sqrt(np.nanmean(np.square(d))))
    unreg = _fit(tmp / "seq_False", material_regions(tmp / "truth"))
    assert z[True] < 1.5 and z[False] > 5, z                     # measured 0.86 and 9.7
    # measured chi^2 per degree of freedom 38 against 0.47
    assert unreg["chi2_per_dof"] > 10 * fit["chi2_per_dof"], (unreg["chi2_per_dof"],
                                                              fit["chi2_per_dof"])


def test_a_frame_that_moved_beyond_the_limit_is_refused(shaken, tmp_path):
    """A frame displaced beyond --register-limit gets one line naming it, exit 2, and
    nothing is written."""
    from skyfit_mi.cli import main
    from skyfit_mi.pipeline.ingest import ingest

    out = tmp_path / "o"
    with pytest.raises(SkyfitError, match=r"IMG_0001.png: it moved 1.7 px from IMG_0003.png "
                                          r"\(at most 1 px, --register-limit\)"):
        ingest([shaken["photos"]], shaken["spec"], out, progress=False, calibrate=GREY,
               register_limit_px=1.0, **QUIET)
    assert not out.exists()
    assert main(["ingest", str(shaken["spec"]), str(shaken["photos"]), "-o", str(out), "-q",
                 "--calibrate", "grey_card=0.18", "--register-limit", "0"]) == 2
    assert not out.exists()


def test_a_distorted_photograph_is_undone_onto_the_pinhole(shaken, tmp_path):
    """A frame bent by a barrel lens (k1 = -0.1 at a 90-degree field of view: the scene moves
    by up to 5 px; the simulator's inverse, bicubic) is brought back onto the pinhole by the
    registration's map: its rms relative error over the frame 0.086, the two resamplings'
    blur of a 64-px frame's edges, against the bent frame's 0.40.  Ingested with the spec's [camera] distortion = [-0.1] (at its
    30 degrees the barrel moves the corners 0.3 px), the frames agree with the render within
    their noise and record what was undone; pixels off the photograph are NaN."""
    from skyfit_mi.pipeline.ingest import ingest
    from skyfit_mi.pipeline.manifest import load_manifest, read_frame_image
    from skyfit_testkit.photo_sim import PhotoSettings, _lens, photograph_day
    from skyfit_mi.pipeline.pixels import scene_labels
    from skyfit_mi.pipeline.region_edges import colour_mixed
    from skyfit_mi.pipeline.registration import pixel_map, remap

    truth_doc, truth_root = load_manifest(shaken["tmp"] / "truth")
    true = read_frame_image(truth_root, truth_doc["frames"][3], "radiance", (44, 64, 3))
    labels = scene_labels(shaken["tmp"] / "truth")[2]
    inside = (labels > 0) & ~colour_mixed(labels, 2)
    wide = {"width": 64, "height": 44, "fov_deg": 90.0, "distortion": [-0.1, 0.0]}
    bent = _lens(true, None, (-0.1,), 90.0)
    back = remap(bent, pixel_map(np.eye(3)[:2], wide))
    err, was = (float(np.sqrt(np.nanmean(np.square(x / true - 1)))) for x in (back, bent))
    assert err < 0.12 and was > 4 * err                      # measured 0.086 and 0.40

    raw = read_spec(shaken["spec"])
    raw["camera"]["distortion"] = [-0.1]
    spec = tmp_path / "spec.toml"
    spec.write_text(_toml(raw))
    photos = tmp_path / "photos"
    photograph_day(shaken["tmp"] / "truth", photos, PhotoSettings(fmt="png", distortion=(-0.1,)),
                   seed=5)
    doc = ingest([photos], spec, tmp_path / "seq", progress=False, calibrate=GREY,
                 vignetting="cos4", register=False, **QUIET)
    reg = doc["ingest"]["registration"]
    assert reg["distortion_undone"] == [-0.1, 0.0] and reg["erode_px"] == 1
    got_doc, root = load_manifest(tmp_path / "seq")
    z = []
    for f, g in zip(got_doc["frames"], truth_doc["frames"]):
        got = read_frame_image(root, f, "radiance", (44, 64, 3))[inside]
        sd = read_frame_image(root, f, "radiance_sigma", (44, 64, 3))[inside]
        z.append((got - read_frame_image(truth_root, g, "radiance", (44, 64, 3))[inside]) / sd)
    assert np.sqrt(np.nanmean(np.square(z))) < 1.5


def test_a_frames_record_gives_back_its_measured_motion():
    """The manifest's record of a motion (its centre's displacement and rotation) gives back the
    motion measured, the map the frame was resampled by."""
    from skyfit_mi.pipeline.registration import motion_of_record

    t = np.radians(0.3)
    M = np.array([[np.cos(t), -np.sin(t), 1.2], [np.sin(t), np.cos(t), -0.7]])
    c = np.array([(64 - 1) / 2.0, (44 - 1) / 2.0])
    d = M[:, :2] @ c + M[:, 2] - c                 # as register_frames records it
    rec = {"dx_px": d[0], "dy_px": d[1], "rotation_deg": 0.3}
    np.testing.assert_allclose(motion_of_record(rec, 64, 44), M, atol=1e-12)


def test_the_frames_are_registered_on_the_photograph_the_pose_was_marked_on(shaken, tmp_path):
    """The spec's [camera] photo (skyfit camera --photo writes it) is the reference: every frame
    is brought onto the view the pose describes, its motion measured against that frame's;
    a photo not among the frames is said, and the middle frame taken."""
    from skyfit_mi.pipeline.ingest import ingest

    raw = read_spec(shaken["spec"])
    for name, tag in (("IMG_0001.png", "on"), ("IMG_9999.png", "off")):
        raw["camera"]["photo"] = name
        spec = tmp_path / f"spec_{tag}.toml"
        spec.write_text(_toml(raw))
        logs = []
        doc = ingest([shaken["photos"]], spec, tmp_path / tag, progress=False, calibrate=GREY,
                     vignetting="cos4", log=logs.append)
        reg = doc["ingest"]["registration"]
        if tag == "off":
            assert reg["reference"] == "IMG_0003.png"
            assert any("marked on IMG_9999.png, which is not among" in m for m in logs), logs
            continue
        assert reg["reference"] == "IMG_0001.png"
        base = np.array(MOTION[1][:2])
        for f in doc["frames"]:                   # small motions: shifts nearly add
            want = np.array(MOTION.get(f["index"], (0.0, 0.0, 0.0))[:2]) - base
            got = np.array([f["registration"]["dx_px"], f["registration"]["dy_px"]])
            assert np.all(np.abs(got - want) < 0.15), (f["index"], got, want)
