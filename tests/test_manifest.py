"""The manifest contract: schema, upgrade of old files, clear messages, per-frame exposure,
and observations checked on load."""
import json
import shutil

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from skyfit_mi.errors import SkyfitError
from skyfit_mi.pipeline.manifest import (SCHEMA, ManifestError, frame_exposure, frame_sky,
                                         load_manifest, schema, upgrade, validate_manifest,
                                         write_manifest)


@pytest.fixture(scope="module")
def day(tmp_path_factory, mi):
    """A small rendered disc day (12x12, 13 frames)."""
    from conftest import disc_day

    return disc_day(tmp_path_factory.mktemp("manifest"), "day", spp=16)


def _copy(day, tmp_path):
    out = tmp_path / "copy"
    shutil.copytree(day, out)
    return out


def test_rendered_manifest_follows_the_shipped_schema(day):
    import jsonschema

    doc = json.loads((day / "manifest.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema())
    jsonschema.validate(doc, schema())               # the file itself, not an upgraded copy
    assert doc["schema"] == SCHEMA and doc["source"] == "render"
    f = doc["frames"][0]
    assert f["illumination"]["kind"] == "sky"
    assert f["time_utc"].endswith("+00:00")


def test_a_manifest_read_again_is_validated_again_only_when_its_text_changed(day, tmp_path,
                                                                          monkeypatch):
    from skyfit_mi.pipeline import manifest

    out = _copy(day, tmp_path)
    calls = []
    check = manifest.validate_manifest
    monkeypatch.setattr(manifest, "validate_manifest", lambda d, s: calls.append(s) or check(d, s))
    load_manifest(out)
    load_manifest(out)                     # the same text, seen by another step of a command
    seen = len(calls)
    assert seen <= 1                       # (none when an earlier test read this text)
    doc = json.loads((out / "manifest.json").read_text())
    doc["camera"]["width"] = "wide"
    (out / "manifest.json").write_text(json.dumps(doc))
    with pytest.raises(ManifestError, match=r"camera\.width"):
        load_manifest(out)
    assert len(calls) == seen + 1


def test_a_frame_read_again_is_shared_until_its_file_changes(day, tmp_path):
    """read_frame_image keeps what it read lately: the next reader of an unchanged file gets the
    same (read-only) array; a file written again is read anew."""
    from skyfit_mi.pipeline.manifest import read_frame_image
    from skyfit_mi.render.image import write_exr

    out = _copy(day, tmp_path)
    doc, root = load_manifest(out)
    f = doc["frames"][4]
    a = read_frame_image(root, f, "radiance", (12, 12, 3))
    assert read_frame_image(root, f, "radiance", (12, 12, 3)) is a and not a.flags.writeable
    write_exr(out / f["radiance"], a * 2)                  # written again (atomically)
    b = read_frame_image(root, f, "radiance", (12, 12, 3))
    assert b is not a and np.array_equal(b, a * 2)
    (out / f["radiance"]).write_bytes((out / f["radiance"]).read_bytes()[:200])   # in place
    with pytest.raises(SkyfitError, match="frame 4: cannot read"):
        read_frame_image(root, f, "radiance", (12, 12, 3))


def test_a_frame_just_written_is_read_from_memory_bit_for_bit(tmp_path, monkeypatch):
    """write_frame keeps the radiance and its error it wrote for read_frame_image, with the
    values the file reads back as (NaN and inf of an ingested frame included); a later write
    of the file is read anew."""
    from skyfit_mi.pipeline import manifest
    from skyfit_mi.pipeline.sequence import write_frame
    from skyfit_mi.render.image import read_exr, read_exr_checked

    rng = np.random.default_rng(5)
    images = [rng.random((6, 7, 3)) * 10 ** rng.uniform(-3, 3) for _ in range(4)]
    images[0][0, 0], images[1][1, 1] = np.nan, np.inf
    rec = dict(write_frame(tmp_path, 2, *images), index=2)

    def no_reads(path, shape):
        raise AssertionError(f"{path} was read from the file")
    monkeypatch.setattr(manifest, "read_exr_checked", no_reads)
    for key, image in zip(("radiance", "radiance_sigma"), images):
        kept = manifest.read_frame_image(tmp_path, rec, key, (6, 7, 3))
        assert not kept.flags.writeable
        assert np.array_equal(kept, read_exr(tmp_path / rec[key]), equal_nan=True)
        assert np.array_equal(kept, image.astype(np.float32), equal_nan=True)
    write_frame(tmp_path, 2, *(2 * im for im in images))
    with pytest.raises(AssertionError, match="read from the file"):
        manifest.read_frame_image(tmp_path, rec, "sensor", (6, 7, 3))      # not kept
    monkeypatch.setattr(manifest, "read_exr_checked", read_exr_checked)
    assert np.array_equal(manifest.read_frame_image(tmp_path, rec, "radiance", (6, 7, 3)),
                          (2 * images[0]).astype(np.float32), equal_nan=True)


def test_a_version_1_manifest_is_upgraded(day, tmp_path):
    out = _copy(day, tmp_path)
    doc = json.loads((out / "manifest.json").read_text())
    old = dict(doc, schema="skyfit-manifest/1")
    old["frames"] = [{k: v for k, v in f.items() if k not in ("illumination", "time_utc")}
                     | ({"sky": {k: v for k, v in f["illumination"].items() if k != "kind"}}
                        if "illumination" in f else {}) for f in doc["frames"]]
    (out / "manifest.json").write_text(json.dumps(old))
    new, root = load_manifest(out)
    assert root == out and new["schema"] == SCHEMA
    assert new["frames"][3]["illumination"] == doc["frames"][3]["illumination"]
    assert new["frames"][3]["time_utc"] == doc["frames"][3]["time_utc"]
    assert upgrade(doc) is doc


@pytest.mark.parametrize("text, match", [
    ('{"schema": "skyfit-manifest/2", "frames": [', "damaged .not complete JSON"),
    ('{"hello": 1}', "not a skyfit manifest"),
    ('[1, 2]', "not a skyfit manifest"),
    ('{"schema": "skyfit-manifest/9"}', "cannot read .*upgrade skyfit-mi"),
    ('{"schema": "skyfit-manifest/2", "run_id": "x", "status": "complete"}',
     "not a valid skyfit-manifest/2 manifest: at .*required property"),
])
def test_bad_manifests_get_one_clear_message(tmp_path, text, match):
    (tmp_path / "manifest.json").write_text(text)
    with pytest.raises(ManifestError, match=match):
        load_manifest(tmp_path)


def test_missing_manifest(tmp_path):
    with pytest.raises(ManifestError, match="no manifest at"):
        load_manifest(tmp_path / "nowhere")


def test_a_folder_of_frames_without_its_manifest_is_named_as_unfinished(tmp_path):
    (tmp_path / "frames").mkdir()
    with pytest.raises(ManifestError, match="stopped before its end; run it again"):
        load_manifest(tmp_path)


def test_frames_sharing_an_index_or_a_file_or_a_false_time_are_refused(day, tmp_path):
    """A hand-edited manifest whose frames share an index or an image file was fitted (chi2/dof
    1757, C 0.41 for 0.5) and one whose time is no date crashed after the fit wrote its JSON:
    refused on load, naming the frames; a spec or frame given as the sequence is named."""
    doc, _ = load_manifest(day)
    for frame, change, match in (
            (1, {"index": 0}, r"frames\[0\] and frames\[1\] share their index 0"),
            (1, {"sensor": doc["frames"][0]["sensor"]}, r"frames\[0\] and frames\[1\] share their sensor"),
            (1, {"time": "2026-02-30T12:00:00+00:00"}, r"frame 1's time '2026-02-30T12:00:00"
                                                       r"\+00:00' is not an ISO date")):
        bad = json.loads(json.dumps(doc))
        bad["frames"][frame].update(change)
        (tmp_path / "manifest.json").write_text(json.dumps(bad))
        with pytest.raises(ManifestError, match=match):
            load_manifest(tmp_path)
    (tmp_path / "day.toml").write_text("")
    with pytest.raises(ManifestError, match=r"day\.toml is not a sequence: give the folder"):
        load_manifest(tmp_path / "day.toml")


def test_invalid_frame_is_named(day):
    doc, _ = load_manifest(day)
    doc = json.loads(json.dumps(doc))
    doc["frames"][2]["illumination"] = {"kind": "envmap", "file": "x.exr"}   # no projection
    with pytest.raises(ManifestError, match=r"frames\[2\]\.illumination"):
        validate_manifest(doc)
    doc["frames"][2]["illumination"]["projection"] = "latlong"
    validate_manifest(doc)
    with pytest.raises(ManifestError, match=r"manifest\.json frame 2: envmap illumination: "
                                            r".*x\.exr: does not"):
        frame_sky(doc["frames"][2], day)                 # the map's file is named
    doc["frames"][2]["illumination"] = {"kind": "irradiance", "global_horizontal_W_m2": 300.0,
                                        "model": "cie"}
    validate_manifest(doc)
    with pytest.raises(ManifestError, match="frame 2: irradiance illumination: model 'cie'"):
        frame_sky(doc["frames"][2], day)
    frame = {k: v for k, v in doc["frames"][2].items() if k != "time"}
    frame["illumination"]["model"] = "Perez"
    with pytest.raises(ManifestError, match="needs its time"):
        frame_sky(frame, day)


_FIELDS = ["kind", "sun_direction", "sun_radiance", "sun_solid_angle_sr", "clear", "overcast",
           "uniform", "intermediate", "perez", "perez_coefficients", "ground", "horizon_blend",
           "text", "file", "projection", "direction", "irradiance_W_m2", "solid_angle_sr",
           "global_horizontal_W_m2", "diffuse_horizontal_W_m2", "direct_normal_W_m2", "model"]
_NUMBERS = st.floats(-1e6, 1e6) | st.sampled_from([0.0, -1.0, 1e308])
_VALUES = (_NUMBERS | st.lists(_NUMBERS, min_size=0, max_size=6) | st.booleans() | st.none()
           | st.sampled_from(["sky", "gensky", "envmap", "directional", "irradiance", "perez",
                              "latlong", "nosuch.exr", "# gensky 6 21 12 +s\n"]))


@settings(max_examples=200, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.sampled_from([0, 1, 2]), st.lists(st.tuples(st.sampled_from(_FIELDS), _VALUES),
                                            min_size=1, max_size=3))
def test_any_illumination_record_lights_a_frame_or_is_refused_naming_it(day, index, changes):
    """A hand-edited illumination record (any field set to any value): the manifest's schema
    refuses it, or its frame lights with a sky of finite, non-negative radiances, or a
    ManifestError in one line names the manifest and the frame (never another exception)."""
    doc, _ = load_manifest(day)
    frame = json.loads(json.dumps(doc["frames"][index]))
    for key, value in changes:
        frame["illumination"][key] = value
    try:
        validate_manifest({**doc, "frames": [frame]})
    except ManifestError as exc:
        assert "\n" not in str(exc)
        return
    try:
        sky = frame_sky(frame, day)
    except ManifestError as exc:
        assert f"{day / 'manifest.json'} frame {index}: " in str(exc) and "\n" not in str(exc)
        return
    for v in (sky.sun_radiance, sky.ground, sky.clear, sky.overcast, sky.perez):
        assert np.all(np.isfinite(v)) and np.all(v >= 0)


_PLACES = [("camera", "width"), ("camera", "fov_deg"), ("camera", "to_world"),
           ("sensor", "exposure"), ("sensor", "bits"), ("sensor", "response"),
           ("sensor", "gamma"), ("sensor", "noise_percent"), ("render", "variant"),
           ("frames", 1, "time"), ("frames", 1, "status"), ("frames", 1, "exposure"),
           ("frames", 1, "sun_zenith_deg"), ("frames", 1, "sensor"), ("frames", 1, "index"),
           ("run_id",), ("status",), ("schema",)]


@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.sampled_from(_PLACES), st.one_of(
    *[st.integers(-2, 4096)] * 3, *[st.floats(-10.0, 1e4)] * 3, _VALUES,
    st.fixed_dictionaries({"exposure": _NUMBERS}, optional={"white_balance": st.lists(
        _NUMBERS, min_size=3, max_size=3)}))), min_size=1, max_size=2))
def test_any_hand_edited_manifest_is_read_or_refused_in_one_line(day, tmp_path, changes):
    """A hand-edited manifest (any of its fields set to any value): it loads, and each frame
    lights, has an exposure and reads as a sensor record, or a SkyfitError refuses it in one
    line (never another exception)."""
    from skyfit_mi.pipeline.manifest import rendered_frames, sensor_from_record

    doc = json.loads((day / "manifest.json").read_text())
    for place, value in changes:
        *parents, key = place
        node = doc
        for k in parents:
            node = node[k]
        node[key] = value
    folder = tmp_path / "edited"
    folder.mkdir(exist_ok=True)
    (folder / "manifest.json").write_text(json.dumps(doc))
    try:
        doc, root = load_manifest(folder)
        sensor_from_record(doc["sensor"])
        for f in rendered_frames(doc):
            frame_sky(f, day)
            assert np.all(frame_exposure(doc, f) > 0)
    except SkyfitError as exc:
        assert "\n" not in str(exc), str(exc)


def test_a_negative_radiance_in_a_manifest_is_refused_by_frame(day, tmp_path, capsys):
    """A hand-edited negative sun radiance: the fit refuses it naming the manifest and frame."""
    from skyfit_mi.cli import main

    out = _copy(day, tmp_path)
    doc = json.loads((out / "manifest.json").read_text())
    doc["frames"][3]["illumination"]["sun_radiance"] = [-1e6, 1e6, 1e6]
    (out / "manifest.json").write_text(json.dumps(doc))
    assert main(["fit", str(out), "--region", "disc=rect:4,4,7,7", "-o", str(tmp_path / "f")]) == 2
    err = capsys.readouterr().err
    assert f"{out / 'manifest.json'} frame 3: sky illumination: sun_radiance" in err
    assert "is negative" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "f").exists()


def test_measured_irradiance_lights_a_frame_as_the_specs_perez_sky(day):
    """An ``irradiance`` record (measured DHI and DNI, or GHI split by Erbs) becomes the Perez
    sky that a spec's ``perez`` sky of the same values gives at the frame's sun and time; its
    horizontal irradiance is the measured (diffuse within 1%, direct exactly)."""
    import datetime as dt

    from skyfit_mi.physics.colour import SRGB_LUMINANCE
    from skyfit_mi.pipeline.illumination import perez_from_irradiance

    doc, _ = load_manifest(day)
    frame = json.loads(json.dumps(doc["frames"][2]))
    z, a = frame["sun_zenith_deg"], frame["sun_azimuth_deg"]
    t = dt.datetime.fromisoformat(frame["time"])
    for rec in ({"diffuse_horizontal_W_m2": 110.0, "direct_normal_W_m2": 700.0},
                {"global_horizontal_W_m2": 600.0}):
        frame["illumination"] = {"kind": "irradiance", **rec}
        validate_manifest({**doc, "frames": [frame]})
        sky = frame_sky(frame, day)
        ref = perez_from_irradiance(rec, z, a, t)
        np.testing.assert_allclose(sky.perez, ref.perez)
        np.testing.assert_allclose(sky.sun_radiance, ref.sun_radiance)
        assert sky.perez.max() > 0
    frame["illumination"] = {"kind": "irradiance", "diffuse_horizontal_W_m2": 110.0,
                             "direct_normal_W_m2": 700.0}
    sky = frame_sky(frame, day)
    diffuse = sky.sky_horizontal_irradiance() @ SRGB_LUMINANCE
    sun = sky.sun_horizontal_irradiance() @ SRGB_LUMINANCE
    assert abs(diffuse / 110.0 - 1) < 0.01, diffuse
    assert abs(sun / (700.0 * np.cos(np.radians(z))) - 1) < 0.01, sun


def test_write_refuses_an_invalid_document_and_keeps_the_old_file(day, tmp_path):
    out = _copy(day, tmp_path)
    before = (out / "manifest.json").read_text()
    doc, _ = load_manifest(out)
    doc["camera"]["width"] = 0
    with pytest.raises(ManifestError, match=r"camera\.width"):
        write_manifest(out, doc)
    assert (out / "manifest.json").read_text() == before
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


def test_per_frame_exposure_and_white_balance_reach_the_fit(day, tmp_path):
    """A frame photographed at half the exposure, with a white balance, fits the same
    radiance: the observations' gain follows each frame's exposure record."""
    from skyfit_mi.fitting.chi2 import load_observations
    from skyfit_mi.render.image import read_exr, write_exr

    out = _copy(day, tmp_path)
    doc, _ = load_manifest(out)
    px = np.array([[5, 5], [6, 6]])
    ref = load_observations(out, px)
    f = doc["frames"][4]
    wb = np.array([1.0, 0.8, 1.25])
    f["exposure"] = {"exposure": doc["sensor"]["exposure"] / 2, "exposure_time_s": 0.005,
                     "white_balance": wb.tolist()}
    write_manifest(out, doc)
    assert np.allclose(frame_exposure(doc, f), doc["sensor"]["exposure"] / 2 * wb)
    obs = load_observations(out, px)
    t = obs.frames.index(4)
    assert np.allclose(obs.gain[:, t], ref.gain[:, t] / 2 * wb)
    others = [i for i in range(len(obs.frames)) if i != t]
    assert np.allclose(obs.gain[:, others], ref.gain[:, others])
    # frame 4's files untouched here; the gain is what changes
    assert read_exr(out / f["sensor"]).shape == (12, 12, 3) and write_exr


def test_frames_are_checked_on_load(day, tmp_path):
    from skyfit_mi.fitting.chi2 import load_observations
    from skyfit_mi.render.image import read_exr, write_exr

    out = _copy(day, tmp_path)
    doc, _ = load_manifest(out)
    px = np.array([[5, 5], [6, 6], [7, 7]])
    f3, f5, f7 = (doc["frames"][i] for i in (3, 5, 7))
    img = read_exr(out / f3["sensor"])
    img[5, 5] = np.nan                                     # one damaged pixel: left out, counted
    write_exr(out / f3["sensor"], img)
    obs = load_observations(out, px)
    assert any("frame 3: 3 of the region's values are not finite" in w for w in obs.warnings)
    assert np.isinf(obs.sigma[0, obs.frames.index(3)]).all()
    sigma7 = read_exr(out / f7["sigma"])         # a frame of zero sigmas was dropped silently
    write_exr(out / f7["sigma"], np.zeros_like(sigma7))
    with pytest.raises(SkyfitError, match=r"frame 7 \(.*sensor_007\.exr, frames/sigma_007\.exr"
                                          r"\) has no value in the region that is finite with a "
                                          "positive sigma"):
        load_observations(out, px)
    write_exr(out / f7["sigma"], sigma7)
    write_exr(out / f5["sensor"], np.full((12, 12, 3), np.nan, np.float32))
    with pytest.raises(SkyfitError, match="frame 5 .* no value in the region that is finite"):
        load_observations(out, px)
    write_exr(out / f5["sensor"], np.zeros((10, 12, 3), np.float32))        # another size
    with pytest.raises(SkyfitError, match="frame 5: .* is 12x10 .* not the camera.s 12x12"):
        load_observations(out, px)
    (out / f5["sensor"]).write_bytes((out / f7["sensor"]).read_bytes()[:200])  # truncated
    with pytest.raises(SkyfitError, match="frame 5: cannot read"):
        load_observations(out, px)


def test_incomplete_render_is_warned_and_frames_can_be_chosen(day, tmp_path):
    from skyfit_mi.fitting.chi2 import load_observations

    out = _copy(day, tmp_path)
    doc, _ = load_manifest(out)
    doc["status"] = "incomplete"
    for f in doc["frames"][8:]:
        for k in ("radiance", "sensor", "sigma", "illumination"):
            f.pop(k, None)
        f["status"] = "pending"
    write_manifest(out, doc)
    obs = load_observations(out, [[5, 5]])
    assert obs.frames == list(range(8))
    assert any("incomplete" in w and "8 of its 13 frames" in w for w in obs.warnings)
    assert load_observations(out, [[5, 5]], frames=[0, 2, 4]).frames == [0, 2, 4]
    with pytest.raises(SkyfitError, match="frame 9 is not a rendered frame"):
        load_observations(out, [[5, 5]], frames=[0, 9])
    with pytest.raises(SkyfitError, match="region has no pixels"):
        load_observations(out, np.zeros((0, 2), int))


def test_the_fit_reports_what_loading_noticed(day, tmp_path):
    from skyfit_mi.fitting.fit import fit_region, FitCache

    out = _copy(day, tmp_path)
    doc, _ = load_manifest(out)
    doc["status"] = "incomplete"
    write_manifest(out, doc)
    res = fit_region(out, "disc", [[5, 5], [6, 6]],
                     cache=FitCache(positions=4, directions=16), log=lambda *a: None)
    assert any("render is incomplete" in w for w in res["warnings"])
