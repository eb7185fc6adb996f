"""The lab example (scenes/lab): a photometric-stereo rig's table made from a render of
``lab_disc.toml`` by ``scripts/lab_example.py``, checked against the shipped
``observations.csv``, then ingested, fitted, relit and mapped through the CLI with frames by
index; its clipped highlight, marked ``saturated``, censored as an image's top code."""
import csv
import json
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2 as chi2_dist

from skyfit_mi.cli import main
from skyfit_mi.pipeline.manifest import load_manifest
from skyfit_mi.pipeline.spec import load_spec

ROOT = Path(__file__).resolve().parents[1]
LAB = ROOT / "scenes" / "lab"


@pytest.fixture(scope="module")
def example(tmp_path_factory, mi):
    """(folder, the render, the table made again, ingested sequence, fit JSON) of the example."""
    sys.path.insert(0, str(ROOT / "scripts"))
    from lab_example import make_table

    tmp = tmp_path_factory.mktemp("lab")
    table = make_table(tmp / "render", tmp / "observations.csv")
    seq, fits = tmp / "seq", tmp / "fits"
    assert main(["ingest", str(LAB / "lab_disc.toml"), "--table", str(table), "-o",
                 str(seq)]) == 0
    assert main(["fit", str(seq), "--all", "--model", "5", "-o", str(fits)]) == 0
    return tmp, tmp / "render", table, seq, fits / "fit_disc.json"


def _rows(path):
    return list(csv.DictReader(Path(path).open()))


def test_the_shipped_example_table_is_the_scripts(example):
    """The table made again from a render agrees with the shipped one: the same rows and
    flags, values within a tenth of their sigma (the render's Monte Carlo error, a small part
    of the sigma, may differ between machines)."""
    _, _, table, _, _ = example
    new, shipped = _rows(table), _rows(LAB / "observations.csv")
    key = ("frame", "region", "point", "saturated_r", "saturated_g", "saturated_b")
    assert [tuple(r[k] for k in key) for r in new] == [tuple(r[k] for k in key) for r in shipped]
    for a, b in zip(new, shipped):
        for c in "rgb":
            assert abs(float(a[c]) - float(b[c])) <= 0.1 * float(b[f"sigma_{c}"]), (a, b)
    assert sum(r["saturated_r"] == "1" for r in shipped) > 0         # the highlight clips


def test_the_example_table_is_ingested_by_index_and_fitted_to_its_truth(example):
    """The sequence keeps the twelve lights as frames 0-11 without time; its saturated values
    are censored (read as an image's top code) and the truth lies in the fit's joint 99.9%
    region; without their flags, the clipped highlight pulls rho_s down, out of it."""
    from skyfit_mi.fitting.fit import FitSession

    tmp, _, table, seq, fit = example
    doc, _ = load_manifest(seq)
    assert [f["index"] for f in doc["frames"]] == list(range(12))
    assert not any("time" in f for f in doc["frames"]) and "location" not in doc
    flags = sum(r[f"saturated_{c}"] == "1" for r in _rows(table) for c in "rgb")
    assert doc["ingest"]["saturated_values"] == flags
    truth_spec = load_spec(LAB / "lab_disc.toml").materials["disc"]
    truth = np.array([*truth_spec["C"], truth_spec["rho_s"], truth_spec["sigma_alpha"]])
    r = json.loads(fit.read_text())
    assert r["series"]["times"] == [None] * 12 and r["frames"] == list(range(12))
    s = FitSession(seq, "disc", None, model="colour")
    assert int(s.problem.clipped()[1].sum()) == flags
    bound = chi2_dist.ppf(0.999, 5) * r["interval_scale_s2"] + r["cache_noise_chi2"]
    theta = np.array(list(r["parameters"].values()))
    rise = s.problem.chi2(truth) - s.problem.chi2(theta)
    assert 0.0 <= rise <= bound, (rise, r["parameters"])

    # the same table without its flags: the clipped values taken as measured
    rows = _rows(table)
    plain = tmp / "unflagged.csv"
    with plain.open("w") as f:
        w = csv.DictWriter(f, [k for k in rows[0] if not k.startswith("saturated")],
                           extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    assert main(["ingest", str(LAB / "lab_disc.toml"), "--table", str(plain), "-o",
                 str(tmp / "unflagged")]) == 0
    biased = FitSession(tmp / "unflagged", "disc", None, model="colour").run("global",
                                                                            log=lambda *a: None)
    assert biased["parameters"]["rho_s"] < r["intervals"]["rho_s"]["95"][0]
    assert biased["chi2_per_dof"] > 2.0


def test_the_example_relights_and_maps_by_frame_index(example):
    tmp, render, _, seq, fit = example
    out = tmp / "relit"
    assert main(["relight", str(fit), "--target", str(seq), "--no-images", "-o", str(out)]) == 0
    rows = _rows(out / "prediction.csv")
    assert sorted({int(r["frame"]) for r in rows}) == list(range(12))
    assert {r["time"] for r in rows} == {""}
    errors = json.loads((out / "relight.json").read_text())
    assert errors["band_coverage"]["share"] >= 0.8
    # every point's value is predicted; the clipped highlight's, lower bounds only, are marked
    # and left out of the band's coverage and the errors
    assert {r["point"] for r in rows} == {r["point"] for r in _rows(LAB / "observations.csv")}
    clipped = [r for r in rows if r["saturated"] == "yes"]
    assert clipped and errors["band_coverage"]["values"] == len(rows) - len(clipped)
    assert errors["regions"]["disc"]["values"] == len(rows) - len(clipped)
    # the clipped highlight's values, lower bounds only, are left out of the region means
    assert errors["region_means"]["disc"]["fit"] < 0.02, errors["region_means"]
    assert main(["chi2map", str(seq), str(fit), "--n", "6", "-o", str(tmp / "map")]) == 0
    assert (tmp / "map.csv").is_file()
    # the rendered lab frames relit with the fit, images and all
    assert main(["relight", str(fit), "--target", str(render), "-o", str(tmp / "relit_images"),
                 "--quiet"]) == 0
    assert len(list((tmp / "relit_images").glob("compare_*.png"))) == 12
