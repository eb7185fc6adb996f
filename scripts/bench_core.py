"""Benchmark of the fit core: wall time and peak memory of `skyfit` commands, each run by this
checkout and (``--peer PATH``) by another one in the same run, on the same inputs.

Cases (``--cases``):

* ``board``: the README's sample-board day (``scenes/specs/board_east_37.toml``),
  ``fit --all --model 5``: every region's own wall time (its fit JSON's ``wall_time_s``, its
  share of the light traced for all regions included), median and slowest, and the command's.
* ``misfit``: a disc of Mitsuba's ``roughconductor`` (gold, Beckmann 0.15; frames by
  tests/independent.py), which Ward's model cannot describe (chi2/dof in the thousands),
  ``fit --region disc=rect:4,4,11,11 --model 5``.
* ``tableN``: a photometric-stereo table of N points under 96 directional lights
  (:func:`make_table`), ``ingest --table``, ``fit --all --model 5`` and
  ``relight --no-images`` of the fit onto the table.

Each command runs in a new process (``python -m skyfit_mi.cli``, the checkout first on
``PYTHONPATH``); its peak resident memory is the process's ``ru_maxrss``.  Prints a markdown
table and writes ``DIR/bench_core.json``.

    .venv/bin/python scripts/bench_core.py -o DIR [--peer PATH] [--cases board,misfit,table400]
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
GOLD = ('<bsdf type="roughconductor"><string name="material" value="Au"/>'
        '<string name="distribution" value="beckmann"/><float name="alpha" value="0.15"/></bsdf>')


def run(checkout, args, log):
    """Run ``skyfit ARGS`` with ``checkout``'s package: (wall time [s], peak RSS [MB])."""
    env = dict(os.environ, PYTHONPATH=str(checkout))
    t0 = time.perf_counter()
    with open(log, "w") as out:
        p = subprocess.Popen([sys.executable, "-m", "skyfit_mi.cli", *map(str, args)], env=env,
                             stdout=out, stderr=subprocess.STDOUT, cwd=checkout)
        _, status, usage = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{' '.join(map(str, args))} failed in {checkout}; see {log}")
    return wall, usage.ru_maxrss / 1024


def region_times(folder):
    """Every fit JSON's wall time in ``folder`` [s]."""
    return [json.loads(p.read_text())["wall_time_s"] for p in sorted(folder.glob("fit_*.json"))]


def board(out, checkout, tag):
    day = out / "board"
    if not (day / "manifest.json").exists():
        run(ROOT, ["render", ROOT / "scenes/specs/board_east_37.toml", "-o", day, "-q"],
            out / "render-board.log")
    fits = out / f"board-fits-{tag}"
    shutil.rmtree(fits, ignore_errors=True)
    wall, rss = run(checkout, ["fit", day, "--all", "--model", 5, "-o", fits],
                    out / f"fit-board-{tag}.log")
    t = region_times(fits)
    return {"command_s": wall, "peak_MB": rss, "region_median_s": float(np.median(t)),
            "region_max_s": float(np.max(t)), "regions": len(t)}


def misfit(out, checkout, tag):
    from independent_set import MITSUBA_HOURS, MITSUBA_SIZE, _render, _spec

    from independent import mitsuba_frames

    day = out / "misfit"
    if not (day / "manifest.json").exists():
        _render(_spec("gold disc", 40.0, {"type": "clear"}, 90.0, 5.0, 8.0, "disc",
                      MITSUBA_HOURS, MITSUBA_SIZE), day)
        mitsuba_frames(day, "disc", GOLD, spp=1024)
    fits = out / f"misfit-fits-{tag}"
    shutil.rmtree(fits, ignore_errors=True)
    wall, rss = run(checkout, ["fit", day, "--region", "disc=rect:4,4,11,11", "--model", 5,
                               "-o", fits], out / f"fit-misfit-{tag}.log")
    r = json.loads((fits / "fit_disc.json").read_text())
    return {"command_s": wall, "peak_MB": rss, "region_s": r["wall_time_s"],
            "chi2_per_dof": r["chi2_per_dof"], "positions": r["light_cache"]["positions"]}


CASES = {"board": board, "misfit": misfit}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--output", required=True, type=Path)
    ap.add_argument("--peer", type=Path, help="another checkout, run on the same inputs")
    ap.add_argument("--cases", default="board,misfit")
    args = ap.parse_args()
    args.output.mkdir(parents=True, exist_ok=True)
    checkouts = {"this": ROOT, **({"peer": args.peer.resolve()} if args.peer else {})}
    commit = {k: subprocess.run(["git", "-C", str(v), "rev-parse", "--short", "HEAD"],
                                capture_output=True, text=True).stdout.strip()
              for k, v in checkouts.items()}
    results = {"commits": commit, "date": time.strftime("%Y-%m-%d"), "cases": {}}
    for case in args.cases.split(","):
        for tag, checkout in checkouts.items():
            r = CASES[case](args.output, checkout, tag)
            results["cases"].setdefault(case, {})[tag] = r
            print(f"# {case} {tag} ({commit[tag]}): {r}", flush=True)
    (args.output / "bench_core.json").write_text(json.dumps(results, indent=1))
    print("| case | checkout | command [s] | peak memory [MB] | region median / max [s] |")
    print("|---|---|---|---|---|")
    for case, by in results["cases"].items():
        for tag, r in by.items():
            reg = (f"{r['region_median_s']:.1f} / {r['region_max_s']:.1f}"
                   if "region_median_s" in r else f"{r.get('region_s', float('nan')):.1f}")
            print(f"| {case} | {tag} {commit[tag]} | {r['command_s']:.1f} | {r['peak_MB']:.0f} "
                  f"| {reg} |")


if __name__ == "__main__":
    main()
