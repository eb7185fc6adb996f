"""chi2map: chi-square over two parameters of a fitted region, from the fit's fast model."""
import csv
import json

import numpy as np
import pytest

from skyfit_mi.cli import main


@pytest.fixture(scope="module")
def fitted(days, tmp_path_factory):
    out = tmp_path_factory.mktemp("chi2map")
    assert main(["fit", str(days["noisy"]), "--region", "disc=rect:4,4,7,7", "--model", "3",
                 "-o", str(out)]) == 0
    return days["noisy"], out / "fit_disc.json"


def test_the_maps_minimum_is_the_fits(fitted, tmp_path, capsys):
    """A 60 x 60 map around the fit: its grid minimum lies within one grid step of the fitted
    (rho_s, sigma_alpha), and it is the true chi-square there (the fit's chi2 within 0.1%)."""
    day, fit = fitted
    r = json.loads(fit.read_text())
    rho, sigma = r["parameters"]["rho_s"], r["parameters"]["sigma_alpha"]
    prefix = tmp_path / "map"
    assert main(["chi2map", str(day), str(fit), "--x-range", f"{rho - 0.1:.4f},{rho + 0.1:.4f}",
                 "--y-range", f"{sigma - 0.05:.4f},{sigma + 0.05:.4f}", "-o", str(prefix)]) == 0
    rows = list(csv.reader(open(prefix.with_suffix(".csv"))))
    assert rows[0] == ["rho_s", "sigma_alpha", "chi2"] and len(rows) == 1 + 60 * 60
    grid = np.array(rows[1:], dtype=float)
    best = grid[np.argmin(grid[:, 2])]
    assert abs(best[0] - rho) <= 0.2 / 59 + 1e-9 and abs(best[1] - sigma) <= 0.1 / 59 + 1e-9
    assert best[2] == pytest.approx(r["chi2"], rel=1e-3)
    assert prefix.with_suffix(".png").stat().st_size > 0
    assert "chi2 minimum" in capsys.readouterr().out


@pytest.mark.parametrize("args, phrase", [
    (["--x", "C_r"], "'C_r' is not a parameter of the achromatic model"),
    (["--x", "sigma_alpha"], "two different parameters"),
    (["--x-range", "0.5,0.2"], "must rise within"),
    (["--y-range", "1"], "give a range as LO,HI"),
])
def test_bad_maps_get_one_line(fitted, capsys, args, phrase):
    day, fit = fitted
    assert main(["chi2map", str(day), str(fit), "--n", "5", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert phrase in err and len(err.splitlines()) == 1, err


def test_a_profiled_map_is_at_most_the_fixed_one(fitted, tmp_path):
    """With R at its best for every (rho_s, sigma_alpha) the map lies at or below the map with
    R fixed at the fit (up to the linearisation), and lower at most points."""
    day, fit = fitted
    maps = {}
    for flag in ([], ["--profile"]):
        prefix = tmp_path / ("p" if flag else "f")
        assert main(["chi2map", str(day), str(fit), "--n", "12", "--y-range", "0.02,0.3",
                     *flag, "-o", str(prefix)]) == 0
        maps[bool(flag)] = np.array(list(csv.reader(open(prefix.with_suffix(".csv"))))[1:],
                                    dtype=float)[:, 2]
    fixed, profiled = maps[False], maps[True]
    assert np.all(profiled <= fixed * 1.01 + 1.0)
    assert np.mean(profiled < fixed - 1.0) > 0.5              # R's freedom lowers most points
    assert main(["chi2map", str(day), str(fit), "--x", "R", "--profile"]) == 2
