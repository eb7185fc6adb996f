"""Coverage of C on saturated and pale colours after `skyfit ingest` of JPEGs or camera RAWs.

A board of five samples (saturated red, green, blue and yellow paint, a pale blue paper; all
rho_s 0.05, sigma_alpha 0.08) beside a grey card (written into the work folder) is rendered
once, hourly over a clear day, then photographed (skyfit_testkit.photo_sim) with SEEDS
noise seeds at each JPEG quality with the chroma subsampling asked (default 4:2:0), or as PNG
(``--quality 0``: lossless), or with ``--format dng`` as camera RAWs (a Bayer mosaic in the
camera's RGB, demosaiced by LibRaw on ingest) at each ``--matrix-error`` (the DNG colour
matrix's relative error), ingested with the grey card's calibration and the noise estimated
from the frames, and every sample fitted (64 pixels each, colour model).  Prints a markdown
table per quality (or matrix error): per material the share of seeds whose 95% interval holds
the truth, for C_r, C_g, C_b, rho_s and sigma_alpha, and the median relative 95% half-width
of C; and the share of C's intervals holding the truth without the JPEG's shared rounding error
(``jpeg_shared_error_sd`` of the fit taken out of each half-width in quadrature);
``--diagnose`` adds, per quality and channel, the z of the region means per frame
((ingested - true radiance) / sigma, averaged over the region's pixels) times sqrt(pixels): 1
for independent errors, more where the pixels share their errors; and over the board's pixels
the relative error of the ingested radiance by distance to another material, the rms of the
per-pixel z, its correlation between neighbouring pixels and between channels.

    .venv/bin/python scripts/jpeg_colour_coverage.py [--quality 85 90 95] [--seeds 4]
        [--subsampling 2] [--format dng --matrix-error 0 0.03 [--colour-matrix-error SD]]
        [--diagnose] [-o DIR]
"""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = {"red": (0.70, 0.08, 0.05), "green": (0.10, 0.45, 0.12), "blue": (0.08, 0.15, 0.60),
           "yellow": (0.85, 0.70, 0.08), "pale_blue": (0.55, 0.68, 0.85)}
RHO_S, SIGMA_ALPHA = 0.05, 0.08
TRUTH_SPP = 1024
NAMES = ("C_r", "C_g", "C_b", "rho_s", "sigma_alpha")


def scene_xml():
    """The board: the grey card and SAMPLES in a 2 x 3 grid of 0.4 m squares, 0.1 m apart."""
    cells = [(-0.5, 0.25), (0.0, 0.25), (0.5, 0.25), (-0.5, -0.25), (0.0, -0.25), (0.5, -0.25)]
    parts = ['<scene version="3.0.0">',
             '<bsdf type="ward" id="grey_card"><string name="model" value="raw"/>'
             '<rgb name="rho_d" value="0.18, 0.18, 0.18"/><rgb name="rho_s" value="0, 0, 0"/>'
             '<float name="sigma_alpha" value="0.1"/></bsdf>']
    for name, c in SAMPLES.items():
        parts.append(f'<bsdf type="ward" id="{name}"><string name="model" value="colour"/>'
                     f'<rgb name="C" value="{c[0]}, {c[1]}, {c[2]}"/>'
                     f'<float name="rho_s" value="{RHO_S}"/>'
                     f'<float name="sigma_alpha" value="{SIGMA_ALPHA}"/></bsdf>')
    for (x, y), name in zip(cells, ["grey_card", *SAMPLES]):
        parts.append(f'<shape type="rectangle" id="{name}_shape"><transform name="to_world">'
                     f'<scale value="0.2"/><translate x="{x}" y="{y}" z="0.001"/></transform>'
                     f'<ref id="{name}"/></shape>')
    parts.append('<shape type="rectangle" id="board"><transform name="to_world">'
                 '<scale x="0.8" y="0.55" z="1"/></transform>'
                 '<bsdf type="diffuse"><rgb name="reflectance" value="0.05"/></bsdf></shape>')
    return "\n".join(parts + ["</scene>"])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quality", type=int, nargs="+", default=[85, 90, 95],
                    help="JPEG qualities (0: PNG, lossless)")
    ap.add_argument("--subsampling", type=int, default=2, choices=(0, 1, 2),
                    help="chroma: 0 4:4:4, 1 4:2:2, 2 4:2:0 (default)")
    ap.add_argument("--format", choices=("jpeg", "dng"), default="jpeg",
                    help="dng: camera RAWs at each --matrix-error instead of JPEG qualities")
    ap.add_argument("--matrix-error", type=float, nargs="+", default=[0.0, 0.03],
                    help="the DNG colour matrix's relative errors (--format dng)")
    ap.add_argument("--colour-matrix-error", type=float,
                    help="the colour matrix's prior error ingest gives the fits (default: "
                    "ingest's, 0.03 for RAWs)")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--diagnose", action="store_true")
    ap.add_argument("--refit", action="store_true",
                    help="fit the sequences an earlier run ingested into -o DIR again")
    ap.add_argument("-o", "--output", help="work folder (default a temporary one)")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "tests"))
    from test_ingest import _small_spec

    from skyfit_mi.fitting.chi2 import subsample_region
    from skyfit_mi.fitting.fit import fit_regions
    from skyfit_mi.pipeline.ingest import ingest
    from skyfit_testkit.photo_sim import PhotoSettings, photograph_day
    from skyfit_mi.pipeline.pixels import material_regions
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import validate_spec

    quiet = {"log": lambda *a: None}
    work = Path(args.output or tempfile.mkdtemp(prefix="jpeg_colour_"))
    work.mkdir(parents=True, exist_ok=True)
    (work / "colour_board.xml").write_text(scene_xml())
    spec_path, raw = _small_spec(work, width=128, height=88)
    raw["scene"] = {**raw["scene"], "file": "colour_board.xml"}
    # the scene photographed, with little Monte Carlo error of its own: the fit's model at the
    # truth meets a 64-pixel region's mean per frame within 0.06% at 1024 spp (0.26% at the
    # tests' 128), so that the photographs carry the camera's errors
    raw["render"] = {**raw["render"], "spp": TRUTH_SPP}
    from test_ingest import _toml
    spec_path.write_text(_toml(raw))
    truth = work / "truth"
    if not (truth / "manifest.json").exists():
        render_sequence(validate_spec(raw, spec_path.parent), truth, progress=False, **quiet)
    regions = [(k, subsample_region(v, 64, 0)) for k, v in material_regions(truth)
               if k in SAMPLES]
    raw = args.format == "dng"
    print(("camera RAW (DNG)" if raw else f"subsampling {args.subsampling}")
          + f"; {args.seeds} seeds\n")
    print(f"| {'matrix error' if raw else 'quality'} | material | coverage C_r / C_g / C_b / "
          "rho_s / sigma_alpha | median C 95% half-width [%] | median C error [%] |")
    print("|---|---|---|---|---|")
    for q in (args.matrix_error if raw else args.quality):
        label = f"{q:g}" if raw else (q or "png")
        inside = {k: [] for k, _ in regions}
        half = {k: [] for k, _ in regions}
        err = {k: [] for k, _ in regions}
        zs, without, pix = [], [], []
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            tag = (f"dng_m{q:g}_p{args.colour_matrix_error}_s{seed}" if raw
                   else f"q{q}_c{args.subsampling}_s{seed}")
            photos, seq = work / f"photos_{tag}", work / f"seq_{tag}"
            if not (args.refit and (seq / "manifest.json").exists()):
                if raw:
                    photograph_day(truth, photos, PhotoSettings(fmt="dng", matrix_error=q),
                                   seed=seed)
                else:
                    photograph_day(truth, photos, PhotoSettings(
                        quality=q, fmt="jpeg" if q else "png", subsampling=args.subsampling),
                        seed=seed)
                ingest([photos], spec_path, seq, calibrate={"grey_card": (0.18,) * 3},
                       vignetting="cos4", colour_matrix_error=args.colour_matrix_error,
                       exact_curve=args.format != "dng",   # the simulated JPEGs' sRGB is exact
                       overwrite=True, progress=False, **quiet)
            for fit in fit_regions(seq, regions, model="colour", **quiet):
                name = fit["region"]
                truth_v = (*SAMPLES[name], RHO_S, SIGMA_ALPHA)
                ok, h, e = [], [], []
                for k, t in zip(NAMES, truth_v):
                    lo, hi = fit["intervals"][k]["95"]
                    ok.append(lo <= t <= hi)
                    if k.startswith("C_"):
                        h.append(50 * (hi - lo) / t)
                        sd = 1.96 * fit.get("jpeg_shared_error_sd", {}).get(k, 0.0)
                        v = fit["parameters"][k]
                        without.append(v - np.sqrt(max((v - lo) ** 2 - sd ** 2, 0.0)) <= t
                                       <= v + np.sqrt(max((hi - v) ** 2 - sd ** 2, 0.0)))
                        e.append(100 * (fit["parameters"][k] / t - 1))
                inside[name].append(ok)
                half[name].append(h)
                err[name].append(e)
                if not all(ok):
                    print(f"<!-- {tag} {name} misses: " + "; ".join(
                        f"{k} {fit['parameters'][k]:.4g} {fit['intervals'][k]['95']}"
                        for k, o in zip(NAMES, ok) if not o) + " -->", flush=True)
            if args.diagnose:
                zs.append(region_z(seq, truth, regions))
                pix.append(pixel_errors(seq, truth))
        for name in inside:
            cov = np.mean(inside[name], axis=0)
            print(f"| {label} | {name} | {' / '.join(f'{c:.2f}' for c in cov)} | "
                  f"{' / '.join(f'{x:.2f}' for x in np.median(half[name], axis=0))} | "
                  f"{' / '.join(f'{x:+.2f}' for x in np.median(err[name], axis=0))} |",
                  flush=True)
        allc = np.concatenate([np.asarray(v)[:, :3].ravel() for v in inside.values()])
        print(f"| {label} | all C | {np.mean(allc):.2f} (without the shared rounding "
              f"error {np.mean(without):.2f}) | | |", flush=True)
        if zs:
            z = np.sqrt(np.mean(np.concatenate(zs, axis=1) ** 2, axis=1))     # (regions, 3)
            for (name, _), zz in zip(regions, z):
                print(f"<!-- {label} {name}: region-mean z x sqrt(P) per channel "
                      f"{np.round(zz, 2)} -->", flush=True)
            report_pixels(label, pix)


def region_z(seq, truth, regions):
    """Per region, frame and channel the mean over the region's pixels of (ingested - true
    radiance) / sigma, times sqrt(pixels): (regions, frames, 3)."""
    from skyfit_mi.pipeline.manifest import load_manifest, read_frame_image, rendered_frames

    doc, root = load_manifest(seq)
    tdoc, troot = load_manifest(truth)
    shape = (doc["camera"]["height"], doc["camera"]["width"], 3)
    tframes = {f["time"]: f for f in rendered_frames(tdoc)}
    out = []
    for _, px in regions:
        rows = []
        for f in rendered_frames(doc):
            got = read_frame_image(root, f, "radiance", shape)[px[:, 1], px[:, 0]]
            sd = read_frame_image(root, f, "radiance_sigma", shape)[px[:, 1], px[:, 0]]
            t = read_frame_image(troot, tframes[f["time"]], "radiance", shape)[px[:, 1], px[:, 0]]
            rows.append(np.mean((got - t) / sd, axis=0) * np.sqrt(len(px)))
        out.append(rows)
    return np.asarray(out)


#: Distances [px] to another material at which pixel_errors takes the bias; from the last on
#: a pixel is inside, where it takes the noise's statistics.
DISTANCES = range(1, 9)


def pixel_errors(seq, truth):
    """Over the board's sample pixels and every frame: per material and distance to another
    material (DISTANCES; chessboard) the mean relative error of the ingested radiance per
    channel (materials, distances, 3); inside, the per-pixel z = (ingested - truth) / sigma as
    (pixels, frames, 3) with each pixel's right and lower neighbours' (for correlations)."""
    from scipy.ndimage import distance_transform_cdt

    from skyfit_mi.pipeline.manifest import load_manifest, read_frame_image, rendered_frames
    from skyfit_mi.pipeline.pixels import scene_labels

    doc, root = load_manifest(seq)
    tdoc, troot = load_manifest(truth)
    _, _, labels, ids = scene_labels(truth)
    shape = labels.shape + (3,)
    dist = np.zeros(labels.shape, int)
    for k in range(1, len(ids) + 1):
        inside = labels == k
        dist[inside] = distance_transform_cdt(inside, "chessboard")[inside]
    tframes = {f["time"]: f for f in rendered_frames(tdoc)}
    names = [n for n in SAMPLES if n in ids]
    bias = np.zeros((len(names), len(DISTANCES), 3))
    z, zx, zy = [], [], []
    frames = rendered_frames(doc)
    for f in frames:
        got = read_frame_image(root, f, "radiance", shape)
        sd = read_frame_image(root, f, "radiance_sigma", shape)
        t = read_frame_image(troot, tframes[f["time"]], "radiance", shape)
        rel = got / np.where(t > 0, t, np.nan) - 1.0
        zz = (got - t) / sd
        for m, name in enumerate(names):
            mat = labels == ids.index(name) + 1
            for j, d in enumerate(DISTANCES):
                sel = mat & (dist == d)
                bias[m, j] += np.nanmean(rel[sel], axis=0) / len(frames)
            core = mat & (dist >= DISTANCES[-1])
            ys, xs = np.nonzero(core[:-1, :-1])
            z.append(zz[ys, xs])
            zx.append(zz[ys, xs + 1])
            zy.append(zz[ys + 1, xs])
    return bias, np.concatenate(z), np.concatenate(zx), np.concatenate(zy)


def report_pixels(label, pix):
    """Print :func:`pixel_errors` over the seeds as comments."""
    bias = np.mean([p[0] for p in pix], axis=0)
    for m, name in enumerate(n for n in SAMPLES):
        print(f"<!-- {label} {name}: relative error [%] by distance to another material "
              + "; ".join(f"{d}px {np.round(100 * b, 1).tolist()}"
                          for d, b in zip(DISTANCES, bias[m])) + " -->")
    z, zx, zy = (np.concatenate([p[k] for p in pix]) for k in (1, 2, 3))
    ok = np.all(np.isfinite(z) & np.isfinite(zx) & np.isfinite(zy), axis=1)
    z, zx, zy = z[ok], zx[ok], zy[ok]
    corr = [np.corrcoef(z[:, c], z[:, (c + 1) % 3])[0, 1] for c in range(3)]
    right = [np.corrcoef(z[:, c], zx[:, c])[0, 1] for c in range(3)]
    lower = [np.corrcoef(z[:, c], zy[:, c])[0, 1] for c in range(3)]
    print(f"<!-- {label} inside (>= {DISTANCES[-1]} px from an edge, {len(z)} values): rms z "
          f"{np.round(np.sqrt(np.mean(z ** 2, axis=0)), 2).tolist()}, mean z "
          f"{np.round(np.mean(z, axis=0), 2).tolist()}; correlation with the right neighbour "
          f"{np.round(right, 2).tolist()}, the lower {np.round(lower, 2).tolist()}"
          f"; between channels RG/GB/BR {np.round(corr, 2).tolist()} -->", flush=True)


if __name__ == "__main__":
    main()
