"""Benchmark: what fitting the sky with the materials costs (issue 36: <= 2x the separate fits).

The README's sample board (scenes/specs/board_east_37.toml: 8 regions, 13 frames) is rendered
once (or --day gives a rendered folder), then each command runs as a user runs it, one after
another in rounds (so a slow spell of the machine hits every command alike), each timed with
its peak memory:

* spec: ``skyfit fit DAY --all --model 5 --sky spec`` (every region's light traced together)
* separate: the eight regions fitted one by one, ``--region NAME=pixels:...`` on the pixels the
  spec fit chose, under the spec's sky (summed; the peak is the largest)
* prior: ``--sky prior``, the sky's level (and its curve over the day) fitted with them
* shape: ``--sky prior --sky-shape``, its shape too
* departure: ``--sky prior --sky-departure``, its departure from the model's shape (the
  photographs' default)

Prints a markdown table: median wall time over the rounds, peak memory, and each joint fit's
ratio to the spec fit and to the separate fits.

    .venv/bin/python scripts/bench_sky_fit.py [--rounds 2] [--day DIR]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SKYFIT = [sys.executable, "-m", "skyfit_mi.cli"]
FIT = ["fit", "--all", "--model", "5", "-q"]


def run(args):
    """Wall time [s] and peak resident memory [GB] of one skyfit command."""
    with tempfile.TemporaryFile() as err:
        t0 = time.perf_counter()
        p = subprocess.Popen(SKYFIT + args, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(p.pid, 0)
        t = time.perf_counter() - t0
        if status:
            err.seek(0)
            sys.exit(f"skyfit {' '.join(args[:4])} failed: {err.read().decode()[-500:]}")
    return t, usage.ru_maxrss / 2**20


def separate(day, spec, out):
    """The eight regions one by one on the pixels of the spec fit (its output folder
    ``spec``): summed time, largest peak."""
    total, peak = 0.0, 0.0
    for f in sorted(Path(spec).glob("fit_*.json")):
        fit = json.loads(f.read_text())
        px = ";".join(f"{x},{y}" for x, y in fit["pixels"])
        t, m = run(["fit", str(day), "--region", f"{fit['region']}=pixels:{px}", "--model", "5",
                    "--sky", "spec", "-q", "-o", str(Path(out) / fit["region"])])
        total, peak = total + t, max(peak, m)
    return total, peak


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--day", help="a rendered board (default: render it to a temporary folder)")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        day = a.day or str(Path(tmp) / "board")
        if a.day is None:
            run(["render", str(ROOT / "scenes/specs/board_east_37.toml"), "-o", day, "-q"])
        times = {k: [] for k in ("spec", "separate", "prior", "shape", "departure")}
        peaks = dict.fromkeys(times, 0.0)
        for r in range(a.rounds):
            for key, extra in (("spec", ["--sky", "spec"]), ("separate", None),
                               ("prior", ["--sky", "prior"]),
                               ("shape", ["--sky", "prior", "--sky-shape"]),
                               ("departure", ["--sky", "prior", "--sky-departure"])):
                t, m = separate(day, Path(tmp) / f"spec{r}", Path(tmp) / f"sep{r}") \
                    if extra is None else \
                    run([FIT[0], day, *FIT[1:], *extra, "-o", str(Path(tmp) / f"{key}{r}")])
                times[key].append(t)
                peaks[key] = max(peaks[key], m)
                print(f"round {r} {key}: {t:.1f} s, {m:.2f} GB", flush=True)
    med = {k: sorted(v)[len(v) // 2] if len(v) % 2 else sum(sorted(v)[len(v) // 2 - 1:
                                                                   len(v) // 2 + 1]) / 2
           for k, v in times.items()}
    print("\n| command | wall time [s] | peak [GB] | / spec | / separate |\n|---|---|---|---|---|")
    for k in times:
        print(f"| {k} | {med[k]:.1f} | {peaks[k]:.2f} | {med[k] / med['spec']:.2f} | "
              f"{med[k] / med['separate']:.2f} |")


if __name__ == "__main__":
    main()
