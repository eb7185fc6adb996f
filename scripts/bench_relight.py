"""Benchmark: relighting a 13-frame 256x256 day and a 60x60 chi-square map (issue 14).

In one run, each step a fresh `skyfit` process (imports and JIT compilation included), on
scenes/specs/disc_clear_east.toml at 256x256, 64 spp, its disc made of table 7.10's material
(C = 0.25, 0.5, 0.75, rho_s 0.2, sigma_alpha 0.05) with 2% sensor noise (12 bits):
1. `skyfit render` of the day (the peer: relighting should cost no more);
2. `skyfit fit` of the disc's central 8x8 pixels (64 pixels, --model 5);
3. `skyfit relight` of that fit onto the day (render, prediction with its band, comparison
   images, the noise floor from the sigma images);
4. `skyfit relight --no-images` (the prediction alone);
5. the same as 3 with `--reference` (the target's own materials rendered again: a second
   render);
6. `skyfit chi2map` 60 x 60 over (rho_s, sigma_alpha), others at the fit;
7. the same with `--profile` (C at its best for each point).
Prints a markdown table of wall times and the ratio of each to the render's; then, in this
warm process, ``--warm`` predictions without images (the fast path per sequence): each one's
wall time, its light cache's, and the kernels compiled during it (Dr.Jit's kernel history).
With ``--board``, the same for the README's several regions: the sample board's day
(scenes/specs/board_east_37.toml as it is), `fit --all --model 5` of its eight samples, then
relight with images and without (a few minutes more, most of them the fits).

With ``--pairs N``, then N renders and relights one after the other, for the ratio's spread.

    .venv/bin/python scripts/bench_relight.py [-o DIR] [--board] [--pairs N]
"""

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "scenes" / "specs" / "disc_clear_east.toml"
MATERIAL = {"model": "colour", "C": [0.25, 0.5, 0.75], "rho_s": 0.2, "sigma_alpha": 0.05}


def timed(args):
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "skyfit_mi.cli", *map(str, args)], check=True,
                   stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--output", help="work folder (default a temporary one)")
    ap.add_argument("--warm", type=int, default=4,
                    help="predictions without images timed in this process (default 4)")
    ap.add_argument("--board", action="store_true",
                    help="also the sample board's day with its eight regions (README)")
    ap.add_argument("--pairs", type=int, default=0,
                    help="then render and relight (with images) alternately this many times "
                    "more, each pair's ratio and their median (the machine's spread)")
    args = ap.parse_args()
    work = Path(args.output or tempfile.mkdtemp(prefix="bench_relight_"))
    work.mkdir(parents=True, exist_ok=True)
    day, fits = work / "day", work / "fits"
    from skyfit_mi.pipeline.spec import read_spec

    raw = read_spec(SPEC)
    raw["camera"].update(width=256, height=256)
    raw["materials"] = {"disc": MATERIAL}
    raw["sensor"].update(bits=12, noise_percent=2.0)
    spec = work / "day.json"
    spec.write_text(json.dumps(raw))
    rows = [("render (the peer)", timed(["render", spec, "-o", day, "-q", "--overwrite"]))]
    rows.append(("fit, 64 pixels, --model 5",
                 timed(["fit", day, "--region", "disc=rect:124,124,131,131", "-o", fits])))
    rows += relights(fits, day, work)
    rows.append(("relight --reference (also the truth rendered again)",
                 timed(relight_args(fits, day, work / "relit", "--reference"))))
    rows.append(("chi2map 60 x 60, 64 pixels",
                 timed(["chi2map", day, fits / "fit_disc.json", "-o", work / "map"])))
    rows.append(("chi2map 60 x 60 --profile",
                 timed(["chi2map", day, fits / "fit_disc.json", "-o", work / "profile",
                        "--profile"])))
    table(rows)
    warm(fits, day, work / "warm", args.warm)
    if args.board:
        board(work / "board")
    if args.pairs:
        pairs("disc", ["render", spec, "-o", day, "-q", "--overwrite"], fits, day, work,
              args.pairs)
    if args.pairs and args.board:
        b = work / "board"
        pairs("board", ["render", ROOT / "scenes" / "specs" / "board_east_37.toml", "-o",
                        b / "day", "-q", "--overwrite"], b / "fits", b / "day", b, args.pairs)


def relight_args(fits, day, out, *flags):
    """The arguments of `skyfit relight` of ``fits`` onto ``day`` into ``out`` (quiet, over an
    earlier run), with ``flags``."""
    return ["relight", fits, "--target", day, "-o", out, "-q", "--overwrite", *flags]


def table(rows):
    """Print ``rows`` [(step, wall time)] as markdown, each also over the first's."""
    peer = rows[0][1]
    print("| step | wall time [s] | / render |\n|---|---|---|")
    for name, t in rows:
        print(f"| {name} | {t:.1f} | {t / peer:.2f} |", flush=True)


def board(work):
    """The README's day: render, fit of every sample, relight with and without images."""
    day, fits = work / "day", work / "fits"
    rows = [("board: render (the peer)",
             timed(["render", ROOT / "scenes" / "specs" / "board_east_37.toml", "-o", day, "-q",
                    "--overwrite"]))]
    rows.append(("board: fit --all --model 5 (8 regions)",
                 timed(["fit", day, "--all", "--model", "5", "-o", fits])))
    rows += relights(fits, day, work, "board, 8 regions: ")
    print()
    table(rows)


def relights(fits, day, work, label=""):
    """Rows of ``fits`` relit onto ``day`` with images, then without (``--no-images``)."""
    return [(f"{label}relight (images, band, comparisons)",
             timed(relight_args(fits, day, work / "relit"))),
            (f"{label}relight --no-images (prediction and band only)",
             timed(relight_args(fits, day, work / "predicted", "--no-images")))]


def pairs(name, render, fits, day, work, n):
    """``n`` times a render (command ``render``, which writes ``day`` again as it was) and a
    relight of ``fits`` onto ``day`` with images, one after the other: each pair's times and
    ratio, and the median ratio."""
    print(f"\n| {name}: pair | render [s] | relight [s] | relight / render |\n|---|---|---|---|")
    ratios = []
    for i in range(n):
        a = timed(render)
        b = timed(relight_args(fits, day, work / "relit"))
        ratios.append(b / a)
        print(f"| {i + 1} | {a:.2f} | {b:.2f} | {b / a:.3f} |", flush=True)
    print(f"| median | | | {statistics.median(ratios):.3f} |")


def warm(fits, day, out, n):
    """``n`` predictions without images of ``fits`` onto ``day`` in this process, each timed
    (the first loads Mitsuba and the compiled kernels from disk)."""
    import drjit as dr

    from skyfit_mi.fitting.relight import relight
    from skyfit_mi.pipeline.fit_result import load_fits
    from skyfit_mi.render import basis_table

    cache_time = []
    build = basis_table.light_caches

    def timed_build(*a, **k):
        t0 = time.perf_counter()
        c = build(*a, **k)
        cache_time.append(time.perf_counter() - t0)
        return c
    basis_table.light_caches = timed_build          # trace_basis looks it up at each block
    print("\n| warm prediction | wall time [s] | light cache [s] | kernels compiled |\n"
          "|---|---|---|---|")
    loaded = load_fits([fits])
    for i in range(n):
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        dr.kernel_history()                                   # clears it
        t0, first = time.perf_counter(), len(cache_time)
        relight(loaded, day, out, images=False, log=lambda *a: None, progress=False,
                overwrite=True)
        wall = time.perf_counter() - t0
        compiled = sum(1 for k in dr.kernel_history() if "cache_hit" in k and not k["cache_hit"])
        dr.set_flag(dr.JitFlag.KernelHistory, False)
        print(f"| {i + 1} | {wall:.2f} | {sum(cache_time[first:]):.2f} | {compiled} |", flush=True)
    basis_table.light_caches = build


if __name__ == "__main__":
    main()
