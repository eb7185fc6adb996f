"""A sky photographed: a day fitted under its sky as ``skyfit sky-series``
merges it, against the day's own light.

The thesis disc in a known colour-model paint is rendered under measured scans as maps
(``tests/measured_light.py``); each frame's sky is photographed through an upward fisheye in a
bracket of 8-bit JPEGs, with a horizontal grey card beside it (``tests/sky_shots.py``), merged,
and named by a spec's envmap sky.  The day is fitted (``--sky prior``) with its true light and
with the photographed series, each with the sun exact and with the card's uncertainty of it;
each fit's held parameters and C's median 95% half-width are printed and written to
``results.json``.  Data: Kider et al. 2014, github.com/spectralskylight/sky-measurements-2014,
Apache-2.0.

    .venv/bin/python scripts/sky_series_fit.py [--every N] [-o out/sky_series_fit]

``--every N``: every Nth of the 15 scans (default 5: three frames, the test's day).
``--gamma G``: the fisheye camera encodes its JPEGs with a pure gamma G (its own tone curve)
instead of sRGB; the series is merged both as ``sky-series`` does by default (the curve
measured on the brackets' overlaps) and told the codes are sRGB's (``--exact-curve``).
"""

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--every", type=int, default=5, help="every Nth scan (default 5)")
    ap.add_argument("--gamma", type=float, default=None,
                    help="the fisheye camera's own curve: a pure gamma (default sRGB's)")
    ap.add_argument("-o", "--output", default="out/sky_series_fit", help="output folder")
    args = ap.parse_args(argv)

    from sky_shots import fit_disc, photographed_day

    from skyfit_mi.files import ensure_dir, write_json
    from skyfit_mi.fitting.sky_fit import default_sun_sd
    from skyfit_testkit.sky_measurement import load_scans

    out = ensure_dir(args.output)
    t0 = time.perf_counter()
    scans = load_scans()[::args.every]
    day, photographed, skies = photographed_day(out / "work", scans, gamma=args.gamma)
    lights = [("true light", day), ("photographed series", photographed)]
    if args.gamma is not None:                # the same shots, read as sRGB's
        _, told, _ = photographed_day(out / "work", scans, gamma=args.gamma, exact_curve=True)
        lights.append(("series read as sRGB", told))
    sun_sd = default_sun_sd({"source": "photographs"}, list(skies.values()))
    rows = []
    for name, light in lights:
        for sd in (0.0, sun_sd):
            t = time.perf_counter()
            held, half, _ = fit_disc(light, sd)
            rows.append({"light": name, "sun_sd": sd, "held": sum(held.values()),
                         "c_half_width": half, "seconds": time.perf_counter() - t})
            print(f"{name:20s} sun sd {sd:.3f}: held {sum(held.values())} of 5, "
                  f"C half-width {100 * half:.2f}% ({rows[-1]['seconds']:.1f} s)")
    write_json(out / "results.json", {"frames": len(skies), "sun_sd": sun_sd, "fits": rows,
                                      "seconds": time.perf_counter() - t0})


if __name__ == "__main__":
    main()
