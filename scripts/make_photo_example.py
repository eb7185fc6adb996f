"""The example photographs of scenes/specs/photo_board.toml: render the day (the truth), then
photograph it as a camera would (8-bit sRGB JPEG, auto-exposure in EXIF, cos^4 vignetting,
read and shot noise; skyfit_testkit.photo_sim), for `skyfit ingest` to turn into a fit.

    .venv/bin/python scripts/make_photo_example.py -o out/photo_example
"""
import argparse
from pathlib import Path

from skyfit_testkit.photo_sim import PhotoSettings, photograph_day
from skyfit_mi.pipeline.sequence import render_sequence
from skyfit_mi.pipeline.spec import SCENES_DIR, load_spec


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-o", "--output", required=True, help="folder: truth/ and photos/ inside")
    ap.add_argument("--quality", type=int, default=95, help="JPEG quality (default 95)")
    ap.add_argument("--seed", type=int, default=0, help="noise seed (recorded in photos.json)")
    args = ap.parse_args()
    out = Path(args.output)
    render_sequence(load_spec(SCENES_DIR / "specs" / "photo_board.toml"), out / "truth")
    paths = photograph_day(out / "truth", out / "photos", PhotoSettings(quality=args.quality),
                           seed=args.seed)
    print(f"wrote {len(paths)} photographs and photos.json in {out / 'photos'}")


if __name__ == "__main__":
    main()
