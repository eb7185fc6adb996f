"""Measured light against model skies: a day rendered under the measured clear day's skies,
fitted under them and under the thesis's CIE clear sky (issue 36, item 3).

The thesis disc in a known colour-model paint (C 0.6, 0.4, 0.2; rho_s 0.08; sigma_alpha 0.08),
seen from the west-north-west at 45 degrees, is rendered at the scans' times under the
envmaps made from them (``skyfit_testkit/measured_sky.py``: each scan's 81 points
interpolated over a fitted CIE general sky, the sun's DNI from the pyranometer's GHI less the
map's diffuse irradiance).  Its frames are fitted with

* the measured envmaps (the light the frames were rendered under),
* the thesis's CIE clear sky (eqs. 4.10-4.15, sun of eq. 4.7): what a user would assume,
* the same CIE clear sky scaled to the measured diffuse and direct irradiance,

and each fit's parameters, 95% intervals and the chi-square rise at the truth against the
joint 99.9% bound are tabulated.  First, the maps' leave-one-out error: each scan's points
predicted from the other 80, by the interpolated sky and by the fitted CIE general sky alone.

Data: Kider et al. 2014, github.com/spectralskylight/sky-measurements-2014, Apache-2.0.

    .venv/bin/python scripts/measured_sky_fit.py [--quick] [-o out/measured_sky_fit]

``--quick``: five scans (09:30, 10:30, 11:30, 12:15, 13:30), 12x12 pixels, 2% noise, a
16-pixel region, a small light cache (the test's day, tests/test_measured_sky.py); by default
all 15 scans, 16x16 pixels, 1% noise, a 64-pixel region, the light cache sized from the data.
Writes ``results.json`` to the output folder.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

QUICK_SCANS = (0, 4, 8, 11, 14)


def loo_table(scans):
    """Per scan: median and rms relative error of the held-out luminance, interpolated sky and
    CIE general sky alone, over all 81 points and over those 10 degrees or more from the sun
    other than point 0 (which reads 25-42% below its neighbours from 10:00 on)."""
    from skyfit_testkit.measured_sky import EXCLUDE_DEG, leave_one_out
    from skyfit_testkit.sky_measurement import angle_to_sun_deg

    rows = []
    for s in scans:
        d = s.directions(rotated=True)
        interpolated, model = leave_one_out(d, s.xyz, s.sun_direction)
        far = (angle_to_sun_deg(d, s.sun_direction) >= EXCLUDE_DEG) & (np.arange(81) != 0)
        row = {"time": s.label}
        for name, pred in (("interp", interpolated), ("cie", model)):
            e = pred / s.luminance - 1
            row[f"{name}_median"] = float(np.median(np.abs(e)))
            row[f"{name}_rms"] = float(np.sqrt(np.mean(e ** 2)))
            row[f"{name}_rms_far"] = float(np.sqrt(np.mean(e[far] ** 2)))
        rows.append(row)
    return rows


def main(argv=None):
    from measured_light import LIGHTS, TRUTH, fit, measured_disc_day, relabelled

    from skyfit_mi.files import ensure_dir, write_json
    from skyfit_testkit.sky_measurement import CITATION, load_scans
    from skyfit_mi.render import setup

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the test's small day")
    ap.add_argument("-o", "--out", type=Path, default=Path("out/measured_sky_fit"))
    ap.add_argument("--data", type=Path, default=None, help="the data folder")
    args = ap.parse_args(argv)
    setup()
    scans = load_scans(args.data)
    if args.quick:
        scans = [scans[i] for i in QUICK_SCANS]
        day_kw, fit_kw = {}, {}
    else:
        day_kw = {"size": 16, "noise_percent": 1.0, "spp": 512}
        fit_kw = {"region": "rect:4,4,11,11", "positions": None, "directions": 128}
    ensure_dir(args.out)

    t0 = time.perf_counter()
    loo = loo_table(scans)
    print(f"## Leave-one-out error of the maps ({time.perf_counter() - t0:.1f} s)\n")
    print("| scan | interpolated: median | rms | rms, >= 10 deg from the sun, no point 0 "
          "| CIE general alone: median | rms | rms, >= 10 deg, no point 0 |")
    print("|---|---|---|---|---|---|---|")
    for r in loo:
        print(f"| {r['time']} | {r['interp_median']:.3f} | {r['interp_rms']:.3f} | "
              f"{r['interp_rms_far']:.3f} | {r['cie_median']:.3f} | {r['cie_rms']:.3f} | "
              f"{r['cie_rms_far']:.3f} |")
    mean = {k: float(np.mean([r[k] for r in loo])) for k in loo[0] if k != "time"}
    print(f"| mean | {mean['interp_median']:.3f} | {mean['interp_rms']:.3f} | "
          f"{mean['interp_rms_far']:.3f} | {mean['cie_median']:.3f} | {mean['cie_rms']:.3f} | "
          f"{mean['cie_rms_far']:.3f} |\n")

    t0 = time.perf_counter()
    day = measured_disc_day(args.out, scans, **day_kw)
    print(f"rendered {len(scans)} frames under the measured envmaps in "
          f"{time.perf_counter() - t0:.1f} s ({day})\n")
    names = ("C_r", "C_g", "C_b", "rho_s", "sigma_alpha")
    print("## Fits (truth " + ", ".join(f"{n} {t:g}" for n, t in zip(names, TRUTH)) + ")\n")
    print("| light | chi2/dof | " + " | ".join(names)
          + " | chi2 rise at the truth / joint 99.9% bound | warnings |")
    print("|---|---|" + "---|" * len(names) + "---|---|")
    fits = {}
    for label, light in LIGHTS.items():
        folder = day if light is None else relabelled(
            day, args.out / label.replace(" ", "_").replace(",", ""), light)
        t0 = time.perf_counter()
        r, rise, bound = fit(folder, **fit_kw)
        cells = []
        for n, t in zip(names, TRUTH):
            lo, hi = r["intervals"][n]["95"]
            cells.append(f"{r['parameters'][n]:.4f} [{lo:.4f}, {hi:.4f}]"
                         + ("" if lo <= t <= hi else " **x**"))
        print(f"| {label} | {r['chi2_per_dof']:.2f} | " + " | ".join(cells)
              + f" | {rise:.4g} / {bound:.4g} | {len(r['warnings'])} |")
        fits[label] = {"parameters": r["parameters"],
                       "intervals_95": {n: r["intervals"][n]["95"] for n in names},
                       "chi2_per_dof": r["chi2_per_dof"], "truth_rise": rise,
                       "joint_999_bound": bound, "warnings": r["warnings"],
                       "seconds": time.perf_counter() - t0}
    write_json(args.out / "results.json",
               {"quick": args.quick, "scans": [s.label for s in scans], "truth": dict(
                   zip(names, TRUTH.tolist())), "leave_one_out": loo, "fits": fits,
                "data": CITATION})
    print(f"\nwrote {args.out / 'results.json'}\nData: {CITATION}")
    for label, f in fits.items():
        for w in f["warnings"]:
            print(f"[{label}] {w}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
