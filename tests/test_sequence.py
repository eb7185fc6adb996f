"""Specs, `skyfit render` and `skyfit pixels`: validation, resume, physics, end to end."""
import copy
import csv
import json
from pathlib import Path

import numpy as np
import pytest

from skyfit_mi.cli import main
from skyfit_mi.errors import SkyfitError
from skyfit_mi.pipeline.spec import SpecError, load_spec, validate_spec

TINY = {
    "name": "tiny",
    "location": {"latitude_deg": 40.0, "longitude_deg": 0.0, "timezone": "UTC"},
    "time": {"date": "2026-06-21", "times": ["07:00", "10:00", "13:00", "16:00"]},
    "sky": {"type": "clear"},
    "scene": {"file": "disc.xml"},
    "materials": {"disc": {"model": "two", "rho_s": 0.0, "sigma_alpha": 0.0}},
    "camera": {"azimuth_deg": 90.0, "angle_deg": 45.0, "distance": 5.0, "fov_deg": 8.0,
               "width": 16, "height": 16},
    "sensor": {"exposure": "auto", "bits": 12, "noise_percent": 2.0},
    "render": {"spp": 64, "seed": 3},
}


def spec(**changes):
    raw = copy.deepcopy(TINY)
    for path, v in changes.items():
        sec, _, key = path.partition("__")
        if key:
            raw.setdefault(sec, {})[key] = v
        elif v is None:
            raw.pop(sec)
        else:
            raw[sec] = v
    return raw


@pytest.mark.parametrize("changes, match", [
    (dict(location__latitude_deg=95), r"latitude_deg = 95 is outside \[-90, 90\]"),
    (dict(location__timezone="Mars/Olympus"), "IANA name such as 'Europe/London'"),
    (dict(time={"date": "2026-06-21"}), "needs times = \\[...\\] or start, end and step_minutes"),
    (dict(time={"date": "21/06/2026", "times": ["12:00"]}), "write 'YYYY-MM-DD'"),
    (dict(time={"date": "2026-06-21", "times": ["noon"]}), "write 'HH:MM'"),
    (dict(sky={"type": "stormy"}), "valid: clear, overcast, intermediate, cie_general, turbid, gensky"),
    (dict(sky={"type": "intermediate"}), "needs phi"),
    (dict(sky={"type": "intermediate", "phi": 2}), r"phi = 2 is outside \[0, 1\]"),
    (dict(scene={"file": "nothere.xml"}), "shipped: disc.xml, photo_board.xml, sample_board.xml, sphere.xml"),
    (dict(materials={"disc": {"model": "raw", "rho_d": 0.8, "rho_s": 0.4, "sigma_alpha": 0.1}}),
     "rho_d \\+ rho_s = 1.2 > 1"),
    (dict(materials={"disc": {"model": "two", "rho_s": 0.1, "sigma_alpha": -0.1}}), "negative"),
    (dict(camera={"fov_deg": 30}), "place the camera one way"),
    (dict(camera__origin=[0, 0, 5]), "place the camera one way"),
    (dict(sensor__bits=7), "valid values are: 8, 10, 12, 16"),
    (dict(render__below_horizon="maybe"), "'sky' .render the sky alone. or 'skip'"),
    (dict(camera__colour="red"), r"unknown key\(s\) colour in \[camera\]"),
    (dict(location=None), r"no \[location\] section"),
    (dict(render__variant="scalar_rgb"), "valid: 'llvm_ad_rgb' .CPU., 'cuda_ad_rgb'"),
    (dict(render__integrator="bdpt"), "integrator 'bdpt'; valid: sun_sky_path, path"),
])
def test_spec_errors_name_the_fix(changes, match, tmp_path):
    with pytest.raises(SpecError, match=match):
        validate_spec(spec(**changes), tmp_path)


def test_unknown_material_names_the_scene_materials(tmp_path):
    with pytest.raises(SpecError, match="'plate' is not a ward material .* its materials are: disc"):
        validate_spec(spec(materials={"plate": {"model": "two", "rho_s": 0.1, "sigma_alpha": 0.1}}),
                      tmp_path)


def test_time_range_and_per_frame_skies(tmp_path):
    s = validate_spec(spec(time={"date": "2026-06-21", "start": "06:00", "end": "18:00",
                                 "step_minutes": 60},
                           sky=[{"type": "clear"}] * 6 + [{"type": "intermediate", "phi": 0.5}]
                           + [{"type": "overcast", "diffuse_horizontal_W_m2": 150.0}] * 6),
                      tmp_path)
    assert len(s.frames) == 13 and s.frames[0].time.hour == 6 and s.frames[-1].time.hour == 18
    assert s.frames[6].sky.info["phi"] == 0.5
    lum = s.frames[9].sky.sky_horizontal_irradiance() @ [0.2126, 0.7152, 0.0722]
    assert lum == pytest.approx(150.0)


def test_thesis_disc_spec_is_valid(tmp_path):
    from skyfit_mi.pipeline.spec import thesis_disc_spec
    spec = validate_spec(thesis_disc_spec("d", {"model": "two", "rho_s": 0.5, "sigma_alpha": 0.1},
                                          camera_azimuth_deg=0.0), tmp_path)
    assert len(spec.frames) == 13 and spec.camera["azimuth_deg"] == 0.0


def test_example_specs_are_valid():
    from skyfit_mi.pipeline.spec import SCENES_DIR
    names = sorted(p.name for p in (SCENES_DIR / "specs").glob("*.toml"))
    assert len(names) >= 8
    for p in (SCENES_DIR / "specs").glob("*.toml"):
        s = load_spec(p)
        assert s.frames and not any(f.skipped for f in s.frames)
    board = load_spec(SCENES_DIR / "specs" / "board_east_37.toml")
    assert [f.time.strftime("%H:%M %Z") for f in board.frames][::12] == ["12:00 BST", "18:00 BST"]


def _render(raw, out, tmp_path, **kw):
    from skyfit_mi.pipeline.sequence import render_sequence
    return render_sequence(validate_spec(raw, tmp_path), out, progress=False, log=lambda *a: None, **kw)


def test_interrupted_render_resumes_to_identical_frames(tmp_path, mi, monkeypatch):
    from skyfit_mi.pipeline import sequence
    from skyfit_mi.render.image import read_exr
    ref = _render(spec(), tmp_path / "a", tmp_path)

    calls = {"n": 0}
    real = sequence.write_exr

    def dying(path, img, meta=None):
        calls["n"] += 1
        if calls["n"] == 5:                        # frame 0: 3 files, frame 1: dies on its 2nd file
            raise KeyboardInterrupt
        return real(path, img, meta)

    monkeypatch.setattr(sequence, "write_exr", dying)
    with pytest.raises(KeyboardInterrupt):
        _render(spec(), tmp_path / "b", tmp_path)
    monkeypatch.setattr(sequence, "write_exr", real)
    partial = json.loads((tmp_path / "b" / "manifest.json").read_text())
    assert partial["status"] == "incomplete"
    assert [f["status"] for f in partial["frames"]] == ["rendered", "pending", "pending", "pending"]
    assert not list((tmp_path / "b" / "frames").glob(".*"))          # no half-written files

    logs = []
    from skyfit_mi.pipeline.sequence import render_sequence
    done = render_sequence(validate_spec(spec(), tmp_path), tmp_path / "b", progress=False,
                           log=logs.append)
    assert "(1 kept from an earlier run)" in logs[-1] and done["status"] == "complete"
    for fa, fb in zip(ref["frames"], done["frames"]):
        for k in ("radiance", "sensor", "sigma"):
            assert np.array_equal(read_exr(tmp_path / "a" / fa[k]), read_exr(tmp_path / "b" / fb[k]))


def test_refuses_to_mix_runs(tmp_path, mi):
    _render(spec(), tmp_path / "a", tmp_path)
    other = spec(render__seed=4)
    with pytest.raises(SkyfitError, match="holds another run.*--overwrite"):
        _render(other, tmp_path / "a", tmp_path)
    m = _render(other, tmp_path / "a", tmp_path, overwrite=True)
    assert m["render"]["seed"] == 4


def test_lambertian_disc_across_the_day_equals_irradiance_over_pi(tmp_path, mi):
    """A white Lambertian disc (rho_s = 0): every pixel's radiance is E/pi.

    16x16 pixels, all on the disc (8-degree field), 64 spp, seed 3: 16k samples per
    frame; the clear-sky sun dominates and is sampled exactly. Tolerance 1%.
    """
    from skyfit_mi.render.image import read_exr
    m = _render(spec(time={"date": "2026-06-21", "start": "06:00", "end": "18:00",
                           "step_minutes": 120}), tmp_path / "d", tmp_path)
    for f in m["frames"]:
        img = read_exr(tmp_path / "d" / f["radiance"])
        expected = np.array(f["illumination"]["horizontal_irradiance_W_m2"]) / np.pi
        np.testing.assert_allclose(img.reshape(-1, 3).mean(axis=0), expected, rtol=0.01)


def test_sun_below_horizon_is_skipped_or_sky_only(tmp_path, mi):
    times = {"date": "2026-06-21", "times": ["02:00", "12:00", "21:00"]}
    m = _render(spec(time=times, render__below_horizon="skip"), tmp_path / "s", tmp_path)
    assert [f["status"] for f in m["frames"]] == ["skipped", "rendered", "skipped"]
    m = _render(spec(time=times, sensor__exposure=0.01), tmp_path / "k", tmp_path)
    assert [f["status"] for f in m["frames"]] == ["rendered"] * 3
    from skyfit_mi.render.image import read_exr
    night = read_exr(tmp_path / "k" / m["frames"][0]["radiance"])
    assert np.all(np.isfinite(night)) and night.max() < 1e-3
    # a day of night alone: said as such (it was "every frame is dark ... give exposure")
    with pytest.raises(SkyfitError, match="the sun is below the horizon at every time"):
        _render(spec(time={"date": "2026-06-21", "times": ["00:00", "01:00"]}),
                tmp_path / "n", tmp_path)


def test_a_fitted_material_renders_and_the_manifest_says_where_it_came_from(tmp_path, mi):
    """A spec material given as a fit JSON is rendered with the fitted parameters; the
    manifest's materials name their source (the fit file and region, or the spec)."""
    (tmp_path / "fit_disc.json").write_text(json.dumps(
        {"region": "disc", "model": "achromatic", "normalisation": "balanced",
         "parameters": {"R": 0.5, "rho_s": 0.2, "sigma_alpha": 0.05},
         "intervals": {"R": {"95": [0.4, 0.6]}, "rho_s": {"95": [0.1, 0.3]},
                       "sigma_alpha": {"95": [0.02, 0.08]}}}))
    raw = copy.deepcopy(TINY)
    raw["materials"] = {"disc": {"fit": "fit_disc.json"}}
    raw["time"]["times"] = ["12:00"]
    p = tmp_path / "relit.json"
    p.write_text(json.dumps(raw))
    assert main(["render", str(p), "-o", str(tmp_path / "run"), "-q"]) == 0
    m = json.loads((tmp_path / "run" / "manifest.json").read_text())["scene"]["materials"]
    assert m["disc"]["source"] == "fit fit_disc.json (region disc)"
    assert m["disc"]["normalisation"] == "balanced"
    assert m["disc"]["raw"]["rho_d"] == pytest.approx([0.4] * 3)
    assert m["disc"]["raw"]["rho_s"] == pytest.approx([0.1] * 3)


def test_cli_render_and_pixels_end_to_end(tmp_path, mi):
    p = tmp_path / "tiny.json"
    p.write_text(json.dumps(TINY))
    out = tmp_path / "run"
    assert main(["render", str(p), "-o", str(out), "-q"]) == 0
    m = json.loads((out / "manifest.json").read_text())
    assert m["schema"] == "skyfit-manifest/2" and m["status"] == "complete"
    assert m["scene"]["materials"]["disc"]["raw"]["rho_d"] == [1.0, 1.0, 1.0]
    assert len(m["camera"]["to_world"]) == 4 and m["sensor"]["max_code"] == 4095
    assert (out / "contact_sheet.png").exists()
    assert main(["pixels", str(out), "--pixel", "8,8", "--pixel", "3,12", "--source", "sensor"]) == 0
    rows = list(csv.reader(open(out / "pixels_sensor.csv")))
    assert rows[0][4] == "R [DN]" and len(rows) == 1 + 4 * 2
    assert (out / "pixels_sensor.png").stat().st_size > 5000
    # -o a folder (existing, or new with its trailing slash): the default names in it
    (tmp_path / "px").mkdir()
    for folder in (tmp_path / "px", f"{tmp_path / 'new'}/"):
        assert main(["pixels", str(out), "--pixel", "8,8", "-o", str(folder)]) == 0
        assert (Path(folder) / "pixels_radiance.csv").is_file()
    assert not (tmp_path / "px.csv").exists()
    assert main(["pixels", str(out), "--pixel", "99,1"]) == 2
    assert main(["render", str(tmp_path / "missing.toml"), "-o", str(out)]) == 2


def test_render_error_estimate_and_pass_counts(tmp_path, mi):
    from skyfit_mi.pipeline.sequence import pass_spp
    assert pass_spp(64, "multijitter") == 36 and pass_spp(64, "independent") == 32
    assert pass_spp(1024, "stratified") == 529 and pass_spp(1, "independent") == 1
    m = _render(spec(), tmp_path / "e", tmp_path)
    assert m["render"]["spp_rendered"] == 72
    from skyfit_mi.render.image import read_exr
    sig = read_exr(tmp_path / "e" / m["frames"][1]["sigma"])
    # sensor part alone: sqrt((2% of 4095)^2 + 1/12); the render's error only adds to it
    assert np.all(sig >= np.sqrt((0.02 * 4095) ** 2 + 1 / 12) - 1e-3)


@pytest.mark.parametrize("kind, efficacy", [("overcast", 120.0), ("clear", 150.0)])
def test_sky_given_by_illuminance_uses_its_own_efficacy(tmp_path, kind, efficacy):
    """An overcast sky of 12 000 lx diffuse illuminance is 12 000 / 120 = 100 W m^-2 of
    diffuse irradiance (thesis 4.2.2: overcast efficacy 120 lm/W); a clear one 12 000 / 150."""
    from skyfit_mi.physics.colour import SRGB_LUMINANCE

    raw = spec()
    raw["sky"] = {"type": kind, "diffuse_horizontal_lux": 12000.0}
    s = validate_spec(raw, tmp_path)
    e = s.frames[0].sky.sky_horizontal_irradiance() @ SRGB_LUMINANCE
    assert e == pytest.approx(12000.0 / efficacy, rel=1e-3)


@pytest.mark.parametrize("integrator, rho_s", [("sun_sky_path", 0.3), ("sun_sky_path", 0.0),
                                               ("path", 0.3)])
def test_monte_carlo_error_estimate_matches_the_scatter_of_independent_renders(
        tmp_path, mi, integrator, rho_s):
    """The render's per-pixel standard error (two half-spp passes, 3x3-smoothed) agrees with the
    scatter of the same frame rendered with eight other seeds: the variance ratio is within
    the sampling error of eight renders, and an estimate off by sqrt(2) (the error of one pass,
    not of their mean) would fail.  Glossy and Lambertian discs (whose noise sun_sky_path makes
    small, but no less honestly estimated), and Mitsuba's path."""
    from skyfit_mi.pipeline.sequence import FrameRenderer

    raw = spec(materials={"disc": {"model": "two", "rho_s": rho_s, "sigma_alpha": 0.1}},
               time={"date": "2026-06-21", "times": ["08:00"]}, render__spp=32,
               render__integrator=integrator)
    s = validate_spec(raw, tmp_path)
    renderer = FrameRenderer(s)
    images, sds = [], []
    for seed in range(8):
        renderer.seed = 1000 * seed
        img, sd = renderer.render(s.frames[0])
        images.append(img)
        sds.append(sd)
    images, sds = np.array(images, dtype=float), np.array(sds, dtype=float)
    scatter_var = images.var(axis=0, ddof=1)
    estimate_var = np.mean(sds**2, axis=0)
    # pixels whose 3x3 neighbourhood lies on the disc (the estimate is smoothed over it)
    on = images.mean(axis=0).sum(axis=-1) > 0
    inner = on.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            inner &= np.roll(np.roll(on, dy, axis=0), dx, axis=1)
    inner[[0, -1], :] = inner[:, [0, -1]] = False
    assert inner.sum() >= 50
    ratio = scatter_var[inner].sum() / estimate_var[inner].sum()
    assert 0.75 < ratio < 1.33, ratio
    assert np.all(estimate_var[inner] > 0)


def test_materials_of_equal_parameters_keep_their_own_labels(mi):
    """Mitsuba merges identical objects by default: two materials of equal parameters (a
    photographed scene's placeholders) would share one BSDF id, and one of them would vanish
    from the label image; skyfit loads its scenes with them kept apart."""
    from skyfit_mi.render.labels import label_image
    from skyfit_mi.render.scene import load_xml

    xml = """<scene version="3.0.0">
      <sensor type="perspective"><float name="fov" value="60"/>
        <transform name="to_world"><lookat origin="0,0,5" target="0,0,0" up="0,1,0"/></transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="8"/>
        </film></sensor>
      <bsdf type="diffuse" id="left"><rgb name="reflectance" value="0.5"/></bsdf>
      <bsdf type="diffuse" id="right"><rgb name="reflectance" value="0.5"/></bsdf>
      <shape type="rectangle"><ref id="left"/>
        <transform name="to_world"><translate x="-1.2"/></transform></shape>
      <shape type="rectangle"><ref id="right"/>
        <transform name="to_world"><translate x="1.2"/></transform></shape>
    </scene>"""
    labels, ids = label_image(load_xml(xml))
    assert ids == ["left", "right"] and set(np.unique(labels)) == {0, 1, 2}


def test_a_render_says_when_its_frames_clip_or_its_samples_are_few(tmp_path, mi):
    """An exposure that clips a share of a frame's lit values, and fewer samples per pixel
    than fitting wants, are each said in a line; the render goes on."""
    from skyfit_mi.pipeline.sequence import FEW_SPP, render_sequence

    logs = []
    raw = spec(sensor__exposure=1.0)                  # far above auto: most values clip
    render_sequence(validate_spec(raw, tmp_path), tmp_path / "a", progress=False,
                    log=logs.append)
    assert any("of the lit pixel values at the top code" in m for m in logs), logs
    assert any(m.startswith(f"spp {raw['render']['spp']}: ") for m in logs) \
        == (raw["render"]["spp"] < FEW_SPP)
    logs.clear()
    render_sequence(validate_spec(spec(), tmp_path), tmp_path / "b", progress=False,
                    log=logs.append)
    assert not any("at the top code" in m for m in logs), logs
