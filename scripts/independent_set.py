"""Issue 13's independent test set: fits of days the fit's own renderer did not make.

Radiance days (rtrace with gensky's skies and Radiance plastic/metal; tests/independent.py):
an east camera under a clear sky (colour plastic), an overcast day, the southern hemisphere,
a camera on the sun's side, a near camera (every pixel a different view), a metal sphere.
Each is fitted on its noise replicates (2% sensor noise, 12-bit): the table gives the
first replicate's fit, whether each parameter's 95% interval holds the truth or a warning
names it, and the coverage of the truth by 95% intervals over the replicates.

Mitsuba days of non-Ward materials (roughplastic, roughconductor, principled), each from
three cameras (azimuths 90, 45, 135 degrees) over the project's standard day (13 hourly
frames, a 64-pixel region): on each noise replicate the fit to the first camera predicts the
other two (relative RMS error of the predicted radiance against Mitsuba's), against the best
Ward fit possible, the fit to all three cameras at once.  Goal: within 1.2x.

    .venv/bin/python scripts/independent_set.py [--replicates 20] [--mitsuba-replicates 3]
        [--cases NAME,...] [-o DIR]

writes DIR/independent_set.json and prints the tables (docs/BENCHMARKS.md, "The independent
test set").
"""
import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

HOURS = (8.0, 10.0, 12.0, 14.0, 16.0)
DATE = "2026-06-21"
SIZE = 12
REGION = "rect:4,4,7,7"
#: (name, latitude, gensky kind, camera azimuth, distance, fov, geometry, Radiance material,
#: truth as the colour model's (C_r, C_g, C_b, rho_s, sigma_alpha), region)
RADIANCE = [
    ("east clear, colour plastic", 40.0, "+s", 90.0, 5.0, 8.0, "disc",
     "void plastic mat 0 0 5 0.6 0.4 0.2 0.08 0.1", (0.6, 0.4, 0.2, 0.08, 0.1), REGION),
    ("overcast, grey plastic", 40.0, "-c", 90.0, 5.0, 8.0, "disc",
     "void plastic mat 0 0 5 0.5 0.5 0.5 0.05 0.05", (0.5, 0.5, 0.5, 0.05, 0.05), REGION),
    ("southern hemisphere, colour plastic", -34.0, "+s", 90.0, 5.0, 8.0, "disc",
     "void plastic mat 0 0 5 0.3 0.5 0.6 0.06 0.15", (0.3, 0.5, 0.6, 0.06, 0.15), REGION),
    ("camera on the sun's side", 40.0, "+s", 180.0, 5.0, 8.0, "disc",
     "void plastic mat 0 0 5 0.6 0.4 0.2 0.08 0.1", (0.6, 0.4, 0.2, 0.08, 0.1), REGION),
    ("near camera, smooth grey plastic", 40.0, "+s", 90.0, 2.0, 50.0, "disc",
     "void plastic mat 0 0 5 0.4 0.4 0.4 0.05 0.03", (0.4, 0.4, 0.4, 0.05, 0.03),
     "rect:2,3,9,8"),
    ("sphere, rough grey metal", 40.0, "+s", 90.0, 6.0, 22.0, "sphere",
     "void metal mat 0 0 5 0.7 0.7 0.7 0.9 0.15", (0.7, 0.7, 0.7, 0.9, 0.15), "rect:4,3,7,6"),
]
#: Mitsuba's non-Ward materials (a <bsdf> without id).
MITSUBA = [
    ("roughplastic (GGX 0.1, orange)",
     '<bsdf type="roughplastic"><string name="distribution" value="ggx"/>'
     '<float name="alpha" value="0.1"/><rgb name="diffuse_reflectance" value="0.7,0.35,0.1"/>'
     '</bsdf>'),
    ("roughconductor (gold, Beckmann 0.15)",
     '<bsdf type="roughconductor"><string name="material" value="Au"/>'
     '<string name="distribution" value="beckmann"/><float name="alpha" value="0.15"/></bsdf>'),
    ("principled (blue, roughness 0.4)",
     '<bsdf type="principled"><rgb name="base_color" value="0.1,0.2,0.6"/>'
     '<float name="roughness" value="0.4"/><float name="specular" value="0.5"/></bsdf>'),
]
CAMERAS = (90.0, 45.0, 135.0)
#: the Mitsuba days: the project's standard day (13 hourly frames) and a 64-pixel region, so
#: that the fit's own estimation noise is small beside the Ward model's misfit
MITSUBA_HOURS = tuple(float(h) for h in range(6, 19))
MITSUBA_SIZE = 16
MITSUBA_REGION = "rect:4,4,11,11"


def _spec(name, latitude, skies, azimuth, distance, fov, geometry, hours=HOURS, size=SIZE,
          seed=1):
    return {"name": name.split(",")[0].replace(" ", "-").replace("'", ""),
            "location": {"latitude_deg": latitude, "longitude_deg": 0.0, "timezone": "UTC"},
            "time": {"date": DATE, "times": [f"{int(h):02d}:00" for h in hours]},
            "sky": skies, "scene": {"file": f"{geometry}.xml"},
            "materials": {geometry: {"model": "two", "rho_s": 0.05, "sigma_alpha": 0.1}},
            "camera": {"azimuth_deg": azimuth, "angle_deg": 45.0, "distance": distance,
                       "fov_deg": fov, "width": size, "height": size, "target": [0.0, 0.0, 1.0]
                       if geometry == "sphere" else [0.0, 0.0, 0.0]},
            "sensor": {"exposure": "auto", "bits": 12, "noise_percent": 2.0},
            "render": {"spp": 64, "seed": seed}}


def _render(spec, out):
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import validate_spec

    render_sequence(validate_spec(spec, out.parent), out, progress=False, log=lambda *a: None,
                    overwrite=True)


def radiance_case(case, root, replicates, run):
    from independent import gensky_entries, held_or_warned, radiance_frames
    from skyfit_mi.fitting.chi2 import parse_region
    from skyfit_mi.fitting.fit import FitSession
    from skyfit_mi.pipeline.pixels import frame_values

    name, lat, kind, az, dist, fov, geometry, material, truth, region = case
    out = root / f"radiance-{RADIANCE.index(case)}"
    skies = gensky_entries(run, DATE, HOURS, lat, 0.0, kind)
    _render(_spec(name, lat, skies, az, dist, fov, geometry), out)
    radiance_frames(run, out, [s["gensky"] for s in skies], material, geometry)
    s = FitSession(out, geometry, parse_region(region), model="colour",
                   normalisation="balanced")
    traced = frame_values(out, s.obs.pixels, s.obs.frames)
    model_ratio = float(np.median(s.wm.radiance(np.array(truth)) / traced))
    rows, covered = [], []
    for r in range(replicates):
        s.obs.recapture(traced, np.random.default_rng([31, r]))
        res = s.run("global", seed=r, log=lambda *a: None)
        held = held_or_warned(s.names, res["intervals"], res["warnings"], truth)
        covered.append([res["intervals"][p]["95"][0] <= t <= res["intervals"][p]["95"][1]
                        for p, t in zip(s.names, truth)])
        rows.append({"parameters": res["parameters"], "held": held,
                     "chi2_per_dof": res["chi2_per_dof"], "warnings": res["warnings"],
                     "readings": res["readings"], "wall_s": res["wall_time_s"]})
    return {"case": name, "truth": dict(zip(s.names, truth)), "model_over_radiance": model_ratio,
            "first": rows[0], "coverage95": dict(zip(s.names, np.mean(covered, 0).tolist())),
            "within_or_warned": float(np.mean([all(v != "MISSED" for v in r["held"].values())
                                               for r in rows])),
            "replicates": replicates, "closest_sun_half_angle_deg":
                s.geometry["closest_highlight_half_angle_deg"]}


class Joint:
    """Chi-square of several fit sessions at once (the same parameters), for the best Ward fit."""

    def __init__(self, problems):
        self.problems = problems
        self.evaluations = 0

    def residuals(self, theta):
        return np.concatenate([p.residuals(theta) for p in self.problems])

    def jacobian(self, theta):
        parts = [p.jacobian(theta) for p in self.problems]
        return np.concatenate([r for r, _ in parts]), np.concatenate([j for _, j in parts])

    def chi2(self, theta):
        r = self.residuals(theta)
        return float(r @ r)


def mitsuba_case(case, root, replicates):
    from independent import mitsuba_frames
    from skyfit_mi.fitting.chi2 import parse_region
    from skyfit_mi.fitting.fit import FitSession
    from skyfit_mi.fitting.methods.levenberg_marquardt import levenberg_marquardt
    from skyfit_mi.fitting.relight import rel_rms
    from skyfit_mi.pipeline.pixels import frame_values

    name, bsdf = case
    sessions, radiance = [], []
    for j, az in enumerate(CAMERAS):
        out = root / f"mitsuba-{MITSUBA.index(case)}-{j}"
        _render(_spec(name, 40.0, {"type": "clear"}, az, 5.0, 8.0, "disc", MITSUBA_HOURS,
                      MITSUBA_SIZE), out)
        mitsuba_frames(out, "disc", bsdf, spp=1024)
        s = FitSession(out, "disc", parse_region(MITSUBA_REGION), model="colour")
        sessions.append(s)
        radiance.append(frame_values(out, s.obs.pixels, s.obs.frames))

    def error(theta, j):
        """Relative RMS error of the radiance predicted at camera j (against Mitsuba's)."""
        pred = sessions[j].wm.radiance(theta)
        ok = sessions[j].table.hit
        return float(rel_rms(pred[ok], radiance[j][ok]))

    rows = []
    for r in range(replicates):
        for j, s in enumerate(sessions):
            s.obs.recapture(radiance[j], np.random.default_rng([37, r, j]))
        fits = [s.run("global", seed=r, log=lambda *a: None) for s in sessions]
        # the best Ward fit: all cameras at once, from each camera's own global fit
        joint = Joint([s.problem for s in sessions])
        best = min((levenberg_marquardt(joint, np.array(list(f["parameters"].values())),
                                        sessions[0].lower, sessions[0].upper,
                                        max_iterations=200) for f in fits),
                   key=lambda f: f["chi2"])
        theta_own = np.array(list(fits[0]["parameters"].values()))
        held = [error(theta_own, j) for j in (1, 2)]
        floor = [error(np.asarray(best["theta"]), j) for j in (1, 2)]
        rows.append({"fit_camera_90": fits[0]["parameters"], "warnings": fits[0]["warnings"],
                     "chi2_per_dof": fits[0]["chi2_per_dof"],
                     "best_ward_all_cameras": dict(zip(sessions[0].names, best["theta"])),
                     "held_out_rel_rms": held, "best_ward_rel_rms": floor,
                     "ratio": [h / f for h, f in zip(held, floor)]})
    return {"case": name, "first": rows[0], "replicates": replicates,
            "held_out_rel_rms": np.mean([r["held_out_rel_rms"] for r in rows], 0).tolist(),
            "best_ward_rel_rms": np.mean([r["best_ward_rel_rms"] for r in rows], 0).tolist(),
            "ratio": np.mean([r["ratio"] for r in rows], 0).tolist(),
            "ratio_max": np.max([r["ratio"] for r in rows], 0).tolist()}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--replicates", type=int, default=20,
                    help="noise replicates of each Radiance case (default 20)")
    ap.add_argument("--mitsuba-replicates", type=int, default=3,
                    help="noise replicates of each Mitsuba case (default 3; about 2.5 min each)")
    ap.add_argument("--cases", help="comma-separated: r0..r5 (Radiance), m0..m2 (Mitsuba)")
    ap.add_argument("-o", "--output", default="skyfit-out/independent-set")
    args = ap.parse_args()
    from independent import radiance_runner

    root = Path(args.output)
    root.mkdir(parents=True, exist_ok=True)
    run = radiance_runner()
    chosen = args.cases.split(",") if args.cases else \
        [f"r{i}" for i in range(len(RADIANCE))] + [f"m{i}" for i in range(len(MITSUBA))]
    results = []
    for c in chosen:
        t0 = time.perf_counter()
        res = (radiance_case(RADIANCE[int(c[1:])], root, args.replicates, run) if c[0] == "r"
               else mitsuba_case(MITSUBA[int(c[1:])], root, args.mitsuba_replicates))
        res["time_s"] = time.perf_counter() - t0
        results.append(res)
        print(json.dumps(res, default=float), flush=True)
        (root / "independent_set.json").write_text(json.dumps(results, indent=1, default=float))
    print("\n| Radiance case | fit (replicate 0) | truth | in 95% or warned | coverage 95% "
          "(C_r, C_g, C_b, rho_s, sigma_alpha) | model/Radiance at truth |")
    for r in results:
        if "coverage95" in r:
            p = r["first"]["parameters"]
            print(f"| {r['case']} | " + ", ".join(f"{v:.3f}" for v in p.values()) + " | "
                  + ", ".join(f"{v:g}" for v in r["truth"].values())
                  + f" | {r['within_or_warned']:.2f} | "
                  + ", ".join(f"{v:.2f}" for v in r["coverage95"].values())
                  + f" | {r['model_over_radiance']:.4f} |")
    print("\n| Mitsuba material | held-out rel. RMS (az 45, 135) | best Ward (all cameras) | "
          "ratio (mean over replicates) | ratio (largest) |")
    for r in results:
        if "ratio" in r:
            print(f"| {r['case']} | " + ", ".join(f"{v:.2%}" for v in r["held_out_rel_rms"])
                  + " | " + ", ".join(f"{v:.2%}" for v in r["best_ward_rel_rms"]) + " | "
                  + ", ".join(f"{v:.2f}" for v in r["ratio"]) + " | "
                  + ", ".join(f"{v:.2f}" for v in r["ratio_max"]) + " |")


if __name__ == "__main__":
    main()
