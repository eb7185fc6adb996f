"""EXR frames through OpenEXR's Python bindings (skyfit_mi.render.image): float32 values exact,
frame metadata in the header, only some rows read, a bad file one SkyfitError line."""
import datetime as dt

import numpy as np
import pytest

from skyfit_mi.errors import SkyfitError
from skyfit_mi.render.image import (check_exr, read_exr, read_exr_checked, read_exr_header,
                                    read_exr_meta, read_exr_pixels, read_exr_shape, write_exr)

OpenEXR = pytest.importorskip("OpenEXR")
RNG = np.random.default_rng(2024)


def _image(h=37, w=23):
    """Float32 values that test exactness: every exponent, signs, zeros, inf and NaN."""
    a = (RNG.standard_normal((h, w, 3)) * 10.0 ** RNG.integers(-30, 30, (h, w, 3))).astype(
        np.float32)
    a[0, 0] = [0.0, -0.0, np.inf]
    a[0, 1] = [np.nan, np.float32(1e-42), np.finfo(np.float32).max]        # a subnormal
    return a


def test_round_trip_is_exact_and_the_header_carries_the_frame(tmp_path):
    a = _image()
    when = dt.datetime(2026, 6, 21, 13, 30, tzinfo=dt.timezone(dt.timedelta(hours=2)))
    p = write_exr(tmp_path / "radiance_007.exr", a,
                  {"kind": "radiance", "units": "W m^-2 sr^-1", "frame": 7, "time": when})
    b = read_exr(p)
    assert b.dtype == np.float32 and b.shape == a.shape
    assert np.array_equal(a.view(np.uint32), b.view(np.uint32))          # bit for bit
    assert read_exr_meta(p) == {"kind": "radiance", "units": "W m^-2 sr^-1", "frame": 7,
                                "time": "2026-06-21T13:30:00+02:00"}
    hdr = read_exr_header(p)
    assert hdr["capDate"] == "2026:06:21 13:30:00" and hdr["utcOffset"] == -7200.0
    assert [c.name for c in hdr["channels"]] == ["B", "G", "R"]          # as Mitsuba wrote them
    assert hdr["compression"] == OpenEXR.ZIPS_COMPRESSION
    assert read_exr_shape(p) == a.shape
    assert not list(tmp_path.glob(".*"))                                 # no temporary left


def test_photos_read_the_header_time_back(tmp_path):
    """The standard capDate / utcOffset that write_exr puts in are the ones ingest reads."""
    from skyfit_mi.pipeline.photos import read_photo

    when = dt.datetime(2026, 8, 16, 12, 30, tzinfo=dt.timezone(dt.timedelta(hours=1)))
    a = RNG.random((4, 5, 3)).astype(np.float32)
    ph = read_photo(write_exr(tmp_path / "a.exr", a, {"time": when}))
    assert np.array_equal(ph.values, a)
    assert (ph.metadata["datetime_original"], ph.metadata["offset_time_original"]) == \
        ("2026:08:16 12:30:00", "+01:00")


def test_one_channel_maps_and_files_mitsuba_wrote_read_as_before(tmp_path):
    import mitsuba as mi

    y = RNG.random((6, 9)).astype(np.float32)
    assert np.array_equal(read_exr(write_exr(tmp_path / "y.exr", y)), y)
    assert read_exr_meta(tmp_path / "y.exr") == {}
    a = _image(40, 11)
    mi.Bitmap(a, mi.Bitmap.PixelFormat.RGB).write(str(tmp_path / "old.exr"))   # PIZ, 32 lines
    assert np.array_equal(read_exr(tmp_path / "old.exr").view(np.uint32), a.view(np.uint32))
    assert np.array_equal(read_exr(tmp_path / "old.exr", [39, 0, 33, 33]), a[[39, 0, 33, 33]],
                          equal_nan=True)
    bmp = mi.Bitmap(str(write_exr(tmp_path / "new.exr", a)))           # Mitsuba reads ours
    assert np.array_equal(np.array(bmp), a, equal_nan=True)


@pytest.mark.parametrize("compression", ["ZIPS_COMPRESSION", "ZIP_COMPRESSION",
                                         "PIZ_COMPRESSION", "NO_COMPRESSION"])
def test_rows_and_pixels_equal_the_full_reads(tmp_path, compression):
    a = _image(70, 13)
    p = tmp_path / "a.exr"
    OpenEXR.File({"compression": getattr(OpenEXR, compression), "type": OpenEXR.scanlineimage},
                 {"RGB": a}).write(str(p))
    full = read_exr(p)
    for rows in ([5], [69, 0], [31, 32, 33, 3, 3], list(range(70)), []):
        part = read_exr(p, rows)
        assert part.shape == (len(rows), 13, 3)
        assert np.array_equal(part.view(np.uint32), full[rows].view(np.uint32))
    px = np.stack([RNG.integers(0, 13, 64), RNG.integers(0, 70, 64)], axis=1)
    got = read_exr_pixels(p, px)
    assert np.array_equal(got.view(np.uint32), full[px[:, 1], px[:, 0]].view(np.uint32))
    assert np.array_equal(read_exr_checked(p, (70, 13, 3), px), got, equal_nan=True)
    with pytest.raises(SkyfitError, match="row 70 of"):
        read_exr(p, [70])


def _bad_files(tmp_path):
    good = write_exr(tmp_path / "good.exr", _image(64, 16)).read_bytes()
    files = {"truncated.exr": good[:len(good) * 2 // 3], "header_only.exr": good[:120],
             "text.exr": b"not an image\n" * 20, "empty.exr": b""}
    for name, blob in files.items():
        (tmp_path / name).write_bytes(blob)
    return [tmp_path / n for n in files] + [tmp_path / "missing.exr"]


def test_a_bad_file_is_one_skyfit_line(tmp_path, capfd):
    for p in _bad_files(tmp_path):
        for read in (read_exr, lambda q: read_exr(q, [63]),
                     lambda q: read_exr_checked(q, (64, 16, 3)), lambda q: check_exr(q, (64, 16, 3))):
            with pytest.raises(SkyfitError) as e:
                read(p)
            msg = str(e.value)
            assert msg.startswith(f"cannot read {p}: ") and "\n" not in msg, msg
    out, err = capfd.readouterr()
    assert out == "" and err == ""                       # the library's own lines are taken in
    with pytest.raises(SkyfitError, match=r"text\.exr: not an OpenEXR file$"):
        read_exr(tmp_path / "text.exr")
    with pytest.raises(SkyfitError, match=r"truncated\.exr: a (damaged or )?truncated OpenEXR"):
        read_exr(tmp_path / "truncated.exr")
    with pytest.raises(SkyfitError, match=r"truncated\.exr: a truncated OpenEXR file"):
        check_exr(tmp_path / "truncated.exr", (64, 16, 3))
    with pytest.raises(SkyfitError, match=r"missing\.exr: no such file$"):
        read_exr(tmp_path / "missing.exr")
    with pytest.raises(SkyfitError, match=r"good\.exr is 16x64 with 3 channels, not the "
                       r"camera's 16x60 RGB"):
        check_exr(tmp_path / "good.exr", (60, 16, 3))
    assert read_exr(tmp_path / "truncated.exr", [0]).shape == (1, 16, 3)   # its whole rows read


def test_a_full_disk_while_writing_is_one_output_line(tmp_path, monkeypatch):
    """OpenEXR's bindings raise RuntimeError on a failed write (a full disk): one
    OutputError naming the file and the reason, the earlier file kept, no temporary file."""
    import OpenEXR

    from skyfit_mi.errors import OutputError

    class Full:
        def __init__(self, *a):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def write(self, name):
            raise RuntimeError(f'Cannot write image file "{name}". No space left on device.')

    out = tmp_path / "map.exr"
    write_exr(out, np.ones((4, 4), np.float32))
    monkeypatch.setattr(OpenEXR, "File", Full)
    with pytest.raises(OutputError, match=r"^cannot write '.*map\.exr': No space left on "
                       r"device\.$"):
        write_exr(out, np.zeros((4, 4), np.float32))
    assert [p.name for p in tmp_path.iterdir()] == ["map.exr"]
    monkeypatch.undo()
    assert np.all(read_exr(out) == 1.0)


@pytest.fixture(scope="module")
def day(tmp_path_factory, mi):
    """A tiny rendered day (8x8, 3 frames)."""
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import thesis_disc_spec, validate_spec

    tmp = tmp_path_factory.mktemp("exr_day")
    raw = thesis_disc_spec("exr", {"model": "two", "rho_s": 0.3, "sigma_alpha": 0.1}, size=8,
                           spp=4, exposure=0.0015)
    raw["time"] = {"date": "2026-06-21", "times": ["09:00", "12:00", "15:00"]}
    render_sequence(validate_spec(raw, tmp), tmp / "day", progress=False, log=lambda *a: None)
    return tmp / "day"


def test_a_rendered_frame_carries_its_record_in_its_headers(day):
    import json

    from skyfit_mi.pipeline.sequence import FRAME_FILES, FRAME_UNITS

    doc = json.loads((day / "manifest.json").read_text())
    for f in doc["frames"]:
        for kind in FRAME_FILES:
            meta = read_exr_meta(day / f[kind])
            assert meta == {"kind": kind, "units": FRAME_UNITS[kind], "frame": f["index"],
                            "time": f["time"]}
            assert read_exr_header(day / f[kind])["capDate"] == \
                dt.datetime.fromisoformat(f["time"]).strftime("%Y:%m:%d %H:%M:%S")


def test_a_cut_frame_file_is_one_error_line_and_exit_2(day, tmp_path, capsys):
    """A frame file cut short: ``skyfit pixels`` (rows read past the cut) and ``relight``'s
    check of the target's frames (headers and chunk tables) refuse it in one line, status 2."""
    import json
    import shutil

    from skyfit_mi.cli import main

    bad = tmp_path / "day"
    shutil.copytree(day, bad)
    frame = json.loads((day / "manifest.json").read_text())["frames"][1]
    data = (day / frame["sensor"]).read_bytes()
    (bad / frame["sensor"]).write_bytes(data[:len(data) // 2])
    code = main(["pixels", str(bad), "--pixel", "1,7", "--source", "sensor"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith("skyfit") and "frame 1: cannot read" in err and \
        frame["sensor"] in err, err
    from skyfit_mi.pipeline.manifest import check_frames, load_manifest

    doc, root = load_manifest(bad)
    with pytest.raises(SkyfitError, match=r"frame 1: cannot read .*sensor_001\.exr: a truncated "
                       r"OpenEXR file"):
        check_frames(doc, root)
