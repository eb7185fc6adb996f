"""The `skyfit` command under bad input: one line naming the input, exit 2, never a traceback;
Ctrl-C exits 130; fits.csv always agrees with the fit results on disk."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from skyfit_mi import cli
from skyfit_mi.cli import build_parser, main
from skyfit_mi.errors import SkyfitError
from skyfit_mi.pipeline.spec import SpecError, thesis_disc_spec, validate_spec


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err.strip()
    return code, err


def _one_line_error(err, *phrases):
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    assert err.startswith("skyfit")
    for p in phrases:
        assert p in err, err


@pytest.fixture(scope="module")
def day(tmp_path_factory, mi):
    """A tiny rendered day (8x8, 3 frames) for the CLI's checks."""
    from skyfit_mi.pipeline.sequence import render_sequence

    tmp = tmp_path_factory.mktemp("cli")
    raw = thesis_disc_spec("cli", {"model": "two", "rho_s": 0.3, "sigma_alpha": 0.1}, size=8,
                           spp=4, exposure=0.0015)
    raw["time"] = {"date": "2026-06-21", "times": ["09:00", "12:00", "15:00"]}
    render_sequence(validate_spec(raw, tmp), tmp / "day", progress=False, log=lambda *a: None)
    return tmp / "day"


def test_version_help_and_description(capsys):
    import skyfit_mi

    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"skyfit-mi {skyfit_mi.__version__}"
    parser = build_parser()
    assert parser.description.endswith(".") and "\n" not in parser.description
    subs = next(a for a in parser._actions if a.dest == "command").choices
    for name, sub in subs.items():
        for action in sub._actions:
            assert action.help, f"skyfit {name} {action.option_strings or action.dest} has no help"
        assert "usage" in sub.format_help()          # formats (a bare % in a help breaks it)
    fit = subs["fit"]
    assert fit.get_default("model") == "5"        # the README's main job fits --model 5


@pytest.mark.parametrize("argv, phrases", [
    (["fit", "{day}", "--all", "--positions", "0"], ["--positions", "0 is outside [1, 4096]"]),
    (["fit", "{day}", "--all", "--seed", "-1"], ["--seed", "-1 is outside"]),
    (["fit", "{day}", "--all", "--seed", "x"], ["--seed", "'x' is not a whole number"]),
    (["fit", "{day}", "--all", "--max-pixels", "-3"], ["--max-pixels", "-3 is below 0"]),
    (["fit", "{day}", "--mask", "m.png", "--label", "disc=abc"], ["--label", "whole number"]),
    (["fit", "{day}", "--region", "disc=rect:1,1", "--model", "2"], ["--region", "rect:x0,y0,x1,y1"]),
    (["fit", "{day}", "--region", "disc=pixels:"], ["--region", "at least one pixel"]),
    (["fit", "{day}", "--region", "../x=rect:1,1,2,2"], ["--region", "letters, digits"]),
    (["fit", "{day}", "--all", "--start", "a,b"],
     ["--start", "not comma-separated finite numbers"]),
    (["fit", "{day}", "--all", "--pose-sd-deg", "-1"],
     ["--pose-sd-deg", "pose_sd_deg azimuth = -1 deg is outside the valid range [0, 10]"]),
    (["fit", "{day}", "--all", "--pose-sd-deg", "x"], ["--pose-sd-deg", "not a number"]),
    (["fit", "{day}", "--all", "--per-pixel", "--pose-sd-deg", "1"],
     ["--pose-sd-deg belongs to region fits"]),
    (["render", "{tmp}/pose.toml", "-o", "{tmp}/out"],
     ["[camera] pose_sd_deg has no angle 'tilt'"]),
    (["fit", "{day}", "--all", "--normalisation", "radiance"],
     ["normalisation 'radiance' cannot be fitted", "'balanced'"]),
    (["fit", "{day}", "--all", "--model", "2", "--start", "0.5"],
     ["start gives 1 value(s); model 'two' has 2: rho_s, sigma_alpha"]),
    (["fit", "{day}", "--all", "--model", "2", "--start", "0.5,0.1,0.2"], ["gives 3 value(s)"]),
    (["fit", "{day}", "--all", "--model", "2", "--start", "1.5,0.1"],
     ["start rho_s = 1.5 is outside its bounds [0, 1]"]),
    (["fit", "{day}", "--region", "disc=rect:1,1,2,2", "--region", "disc=rect:3,3,4,4"],
     ["region 'disc' is given twice"]),
    (["fit", "{day}", "--label", "disc=1"], ["--label NAME=VALUE needs --mask"]),
    (["fit", "{day}", "--mask", "{tmp}/nosuch.png", "--label", "disc=1"], ["cannot read mask"]),
    (["fit", "{day}", "--region", "disc=rect:1,1,2,2", "-o", "{tmp}/afile"], ["is a file, not a folder"]),
    (["fit", "{tmp}/nosuch"], ["no manifest at"]),
    (["fit", "{day}"], ["give at least one --region"]),
    (["fit", "{day}", "--region", "disc=rect:6,6,9,9"], ["outside the 8x8 frames"]),
    (["labels", "{day}", "-o", "{tmp}/x.jpg"], ["ending in .png"]),
    (["pixels", "{day}", "--pixel", "1"], ["pixel '1' is not 'X,Y'"]),
    (["pixels", "{day}", "--pixel", "8,0"], ["pixel 8,0 is outside the 8x8 image"]),
    (["render", "{tmp}/nosuch.toml", "-o", "{tmp}/out"], ["does not exist"]),
    (["render", "scenes/specs/disc_clear_east.toml", "-o", "{tmp}/afile"], ["is a file, not a folder"]),
    (["render", "scenes/specs/disc_clear_east.toml", "-o", "/dev/null/out"], ["cannot create"]),
    (["render", "{tmp}/bad.toml", "-o", "{tmp}/out"], ["bad.toml is not valid TOML"]),
])
def test_bad_input_gets_one_line_and_exit_2(argv, phrases, day, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(cli.__file__.rsplit("/skyfit_mi/", 1)[0])        # the repo (scenes/)
    (tmp_path / "afile").write_text("x")
    (tmp_path / "bad.toml").write_text("name = [unclosed")
    spec = (Path(cli.__file__).parents[1] / "scenes/specs/disc_clear_east.toml").read_text()
    (tmp_path / "pose.toml").write_text(spec.replace("[camera]",
                                                     "[camera]\npose_sd_deg = {tilt = 1}"))
    args = [a.format(day=day, tmp=tmp_path) for a in argv]
    code, err = _run(capsys, *args)
    assert code == 2
    _one_line_error(err, *phrases)


def test_damaged_inputs_get_one_line(day, tmp_path, capsys):
    from skyfit_mi.render.image import write_exr

    bad = tmp_path / "day"
    shutil.copytree(day, bad)
    (bad / "manifest.json").write_text((day / "manifest.json").read_text()[:200])      # truncated
    code, err = _run(capsys, "fit", bad, "--region", "disc=rect:1,1,2,2")
    assert code == 2
    _one_line_error(err, "is damaged (not complete JSON")
    shutil.copy(day / "manifest.json", bad / "manifest.json")
    frame = json.loads((day / "manifest.json").read_text())["frames"][1]
    (bad / frame["sensor"]).write_bytes(b"not an exr")
    code, err = _run(capsys, "pixels", bad, "--pixel", "1,1", "--source", "sensor")
    assert code == 2
    _one_line_error(err, "frame 1: cannot read", "render the sequence again")
    write_exr(bad / frame["sensor"], np.zeros((5, 8, 3), np.float32))
    code, err = _run(capsys, "fit", bad, "--region", "disc=rect:1,1,2,2", "--model", "2")
    assert code == 2
    _one_line_error(err, "is 8x5", "not the camera's 8x8")


@pytest.mark.parametrize("args, phrase", [
    (["--region", "disc=rect:1,1,2,2", "--region", "plate=rect:6,6,7,7"], "'plate' names no"),
    (["--region", "disc=rect:1,1,2,2", "--frames", "1-5"], "frame 3 is not a rendered frame"),
    (["--region", "disc=rect:3,3,4,4"],
     "frame 1 (nan/frames/sensor_001.exr, frames/sigma_001.exr) has no value"),
])
def test_a_refused_fit_writes_nothing(day, tmp_path, capsys, monkeypatch, args, phrase):
    """Every region, its frames and their light are checked before the first fit is written:
    a bad second region, frame list or frame leaves no output folder (not an empty one, nor
    the first region's fit)."""
    from skyfit_mi.render.image import write_exr

    monkeypatch.chdir(tmp_path)
    shutil.copytree(day, tmp_path / "nan")
    frame = json.loads((day / "manifest.json").read_text())["frames"][1]
    image = np.ones((8, 8, 3), np.float32)
    image[3:5, 3:5] = np.nan
    write_exr(tmp_path / "nan" / frame["sensor"], image)
    code, err = _run(capsys, "fit", "nan", *args, "--model", "2", "-o", "out")
    assert code == 2
    _one_line_error(err, phrase)
    assert not (tmp_path / "out").exists()


def test_debug_shows_the_traceback(tmp_path):
    with pytest.raises(SkyfitError, match="no manifest"):
        main(["fit", str(tmp_path), "--all", "--debug"])
    with pytest.raises(SkyfitError, match="no manifest"):
        main(["--debug", "labels", str(tmp_path)])


def _fake_fits(manifest, regions, **kw):
    for name, pixels in regions:
        yield _fake_fit(manifest, name, pixels, **kw)


def _fake_fit(manifest, name, pixels, **kw):
    return {"region": name, "model": "two", "method": kw["method"], "pixels": pixels.tolist(),
            "parameters": {"rho_s": 0.3 + 0.01 * kw["seed"], "sigma_alpha": 0.1},
            "intervals": {"rho_s": {"95": [0.2, 0.4]}, "sigma_alpha": {"95": [0.05, 0.15]}},
            "chi2_per_dof": 1.0, "evaluations": 1, "wall_time_s": 0.1, "truth": None,
            "warnings": [], "series": {"times": [], "observed_DN": [], "model_DN": []}}


def test_fits_csv_merges_by_region_and_survives_ctrl_c(day, tmp_path, capsys, monkeypatch):
    import skyfit_mi.fitting.fit as fit
    import skyfit_mi.fitting.report as report

    monkeypatch.setattr(fit, "fit_regions", _fake_fits)
    monkeypatch.setattr(report, "write_fit", lambda res, prefix: (
        report.write_json(prefix.with_suffix(".json"), res),))
    out = tmp_path / "fits"

    def rows():
        lines = (out / "fits.csv").read_text().splitlines()[1:]
        return {ln.split(",")[0]: ln for ln in lines}

    assert main(["fit", str(day), "--region", "a=rect:1,1,2,2", "-o", str(out)]) == 0
    assert main(["fit", str(day), "--region", "b=rect:3,3,4,4", "-o", str(out)]) == 0
    assert set(rows()) == {"a", "b"}                       # fitting b kept a's row
    assert main(["fit", str(day), "--region", "a=rect:1,1,2,2", "--seed", "5", "-o", str(out)]) == 0
    assert "0.35000" in rows()["a"] and set(rows()) == {"a", "b"}         # newest a wins

    calls = []

    def interrupted(manifest, regions, **kw):
        for name, pixels in regions:
            calls.append(name)
            if len(calls) == 2:
                raise KeyboardInterrupt
            yield _fake_fit(manifest, name, pixels, **kw)

    monkeypatch.setattr(fit, "fit_regions", interrupted)
    code = main(["fit", str(day), "--region", "c=rect:1,1,2,2", "--region", "d=rect:3,3,4,4",
                 "-o", str(out)])
    assert code == 130 and "interrupted" in capsys.readouterr().err
    on_disk = {json.loads(p.read_text())["region"] for p in out.glob("fit_*.json")}
    assert on_disk == set(rows()) == {"a", "b", "c"}


def test_every_writer_refuses_a_folder_in_use(day, tmp_path, capsys, monkeypatch):
    """Region fits, a map, chi2map and export each take their output folder's lock, as render
    does: a second run into a folder in use gets the same one line, exit 2, and writes nothing
    (a map's --overwrite no longer removes a live map's store)."""
    import os

    import skyfit_mi.fitting.fit as fit
    import skyfit_mi.fitting.report as report
    from skyfit_mi.files import LOCK_NAME, FolderLock

    monkeypatch.setattr(fit, "fit_regions", _fake_fits)
    monkeypatch.setattr(report, "write_fit", lambda res, prefix: (
        report.write_json(prefix.with_suffix(".json"), res),))
    fits, busy = tmp_path / "fits", tmp_path / "busy"
    assert main(["fit", str(day), "--region", "a=rect:1,1,2,2", "-o", str(fits)]) == 0
    capsys.readouterr()
    with FolderLock(busy):
        for argv in (["fit", day, "--region", "a=rect:1,1,2,2", "-o", busy],
                     ["fit", day, "--per-pixel", "--region", "a=rect:1,1,2,2", "--overwrite",
                      "-o", busy],
                     ["chi2map", day, fits / "fit_a.json", "-o", f"{busy}/"],
                     ["export", fits, "-o", busy]):
            code, err = _run(capsys, *argv)
            assert code == 2, (argv, err)
            _one_line_error(err, f"output folder '{busy}' is in use by process {os.getpid()}")
            assert [p.name for p in busy.iterdir()] == [LOCK_NAME], argv


def test_sigterm_stops_a_command_as_ctrl_c_does(tmp_path, capsys, monkeypatch):
    """SIGTERM (timeout, docker stop, a batch system) unwinds a command as Ctrl-C does: one
    line, exit 143, the half-written file's temporary removed and the folder's lock released
    (the folder it made, left empty, removed)."""
    import os
    import signal

    from skyfit_mi.files import FolderLock, atomic_write

    out = tmp_path / "out"

    def terminated_while_writing(args):
        def write(tmp):
            Path(tmp).write_text("half")
            os.kill(os.getpid(), signal.SIGTERM)
        with FolderLock(out):
            atomic_write(out / "export.json", write)

    monkeypatch.setattr(cli, "_export", terminated_while_writing)
    code, err = _run(capsys, "export", tmp_path / "fits", "-o", out)
    assert code == 143
    _one_line_error(err, "skyfit: terminated (SIGTERM); nothing unfinished was kept as done")
    assert not out.exists()
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL          # restored after the run


# ---- property tests: no input makes the parsers or the spec validator crash ------------------
@settings(max_examples=300, deadline=None)
@given(st.text(max_size=40))
def test_argument_parsers_accept_or_refuse_cleanly(text):
    import argparse

    from skyfit_mi.fitting.chi2 import parse_region
    from skyfit_mi.pipeline.pixels import parse_pixel

    for parse in (cli._numbers, cli._label, cli._region, cli._int_in(0, 10)):
        try:
            parse(text)
        except argparse.ArgumentTypeError as exc:
            assert str(exc)
    for parse in (parse_region, parse_pixel):
        try:
            parse(text)
        except SkyfitError as exc:
            assert str(exc)


_VALUES = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
                    st.lists(st.floats(-10, 10), max_size=5), st.dictionaries(
                        st.text(max_size=5), st.integers(), max_size=2))
_KEYS = [("location", "latitude_deg"), ("location", "timezone"), ("location", "elevation_m"),
         ("time", "date"), ("time", "times"), ("sky", "type"), ("sky", "phi"),
         ("sky", "diffuse_horizontal_W_m2"), ("camera", "fov_deg"), ("camera", "width"),
         ("camera", "azimuth_deg"), ("camera", "up"), ("camera", "target"),
         ("sensor", "bits"), ("sensor", "exposure"), ("sensor", "response"),
         ("render", "spp"), ("render", "seed"), ("render", "sampler"),
         ("materials", "disc"), ("scene", "file"), ("scene", "ground_albedo")]


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.sampled_from(_KEYS), _VALUES), min_size=1, max_size=3))
def test_a_damaged_spec_is_refused_with_a_spec_error(changes):
    raw = thesis_disc_spec("p", {"model": "two", "rho_s": 0.3, "sigma_alpha": 0.1}, size=4)
    raw["time"] = {"date": "2026-06-21", "times": ["12:00"]}
    for (section, key), value in changes:
        raw[section][key] = value
    try:
        validate_spec(raw)
    except SpecError as exc:
        assert str(exc) and "\n" not in str(exc)


def test_a_comma_list_of_numbers_may_start_with_a_minus():
    """argparse takes '-0.1,0.02' for an option's name; the options of comma-separated numbers
    take it as their value (a barrel lens's k1, a southern latitude), and nothing else is
    joined."""
    from skyfit_mi.cli import _join_negative_lists, build_parser

    parser = build_parser()
    argv = ["camera", "pts.csv", "--distortion", "-0.1,0.02", "--target", "-0.3,0,0", "-o",
            "cam.toml"]
    args = parser.parse_args(_join_negative_lists(parser, argv))
    assert args.distortion == [-0.1, 0.02] and args.target == [-0.3, 0.0, 0.0]
    args = parser.parse_args(_join_negative_lists(
        parser, ["ingest", "spec.toml", "photos", "--site", "-33.9,151.2", "-o", "seq"]))
    assert args.site == [-33.9, 151.2] and args.output == "seq"
    assert _join_negative_lists(parser, ["fit", "seq", "-q", "-o", "-1,2"]) == \
        ["fit", "seq", "-q", "-o", "-1,2"]


def test_a_site_beyond_the_globe_is_named_as_the_option(tmp_path, capsys):
    """--site 95,0 was refused naming the spec's [location] latitude_deg."""
    assert main(["ingest", "spec.toml", str(tmp_path), "-o", str(tmp_path / "o"),
                 "--site", "95,0"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("--site 95,0: give the latitude in [-90, 90] (north) and the longitude "
                        "in [-180, 180] (east), degrees."), err
