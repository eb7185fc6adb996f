"""Lab lights (a photometric-stereo rig): frames by index, with no date, time or site, in the
spec, a render, its manifest and pixels, and observation tables (a ``frame`` column); each
table row checked from its own view; saturated flags read.  The whole chain (table, fit,
relight, chi2map) runs on the example of scenes/lab in tests/test_lab_example.py."""
import csv
import json
import re
import time

import numpy as np
import pytest
from scipy.stats import chi2 as chi2_dist

from skyfit_mi.cli import main
from skyfit_mi.errors import SkyfitError
from skyfit_mi.pipeline.manifest import ManifestError, load_manifest, validate_manifest
from skyfit_mi.pipeline.spec import SpecError, validate_spec

LIGHTS = [(15.0, 0.0), (30.0, 120.0), (45.0, 240.0), (60.0, 0.0)]
CAMERA = {"azimuth_deg": 180, "angle_deg": 20.0, "distance": 4.0, "fov_deg": 24.0, "width": 8,
          "height": 8}


def _lab(scene="disc.xml", camera=CAMERA, lights=LIGHTS, **extra):
    """A raw spec of lab lights (no [time], no [location])."""
    return {"name": "lab", "scene": {"file": scene}, "camera": dict(camera),
            "sky": [{"type": "directional", "zenith_deg": z, "azimuth_deg": a,
                     "irradiance_W_m2": 100} for z, a in lights],
            "render": {"spp": 4}, **extra}


def _write(tmp, raw, name="lab.json"):
    p = tmp / name
    p.write_text(json.dumps(raw))
    return p


def test_lab_lights_are_frames_by_index_without_time_or_site(tmp_path):
    from skyfit_mi.pipeline.sequence import frame_record

    spec = validate_spec(_lab(), tmp_path)
    assert spec.lab and [f.index for f in spec.frames] == [0, 1, 2, 3]
    assert all(f.time is None for f in spec.frames)
    assert [f.sun_zenith_deg for f in spec.frames] == pytest.approx([z for z, _ in LIGHTS])
    assert [f.sun_azimuth_deg for f in spec.frames] == pytest.approx([a for _, a in LIGHTS])
    rec = frame_record(spec.frames[1], 0, tmp_path)
    assert "time" not in rec and "time_utc" not in rec
    assert rec["illumination"]["kind"] == "directional"
    # a day's spec is unchanged: times, and the sun from the site
    day = validate_spec({**_lab(), "location": {"latitude_deg": 40, "longitude_deg": 0,
                                                "timezone": "UTC"},
                         "time": {"date": "2026-06-21", "times": ["09:00", "10:00", "11:00",
                                                                  "12:00"]}}, tmp_path)
    assert not day.lab and day.frames[2].time.hour == 11


@pytest.mark.parametrize("change, message", [
    ({"sky": [{"type": "clear"}, {"type": "clear"}]},
     r"no \[time\] section, but \[\[sky\]\] 0 is a clear sky"),
    ({"sky": None}, r"no \[time\] section; it is required unless every \[\[sky\]\] is a "
                    "directional"),
    ({"location": {"latitude_deg": 40, "longitude_deg": 0, "timezone": "UTC"}},
     r"has \[location\] but no \[time\]"),
    ({"sky": [{"type": "directional", "zenith_deg": 20, "azimuth_deg": 0,
               "irradiance_W_m2": 1, "time": "12:00"}]}, "frames by index, in the order listed"),
])
def test_bad_lab_specs_are_refused_in_one_line(tmp_path, change, message):
    raw = {**_lab(), **change}
    raw = {k: v for k, v in raw.items() if v is not None}
    with pytest.raises(SpecError, match=message) as exc:
        validate_spec(raw, tmp_path)
    assert "\n" not in str(exc.value)
    assert main(["render", str(_write(tmp_path, raw)), "-o", str(tmp_path / "out"),
                 "--quiet"]) == 2


def test_a_rendered_lab_sequence_has_no_time_and_a_days_frame_must(tmp_path, mi):
    from skyfit_mi.pipeline.pixels import write_pixels
    from skyfit_mi.pipeline.sequence import render_sequence

    render_sequence(validate_spec(_lab(), tmp_path), tmp_path / "seq", progress=False,
                    log=lambda *a: None)
    doc, _ = load_manifest(tmp_path / "seq")
    assert "location" not in doc and [f["status"] for f in doc["frames"]] == ["rendered"] * 4
    assert not any("time" in f for f in doc["frames"])
    csv_path, _ = write_pixels(tmp_path / "seq", [(4, 4)], tmp_path / "px")
    rows = list(csv.DictReader(csv_path.open()))
    assert [r["frame"] for r in rows] == ["0", "1", "2", "3"] and {r["time"] for r in rows} == {""}
    # without a time, only a lab light (directional) identifies a frame
    doc["frames"][0]["illumination"] = {"kind": "gensky", "text": "# gensky"}
    with pytest.raises(ManifestError, match="'time' is a required property"):
        validate_manifest(doc)


# ---- tables of lab lights: bad input -----------------------------------------------------

def _table(tmp, rows, head="frame,region,r,g,b,sigma", name="obs.csv"):
    p = tmp / name
    p.write_text(head + "\n" + "\n".join(rows) + "\n")
    return p


FRAMES = ["0,disc,1,1,1,0.1", "1,disc,2,2,2,0.1", "2,disc,1,1,1,0.1"]


@pytest.mark.parametrize("rows, head, message", [
    (["0,disc,1,1,1,0.1", "-1,disc,1,1,1,0.1"], None, "frame = '-1' is not a frame index"),
    (["0,disc,1,1,1,0.1", "1.5,disc,1,1,1,0.1"], None, "frame = '1.5' is not a frame index"),
    (["0,disc,1,1,1,0.1", "0,disc,2,2,2,0.1"], None, "in frame 0 is measured again"),
    (["0,disc,1,1,1,0.1"], "region,r,g,b,sigma", "no column time .or frame."),
    (["0,disc,1,1,1,0.1,yes"], "frame,region,r,g,b,sigma,saturated", "saturated = 'yes'"),
    (["0,disc,0,1,1,0.1,1"], "frame,region,r,g,b,sigma,saturated",
     "a saturated value must be the positive level"),
    (["0,disc,1,1,1,0.1,1,0,0,0"], "frame,region,r,g,b,sigma,saturated,saturated_r,saturated_g,"
                                   "saturated_b", "give saturated .* not both"),
    (["0,disc,1,0.1,1"], "frame,region,luminance,sigma,saturated_r", "not both"),
])
def test_bad_lab_tables_are_refused_in_one_line(tmp_path, rows, head, message):
    from skyfit_mi.pipeline.observation_table import read_observation_table

    with pytest.raises(SkyfitError, match=message) as exc:
        read_observation_table(_table(tmp_path, rows, head or "frame,region,r,g,b,sigma"))
    assert "\n" not in str(exc.value)


@pytest.mark.parametrize("table, spec, extra, message", [
    ("frames", "day", [], r"names its frames by index .* but .* has \[time\]"),
    ("times", "lab", [], r"has lab lights .* name each row's light by its 0-based index"),
    ("frames", "lab", ["--tz", "UTC"], "--tz: .* which have no time or site"),
    ("frames", "lab", ["--site", "40,0"], "--site: .* which have no time or site"),
    ("late", "lab", [], "frame 7 is not one of the spec's 4 lights"),
    ("one", "lab", [], "measures one frame"),
])
def test_lab_tables_and_specs_must_agree(tmp_path, capsys, table, spec, extra, message, mi):
    day = {**_lab(), "sky": {"type": "clear"},
           "location": {"latitude_deg": 40, "longitude_deg": 0, "timezone": "UTC"},
           "time": {"date": "2026-06-21", "times": ["09:00", "12:00", "15:00"]}}
    spec_path = _write(tmp_path, _lab() if spec == "lab" else day)
    rows = {"frames": FRAMES, "late": FRAMES + ["7,disc,1,1,1,0.1"], "one": FRAMES[:1],
            "times": [f"2026-06-21T{h}:00:00+00:00,disc,1,1,1,0.1" for h in (10, 12)]}[table]
    path = _table(tmp_path, rows, "time,region,r,g,b,sigma" if table == "times" else
                  "frame,region,r,g,b,sigma")
    assert main(["ingest", str(spec_path), "--table", str(path), "-o", str(tmp_path / "out"),
                 *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and re.search(message, err), err
    assert not (tmp_path / "out").exists()


# ---- each row's own view --------------------------------------------------------------------

def test_each_row_is_checked_from_its_own_view(tmp_path, mi):
    """A sphere seen by the spec's camera from the east, 10 units away; a point on its west
    side is measured only in the second light, from the west (its own view, in front).  The
    camera's default view would see it from behind in the first light, where it has no row:
    that row does not exist, so nothing is refused.  A row whose own view is behind is
    refused, naming the point, the frame, the view, where the view came from and the fix."""
    from skyfit_mi.pipeline.observation_table import ingest_table

    spec = _write(tmp_path, _lab(scene="sphere.xml", camera={
        "azimuth_deg": 90, "angle_deg": 80.0, "distance": 10.0, "target": [0, 0, 1],
        "fov_deg": 10.0, "width": 8, "height": 8}))
    head = "frame,region,point,x,y,z,view_x,view_y,view_z,r,g,b,sigma"
    east = "sphere,e,1,0,1,1,0,0.3,1,1,1,0.1"
    west = "sphere,w,-1,0,1,-1,0,0.3,1,1,1,0.1"
    doc = ingest_table(_table(tmp_path, [f"0,{east}", f"1,{east}", f"1,{west}"], head), spec,
                       tmp_path / "ok", log=lambda *a: None)
    assert doc["ingest"]["rows"] == 3
    with pytest.raises(SkyfitError, match=r"line 4: point 'w' of 'sphere' \(frame 1\) at \[-1\.0, "
                       r"0\.0, 1\.0\] is viewed from behind its surface: its view \[0\.958, 0\.0, "
                       r"0\.287\] \(the row's view columns\) is 163 deg from the scene's "
                       r"normal \[-1\.0, .*\]; .* give the row's view on the normal's side") as exc:
        ingest_table(_table(tmp_path, [f"0,{east}", f"1,{east}",
                                       f"1,{west.replace(',-1,0,0.3', ',1,0,0.3')}"], head),
                     spec, tmp_path / "behind", log=lambda *a: None)
    assert "\n" not in str(exc.value)
    # no view given: the default, toward the camera, named as such
    with pytest.raises(SkyfitError, match=r"point 'w' of 'sphere' \(frame 1\) .* \(toward the "
                       r"camera at \[.*\]: the row gives no view\)"):
        ingest_table(_table(tmp_path, ["0,sphere,e,1,0,1,1,1,1,0.1", "1,sphere,e,1,0,1,1,1,1,0.1",
                                       "1,sphere,w,-1,0,1,1,1,1,0.1"],
                            "frame,region,point,x,y,z,r,g,b,sigma"),
                     spec, tmp_path / "default", log=lambda *a: None)


# ---- a table in its own units, scaled by a reference of known reflectance ------------------

RIG = """<scene version="3.0.0">
 <bsdf type="ward" id="sample"><string name="model" value="colour"/>
  <rgb name="C" value="0.5, 0.35, 0.25"/><float name="rho_s" value="0.06"/>
  <float name="sigma_alpha" value="0.15"/></bsdf>
 <bsdf type="ward" id="white"><string name="model" value="colour"/>
  <rgb name="C" value="0.9, 0.9, 0.9"/><float name="rho_s" value="0.0"/>
  <float name="sigma_alpha" value="0.1"/></bsdf>
 <shape type="rectangle"><transform name="to_world"><scale value="0.4"/>
  <translate x="-0.45"/></transform><ref id="sample"/></shape>
 <shape type="rectangle"><transform name="to_world"><scale value="0.4"/>
  <translate x="0.45"/></transform><ref id="white"/></shape>
</scene>"""
#: The instrument's units (DN) per W m^-2 sr^-1, per channel: unknown to the ingest.
DN_PER_RADIANCE = np.array([800.0, 1000.0, 1300.0])


@pytest.fixture(scope="module")
def dn_rig(tmp_path_factory, mi):
    """(folder, spec, a table of a sample and a white Lambertian reference (reflectance 0.9)
    under six lab lights in the instrument's DN) made from a render."""
    from skyfit_mi.pipeline.pixels import material_regions
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_testkit.table_sim import measure_table

    tmp = tmp_path_factory.mktemp("dn")
    (tmp / "rig.xml").write_text(RIG)
    raw = _lab(scene="rig.xml", camera={**CAMERA, "angle_deg": 10.0, "fov_deg": 28.0,
                                        "width": 16, "height": 16},
               lights=[(15, 0), (20, 180), (35, 60), (35, 300), (50, 120), (50, 240)])
    raw["render"] = {"spp": 64}
    spec = _write(tmp, raw)
    render_sequence(validate_spec(raw, tmp), tmp / "render", progress=False, log=lambda *a: None)
    rng = np.random.default_rng(1)
    px = np.concatenate([v[rng.choice(len(v), 4, replace=False)]
                         for _, v in material_regions(tmp / "render")])
    rows = list(csv.DictReader(measure_table(tmp / "render", px, tmp / "radiance.csv").open()))
    for r in rows:
        for c, k in zip("rgb", DN_PER_RADIANCE):
            r[c], r[f"sigma_{c}"] = (f"{float(r[key]) * k:.6g}" for key in (c, f"sigma_{c}"))
    with (tmp / "dn.csv").open("w") as f:
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return tmp, spec, tmp / "dn.csv"


def test_a_table_in_its_own_units_is_scaled_by_its_reference(dn_rig, capsys):
    """--calibrate white=0.9 finds the instrument's scale within its standard error (a joint
    99.9% test over the channels), the sample's fit holds the truth in its joint 99.9% region
    and carries the scale's error in its intervals; without the reference the reflectances
    run into their bound of 1, and the fit says so with the fix."""
    from skyfit_mi.fitting.fit import FitSession

    tmp, spec, table = dn_rig
    assert main(["ingest", str(spec), "--table", str(table), "--calibrate", "white=0.9", "-o",
                 str(tmp / "seq")]) == 0
    said = capsys.readouterr().out                      # what was written, in one line
    assert f"wrote 48 rows of 8 point(s) in 2 region(s) over 6 frame(s): {tmp / 'seq'}" in said, said
    cal = load_manifest(tmp / "seq")[0]["ingest"]["calibration"]
    dev = np.array(cal["scale_W_m2_sr_per_unit"]) * DN_PER_RADIANCE - 1.0
    assert np.sum((dev / cal["scale_relative_sd"]) ** 2) < chi2_dist.ppf(0.999, 3), cal
    assert cal["references"] == {"white": [0.9, 0.9, 0.9]} and cal["reference_rows"] == 24
    s = FitSession(tmp / "seq", "sample", None, model="colour")
    r = s.run("global", log=lambda *a: None)
    assert set(r["calibration_error_sd"]) == set(s.names) and r["calibration_error_sd"]["C_r"] > 0
    truth = np.array([0.5, 0.35, 0.25, 0.06, 0.15])
    rise = s.problem.chi2(truth) - r["chi2"]
    assert 0.0 <= rise <= chi2_dist.ppf(0.999, 5) * r["interval_scale_s2"] \
        + r["cache_noise_chi2"], (rise, r["parameters"])
    # the reference's own error (2%) in quadrature on every reflectance, not on the roughness
    assert main(["ingest", str(spec), "--table", str(table), "--calibrate", "white=0.9+-2%",
                 "-o", str(tmp / "stated")]) == 0
    assert load_manifest(tmp / "stated")[0]["ingest"]["calibration"][
        "reference_relative_sd"] == pytest.approx([0.02] * 3)
    stated = FitSession(tmp / "stated", "sample", None, model="colour").run(
        "global", log=lambda *a: None)
    for k in ("C_r", "C_g", "C_b", "rho_s"):
        assert stated["calibration_error_sd"][k] == pytest.approx(np.hypot(
            r["calibration_error_sd"][k], 0.02 * stated["parameters"][k]), rel=0.02)
    assert stated["calibration_error_sd"]["sigma_alpha"] == 0.0
    assert main(["ingest", str(spec), "--table", str(table), "-o", str(tmp / "raw")]) == 0
    raw = FitSession(tmp / "raw", "sample", None, model="colour").run("global",
                                                                     log=lambda *a: None)
    assert raw["parameters"]["C_r"] == pytest.approx(1.0)
    assert any("C_r" in w and "at the upper bound of 1" in w and "--unknown-scale" in w
               for w in raw["warnings"]), raw["warnings"]


def test_a_table_of_unknown_scale_gives_relative_reflectances_without_a_bound(dn_rig,
                                                                              tmp_path, capsys,
                                                                              monkeypatch):
    """--unknown-scale (no reference, the channels sharing one unknown gain) puts the values
    on a relative scale, recorded: the fit holds the truth times that scale in its joint
    99.9% region, says its reflectances are relative, and no bound decides it; the
    2-parameter model (a white surface) and --calibrate with it are refused in one line."""
    from skyfit_mi.fitting.fit import FitSession

    tmp, spec, _ = dn_rig
    gain = 1000.0                                          # DN per W m^-2 sr^-1, unknown
    rows = list(csv.DictReader((tmp / "radiance.csv").open()))
    for r in rows:
        for c in "rgb":
            r[c], r[f"sigma_{c}"] = (f"{float(r[k]) * gain:.6g}" for k in (c, f"sigma_{c}"))
    table = tmp_path / "dn.csv"
    with table.open("w") as f:
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    assert main(["ingest", str(spec), "--table", str(table), "--unknown-scale", "--calibrate",
                 "white=0.9", "-o", str(tmp_path / "both")]) == 2
    assert "leave out --unknown-scale" in capsys.readouterr().err
    assert main(["ingest", str(spec), "--unknown-scale", "-o", str(tmp_path / "photos")]) == 2
    assert "--unknown-scale belongs to --table" in capsys.readouterr().err
    assert main(["ingest", str(spec), "--table", str(table), "--unknown-scale", "-o",
                 str(tmp_path / "seq")]) == 0
    scale = load_manifest(tmp_path / "seq")[0]["ingest"]["scale"]
    assert scale["known"] is False and scale["brightest_apparent_albedo_reads"] == 0.5
    f = scale["scale_per_unit"] * gain                     # relative units per radiance
    for name, (C, rho_s, sigma) in {"sample": ((0.5, 0.35, 0.25), 0.06, 0.15),
                                    "white": ((0.9, 0.9, 0.9), 0.0, 0.1)}.items():
        s = FitSession(tmp_path / "seq", name, None, model="colour")
        r = s.run("global", log=lambda *a: None)
        assert r["radiometric_scale"] == scale and "relative" in r["units"]
        assert any("scale is unknown" in x for x in r["warnings"]), r["warnings"]
        theta = np.array(list(r["parameters"].values()))
        assert np.all(theta[:4] < s.upper[:4] - 1e-3), r["parameters"]
        # the truth on the relative scale: rho_d and the (white) specular reflectance times f
        truth = np.r_[f * np.array(C) * (1 - rho_s) / (1 - f * rho_s), f * rho_s, sigma]
        rise = s.problem.chi2(truth) - r["chi2"]
        assert 0.0 <= rise <= chi2_dist.ppf(0.999, 5) * r["interval_scale_s2"] \
            + r["cache_noise_chi2"], (name, rise, r["parameters"], truth)
    capsys.readouterr()
    assert main(["fit", str(tmp_path / "seq"), "--region", "sample", "--model", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "fit it with --model 3 or 5" in err, err
    # --model auto leaves the 2-parameter model out, says so, and counts the ranking's time
    # once: the table the ranking traced and the fit reused is in the fit's time alone
    t0 = time.perf_counter()
    assert main(["fit", str(tmp_path / "seq"), "--region", "sample", "--model", "auto", "-o",
                 str(tmp_path / "auto")]) == 0
    elapsed = time.perf_counter() - t0
    r = json.loads((tmp_path / "auto" / "fit_sample.json").read_text())
    sel = r["model_selection"]
    assert "two" in sel["left_out"] and "unknown" in sel["left_out"]["two"]
    assert {row["model"] for row in sel["ranking"]} == {"achromatic", "colour"}
    assert r["wall_time_s"] == pytest.approx(r["fit_wall_time_s"] + sel["wall_time_s"])
    assert sel["reused_trace_time_s"] == pytest.approx(r["light_cache_time_s"], abs=0.05)
    assert sel["reused_trace_time_s"] > 0
    assert 0.5 * elapsed < r["wall_time_s"] <= elapsed
    # a region of more points than RANK_POINTS is ranked on a seeded subset of them, its
    # chi-squares scaled to the whole table's; the chosen model is fitted on every point
    from skyfit_mi.fitting import selection
    monkeypatch.setattr(selection, "RANK_POINTS", 3)
    assert main(["fit", str(tmp_path / "seq"), "--region", "sample", "--model", "auto", "-o",
                 str(tmp_path / "auto3")]) == 0
    sub_r = json.loads((tmp_path / "auto3" / "fit_sample.json").read_text())
    sub_sel = sub_r["model_selection"]
    assert sub_sel["ranking_light"]["most_points"] == 3 and sub_sel["ranking_scale"] > 1.1
    assert sub_r["points"] == r["points"] and len(r["points"]) > 3
    assert sub_sel["reused_trace_time_s"] == 0 and sub_r["light_cache_time_s"] > 0
    assert sub_sel["chosen"]["model"] == sel["chosen"]["model"]


def test_a_held_out_table_of_unknown_scale_is_put_on_the_fits_scale(dn_rig, tmp_path):
    """A fit on one relative-scale ingest relit onto another (the sample alone without its
    highlight, another gain: its relative scale differs 2-3x) is compared after one factor that
    puts the
    target's values on the fit's scale: the factor is the ratio of the two ingests' scales
    within 2% (each frame's from the other frames', within 3%), recorded, and the values' and
    region means' errors are those of the fit's own table."""
    def table_at(gain, path, keep=lambda r: True):
        rows = [r for r in csv.DictReader((tmp / "radiance.csv").open()) if keep(r)]
        for r in rows:
            for c in "rgb":
                r[c], r[f"sigma_{c}"] = (f"{float(r[k]) * gain:.6g}" for k in (c, f"sigma_{c}"))
        with path.open("w") as f:
            w = csv.DictWriter(f, list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        return path

    tmp, spec, _ = dn_rig
    seqs = {}
    for name, gain, keep in (("fitted", 1000.0, lambda r: True),
                             ("target", 700.0, lambda r: r["region"] == "sample" and r["frame"] != "0")):
        seqs[name] = tmp_path / name
        assert main(["ingest", str(spec), "--table", str(table_at(gain, tmp_path / f"{name}.csv",
                                                                  keep)),
                     "--unknown-scale", "-o", str(seqs[name]), "-q"]) == 0
    assert main(["fit", str(seqs["fitted"]), "--region", "sample", "-o",
                 str(tmp_path / "fit"), "-q"]) == 0
    assert main(["relight", str(tmp_path / "fit"), "--target", str(seqs["target"]),
                 "--no-images", "-o", str(tmp_path / "relit")]) == 0
    errors = json.loads((tmp_path / "relit" / "relight.json").read_text())
    scales = {k: load_manifest(v)[0]["ingest"]["scale"]["scale_per_unit"] for k, v in seqs.items()}
    expected = scales["fitted"] * 1000.0 / (scales["target"] * 700.0)
    assert abs(expected - 1.0) > 0.3                      # the two relative scales differ
    scale = errors["target_scale"]["sample"]
    assert scale["factor"] == pytest.approx(expected, rel=0.02)
    assert len(scale["by_frame"]) == 5 and np.allclose(scale["by_frame"], expected, rtol=0.03)
    assert errors["rel_rms"] < 0.05 and errors["region_means"]["sample"]["fit"] < 0.05
    assert errors["band_coverage"]["share"] >= 0.8, errors
    # relit onto the rig's rendered frames, the relative fit is named, not scaled
    assert main(["relight", str(tmp_path / "fit"), "--target", str(tmp / "render"),
                 "--no-images", "-o", str(tmp_path / "relit_render")]) == 0
    errors = json.loads((tmp_path / "relit_render" / "relight.json").read_text())
    assert errors["relative_scale_fits"] == ["sample"] and "target_scale" not in errors


@pytest.mark.parametrize("reference, message", [
    ("wall=0.9", "--calibrate wall: no material 'wall' in the spec's scene"),
    ("white=0.9", "--calibrate white: .* has no unsaturated row on region 'white'"),
])
def test_a_reference_must_be_in_the_scene_and_the_table(dn_rig, tmp_path, capsys, reference,
                                                        message):
    """A table of the sample alone: a reference the scene lacks, or one the table does not
    measure, is refused in one line before anything is written."""
    _, spec, table = dn_rig
    lines = table.read_text().splitlines()
    only_sample = tmp_path / "sample.csv"
    only_sample.write_text("\n".join([lines[0]] + [x for x in lines[1:] if ",sample," in x])
                           + "\n")
    assert main(["ingest", str(spec), "--table", str(only_sample), "--calibrate", reference,
                 "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and re.search(message, err), err
    assert not (tmp_path / "out").exists()


def test_photographs_of_lab_lights_are_refused_by_name(tmp_path, capsys):
    """Photographs are placed by their times, which lab lights do not have: one line naming
    the spec and the table route."""
    from PIL import Image

    names = []
    for i in range(2):
        Image.fromarray(np.full((8, 8, 3), 100, np.uint8)).save(tmp_path / f"p{i}.png")
        names.append(str(tmp_path / f"p{i}.png"))
    times = tmp_path / "times.csv"
    times.write_text("file,time\np0.png,2026-06-21T10:00:00+00:00\n"
                     "p1.png,2026-06-21T11:00:00+00:00\n")
    assert main(["ingest", str(_write(tmp_path, _lab())), *names, "--times", str(times),
                 "--exposure", "1", "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "has lab lights (frames by index, no [time])" in err \
        and "ingest --table with a frame column" in err, err


def test_model_auto_on_a_table_ranks_large_regions_on_a_subset_and_small_ones_whole(
        dn_rig, tmp_path, monkeypatch):
    """``fit --all --model auto`` on a table whose sample has 4 points and whose reference 2,
    ranking at most 3 points a region (RANK_POINTS): the sample ranked on a seeded 3 (its
    chi-squares scaled up to its 4), its chosen lobe traced and fitted on all 4; the reference
    ranked whole at the fit's cache, its fit taking that trace."""
    from skyfit_mi.fitting import selection

    tmp, spec, table = dn_rig
    rows = list(csv.DictReader(table.open()))
    white = sorted({r["point"] for r in rows if r["region"] == "white"})
    kept = [r for r in rows if r["region"] != "white" or r["point"] in white[:2]]
    with (tmp_path / "t.csv").open("w") as f:
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(kept)
    assert main(["ingest", str(spec), "--table", str(tmp_path / "t.csv"), "--calibrate",
                 "white=0.9", "-o", str(tmp_path / "seq")]) == 0
    monkeypatch.setattr(selection, "RANK_POINTS", 3)
    assert main(["fit", str(tmp_path / "seq"), "--all", "--model", "auto", "-o",
                 str(tmp_path / "fits")]) == 0
    fits = {name: json.loads((tmp_path / "fits" / f"fit_{name}.json").read_text())
            for name in ("sample", "white")}
    assert len(fits["sample"]["points"]) == 4 and len(fits["white"]["points"]) == 2
    sample, ref = (fits[k]["model_selection"] for k in ("sample", "white"))
    assert sample["ranking_scale"] > 1.1 and sample["reused_trace_time_s"] == 0
    assert ref["ranking_scale"] == 1.0 and ref["reused_trace_time_s"] > 0
