"""Measured irradiance series: a CSV, or an EPW / TMY3 weather file (pvlib's readers), read
once and interpolated to each frame's time, to drive the Perez all-weather sky.

A CSV has columns ``time`` (ISO 8601; naive times in the spec's zone) and ``ghi``, optionally
``dhi`` and ``dni`` [W m^-2] (or the long names, :data:`COLUMNS`).  EPW and TMY3 hourly sums
end at their time stamp, so they are placed mid-hour.  Values are interpolated linearly in
time; a frame beyond the series by more than half its largest step is refused.
"""

import datetime as dt
from pathlib import Path

import numpy as np

from ..errors import SkyfitError

#: The columns a series may give [W m^-2], by their short and long names.
COLUMNS = {"ghi": "global_horizontal_W_m2", "dhi": "diffuse_horizontal_W_m2",
           "dni": "direct_normal_W_m2"}


def _csv(path, tz):
    import pandas as pd

    try:
        df = pd.read_csv(path)
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise SkyfitError(f"cannot read irradiance file {path} ({str(exc).splitlines()[0]}); "
                          "give a CSV with a header row time,ghi[,dhi,dni].") from None
    df = df.rename(columns={v: k for k, v in COLUMNS.items()})
    if "time" not in df.columns or "ghi" not in df.columns and "dhi" not in df.columns:
        raise SkyfitError(f"irradiance file {path} needs the columns time and ghi (or dhi and "
                          f"dni) [W m^-2]; it has {', '.join(map(str, df.columns))}.")
    times = []
    for i, s in enumerate(df["time"]):
        try:
            t = dt.datetime.fromisoformat(str(s))
        except ValueError:
            raise SkyfitError(f"irradiance file {path}, row {i + 2}: time {s!r} is not ISO 8601 "
                              "(e.g. 2026-08-16T12:00+01:00).") from None
        times.append(t if t.tzinfo else t.replace(tzinfo=tz))
    return times, df


def _weather(path, year):
    import pvlib.iotools

    try:
        if path.suffix.lower() == ".epw":
            df, _ = pvlib.iotools.read_epw(str(path), coerce_year=year)
        else:
            df, _ = pvlib.iotools.read_tmy3(str(path), coerce_year=year)
    except Exception as exc:          # pvlib raises assorted parse errors on damaged files
        raise SkyfitError(f"cannot read weather file {path} as "
                          f"{'EPW' if path.suffix.lower() == '.epw' else 'TMY3'} "
                          f"({str(exc).splitlines()[0] if str(exc) else type(exc).__name__}).") from None
    times = [t.to_pydatetime() - dt.timedelta(minutes=30) for t in df.index]   # hour's middle
    return times, df


def read_irradiance(path, tz, year=None):
    """The series of a CSV or weather file: (UTC seconds (N,), {'ghi'|'dhi'|'dni': (N,)}
    [W m^-2], the file's kind).  ``tz`` reads naive CSV times; ``year`` is put on a typical
    year's (EPW/TMY3) time stamps."""
    path = Path(path)
    if not path.is_file():
        raise SkyfitError(f"irradiance file {path} not found.")
    is_csv = path.suffix.lower() == ".csv"
    if is_csv:
        with open(path, errors="replace") as fh:
            is_csv = "time" in fh.readline().lower()
    times, df = _csv(path, tz) if is_csv else _weather(path, year)
    cols = {}
    for k in COLUMNS:
        if k in df.columns:
            v = np.asarray(df[k], dtype=float)
            bad = ~np.isfinite(v) | (v < 0)
            if bad.any():
                raise SkyfitError(f"irradiance file {path}: {k} at {times[int(np.argmax(bad))]} "
                                  f"is {v[bad][0]!r}; give a value >= 0 W m^-2 or drop the row.")
            cols[k] = v
    sec = np.array([t.timestamp() for t in times])
    if len(sec) < 1 or np.any(np.diff(sec) <= 0):
        raise SkyfitError(f"irradiance file {path}: times must increase, one row per time.")
    return sec, cols, "csv" if is_csv else path.suffix.lower().lstrip(".")


def irradiance_at(series, times, path="irradiance file"):
    """Each quantity of ``series`` (:func:`read_irradiance`) at ``times`` (aware datetimes),
    linear in time: a list of {'ghi': ..} dicts [W m^-2], one per time."""
    sec, cols, _ = series
    step = float(np.max(np.diff(sec))) if len(sec) > 1 else 0.0
    out = []
    for t in times:
        x = t.timestamp()
        if x < sec[0] - step / 2 or x > sec[-1] + step / 2:
            raise SkyfitError(f"{path} covers {dt.datetime.fromtimestamp(sec[0], t.tzinfo):%Y-%m-%d %H:%M}"
                              f" to {dt.datetime.fromtimestamp(sec[-1], t.tzinfo):%Y-%m-%d %H:%M}; "
                              f"the frame at {t.isoformat()} lies outside it. Give a series that "
                              "covers every frame.")
        out.append({k: float(np.interp(x, sec, v)) for k, v in cols.items()})
    return out
