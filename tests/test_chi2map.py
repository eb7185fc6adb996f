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
    rows = list(csv.reader(prefix.with_suffix(".csv").read_text().splitlines()))
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


@pytest.fixture(scope="module")
def session(fitted):
    from skyfit_mi.fitting.fit import FitCache, FitSession

    day, fit = fitted
    r = json.loads(fit.read_text())
    return FitSession.from_fit(r, day, cache=FitCache(seed=0)), r


@pytest.mark.parametrize("x, y", [("rho_s", "sigma_alpha"), ("R", "sigma_alpha"),
                                  ("R", "rho_s")])
def test_a_profiled_map_is_at_most_the_fixed_one(session, x, y):
    """With every other parameter at its best for each point (started from the linearised
    best and from the fit, polished on the true chi-square) the map lies below the map with
    them fixed at the fit at many points, never above it, and never below the fit's own
    chi-square (the global minimum)."""
    from skyfit_mi.fitting.landscape import chi2_map, map_axes, profiled_map

    s, r = session
    theta = np.array([r["parameters"][k] for k in s.names])
    xs, ys = map_axes(s.model, x, y, None, (0.02, 0.3) if y == "sigma_alpha" else None, 12,
                      profile=True)
    fixed = chi2_map(s, theta, x, y, xs, ys)
    profiled = profiled_map(s, theta, x, y, xs, ys)
    # the freedom lowers many points (share measured: 0.32 for (rho_s, sigma_alpha) on the
    # sun_sky_path frames, above 0.5 on Mitsuba path's): the fitted R is at its upper bound 1
    # (the truth of this disc), so at the points that would want R > 1 it cannot move
    assert np.mean(profiled < fixed - 1.0) > 0.25
    assert np.all(profiled <= fixed * (1 + 1e-6) + 1e-6)
    assert profiled.min() >= r["chi2"] * (1 - 1e-4)


@pytest.fixture(scope="module")
def few_pixels(fitted, tmp_path_factory):
    """The fit with its first four pixels alone (a cheaper light cache to trace), for the
    tests of what chi2map writes where, which do not read the map's values."""
    day, fit = fitted
    r = json.loads(fit.read_text())
    r["pixels"] = r["pixels"][:4]
    path = tmp_path_factory.mktemp("few") / "fit_disc.json"
    path.write_text(json.dumps(r))
    return day, path


def test_a_profiled_map_from_the_command_line(few_pixels, tmp_path, capsys):
    day, fit = few_pixels
    assert main(["chi2map", str(day), str(fit), "--n", "4", "--profile", "--x", "R",
                 "-o", str(tmp_path / "p")]) == 0
    assert len((tmp_path / "p.csv").read_text().splitlines()) == 1 + 16
    assert "chi2 minimum" in capsys.readouterr().out


def test_a_two_parameter_fit_has_nothing_to_profile(fitted, tmp_path, capsys):
    day, fit = fitted
    r = json.loads(fit.read_text())
    two = {**r, "model": "two", "parameters": {k: r["parameters"][k]
                                               for k in ("rho_s", "sigma_alpha")}}
    two.pop("draws", None)                     # the colour model's sets: not the two's
    (tmp_path / "fit_two.json").write_text(json.dumps(two))
    assert main(["chi2map", str(day), str(tmp_path / "fit_two.json"), "--profile"]) == 2
    assert "no other parameter to profile" in capsys.readouterr().err


def test_a_map_does_not_replace_a_fit_folders_files(fitted, few_pixels, tmp_path, capsys):
    """-o onto a fit folder's files (fits.csv, a fit's PNG) is refused unless --overwrite; a
    folder as -o (existing, or new with a trailing slash) takes the map under its default name,
    and an earlier map is replaced."""
    import shutil

    day, fit = few_pixels
    folder = tmp_path / "fits"
    shutil.copytree(fitted[1].parent, folder)
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    for prefix in ("fits", "fit_disc"):
        assert main(["chi2map", str(day), str(fit), "--n", "3", "-o", str(folder / prefix)]) == 2
        err = capsys.readouterr().err
        assert "is not a chi-square map's" in err and len(err.splitlines()) == 1
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
    for _ in range(2):
        assert main(["chi2map", str(day), str(fit), "--n", "3", "-o", str(folder)]) == 0
    assert (folder / "chi2map_disc_rho_s_sigma_alpha.csv").exists()
    made = json.loads((folder / "chi2map_disc_rho_s_sigma_alpha.chi2map.json").read_text())
    assert made["seed"] == 0 and made["fit"] == str(fit) and made["minimum"]["chi2"] > 0
    # a new folder, written with its trailing slash
    assert main(["chi2map", str(day), str(fit), "--n", "3", "-o", f"{tmp_path / 'new'}/"]) == 0
    assert (tmp_path / "new" / "chi2map_disc_rho_s_sigma_alpha.csv").exists()
    assert main(["chi2map", str(day), str(fit), "--n", "3", "-o", str(folder / "fit_disc"),
                 "--overwrite"]) == 0
    assert (folder / "fit_disc.png").read_bytes() != before["fit_disc.png"]
    assert (folder / "fit_disc.json").read_bytes() == before["fit_disc.json"]


@pytest.mark.parametrize("change, phrase", [
    ({"parameters": {"rho_s": 1.5}}, "rho_s = 1.5 is outside its bounds [0, 1]"),
    ({"intervals": {"rho_s": {"95": [0.5, 0.1]}}}, "runs backwards (lo > hi)"),
    ({"covariance": [[1.0, 0.0], [0.0, 1.0]]}, "covariance must be"),
    ({"covariance": {"names": ["rho_s", "sigma_alpha"], "matrix": [[-1.0, 0.0], [0.0, 1.0]]}},
     "no variance below 0"),
    ({"frames": "all"}, "frames must be a list of manifest frame indices"),
])
def test_a_hand_edited_fit_is_refused_by_name(fitted, tmp_path, capsys, change, phrase):
    """chi2map and relight read a fit JSON through one reader: a parameter beyond its bounds,
    an interval running backwards, a covariance or frames of the wrong shape are refused,
    not mapped (or crashed on)."""
    day, fit = fitted
    r = json.loads(fit.read_text())
    for key, value in change.items():
        if isinstance(value, dict):
            for k, v in value.items():
                r[key][k] = v
        else:
            r[key] = value
    bad = tmp_path / "fit_disc.json"
    bad.write_text(json.dumps(r))
    for argv in (["chi2map", str(day), str(bad), "--n", "3", "-o", str(tmp_path / "m")],
                 ["relight", str(bad), "--target", str(day), "-o", str(tmp_path / "r"),
                  "--no-images"]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert phrase in err and str(bad) in err and len(err.splitlines()) == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit_disc.json"]


@pytest.mark.parametrize("change, phrase", [
    ({"points": ["disc"]}, "is a fit of an observation table's points, but"),
    ({"frames": [0, 99]}, "lists frame 99, which"),
    ({"sequence_run_id": "0123456789abcdef"}, "was fitted to another sequence (run 0123"),
])
def test_a_fit_of_another_sequence_is_refused_with_the_cause(fitted, tmp_path, capsys, change,
                                                             phrase):
    """chi2map maps a fit's own chi-square: a fit of a table's points, of another run, or of
    frames the sequence lacks is refused saying so (not 'frame 4 is not a rendered frame' or
    an internal error)."""
    day, fit = fitted
    bad = tmp_path / "fit_disc.json"
    bad.write_text(json.dumps({**json.loads(fit.read_text()), **change}))
    assert main(["chi2map", str(day), str(bad), "--n", "3", "-o", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err
    assert phrase in err and len(err.splitlines()) == 1, err
