"""The measured clear day's sky scans as HDR environment maps and a spec that renders with them.

Each scan of 2013-05-27 (Ithaca NY; Kider et al. 2014) becomes ``maps/sky_HHMM.exr``, a
lat-long map of the sky's radiance (linear sRGB [W m^-2 sr^-1], world frame, interpolated from
its 81 points over a fitted CIE general sky, ``skyfit_testkit/measured_sky.py``), and a
``[[sky]]`` table of ``type = "envmap"`` whose ``direct_normal_W_m2`` is the pyranometer's GHI
less the map's own diffuse irradiance.  The template spec's scene, materials, camera, sensor
and render settings are kept; its place, times and sky become the measured day's.  Then:

    skyfit render OUT/measured_sky.json -o OUT/day
    skyfit fit OUT/day --all

Data: Kider et al. 2014, github.com/spectralskylight/sky-measurements-2014, Apache-2.0.

    .venv/bin/python scripts/measured_sky_maps.py [-o out/measured_sky]
        [--template scenes/specs/disc_clear_east.toml] [--times 09:30,11:30,13:30]
        [--rows 128] [--nominal] [--data FOLDER]
"""

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None):
    from skyfit_mi.errors import SkyfitError
    from skyfit_testkit.measured_sky import ROWS
    from skyfit_testkit.sky_measurement import CITATION, load_scans
    from skyfit_testkit.sky_scans import SUMMARY_FILE, measured_day
    from skyfit_mi.pipeline.spec import read_spec

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("out/measured_sky"))
    ap.add_argument("--template", type=Path, default=ROOT / "scenes/specs/disc_clear_east.toml",
                    help="a spec whose scene, materials, camera, sensor and render are kept")
    ap.add_argument("--times", default=None,
                    help="scans to use, by start time HH:MM, comma-separated (default: all 15)")
    ap.add_argument("--rows", type=int, default=ROWS, help="rows of each lat-long map")
    ap.add_argument("--nominal", action="store_true",
                    help="use the scanner's nominal directions, not turned by the data's "
                         "fitted rotation")
    ap.add_argument("--data", type=Path, default=None, help="the data folder")
    args = ap.parse_args(argv)
    try:
        scans = load_scans(args.data)
        if args.times:
            wanted = [t.strip() for t in args.times.split(",")]
            missing = sorted(set(wanted) - {s.label for s in scans})
            if missing:
                raise SkyfitError(f"--times {', '.join(missing)}: no such scan; the scans start "
                                  f"at {', '.join(s.label for s in scans)}.")
            scans = [s for s in scans if s.label in wanted]
        spec = measured_day(scans, args.out, read_spec(args.template), args.template.parent,
                            rows=args.rows, rotated=not args.nominal)
    except SkyfitError as exc:
        print(f"measured_sky_maps: error: {exc}", file=sys.stderr)
        return 2
    print((args.out / SUMMARY_FILE).read_text())
    print(f"{len(scans)} maps in {args.out / 'maps'}; spec {spec}\n"
          f"render: skyfit render {spec} -o {args.out / 'day'}\nData: {CITATION}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
