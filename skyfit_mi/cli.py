"""The ``skyfit`` command: thin argument parsing over the package."""

import argparse
import sys

from .errors import SetupError, SkyfitError
from .render.light_cache import DIRECTIONS, POSITIONS


def _render(args):
    from .pipeline.sequence import render_sequence
    from .pipeline.spec import load_spec

    render_sequence(load_spec(args.spec), args.output, overwrite=args.overwrite,
                    progress=not args.quiet)


def _pixels(args):
    from .pipeline.pixels import parse_pixel, write_pixels

    paths = write_pixels(args.manifest, [parse_pixel(p) for p in args.pixel], args.output,
                         args.source)
    print("wrote " + " and ".join(str(p) for p in paths))


def _fit(args):
    from pathlib import Path

    from .fitting.chi2 import parse_region, region_from_mask, subsample_region
    from .fitting.fit import fit_region
    from .fitting.report import write_fit, write_summary

    regions = []
    for r in args.region or []:
        name, sep, text = r.partition("=")
        if not sep:
            raise SkyfitError(f"--region {r!r}: write NAME=rect:x0,y0,x1,y1 or NAME=pixels:x,y;x,y.")
        regions.append((name, parse_region(text)))
    for lab in args.label or []:
        name, sep, value = lab.partition("=")
        if not sep or args.mask is None:
            raise SkyfitError("--label NAME=VALUE needs --mask PNG (a label image of the frames' size).")
        regions.append((name, region_from_mask(args.mask, int(value))))
    if args.all:
        regions += _material_regions(args.manifest)
    if not regions:
        raise SkyfitError("give at least one --region NAME=rect:... (or --mask and --label, or --all).")
    start = [float(v) for v in args.start.split(",")] if args.start else None
    root = Path(args.manifest)
    root = root if root.is_dir() else root.parent
    out = Path(args.output) if args.output else root
    results = []
    for name, pixels in regions:
        kept = subsample_region(pixels, args.max_pixels or None, args.seed)
        if len(kept) < len(pixels):
            print(f"{name}: fitting {len(kept)} of its {len(pixels)} pixels (--max-pixels, seed "
                  f"{args.seed})")
        res = fit_region(args.manifest, name, kept, model=int(args.model), method=args.method,
                         normalisation=args.normalisation, seed=args.seed, start=start,
                         positions=args.positions, directions=args.directions)
        res["region_pixels_total"] = int(len(pixels))
        paths = write_fit(res, out / f"fit_{name}")
        results.append(res)
        print("wrote " + " and ".join(str(p) for p in paths))
    print(f"wrote {write_summary(results, out / 'fits.csv')}")


def _material_regions(manifest):
    """(name, pixels) of every material the camera sees, from the scene's label image: the
    pixels inside each material's area (edge pixels, which also see a neighbour, left out)."""
    import numpy as np
    from scipy.ndimage import binary_erosion

    doc, _, labels, ids = _scene_labels(manifest)
    ward = set(doc["scene"]["materials"])
    regions = []
    for k, name in enumerate(ids):
        ys, xs = np.nonzero(binary_erosion(labels == k + 1, border_value=1))
        if name in ward and len(xs):
            regions.append((name, np.stack([xs, ys], axis=1)))
    return regions


def _scene_labels(manifest):
    """(manifest document, its folder, label image, material ids) of a rendered sequence."""
    from .render import setup
    from .render.labels import label_image
    from .pipeline.manifest import load_manifest

    doc, root = load_manifest(manifest)
    mi = setup(doc["render"]["variant"])
    return (doc, root, *label_image(mi.load_string(doc["scene"]["xml"])))


def _labels(args):
    from pathlib import Path

    import numpy as np

    from .files import write_json
    from .render.image import write_png

    _, root, labels, ids = _scene_labels(args.manifest)
    out = Path(args.output) if args.output else root / "labels.png"
    write_png(out, np.repeat(labels[..., None], 3, axis=2).astype(np.uint8))
    legend = {name: k + 1 for k, name in enumerate(ids)}
    write_json(out.with_suffix(".json"), {"labels": legend, "0": "no material"})
    print(f"wrote {out} (pixel value = material label) and {out.with_suffix('.json')}: "
          + ", ".join(f"{k}={v}" for k, v in legend.items()))


def main(argv=None):
    parser = argparse.ArgumentParser(prog="skyfit", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    render = sub.add_parser("render", help="render the day a sequence spec describes")
    render.add_argument("spec", help="sequence spec (.toml or .json), e.g. scenes/specs/disc_clear_east.toml")
    render.add_argument("-o", "--output", required=True, help="output folder")
    render.add_argument("--overwrite", action="store_true",
                        help="replace another run's output in the folder")
    render.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    render.set_defaults(func=_render)

    pixels = sub.add_parser("pixels", help="values of chosen pixels across a rendered sequence")
    pixels.add_argument("manifest", help="folder written by `skyfit render` (or its manifest.json)")
    pixels.add_argument("--pixel", action="append", required=True, metavar="X,Y",
                        help="pixel column,row from the top left; repeat for more pixels")
    pixels.add_argument("--source", choices=("radiance", "sensor"), default="radiance",
                        help="linear radiance frames or the sensor model's pixel values")
    pixels.add_argument("-o", "--output", help="output path prefix (default: MANIFEST/pixels_SOURCE)")
    pixels.set_defaults(func=_pixels)

    labels = sub.add_parser("labels", help="label-mask PNG of the materials each pixel sees")
    labels.add_argument("manifest", help="folder written by `skyfit render` (or its manifest.json)")
    labels.add_argument("-o", "--output", help="PNG path (default: MANIFEST/labels.png)")
    labels.set_defaults(func=_labels)

    fit = sub.add_parser("fit", help="fit Ward parameters to material regions of a sequence")
    fit.add_argument("manifest", help="folder written by `skyfit render` (or its manifest.json)")
    fit.add_argument("--region", action="append", metavar="NAME=rect:x0,y0,x1,y1",
                     help="a material region (NAME = the material id); also NAME=pixels:x,y;x,y")
    fit.add_argument("--mask", help="label-mask PNG (values per material), with --label")
    fit.add_argument("--label", action="append", metavar="NAME=VALUE",
                     help="the mask value of material NAME")
    fit.add_argument("--all", action="store_true",
                     help="fit every Ward material the camera sees (regions from the label image)")
    fit.add_argument("--max-pixels", type=int, default=64,
                     help="fit at most this many pixels of a region, a seeded random subset "
                     "(default 64; 0 = every pixel)")
    fit.add_argument("--model", choices=("2", "3", "5"), default="2",
                     help="2: rho_s, sigma_alpha; 3: R, rho_s, sigma_alpha; 5: C, rho_s, sigma_alpha")
    fit.add_argument("--method", choices=("global", "lm", "anneal", "adam"), default="global")
    fit.add_argument("--normalisation", choices=("ward", "duer", "balanced"), default="ward")
    fit.add_argument("--start", help="starting parameters, comma-separated (lm, anneal, adam)")
    fit.add_argument("--seed", type=int, default=0, help="seed of the light cache and random starts")
    fit.add_argument("--positions", type=int, default=POSITIONS, help="light-cache positions per pixel")
    fit.add_argument("--directions", type=int, default=DIRECTIONS, help="light-cache directions per position")
    fit.add_argument("-o", "--output", help="output folder (default: the manifest's folder)")
    fit.set_defaults(func=_fit)
    args = parser.parse_args(argv)
    try:
        args.func(args)
    except (SkyfitError, SetupError) as exc:
        print(f"skyfit: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
