"""Benchmark: what fitting the sky with the materials costs (issue 36: <= 2x the separate fits;
issue 52: the photographs' default <= 2x the spec fit, <= 1.2 GB).

The README's sample board (scenes/specs/board_east_37.toml: 8 regions, 13 frames) is rendered
once (or --day gives a rendered or ingested folder), then each command of --commands runs as a
user runs it, one after another in rounds (so a slow spell of the machine hits every command
alike), each timed with its peak memory:

* spec: ``skyfit fit DAY --all --model 5 --sky spec`` (every region's light traced together)
* separate: the eight regions fitted one by one, ``--region NAME=pixels:...`` on the pixels the
  spec fit chose, under the spec's sky (summed; the peak is the largest)
* prior: ``--sky prior``, the sky's level (and its curve over the day) fitted with them
* shape: ``--sky prior --sky-shape``, its shape too
* departure: ``--sky prior --sky-departure``, its departure from the model's shape
* default: no ``--sky`` (on an ingested sequence the photographs' default: the level under its
  prior, its departure marginalised; on a rendered day the spec's sky)
* auto: ``--model auto`` with the default sky (issue 53: <= 2x the Ward fit, ``default``)

Prints a markdown table: median wall time over the rounds, peak memory, and each command's
ratio to the spec fit, to the separate fits and to the default.  With ``--bands``, each fit
of the last round is then relit onto the day it was fitted to (``relight --no-images``) and a
second table gives its region means' bands (issue 53, point 6): the median 95% half-width and
median |observed - predicted|, both over the prediction, and how many means the band holds.

The photographed card day of issue 52 (the README's board with a grey card, JPEGs, ingested):
``scripts/photo_test_set.py --scenario card --seeds 1 -o PS``, then ``--day
PS/seq_card_q92_s0 --commands spec default auto --bands``.

    .venv/bin/python scripts/bench_sky_fit.py [--rounds 2] [--day DIR] [--commands ...]
        [--bands]
"""

import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SKYFIT = [sys.executable, "-m", "skyfit_mi.cli"]
FIT = ["fit", "--all", "--model", "5", "-q"]
#: Each joint command's options after ``FIT`` (``separate`` is its own loop).
COMMANDS = {"spec": ["--sky", "spec"], "separate": None, "prior": ["--sky", "prior"],
            "shape": ["--sky", "prior", "--sky-shape"],
            "departure": ["--sky", "prior", "--sky-departure"], "default": [],
            "auto": ["--model", "auto"]}


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


def bands(fits, day, out):
    """Relight the fit folder ``fits`` onto ``day`` (no images): the median 95% half-width and
    median |observed - predicted| of its region means, both relative to the prediction [%],
    the means inside their band and their number."""
    run(["relight", str(fits), "--target", str(day), "--no-images", "-q", "-o", str(out)])
    with (Path(out) / "prediction.csv").open() as f:
        rows = [{k: float(r[f"{k} [W m^-2 sr^-1]"]) for k in ("predicted", "lo95", "hi95",
                                                              "observed")}
                for r in csv.DictReader(f)]
    half = [50 * (r["hi95"] - r["lo95"]) / r["predicted"] for r in rows]
    err = [100 * abs(r["observed"] - r["predicted"]) / r["predicted"] for r in rows]
    held = sum(r["lo95"] <= r["observed"] <= r["hi95"] for r in rows)
    return statistics.median(half), statistics.median(err), held, len(rows)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--day", help="a rendered or ingested board (default: render the README's "
                    "to a temporary folder)")
    ap.add_argument("--commands", nargs="+", choices=COMMANDS,
                    default=["spec", "separate", "prior", "shape", "departure"])
    ap.add_argument("--bands", action="store_true",
                    help="then relight each joint fit onto its day: its bands' table")
    a = ap.parse_args()
    if "separate" in a.commands and "spec" not in a.commands[:a.commands.index("separate")]:
        ap.error("separate fits the spec fit's pixels: put spec before it in --commands")
    times = {k: [] for k in a.commands}
    peaks = dict.fromkeys(times, 0.0)
    with tempfile.TemporaryDirectory() as tmp:
        day = a.day or str(Path(tmp) / "board")
        if a.day is None:
            run(["render", str(ROOT / "scenes/specs/board_east_37.toml"), "-o", day, "-q"])
        for r in range(a.rounds):
            for key in a.commands:
                t, m = separate(day, Path(tmp) / f"spec{r}", Path(tmp) / f"sep{r}") \
                    if COMMANDS[key] is None else \
                    run([FIT[0], day, *FIT[1:], *COMMANDS[key], "-o", str(Path(tmp) / f"{key}{r}")])
                times[key].append(t)
                peaks[key] = max(peaks[key], m)
                print(f"round {r} {key}: {t:.1f} s, {m:.2f} GB", flush=True)
        relit = {k: bands(Path(tmp) / f"{k}{a.rounds - 1}", day, Path(tmp) / f"relit-{k}")
                 for k in a.commands if a.bands and COMMANDS[k] is not None}
    med = {k: statistics.median(v) for k, v in times.items()}
    peers = [p for p in ("spec", "separate", "default") if p in med]
    print("\n| command | wall time [s] | peak [GB] |" + "".join(f" / {p} |" for p in peers))
    print("|---|---|---|" + "---|" * len(peers))
    for k in times:
        print(f"| {k} | {med[k]:.1f} | {peaks[k]:.2f} |"
              + "".join(f" {med[k] / med[p]:.2f} |" for p in peers))
    if relit:
        print("\n| fit | median 95% half-width | median error | means in band |\n|---|---|---|---|")
        for k, (half, err, held, n) in relit.items():
            print(f"| {k} | {half:.2f}% | {err:.2f}% | {held} of {n} |")


if __name__ == "__main__":
    main()
