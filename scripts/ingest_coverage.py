"""Coverage of fits after `skyfit ingest` of JPEG photographs (issue 15).

The example board's day of tests/test_ingest.py (64x44, hourly) is rendered once, then
photographed with SEEDS noise seeds at each JPEG quality (skyfit_testkit.photo_sim:
auto-exposure, cos^4 vignetting, read and shot noise, sRGB), ingested with the grey card's
calibration and the noise estimated from the frames, and the sample fitted (64 pixels, colour
model).  Prints a markdown table: per quality, the share of (seed, parameter) pairs whose 95%
interval holds the truth, the median interval width per parameter, and the mean chi2/dof.
``--clean`` also renders the day again with SEEDS render seeds (the clean frames, with the
test's sensor noise or ``--clean-noise``: other Monte Carlo and sensor noise, no photographic
degradation), fits them the same way, and adds the row "clean" and each quality's median
widths over the clean ones' (the issue's 1.5x goal, judged on widths over noise seeds rather
than one realisation's, which follow where each fit lands on the rho_s - sigma_alpha ridge).

    .venv/bin/python scripts/ingest_coverage.py [--quality 100 95] [--seeds 8] [--scale 1]
        [--first-seed N] [--clean [--clean-noise PERCENT]] [--true-noise]
        [--sigma-floor-sensor] [--diagnose] [--refit] [-o DIR]
"""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TRUTH = {"C_r": 0.62, "C_g": 0.12, "C_b": 0.10, "rho_s": 0.05, "sigma_alpha": 0.08}


def true_noise(settings):
    """The simulator's own sensor noise (a :class:`PhotoSettings`' :meth:`noise`) as ingest's
    ``noise``: (read variance [DN^2], shot gain [DN])."""
    read, shot = settings.noise()
    return read ** 2, shot


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quality", type=int, nargs="+", default=[100, 95])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--first-seed", type=int, default=0,
                    help="photograph with seeds FIRST .. FIRST + SEEDS - 1 (to add seeds to a run)")
    ap.add_argument("--scale", type=int, default=1,
                    help="frame size as a multiple of the test's 64x44 (more pixels inside the "
                         "materials, away from the JPEG's edge blocks)")
    ap.add_argument("--clean", action="store_true",
                    help="also fit the clean frames rendered with SEEDS seeds (width ratios)")
    ap.add_argument("--clean-noise", type=float, default=None, metavar="PERCENT",
                    help="the clean frames' sensor noise [%% of full scale] (default the "
                         "test's)")
    ap.add_argument("--true-noise", action="store_true",
                    help="give ingest the simulator's own sensor noise (--noise) instead of "
                         "estimating it from the frames")
    ap.add_argument("--sigma-floor-sensor", action="store_true",
                    help="experiment: a JPEG pixel's sigma at least the sensor's noise formula "
                         "(ingest's floor is the noise the compressed frames show)")
    ap.add_argument("--diagnose", action="store_true",
                    help="per missed sequence: chi2 at the truth minus at the fit, and the z "
                         "of the values about the truth (rms, mean, per-frame pixel means)")
    ap.add_argument("--refit", action="store_true",
                    help="fit the sequences an earlier run ingested into -o DIR again, without "
                         "photographing and ingesting them anew (after a change in the fit)")
    ap.add_argument("-o", "--output", help="work folder (default a temporary one)")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "tests"))
    from test_ingest import _small_spec

    from skyfit_mi.fitting.chi2 import subsample_region
    from skyfit_mi.fitting.fit import fit_region
    from skyfit_mi.pipeline.ingest import ingest
    from skyfit_testkit.photo_sim import PhotoSettings, photograph_day
    from skyfit_mi.pipeline.pixels import material_regions
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import validate_spec

    quiet = {"log": lambda *a: None}
    if args.sigma_floor_sensor:
        import skyfit_mi.pipeline.ingest as ingest_module
        shown_floor = ingest_module.pixel_sigma

        def sensor_floor(values, sensor, noise, jpeg=None):
            return shown_floor(values, sensor, noise,
                               None if jpeg is None else dict(jpeg, shown=noise))
        ingest_module.pixel_sigma = sensor_floor
    work = Path(args.output or tempfile.mkdtemp(prefix="ingest_coverage_"))
    work.mkdir(parents=True, exist_ok=True)
    spec_path, raw = _small_spec(work, width=64 * args.scale, height=44 * args.scale)
    truth = work / "truth"
    if not (truth / "manifest.json").exists():
        render_sequence(validate_spec(raw, spec_path.parent), truth, progress=False, **quiet)
    pixels = subsample_region(dict(material_regions(truth))["sample"], 64, 0)
    print(f"frames {64 * args.scale}x{44 * args.scale}\n")
    print("| quality | seeds | coverage | median 95% width C_r / C_g / C_b / rho_s / sigma_alpha "
          "| mean chi2/dof |")
    print("|---|---|---|---|---|")

    def row(name, sequences):
        inside, widths, chi2 = [], [], []
        for seq in sequences:
            fit = fit_region(seq, "sample", pixels, model="colour", **quiet)
            missed = []
            for k, t in TRUTH.items():
                lo, hi = fit["intervals"][k]["95"]
                inside.append(lo <= t <= hi)
                if not inside[-1]:
                    missed.append(f"{k} {fit['parameters'][k]:.4g} [{lo:.4g}, {hi:.4g}]")
            if missed:
                print(f"<!-- {seq.name} misses: {'; '.join(missed)} -->", flush=True)
                if args.diagnose:
                    diagnose(seq, pixels, fit)
            widths.append([fit["intervals"][k]["95"][1] - fit["intervals"][k]["95"][0]
                           for k in TRUTH])
            chi2.append(fit["chi2_per_dof"])
        w = np.median(widths, axis=0)
        print(f"| {name} | {args.seeds} | {np.mean(inside):.2f} | "
              f"{' / '.join(f'{x:.3g}' for x in w)} | {np.mean(chi2):.2f} |", flush=True)
        return w

    medians = {}
    if args.clean:
        clean = []
        for seed in range(args.seeds):
            seq = work / f"clean_s{seed}" if args.clean_noise is None \
                else work / f"clean{args.clean_noise:g}_s{seed}"
            if not (seq / "manifest.json").exists():
                again = {**raw, "render": {**raw["render"], "seed": 100 + seed}}
                if args.clean_noise is not None:
                    again["sensor"] = {**raw["sensor"], "noise_percent": args.clean_noise}
                render_sequence(validate_spec(again, spec_path.parent), seq, progress=False,
                                **quiet)
            clean.append(seq)
        medians["clean"] = row("clean", clean)
    for q in args.quality:
        sequences = []
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            photos = work / f"q{q}_s{seed}"
            seq = work / f"seq_q{q}_s{seed}"
            if not (args.refit and (seq / "manifest.json").exists()):
                camera = PhotoSettings(quality=q)
                photograph_day(truth, photos, camera, seed=seed)
                ingest([photos], spec_path, seq, calibrate={"grey_card": (0.18,) * 3},
                       vignetting="cos4", overwrite=True, progress=False,
                       noise=true_noise(camera) if args.true_noise else None,
                       exact_curve=True, **quiet)       # the simulated camera's sRGB is exact
            sequences.append(seq)
        medians[q] = row(q, sequences)
    if args.clean:
        print("\n| quality | median width / the clean frames' C_r / C_g / C_b / rho_s / "
              "sigma_alpha |\n|---|---|")
        for q in args.quality:
            print(f"| {q} | {' / '.join(f'{x:.2f}' for x in medians[q] / medians['clean'])} |")


def diagnose(seq, pixels, fit):
    """chi2 at the truth minus at the fit (the fit's own problem), and the z of the values
    about the model at the truth: rms and mean per channel, and the rms of the per-frame
    means over pixels times sqrt(pixels) (1 for independent errors)."""
    from skyfit_mi.fitting.fit import FitSession

    s = FitSession(seq, "sample", pixels, model="colour")
    names = list(TRUTH)
    truth = np.array([TRUTH[k] for k in names])
    best = np.array([fit["parameters"][k] for k in names])
    excess = s.problem.chi2(truth) - s.problem.chi2(best)
    z = (s.obs.y - s.problem.predict(s.wm.radiance(truth))) / s.obs.sigma      # (P, T, 3)
    frame_means = np.sqrt(np.mean(np.mean(z, axis=0) ** 2, axis=0) * z.shape[0])
    print(f"<!-- {seq.name}: chi2(truth) - chi2(fit) = {excess:.1f}; z rms "
          f"{np.round(np.sqrt(np.mean(z ** 2, axis=(0, 1))), 2)}, mean "
          f"{np.round(np.mean(z, axis=(0, 1)), 2)}, frame means x sqrt(P) "
          f"{np.round(frame_means, 2)} -->", flush=True)


if __name__ == "__main__":
    main()
