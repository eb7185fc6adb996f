"""Benchmark: the light cache's accuracy and cost against a high-sample render (issue: fitting).

The table 7.7 disc (R = 0.33, rho_s = 0.2, sigma_alpha = 0.05, a highlight in the afternoon
frames) from the east at 45 degrees, 40 N, 21 June, hourly 06:00-18:00, 16x16 frames rendered
at --spp; the cache of the central 4x4 pixels is built with several positions x directions
splits and its radiance at the truth compared with the render's.  Reports the RMS relative
error per value, the largest per-frame mean relative error (a shared error that biases fits),
and the cache's build time.  Prints a markdown table.

    .venv/bin/python scripts/bench_cache.py [--spp 4096]
"""

import argparse
import datetime as dt
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SPLITS = [(4, 1024), (16, 256), (32, 128), (64, 64), (32, 256)]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=4096)
    args = ap.parse_args()
    from skyfit_mi.fitting.chi2 import parse_region
    from skyfit_mi.fitting.fit import FitSession
    from skyfit_mi.pipeline.pixels import frame_values
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import thesis_disc_spec, validate_spec

    truth = {"R": 0.33, "rho_s": 0.2, "sigma_alpha": 0.05}
    raw = thesis_disc_spec("cache-bench", {"model": "achromatic", **truth}, spp=args.spp, seed=8)
    print(f"Command: `.venv/bin/python scripts/bench_cache.py {' '.join(sys.argv[1:])}`. "
          f"Date: {dt.date.today().isoformat()}.\n")
    print("| positions x directions | samples per pixel | RMS relative error | largest per-frame "
          "mean error | build time [s] |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "seq"
        render_sequence(validate_spec(raw, tmp), out, progress=False, log=lambda *a: None)
        for positions, directions in SPLITS:
            t0 = time.perf_counter()
            s = FitSession(out, "disc", parse_region("rect:6,6,9,9"), model="achromatic", seed=1,
                           positions=positions, directions=directions)
            t = time.perf_counter() - t0
            rendered = frame_values(out, s.obs.pixels, s.obs.frames)
            rel = s.wm.radiance([truth["R"], truth["rho_s"], truth["sigma_alpha"]]) / rendered - 1
            print(f"| {positions} x {directions} | {positions * directions} | "
                  f"{100 * np.sqrt(np.mean(rel**2)):.2f}% | "
                  f"{100 * np.max(np.abs(rel.mean(axis=(0, 2)))):.2f}% | {t:.1f} |", flush=True)
    print(f"\nThe render ({args.spp} spp) has its own error: compare rows with each other.")


if __name__ == "__main__":
    main()
