"""Diagnostic: which of the light cache and the rendered frames is right for a narrow lobe.

The thesis disc (two parameters, rho_s --rho-s, sigma_alpha --sigma, noise-free, 12-bit) seen
from the east at 45 degrees, 40 N, 21 June, hourly 06:00-18:00, 16x16 frames at --spp.  For the
central 4x4 pixels and every frame it compares three estimates of the radiance at the truth:

- the frames (Mitsuba's path tracer, the cie_sky emitter's sampling and the ward plugin's);
- the light cache the fit uses (``FitSession``, --positions x --directions, --cache-seed);
- a deterministic quadrature in NumPy (``ward.ward_brdf`` times ``Sky.radiance``): Gauss-Legendre
  over the solar disc, over a cap around each position's mirror direction for the lobe, and over
  the hemisphere for the diffuse part, averaged over an 8x8 grid of positions in the pixel.

It prints, per frame, the region's mean of each estimate and the cache's and the frames'
differences from the quadrature (in per cent, and for the frames in units of their own Monte
Carlo standard error), then the global fit with its 95% interval and chi-square at the fit and
at the truth.

    .venv/bin/python scripts/diagnose_narrow_lobe.py [--sigma 0.01] [--spp 1024] [--out DIR]
"""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np


def _gauss(n, a, b):
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (b - a) * x + 0.5 * (b + a), 0.5 * (b - a) * w


def _basis(axis):
    """Two unit vectors orthogonal to ``axis`` and to each other."""
    a = np.asarray(axis, float)
    t = np.array([1.0, 0, 0]) if abs(a[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(a, t)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(a, e1)


def _cap(axis, radius, n_r=48, n_phi=96):
    """Directions and solid-angle weights of a Gauss-Legendre x uniform grid over the cap of
    angular ``radius`` [rad] around ``axis``: (n, 3), (n,)."""
    th, wt = _gauss(n_r, 0.0, radius)
    ph = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    e1, e2 = _basis(axis)
    T, F = np.meshgrid(th, ph, indexing="ij")
    d = (np.cos(T)[..., None] * axis + np.sin(T)[..., None]
         * (np.cos(F)[..., None] * e1 + np.sin(F)[..., None] * e2))
    w = (wt[:, None] * np.sin(T) * (2 * np.pi / n_phi))
    return d.reshape(-1, 3), w.ravel()


def _hemisphere(n_t=96, n_phi=192):
    """Directions and weights over the upper hemisphere (Gauss-Legendre in cos theta)."""
    c, wc = _gauss(n_t, 0.0, 1.0)
    ph = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    C, F = np.meshgrid(c, ph, indexing="ij")
    s = np.sqrt(1 - C**2)
    d = np.stack([s * np.cos(F), s * np.sin(F), C], axis=-1)
    return d.reshape(-1, 3), np.repeat(wc, n_phi) * (2 * np.pi / n_phi)


def quadrature_radiance(sky, wo, rho_d, rho_s, sigma):
    """Radiance [W m^-2 sr^-1] (3,) leaving a horizontal Ward surface toward world ``wo``
    under ``sky``, by quadrature (sun disc, lobe cap, diffuse hemisphere)."""
    from skyfit_mi.ward import specular_lobe

    wo = np.asarray(wo, float)
    out = np.zeros(3)
    # sun: the whole BRDF over the disc
    alpha = np.arccos(1 - sky.sun_chord2 / 2)
    d, w = _cap(sky.sun_direction, alpha)
    f = rho_d / np.pi + rho_s * specular_lobe(d, wo, sigma)[:, None]
    out += np.sum((f * np.clip(d[:, 2], 0, None)[:, None] * w[:, None]), axis=0) * sky.sun_radiance
    # sky, diffuse part
    d, w = _hemisphere()
    out += rho_d / np.pi * np.sum(sky.sky_radiance(d) * (d[:, 2] * w)[:, None], axis=0)
    # sky, lobe: a cap around the mirror direction holding all but e^-100 of the lobe
    r = np.array([-wo[0], -wo[1], wo[2]])
    d, w = _cap(r, min(np.pi, 20 * sigma), n_r=96, n_phi=128)
    lobe = specular_lobe(d, wo, sigma) * np.clip(d[:, 2], 0, None)
    out += rho_s * np.sum(sky.sky_radiance(d) * (lobe * w)[:, None], axis=0)
    return out


def pixel_views(scene, pixels, m=8):
    """World view directions (toward the camera) of an m x m grid of positions in each pixel
    on the horizontal plane z = 0: (P, m*m, 3)."""
    import mitsuba as mi

    sensor = scene.sensors()[0]
    w, h = sensor.film().crop_size()
    g = (np.arange(m) + 0.5) / m
    u = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    pos = (np.asarray(pixels)[:, None, :] + u[None]).reshape(-1, 2) / [w, h]
    ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5), mi.Point2f(pos[:, 0], pos[:, 1]),
                               mi.Point2f(0.5, 0.5))
    d = np.array(ray.d, dtype=float).T
    return (-d).reshape(len(pixels), m * m, 3)


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
    from skyfit_mi.chi2 import parse_region
    from skyfit_mi.fit import FitSession
    from skyfit_mi.render.fit_model import material_dict
    from skyfit_mi.render.image import read_exr
    from skyfit_mi.sequence import load_manifest, render_sequence
    from skyfit_mi.spec import thesis_disc_spec, validate_spec
    from skyfit_mi.ward import raw_parameters

    print(f"Command: `.venv/bin/python scripts/diagnose_narrow_lobe.py {' '.join(sys.argv[1:])}`\n")
    truth = np.array([args.rho_s, args.sigma])
    raw = thesis_disc_spec("narrow-lobe", {"model": "two", "rho_s": args.rho_s,
                                           "sigma_alpha": args.sigma},
                           spp=args.spp, seed=args.render_seed)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.out or Path(tmp) / "seq")
        render_sequence(validate_spec(raw, tmp), out, progress=False, log=lambda *a: None)
        doc, root = load_manifest(out)
        s = FitSession(out, "disc", parse_region("rect:6,6,9,9"), model="two",
                       seed=args.cache_seed, positions=args.positions, directions=args.directions)
        px = s.obs.pixels
        frames = [f for f in doc["frames"] if f["index"] in s.obs.frames]
        rendered = np.stack([read_exr(root / f["radiance"])[px[:, 1], px[:, 0]] for f in frames], 1)
        sd = np.stack([read_exr(root / f["sigma"])[px[:, 1], px[:, 0]] for f in frames], 1) \
            / (s.obs.gain[:, None, None] * s.obs.sensor.exposure)
        cache, cache_var = s.wm.radiance_and_variance(truth)
        rho_d, rho_s, _ = raw_parameters(**{k: v for k, v in material_dict("two", truth).items()
                                            if k != "normalisation"})
        views = pixel_views(s.scene, px)
        quad = np.array([[np.mean([quadrature_radiance(sky, wo, rho_d, rho_s, args.sigma)
                                   for wo in views[p]], axis=0) for sky in s.skies]
                         for p in range(len(px))])
        print("| frame | quadrature | frames | frames - quad [%] | (frames - quad) / sd | "
              "cache | cache - quad [%] | (cache - quad) / cache sd |")
        print("|---|---|---|---|---|---|---|---|")
        lum = np.array([0.2126, 0.7152, 0.0722])
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
