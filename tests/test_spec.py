"""Spec validation: every bad spec is refused before frame 0 with a message naming the key."""

import copy
import datetime as dt

import numpy as np
import pytest

from skyfit_mi.pipeline.spec import SpecError, load_spec, thesis_disc_spec, validate_spec

BASE = """
name = "t"
[location]
latitude_deg = 40.0
longitude_deg = 0.0
timezone = "{tz}"
[time]
{time}
[sky]
{sky}
[scene]
file = "{scene}"
[camera]
{camera}
"""
TIME = 'date = "2026-06-21"\ntimes = ["10:00", "12:00"]'
CAMERA = "azimuth_deg = 90\nangle_deg = 45.0\ndistance = 5.0\nwidth = 8\nheight = 8"


def _spec(tmp_path, tz="UTC", time=TIME, sky='type = "clear"', scene="disc.xml", camera=CAMERA):
    p = tmp_path / "s.toml"
    p.write_text(BASE.format(tz=tz, time=time, sky=sky, scene=scene, camera=camera))
    return load_spec(p)


def test_native_toml_dates_and_times_mean_what_quoted_ones_do(tmp_path):
    quoted = _spec(tmp_path, time='times = ["2026-08-16T12:00:00+01:00", "2026-08-16T13:00:00+01:00"]')
    native = _spec(tmp_path, time="times = [2026-08-16T12:00:00+01:00, 2026-08-16T13:00:00+01:00]")
    assert [f.time for f in native.frames] == [f.time for f in quoted.frames]
    assert native.frames[0].time.utcoffset() == dt.timedelta(hours=1)
    assert native.raw["time"]["times"][0] == "2026-08-16T12:00:00+01:00"     # JSON-ready
    local = _spec(tmp_path, time="date = 2026-06-21\nstart = 10:00:00\nend = 11:00:00\n"
                                 "step_minutes = 30")
    assert [f.time.strftime("%H:%M") for f in local.frames] == ["10:00", "10:30", "11:00"]
    assert native.raw == quoted.raw and native.run_id() == quoted.run_id()


@pytest.mark.parametrize("tz, match", [
    ("+25:00", "not a civil time offset"),
    ("+01:75", "not a civil time offset"),
    ("+1:xx", "not an offset"),
    ("Mars/Olympus", "not a time zone"),
])
def test_bad_time_zones(tmp_path, tz, match):
    with pytest.raises(SpecError, match=match):
        _spec(tmp_path, tz=tz)


@pytest.mark.parametrize("time, match", [
    ('date = "2026-06-21"\ntimes = ["12:00", "10:00"]', "must increase: .* comes after"),
    ('date = "2026-06-21"\ntimes = ["12:00", "12:00"]', "must increase: .* repeats"),
    ('times = ["2026-06-21T12:00+25:00"]', "is not a time"),
    ('date = "2026-06-21"\ntimes = ["25:00"]', "is not a time"),
    ('date = "2026-06-21"\ntimes = ["12:00:99"]', "'12:00:99' is not a time; write 'HH:MM'"),
    ('date = "2026-06-21"\ntimes = ["12:5"]', "'12:5' is not a time"),
    ('date = "2026-06-21"\ntimes = ["12:60"]', "'12:60' is not a time"),
    ('date = "2026-06-21"\ntimes = ["12:00:00:00"]', "is not a time"),
    ('date = "2026-06-21"\ntimes = ["１２:００"]', "is not a time"),
    ('date = "2026-06-21"\nstart = "6:00"\nend = "10:00"\nstep_minutes = 60', "start '6:00'"),
    ('date = "2026-06-21"\nstart = "12:00"\nend = "10:00"\nstep_minutes = 5', "before start"),
])
def test_bad_times(tmp_path, time, match):
    with pytest.raises(SpecError, match=match):
        _spec(tmp_path, time=time)


def test_a_time_s_seconds_are_kept(tmp_path):
    spec = _spec(tmp_path, time='date = "2026-06-21"\ntimes = ["10:00:30", "12:00"]')
    assert [f"{f.time:%H:%M:%S}" for f in spec.frames] == ["10:00:30", "12:00:00"]


def test_a_day_across_a_clock_change_steps_in_real_time_and_names_lost_or_twice_hours(tmp_path):
    """Across a daylight-saving change start/end/step_minutes steps in real time (the clocks
    read 01:30 BST, 01:00 GMT, 01:30 GMT: every 30 minutes); a wall time the clocks skip or
    pass twice is refused, naming it, until given with its offset."""
    day = _spec(tmp_path, tz="Europe/London", time='date = "2026-10-25"\nstart = "00:30"\n'
                'end = "02:30"\nstep_minutes = 30')
    t = [f.time for f in day.frames]
    assert [b.timestamp() - a.timestamp() for a, b in zip(t, t[1:])] == [1800.0] * (len(t) - 1)
    assert [f"{x:%H:%M%z}" for x in t] == ["00:30+0100", "01:00+0100", "01:30+0100",
                                           "01:00+0000", "01:30+0000", "02:00+0000",
                                           "02:30+0000"]
    for time, match in (('date = "2026-10-25"\ntimes = ["01:30"]', "'01:30' happens twice in "
                         "Europe/London"),
                        ('date = "2026-03-29"\ntimes = ["01:30"]', "'01:30' does not exist in "
                         "Europe/London"),
                        ('date = "2026-03-29"\nstart = "01:30"\nend = "03:00"\n'
                         'step_minutes = 30', "start '01:30' does not exist")):
        with pytest.raises(SpecError, match=match):
            _spec(tmp_path, tz="Europe/London", time=time)
    given = _spec(tmp_path, tz="Europe/London", time='times = ["2026-10-25T01:30+00:00"]')
    assert given.frames[0].time.utcoffset() == dt.timedelta(0)


def test_phi_only_on_an_intermediate_sky(tmp_path):
    for kind in ("clear", "overcast"):
        with pytest.raises(SpecError, match="phi .* belongs to an intermediate sky"):
            _spec(tmp_path, sky=f'type = "{kind}"\nphi = 0.5')
    assert _spec(tmp_path, sky='type = "intermediate"\nphi = 0.5').frames


@pytest.mark.parametrize("camera, match", [
    ("origin = [0, 0, 0]\nwidth = 8\nheight = 8", "is its target"),
    ("origin = [0, 0, 5]\nup = [0, 0, 1]\nwidth = 8\nheight = 8", "lies along its view"),
    ("origin = [nan, 0, 5]\nwidth = 8\nheight = 8", r"origin\[0\] must be a number"),
    ("origin = [1, 0, 5]\nup = [0, 0, 0]\nwidth = 8\nheight = 8", "up vector is zero"),
    (CAMERA + "\nfov_deg = 0", "fov_deg = 0 is outside"),
    (CAMERA + "\nfov_deg = nan", "fov_deg must be a number"),
    ("matrix = [[1,0,0,0],[0,1,0,0],[0,0,0,0],[0,0,0,1]]", "singular"),
    ("matrix = [[1,0,0],[0,1,0]]", "4 rows of 4 numbers"),
    (CAMERA + "\npose_sd_deg = -0.5", r"pose_sd_deg azimuth = -0.5 deg is outside .*\[0, 10\]"),
    (CAMERA + "\npose_sd_deg = {roll = true}", "pose_sd_deg roll must be a number"),
    (CAMERA + '\npose_sd_deg = "1"', "pose_sd_deg azimuth must be a number"),
])
def test_degenerate_cameras(tmp_path, camera, match):
    with pytest.raises(SpecError, match=match):
        _spec(tmp_path, camera=camera)


def test_straight_down_camera_takes_north_as_up(tmp_path):
    s = _spec(tmp_path, camera="origin = [0, 0, 5]\nwidth = 8\nheight = 8")
    assert s.frames


def test_malformed_scene_xml_and_unknown_material(tmp_path):
    (tmp_path / "bad.xml").write_text("<scene version='3.0.0'><bsdf type='ward' id='x'>")
    with pytest.raises(SpecError, match="bad.xml is not valid XML"):
        _spec(tmp_path, scene="bad.xml")
    raw = thesis_disc_spec("t", {"model": "two", "rho_s": 0.5, "sigma_alpha": 0.1})
    raw["materials"] = {"nosuch": raw["materials"]["disc"]}
    with pytest.raises(SpecError, match="'nosuch' is not a ward material of disc.xml"):
        validate_spec(raw)


def test_measured_levels_scale_sky_and_ground(tmp_path):
    s = _spec(tmp_path, sky='type = "clear"\ndiffuse_horizontal_W_m2 = 50.0\n'
                            'direct_normal_W_m2 = 400.0')
    sky = s.frames[0].sky
    albedo = sky.info.get("ground_albedo", 0.2)
    np.testing.assert_allclose(sky.ground, albedo * sky.horizontal_irradiance() / np.pi, rtol=1e-3)


def _fit_json(path, **changes):
    import json
    result = {"region": "disc", "model": "colour", "normalisation": "balanced",
              "parameters": {"C_r": 0.6, "C_g": 0.4, "C_b": 0.2, "rho_s": 0.08,
                             "sigma_alpha": 0.1}, **changes}
    result.setdefault("intervals", {k: {"95": [v, v]} for k, v in result["parameters"].items()})
    path.write_text(json.dumps(result))
    return path.name


def test_a_fit_json_is_a_spec_material(tmp_path):
    """``materials.disc = { fit = "fit_disc.json" }`` takes the fit's model, normalisation and
    parameters; the resolved materials say where each came from."""
    from skyfit_mi.render.scene_xml import resolve_materials
    raw = thesis_disc_spec("t", {"model": "two", "rho_s": 0.5, "sigma_alpha": 0.1})
    raw["materials"] = {"disc": {"fit": _fit_json(tmp_path / "fit_disc.json")}}
    spec = validate_spec(raw, tmp_path)
    m = spec.materials["disc"]
    assert m["model"] == "colour" and m["normalisation"] == "balanced"
    assert m["C"] == [0.6, 0.4, 0.2] and m["rho_s"] == 0.08 and m["sigma_alpha"] == 0.1
    assert m["source"] == "fit fit_disc.json (region disc)"
    _, mats = resolve_materials(spec.scene_file, spec.materials)
    assert mats["disc"]["source"].startswith("fit ")
    raw["materials"] = {"disc": {"model": "two", "rho_s": 0.5, "sigma_alpha": 0.1}}
    _, mats = resolve_materials(validate_spec(raw, tmp_path).scene_file,
                                validate_spec(raw, tmp_path).materials)
    assert mats["disc"]["source"] == "spec"


@pytest.mark.parametrize("fit, match", [
    ({"fit": "missing.json"}, "missing.json does not exist"),
    ({"fit": "fit_disc.json", "rho_s": 0.1}, "either fit = .* not both"),
    ({"fit": "not_json.json"}, "not readable JSON"),
    ({"fit": "other.json"}, "is not a fit result of `skyfit fit`"),
    ({"fit": "nan.json"}, "not finite numbers"),
])
def test_bad_fit_materials(tmp_path, fit, match):
    _fit_json(tmp_path / "fit_disc.json")
    (tmp_path / "not_json.json").write_text("{oops")
    _fit_json(tmp_path / "other.json", model="raw")
    _fit_json(tmp_path / "nan.json", model="two",
              parameters={"rho_s": float("nan"), "sigma_alpha": 0.1},
              intervals={"rho_s": {"95": [0.0, 1.0]}, "sigma_alpha": {"95": [0.0, 0.5]}})
    raw = thesis_disc_spec("t", {"model": "two", "rho_s": 0.5, "sigma_alpha": 0.1})
    raw["materials"] = {"disc": fit}
    with pytest.raises(SpecError, match=match):
        validate_spec(raw, tmp_path)


# ---- the Perez all-weather sky as a spec sky type (issue 15) -------------------------------

def test_perez_sky_type_is_the_physics_perez_sky(tmp_path):
    from skyfit_mi.physics.perez import perez_sky
    from skyfit_mi.physics.sky import SRGB_LUMINANCE
    spec = _spec(tmp_path, sky='type = "perez"\ndiffuse_horizontal_W_m2 = 110\n'
                               'direct_normal_W_m2 = 720\ncct = 9000')
    f = spec.frames[1]
    ref = perez_sky(f.sun_zenith_deg, f.sun_azimuth_deg, f.time.timetuple().tm_yday,
                    dhi=110, dni=720)
    d = np.array([[0.0, 0.0, 1.0], [0.6, -0.3, 0.5], [-0.2, 0.9, 0.1]])
    np.testing.assert_allclose(f.sky.sky_radiance(d) @ SRGB_LUMINANCE, ref.radiance(d), rtol=1e-12)
    assert float(f.sky.sky_horizontal_irradiance() @ SRGB_LUMINANCE) == pytest.approx(110, rel=1e-9)
    assert float(f.sky.sun_horizontal_irradiance() @ SRGB_LUMINANCE) == pytest.approx(
        720 * np.cos(np.radians(f.sun_zenith_deg)), rel=1e-9)
    assert f.sky.info["kind"] == "perez" and f.sky.info["epsilon"] == pytest.approx(
        ref.info["epsilon"])


def test_perez_sky_from_an_irradiance_csv_is_interpolated_in_time(tmp_path):
    (tmp_path / "irr.csv").write_text("time,ghi\n2026-06-21T09:00,500\n2026-06-21T11:00,700\n"
                                      "2026-06-21T13:00,900\n")
    spec = _spec(tmp_path, sky='type = "perez"\nirradiance_file = "irr.csv"')
    # 10:00 lies halfway between 500 and 700; the frame's GHI is split by erbs (the default)
    assert spec.frames[0].sky.info["ghi_w_m2"] == pytest.approx(600.0)
    assert spec.frames[1].sky.info["ghi_w_m2"] == pytest.approx(800.0)
    assert spec.frames[0].sky.info["decomposition"] == "erbs"
    g = spec.frames[1].sky.horizontal_irradiance()
    assert float(g @ np.array([0.2126, 0.7152, 0.0722])) == pytest.approx(800.0, rel=1e-6)


def test_perez_sky_from_a_tmy3_weather_file(tmp_path):
    import shutil
    import pvlib
    from pathlib import Path
    src = Path(pvlib.__file__).parent / "data" / "723170TYA.CSV"      # Greensboro NC, TMY3
    shutil.copy(src, tmp_path / "tmy.csv")
    spec = _spec(tmp_path, tz="-05:00", sky='type = "perez"\nirradiance_file = "tmy.csv"')
    import pvlib.iotools
    df, _ = pvlib.iotools.read_tmy3(str(src), coerce_year=2026)
    # 10:00 is the middle of the hours ending 10:00 and 11:00 (their values at 9:30 and 10:30)
    row = df.loc["2026-06-21 10:00-05:00":"2026-06-21 11:00-05:00"]
    info = spec.frames[0].sky.info
    assert info["dhi_w_m2"] == pytest.approx(row["dhi"].mean(), rel=1e-9)
    assert info["dni_w_m2"] == pytest.approx(row["dni"].mean(), rel=1e-9)


# ---- the CIE S 011 general sky as a spec sky type (issue 15) -------------------------------

def test_cie_general_type_12_is_the_thesis_clear_sky(tmp_path):
    from skyfit_mi.physics.sky import SRGB_LUMINANCE
    general = _spec(tmp_path, sky='type = "cie_general"\ncie_type = 12')
    clear = _spec(tmp_path, sky='type = "clear"')
    rng = np.random.default_rng(3)
    d = rng.normal(size=(500, 3))
    d[:, 2] = np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    for g, c in zip(general.frames, clear.frames):
        # the thesis's 0.91 is 1 - 10 exp(-3 pi / 2) to 2e-4 (eq. 4.13)
        np.testing.assert_allclose(g.sky.sky_radiance(d), c.sky.sky_radiance(d), rtol=3e-4)
        np.testing.assert_allclose(g.sky.sun_radiance, c.sky.sun_radiance, rtol=1e-12)
        np.testing.assert_allclose(g.sky.ground, c.sky.ground, rtol=3e-4)
        assert g.sky.info["kind"] == "cie_general"
        assert float(g.sky.sky_horizontal_irradiance() @ SRGB_LUMINANCE) == pytest.approx(
            float(c.sky.sky_horizontal_irradiance() @ SRGB_LUMINANCE), rel=3e-4)


def test_cie_general_groups_follow_the_standard_and_measured_light(tmp_path):
    from skyfit_mi.physics import cie_general as cg
    from skyfit_mi.physics.sky import SRGB_LUMINANCE
    spec = _spec(tmp_path, sky='type = "cie_general"\ngradation = 5.98\nindicatrix = 4\n'
                               'zenith_luminance = 4000\ncct = 9000')
    f = spec.frames[1]
    rng = np.random.default_rng(4)
    d = rng.normal(size=(500, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.02
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    luminance = f.sky.sky_radiance(d) @ SRGB_LUMINANCE * 150.0       # default efficacy
    want = 4000.0 * cg.pattern(d, f.sky.sun_direction, cg.group_parameters(5.98, 4))
    np.testing.assert_allclose(luminance, want, rtol=1e-6)       # cct's luminance is 1 to 2e-7
    measured = _spec(tmp_path, sky='type = "cie_general"\ncie_type = 7\n'
                                   'diffuse_horizontal_W_m2 = 150\ndirect_normal_W_m2 = 300')
    f = measured.frames[0]
    assert float(f.sky.sky_horizontal_irradiance() @ SRGB_LUMINANCE) == pytest.approx(150, rel=1e-9)
    assert float(f.sky.sun_horizontal_irradiance() @ SRGB_LUMINANCE) == pytest.approx(
        300 * np.cos(np.radians(f.sun_zenith_deg)), rel=1e-9)


def test_cie_general_sky_survives_the_manifest(tmp_path):
    # The manifest records the sky's terms, not its kind's recipe: fit and relight rebuild it.
    from skyfit_mi.pipeline.manifest import frame_sky, illumination_record
    spec = _spec(tmp_path, sky='type = "cie_general"\ngradation = 5.98\nindicatrix = 4')
    sky = spec.frames[0].sky
    back = frame_sky({"index": 0, "illumination": illumination_record(sky, tmp_path)}, tmp_path)
    d = np.array([[0.0, 0.0, 1.0], [0.6, -0.3, 0.5], [-0.2, 0.9, 0.1], [0.3, 0.3, -0.5]])
    np.testing.assert_array_equal(back.radiance(d), sky.radiance(d))


@pytest.mark.parametrize("sky, message", [
    ('type = "cie_general"', "needs either cie_type"),
    ('type = "cie_general"\ncie_type = 12\ngradation = 5', "not both"),
    ('type = "cie_general"\ngradation = 5', "both gradation and indicatrix"),
    ('type = "cie_general"\ncie_type = 16', "does not exist"),
    ('type = "cie_general"\ngradation = 7\nindicatrix = 4', "gradation group"),
    ('type = "cie_general"\ncie_type = 12\nefficacy_overcast = 120', "drop efficacy_overcast"),
    ('type = "clear"\ncie_type = 12', "only type = 'cie_general'"),
    ('type = "cie_general"\ncie_type = "12"', "cie_type"),
])
def test_bad_cie_general_specs_are_refused_by_key(tmp_path, sky, message):
    with pytest.raises(SpecError, match=message):
        _spec(tmp_path, sky=sky)


@pytest.mark.parametrize("sky, message", [
    ('type = "perez"', "needs measured irradiance"),
    ('type = "clear"\nglobal_horizontal_W_m2 = 500', "belong to a Perez sky"),
    ('type = "perez"\nirradiance_file = "none.csv"', "not found"),
    ('type = "perez"\nirradiance_file = "short.csv"', "lies outside it"),
    ('type = "clear"\nirradiance_file = "short.csv"', "scaled by dhi and dni"),
    ('type = "perez"\nglobal_horizontal_W_m2 = -5', "global horizontal irradiance"),
])
def test_bad_perez_specs_are_refused_by_key(tmp_path, sky, message):
    (tmp_path / "short.csv").write_text("time,ghi\n2026-06-21T09:00,500\n2026-06-21T10:00,600\n")
    with pytest.raises(SpecError, match=message):
        _spec(tmp_path, sky=sky)


def test_the_pose_sd_reads_as_azimuth_and_angle_or_a_table(tmp_path):
    assert _spec(tmp_path, camera=CAMERA + "\npose_sd_deg = 0.5").camera["pose_sd_deg"] == {
        "azimuth": 0.5, "angle": 0.5, "roll": 0.0}
    assert _spec(tmp_path, camera=CAMERA + "\npose_sd_deg = {roll = 1}").camera[
        "pose_sd_deg"] == {"azimuth": 0.0, "angle": 0.0, "roll": 1.0}
    assert "pose_sd_deg" not in _spec(tmp_path).camera


# ---- reading the file: its encoding, and a folder for a file ---------------------------------

def _spec_text():
    return BASE.format(tz="UTC", time=TIME, sky='type = "clear"', scene="disc.xml", camera=CAMERA)


def _write(path, data):
    path.write_bytes(data)
    return path


def test_a_spec_saved_with_a_byte_order_mark_reads_as_without(tmp_path):
    """Windows Notepad starts a UTF-8 file with a byte-order mark; TOML and JSON alike."""
    plain = load_spec(_write(tmp_path / "plain.toml", _spec_text().encode()))
    bom = load_spec(_write(tmp_path / "bom.toml", b"\xef\xbb\xbf" + _spec_text().encode()))
    assert bom.raw == plain.raw and bom.run_id() == plain.run_id()
    import json
    doc = json.dumps(plain.raw).encode()
    assert load_spec(_write(tmp_path / "bom.json", b"\xef\xbb\xbf" + doc)).raw == plain.raw


def test_a_spec_or_gensky_file_not_utf8_is_refused_naming_it(tmp_path):
    latin1 = ("# 40\xb0 N\n" + _spec_text()).encode("latin-1")
    with pytest.raises(SpecError, match=r"spec file '.*s.toml' is not UTF-8 text \(byte 0xb0 "
                                        r"at offset 4\); save it as UTF-8\.$"):
        load_spec(_write(tmp_path / "s.toml", latin1))
    _write(tmp_path / "sky.rad", b"# gensky 6 21 12 +s -a 40\xb0\n")
    with pytest.raises(SpecError, match=r"\[sky\] gensky_file '.*sky.rad' is not UTF-8 text .*"
                                        "save it as UTF-8"):
        _spec(tmp_path, sky='gensky_file = "sky.rad"')


def test_a_scene_xml_in_latin1_gets_a_run_id(tmp_path):
    """An XML may declare its own encoding; the run's hash takes its bytes as they are, and a
    UTF-8 scene's hash is its text's."""
    from skyfit_mi.pipeline.spec import SCENES_DIR
    xml = (SCENES_DIR / "disc.xml").read_text()
    utf8 = _spec(tmp_path).run_id()
    (tmp_path / "disc.xml").write_bytes(b'<?xml version="1.0" encoding="ISO-8859-1"?>\n'
                                        b"<!-- 40\xb0 N -->\n" + xml.encode())
    latin1 = _spec(tmp_path).run_id()
    assert len(latin1) == 16 and latin1 != utf8
    (tmp_path / "disc.xml").write_text(xml)
    assert _spec(tmp_path).run_id() == utf8


def test_a_folder_given_as_the_spec_is_named_a_folder(tmp_path):
    with pytest.raises(SpecError, match=r"spec '.*' is a folder; give a spec file \(.toml or "
                                        r"\.json\)\.$"):
        load_spec(tmp_path)
    (tmp_path / "day.toml").write_text(_spec_text())
    with pytest.raises(SpecError, match="is a folder; .*, such as .*day.toml.$"):
        load_spec(tmp_path)
    with pytest.raises(SpecError, match="does not exist"):
        load_spec(tmp_path / "nosuch.toml")


def test_a_spec_error_names_the_language_it_was_read_in(tmp_path):
    for name, language in (("s.toml", "TOML"), ("s.json", "JSON"), ("S.JSON", "JSON")):
        with pytest.raises(SpecError, match=f"{name} is not valid {language}: "):
            load_spec(_write(tmp_path / name, b"{oops"))


def test_an_integer_beyond_python_s_digit_limit_is_a_spec_error(tmp_path):
    for name in ("big.json", "big.toml"):
        text = '{"name": %s}' % ("9" * 5000) if name.endswith("json") else "name = " + "9" * 5000
        with pytest.raises(SpecError, match=f"{name} holds a number of over 4300 digits"):
            load_spec(_write(tmp_path / name, text.encode()))


# ---- [[sky]]: one table per frame, in order or each at its frame's time ----------------------

def _day_of_skies(tmp_path, times, *entries):
    """A spec of frames at ``times`` on 21 June and a [[sky]] table of each of ``entries``."""
    p = tmp_path / "s.toml"
    p.write_text(BASE.replace("[sky]\n{sky}", "{sky}").format(
        tz="UTC", time=f'date = "2026-06-21"\ntimes = {times!r}'.replace("'", '"'),
        sky="\n".join(f"[[sky]]\n{e}" for e in entries), scene="disc.xml", camera=CAMERA))
    return load_spec(p)


def test_timed_sky_entries_go_to_their_frames_whatever_their_order(tmp_path):
    spec = _day_of_skies(tmp_path, ["09:00", "12:00", "15:00"],
                         'type = "overcast"\ntime = "15:00"', 'type = "clear"\ntime = "09:00"',
                         'type = "intermediate"\nphi = 0.5\ntime = "12:00"')
    assert [f.sky.info["kind"] for f in spec.frames] == ["clear", "intermediate", "overcast"]


@pytest.mark.parametrize("entries, match", [
    (['type = "clear"', 'type = "clear"', 'type = "overcast"\ntime = "15:00"'],
     r"\[\[sky\]\] gives a time in entry 2 but not in entries 0 and 1; give every entry its "
     r"frame's time, or none"),
    (['type = "clear"\ntime = "09:00"', 'type = "clear"\ntime = "12:00"',
      'type = "clear"\ntime = "15:00"', 'type = "overcast"\ntime = "18:00"'],
     r"entry 3 has time '18:00', which is no frame's \(\[time\] gives 09:00, 12:00, 15:00\); "
     "drop the entry"),
    (['type = "clear"\ntime = "09:00"', 'type = "clear"\ntime = "12:00"',
      'type = "clear"\ntime = "15:00"', 'type = "overcast"\ntime = "12:00:00"'],
     "entries 1 and 3 both have time '12:00:00'; give each frame's sky once"),
    (['type = "clear"\ntime = "09:00"\nframes = []', 'type = "clear"', 'type = "clear"'],
     "unknown key.* frames in \\[sky\\]"),
])
def test_sky_entries_whose_times_do_not_match_the_frames_are_refused(tmp_path, entries, match):
    with pytest.raises(SpecError, match=match):
        _day_of_skies(tmp_path, ["09:00", "12:00", "15:00"], *entries)


@pytest.mark.parametrize("sky, match", [
    ([1, 2, 3], r"\[\[sky\]\] entry 0 is 1, not a table"),
    ([], r"\[\[sky\]\] must be a list of tables, one per frame; got \[\]"),
    ({"type": "clear", "frames": 5}, r"\[sky\] frames must be a list of tables, one per frame; "
                                     "got 5"),
    ({"frames": [{"type": "clear"}, "overcast"]}, r"\[sky\] frames entry 1 is 'overcast'"),
    ({"type": "clear", "time": "12:00"}, r"\[sky\] time: one \[sky\] table is every frame's"),
])
def test_a_sky_list_of_other_than_tables_is_refused(sky, match):
    raw = thesis_disc_spec("t", {"model": "two", "rho_s": 0.5, "sigma_alpha": 0.1})
    raw["time"] = {"date": "2026-06-21", "times": ["12:00"]}
    raw["sky"] = sky
    with pytest.raises(SpecError, match=match):
        validate_spec(raw)


# ---- wrong types at every key: refused in one line, never a crash later ----------------------

@pytest.mark.parametrize("section, key, value, match", [
    ("materials", None, [1], r"\[materials\] must be a table of tables"),
    ("materials", None, None, r"\[materials\] must be a table of tables"),
    ("materials", "disc", {"model": "colour", "C": ["a", 0.4, 0.3], "rho_s": 0.1,
                           "sigma_alpha": 0.1}, r"\[materials.disc\] C\[0\] must be a number, "
                                                "got 'a'; write it without quotes"),
    ("materials", "disc", {"model": "two", "rho_s": "0.1", "sigma_alpha": 0.1},
     r"\[materials.disc\] rho_s must be a number, got '0.1'"),
    ("materials", "disc", {"model": "two", "rho_s": [0.1], "sigma_alpha": 0.1},
     r"\[materials.disc\] rho_s must be a number, got \[0.1\]"),
    ("materials", "disc", {"model": "two", "rho_s": 0.1, "sigma_alpha": None},
     r"\[materials.disc\] sigma_alpha must be a number, got None"),
    ("materials", "disc", {"model": ["two"], "rho_s": 0.1, "sigma_alpha": 0.1},
     r"\[materials.disc\] unknown Ward model \['two'\]"),
    ("sensor", "gamma", "2.2", r"\[sensor\] gamma must be a number, got '2.2'"),
    ("sensor", "noise_percent", "1", r"\[sensor\] noise_percent must be a number, got '1'"),
    ("sensor", "bits", 8.5, r"\[sensor\] bits must be a whole number"),
    ("sensor", "cos4", "false", r"\[sensor\] cos4 must be true or false"),
    ("location", "latitude_deg", "40", r"\[location\] latitude_deg must be a number, got '40'"),
    ("location", "timezone", None, r"\[location\] timezone must be text, got None"),
    ("camera", "width", -25000000000000000000, r"\[camera\] width = -25000000000000000000 is "
                                               r"outside \[1, 16384\]"),
    ("camera", "fov_deg", 10**400, r"\[camera\] fov_deg is a whole number of 401 digits, "
                                   r"beyond any float; give a value in \[0.1, 170\]"),
    ("camera", "pose_sd_deg", -(2**63) - 1, r"\[camera\] pose_sd_deg azimuth = -9.22337e\+18 deg "
                                            "is outside"),
    ("camera", "pose_sd_deg", {"roll": 2**64}, r"pose_sd_deg roll = 1.84467e\+19 deg is outside"),
    ("scene", "ground_albedo", None, r"\[scene\] ground_albedo must be a number, got None"),
    ("time", "date", 20260621, r"\[time\] date 20260621 is not a date; write 'YYYY-MM-DD'"),
    ("time", "times", 5, r"\[time\] times must be a non-empty list"),
    ("time", "times", [1200], r"\[time\] time 1200 is not a time"),
])
def test_wrong_types_are_refused_naming_the_key(section, key, value, match):
    raw = thesis_disc_spec("t", {"model": "two", "rho_s": 0.5, "sigma_alpha": 0.1})
    raw["time"] = {"date": "2026-06-21", "times": ["12:00"]}
    if key is None:
        raw[section] = value
    else:
        raw[section][key] = value
    with pytest.raises(SpecError, match=match):
        validate_spec(raw)


def test_a_time_list_of_numbers_without_a_date_is_a_spec_error():
    raw = thesis_disc_spec("t", {"model": "two", "rho_s": 0.5, "sigma_alpha": 0.1})
    raw["time"] = {"times": 5}
    with pytest.raises(SpecError, match=r"\[time\] times must be a non-empty list"):
        validate_spec(raw)


def _example_spec():
    import tomllib
    from skyfit_mi.pipeline.spec import SCENES_DIR
    return tomllib.loads((SCENES_DIR / "specs" / "disc_clear_east.toml").read_text()), \
        SCENES_DIR / "specs"


def _key_paths():
    """Every key of the example spec, at every depth, and every key the schema allows."""
    from skyfit_mi.pipeline.spec import _SCHEMA

    def walk(d, at):
        for k, v in d.items():
            yield at + (k,)
            if isinstance(v, dict):
                yield from walk(v, at + (k,))
    raw, _ = _example_spec()
    paths = set(walk(raw, ()))
    paths |= {(sec, k) for sec, keys in _SCHEMA.items() for k in (keys or ())}
    paths |= {("materials", "disc", k) for k in ("R", "C", "rho_d", "normalisation", "fit")}
    return sorted(paths)


def _wrong_values():
    from hypothesis import strategies as st
    scalars = st.one_of(
        st.none(), st.booleans(), st.integers(), st.sampled_from([-2.5e19, 10**400, -(10**30)]),
        st.floats(), st.text(max_size=8),
        st.sampled_from(["0.1", "2.2", "1", "40", "12:00", "12:00:99", "auto", "clear", "disc"]))
    return st.one_of(scalars, st.lists(scalars, max_size=4),
                     st.dictionaries(st.text(max_size=4), scalars, max_size=2))


def test_a_spec_with_wrong_types_anywhere_is_refused_in_one_line_or_works():
    """Hypothesis: copies of disc_clear_east.toml with one to three keys (at any depth, or any
    the schema allows) given a value of another type; validate_spec raises only SpecError, in
    one line, or gives a spec whose sensor and materials hold numbers where numbers belong."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st
    from skyfit_mi.errors import SkyfitError

    example, base_dir = _example_spec()
    sun = {f.time.isoformat(): (f.sun_zenith_deg, f.sun_azimuth_deg)
           for f in validate_spec(example, base_dir).frames}         # pvlib once

    @settings(max_examples=200, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow])
    @given(st.lists(st.tuples(st.sampled_from(_key_paths()), _wrong_values()), min_size=1,
                    max_size=3))
    def check(changes):
        raw = copy.deepcopy(example)
        for path, value in changes:
            at = raw
            for k in path[:-1]:
                at = at.setdefault(k, {}) if isinstance(at.get(k, {}), dict) else {}
            at[path[-1]] = value
        try:
            spec = validate_spec(raw, base_dir, sun=sun)
        except SkyfitError as exc:
            assert isinstance(exc, SpecError) and str(exc) and "\n" not in str(exc)
            return
        for k in ("gamma", "noise_percent", "bits"):
            assert isinstance(spec.sensor[k], (int, float)), spec.sensor
        for m in spec.materials.values():
            for k, v in m.items():
                if k not in ("model", "normalisation", "source"):
                    assert all(isinstance(x, (int, float)) for x in np.ravel(v)), m

    check()
