"""The ``skyfit`` command: thin argument parsing over the package."""

import argparse
import sys

from .errors import SetupError, SkyfitError


def _demo(args):
    from .demo import disc_day

    disc_day(args.output, spp=args.spp, width=args.resolution, height=args.resolution,
             seed=args.seed, variant=args.variant)


def main(argv=None):
    parser = argparse.ArgumentParser(prog="skyfit", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="render the built-in example: a white disc through a clear day")
    demo.add_argument("-o", "--output", default="skyfit-demo", help="output folder")
    demo.add_argument("--spp", type=int, default=64, help="samples per pixel")
    demo.add_argument("--resolution", type=int, default=96, help="image width and height [pixels]")
    demo.add_argument("--seed", type=int, default=0, help="random seed of the first frame")
    demo.add_argument("--variant", default="llvm_ad_rgb", help="llvm_ad_rgb (CPU) or cuda_ad_rgb")
    demo.set_defaults(func=_demo)
    args = parser.parse_args(argv)
    try:
        args.func(args)
    except (SkyfitError, SetupError) as exc:
        print(f"skyfit: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
