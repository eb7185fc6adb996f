"""Environment maps and lab lights through the spec and the manifest (pipeline/illumination.py):
per-frame map files, the records a render writes (the map's file, not its numbers), reading
them back, and bad input refused in one line naming the key or the file."""
import json

import numpy as np
import pytest

from skyfit_mi.conventions import direction_from_angles
from skyfit_mi.pipeline.manifest import ManifestError, frame_sky, load_manifest
from skyfit_mi.pipeline.spec import SpecError, validate_spec

from test_spec import _spec


@pytest.fixture
def maps(tmp_path, mi):
    """Three 16x32 lat-long maps (maps/sky_000.exr ...) of different brightness."""
    from skyfit_mi.render.image import write_exr

    (tmp_path / "maps").mkdir()
    rng = np.random.default_rng(0)
    for i in range(3):
        write_exr(tmp_path / "maps" / f"sky_{i:03d}.exr",
                  ((i + 1) * 10 * rng.random((16, 32, 3))).astype(np.float32))
    return tmp_path


ENVMAP = ('type = "envmap"\nfile = "maps/sky_{index:03d}.exr"\nnorth_rotation_deg = 90\n'
          'direct_normal_W_m2 = 700\nsun_mask_deg = 5\nground_albedo = 0.2')


def test_envmap_spec_reads_a_map_per_frame(maps):
    spec = _spec(maps, sky=ENVMAP)
    a, b = (f.sky for f in spec.frames)
    assert a.envmap.shape == (16, 32, 3) and a.info["file"].endswith("sky_000.exr")
    assert b.info["file"].endswith("sky_001.exr")
    assert b.sky_horizontal_irradiance()[1] > 1.5 * a.sky_horizontal_irradiance()[1]
    # the disc at the frame's solar position, carrying the measured DNI
    s = direction_from_angles(np.radians(spec.frames[0].sun_zenith_deg),
                              np.radians(spec.frames[0].sun_azimuth_deg))
    np.testing.assert_allclose(a.sun_direction, s, atol=1e-12)
    np.testing.assert_allclose(a.sun_radiance @ [0.2126, 0.7152, 0.0722] * a.sun_solid_angle, 700)
    assert a.ground.min() > 0
    # a new map file is a new run (resume keeps no frame of the old maps)
    before = spec.run_id()
    (maps / "maps" / "sky_001.exr").write_bytes((maps / "maps" / "sky_002.exr").read_bytes())
    assert _spec(maps, sky=ENVMAP).run_id() != before


def test_sky_tables_may_name_a_map_each_and_times_name_files(maps):
    for i, name in enumerate(["1000", "1200"]):
        (maps / "maps" / f"sky_{name}.exr").write_bytes((maps / "maps" / f"sky_00{i}.exr").read_bytes())
    by_time = _spec(maps, sky='type = "envmap"\nfile = "maps/sky_{time:%H%M}.exr"')
    assert by_time.frames[1].sky.info["file"].endswith("sky_1200.exr")
    raw = dict(by_time.raw, sky=[{"type": "envmap", "file": "maps/sky_002.exr"},
                              {"type": "envmap", "file": "maps/sky_000.exr", "scale": 2.0}])
    spec = validate_spec(raw, maps)
    assert spec.frames[0].sky.info["file"].endswith("sky_002.exr")
    np.testing.assert_allclose(spec.frames[1].sky.envmap, 2 * by_time.frames[0].sky.envmap)


def test_directional_spec_is_the_frame_sun(tmp_path):
    spec = _spec(tmp_path, sky='type = "directional"\nzenith_deg = 30\nazimuth_deg = 120\n'
                                'irradiance_W_m2 = [500, 400, 300]')
    f = spec.frames[0]
    assert f.sun_zenith_deg == pytest.approx(30) and f.sun_azimuth_deg == pytest.approx(120)
    np.testing.assert_allclose(f.sky.horizontal_irradiance(), np.array([500, 400, 300]) * np.cos(np.radians(30)))
    vec = _spec(tmp_path, sky='type = "directional"\ndirection = [0, 0, 2]\nirradiance_W_m2 = 80\n'
                              'solid_angle_sr = 1e-3')
    np.testing.assert_allclose(vec.frames[1].sky.sun_radiance, 80 / 1e-3)


@pytest.mark.parametrize("sky, match", [
    ('type = "directional"\ndirection = [0, 0, 0]\nirradiance_W_m2 = 1', "non-zero direction"),
    ('type = "directional"\ndirection = [1, 0, -1]\nirradiance_W_m2 = 1', "below the horizon"),
    ('type = "directional"\nzenith_deg = 95\nazimuth_deg = 0\nirradiance_W_m2 = 1', "below the horizon"),
    ('type = "directional"\ndirection = [0, 0, 1]\nirradiance_W_m2 = -5', "irradiance = -5"),
    ('type = "directional"\ndirection = [0, 0, 1]\nirradiance_W_m2 = [1, 2]', "irradiance_W_m2 must be"),
    ('type = "directional"\ndirection = [0, 0, 1]', "needs irradiance_W_m2"),
    ('type = "directional"\nirradiance_W_m2 = 1', "either as direction"),
    ('type = "directional"\ndirection = [0, 0, 1]\nzenith_deg = 3\nirradiance_W_m2 = 1', "either as direction"),
    ('type = "directional"\ndirection = [0, 0, 1]\nirradiance_W_m2 = 1\nphi = 0.5', "phi"),
    ('type = "directional"\ndirection = [0, 0, 1]\nirradiance_W_m2 = 1\nground_albedo = 0.2',
     "drop ground_albedo"),
    ('type = "clear"\nfile = "x.exr"', "file: only type = 'envmap' takes this key"),
    ('type = "clear"\nirradiance_W_m2 = 3', "irradiance_W_m2: only type = 'directional'"),
    ('type = "envmap"', "needs file"),
    ('type = "envmap"\nfile = "maps/none_{index}.exr"', "none_0.exr: does not exist"),
    ('type = "envmap"\nfile = "maps/sky_{frame}.exr"', "not a pattern of {index} and {time}"),
    ('type = "envmap"\nfile = "maps/sky_000.exr"\nprojection = "cube"', "unknown envmap projection"),
    ('type = "envmap"\nfile = "maps/sky_000.exr"\nscale = -1', "envmap scale = -1"),
    ('type = "envmap"\nfile = "maps/sky_000.exr"\nsun_mask_deg = 60', "sun_mask_deg = 60"),
    ('type = "envmap"\nfile = "maps/sky_000.exr"\ncct = 6000', "belong to a Perez sky"),
    ('type = "envmap"\nfile = "maps/bad.png"', "not the linear floats of an HDR"),
])
def test_bad_light_specs_are_refused_in_one_line(maps, sky, match):
    from PIL import Image
    Image.fromarray(np.zeros((8, 16, 3), np.uint8)).save(maps / "maps" / "bad.png")
    with pytest.raises(SpecError, match=match) as e:
        _spec(maps, sky=sky)
    assert "\n" not in str(e.value)


def _render(spec, out):
    from skyfit_mi.pipeline.sequence import render_sequence
    render_sequence(spec, out, progress=False, log=lambda *a: None)
    return load_manifest(out)


def test_envmap_frames_render_and_their_records_refer_to_the_map(maps):
    spec = _spec(maps, sky=ENVMAP)
    doc, root = _render(spec, maps / "out")
    rec = doc["frames"][1]["illumination"]
    assert rec["kind"] == "envmap" and rec["file"] == "../maps/sky_001.exr"
    assert rec["north_rotation_deg"] == 90 and rec["direct_normal_W_m2"] == 700
    assert "file" not in rec["info"] and rec["info"]["invalid_values"] == 0
    assert len(json.dumps(rec)) < 2000                          # a reference, not the numbers
    again = frame_sky(doc["frames"][1], root)
    sky = spec.frames[1].sky
    np.testing.assert_array_equal(again.envmap, sky.envmap)
    np.testing.assert_allclose(again.sun_radiance, sky.sun_radiance)
    np.testing.assert_allclose(again.ground, sky.ground)
    from skyfit_mi.render.image import read_exr
    img = read_exr(root / doc["frames"][1]["radiance"])
    assert np.all(np.isfinite(img)) and img.mean() > 0


def test_directional_frames_render_and_read_back(tmp_path):
    spec = _spec(tmp_path, sky='type = "directional"\nzenith_deg = 30\nazimuth_deg = 120\n'
                                'irradiance_W_m2 = 500')
    doc, root = _render(spec, tmp_path / "out")
    f = doc["frames"][0]
    assert f["illumination"]["kind"] == "directional" and f["sun_zenith_deg"] == pytest.approx(30)
    sky = frame_sky(f, root)
    np.testing.assert_allclose(sky.horizontal_irradiance(), 500 * np.cos(np.radians(30)))


def test_manifest_records_of_hand_written_lights(maps):
    frame = {"index": 4, "sun_zenith_deg": 40.0, "sun_azimuth_deg": 180.0,
             "illumination": {"kind": "envmap", "file": "maps/sky_000.exr", "projection": "latlong",
                              "scale": 3.0, "north_rotation_deg": 0.0}}
    sky = frame_sky(frame, maps)
    assert sky.envmap.shape == (16, 32, 3) and not sky.sun_radiance.any()
    light = frame_sky({"index": 0, "illumination": {
        "kind": "directional", "direction": [0.0, 0.0, 1.0], "irradiance_W_m2": [10.0, 20.0, 30.0],
        "solid_angle_sr": 1e-4}}, maps)
    np.testing.assert_allclose(light.horizontal_irradiance(), [10, 20, 30])
    frame["illumination"]["file"] = "maps/gone.exr"
    with pytest.raises(ManifestError, match=r"frame 4: envmap illumination: .*gone\.exr: does not "
                                            "exist"):
        frame_sky(frame, maps)
    del frame["sun_zenith_deg"]
    with pytest.raises(ManifestError, match="needs sun_zenith_deg"):
        frame_sky(frame, maps)
    with pytest.raises(ManifestError, match="frame 0: directional illumination: .*below the horizon"):
        frame_sky({"index": 0, "illumination": {"kind": "directional", "direction": [1, 0, -1],
                                                "irradiance_W_m2": [1, 1, 1]}}, maps)
