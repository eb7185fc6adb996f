"""The microfacet lobe families in the fit: their light cache and table against the Dr.Jit model
they tabulate, and a day rendered with Mitsuba's own ``roughplastic`` fitted by each family."""
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from skyfit_mi.fitting.chi2 import parse_region
from skyfit_mi.fitting.fit import FitCache
from skyfit_mi.fitting.light import LightOptions

REGION = parse_region("rect:4,4,7,7")          # 16 pixels, all on the disc
#: The rendered plastic: rho_d = 0.2 and a GGX coat (eta 1.5) of alpha 0.08 at s = 0.8; the
#: ``two`` model's reading (rho_d = 1 - rho_s).
TRUTH = {"rho_s": 0.8, "sigma_alpha": 0.08}


@pytest.fixture(scope="module")
def traced(plastic_day):
    """A GGX plastic's light cache on the plastic's day (the day the fits below read, rendered
    once for the module), the Dr.Jit model on it and its table."""
    from skyfit_mi.fitting.fit import FitCache, FitSession
    from skyfit_mi.render.basis_table import tabulate
    from skyfit_mi.render.fit_model import WardModel

    s = FitSession(plastic_day, "disc", REGION, model="two", normalisation="ggx_plastic",
                   cache=FitCache(positions=8, directions=128, seed=2), light=None)
    cache = s.light_cache()
    wm = WardModel(cache, "two", "ggx_plastic")
    return cache, wm, tabulate(cache, wm)


@pytest.mark.parametrize("sigma", [0.0, 0.001, 0.0031, 0.011, 0.042, 0.07, 0.31, 0.5])
def test_a_microfacet_table_equals_the_dr_jit_model(traced, sigma):
    """The table's Chebyshev series of the GGX lobe hold the Dr.Jit model to float32's
    rounding, as Ward's do (tests/test_basis_table.py)."""
    from skyfit_mi.render.basis_table import TableModel

    _, wm, table = traced
    assert table.normalisation == "ggx_plastic"
    theta = np.array([0.7, sigma])
    a, b = wm.radiance(theta), TableModel(table, "two").radiance(theta)
    assert np.max(np.abs(a - b)) <= 2e-6 * np.max(np.abs(a)), sigma


@pytest.mark.parametrize("sigma", [0.01, 0.042, 0.2])
def test_the_numpy_basis_equals_the_dr_jit_model(traced, sigma):
    """The NumPy twin (physics.microfacet through ward.specular_lobe and lobe_albedo, the control
    variate's GGX nodes) and the Dr.Jit model (the plugin) on the same cache."""
    cache, wm, _ = traced
    basis = 0.3 * cache.diffuse_basis() + 0.7 * cache.specular_basis(sigma, "ggx_plastic")
    assert np.allclose(basis, wm.radiance([0.7, sigma]), rtol=1e-4)


def _mitsuba_plastic(xml, rho_d, s, alpha):
    """The scene ``xml`` with the disc's material made of Mitsuba's own BSDFs: a blend of
    ``diffuse`` and ``roughplastic`` without its diffuse part (GGX, eta 1.5), half each, so
    f_r = rho_d / pi + s F D G1 G1 / (4 cos_i cos_o)."""
    root = ET.fromstring(xml)
    for el in root.iter("bsdf"):
        if el.get("id") == "disc":
            for child in list(el):
                el.remove(child)
            el.attrib = {"type": "blendbsdf", "id": "disc"}
            ET.SubElement(el, "float", name="weight", value="0.5")
            d = ET.SubElement(el, "bsdf", type="diffuse")
            ET.SubElement(d, "rgb", name="reflectance", value=repr(2 * rho_d))
            p = ET.SubElement(el, "bsdf", type="roughplastic")
            for k, v in (("distribution", "ggx"), ("alpha", alpha), ("int_ior", 1.5),
                         ("ext_ior", 1.0), ("diffuse_reflectance", 0.0),
                         ("specular_reflectance", 2 * s)):
                ET.SubElement(p, "string" if isinstance(v, str) else "float", name=k,
                              value=str(v))
    return ET.tostring(root, encoding="unicode")


@pytest.fixture(scope="module")
def plastic_day(tmp_path_factory, mi):
    """The disc day (tests/conftest.py's) rendered with the Mitsuba plastic of TRUTH, 1%
    noise."""
    from skyfit_mi.render import scene_xml
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import thesis_disc_spec, validate_spec

    tmp = tmp_path_factory.mktemp("plastic")
    raw = thesis_disc_spec("plastic", {"model": "two", **TRUTH}, size=12, noise_percent=1.0,
                           spp=1024, seed=11, exposure=0.0015)
    build = scene_xml.build_scene_xml

    def mitsuba_scene(spec):
        xml, mats, to_world = build(spec)
        return _mitsuba_plastic(xml, 1 - TRUTH["rho_s"], TRUTH["rho_s"],
                                TRUTH["sigma_alpha"]), mats, to_world
    scene_xml.build_scene_xml = mitsuba_scene
    try:
        render_sequence(validate_spec(raw, tmp), tmp / "plastic", progress=False,
                        log=lambda *a: None)
    finally:
        scene_xml.build_scene_xml = build
    return tmp / "plastic"


def test_a_mitsuba_plastic_is_fitted_best_by_its_own_family(plastic_day):
    """GGX plastic fits the day rendered with Mitsuba's roughplastic at chi2/dof near 1, its
    roughness and reflectance within their intervals; Ward's lobe and Beckmann's cannot."""
    from skyfit_mi.fitting.fit import fit_region, FitCache

    r = {n: fit_region(plastic_day, "disc", REGION, normalisation=n,
                       cache=FitCache(positions=4, directions=256), log=lambda *a: None)
         for n in ("ggx_plastic", "beckmann_plastic", "ward")}
    chi2 = {n: v["chi2_per_dof"] for n, v in r.items()}
    g = r["ggx_plastic"]
    for k, v in TRUTH.items():
        lo, hi = g["intervals"][k]["95"]
        assert lo <= v <= hi, (k, v, lo, hi, chi2)
    assert chi2["ggx_plastic"] < 2.0, chi2
    # its frames predicted from the others as well as noise and the parameters' spread say
    assert g["model_error"]["held_out"]["kappa"] == 0.0, g["model_error"]
    assert not any(w.startswith("frames left out") for w in g["warnings"])
    assert chi2["ggx_plastic"] < 0.5 * min(chi2["beckmann_plastic"], chi2["ward"]), chi2


def test_model_auto_ranks_the_true_family_first_and_writes_the_ranking(plastic_day, tmp_path):
    """``fit --model auto`` on the Mitsuba plastic: GGX plastic ranked first by held-out frames,
    the two-parameter model chosen (the one-standard-error rule), its fit written with the
    ranking (JSON and fits.csv), and relight takes the chosen lobe from the JSON."""
    import csv
    import json

    from skyfit_mi.cli import main

    out = tmp_path / "auto"
    main(["fit", str(plastic_day), "--region", "disc=rect:4,4,7,7",
          "--model", "auto", "--positions", "4", "--directions", "256", "--output", str(out),
          "--quiet"])
    r = json.loads((out / "fit_disc.json").read_text())
    sel = r["model_selection"]
    assert sel["ranking"][0]["normalisation"] == "ggx_plastic"
    assert sel["chosen"] == {"normalisation": "ggx_plastic", "model": "two",
                             "rank": sel["chosen"]["rank"]}
    assert (r["model"], r["normalisation"]) == ("two", "ggx_plastic")
    assert len(sel["ranking"]) == 18 and set(sel["trace_time_s"]) >= {"ggx_plastic", "ward"}
    lo, hi = r["intervals"]["sigma_alpha"]["95"]
    assert lo <= TRUTH["sigma_alpha"] <= hi
    rows = list(csv.DictReader((out / "fits.csv").open()))
    assert rows[0]["normalisation"] == "ggx_plastic"
    assert rows[0]["model_ranking"].startswith("1 ggx_plastic/")


@pytest.mark.parametrize("per_value, chosen", [(1.0, 5), (0.5, 5), (4.0, 2)])
def test_selection_window_widens_with_what_the_noise_model_leaves_out(per_value, chosen):
    """The one-standard-error window is sqrt(2 n) held-out chi-square where the best candidate
    fits to its noise (a 2-parameter model 2 sqrt(2 n) worse is left out) and c sqrt(2 n) where
    its held-out chi-square per value is c > 1 (model error, quantisation): the same gap is
    then inside it."""
    from skyfit_mi.fitting.selection import choose

    n = 800
    best = per_value * n
    rows = [{"parameters": 5, "held_out_chi2": best, "held_out_values": n,
             "held_out_chi2_per_value": best / n},
            {"parameters": 2, "held_out_chi2": best + 2 * np.sqrt(2 * n), "held_out_values": n,
             "held_out_chi2_per_value": (best + 2 * np.sqrt(2 * n)) / n}]
    pick, c = choose(rows)
    assert pick["parameters"] == chosen
    assert c == max(1.0, per_value)


@pytest.fixture(scope="module")
def photographed_plastic(plastic_day, tmp_path_factory):
    """The plastic's day called photographed (``source`` 'ingest'): its spec's sky is then a
    model of the real one, and fits take its level with their prior (``--sky prior``)."""
    import json
    import shutil

    day = tmp_path_factory.mktemp("photographed") / "day"
    shutil.copytree(plastic_day, day)
    m = json.loads((day / "manifest.json").read_text())
    (day / "manifest.json").write_text(json.dumps({**m, "source": "ingest"}))
    return day


@pytest.fixture(scope="module")
def auto_map(photographed_plastic, tmp_path_factory):
    """The first run of ``fit --per-pixel --model auto`` on the plastic's day called
    photographed (two lobes and a small light cache in the ranking, for time), its first fits
    (:func:`~skyfit_mi.fitting.selection.fit_auto` on up to ``light_pixels`` of the region's
    pixels, in the light the map resolved: ``--sky prior``, the default for photographs)
    recorded as they ran: their arguments, results and every line they logged.  The map's test
    and the test of ``--model auto`` on photographs share this one ranking and fit."""
    import functools

    from skyfit_mi.fitting import pixel_map
    from skyfit_mi.fitting.pixel_map import ClusterOptions, MapOptions, run_map
    from skyfit_mi.fitting.selection import fit_auto

    ranked = functools.partial(fit_auto, families=("ward", "ggx_plastic"), cache=FitCache(4, 256))
    auto = {"calls": 0, "results": [], "lines": []}

    def recorded(manifest_path, regions, log=print, **kw):
        auto.update(calls=auto["calls"] + 1, regions=regions, options=kw)

        def both(line):
            auto["lines"].append(line)
            log(line)
        for r in ranked(manifest_path, regions, log=both, **kw):
            auto["results"].append(r)
            yield r

    day = photographed_plastic                        # the sky's level is fitted first too
    pixels = np.stack(np.meshgrid(np.arange(3, 9), np.arange(3, 9)), -1).reshape(-1, 2)
    out = tmp_path_factory.mktemp("auto_map") / "map"
    logs = []
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(pixel_map, "fit_auto", recorded)
        s = run_map(day, [("disc", pixels)], out, MapOptions("auto", chunk=18, light_pixels=16),
                    ClusterOptions(workers=1), progress=False, log=logs.append)
    return {"day": day, "pixels": pixels, "out": out, "summary": s, "logs": logs, "auto": auto}


def test_model_auto_on_photographs_fits_the_chosen_model_with_the_skys_level(auto_map):
    """The plastic's day called photographed (the spec's sky then a model of the real one):
    ``--model auto`` (the map's first fits, :func:`auto_map`: every parameter count of two
    lobes ranked on 16 of the disc's pixels) ranks the candidates, then fits each region's
    chosen model with the sky's level (``--sky prior``, the default for photographs), whose
    interval holds the day's own (1); the sigma_alpha interval holds the truth and the result
    keeps its ranking. A sky option a fit cannot take is refused before any light is
    traced."""
    from skyfit_mi.errors import SkyfitError
    from skyfit_mi.fitting.selection import fit_auto

    day, auto = auto_map["day"], auto_map["auto"]
    (name, pixels), = auto["regions"]
    assert auto["calls"] == 1 and name == "disc" and len(pixels) == 16
    assert "models" not in auto["options"] and auto["options"]["light"].sky == "prior"
    logs = auto["lines"]
    r, = auto["results"]
    assert len(r["model_selection"]["ranking"]) == 6       # two lobes, three models each
    assert r["model_selection"]["chosen"]["normalisation"] == "ggx_plastic"
    assert r["normalisation"] == "ggx_plastic" and r["sky"]["regions"] == ["disc"]
    lo, hi = r["sky"]["interval95"]
    assert lo < 1.0 < hi, r["sky"]
    lo, hi = r["intervals"]["sigma_alpha"]["95"]
    assert lo <= TRUTH["sigma_alpha"] <= hi, r["intervals"]["sigma_alpha"]
    assert any("with the sky's level (--sky prior)" in x for x in logs), logs
    with pytest.raises(SkyfitError, match="--sky-terms 9"):
        next(fit_auto(day, [("disc", pixels)], light=LightOptions(sky="fit", terms=9),
                      log=logs.append))


def test_a_map_with_model_auto_maps_each_region_in_its_chosen_lobe(auto_map, monkeypatch):
    """``fit --per-pixel --model auto`` on the plastic's day called photographed: the region's
    model and lobe ranked first (on up to --max-pixels of its pixels) and the sky's level
    fitted with them (its interval holding the day's own), then every pixel mapped in them
    under that light: GGX plastic, the map's planes its model's parameters alone, the pixels'
    roughness about the truth; run again, the map resumes with the choices and light its
    store holds.  (The map's first run is :func:`auto_map`'s.)"""
    from skyfit_mi.fitting import pixel_map
    from skyfit_mi.fitting.pixel_map import ClusterOptions, MapOptions, run_map
    from skyfit_mi.render.fit_model import PARAMETERS

    day, pixels, out = auto_map["day"], auto_map["pixels"], auto_map["out"]
    s, logs = auto_map["summary"], list(auto_map["logs"])
    assert auto_map["auto"]["calls"] == 1                 # the ranking ran, once
    lo, hi = s["sky"]["interval95"]
    assert lo < 1.0 < hi and any("fitted sky level" in w for w in s["widths_include"]), s["sky"]
    disc = s["regions"]["disc"]
    # GGX plastic; its two-parameter model (a white material's rho_d + rho_s = 1) or, with
    # the light's level fitted apart, the one with R free (measured)
    assert disc["normalisation"] == "ggx_plastic" and disc["model"] in ("two", "achromatic")
    assert s["parameters"] == list(PARAMETERS[disc["model"]]) and "ranked" in s["models"]
    assert not (out / "C_r.exr").exists()
    assert abs(disc["median"]["sigma_alpha"] / TRUTH["sigma_alpha"] - 1) < 0.15, disc
    assert any(f": chose ggx_plastic {disc['model']}" in x for x in logs), logs
    # the same command again resumes the store with the choices it holds, ranking nothing
    monkeypatch.setattr(pixel_map, "fit_auto", None)
    again = run_map(day, [("disc", pixels)], out,
                    MapOptions("auto", chunk=18, light_pixels=16), ClusterOptions(workers=1),
                    progress=False, log=logs.append)
    assert again["chunks_this_run"] == 0 and again["regions"]["disc"]["normalisation"] == \
        "ggx_plastic" and again["sky"]["k"] == s["sky"]["k"]
