"""Coverage of the 95% intervals and RMSE against the Cramer-Rao bound (issue: fitting).

For each case (the thesis's tables 7.2-like rough disc from the east, 7.7 and 7.10, and a
narrow lobe, sigma_alpha 0.02 at four times the sun's radius, not run by default) a
high-quality noise-free day is rendered once (16x16, 4096 spp, east camera at 45 degrees,
40 N, 21 June); then --replicates times the sensor draws new Gaussian noise (5% and 10% of
the dynamic range, seeded by replicate) from the same radiance, and the global method fits
the central 4x4 region.  Reports, per parameter, how often the 95% profile and covariance
intervals contain the truth, and the RMSE of the estimates over the replicates divided by
the Cramer-Rao bound sqrt(diag(F^-1)) at the truth, F the Fisher information of the
sensor's data (Gaussian noise, values clipped at both ends of the range).  --region fits
other pixels (e.g. rect:4,4,11,11, the central 8x8, all on the disc).

    .venv/bin/python scripts/coverage.py [--replicates 50] [--region rect:6,6,9,9]
"""

import argparse
import dataclasses
import datetime as dt
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: Case key: (label, model, truth).
CASES = {"7.2": ("rough disc (cf. 7.2)", "two", {"rho_s": 0.5, "sigma_alpha": 0.1}),
         "7.7": ("7.7", "achromatic", {"R": 0.33, "rho_s": 0.2, "sigma_alpha": 0.05}),
         "7.10": ("7.10", "colour", {"C": [0.25, 0.5, 0.75], "rho_s": 0.2, "sigma_alpha": 0.05}),
         "narrow": ("narrow lobe", "two", {"rho_s": 0.5, "sigma_alpha": 0.02})}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--replicates", type=int, default=50)
    ap.add_argument("--noise", default="5,10")
    ap.add_argument("--cases", default="7.2,7.7,7.10",
                    help=f"comma-separated case keys ({', '.join(CASES)})")
    ap.add_argument("--region", default="rect:6,6,9,9",
                    help="fitted pixels of the 16x16 frames (default: the central 4x4)")
    args = ap.parse_args()
    from reproduce_thesis import truth_vector

    from skyfit_testkit import cramer_rao
    from skyfit_mi.fitting.chi2 import parse_region
    from skyfit_mi.fitting.fit import FitCache, FitSession
    from skyfit_mi.pipeline.manifest import load_manifest, sensor_from_record
    from skyfit_mi.pipeline.pixels import frame_values
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import thesis_disc_spec, validate_spec

    region = parse_region(args.region)
    print(f"Command: `.venv/bin/python scripts/coverage.py {' '.join(sys.argv[1:])}`. "
          f"Date: {dt.date.today().isoformat()}.\n")
    print("| case | noise | parameter | truth | 95% profile coverage | 95% covariance coverage | "
          "RMSE / CRB | bias / CRB | SD / CRB | noise-free offset / CRB | median chi2/dof |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for i, key in enumerate(CASES):
            if key not in args.cases.split(","):
                continue
            label, model, truth = CASES[key]
            raw = thesis_disc_spec(label, {"model": model, **truth}, spp=4096, seed=7 + i)
            raw["sensor"]["bits"] = 8
            out = Path(tmp) / f"case{i}"
            render_sequence(validate_spec(raw, tmp), out, progress=False, log=lambda *a: None)
            doc, _ = load_manifest(out)
            session = FitSession(out, "disc", region, model=model, cache=FitCache(seed=i))
            obs = session.obs
            radiance = frame_values(out, obs.pixels, obs.frames)
            tv = truth_vector(model, truth)
            for noise in (float(v) for v in args.noise.split(",")):
                sensor = dataclasses.replace(sensor_from_record(doc["sensor"]),
                                             noise_percent=noise)
                obs.sensor = sensor
                # Cramer-Rao bound at the truth with this noise, for the data as the sensor
                # gives them: Gaussian, clipped at both ends of its range
                obs.sigma = np.full_like(obs.y, sensor.sigma)
                crb = cramer_rao.bound(cramer_rao.fisher_jacobian(session, tv, sensor.sigma))
                # the fit of the noise-free values: the offset every replicate shares
                obs.y = sensor.respond(radiance * obs.gain) * sensor.max_code
                offset = np.array(list(session.run("global", log=lambda *a: None)
                                       ["parameters"].values())) - tv
                est, cov_prof, cov_cov, chis = [], [], [], []
                t0 = time.perf_counter()
                for r in range(args.replicates):
                    obs.recapture(radiance, np.random.default_rng([i, int(noise), r]))
                    res = session.run("global", seed=r, log=lambda *a: None)
                    th = np.array(list(res["parameters"].values()))
                    est.append(th)
                    chis.append(res["chi2_per_dof"])
                    iv = res["intervals"]
                    cov_prof.append([iv[p]["95"][0] <= t <= iv[p]["95"][1]
                                     for p, t in zip(session.names, tv)])
                    lo = th - 1.96 * np.sqrt(np.clip(np.diag(res["covariance"]["matrix"]), 0, None))
                    hi = th + 1.96 * np.sqrt(np.clip(np.diag(res["covariance"]["matrix"]), 0, None))
                    cov_cov.append((lo <= tv) & (tv <= hi))
                est = np.array(est)
                rmse = np.sqrt(np.mean((est - tv) ** 2, axis=0))
                bias, sd = np.mean(est - tv, axis=0), np.std(est, axis=0)
                for k, p in enumerate(session.names):
                    print(f"| {label} | {noise:g}% | {p} | {tv[k]:g} | "
                          f"{np.mean([c[k] for c in cov_prof]):.2f} | "
                          f"{np.mean([c[k] for c in cov_cov]):.2f} | {rmse[k] / crb[k]:.2f} | "
                          f"{bias[k] / crb[k]:+.2f} | {sd[k] / crb[k]:.2f} | "
                          f"{offset[k] / crb[k]:+.2f} | {np.median(chis):.2f} |", flush=True)
                print(f"<!-- {label} {noise}%: {args.replicates} fits in "
                      f"{time.perf_counter() - t0:.0f} s -->", flush=True)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).parent))
    main()
