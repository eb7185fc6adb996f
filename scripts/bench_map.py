"""Benchmark: per-pixel material maps (issue 16), their speed, scaling and memory.

In one run, on scenes/specs/disc_clear_east.toml (13 frames) at SIZE x SIZE, the disc made of
table 7.10's material (C = 0.25, 0.5, 0.75, rho_s 0.2, sigma_alpha 0.05) with 2% sensor
noise (12 bits):
1. one chunk of the map's default size (pixel_map.CHUNK, a compact tile) fitted in a fresh
   process (5-parameter model): its wall time and peak resident memory (the cost model's
   per-chunk time and the memory per pixel);
2. `skyfit fit --per-pixel --all` of every disc pixel with 1 worker, then with 2 (fresh
   processes, cluster start and JIT compilation included): pixels per second and the scaling;
   each also on a 32x32 region, so that the slope between the two is the marginal rate
   and the intercept the overhead (processes, cluster, JIT): the cost model t = overhead +
   pixels / rate, and from it estimates for a 256 x 256 and a 4096 x 4096 map on N such
   machines (one Dask worker per machine: Dr.Jit already uses every core of one).
Prints a markdown table.

    .venv/bin/python scripts/bench_map.py [--size 256] [-o DIR]
"""

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "scenes" / "specs" / "disc_clear_east.toml"
MATERIAL = {"model": "colour", "C": [0.25, 0.5, 0.75], "rho_s": 0.2, "sigma_alpha": 0.05}
SMALL = 32

ONE_CHUNK = """
import json, resource, sys, time
import numpy as np
from skyfit_mi.fitting.pixel_fit import fit_pixels
from skyfit_mi.fitting.pixel_map import CHUNK, plan_chunks
from skyfit_mi.pipeline.pixels import material_regions
px = plan_chunks(material_regions(sys.argv[1]), 1, CHUNK)[0]["pixels"]
fit_pixels(sys.argv[1], "disc", px[:8])                      # imports and JIT compilation
t = time.perf_counter()
fit_pixels(sys.argv[1], "disc", px)
print(json.dumps({"seconds": time.perf_counter() - t, "pixels": len(px),
                  "peak_rss_MiB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def timed(args):
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "skyfit_mi.cli", *map(str, args)], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=256,
                    help="frame width and height (default 256)")
    ap.add_argument("-o", "--output", help="work folder (default a temporary one)")
    args = ap.parse_args()
    work = Path(args.output or tempfile.mkdtemp(prefix="bench_map_"))
    work.mkdir(parents=True, exist_ok=True)
    from skyfit_mi.pipeline.pixels import material_regions
    from skyfit_mi.pipeline.spec import read_spec

    raw = read_spec(SPEC)
    raw["camera"].update(width=args.size, height=args.size, fov_deg=12.0)
    raw["materials"] = {"disc": MATERIAL}
    raw["sensor"].update(bits=12, noise_percent=2.0)
    spec = work / "day.json"
    spec.write_text(json.dumps(raw))
    day = work / "day"
    timed(["render", spec, "-o", day, "-q", "--overwrite"])
    n_px = len(dict(material_regions(day))["disc"])
    chunk = json.loads(subprocess.run([sys.executable, "-c", ONE_CHUNK, str(day)],
                                      check=True, capture_output=True, text=True).stdout
                       .strip().splitlines()[-1])
    half, n_small = args.size // 2, SMALL * SMALL
    small = f"disc=rect:{half - SMALL // 2},{half - SMALL // 2},{half + SMALL // 2 - 1}," \
        f"{half + SMALL // 2 - 1}"
    runs = {}
    for workers in (1, 2):
        for what, region in (("small", ["--region", small]), ("all", ["--all"])):
            runs[workers, what] = timed(["fit", day, *region, "--per-pixel", "--workers",
                                         workers, "-o", work / f"map{workers}{what}",
                                         "--overwrite", "-q"])
    print("| step | pixels | workers | wall time [s] | pixels/s |")
    print("|---|---|---|---|---|")
    print(f"| one chunk in a warm process | {chunk['pixels']} | 1 | {chunk['seconds']:.1f} | "
          f"{chunk['pixels'] / chunk['seconds']:.1f} |")
    model = {}
    for (w, what), t in runs.items():
        n = n_small if what == "small" else n_px
        print(f"| `skyfit fit --per-pixel` ({what}) | {n} | {w} | {t:.1f} | {n / t:.1f} |")
    for w in (1, 2):
        rate = (n_px - n_small) / (runs[w, "all"] - runs[w, "small"])  # marginal pixels/s
        model[w] = (runs[w, "small"] - n_small / rate, rate)
    print(f"\nscaling 1 -> 2 workers (whole map): {runs[1, 'all'] / runs[2, 'all']:.2f}x; "
          f"peak RSS of the chunk process {chunk['peak_rss_MiB']:.0f} MiB "
          f"({chunk['peak_rss_MiB'] / chunk['pixels']:.2f} MiB per pixel of a {chunk['pixels']}-pixel "
          "chunk, imports included)")
    for w, (overhead, rate) in model.items():
        print(f"cost model, {w} worker(s) on this machine: t = {overhead:.0f} s + pixels / "
              f"{rate:.1f} px/s")
    overhead, rate = model[2]
    for side in (256, 4096):
        for machines in (1, 16, 64):
            print(f"estimate {side}x{side} on {machines} such machine(s): "
                  f"{(side * side / (rate * machines) + overhead) / 60:.1f} min")

if __name__ == "__main__":
    main()
