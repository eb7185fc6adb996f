"""Benchmark: the light cache's accuracy at every roughness, and its cost (issue: honest fits).

For each roughness, the table 7.7 disc (R = 0.33, rho_s = 0.2) from the east at 45 degrees,
40 N, 21 June, hourly 06:00-18:00, 16x16 frames rendered at --spp under a clear and an
overcast sky; the cache of the central 4x4 pixels (default positions x directions) is built
and its radiance at the truth compared with the render's.  Reports per sky and roughness:

* the cache's own Monte Carlo error, rms per value: the relative difference of its two
  independent half caches, (a - b) / (a + b), whose rms equals the whole cache's error;
* the rms relative difference from the render (which adds the render's own noise);
* the largest per-frame mean difference from the render (a shared error that biases fits);
* the build time.

    .venv/bin/python scripts/bench_cache.py [--spp 4096] [--sigmas 0.01,0.05,0.1,0.2,0.35]
"""

import argparse
import datetime as dt
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=4096)
    ap.add_argument("--sigmas", default="0.01,0.05,0.1,0.2,0.35")
    ap.add_argument("--skies", default="clear,overcast")
    args = ap.parse_args()
    from skyfit_mi.fitting.chi2 import parse_region
    from skyfit_mi.fitting.fit import FitCache, FitSession
    from skyfit_mi.pipeline.pixels import frame_values
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import thesis_disc_spec, validate_spec

    print(f"Command: `.venv/bin/python scripts/bench_cache.py {' '.join(sys.argv[1:])}`. "
          f"Date: {dt.date.today().isoformat()}.\n")
    print("| sky | sigma_alpha | cache's own error (rms per value) | rms difference from the "
          "render | largest per-frame mean difference | build time [s] |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for sky in args.skies.split(","):
            for sigma in (float(s) for s in args.sigmas.split(",")):
                truth = {"R": 0.33, "rho_s": 0.2, "sigma_alpha": sigma}
                raw = thesis_disc_spec(f"cache-{sky}-{sigma}", {"model": "achromatic", **truth},
                                       spp=args.spp, seed=8, sky=sky)
                out = Path(tmp) / f"{sky}-{sigma}"
                render_sequence(validate_spec(raw, tmp), out, progress=False, log=lambda *a: None)
                t0 = time.perf_counter()
                s = FitSession(out, "disc", parse_region("rect:6,6,9,9"), model="achromatic",
                               cache=FitCache(seed=1))
                t = time.perf_counter() - t0
                theta = [truth["R"], truth["rho_s"], sigma]
                # the table's two independent halves of the positions (parts 1 and 2)
                a, b = (s.model_on(s.table, part=j).radiance(theta) for j in (1, 2))
                own = np.sqrt(np.mean(((a - b) / (a + b)) ** 2))
                rendered = frame_values(out, s.obs.pixels, s.obs.frames)
                rel = s.wm.radiance(theta) / rendered - 1
                print(f"| {sky} | {sigma:g} | {100 * own:.3f}% | "
                      f"{100 * np.sqrt(np.mean(rel**2)):.2f}% | "
                      f"{100 * np.max(np.abs(rel.mean(axis=(0, 2)))):.2f}% | {t:.1f} |", flush=True)
    print(f"\nThe render ({args.spp} spp) has its own noise: the differences from it are bounded "
          "below by it.")


if __name__ == "__main__":
    main()
