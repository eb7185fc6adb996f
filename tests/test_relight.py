"""Relighting: a target rendered with fitted materials, and the prediction error against the
target's frames."""
import copy
import csv
import json

import numpy as np
import pytest

from skyfit_mi.cli import main

from test_sequence import TINY

PIXELS = [[x, y] for x in range(6, 10) for y in range(6, 10)]


def _fit_json(path, region="disc", model="two", **parameters):
    """A fit result as `skyfit fit` writes it (the keys relight reads)."""
    parameters = parameters or {"rho_s": 0.0, "sigma_alpha": 0.0}
    path.write_text(json.dumps({
        "region": region, "model": model, "normalisation": "ward", "parameters": parameters,
        "intervals": {k: {"95": [v, v]} for k, v in parameters.items()}, "pixels": PIXELS}))
    return path


@pytest.fixture(scope="module")
def day(tmp_path_factory, mi):
    tmp = tmp_path_factory.mktemp("relight")
    (tmp / "day.json").write_text(json.dumps(TINY))
    assert main(["render", str(tmp / "day.json"), "-o", str(tmp / "day"), "-q"]) == 0
    return tmp


def test_relit_with_the_true_material_reproduces_the_target(day, tmp_path):
    """The target's own material as a fit: the relit day is the target's render (same spec and
    seeds), so the prediction error is zero; the manifest says the material came from the fit."""
    fit = _fit_json(tmp_path / "fit_disc.json")
    out = tmp_path / "relit"
    assert main(["relight", str(fit), "--target", str(day / "day"), "-o", str(out), "-q",
                 "--reference"]) == 0
    errors = json.loads((out / "relight.json").read_text())
    # a fit JSON without its sequence's run id: compared over the disc's interior (64 of it)
    assert errors["rel_rms"] < 1e-6 and errors["regions"]["disc"]["pixels"] == 64
    # relit with the target's seeds (common random numbers): no noise floor applies; the
    # reference render (other seeds) measures independent Monte Carlo noise (64 spp: ~1-10%),
    # which the noise floor from the two days' radiance_sigma images estimates (256 values:
    # within 25%)
    assert errors["shares_target_seeds"] and "noise_floor_rel_rms" not in errors
    from skyfit_mi.fitting.relight import noise_floor, target_pixels
    from skyfit_mi.pipeline.fit_result import load_fits
    pixels = target_pixels(load_fits([fit]), day / "day")         # as relight chose them
    estimated = noise_floor(day / "day", out / "reference", pixels, errors["frames"])["all"]
    measured = errors["reference_rel_rms"]
    assert 0.002 < measured < 0.2 and estimated == pytest.approx(measured, rel=0.25)
    assert (out / "reference" / "manifest.json").exists()
    # the region means predicted at the truth (the target's own material): noise alone
    assert errors["region_means"]["disc"]["truth"] < 0.02
    assert len(errors["regions"]["disc"]["per_frame"]) == len(TINY["time"]["times"])
    m = json.loads((out / "manifest.json").read_text())
    assert m["source"] == "relight"
    assert m["scene"]["materials"]["disc"]["source"] == "fit fit_disc.json (region disc)"
    rows = (out / "relight.csv").read_text().splitlines()
    assert rows[0] == "region,frame,time,rel_rms_error,held_out"
    assert rows[-1].startswith("all,all,,")
    # the fast path: the fit's cached model of the target's light predicts the observed region
    # means (a fit with zero-width intervals: a band of the model's own noise only)
    pred = list(csv.reader((out / "prediction.csv").read_text().splitlines()))
    assert pred[0][:4] == ["region", "frame", "time", "channel"] and len(pred) == 1 + 4 * 3
    for row in pred[1:]:
        assert float(row[4]) == pytest.approx(float(row[7]), rel=0.01)
    assert (out / "prediction.png").stat().st_size > 0
    assert errors["comparison_images"] == [f"compare_{i:04d}.png" for i in range(4)]
    assert all((out / n).stat().st_size > 0 for n in errors["comparison_images"])


def test_a_folder_target_keeps_the_sun_its_render_computed(day, tmp_path, monkeypatch):
    """The target folder's spec is validated with the sun positions its manifest recorded
    (SPA is not run again): the same frames as computing them."""
    from skyfit_mi.fitting.relight import target_spec
    from skyfit_mi.pipeline.fit_result import load_fits
    from skyfit_mi.pipeline import spec as spec_module

    fits = load_fits([_fit_json(tmp_path / "fit_disc.json")])
    computed, _ = target_spec(day / "day.json", fits)

    def no_spa(*args, **kwargs):
        raise AssertionError("the sun was computed again")
    monkeypatch.setattr(spec_module, "solar_position", no_spa)
    recorded, _ = target_spec(day / "day", fits)
    assert len(recorded.frames) == len(computed.frames)
    for a, b in zip(recorded.frames, computed.frames):
        assert (a.time, a.sun_zenith_deg, a.sun_azimuth_deg) == \
            (b.time, b.sun_zenith_deg, b.sun_azimuth_deg)
        assert np.array_equal(a.sky.sun_direction, b.sky.sun_direction)


def test_a_per_pixel_map_given_as_fits_is_named_as_such(tmp_path):
    """A per-pixel map's folder (`fit --per-pixel`: its summary, no fit_NAME.json) given to
    relight: the message says it is a map and what to give instead, not that the folder has no
    fits."""

    from skyfit_mi.errors import SkyfitError
    from skyfit_mi.pipeline.fit_result import MAP_SUMMARY, load_fits

    (tmp_path / MAP_SUMMARY).write_text("{}")
    with pytest.raises(SkyfitError, match="per-pixel map .*skyfit fit SEQUENCE --all"):
        load_fits([tmp_path])
    (tmp_path / MAP_SUMMARY).unlink()
    with pytest.raises(SkyfitError, match="no fit_"):
        load_fits([tmp_path])


def test_a_wrong_material_shows_as_prediction_error(day, tmp_path):
    """Half the target's reflectance (R = 0.5 Lambertian where the target is white): the relit
    radiance is half the observed in every frame (the same seeds trace the same paths), so
    the error is 50% per frame and overall; a fit folder is a valid input."""
    fit = _fit_json(tmp_path / "fit_disc.json", model="achromatic", R=0.5, rho_s=0.0,
                    sigma_alpha=0.0)
    out = tmp_path / "relit"
    assert main(["relight", str(tmp_path), "--target", str(day / "day"), "-o", str(out),
                 "-q"]) == 0
    errors = json.loads((out / "relight.json").read_text())
    assert errors["regions"]["disc"]["fit"] == str(fit)
    assert errors["rel_rms"] == pytest.approx(0.5, rel=1e-3)
    assert errors["regions"]["disc"]["per_frame"] == pytest.approx([0.5] * 4, rel=1e-3)


def test_relight_onto_a_new_day_has_no_observations(day, tmp_path):
    fit = _fit_json(tmp_path / "fit_disc.json", rho_s=0.3, sigma_alpha=0.1)
    raw = copy.deepcopy(TINY)
    raw["time"] = {"date": "2026-12-21", "times": ["12:00"]}
    del raw["materials"]
    (tmp_path / "winter.json").write_text(json.dumps(raw))
    out = tmp_path / "winter"
    assert main(["relight", str(fit), "--target", str(tmp_path / "winter.json"), "-o", str(out),
                 "-q"]) == 0
    m = json.loads((out / "manifest.json").read_text())
    assert m["status"] == "complete" and len(m["frames"]) == 1
    assert m["scene"]["materials"]["disc"]["raw"]["rho_s"] == pytest.approx([0.3] * 3)
    assert not (out / "relight.json").exists()


@pytest.mark.parametrize("case, phrase", [
    ("missing", "does not exist"),
    ("not a fit", "is not a fit result"),
    ("other region", "'plate' is not a ward material of disc.xml"),
    ("twice", "is fitted twice"),
    ("into the target", "the output folder is the target's"),
    ("another model", "is not a fit result of `skyfit fit`"),
    ("bad interval", "is not a fit result of `skyfit fit`"),
    ("no sun", "the target's sun is below the horizon in every frame (frame 0 at 01:00, frame 1 at "
                "23:00)"),
    ("no region in the target", "does not see region 'disc'"),
    ("nothing rendered", "made at the target's rendered frames, and"),
    ("damaged in a folder", "fit_other.json is not readable JSON"),
    ("a target frame missing", "frame 2: cannot read"),
    ("a target light damaged", "frame 1: sky illumination: sun_radiance"),
    ("frames the target lacks", "lists frame 9, which"),
])
def test_bad_relight_inputs_get_one_line(day, tmp_path, capsys, case, phrase):
    fit = _fit_json(tmp_path / "fit_disc.json")
    args = [str(fit)]
    out = tmp_path / "out"
    if case == "missing":
        args = [str(tmp_path / "fit_nothing.json")]
    elif case == "not a fit":
        (tmp_path / "fit_x.json").write_text('{"a": 1}')
        args = [str(tmp_path / "fit_x.json")]
    elif case == "other region":
        args = [str(_fit_json(tmp_path / "fit_plate.json", region="plate"))]
    elif case == "twice":
        args = [str(fit), str(tmp_path)]
    elif case == "damaged in a folder":
        (tmp_path / "fit_other.json").write_text(fit.read_text()[:50])
        args = [str(tmp_path)]
    elif case == "into the target":
        out = day / "day"
    elif case == "another model":
        _fit_json(fit, model="seven", rho_s=0.1, sigma_alpha=0.1)
    elif case == "bad interval":
        r = json.loads(fit.read_text())
        r["intervals"]["rho_s"]["95"] = [0.0, None]
        fit.write_text(json.dumps(r))
    target = day / "day"
    more = []
    if case == "nothing rendered":                   # a folder whose frames are all pending
        doc = json.loads((target / "manifest.json").read_text())
        doc.update(status="incomplete", frames=[{"index": f["index"], "status": "pending"}
                                                for f in doc["frames"]])
        target = tmp_path / "pending"
        target.mkdir()
        (target / "manifest.json").write_text(json.dumps(doc))
        more = ["--no-images"]
    elif case in ("a target frame missing", "a target light damaged"):
        import shutil

        target = tmp_path / "damaged"
        shutil.copytree(day / "day", target)
        if case == "a target frame missing":
            (target / "frames" / "radiance_002.exr").unlink()
        else:
            doc = json.loads((target / "manifest.json").read_text())
            doc["frames"][1]["illumination"]["sun_radiance"] = [-1.0, 0.0, 0.0]
            (target / "manifest.json").write_text(json.dumps(doc))
    elif case == "frames the target lacks":
        r = json.loads(fit.read_text())
        r.update(frames=[0, 9], sequence_run_id=json.loads(
            (target / "manifest.json").read_text())["run_id"])
        fit.write_text(json.dumps(r))
    if case in ("no sun", "no region in the target"):
        raw = copy.deepcopy(TINY)
        if case == "no sun":
            raw["time"]["times"] = ["01:00", "23:00"]
        else:                                   # the camera looks away from the disc
            raw["camera"] = {"origin": [0.0, 0.0, 3.0], "target": [10.0, 0.0, 3.0],
                             "fov_deg": 8.0, "width": 16, "height": 16}
        target = tmp_path / "target.json"
        target.write_text(json.dumps(raw))
        if case == "no region in the target":
            assert main(["render", str(target), "-o", str(tmp_path / "away"), "-q"]) == 0
            target = tmp_path / "away"
    assert main(["relight", *args, "--target", str(target), "-o", str(out), "-q", *more]) == 2
    err = capsys.readouterr().err.strip()
    assert phrase in err and len(err.splitlines()) == 1, err
    assert case == "into the target" or not out.exists()          # nothing written


def test_predictions_without_images_have_bands_as_wide_as_the_fits_intervals(day, tmp_path):
    """--no-images renders nothing and writes numbers alone (no plot); a fit whose roughness
    is unknown (interval 0-0.5) gets a band that holds the observed values, and a zero-width
    fit of the wrong reflectance gets a narrow band that misses them.  Values beyond the
    radiance the fit's data measured (here: its blue nowhere, its green below 1e6) are marked
    in prediction.csv and counted apart in relight.json."""
    params = {"rho_s": 0.0, "sigma_alpha": 0.0}
    fit = tmp_path / "fit_disc.json"
    fit.write_text(json.dumps({
        "region": "disc", "model": "two", "normalisation": "ward", "parameters": params,
        "intervals": {"rho_s": {"95": [0.0, 0.3]}, "sigma_alpha": {"95": [0.0, 0.5]}},
        "pixels": PIXELS,
        "measured_range": {"by_channel": {"R": [0.0, 1e9], "G": [1e6, 1e9], "B": None}}}))
    out = tmp_path / "pred"
    assert main(["relight", str(fit), "--target", str(day / "day"), "-o", str(out), "-q",
                 "--no-images", "--draws", "50"]) == 0
    assert not (out / "manifest.json").exists() and not (out / "prediction.png").exists()
    errors = json.loads((out / "relight.json").read_text())
    assert errors["band_coverage"]["share"] == 1.0
    rows = list(csv.reader((out / "prediction.csv").read_text().splitlines()))[1:]
    assert all(float(r[6]) - float(r[5]) > 0.02 * float(r[4]) for r in rows)
    assert [r[-1] for r in rows] == [{"R": "", "G": "below", "B": "unmeasured"}[r[3]]
                                     for r in rows]
    coverage = errors["band_coverage"]
    assert coverage["beyond_measured"] == 2 * len(rows) // 3
    assert coverage["within_measured"] == {"share": 1.0, "values": len(rows) // 3}
    # the errors of the region means against the observed frames', per frame and overall
    pred, obs = (np.array([float(r[k]) for r in rows]) for k in (4, 7))
    e = errors["regions"]["disc"]
    assert e["rel_rms"] == pytest.approx(np.sqrt(np.mean((pred - obs) ** 2) / np.mean(obs ** 2)),
                                         rel=1e-3)
    assert len(e["per_frame"]) == len({r[1] for r in rows}) and "held_out_rel_rms" not in e
    lines = (out / "relight.csv").read_text().splitlines()
    assert lines[0].startswith("region,frame") and lines[-1].startswith("all,all")
    _fit_json(fit, model="achromatic", R=0.8, rho_s=0.0, sigma_alpha=0.0)
    # another prediction into the folder replaces it only with --overwrite
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    for images in ([], ["--no-images"]):
        assert main(["relight", str(fit), "--target", str(day / "day"), "-o", str(out), "-q",
                     *images, "--draws", "20"]) == 2
        assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert main(["relight", str(fit), "--target", str(day / "day"), "-o", str(out), "-q",
                 "--no-images", "--draws", "20", "--overwrite"]) == 0
    assert json.loads((out / "relight.json").read_text())["band_coverage"]["share"] == 0.0


def test_fit_on_some_frames_and_relight_onto_the_same_folder_reports_the_held_out_error(
        day, tmp_path):
    """The held-out-time test in two commands: `fit --frames` trains on frames 0-1, `relight`
    onto the same folder reports the error on frames 2-3 apart (the fit JSON names its
    sequence and frames)."""
    fits = tmp_path / "fits"
    assert main(["fit", str(day / "day"), "--region", "disc=rect:6,6,9,9", "--model", "2",
                 "--frames", "0-1", "-o", str(fits)]) == 0
    r = json.loads((fits / "fit_disc.json").read_text())
    assert r["frames"] == [0, 1] and len(r["series"]["times"]) == 2
    out = tmp_path / "relit"
    assert main(["relight", str(fits), "--target", str(day / "day"), "-o", str(out), "-q",
                 "--no-images", "--draws", "20"]) == 0
    assert main(["relight", str(fits), "--target", str(day / "day"), "-o", str(out), "-q",
                 "--overwrite", "--draws", "20"]) == 0
    errors = json.loads((out / "relight.json").read_text())
    e = errors["regions"]["disc"]
    assert e["trained_frames"] == [0, 1] and e["held_out_rel_rms"] < 0.05
    assert e["pixels"] == 16                                  # the fit's own pixels
    assert errors["band_coverage"]["share"] >= 0.75          # measured 1.0 (12 values)
    rows = list(csv.reader((out / "relight.csv").read_text().splitlines()))
    assert [row[4] for row in rows[1:5]] == ["no", "no", "yes", "yes"]
    assert errors["bands_drawn"] == {"draws": 20, "seed": 0,
                                     "from": {"disc": "its likelihood draws"}}
    # a prediction without images does not mix into the relit sequence, nor another relight
    # (other draws or seed: its bands were replaced silently); with --overwrite it replaces it
    before = sorted(p.name for p in out.iterdir())
    assert main(["relight", str(fits), "--target", str(day / "day"), "-o", str(out), "-q",
                 "--draws", "10", "--seed", "5"]) == 2
    assert main(["relight", str(fits), "--target", str(day / "day"), "-o", str(out), "-q",
                 "--no-images", "--draws", "20"]) == 2
    assert sorted(p.name for p in out.iterdir()) == before
    assert main(["relight", str(fits), "--target", str(day / "day"), "-o", str(out), "-q",
                 "--no-images", "--draws", "20", "--overwrite"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["prediction.csv", "relight.csv",
                                                     "relight.json"]
    # without images the region means give the held-out error alike
    e = json.loads((out / "relight.json").read_text())["regions"]["disc"]
    assert e["trained_frames"] == [0, 1] and e["held_out_rel_rms"] < 0.05
    rows = list(csv.reader((out / "relight.csv").read_text().splitlines()))
    assert [row[4] for row in rows[1:5]] == ["no", "no", "yes", "yes"]


def test_fits_another_run_left_in_a_sequence_folder_are_refused(day, tmp_path, capsys):
    """`render --overwrite` leaves the old run's fits in the folder: given the folder, relight
    and export refuse them by name rather than use numbers of other frames."""
    import shutil

    folder = tmp_path / "again"
    shutil.copytree(day / "day", folder)
    fit = _fit_json(folder / "fit_disc.json")
    fit.write_text(json.dumps({**json.loads(fit.read_text()), "sequence_run_id": "0ld"}))
    for argv in (["relight", str(folder), "--target", str(folder), "-o", str(tmp_path / "r"),
                  "--no-images", "-q"], ["export", str(folder), "-o", str(tmp_path / "e")]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert "was fitted to another run of the sequence in its folder (run 0ld" in err, err
        assert len(err.splitlines()) == 1


def test_a_day_of_black_frames_is_refused_in_one_line(day, tmp_path, capsys):
    """A sequence whose every frame came out black (marked dark) has nothing to fit."""
    import shutil

    dark = tmp_path / "dark"
    shutil.copytree(day / "day", dark)
    doc = json.loads((dark / "manifest.json").read_text())
    for f in doc["frames"]:
        f["dark"] = True
    (dark / "manifest.json").write_text(json.dumps(doc))
    assert main(["fit", str(dark), "--region", "disc=rect:6,6,9,9", "--model", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert "is black (marked dark" in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("text", ["6-2", "a", "1,,2", "-1"])
def test_bad_frame_lists_get_one_line(day, capsys, text):
    assert main(["fit", str(day / "day"), "--all", "--frames", text]) == 2
    assert "is not a frame list" in capsys.readouterr().err


def test_relight_onto_another_camera_compares_the_material_where_that_camera_sees_it(
        day, tmp_path):
    """A target seen from the north: the fit's pixel coordinates mean nothing there, so the
    region is the disc's interior in the target's own label image; with the true material the
    relit target equals its render (same seeds)."""
    raw = copy.deepcopy(TINY)
    raw["camera"]["azimuth_deg"] = 0.0
    raw["time"]["times"] = ["10:00", "13:00"]
    (tmp_path / "north.json").write_text(json.dumps(raw))
    assert main(["render", str(tmp_path / "north.json"), "-o", str(tmp_path / "north"),
                 "-q"]) == 0
    fit = _fit_json(tmp_path / "fit_disc.json")
    out = tmp_path / "relit"
    assert main(["relight", str(fit), "--target", str(tmp_path / "north"), "-o", str(out), "-q",
                 "--draws", "10"]) == 0
    e = json.loads((out / "relight.json").read_text())["regions"]["disc"]
    assert e["pixels"] > 16 and e["rel_rms"] < 1e-6 and "held_out_rel_rms" not in e


@pytest.fixture(scope="module")
def glossy(tmp_path_factory, mi):
    """A glossy Ward disc's clear day seen from the east, fitted (3 parameters)."""
    tmp = tmp_path_factory.mktemp("glossy")
    raw = copy.deepcopy(TINY)
    raw["materials"] = {"disc": {"model": "achromatic", "R": 0.6, "rho_s": 0.08,
                                 "sigma_alpha": 0.12}}
    raw["render"]["spp"] = 256
    (tmp / "train.json").write_text(json.dumps(raw))
    assert main(["render", str(tmp / "train.json"), "-o", str(tmp / "train"), "-q"]) == 0
    assert main(["fit", str(tmp / "train"), "--region", "disc=rect:6,6,9,9", "--model", "3",
                 "-o", str(tmp / "fits")]) == 0
    return tmp, raw


@pytest.mark.parametrize("change", ["overcast sky", "camera from the north"])
def test_a_fit_of_ward_data_predicts_another_sky_and_camera_within_its_band(
        glossy, tmp_path, change):
    """Predict (the fast path) a day the fit never saw: an overcast sky, or the clear day from
    the north.  The observed region means lie in the predicted 95% bands, and the prediction
    is close.  From the north, the sun and view of half the frames lie over 30 degrees from
    any pair the fit saw from the east, and are marked 'angles'; under the overcast sky, with
    no sun, none is."""
    fitted, target = glossy[0], copy.deepcopy(glossy[1])
    if change == "overcast sky":
        target["sky"] = {"type": "overcast"}
    else:
        target["camera"]["azimuth_deg"] = 0.0
    target["render"]["seed"] = 11
    (tmp_path / "target.json").write_text(json.dumps(target))
    assert main(["render", str(tmp_path / "target.json"), "-o", str(tmp_path / "target"),
                 "-q"]) == 0
    out = tmp_path / "pred"
    assert main(["relight", str(fitted / "fits"), "--target", str(tmp_path / "target"),
                 "-o", str(out), "-q", "--no-images", "--draws", "100"]) == 0
    errors = json.loads((out / "relight.json").read_text())
    assert errors["band_coverage"]["share"] >= 0.75, errors["band_coverage"]
    rows = list(csv.reader((out / "prediction.csv").read_text().splitlines()))[1:]
    pred, seen = (np.array([float(r[k]) for r in rows]) for k in (4, 7))
    err = np.sqrt(np.mean((pred - seen) ** 2) / np.mean(seen**2))
    assert err < 0.02                 # measured 0.56% (overcast) and 0.26% (north); 12 values
    angles = errors["band_coverage"]["beyond_measured_by"].get("angles", 0)
    assert angles == sum(r[-1] == "angles" for r in rows)
    assert (angles == 0) if change == "overcast sky" else (angles >= 3), errors["band_coverage"]
    # the same from the true material: noise alone, which the fit's error is compared with
    means = errors["region_means"]["disc"]
    assert means["fit"] == pytest.approx(err, rel=1e-3) and means["truth"] < 0.02


def test_bands_on_the_fitted_day_are_as_sharp_as_its_data(glossy, tmp_path):
    """Relit onto its own day, a fit's bands draw from its data's likelihood (the fit JSON's
    draws): each region mean's band is within twice the 95% noise of the observed mean (2%
    noise on 16 pixels: 0.98%) and holds the observed, whatever the intervals say: with
    rho_s's and sigma_alpha's widened to their bounds (as a reading 'not determined' has
    them) the band is the same, where the intervals' Gaussian, which a fit without its draws
    falls back on, gives a band several times wider."""
    fitted = glossy[0]
    path = fitted / "fits" / "fit_disc.json"
    original = path.read_text()
    fit = json.loads(original)
    draws = fit["draws"]
    assert len(draws["values"]) == 200 and draws["effective_size"] >= 200
    widths = {}
    try:
        for kind in ("draws", "widened", "intervals"):
            if kind == "widened":
                fit["intervals"]["rho_s"]["95"] = [0.0, 1.0]
                fit["intervals"]["sigma_alpha"]["95"] = [0.0, 0.5]
            if kind == "intervals":
                del fit["draws"]
            path.write_text(json.dumps(fit))
            out = tmp_path / kind
            assert main(["relight", str(fitted / "fits"), "--target", str(fitted / "train"),
                         "-o", str(out), "-q", "--no-images"]) == 0
            rows = list(csv.reader((out / "prediction.csv").read_text().splitlines()))[1:]
            widths[kind] = np.median([(float(r[6]) - float(r[5])) / 2 / float(r[4])
                                      for r in rows])
            share = json.loads((out / "relight.json").read_text())["band_coverage"]["share"]
            assert kind == "intervals" or share >= 0.75, (kind, share)
    finally:
        path.write_text(original)            # the module's fixture, as it was
    assert widths["draws"] < 2 * 1.96 * 0.02 / 4, widths
    assert widths["widened"] == pytest.approx(widths["draws"], rel=0.2), widths
    assert widths["intervals"] > 3 * widths["draws"], widths


def test_a_frame_whose_highlight_the_fit_never_saw_is_marked_beyond_its_data(glossy, tmp_path):
    """The glossy disc fitted on its first three frames (the sun's highlight no nearer than
    17.7 degrees) and predicted on all four: the last frame's highlight (3.1 degrees) is a
    lobe peak its data never showed, marked 'highlight' in prediction.csv and counted beyond
    what the data measured in relight.json; the frames it saw are not."""
    fitted = glossy[0]
    fits = tmp_path / "fits"
    assert main(["fit", str(fitted / "train"), "--region", "disc=rect:6,6,9,9", "--model", "3",
                 "--frames", "0-2", "-o", str(fits)]) == 0
    geometry = json.loads((fits / "fit_disc.json").read_text())["geometry"]
    assert geometry["closest_highlight_half_angle_deg"] > 15
    out = tmp_path / "pred"
    assert main(["relight", str(fits), "--target", str(fitted / "train"), "-o", str(out), "-q",
                 "--no-images", "--draws", "50"]) == 0
    rows = list(csv.DictReader((out / "prediction.csv").read_text().splitlines()))
    marks = {(int(r["frame"]), r["beyond_fit_data"]) for r in rows}
    assert {m for f, m in marks if f == 3} == {"highlight"}, marks
    assert "highlight" not in {m for f, m in marks if f < 3}, marks
    coverage = json.loads((out / "relight.json").read_text())["band_coverage"]
    assert coverage["beyond_measured"] >= 3


def test_regions_traced_together_agree_with_each_traced_alone(tmp_path, mi):
    """relight.fitted_sessions (fit.trace_sessions): one light cache over several regions' pixels (each pixel its
    region's material) gives each region what a trace of its own gives: bit for bit for a
    single region (the same seed and samples), and for three regions on the sample board
    region means within the Monte Carlo error of the two caches (independent: other seeds).
    At 8 of 26 pixels a region alone has as many anchors as pixels, so it takes each pixel's
    own sky integrals through its centre, where the union interpolates between anchors (with
    integrals at one random position of each pixel, |z| reached 28: an error the positions'
    spread did not see)."""
    from skyfit_mi.fitting.chi2 import subsample_region
    from skyfit_mi.fitting.fit import FitCache, FitSession
    from skyfit_mi.fitting.relight import fitted_sessions
    from skyfit_mi.pipeline.pixels import material_regions
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import SCENES_DIR, read_spec, validate_spec
    from skyfit_mi.render.light_cache import SKY_SPACING, anchors_pay

    spec = SCENES_DIR / "specs" / "board_east_37.toml"
    raw = read_spec(spec)
    raw["camera"].update(width=48, height=36)
    raw["time"].update(step_minutes=180)       # 3 frames (12:00, 15:00, 18:00)
    raw["render"] = {"spp": 16, "seed": 2}
    render_sequence(validate_spec(raw, spec.parent), tmp_path / "day", progress=False,
                    log=lambda *a: None)
    seen = dict(material_regions(tmp_path / "day"))
    names = ["white_paper", "red_gloss_paint", "polished_mild_steel"]
    pixels = {n: subsample_region(seen[n], 8, 0) for n in names}
    # the white paper's 8 pixels are all it has (compact: they take anchors alone); the
    # others are 8 of 26 (they do not)
    assert [anchors_pay(pixels[n], SKY_SPACING, 48, 36) for n in names] == [True, False, False]
    assert anchors_pay(np.concatenate(list(pixels.values())), SKY_SPACING, 48, 36)
    fits = {n: {"region": n, "model": "colour", "normalisation": "ward"} for n in names}
    options = dict(cache=FitCache(4, 64, 5, "anchors"), min_frames=1)
    alone = FitSession.from_fit(fits[names[0]], tmp_path / "day", pixels[names[0]], **options)
    one = fitted_sessions({names[0]: fits[names[0]]}, tmp_path / "day", pixels,
                          **options)[names[0]]
    for k in ("D", "G0", "G1", "hit", "sun_cos"):
        assert np.array_equal(getattr(alone.table, k), getattr(one.table, k), equal_nan=True), k
    for a, b in zip(alone.table.coef, one.table.coef):                # block by block
        assert [(r, f) for r, f, _ in a.blocks] == [(r, f) for r, f, _ in b.blocks]
        assert all(np.array_equal(x, y) for (_, _, x), (_, _, y) in zip(a.blocks, b.blocks))
    together = fitted_sessions(fits, tmp_path / "day", pixels, **options)
    theta = np.array([0.5, 0.4, 0.3, 0.1, 0.1])
    z = []
    for n in names:
        own = FitSession.from_fit(fits[n], tmp_path / "day", pixels[n], min_frames=1,
                                  cache=FitCache(4, 64, 6, "anchors"))
        s = together[n]
        assert len(s.table.hit) == len(pixels[n]) and s.table.hit.all()
        (a, va), (b, vb) = (x.wm.radiance_and_variance(theta) for x in (s, own))
        m = len(pixels[n])
        z.append((a.mean(axis=0) - b.mean(axis=0))
                 / np.sqrt((va.sum(axis=0) + vb.sum(axis=0)) / m**2))
    z = np.concatenate([x.ravel() for x in z])
    assert np.all(np.abs(z) < 5) and np.sqrt(np.mean(z**2)) < 2, z


@pytest.mark.parametrize("regions", [1, 8])
def test_the_prediction_plot_has_no_empty_bands_above_or_below_its_panels(regions):
    """The figure is laid out to its panels: however many regions, ink starts and ends within
    a few percent of the image's top and bottom."""
    import io

    from PIL import Image

    from skyfit_mi.fitting.relight import PredictionRow, plot_prediction

    rows = [PredictionRow(f"r{k}", j, f"2026-08-16T{6 + j:02d}:00:00+01:00", ch, v, v - 5,
                          v + 5, v + 1)
            for k in range(regions) for j in range(13)
            for c, ch in enumerate("RGB") for v in [100 + 30 * np.sin(j / 3 + c)]]
    image = np.asarray(Image.open(io.BytesIO(plot_prediction(rows, "observed"))).convert("L"))
    inked = np.flatnonzero((image < 250).any(axis=1))
    assert inked[0] < 0.03 * len(image) and inked[-1] > 0.97 * len(image), \
        (inked[0], inked[-1], len(image))


def test_a_hand_edited_measured_range_or_draws_is_refused_in_one_line(tmp_path):
    """relight reads a fit's measured_range (the radiance its data measured, per channel) and
    draws (sets of its parameters from its likelihood): one not as `fit` writes it is refused
    naming what it must be; `fit`'s own form passes."""
    from skyfit_mi.errors import SkyfitError
    from skyfit_mi.pipeline.fit_result import read_fit_result

    fit = {"region": "disc", "model": "two", "parameters": {"rho_s": 0.1, "sigma_alpha": 0.1},
           "intervals": {"rho_s": {"95": [0.0, 0.2]}, "sigma_alpha": {"95": [0.0, 0.2]}}}
    path = tmp_path / "fit_disc.json"
    for bad in ([1, 2], {"by_channel": [1, 2]}, {"by_channel": {"R": [2.0, 1.0]}},
                {"by_channel": {"R": [1.0]}}, {"by_channel": {"G": "dim"}}):
        path.write_text(json.dumps({**fit, "measured_range": bad}))
        with pytest.raises(SkyfitError, match=r"measured_range must be \{\"by_channel\"") as e:
            read_fit_result(path)
        assert "\n" not in str(e.value)
    for bad in ([[0.1, 0.1]], {"values": []}, {"values": [[0.1]], "added_sd": [0, 0]},
                {"values": [[0.1, None]], "added_sd": [0, 0]},
                {"values": [[0.1, 0.1]], "added_sd": [0, -1]},
                {"values": [[0.1, 0.1]], "added_sd": [0, 0], "shared_rows": [[0.1]]},
                {"values": [[0.1, 0.1]], "added_sd": [0, 0], "shared_rows": [0.1, 0.1]},
                {"values": [[0.1, 0.1]], "added_sd": [0, 0], "shared_rows": [[None, -1]]}):
        path.write_text(json.dumps({**fit, "draws": bad}))
        with pytest.raises(SkyfitError, match=r"draws must be \{\"values\"") as e:
            read_fit_result(path)
        assert "\n" not in str(e.value)
    for good in ({}, {"shared_rows": [[0.01, -0.02], [0, 0.02]]}, {"shared_rows": []}):
        path.write_text(json.dumps({**fit, "draws": {"values": [[0.1, 0.1]],
                                                     "added_sd": [0, 0], **good}}))
        assert read_fit_result(path)["draws"]["values"] == [[0.1, 0.1]]
    good = {"unit": "W m^-2 sr^-1", "by_channel": {"R": [1.0, 2.0], "G": None, "B": [0, 5]}}
    path.write_text(json.dumps({**fit, "measured_range": good}))
    assert read_fit_result(path)["measured_range"]["by_channel"]["G"] is None


def test_a_predicted_values_noise_is_taken_at_the_prediction():
    """relight's image_noise_variance: each value's sigma through the response's slope at the
    model's prediction (a value noise put at or below zero keeps its noise, and so does a dark
    prediction), at the observed value where the prediction lies beyond the top code, none for
    a value clipped at the top (it tells only a bound)."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.relight import image_noise_variance

    top, sigma = 10.0, 0.5

    def slope(radiance):                      # a linear response that clips at 0 and at top
        return np.where((radiance > 0) & (radiance < top), 2.0, 0.0)
    observed = np.array([[[-0.3, 5.0, 9.0, 10.0, 0.2]]])          # (P, T, channels)
    predicted = np.array([[[0.4, 5.0, 11.0, 9.5, 0.0]]])
    obs = SimpleNamespace(rays=np.zeros(1), sigma=np.full(observed.shape, sigma))
    s = SimpleNamespace(obs=obs, doc={"source": "ingest"},
                        problem=SimpleNamespace(slope=slope, clipped=lambda: (
                            observed <= 0, observed >= top)))
    var = image_noise_variance(s, observed, predicted, None)
    np.testing.assert_allclose(var[0, 0], [(sigma / 2) ** 2] * 3 + [0.0, (sigma / 2) ** 2])


def test_a_frame_calibrated_on_its_own_keeps_its_calibrations_error_in_the_band():
    """relight's frame_calibration_variance: a target whose frames were each calibrated on
    their own grey card (ingest's per_frame) shares that calibration's relative error over all
    of a frame's pixels, so a region mean's band keeps (sd x value)^2 whole (the hazy photo test
    day: 77% of its own frames' means held without it, 99% with); one calibration for the day
    adds nothing here (it is a factor on the parameters, in their intervals)."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.relight import frame_calibration_variance

    radiance = np.array([[10.0, 20.0, 30.0], [1.0, 2.0, 3.0]])                    # (T, 3)
    sd = [0.01, 0.02, 0.005]

    def session(per_frame):
        return SimpleNamespace(doc={"ingest": {"calibration": {
            "per_frame": per_frame, "frame_relative_sd": sd}}})
    np.testing.assert_allclose(frame_calibration_variance(session(True), radiance),
                               (np.array(sd) * radiance) ** 2)
    assert frame_calibration_variance(session(False), radiance) == 0.0
    assert frame_calibration_variance(SimpleNamespace(doc={"source": "render"}), radiance) == 0.0


def test_another_cameras_target_keeps_its_own_tone_curves_error_in_the_band():
    """relight's target_tone_variance: a target ingested with a camera's own tone curve counted
    keeps each mean's (move x value)^2 summed over the curve's independent errors, the moves
    those of the region's median codes, where the fit counted another camera's curve, none, or
    one measured by greys where the target's was not; on the fit's own sequence, another of the
    fit's camera read alike, or a camera either does not name, the fit's parameters carry the
    same curve's error; a target without the curve adds nothing."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.relight import target_tone_variance
    from skyfit_mi.physics import tone_curve as tc
    from skyfit_mi.physics.camera import SensorModel

    sensor = SensorModel(1.0, response="srgb", bits=8)
    code = sensor.respond(np.array([0.1, 0.4])) * sensor.max_code
    y = np.empty((4, 2, 3))                        # (P, T, C): the median pixel 4x the anchor
    y[0], y[1:] = code[0], code[1]
    y[3, 0] = 0.0                         # a value left out (sigma inf): not the region's level
    phi = tc.basis(np.full(3, np.log(0.1))).tolist()
    radiance = np.array([[10.0, 20.0, 30.0], [1.0, 2.0, 3.0]])                    # (T, 3)
    t = np.log(sensor.linearise(code))
    want = np.sum(np.square(tc.moves(t[1], t[0])), axis=-1) * radiance ** 2

    def target(make, tone=True):
        model = None if make is None else "X1"
        doc = {"ingest": {"tone_curve": {"anchor_basis": {"0": phi, "1": phi}}},
               "frames": [{"photo": {"make": make, "model": model}}] * 2}
        sigma = np.ones_like(y)
        sigma[3, 0] = np.inf
        obs = SimpleNamespace(rays=None, y=y, sigma=sigma, sensor=sensor, frames=[0, 1])
        return SimpleNamespace(tone=np.zeros((4, 2, 3, 5)) if tone else None, run_id="b",
                               doc=doc, obs=obs)

    other = {"sequence_run_id": "a", "tone_curve_cameras": ["Acme X1"]}
    np.testing.assert_allclose(target_tone_variance(target("Other"), other, radiance), want)
    np.testing.assert_allclose(target_tone_variance(target("Acme"), {"sequence_run_id": "a"},
                                                    radiance), want)        # fit counted none
    np.testing.assert_allclose(target_tone_variance(target("Acme"), {
        **other, "tone_curve_measured": True}, radiance), want)        # read otherwise
    for same in (other, {**other, "tone_curve_cameras": []}):
        assert target_tone_variance(target("Acme"), same, radiance) == 0.0
    assert target_tone_variance(target(None), other, radiance) == 0.0
    assert target_tone_variance(target("Other"), {"sequence_run_id": "b"}, radiance) == 0.0
    assert target_tone_variance(target("Other", tone=False), other, radiance) == 0.0
