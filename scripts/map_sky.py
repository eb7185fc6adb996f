"""Per-pixel maps of days under skies other than the spec's: the spec's sky taken as exact,
against the sky's level fitted first with the regions' materials (issue 36).

The board of tests/test_pixel_map.py (eight known materials, 48x36, hourly 12:00-18:00, 1%
noise) is rendered under each sky of SKIES; its manifest then names the spec's sky, the thesis's
CIE clear sky (tests/measured_light.py ``relabelled``), and calls the frames photographed, as a
user's photographs would be. Every sample pixel is fitted on its own (``fit_pixels``), lit by
the spec's sky and sun as they are (``--sky spec``), and by the spec's sky at the level its
regions' fit finds first (``pixel_map.first_fits``, the default ``--sky prior``: the level a
curve over the day, the sun's level a modelled one's, in the reflectances' intervals);
``--sun-sd 0`` takes the sun as exact there too (these days' sun is the spec's), so that the
reflectances' intervals show the sky's share alone. Prints a markdown table: per sky and
light, the fitted level (its day's mean), the determined pixels of those mapped, the share of
the mapped pixels' (pixel, parameter) pairs whose 95% interval holds the truth (the
reflectances', the roughness'), and the samples' median errors (of their mapped pixels'
medians: C relative, rho_s and sigma_alpha absolute).

    .venv/bin/python scripts/map_sky.py [-o DIR] [--sun-sd 0]
"""

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: Skies the board's day is rendered under: the spec's [sky], and a factor on its sky's level
#: (all but the sun) against the spec's.
SKIES = {"the spec's own (control)": ({"type": "clear"}, 1.0),
         "its sky 1.5 times the spec's": ({"type": "clear"}, 1.5),
         "CIE type 14 (turbid, broad corona)": ({"type": "cie_general", "cie_type": 14}, 1.0),
         "CIE groups 5.98/4 (fitted to the scans)": ({"type": "cie_general", "gradation": 5.98,
                                                     "indicatrix": 4}, 1.0)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--output", help="work folder (default a temporary one)")
    ap.add_argument("--sun-sd", type=float, default=None,
                    help="the sun level's sd (default: a modelled sun's, as fit's)")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "tests"))
    from measured_light import relabelled, thesis_clear
    from test_pixel_map import MATERIALS, SPEC

    from skyfit_mi.fitting.pixel_fit import UNDETERMINED, fit_pixels
    from skyfit_mi.fitting.light import LightOptions
    from skyfit_mi.fitting.pixel_map import first_fits
    from skyfit_mi.pipeline.pixels import material_regions
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import read_spec, validate_spec

    work = Path(args.output or tempfile.mkdtemp(prefix="map_sky_"))
    print("| sky the day was rendered under | map's light | k (95%) | determined pixels | "
          "held: reflectances / roughness | median error C / rho_s / sigma_alpha | time [s] |")
    print("|---|---|---|---|---|---|---|")
    for i, (name, (sky, factor)) in enumerate(SKIES.items()):
        raw = read_spec(SPEC)
        raw["camera"].update(width=48, height=36)
        raw["time"].update(step_minutes=60)
        raw["render"] = {"spp": 32, "seed": 2}
        raw["sky"] = sky
        raw["materials"] = {k: {"model": "colour", "C": list(c), "rho_s": r, "sigma_alpha": a}
                            for k, (c, r, a) in MATERIALS.items()}
        rendered = work / f"sky{i}" / "rendered"
        if not (rendered / "manifest.json").exists():
            render_sequence(validate_spec(raw, SPEC.parent), rendered, progress=False,
                            log=lambda *a: None)
        day = relabelled(rendered, work / f"sky{i}" / "day",
                         lambda f, s: thesis_clear(f, s).sky_scaled(1.0 / factor))
        doc = json.loads((day / "manifest.json").read_text())
        (day / "manifest.json").write_text(json.dumps({**doc, "source": "ingest"}))
        regions = material_regions(day)
        px = np.concatenate([p for _, p in regions])
        mats = np.concatenate([[n] * len(p) for n, p in regions])
        truth = np.array([[*MATERIALS[m][0], *MATERIALS[m][1:]] for m in mats])
        for label in ("spec", "prior"):
            t0 = time.perf_counter()
            light = None if label == "spec" else first_fits(
                day, regions, light=LightOptions(sky="prior", sun_sd=args.sun_sd),
                log=lambda *a: None)[1]
            res = fit_pixels(day, list(mats), px, light=light)
            mapped = np.isfinite(res["theta"][:, 0])
            determined = mapped & ((res["warnings"] & UNDETERMINED) == 0)
            inside = (res["lo"][mapped] <= truth[mapped]) & (truth[mapped] <= res["hi"][mapped])
            errors = []
            for m in MATERIALS:
                sel = mapped & (mats == m)
                if sel.any():
                    med = np.median(res["theta"][sel], axis=0)
                    errors.append([*np.abs(med[:3] / truth[sel][0, :3] - 1),
                                   *np.abs(med[3:] - truth[sel][0, 3:])])
            e = np.median(errors, axis=0)
            k = "-" if light is None else "{:.2f} ({})".format(light["sky"]["k"], "-".join(
                "open" if v is None else f"{v:.2f}" for v in light["sky"]["interval95"]))
            print(f"| {name} | {label} | {k} | {determined.sum()} of {mapped.sum()} | "
                  f"{inside[:, :4].mean():.2f} / {inside[:, 4].mean():.2f} | "
                  f"{100 * np.median(e[:3]):.1f}% / {e[3]:.3f} / {e[4]:.3f} | "
                  f"{time.perf_counter() - t0:.0f} |", flush=True)


if __name__ == "__main__":
    main()
