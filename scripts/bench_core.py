"""Benchmark of the fit core: wall time and peak memory of `skyfit` commands, each run by this
checkout and (``--peer PATH``) by another one in the same run, on the same inputs.

Cases (``--cases``):

* ``board``: the README's sample-board day (``scenes/specs/board_east_37.toml``),
  ``fit --all --model 5``: every region's own wall time (its fit JSON's ``wall_time_s``, its
  share of the light traced for all regions included), median and slowest, and the command's.
* ``auto``: the same day, ``fit --all --model auto`` (every lobe family and parameter count
  ranked, the chosen ones fitted): its cost against ``board``'s, issue 53's goal 2x.
* ``misfit``: a disc of Mitsuba's ``roughconductor`` (gold, Beckmann 0.15; frames by
  tests/independent.py), which Ward's model cannot describe (chi2/dof in the thousands),
  ``fit --region disc=rect:4,4,11,11 --model 5``.
* ``tableN``: a photometric-stereo table of N points under 96 directional lights
  (:func:`make_table`), ``ingest --table``, ``fit --all --model 5`` and
  ``relight --no-images`` of the fit onto the table; ``tableNauto`` the same with ``fit
  --model auto``, against ``tableN``'s fit issue 53's 2x.

Each command runs in a new process (``python -m skyfit_mi.cli``, the checkout first on
``PYTHONPATH``); its peak resident memory is the process's own ``VmHWM``.  Prints a markdown
table and writes ``DIR/bench_core.json``.

    .venv/bin/python scripts/bench_core.py -o DIR [--peer PATH] [--cases board,auto,misfit,table400]
"""

import argparse
import functools
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


#: Runs the CLI and writes the process's own peak resident memory (VmHWM: ru_maxrss would
#: carry a forking parent's across exec) [kB] to the file named by its first argument.
CLI = """
import atexit, runpy, sys
out = sys.argv.pop(1)
def peak():
    with open("/proc/self/status") as f:
        kb = next(int(l.split()[1]) for l in f if l.startswith("VmHWM:"))
    with open(out, "w") as f:
        f.write(str(kb))
atexit.register(peak)
sys.argv[0] = "skyfit"
runpy.run_module("skyfit_mi.cli", run_name="__main__")
"""


def run(checkout, args, log):
    """Run ``skyfit ARGS`` with ``checkout``'s package: (wall time [s], peak RSS [MB])."""
    env = dict(os.environ, PYTHONPATH=str(checkout))
    peak = Path(str(log) + ".peak_kB")
    t0 = time.perf_counter()
    with open(log, "w") as out:
        code = subprocess.run([sys.executable, "-c", CLI, str(peak), *map(str, args)], env=env,
                              stdout=out, stderr=subprocess.STDOUT, cwd=checkout).returncode
    wall = time.perf_counter() - t0
    if code != 0:
        raise SystemExit(f"{' '.join(map(str, args))} failed in {checkout}; see {log}")
    return wall, int(peak.read_text()) / 1024


def region_times(folder):
    """Every fit JSON's wall time in ``folder`` [s]."""
    return [json.loads(p.read_text())["wall_time_s"] for p in sorted(folder.glob("fit_*.json"))]


def board(out, checkout, tag, model=5):
    day = out / "board"
    if not (day / "manifest.json").exists():
        run(ROOT, ["render", ROOT / "scenes/specs/board_east_37.toml", "-o", day, "-q"],
            out / "render-board.log")
    fits = out / f"board-fits-{model}-{tag}"
    shutil.rmtree(fits, ignore_errors=True)
    wall, rss = run(checkout, ["fit", day, "--all", "--model", model, "-o", fits],
                    out / f"fit-board-{model}-{tag}.log")
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


#: The table's material (colour model) and its lights: irradiance [W m^-2], zenith range [deg].
TABLE_TRUTH = {"C": (0.6, 0.45, 0.3), "rho_s": 0.08, "sigma_alpha": 0.12}
LIGHTS, LIGHT_E, LIGHT_ZENITH = 96, 100.0, (10.0, 60.0)


def make_table(folder, n_points, seed=0, lights=LIGHTS, reflect=None, noise_floor=0.0):
    """A photometric-stereo table: ``n_points`` points on the disc, seen from above (a camera
    10 units up), under ``lights`` directional lights spread over the zenith range (a spiral);
    values of the BRDF ``reflect(wi, wo, rng)`` -> (P, 3) [sr^-1] (default the NumPy Ward
    reference at TABLE_TRUTH) with 1% noise, in quadrature with an instrument's ``noise_floor``
    [W m^-2 sr^-1] (a metal's values far from its lobe are otherwise known to 1% of almost
    nothing).  Returns (spec, table) paths."""
    from skyfit_mi.conventions import direction_from_angles
    from skyfit_mi.physics.ward import raw_parameters, ward_brdf

    folder.mkdir(parents=True, exist_ok=True)
    k = np.arange(lights)
    zen = np.radians(np.interp(k, [0, lights - 1], LIGHT_ZENITH))
    az = np.radians((k * 137.508) % 360.0)
    skies = [{"type": "directional", "zenith_deg": float(np.degrees(z)),
              "azimuth_deg": float(np.degrees(a)), "irradiance_W_m2": LIGHT_E}
             for z, a in zip(zen, az)]
    # lab lights: no time and no site, the frames are the lights by index
    spec = {"name": f"table-{n_points}", "sky": skies, "scene": {"file": "disc.xml"},
            "camera": {"origin": [0.0, 0.0, 10.0], "target": [0.0, 0.0, 0.0],
                       "up": [0.0, 1.0, 0.0], "fov_deg": 12.0, "width": 8, "height": 8}}
    rng = np.random.default_rng(seed)
    r, t = 0.9 * np.sqrt(rng.random(n_points)), 2 * np.pi * rng.random(n_points)
    pts = np.stack([r * np.cos(t), r * np.sin(t), np.zeros(n_points)], axis=1)
    if reflect is None:
        rho_d, spec_r, sigma = raw_parameters("colour", **TABLE_TRUTH)

        def reflect(wi, wo, rng):
            return ward_brdf(wi, wo, rho_d, spec_r, sigma)
    rows = ["frame,region,point,x,y,z,view_zenith_deg,view_azimuth_deg,r,g,b,sigma"]
    wo = np.array([0.0, 0.0, 10.0]) - pts                 # the disc is horizontal: local = world
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    vz, va = np.degrees(np.arccos(wo[:, 2])), np.degrees(np.arctan2(wo[:, 0], wo[:, 1])) % 360
    for j, (z, a) in enumerate(zip(zen, az)):
        wi = np.broadcast_to(direction_from_angles(z, a), wo.shape)
        value = reflect(wi, wo, rng) * LIGHT_E * wi[:, 2:]
        noise = np.hypot(0.01 * value.mean(axis=1), noise_floor)
        y = value + noise[:, None] * rng.standard_normal(value.shape)
        rows += [f"{j},disc,p{i},{p[0]:.6f},{p[1]:.6f},0,"
                 f"{vz[i]:.6f},{va[i]:.6f}," + ",".join(f"{v:.6g}" for v in (*y[i], noise[i]))
                 for i, p in enumerate(pts)]
    (folder / "spec.json").write_text(json.dumps(spec))
    (folder / "table.csv").write_text("\n".join(rows) + "\n")
    return folder / "spec.json", folder / "table.csv"


def table(n_points, model=5):
    """The ``tableN`` case (``tableNauto``: ``--model auto``): ingest, fit and relight
    (--no-images) of :func:`make_table`."""
    def case(out, checkout, tag):
        src = out / f"table{n_points}-input"
        if not (src / "table.csv").exists():
            make_table(src, n_points)
        name = f"table{n_points}{'' if model == 5 else model}"
        day, fits, relit = (out / f"{name}-{k}-{tag}" for k in ("day", "fits", "relit"))
        for f in (day, fits, relit):
            shutil.rmtree(f, ignore_errors=True)
        res = {}
        for step, args in (("ingest", ["ingest", src / "spec.json", "--table",
                                       src / "table.csv", "-o", day]),
                           ("fit", ["fit", day, "--all", "--model", model, "-o", fits]),
                           ("relight", ["relight", fits, "--target", day, "-o", relit,
                                        "--no-images"])):
            wall, rss = run(checkout, args, out / f"{step}-{name}-{tag}.log")
            res[f"{step}_s"], res[f"{step}_peak_MB"] = wall, rss
        r = json.loads((fits / "fit_disc.json").read_text())
        res.update(command_s=res["fit_s"], peak_MB=res["fit_peak_MB"],
                   region_s=r["wall_time_s"], chi2_per_dof=r["chi2_per_dof"],
                   parameters=r["parameters"])
        return res
    return case


CASES = {"board": board, "auto": functools.partial(board, model="auto"), "misfit": misfit,
         "table400": table(400), "table4000": table(4000),
         "table400auto": table(400, "auto"), "table4000auto": table(4000, "auto")}


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
