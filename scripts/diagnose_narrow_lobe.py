"""Diagnostic: which of the light cache and the rendered frames is right for a narrow lobe.

The thesis disc (two parameters, rho_s --rho-s, sigma_alpha --sigma, noise-free, 12-bit) seen
from the east at 45 degrees, 40 N, 21 June, hourly 06:00-18:00, 16x16 frames at --spp.  For the
central 4x4 pixels and every frame it compares three estimates of the radiance at the truth:

- the frames (Mitsuba's path tracer, the cie_sky emitter's sampling and the ward plugin's);
- the light cache the fit uses (``FitSession``, --positions x --directions, --cache-seed);
- a deterministic quadrature in NumPy (``reflection.reflected_radiance``: the Ward BRDF of
  ``ward.py`` times ``Sky.radiance``) averaged over an 8x8 grid of positions in the pixel.

It prints, per frame, the region's mean of each estimate and the frames' and the cache's
differences from the quadrature, in per cent and in units of each one's standard error (the
frames': the manifest's sigma, quantisation included, through the sensor's slope; the cache's:
the spread of its positions), then the global fit with its 95% interval and chi-square at the
fit and at the truth.

    .venv/bin/python scripts/diagnose_narrow_lobe.py [--sigma 0.01] [--spp 1024] [--out DIR]
"""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sigma", type=float, default=0.01)
    ap.add_argument("--rho-s", type=float, default=1.0)
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--render-seed", type=int, default=0)
    ap.add_argument("--cache-seed", type=int, default=0)
    ap.add_argument("--positions", type=int, default=32)
    ap.add_argument("--directions", type=int, default=128)
    ap.add_argument("--out", help="render folder (kept; resumed); default: a temporary one")
    args = ap.parse_args()
    from skyfit_mi.fitting.chi2 import parse_region
    from skyfit_mi.fitting.fit import FitCache, FitSession
    from skyfit_mi.physics.colour import SRGB_LUMINANCE
    from skyfit_mi.physics.reflection import reflected_radiance
    from skyfit_mi.render.fit_model import reflectances
    from skyfit_mi.render.scene import pixel_views
    from skyfit_mi.pipeline.manifest import load_manifest
    from skyfit_mi.pipeline.pixels import frame_values
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import thesis_disc_spec, validate_spec

    print(f"Command: `.venv/bin/python scripts/diagnose_narrow_lobe.py {' '.join(sys.argv[1:])}`\n")
    truth = np.array([args.rho_s, args.sigma])
    raw = thesis_disc_spec("narrow-lobe", {"model": "two", "rho_s": args.rho_s,
                                           "sigma_alpha": args.sigma},
                           spp=args.spp, seed=args.render_seed)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.out or Path(tmp) / "seq")
        render_sequence(validate_spec(raw, tmp), out, progress=False, log=lambda *a: None)
        doc, _ = load_manifest(out)
        s = FitSession(out, "disc", parse_region("rect:6,6,9,9"), model="two",
                       cache=FitCache(args.positions, args.directions, args.cache_seed))
        px = s.obs.pixels
        frames = [f for f in doc["frames"] if f["index"] in s.obs.frames]
        rendered = frame_values(out, px, s.obs.frames)
        # the frames' standard error in radiance: the DN sigma (quantisation and the render's
        # own error) through the sensor's slope
        sd = frame_values(out, px, s.obs.frames, "sigma") / s.problem.slope(rendered)
        cache, cache_var = s.wm.radiance_and_variance(truth)
        rho_d, rho_s = reflectances("two", truth)[:2]
        views = pixel_views(s.scene, px)
        quad = np.stack([reflected_radiance(sky, views, rho_d, rho_s, args.sigma).mean(axis=1)
                         for sky in s.skies], axis=1)
        print("| frame | quadrature | frames | frames - quad [%] | (frames - quad) / sd | "
              "cache | cache - quad [%] | (cache - quad) / cache sd |")
        print("|---|---|---|---|---|---|---|---|")
        lum = SRGB_LUMINANCE
        for t, f in enumerate(frames):
            q, r, c = (a[:, t] @ lum for a in (quad, rendered, cache))
            r_sd = np.sqrt(np.sum((sd[:, t] @ lum) ** 2))   # of the region's sum
            c_sd = np.sqrt(np.sum(cache_var[:, t] @ lum**2))
            dq = np.sum(q)
            print(f"| {f['time'][11:16]} | {q.mean():.4g} | {r.mean():.4g} | "
                  f"{100 * (r.sum() - dq) / dq:+.2f} | {(r.sum() - dq) / r_sd:+.1f} | "
                  f"{c.mean():.4g} | {100 * (c.sum() - dq) / dq:+.2f} | "
                  f"{(c.sum() - dq) / c_sd:+.1f} |")
        res = s.run("global", seed=0, log=lambda *a: None)
        fit = [res["parameters"][k] for k in ("rho_s", "sigma_alpha")]
        lo, hi = res["intervals"]["sigma_alpha"]["95"]
        print(f"\nglobal fit: rho_s {fit[0]:.4f}, sigma_alpha {fit[1]:.4f}, 95% ({lo:.4f}, "
              f"{hi:.4f}); chi2(fit) {s.problem.chi2(fit):.1f}, chi2(truth) "
              f"{s.problem.chi2(truth):.1f}")


if __name__ == "__main__":
    main()
