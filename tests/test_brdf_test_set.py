"""The machinery of scripts/brdf_test_set.py (issue 37's BRDF test set; the sweep itself is
slow): how it counts held-out values, bands and ratios, Mitsuba's BSDF evaluated for a table,
and a lab table of a material a family holds exactly, whose chosen model predicts the held-out
lights as well as that family fitted to every light."""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))

import brdf_test_set as bts
from bench_core import TABLE_TRUTH

HEADER = ("region,frame,time,channel,predicted [W m^-2 sr^-1],lo95 [W m^-2 sr^-1],"
          "hi95 [W m^-2 sr^-1],observed [W m^-2 sr^-1]")


def test_coverage_counts_only_the_held_out_frames(tmp_path):
    """Frames 0 and 2 trained: of the four held-out values (frames 1, 3), three lie in their
    bands; the trained frames' values (one outside) are not counted."""
    rows = [("0", 1.0, 0.0, 2.0, 5.0), ("1", 1.0, 0.0, 2.0, 1.5), ("1", 1.0, 0.0, 2.0, 2.5),
            ("2", 1.0, 0.0, 2.0, 1.0), ("3", 1.0, 0.0, 2.0, 0.0), ("3", 1.0, 0.0, 2.0, 2.0)]
    csv = tmp_path / "prediction.csv"
    csv.write_text(HEADER + "\n" + "".join(f"disc,{f},,R,{p},{lo},{hi},{o}\n"
                                           for f, p, lo, hi, o in rows))
    assert bts.coverage(csv, trained=[0, 2]) == (0.75, 4)
    assert bts.coverage(csv) == (4 / 6, 6)


def test_the_verdict_weighs_coverage_by_values_and_checks_both_goals():
    rows = [{"ratio": 1.0, "coverage95": 1.0, "held_out_values": 30},
            {"ratio": 1.1, "coverage95": 0.5, "held_out_values": 10},
            {"ratio": 3.5, "coverage95": 1.0, "held_out_values": 60}]
    v = bts.verdict(rows)
    assert v["median_ratio"] == pytest.approx(1.1) and v["largest_ratio"] == 3.5
    assert not v["goal_met"]                          # one ratio above 3
    assert v["coverage95"] == pytest.approx(0.95) and v["held_out_values"] == 100
    assert bts.verdict(rows[:2])["goal_met"]
    assert v["views_values"] == 0 and v["views_coverage95"] is None
    # a new view's rows (--views) give coverage alone, apart from the held-out camera's
    views = [{"view": True, "coverage95": 0.9, "held_out_values": 20},
             {"view": True, "coverage95": 1.0, "held_out_values": 20}]
    w = bts.verdict(rows + views)
    assert w["coverage95"] == pytest.approx(0.95) and w["held_out_values"] == 100
    assert w["views_coverage95"] == pytest.approx(0.95) and w["views_values"] == 40
    assert "new views: 95% band coverage of 40 values 0.950" in bts.table_markdown(
        [dict(r, material="m", data="d", chosen="c", held_out_rel_rms=0.1, oracle="o",
              oracle_rel_rms=0.1) for r in rows] + [dict(r, material="m", data="d", chosen="c")
                                                   for r in views])


def test_a_mitsuba_bsdf_is_evaluated_as_a_brdf(mi):
    """Mitsuba's ``diffuse`` of reflectance 0.5 gives 0.5 / pi at any pair of directions (its
    eval's cosine divided out); a rough conductor is reciprocal (wi and wo swapped)."""
    from independent import mitsuba_brdf

    rng = np.random.default_rng(3)
    wi, wo = (v / np.linalg.norm(v, axis=1, keepdims=True)
              for v in (rng.normal(size=(50, 3)) * [1, 1, 0] + [0, 0, 0.7] for _ in range(2)))
    f = mitsuba_brdf('<bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf>')
    assert np.allclose(f(wi, wo, None), 0.5 / np.pi, rtol=1e-6)
    gold = mitsuba_brdf(bts.MATERIALS["roughconductor gold (Beckmann 0.15)"])
    assert np.allclose(gold(wi, wo, None), gold(wo, wi, None), rtol=1e-4)
    f = gold(wi, wo, None)
    lit = f[:, 2] > 0                              # the rest far off the lobe: 0 in float32
    assert lit.sum() > 10 and (f[lit, 0] > 2 * f[lit, 2]).all()          # gold is yellow


def test_a_ward_table_is_predicted_as_well_as_its_family_fitted_to_every_light(tmp_path, mi):
    """A lab table of the Ward reference itself (bench_core's TABLE_TRUTH): ``fit --model
    auto`` on every other light predicts the rest within the noise, as the Ward family fitted
    to every light does (ratio within 0.1 of 1); the held-out values are the points x
    the held-out lights x 3 channels, and their 95% bands hold them."""
    from skyfit_mi.physics.ward import raw_parameters, ward_brdf

    rho_d, spec_r, sigma = raw_parameters("colour", **TABLE_TRUTH)

    def ward(wi, wo, rng):
        return ward_brdf(wi, wo, rho_d, spec_r, sigma)
    [row] = bts.table_case("Ward", ward, tmp_path, lights=16, families=("ward", "ggx_metal"),
                           points=8)
    print({k: row[k] for k in ("held_out_values", "oracle", "oracle_rel_rms", "held_out_rel_rms",
                               "ratio", "coverage95")})
    assert row["held_out_values"] == 8 * 8 * 3
    assert row["oracle"] == "ward colour"
    assert 1.0 <= row["oracle_by_family"]["ward two"] / row["oracle_rel_rms"]  # the minimum
    assert row["held_out_rel_rms"] < 0.02                       # the 1% noise, mostly
    assert row["ratio"] == pytest.approx(1.0, abs=0.1)
    assert row["coverage95"] >= 0.9
