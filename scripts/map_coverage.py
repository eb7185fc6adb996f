"""Coverage of a per-pixel map's 95% intervals on the sample board (issue 16).

The board of tests/test_pixel_map.py (eight known materials, 48x36, hourly, 1% noise) rendered
at each SPP, every sample pixel fitted on its own (`fit_pixels`) with the sky integrals
interpolated between anchors (SKY_SPACING 4) and with each pixel's own (1), for each of
SEEDS light-cache seeds: the determined pixels' count and the share of their (pixel,
parameter) pairs whose interval holds the truth. Prints a markdown table.

    .venv/bin/python scripts/map_coverage.py [--spp 32 512] [--seeds 4] [-o DIR]
"""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, nargs="+", default=[32, 512])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("-o", "--output", help="work folder (default a temporary one)")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "tests"))
    from test_pixel_map import MATERIALS, SPEC

    import skyfit_mi.fitting.pixel_fit as pf
    import skyfit_mi.render.light_cache as lc
    from skyfit_mi.pipeline.pixels import material_regions
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import read_spec, validate_spec

    work = Path(args.output or tempfile.mkdtemp(prefix="map_coverage_"))
    print("| spp | sky integrals | seed | determined pixels | coverage | per parameter |")
    print("|---|---|---|---|---|---|")
    for spp in args.spp:
        raw = read_spec(SPEC)
        raw["camera"].update(width=48, height=36)
        raw["time"].update(step_minutes=60)
        raw["render"] = {"spp": spp, "seed": 2}
        raw["materials"] = {k: {"model": "colour", "C": list(c), "rho_s": r, "sigma_alpha": a}
                            for k, (c, r, a) in MATERIALS.items()}
        day = work / f"day_{spp}"
        if not (day / "manifest.json").exists():
            render_sequence(validate_spec(raw, SPEC.parent), day, progress=False,
                            log=lambda *a: None)
        regions = material_regions(day)
        px = np.concatenate([p for _, p in regions])
        mats = np.concatenate([[n] * len(p) for n, p in regions])
        truth = np.array([[*MATERIALS[m][0], *MATERIALS[m][1:]] for m in mats])
        for spacing, what in ((4, "interpolated"), (1, "each pixel's own")):
            lc.SKY_PLANS["anchors"] = lc.SkyPlan("anchors", spacing=spacing)
            for seed in range(args.seeds):
                res = pf.fit_pixels(day, list(mats), px, seed=seed)
                ok = (res["warnings"] & pf.UNDETERMINED) == 0
                inside = (res["lo"][ok] <= truth[ok]) & (truth[ok] <= res["hi"][ok])
                print(f"| {spp} | {what} | {seed} | {ok.sum()} | {inside.mean():.3f} | "
                      f"{' '.join(f'{x:.2f}' for x in inside.mean(axis=0))} |", flush=True)


if __name__ == "__main__":
    main()
