"""Regenerate the thesis's tables 7.1-7.12 and figures 6.5-6.21, 7.10, 7.13-7.14 on skyfit's
synthetic sequences (issues: fitting, relight).

Tables (``--part tables``):

Each case is a noise-free synthetic day (40 N, 21 June, hourly 06:00-18:00, clear sky, the
disc seen at 45 degrees from the thesis's camera), 16x16 frames at 1024 spp, 12-bit sensor;
the region is the central 4x4 pixels.  For the two-parameter cases Levenberg-Marquardt runs
from the thesis's listed starting points and its result is printed beside the thesis's;
annealing (the thesis's schedules) and the global method run from --starts random starts.
A fit succeeds when every determined parameter is within 0.01 (rho_s, R, C) and 0.005
(sigma_alpha) of the truth (sigma_alpha is not counted when rho_s = 0, where it has no
meaning, as in the thesis).

Figures (``--part figures``): see ``scripts/thesis_figures.py``; the PNGs go to
--figures-dir, their summary into --output after the tables.  Each part replaces only its own
section of --output.

    .venv/bin/python scripts/reproduce_thesis.py [--part all|tables|figures] [--starts 30]
        [--output docs/THESIS_TABLES.md] [--figures-dir out/thesis_figures]
"""

import argparse
import datetime as dt
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

LM_STARTS = {
    "7.1": [(0.1, 0.0), (0.0, 0.1), (0.1, 0.1), (0.2, 0.05), (0.2, 0.2), (0.4, 0.05), (0.4, 0.15),
            (0.6, 0.05), (0.6, 0.2), (0.8, 0.0), (0.8, 0.15), (1.0, 0.1), (1.0, 0.2)],
    "7.2": [(1.0, 0.15), (0.9, 0.2), (0.9, 0.1), (0.8, 0.15), (0.8, 0.05), (0.6, 0.1), (0.6, 0.0),
            (0.4, 0.15), (0.4, 0.05), (0.2, 0.2), (0.2, 0.05), (0.0, 0.05), (0.0, 0.15)],
    "7.3": [(1.0, 0.05), (0.9, 0.0), (0.9, 0.1), (0.8, 0.15), (0.8, 0.05), (0.6, 0.1), (0.6, 0.0),
            (0.4, 0.15), (0.4, 0.05), (0.2, 0.2), (0.2, 0.05), (0.0, 0.05), (0.0, 0.15)],
}
#: The thesis's LM results (rho_s, sigma_alpha) or None for "Fail", tables 7.1-7.3.
LM_THESIS = {
    "7.1": [(0.04, 0.0), None, None, None, (0.01, 0.2), (0.0, 0.0), None, (0.0, 0.0), None,
            (0.07, 0.0), (0.0, 0.19), None, (0.0, 0.2)],
    "7.2": [(1.0, 0.2), (1.0, 0.2), (1.0, 0.2), (1.0, 0.19), (0.8, 0.05), (1.0, 0.2), (0.6, 0.0),
            (1.0, 0.2), (0.4, 0.05), (1.0, 0.0), (0.2, 0.05), None, None],
    "7.3": [(1.0, 0.02), (1.0, 0.0), (1.0, 0.08), (0.45, 0.2), (1.0, 0.02), (0.6, 0.1), (1.0, 0.0),
            (0.28, 0.2), (1.0, 0.0), (0.2, 0.2), (0.47, 0.0), (0.37, 0.0), (0.1, 0.15)],
}
# (LM table, annealing table, model, camera azimuth, truth)
CASES = [
    ("7.1", "7.4", "two", 0.0, {"rho_s": 0.0, "sigma_alpha": 0.0}),
    ("7.2", "7.5", "two", 0.0, {"rho_s": 1.0, "sigma_alpha": 0.2}),
    ("7.3", "7.6", "two", 90.0, {"rho_s": 1.0, "sigma_alpha": 0.0}),
    (None, "7.7", "achromatic", 90.0, {"R": 0.33, "rho_s": 0.2, "sigma_alpha": 0.05}),
    (None, "7.8", "achromatic", 90.0, {"R": 0.66, "rho_s": 0.8, "sigma_alpha": 0.15}),
    (None, "7.9", "achromatic", 90.0, {"R": 1.0, "rho_s": 1.0, "sigma_alpha": 0.0}),
    (None, "7.10", "colour", 90.0, {"C": [0.25, 0.5, 0.75], "rho_s": 0.2, "sigma_alpha": 0.05}),
    (None, "7.11", "colour", 90.0, {"C": [0.75, 0.5, 0.25], "rho_s": 0.8, "sigma_alpha": 0.15}),
    (None, "7.12", "colour", 90.0, {"C": [1.0, 1.0, 1.0], "rho_s": 1.0, "sigma_alpha": 0.0}),
]


def truth_vector(model, truth):
    if model == "colour":
        return np.array([*truth["C"], truth["rho_s"], truth["sigma_alpha"]])
    if model == "achromatic":
        return np.array([truth["R"], truth["rho_s"], truth["sigma_alpha"]])
    return np.array([truth["rho_s"], truth["sigma_alpha"]])


def success(model, theta, truth):
    t = truth_vector(model, truth)
    err = np.abs(np.asarray(theta) - t)
    ok = np.all(err[:-1] <= 0.01)
    if t[-2] > 0:                                    # sigma has no meaning when rho_s = 0
        ok = ok and err[-1] <= 0.005
    return bool(ok)


def render_case(tmp, i, model, azimuth, truth):
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import thesis_disc_spec, validate_spec

    raw = thesis_disc_spec(f"case-{i}", {"model": model, **truth}, camera_azimuth_deg=azimuth,
                           seed=100 + i)
    out = Path(tmp) / f"case{i}"
    render_sequence(validate_spec(raw, tmp), out, progress=False, log=lambda *a: None)
    return out


def explain(result, model, truth):
    """Why a Levenberg-Marquardt run ended where it did, from the fit's own warnings."""
    if result["status"] == "failed":
        return "the curvature matrix is singular: chi2 does not change along some direction " \
            "here (e.g. sigma_alpha when rho_s = 0)"
    if success(model, list(result["parameters"].values()), truth):
        return "reached the truth"
    for w in result["warnings"]:
        if "global search finds" in w:
            return w.split(": lm ended")[0].replace("lm stopped", "stopped").replace(", but", "; ")
    return "chi2 at the result is within tolerance of the global minimum: the data do not " \
        "separate the two (see the warnings)"


def fmt(theta):
    return ", ".join(f"{v:.3f}" for v in theta)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=int, default=5,
                    help="random starts per case and method (0: only the Levenberg-Marquardt tables)")
    ap.add_argument("--cases", default="all", help="comma-separated table numbers (7.1-7.12)")
    ap.add_argument("--output", default="docs/THESIS_TABLES.md")
    ap.add_argument("--part", choices=("all", "tables", "figures"), default="all")
    ap.add_argument("--figures-dir", default="out/thesis_figures",
                    help="folder of the figures' PNGs (default out/thesis_figures)")
    args = ap.parse_args()
    command = " ".join([".venv/bin/python", "scripts/reproduce_thesis.py"] + sys.argv[1:])
    if args.part in ("all", "figures"):
        from thesis_figures import figures

        with tempfile.TemporaryDirectory() as tmp:
            section = figures(Path(tmp), Path(args.figures_dir).resolve())
        replace_part(args.output, 1, [FIGURES_MARK, "", f"Command: `{command}`. Date: "
                                      f"{dt.date.today().isoformat()}.", "", *section])
        print(f"wrote the figures' section of {args.output}")
    if args.part in ("all", "tables"):
        tables(args, command)


def tables(args, command):
    from skyfit_mi.fitting.chi2 import parse_region
    from skyfit_mi.fitting.fit import FitCache, FitSession

    region = parse_region("rect:6,6,9,9")
    lines = ["# The thesis's tables 7.1-7.12 (and, below, figures 6.5-6.21, 7.10, 7.13-7.14) on skyfit's sequences", "",
             f"Command: `{command}`. "
             f"Date: {dt.date.today().isoformat()}. Method in the script's docstring.", ""]
    summary = ["| table | model | truth | method | starts | successes | median evaluations | "
               "median time [s] | largest error | thesis |", "|---|---|---|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        for i, (lm_table, sa_table, model, az, truth) in enumerate(CASES):
            if args.cases != "all" and not {sa_table, lm_table} & set(args.cases.split(",")):
                continue
            seq = render_case(tmp, i, model, az, truth)
            session = FitSession(seq, "disc", region, model=model, cache=FitCache(seed=i))
            cam = {0.0: "north", 90.0: "east"}[az]
            tv = truth_vector(model, truth)
            if lm_table:
                lines += [f"## Table {lm_table}: Levenberg-Marquardt, {model}-parameter model, disc "
                          f"from the {cam}, truth ({fmt(tv)})", "",
                          "| start | thesis result | our result | our chi2/dof | our status | why |",
                          "|---|---|---|---|---|---|"]
                for s, th in zip(LM_STARTS[lm_table], LM_THESIS[lm_table]):
                    r = session.run("lm", start=s, log=lambda *a: None)
                    status = r["status"] if r["status"] != "failed" else "Fail (singular curvature)"
                    lines.append(f"| {fmt(s)} | {'Fail' if th is None else fmt(th)} | "
                                 f"{fmt(r['parameters'].values())} | {r['chi2_per_dof']:.3g} | {status} | "
                                 f"{explain(r, model, truth)} |")
                lines.append("")
            rng = np.random.default_rng(1000 + i)
            starts = [session.random_start(rng) for _ in range(args.starts)]
            for method in ("anneal", "global") if args.starts > 0 else ():
                runs = []
                for k, s in enumerate(starts):
                    t0 = time.perf_counter()
                    r = session.run(method, start=s, seed=k, log=lambda *a: None)
                    th = list(r["parameters"].values())
                    runs.append((success(model, th, truth), r["evaluations"],
                                 time.perf_counter() - t0, np.abs(np.array(th) - tv)))
                ok = sum(x[0] for x in runs)
                thesis = f"annealing: table {sa_table}, correct from every start" \
                    if method == "anneal" else "-"
                summary.append(f"| {sa_table} | {model} | {fmt(tv)} | {method} | {len(runs)} | {ok} | "
                               f"{np.median([x[1] for x in runs]):.0f} | "
                               f"{np.median([x[2] for x in runs]):.1f} | "
                               f"{fmt(np.max([x[3] for x in runs], axis=0))} | {thesis} |")
                print(summary[-1], flush=True)
            write(args.output, lines, summary, done=False)
    write(args.output, lines, summary, done=True)
    print(f"wrote {args.output}")


#: The line that starts the figures' section of the output (the tables' part comes before).
FIGURES_MARK = "<!-- figures: scripts/reproduce_thesis.py --part figures -->"


def write(path, lines, summary, done):
    """Write the tables so far, so that an interrupted run keeps its results."""
    text = lines + ["## Annealing (tables 7.4-7.12) and the global method from random starts", ""]
    text += summary + ["", "Times exclude the light cache (built once per case) and include the "
                       "uncertainty analysis of each fit."]
    if not done:
        text += ["", "*Run in progress: the cases above are complete, later ones not yet run.*"]
    replace_part(path, 0, text)


def replace_part(path, part, lines):
    """Replace part 0 (the tables) or 1 (the figures, from FIGURES_MARK on) of the markdown
    file ``path``, keeping the other; written atomically."""
    from skyfit_mi.files import write_text

    old = Path(path).read_text() if Path(path).exists() else ""
    head, mark, tail = old.partition(FIGURES_MARK)
    parts = [head.rstrip("\n"), (mark + tail).rstrip("\n")]
    parts[part] = "\n".join(lines).rstrip("\n")
    write_text(path, "\n\n".join(p for p in parts if p) + "\n")


if __name__ == "__main__":
    main()
