"""``skyfit export``: fitted materials into Mitsuba 3, Radiance and glTF 2.0, round-trip tested.

The exported files are read back by the renderers themselves: Mitsuba evaluates the exported
BSDFs (the built-in blend and the ``ward`` plugin) against the NumPy reference, renders them on
a day's frames and a map's textures on a plane; Radiance (rtrace, from the pyradiance wheel)
traces the exported ``plastic``/``metal`` under gensky's skies.  Each is compared with skyfit's
own prediction of the same frames (the fit model on the day's light): exact forms within 2%,
the nearest forms within the error the export states (plus the renders' noise).
"""
import json
import shutil

import numpy as np
import pytest

from skyfit_mi.cli import main
from skyfit_mi.physics.ward import raw_parameters, ward_brdf

#: Fitted materials (model colour): region, C, rho_s, sigma_alpha, lobe.  A Radiance plastic
#: (exact in Radiance), a GGX conductor (exact in Mitsuba's built-ins), a Ward 1992 paint
#: (nearest in both).
FITS = {"paint": ((0.6, 0.4, 0.2), 0.08, 0.1, "balanced"),
        "steel": ((0.7, 0.6, 0.5), 0.8, 0.15, "ggx_metal"),
        "gloss": ((0.2, 0.5, 0.7), 0.05, 0.06, "ward")}


def _fit_json(folder, region, C, rho_s, sigma, lobe, warnings=()):
    """A fit result as `skyfit fit` writes it (the keys export reads)."""
    params = {"C_r": C[0], "C_g": C[1], "C_b": C[2], "rho_s": rho_s, "sigma_alpha": sigma}
    path = folder / f"fit_{region}.json"
    path.write_text(json.dumps({
        "region": region, "model": "colour", "normalisation": lobe, "parameters": params,
        "intervals": {k: {"95": [0.98 * v, 1.02 * v]} for k, v in params.items()},
        "pixels": [], "warnings": list(warnings)}))
    return path


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("export")
    fits = tmp / "fits"
    fits.mkdir()
    for name, f in FITS.items():
        _fit_json(fits, name, *f, warnings=["sigma_alpha: not determined below 0.05"]
                  if name == "gloss" else ())
    assert main(["export", str(fits), "-o", str(tmp / "out")]) == 0
    return tmp / "out"


def _directions(n, seed, max_deg=80.0):
    """``n`` random unit vectors within ``max_deg`` of the normal, half of them near the
    mirror direction of the others (the highlight)."""
    rng = np.random.default_rng(seed)
    c = rng.uniform(np.cos(np.radians(max_deg)), 1.0, (2, n))
    phi = rng.uniform(0, 2 * np.pi, (2, n))
    s = np.sqrt(1 - c * c)
    v = np.stack([s * np.cos(phi), s * np.sin(phi), c], axis=-1)
    wi, wo = v[0], v[1]
    near = np.arange(n) % 2 == 0
    mirror = wi * np.array([-1, -1, 1]) + rng.normal(0, 0.05, (n, 3))
    mirror[:, 2] = np.maximum(mirror[:, 2], np.cos(np.radians(max_deg)) + 0.02)
    wo[near] = (mirror / np.linalg.norm(mirror, axis=1, keepdims=True))[near]
    return wi, wo


def _bsdf_xml(path, bsdf_id):
    """The <bsdf id=...> element of an exported Mitsuba file, as text without its id."""
    import xml.etree.ElementTree as ET

    el = next(e for e in ET.parse(path).getroot() if e.get("id") == bsdf_id)
    del el.attrib["id"]
    return ET.tostring(el, encoding="unicode")


def _reference(name, wi, wo):
    C, rho_s, sigma, lobe = FITS[name]
    rho_d, s, sigma = raw_parameters("colour", C=C, rho_s=rho_s, sigma_alpha=sigma)
    return ward_brdf(wi, wo, rho_d, s, sigma, lobe)


def test_export_writes_every_format_with_the_fit_beside_it(exported):
    """The sidecar names each material's fit, its intervals and warnings, and per format
    whether the form is exact; the exact forms are the ones the lobes allow."""
    side = json.loads((exported / "export.json").read_text())
    assert set(side["materials"]) == set(FITS)
    ex = {n: m["exports"] for n, m in side["materials"].items()}
    assert ex["paint"]["radiance"]["exact"] and not ex["paint"]["mitsuba"]["exact"]
    assert ex["steel"]["mitsuba"]["exact"] and not ex["steel"]["radiance"]["exact"]
    assert not ex["gloss"]["mitsuba"]["exact"] and not ex["gloss"]["radiance"]["exact"]
    assert all(ex[n]["mitsuba_ward"]["exact"] for n in FITS)
    for n in FITS:
        for f in ("mitsuba", "radiance", "gltf"):
            e = ex[n][f]["error"]
            assert (e["max"] == 0) == ex[n][f]["exact"] and e["rms"] <= e["max"], (n, f, e)
    assert side["materials"]["gloss"]["warnings"] == ["sigma_alpha: not determined below 0.05"]
    assert side["materials"]["paint"]["intervals_95"]["rho_s"] == pytest.approx([0.0784, 0.0816])
    rad = (exported / "materials.rad").read_text()
    assert "void plastic paint\n0\n0\n5 0.6 0.4 0.2 0.08 0.1" in rad
    gltf = json.loads((exported / "materials.gltf").read_text())
    assert sorted(m["name"] for m in gltf["materials"]) == sorted(FITS)
    assert gltf["asset"]["version"] == "2.0"


def test_radiance_identifiers_are_one_word():
    """A material named "dïsc é" was written `void plastic dïsc é`, which oconv refuses ("bad
    arguments for plastic"): Radiance takes one word; two names that become one are refused."""
    from types import SimpleNamespace

    from skyfit_mi.errors import SkyfitError
    from skyfit_mi.pipeline.export import radiance_name, radiance_text

    assert radiance_name("dïsc é") == "d_sc__" and radiance_name("steel_40.grit-a") == \
        "steel_40.grit-a"
    match = {"radiance": {"params": {"type": "plastic", "colour": [0.5, 0.4, 0.3], "spec": 0.05,
                                     "roughness": 0.1}, "exact": True, "error": {}}}
    one = SimpleNamespace(name="dïsc é", maps=None, source="fit_a.json")
    assert "void plastic d_sc__\n0\n0\n5 0.5 0.4 0.3 0.05 0.1" in \
        radiance_text([one], {"dïsc é": match})
    two = SimpleNamespace(name="dèsc ê", maps=None, source="fit_b.json")
    with pytest.raises(SkyfitError, match="are both 'd_sc__' as Radiance identifiers"):
        radiance_text([one, two], {"dïsc é": match, "dèsc ê": match})


@pytest.mark.parametrize("name", list(FITS))
def test_mitsuba_reads_the_exported_bsdfs_as_the_fit(exported, name, mi):
    """Mitsuba's own ``eval`` of the exported files: the ``ward`` plugin element is the fitted
    BRDF to float precision; the built-in blend is too where exact, and otherwise within the
    error the export states (on directions the export's grid did not use)."""
    from independent import mitsuba_brdf

    wi, wo = _directions(4000, seed=3)
    ref = _reference(name, wi, wo)
    ward = mitsuba_brdf(_bsdf_xml(exported / "materials_ward.xml", f"{name}_ward"))(wi, wo, None)
    np.testing.assert_allclose(ward, ref, rtol=2e-5)
    blend = mitsuba_brdf(_bsdf_xml(exported / "materials.xml", name))(wi, wo, None)
    side = json.loads((exported / "export.json").read_text())["materials"][name]
    stated = side["exports"]["mitsuba"]["error"]["max"]
    worst = float(np.max(np.abs(blend - ref) / ref))
    print(name, "largest relative error", worst, "stated", stated)
    assert worst <= (2e-5 if side["exports"]["mitsuba"]["exact"] else 1.05 * stated + 1e-3)


HOURS = (8.0, 11.0, 14.0, 17.0)
SIZE = 8


@pytest.fixture(scope="module")
def gensky_day(radiance, tmp_path_factory, mi):
    """A disc under gensky's clear skies (four frames), the frames skyfit rendered, and the
    skies' texts."""
    from independent import gensky_entries
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import validate_spec

    tmp = tmp_path_factory.mktemp("export_day")
    skies = gensky_entries(radiance, "2026-06-21", HOURS, 40.0, 0.0, "+s")
    spec = {"name": "export-disc",
            "location": {"latitude_deg": 40.0, "longitude_deg": 0.0, "timezone": "UTC"},
            "time": {"date": "2026-06-21", "times": [f"{int(h):02d}:00" for h in HOURS]},
            "sky": skies, "scene": {"file": "disc.xml"},
            "camera": {"azimuth_deg": 90.0, "angle_deg": 45.0, "distance": 5.0,
                       "fov_deg": 16.0 / 3, "width": SIZE, "height": SIZE},
            "sensor": {"exposure": "auto", "bits": 16}, "render": {"spp": 4, "seed": 1}}
    render_sequence(validate_spec(spec, tmp), tmp / "day", progress=False, log=lambda *a: None)
    return tmp / "day", [s["gensky"] for s in skies]


def _predicted(day, name):
    """skyfit's prediction of the disc's central 4 x 4 pixels in every frame (P, T, 3): the
    fit model on the day's light, at the fitted parameters."""
    from skyfit_mi.fitting.chi2 import parse_region
    from skyfit_mi.fitting.fit import FitSession

    C, rho_s, sigma, lobe = FITS[name]
    s = FitSession(day, "disc", parse_region("rect:2,2,5,5"), model="colour", normalisation=lobe)
    return s, s.wm.radiance(np.array([*C, rho_s, sigma]))


def _frames(day, s):
    from skyfit_mi.pipeline.pixels import frame_values

    return frame_values(day, s.obs.pixels, s.obs.frames)


@pytest.mark.parametrize("name, renderer", [
    ("paint", "radiance"), ("steel", "mitsuba"), ("gloss", "radiance"),
    pytest.param("gloss", "mitsuba", marks=pytest.mark.slow)])
def test_exported_materials_render_the_fitted_day(exported, gensky_day, tmp_path, name,
                                                  renderer, radiance):
    """Each renderer renders the exported material on the disc under the day's skies: its
    frames agree with skyfit's prediction of them within 2% (an exact form) or within the
    error the export states plus 2% (the nearest), per frame and channel (the means of 16
    pixels)."""
    from independent import mitsuba_frames, radiance_frames

    day, gensky = gensky_day
    copy = tmp_path / "day"
    shutil.copytree(day, copy)
    if renderer == "radiance":
        text = (exported / "materials.rad").read_text()
        start = text.index(f"# {name} (")
        block = text[start:].split("\n# ")[0].split("\n", 1)[1]
        radiance_frames(radiance, copy, gensky, block.replace(f" {name}\n", " mat\n", 1),
                        region=(2, 2, 5, 5))                      # _predicted's pixels
    else:
        mitsuba_frames(copy, "disc", _bsdf_xml(exported / "materials.xml", name), spp=2048)
    s, predicted = _predicted(day, name)
    ratio = _frames(copy, s).mean(axis=0) / predicted.mean(axis=0)
    side = json.loads((exported / "export.json").read_text())["materials"][name]["exports"]
    allowed = 0.02 + (0 if side[renderer]["exact"] else side[renderer]["error"]["max"])
    print(name, renderer, "rendered / predicted per frame and channel:", ratio.round(4).tolist(),
          "allowed", allowed)
    assert np.all(np.abs(ratio - 1) <= allowed)


def _map_folder(folder, lobe="ggx_plastic"):
    """A per-pixel map as `skyfit fit --per-pixel` writes it (5 x 5, the colour model, two
    metal texels, a mirror, one texel not mapped): its planes and map_summary.json; returns the planes."""
    from skyfit_mi.render.image import write_exr

    rng = np.random.default_rng(0)
    planes = {"C_r": rng.uniform(.2, .9, (5, 5)), "C_g": rng.uniform(.2, .9, (5, 5)),
              "C_b": rng.uniform(.2, .9, (5, 5)), "rho_s": rng.uniform(.02, .2, (5, 5)),
              "sigma_alpha": rng.uniform(.05, .3, (5, 5))}
    planes["rho_s"][0, :2] = 0.8
    planes["sigma_alpha"][2, 3] = 0.0                       # an ideal mirror
    folder.mkdir()
    for k, v in planes.items():
        v[4, 4] = np.nan
        write_exr(folder / f"{k}.exr", v.astype(np.float32))
    bits = np.zeros((5, 5), np.float32)
    bits[1, 2] = 2                                          # sigma_alpha undetermined there
    bits[4, 4] = np.nan
    write_exr(folder / "warnings.exr", bits)
    (folder / "map_summary.json").write_text(json.dumps({
        "parameters": list(planes), "undetermined_bits": 2 | 4 | 8, "regions": {"board": {
            "model": "colour", "normalisation": lobe, "determined": 24,
            "median": {k: float(np.nanmedian(v)) for k, v in planes.items()}}}}))
    return planes


def test_an_exported_map_renders_as_a_textured_plane(tmp_path, mi):
    """A map's Mitsuba textures on a plane under a directional light, seen from above: every
    texel's radiance is the fitted BRDF's there (E cos theta_i f_r), to float precision (a
    microfacet lobe: the blend is exact).  Mitsuba's rectangle runs v up its y axis, so the
    image (row 0 at +y) shows the map's rows upside down."""
    planes = _map_folder(tmp_path / "map")
    out = tmp_path / "out"
    assert main(["export", str(tmp_path / "map"), "-o", str(out)]) == 0
    side = json.loads((out / "export.json").read_text())["materials"]
    assert side["pixel_map"]["exports"]["mitsuba"]["exact"] and side["pixel_map"]["texels"] == 24
    assert side["pixel_map"]["warnings"][0].startswith("1 of 24 texels are not determined")
    from PIL import Image
    flagged = np.asarray(Image.open(out / "textures" / "undetermined.png"))[..., 0] > 0
    assert flagged.sum() == 1 and flagged[1, 2]
    assert "board" in side and "plastic board" in (out / "materials.rad").read_text()
    wi = np.array([0.3, 0.2, 0.9]) / np.linalg.norm([0.3, 0.2, 0.9])
    (out / "scene.xml").write_text(f"""<scene version="3.0.0">
        <include filename="materials.xml"/>
        <integrator type="direct"/>
        <sensor type="orthographic">
            <transform name="to_world"><lookat origin="0,0,1" target="0,0,0" up="0,1,0"/></transform>
            <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
            <film type="hdrfilm"><integer name="width" value="5"/><integer name="height" value="5"/>
                <rfilter type="box"/></film></sensor>
        <emitter type="directional"><vector name="direction" value="{-wi[0]},{-wi[1]},{-wi[2]}"/>
            <float name="irradiance" value="1"/></emitter>
        <shape type="rectangle"><ref id="pixel_map"/></shape></scene>""")
    img = np.array(mi.render(mi.load_file(str(out / "scene.xml"))))[::-1]
    expected = np.zeros((5, 5, 3))
    for y, x in zip(*np.nonzero(np.isfinite(planes["C_r"]))):
        C = [planes[c][y, x] for c in ("C_r", "C_g", "C_b")]
        rho_d, s, sigma = raw_parameters("colour", C=C, rho_s=planes["rho_s"][y, x],
                                         sigma_alpha=planes["sigma_alpha"][y, x])
        expected[y, x] = wi[2] * ward_brdf(wi, np.array([0, 0, 1.0]), rho_d, s, sigma,
                                           "ggx_plastic")
    np.testing.assert_allclose(img, expected, rtol=1e-4, atol=1e-7)
    gltf = json.loads((out / "materials.gltf").read_text())
    assert all((out / i["uri"]).is_file() for i in gltf["images"])
    # the specular texture holds f / max(f) in full 8 bits, the material max(f)
    spec = gltf["materials"][0]["extensions"]["KHR_materials_specular"]
    a = np.asarray(Image.open(out / "textures" / "specular.png"))[..., 3]
    assert a.max() == 255 and 0 < spec["specularFactor"] <= 1
    # --overwrite in one format: the other format's textures go, the user's scene stays
    assert main(["export", str(tmp_path / "map"), "-o", str(out), "--overwrite", "--format",
                 "mitsuba"]) == 0
    assert not (out / "textures" / "base_colour.png").exists()
    assert (out / "textures" / "alpha.exr").exists() and (out / "scene.xml").exists()


def test_refusals_are_one_line_and_write_nothing(tmp_path, capsys):
    """A file that is not a fit, an unknown format and an output holding another export: one
    line, exit code 2, nothing written."""
    bad = tmp_path / "fit_x.json"
    bad.write_text('{"region": "x"}')
    assert main(["export", str(bad), "-o", str(tmp_path / "a")]) == 2
    assert "is not a fit result" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()
    good = _fit_json(tmp_path, "paint", *FITS["paint"])
    assert main(["export", str(good), "-o", str(tmp_path / "b")]) == 0
    before = (tmp_path / "b" / "export.json").read_text()
    assert main(["export", str(good), "-o", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert "holds another export" in err and len(err.strip().splitlines()) == 1
    assert (tmp_path / "b" / "export.json").read_text() == before
    assert main(["export", str(good), "-o", str(tmp_path / "b"), "--overwrite",
                 "--format", "radiance"]) == 0
    assert not (tmp_path / "b" / "materials.xml").exists()        # the earlier export's, gone
    # a user's own files in the folder are not another export's: kept, and not overwritten
    own = tmp_path / "mine" / "textures" / "wood.png"
    own.parent.mkdir(parents=True)
    own.write_bytes(b"mine")
    assert main(["export", str(good), "-o", str(tmp_path / "mine"), "--format", "radiance"]) == 0
    assert own.read_bytes() == b"mine"
    _map_folder(tmp_path / "map")
    summary = json.loads((tmp_path / "map" / "map_summary.json").read_text())
    summary["regions"]["other"] = {**summary["regions"]["board"], "normalisation": "ward"}
    (tmp_path / "map" / "map_summary.json").write_text(json.dumps(summary))
    assert main(["export", str(tmp_path / "map"), "-o", str(tmp_path / "c")]) == 2
    assert "mixes lobes (ggx_plastic, ward)" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()
    summary["regions"] = {"pixel_map": summary["regions"]["board"]}
    (tmp_path / "map" / "map_summary.json").write_text(json.dumps(summary))
    assert main(["export", str(tmp_path / "map"), "-o", str(tmp_path / "c")]) == 2
    assert "a region named 'pixel_map'" in capsys.readouterr().err


def test_an_exported_ideal_mirror_keeps_its_light_in_mitsubas_blend(mi):
    """A Ward lobe of sigma_alpha 0 exports as a blend's mirror: under a uniform sky of radiance
    1 a flat patch seen from above reflects weight x F (a smooth conductor in Mitsuba's
    blendbsdf gave 0.26 for 0.34)."""
    import xml.etree.ElementTree as ET

    from skyfit_mi.pipeline.export import _blend
    from skyfit_mi.render.scene import load_xml

    root = ET.Element("scene", version="3.0.0")
    _blend(root, "m", {"weight": 0.5, "diffuse_reflectance": [0.0] * 3, "distribution": "mirror",
                       "specular_reflectance": [0.675] * 3, "material": "none"})
    bsdf = ET.tostring(root[0], encoding="unicode")
    scene = load_xml(f"""<scene version="3.0.0">
      <integrator type="path"><integer name="max_depth" value="3"/></integrator>
      <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
      <shape type="rectangle">{bsdf}</shape>
      <sensor type="perspective"><float name="fov" value="10"/>
        <transform name="to_world"><lookat origin="0,0,5" target="0,0,0" up="0,1,0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="256"/></sampler>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>
        </film></sensor></scene>""")
    assert float(np.mean(np.array(mi.render(scene)))) == pytest.approx(0.5 * 0.675, rel=0.02)


def test_a_maps_median_materials_say_how_many_pixels_hold_them(tmp_path):
    """A map's region medians go out as materials only where every parameter has a median; one
    over fewer than MEDIAN_PIXELS determined pixels says so, and a region left out is named."""
    from skyfit_mi.pipeline.export import MAP_SUMMARY, MEDIAN_PIXELS, read_map
    from skyfit_mi.render.image import write_exr

    names = ("C_r", "C_g", "C_b", "rho_s", "sigma_alpha")
    for k, v in zip(names, (0.5, 0.4, 0.3, 0.05, 0.1)):
        write_exr(tmp_path / f"{k}.exr", np.full((2, 2), v, np.float32))
    med = dict(zip(names, (0.5, 0.4, 0.3, 0.05, 0.1)))
    regions = {"few": {"model": "colour", "median": med,
                       "determined_by_parameter": {**dict.fromkeys(names, 40), "sigma_alpha": 1}},
               "many": {"model": "colour", "median": med,
                        "determined_by_parameter": dict.fromkeys(names, 40)},
               "none": {"model": "colour", "median": {**med, "sigma_alpha": None},
                        "determined_by_parameter": {**dict.fromkeys(names, 40),
                                                    "sigma_alpha": 0}}}
    (tmp_path / MAP_SUMMARY).write_text(json.dumps({"parameters": list(names),
                                                    "regions": regions}))
    mats = {m.name: m for m in read_map(tmp_path)}
    assert set(mats) == {"pixel_map", "few", "many"}
    assert "none" not in mats and mats["many"].warnings == ()
    assert any(f"fewer than {MEDIAN_PIXELS}" in w and "sigma_alpha (1)" in w
               for w in mats["few"].warnings)
    assert any("none: no median material" in w for m in mats.values() for w in m.warnings)


def test_an_export_that_failed_part_way_is_replaced_by_the_next(tmp_path, capsys, monkeypatch):
    """A map's export that stopped after its textures (a full disk) leaves them marked
    unfinished: the same command then replaces them without --overwrite, and a finished
    export is refused as before."""
    from skyfit_mi.errors import OutputError
    from skyfit_mi.pipeline import export as ex

    _map_folder(tmp_path / "map")
    out = tmp_path / "out"
    real = ex.write_text

    def full(path, text):
        if path.name == "materials.xml":
            raise OutputError(f"cannot write {str(path)!r}: No space left on device.")
        return real(path, text)

    monkeypatch.setattr(ex, "write_text", full)
    assert main(["export", str(tmp_path / "map"), "-o", str(out)]) == 2
    assert "No space left on device" in capsys.readouterr().err
    assert (out / "textures").is_dir() and not (out / ex.SIDECAR).exists()
    monkeypatch.undo()
    assert main(["export", str(tmp_path / "map"), "-o", str(out)]) == 0
    assert (out / ex.SIDECAR).is_file() and not (out / ex.UNFINISHED).exists()
    assert main(["export", str(tmp_path / "map"), "-o", str(out)]) == 2
    assert "holds another export" in capsys.readouterr().err
