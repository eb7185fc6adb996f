"""The ``skyfit`` command: thin argument parsing over the package."""

import argparse
import sys

from .errors import SetupError, SkyfitError


def _render(args):
    from .sequence import render_sequence
    from .spec import load_spec

    render_sequence(load_spec(args.spec), args.output, overwrite=args.overwrite,
                    progress=not args.quiet)


def _pixels(args):
    from .pixels import parse_pixel, write_pixels

    paths = write_pixels(args.manifest, [parse_pixel(p) for p in args.pixel], args.output,
                         args.source)
    print("wrote " + " and ".join(str(p) for p in paths))


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
    args = parser.parse_args(argv)
    try:
        args.func(args)
    except (SkyfitError, SetupError) as exc:
        print(f"skyfit: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
