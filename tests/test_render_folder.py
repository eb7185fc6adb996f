"""`skyfit render`'s output folder: locked, verified on resume, started clean on --overwrite."""

import json
import os

import numpy as np
import pytest

from skyfit_mi.errors import OutputError, SkyfitError
from skyfit_mi.files import LOCK_NAME, FolderLock
from skyfit_mi.pipeline.sequence import render_sequence
from skyfit_mi.pipeline.spec import thesis_disc_spec, validate_spec


def _spec(tmp_path, **render):
    raw = thesis_disc_spec("folder", {"model": "two", "rho_s": 0.3, "sigma_alpha": 0.1}, size=8,
                           spp=4, exposure=0.0015)
    raw["time"] = {"date": "2026-06-21", "times": ["09:00", "12:00", "15:00"]}
    raw["render"].update(render)
    return validate_spec(raw, tmp_path)


def _render(spec, out, **kw):
    logs = []
    m = render_sequence(spec, out, progress=False, log=logs.append, **kw)
    return m, logs


def test_a_locked_folder_is_refused_and_a_stale_lock_taken_over(tmp_path, mi):
    out = tmp_path / "day"
    with FolderLock(out):                                   # another run holds the folder
        with pytest.raises(OutputError, match=f"in use by process {os.getpid()}"):
            _render(_spec(tmp_path), out)
        with pytest.raises(OutputError, match="in use"):
            FolderLock(out).__enter__()
    assert not (out / LOCK_NAME).exists()                   # released on exit
    # a lock left by a process that no longer exists (killed) is stale
    (out / LOCK_NAME).write_text(json.dumps({"host": os.uname().nodename, "pid": 2**22 + 12345,
                                             "since": "2026-01-01T00:00:00+00:00"}))
    m, logs = _render(_spec(tmp_path), out)
    assert m["status"] == "complete" and any("took over the lock" in s for s in logs)
    assert not (out / LOCK_NAME).exists()


def test_a_lock_file_not_yet_naming_its_owner_is_live_until_old(tmp_path, monkeypatch):
    """A live run's lock is empty between its O_EXCL creation and its owner's record: young,
    it is waited for and refused as in use; only one left empty for FRESH_LOCK_S is stale."""
    import threading

    from skyfit_mi import files

    monkeypatch.setattr(files, "LOCK_WAIT_S", 0.2)
    lock = tmp_path / LOCK_NAME
    lock.write_text("")
    with pytest.raises(OutputError, match="in use by another process .*names no owner yet"):
        FolderLock(tmp_path).__enter__()
    me = {"host": os.uname().nodename, "pid": os.getpid(), "since": "2026-01-01T00:00:00+00:00"}
    lock.write_text("")                          # its owner's record comes within the wait
    threading.Timer(0.05, lambda: lock.write_text(json.dumps(me))).start()
    monkeypatch.setattr(files, "LOCK_WAIT_S", 5.0)
    with pytest.raises(OutputError, match=f"in use by process {os.getpid()} on "):
        FolderLock(tmp_path).__enter__()
    lock.write_text('{"host": ')                 # left half-written by a killed run
    old = lock.stat().st_mtime - files.FRESH_LOCK_S - 1
    os.utime(lock, (old, old))
    with FolderLock(tmp_path) as taken:
        assert taken.stale == {"pid": "unknown"}
        assert json.loads(lock.read_text())["pid"] == os.getpid()


def test_resume_rerenders_damaged_frames_and_overwrite_starts_clean(tmp_path, mi):
    from skyfit_mi.render.image import read_exr, write_exr

    out = tmp_path / "day"
    old = os.umask(0o027)                                   # files follow the user's umask
    try:
        ref, _ = _render(_spec(tmp_path), out)
    finally:
        os.umask(old)
    for p in (out / "manifest.json", out / "contact_sheet.png", out / ref["frames"][0]["sigma"]):
        assert p.stat().st_mode & 0o777 == 0o640, p
    first = read_exr(out / ref["frames"][1]["radiance"])
    p = out / ref["frames"][1]["radiance"]
    p.write_bytes(p.read_bytes()[:100])                     # truncated
    write_exr(out / ref["frames"][2]["sigma"], np.zeros((4, 8, 3), np.float32))   # wrong size
    m, logs = _render(_spec(tmp_path), out)
    assert "(1 kept from an earlier run)" in logs[-1]
    assert any(s.startswith("frame 1: cannot read") for s in logs)
    assert any(s.startswith("frame 2: ") and "not the camera's 8x8" in s for s in logs)
    assert np.array_equal(read_exr(out / m["frames"][1]["radiance"]), first)

    (out / "manifest.json").write_text('{"schema": "skyfit-manif')           # truncated
    with pytest.raises(SkyfitError, match="damaged .* --overwrite"):
        _render(_spec(tmp_path), out)
    (out / "frames" / "radiance_007.exr").write_text("an older run's frame")
    (out / "notes.txt").write_text("the user's own file")
    m, logs = _render(_spec(tmp_path, seed=5), out, overwrite=True)
    assert m["status"] == "complete" and "(0 kept from an earlier run)" in logs[-1]
    assert not (out / "frames" / "radiance_007.exr").exists()          # clean: no stale frames
    assert (out / "notes.txt").exists()                                 # but nothing else removed


def test_black_frames_are_reported(tmp_path, mi):
    raw = thesis_disc_spec("polar", {"model": "two", "rho_s": 0.3, "sigma_alpha": 0.1}, size=8,
                           spp=4, exposure=1e-4)
    raw["location"]["latitude_deg"] = 80.0                  # polar night: the sun 13 deg down
    raw["time"] = {"date": "2026-12-21", "times": ["06:00", "12:00"]}
    m, logs = _render(validate_spec(raw, tmp_path), tmp_path / "polar")
    assert all(f["dark"] for f in m["frames"])
    assert "2 dark" in logs[-1] and sum("black at this exposure" in s for s in logs) == 2


def test_an_auto_exposure_of_a_dark_day_is_refused_before_the_folder_is_made(tmp_path):
    raw = thesis_disc_spec("polar", {"model": "two", "rho_s": 0.3, "sigma_alpha": 0.1}, size=8,
                           spp=4)
    raw["location"]["latitude_deg"] = 80.0
    raw["time"] = {"date": "2026-12-21", "times": ["06:00", "12:00"]}
    raw["sensor"]["exposure"] = "auto"
    with pytest.raises(SkyfitError, match="the sun is below the horizon at every time"):
        _render(validate_spec(raw, tmp_path), tmp_path / "polar")
    assert not (tmp_path / "polar").exists()


def test_clean_runs_agree_to_float32_rounding(tmp_path, mi):
    """The promise (docs/cli.md, docs/MANIFEST.md): a render of the same spec in another process,
    even from an empty kernel cache, gives the same sensor values and radiance and sigma equal
    to 1e-6 relative (the parallel film accumulation's float32 rounding order may differ)."""
    import subprocess
    import sys

    from skyfit_mi.render.image import read_exr

    raw_spec = _spec(tmp_path)
    a, _ = _render(raw_spec, tmp_path / "a")
    code = ("import sys; from skyfit_mi.pipeline.spec import thesis_disc_spec, validate_spec; "
            "from skyfit_mi.pipeline.sequence import render_sequence; "
            "raw = thesis_disc_spec('folder', {'model': 'two', 'rho_s': 0.3, 'sigma_alpha': 0.1}, "
            "size=8, spp=4, exposure=0.0015); "
            "raw['time'] = {'date': '2026-06-21', 'times': ['09:00', '12:00', '15:00']}; "
            "render_sequence(validate_spec(raw, sys.argv[2]), sys.argv[1], progress=False, "
            "log=lambda *a: None)")
    env = {**os.environ, "HOME": str(tmp_path / "home")}          # an empty kernel cache
    subprocess.run([sys.executable, "-c", code, str(tmp_path / "b"), str(tmp_path)], check=True,
                   env=env, timeout=600)
    b = json.loads((tmp_path / "b" / "manifest.json").read_text())
    assert a["run_id"] == b["run_id"]
    for fa, fb in zip(a["frames"], b["frames"]):
        assert np.array_equal(read_exr(tmp_path / "a" / fa["sensor"]),
                              read_exr(tmp_path / "b" / fb["sensor"]))
        for k in ("radiance", "sigma"):
            np.testing.assert_allclose(read_exr(tmp_path / "b" / fb[k]),
                                       read_exr(tmp_path / "a" / fa[k]), rtol=1e-6, atol=0)
