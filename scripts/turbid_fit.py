"""A turbid spec one step off, fitted jointly: the turbidity with both light levels and the materials.

The sphere in tests/measured_light.py's paint is rendered under a turbid clear sky of Linke
turbidity ``--truth`` (``type = "turbid"``: Ineichen and Perez's levels, Preetham's pattern) and
fitted with a spec of ``--spec`` (its sun too: off by the haze's air-mass-dependent dimming),
once as the spec's sky is and once with ``fit --sky fit --sky-shape``, which moves the spec's
turbidity and with it the sun's and the sky's levels frame by frame.  One render per seed
(``--seeds``: each its own noise).  Prints, per seed, the fitted turbidity and sky level k with
their 95% intervals and each material parameter's status ('in', 'warned' or 'MISSED': confidently
wrong, tests/independent.py ``held_or_warned``); writes DIR/turbid_fit.json.

    .venv/bin/python scripts/turbid_fit.py [--truth 4.5] [--spec 3] [--seeds 11 12 13] [-o DIR]
"""
import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from sky_test_set import spec_turbid  # noqa: E402  (beside this script)

#: Frame hours (UTC, 40 N on 21 June): the sun 17-65 degrees from the zenith.
HOURS = tuple(range(8, 17))
NAMES = ("C_r", "C_g", "C_b", "rho_s", "sigma_alpha")


def run(out, truth_t, spec_t, seed):
    """Render the day of ``seed`` under turbidity ``truth_t`` into ``out`` and fit it with a
    spec of ``spec_t``, as the spec's sky is and jointly; returns the two fits' records."""
    from independent import held_or_warned
    from measured_light import MATERIAL, TRUTH, relabelled

    from skyfit_mi.fitting.fit import fit_regions
    from skyfit_mi.fitting.light import LightOptions
    from skyfit_mi.pipeline.pixels import material_regions
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import thesis_disc_spec, validate_spec

    raw = thesis_disc_spec("turbid-sphere", MATERIAL, size=16, noise_percent=2.0, spp=256,
                           seed=seed)
    raw["scene"], raw["materials"] = {"file": "sphere.xml"}, {"sphere": dict(MATERIAL)}
    raw["camera"].update({"distance": 6.0, "fov_deg": 22.0, "target": [0.0, 0.0, 1.0]})
    raw["time"] = {"date": raw["time"]["date"], "times": [f"{h:02d}:00" for h in HOURS]}
    raw["sky"] = {"type": "turbid", "turbidity": truth_t}
    render_sequence(validate_spec(raw, out), out / "truth", progress=False, overwrite=True,
                    log=lambda *a: None)
    day = relabelled(out / "truth", out / "spec", spec_turbid(spec_t))
    (_, pixels), = material_regions(day)
    pixels = pixels[pixels.sum(axis=1) % 2 == 0]
    records = {}
    for name, kw in (("spec", dict(light=LightOptions(sky="spec"))),
                     ("joint", dict(light=LightOptions(sky="fit", shape=True)))):
        t0 = time.perf_counter()
        r = next(fit_regions(day, [("sphere", pixels)], model="colour", log=lambda *a: None,
                             **kw))
        status = held_or_warned(NAMES, r["intervals"], r["warnings"], TRUTH)
        sky = r.get("sky") or {}
        records[name] = {"parameters": r["parameters"], "status": status,
                         "warnings": r["warnings"], "wall_s": time.perf_counter() - t0,
                         "k": sky.get("k"), "k_interval95": sky.get("interval95"),
                         "turbidity": ((sky.get("shape") or {}).get("index") or {}).get(
                             "turbidity")}
    return records


def main(argv=None):
    from skyfit_mi.files import ensure_dir, write_json
    from skyfit_mi.render import setup

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--truth", type=float, default=4.5, help="the day's Linke turbidity")
    ap.add_argument("--spec", type=float, default=3.0, help="the spec's Linke turbidity")
    ap.add_argument("--seeds", type=int, nargs="+", default=[11, 12, 13])
    ap.add_argument("-o", "--out", type=Path, default=Path("out/turbid_fit"))
    args = ap.parse_args(argv)
    setup()
    ensure_dir(args.out)
    results = {}
    for seed in args.seeds:
        results[seed] = r = run(args.out / f"seed{seed}", args.truth, args.spec, seed)
        j = r["joint"]
        t, half = j["turbidity"]
        print(f"seed {seed}: spec's sky as it is: "
              + ", ".join(f"{p} {r['spec']['parameters'][p]:.4g} ({s})"
                          for p, s in r["spec"]["status"].items())
              + f"; joint: T {t:.2f} +- {half:.2f} (truth {args.truth:g}), k {j['k']:.3f} "
              f"({j['k_interval95'][0]:.3f}-{j['k_interval95'][1]:.3f}), materials "
              + ", ".join(f"{p} {s}" for p, s in j["status"].items())
              + f" ({j['wall_s']:.0f} s)", flush=True)
    write_json(args.out / "turbid_fit.json", {"truth": args.truth, "spec": args.spec,
                                              "hours_utc": list(HOURS), "seeds": results})
    return 0


if __name__ == "__main__":
    sys.exit(main())
