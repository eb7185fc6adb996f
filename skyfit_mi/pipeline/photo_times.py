"""The capture time of each photograph of a sequence.

:func:`frame_times` gives every frame one time-zone-aware instant, from exactly one source:

1. **EXIF** (the default): ``DateTimeOriginal`` (+ ``SubSecTimeOriginal``) in the zone of
   ``OffsetTimeOriginal``, else ``tz``.
2. **A CSV** ``times_csv`` with header ``file,time``: files matched by base name, ISO 8601
   times (``2026-06-21 12:00:05.25+01:00``); a time without an offset takes ``tz``.
3. **A file-name pattern** ``name_pattern`` matching the whole base name: a ``strptime`` pattern
   (``IMG_%Y%m%d_%H%M%S.jpg``; ``%z`` an offset, ``%f`` a fraction; without a suffix it matches
   the name without its suffix), or, if it contains ``(?P<``, a regular expression with named
   groups ``year month day hour minute`` and optional ``second``, ``fraction`` and ``offset``.

``tz`` is an IANA name or a fixed offset (``'+02:00'``, ``'Z'``); wall-clock times it makes
ambiguous or skips are refused, and a frame's own offset must agree with it (a camera in the
wrong zone is likelier than a deliberate mix; a CSV is the explicit fix).
"""

from __future__ import annotations

import csv
import datetime as dt
import re
from pathlib import Path
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from ..errors import SkyfitError, listed

#: Civil UTC offsets in use [hours].
UTC_OFFSETS = (-12.0, 14.0)

_OFFSET_RE = re.compile(r"^\s*(?:(?P<z>[Zz])|(?P<sign>[+-])(?P<hh>\d{2}):?(?P<mm>\d{2}))\s*$")


def _name(path):
    return Path(str(path)).name


def parse_offset(text):
    """A ``datetime.timezone`` from ``'+01:00'``, ``'+0100'``, ``'-05:30'`` or ``'Z'``, or
    None if ``text`` is not such an offset (or lies outside -12:00 .. +14:00)."""
    m = _OFFSET_RE.match(str(text)) if text is not None else None
    if not m:
        return None
    if m.group("z"):
        return dt.timezone.utc
    hh, mm = int(m.group("hh")), int(m.group("mm"))
    if mm >= 60:
        return None
    minutes = (1 if m.group("sign") == "+" else -1) * (60 * hh + mm)
    if not UTC_OFFSETS[0] * 60 <= minutes <= UTC_OFFSETS[1] * 60:
        return None
    return dt.timezone(dt.timedelta(minutes=minutes))


def parse_tz(tz):
    """A ``tzinfo`` from an IANA name, an offset text or a ``tzinfo``; SkyfitError if bad."""
    if tz is None or isinstance(tz, dt.tzinfo):
        return tz
    off = parse_offset(tz)
    if off is not None:
        return off
    text = str(tz).strip()
    if text.upper() == "UTC":
        return dt.timezone.utc
    try:
        if not text or text.startswith(("+", "-")):
            raise ValueError(text)
        return ZoneInfo(text)
    except (ZoneInfoNotFoundError, ValueError):
        raise SkyfitError(f"time zone {str(tz)!r} is not a time zone; give an IANA name such "
                          "as 'Europe/London' or 'UTC', or an offset such as '+01:00'.") from None


def format_offset(td):
    """'+HH:MM' of a UTC offset ``td`` (a timedelta; EXIF's OffsetTimeOriginal form)."""
    minutes = round(td.total_seconds() / 60)
    sign = "+" if minutes >= 0 else "-"
    return f"{sign}{abs(minutes) // 60:02d}:{abs(minutes) % 60:02d}"


def wall_time_problem(naive, tz):
    """What is wrong with the wall-clock time ``naive`` in zone ``tz``: None, or a phrase
    saying that the clocks skip it or pass it twice (a daylight-saving change)."""
    t0 = naive.replace(tzinfo=tz, fold=0)
    t1 = naive.replace(tzinfo=tz, fold=1)
    if t0.utcoffset() == t1.utcoffset():
        return None
    if t0.astimezone(dt.timezone.utc).astimezone(tz).replace(tzinfo=None) != naive:
        return f"does not exist in {tz} (the clocks skip that hour)"
    return (f"happens twice in {tz} (at {format_offset(t0.utcoffset())} and "
            f"{format_offset(t1.utcoffset())}, when the clocks go back)")


def localize(naive, tz, who, no_tz):
    """Attach ``tz`` to the wall-clock time ``naive``; refuse (naming ``who``) a time that an
    IANA zone makes ambiguous or skips.  Without ``tz``, raise ``f"{who} {no_tz}"``."""
    if tz is None:
        raise SkyfitError(f"{who} {no_tz}")
    problem = wall_time_problem(naive, tz)
    if problem is None:
        return naive.replace(tzinfo=tz, fold=0)
    if problem.startswith("does not exist"):
        raise SkyfitError(
            f"{who}: {naive.isoformat(sep=' ')} {problem}; the camera clock was probably not on "
            "local time: give the frame's offset, e.g. --tz with a fixed offset such as "
            f"'{format_offset(naive.replace(tzinfo=tz).utcoffset())}', or a CSV of times.")
    raise SkyfitError(f"{who}: {naive.isoformat(sep=' ')} {problem}; give the offset: --tz with "
                      "a fixed offset, or a CSV of times with offsets.")


def _with_offset(aware, tz, who, source):
    """Keep an instant that carries its own offset; refuse it if ``tz`` disagrees there."""
    off = aware.utcoffset()
    if not UTC_OFFSETS[0] <= off / dt.timedelta(hours=1) <= UTC_OFFSETS[1]:
        raise SkyfitError(f"{who}: {source} offset {format_offset(off)} is not a civil time "
                          "offset; fix it or give the times in a CSV.")
    if tz is not None:
        zoned = aware.astimezone(tz).utcoffset()
        if zoned != off:
            raise SkyfitError(
                f"{who}: {source} offset {format_offset(off)} disagrees with the time zone "
                f"{tz} ({format_offset(zoned)} at that instant); check the camera's time-zone "
                "setting, then drop --tz to use the file's offset, or give the times in a CSV.")
    return aware


# ------------------------------------------------------------------------------------ EXIF

_EXIF_RE = re.compile(r"^\s*(\d{4})[:\-](\d{2})[:\-](\d{2})[ T](\d{2}):(\d{2}):(\d{2})"
                      r"(?:\.(\d+))?\s*$")


def exif_time(meta, tz, who):
    """The instant of one frame from its EXIF ``metadata`` (:attr:`.photos.Photo.metadata`)."""
    text = (meta or {}).get("datetime_original")
    m = _EXIF_RE.match(str(text)) if text else None
    if not m:
        got = "no DateTimeOriginal" if not text else f"DateTimeOriginal {text!r}, not a time"
        raise SkyfitError(f"{who} has {got}; give the times with a CSV (file,time) or a "
                          "file-name pattern.")
    y, mo, d, h, mi, s = (int(x) for x in m.groups()[:6])
    sub = m.group(7) or (meta.get("subsec_time_original") or "").strip()
    if sub and not sub.isdigit():
        raise SkyfitError(f"{who} has SubSecTimeOriginal {sub!r}, not digits; fix it or "
                          "give the times in a CSV.")
    micro = int((sub + "000000")[:6])                       # the fraction's first 6 digits
    try:
        naive = dt.datetime(y, mo, d, h, mi, s, micro)
    except ValueError:
        raise SkyfitError(f"{who} has DateTimeOriginal {text!r}, not a valid date and time; "
                          "give the times with a CSV (file,time) or a file-name pattern.") \
            from None
    off_text = str(meta.get("offset_time_original") or "")
    if off_text.strip(" :\x00"):                   # EXIF's unknown is blanks and a colon
        off = parse_offset(off_text)
        if off is not None:
            return _with_offset(naive.replace(tzinfo=off), tz, who, "OffsetTimeOriginal")
        if tz is None:
            raise SkyfitError(f"{who} has OffsetTimeOriginal {off_text!r}, not an offset such "
                              "as '+01:00'; give --tz (which then stands for it) or a CSV of "
                              "times.")
    return localize(naive, tz, who, "has DateTimeOriginal but no OffsetTimeOriginal; give --tz "
                    "(an IANA zone such as 'Europe/London' or an offset such as '+01:00').")


# ------------------------------------------------------------------------------------- CSV

def _iso(text):
    s = text.strip()
    if s.endswith(("Z", "z")):
        s = s[:-1] + "+00:00"
    return dt.datetime.fromisoformat(s)


def read_times_csv(csv_path):
    """``{base name: (time text, line number)}`` from a ``file,time`` CSV; refuses a missing
    header, malformed rows and a file listed twice, naming the line."""
    path = Path(csv_path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise SkyfitError(f"cannot read the times CSV {path}: "
                          f"{getattr(exc, 'strerror', None) or exc}; give a readable UTF-8 "
                          "text file.") from None
    rows = list(csv.reader(text.splitlines()))
    numbered = [(i + 1, r) for i, r in enumerate(rows) if r and any(c.strip() for c in r)]
    if not numbered:
        raise SkyfitError(f"{path} is empty; write a header 'file,time' and one row per frame.")
    line, header = numbered[0]
    if [c.strip().lower() for c in header] != ["file", "time"]:
        raise SkyfitError(f"{path} line {line}: the header is {','.join(header)!r}, not "
                          "'file,time'; make the first line 'file,time'.")
    out = {}
    for line, row in numbered[1:]:
        if len(row) != 2 or not row[0].strip() or not row[1].strip():
            raise SkyfitError(f"{path} line {line}: {','.join(row)!r} is not 'file,time'; "
                              "write one file name and one time per row.")
        name = _name(row[0].strip())
        if name in out:
            raise SkyfitError(f"{path} line {line}: {name} is listed again (first on line "
                              f"{out[name][1]}); keep one row per frame.")
        out[name] = (row[1].strip(), line)
    return out


def _csv_times(paths, csv_path, tz, warn):
    table = read_times_csv(csv_path)
    names = [_name(p) for p in paths]
    missing = [n for n in names if n not in table]
    if missing:
        folded = {n.casefold(): n for n in table}
        near = next((folded[n.casefold()] for n in missing if n.casefold() in folded), None)
        raise SkyfitError(f"{csv_path} has no row for {listed(missing)}; list "
                          "every frame (file,time)"
                          + (f" by its exact name (it lists {near!r}: names are matched with "
                             "their case)" if near else "") + ".")
    extra = sorted(set(table) - set(names), key=lambda n: table[n][1])
    if extra:
        msg = (f"{csv_path} lists {listed(extra)} (line "
               f"{table[extra[0]][1]}), which are not frames of this sequence")
        if warn is None:
            raise SkyfitError(msg + "; remove those rows.")
        warn(msg + "; those rows are ignored.")
    times = []
    for n in names:
        text, line = table[n]
        who = f"{csv_path} line {line} ({n})"
        try:
            t = _iso(text)
        except ValueError:
            raise SkyfitError(f"{who}: {text!r} is not an ISO 8601 time; write e.g. "
                              "2026-06-21T12:00:05+01:00.") from None
        if t.tzinfo is not None:
            times.append(_with_offset(t, tz, who, "the"))
        else:
            times.append(localize(t, tz, who, f"has the time {text!r} without an offset; give "
                                  "--tz or write offsets in the CSV (2026-06-21T12:00:05+01:00)."))
    return times


# -------------------------------------------------------------------------------- patterns

_REGEX_GROUPS = ("year", "month", "day", "hour", "minute")


def _pattern_time(name, pattern, tz):
    if "(?P<" in pattern:
        try:
            rx = re.compile(pattern)
        except re.error as exc:
            raise SkyfitError(f"name pattern {pattern!r} is not a regular expression ({exc}); "
                              "fix it.") from None
        lacking = [g for g in _REGEX_GROUPS if g not in rx.groupindex]
        if lacking:
            raise SkyfitError(f"name pattern {pattern!r} lacks the named groups "
                              f"{', '.join(lacking)}; name them (?P<year>...) etc.")
        m = rx.fullmatch(name) or rx.fullmatch(Path(name).stem)
        if not m:
            raise SkyfitError(f"{name} does not match the name pattern {pattern!r}; rename the "
                              "file, fix the pattern, or give the times in a CSV.")
        g = m.groupdict()
        try:
            micro = int(((g.get("fraction") or "") + "000000")[:6])
            naive = dt.datetime(int(g["year"]), int(g["month"]), int(g["day"]), int(g["hour"]),
                                int(g["minute"]), int(g.get("second") or 0), micro)
        except (TypeError, ValueError):
            raise SkyfitError(f"{name}: the name pattern reads no valid date and time from it "
                              f"({g}); fix the pattern or give the times in a CSV.") from None
        off_text = g.get("offset")
        if off_text:
            off = parse_offset(off_text)
            if off is None:
                raise SkyfitError(f"{name}: {off_text!r} is not an offset such as '+01:00'; "
                                  "fix the pattern or the file name.")
            return _with_offset(naive.replace(tzinfo=off), tz, name, "the file name's")
    else:
        target = name if Path(pattern).suffix else Path(name).stem
        try:
            t = dt.datetime.strptime(target, pattern)
        except ValueError:
            raise SkyfitError(f"{name} does not match the name pattern {pattern!r}; rename the "
                              "file, fix the pattern (strptime codes: %Y %m %d %H %M %S %f %z), "
                              "or give the times in a CSV.") from None
        if t.tzinfo is not None:
            return _with_offset(t, tz, name, "the file name's")
        naive = t
    return localize(naive, tz, name, "has a time in its name but no offset; give --tz, or read "
                    "an offset with the pattern (%z).")


# --------------------------------------------------------------------------------- public

def frame_times(paths, metadata=None, *, times_csv=None, name_pattern=None, tz=None,
                warn=None):
    """One aware capture time per frame of ``paths``, in its source's offset (module docstring).

    ``metadata``: each frame's EXIF (``Photo.metadata``, list or mapping), used without
    ``times_csv`` and ``name_pattern``; ``tz``: zone of times without an offset, checked
    against those with one; ``warn``: told of CSV rows naming no frame (without it, an error).
    SkyfitError names the first frame (or CSV line) without a usable time.
    """
    paths = list(paths)
    if times_csv is not None and name_pattern is not None:
        raise SkyfitError("give the frame times from one source: a CSV of times or a "
                          "file-name pattern, not both.")
    zone = parse_tz(tz)
    names = [_name(p) for p in paths]
    if len(set(names)) != len(names) and (times_csv is not None or name_pattern is not None):
        dup = next(n for n in names if names.count(n) > 1)
        raise SkyfitError(f"two frames are named {dup}; times by CSV or name pattern need "
                          "distinct file names: rename one.")
    if times_csv is not None:
        return _csv_times(paths, times_csv, zone, warn)
    if name_pattern is not None:
        return [_pattern_time(n, str(name_pattern), zone) for n in names]
    if metadata is None:
        raise SkyfitError("no frame times: the frames' EXIF metadata, a CSV of times or a "
                          "file-name pattern is needed.")
    if hasattr(metadata, "items"):
        metas = [metadata.get(p, metadata.get(str(p))) for p in paths]
    else:
        metas = list(metadata)
        if len(metas) != len(paths):
            raise ValueError(f"{len(metas)} metadata entries for {len(paths)} paths")
    return [exif_time(m, zone, n) for n, m in zip(names, metas)]


def _check_aware(paths, times):
    for p, t in zip(paths, times):
        if t.tzinfo is None or t.utcoffset() is None:
            raise SkyfitError(f"{_name(p)} has a time without a time zone ({t}); give "
                              "aware times.")


def duplicate_times(paths, times):
    """[(instant, [path, ...])] of instants (UTC) shared by two or more frames, in time order."""
    paths, times = list(paths), list(times)
    _check_aware(paths, times)
    groups = {}
    for p, t in zip(paths, times):
        groups.setdefault(t.astimezone(dt.timezone.utc), []).append(p)
    return [(t, ps) for t, ps in sorted(groups.items()) if len(ps) > 1]


def time_order(times):
    """Indices that sort the frames by instant (stable: equal instants keep their order)."""
    times = list(times)
    _check_aware(range(len(times)), times)
    return sorted(range(len(times)), key=lambda i: times[i].astimezone(dt.timezone.utc))


def check_times(paths, times):
    """Refuse frames that share an instant (naming them); return :func:`time_order`."""
    paths, times = list(paths), list(times)
    dups = duplicate_times(paths, times)
    if dups:
        _, ps = dups[0]
        t = times[paths.index(ps[0])]                  # as the first frame states it
        more = f" ({len(dups) - 1} more instants are shared too)" if len(dups) > 1 else ""
        stems = {Path(p).stem for p in ps}
        pair = len(stems) == 1 and len({Path(p).suffix.lower() for p in ps}) > 1
        raise SkyfitError(
            f"{', '.join(_name(p) for p in ps)} {'both have' if len(ps) == 2 else 'all have'} "
            f"the time {t.isoformat()}{more}; every frame needs its own time: "
            + ("one shot in two formats (a RAW and its JPEG): give one format's files."
               if pair else "remove the extra frames, or give distinct times "
               "(SubSecTimeOriginal, or a CSV of times)."))
    return time_order(times)
