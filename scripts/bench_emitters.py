"""Benchmark: cie_sky vs Mitsuba's built-in sunsky on a horizontal disc (issue: the plugins).

A white Lambertian disc seen by the thesis's east camera (45 degrees), 256x256,
64 spp, under a clear sky with sun (40 N 0 E, 21 June 10:00 UTC); sunsky gets
the same sun direction, and the cie_sky emitter also renders a Perez all-weather sky of
that sun (DHI 100, DNI 800 W m^-2; issue 15: "an emitter as fast as cie_sky").  For each: median wall time per 64-spp frame
(renders alternate between the two emitters, after a warm-up), and the
relative RMSE (RMSE / mean of the reference) against the emitter's own
4096-spp reference.  Prints a markdown table.

    .venv/bin/python scripts/bench_emitters.py [--repeats 7] [--ref-spp 4096]
"""

import argparse
import time
from datetime import datetime, timezone

import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--resolution", type=int, default=256)
    args = ap.parse_args()

    from skyfit_mi.render import setup
    from skyfit_mi.render.daylight import sky_dict
    from skyfit_mi.render.scene import camera_origin, disc_scene, perspective_sensor
    from skyfit_mi.physics.sky import cie_sky
    from skyfit_mi.physics.sun import solar_position

    mi = setup()
    import drjit as dr

    t = datetime(2026, 6, 21, 10, tzinfo=timezone.utc)
    pos = solar_position(t, 40.0, 0.0)
    sky = cie_sky("clear", pos.zenith_deg, pos.azimuth_deg, day=172)
    from skyfit_mi.physics.perez import perez_sky

    perez = perez_sky(pos.zenith_deg, pos.azimuth_deg, 172, dhi=100.0, dni=800.0).to_sky()
    emitters = {
        "cie_sky": sky_dict(sky),
        "cie_sky (Perez)": sky_dict(perez),
        "sunsky": {"type": "sunsky", "sun_direction": mi.ScalarVector3f(*map(float, pos.direction()))},
    }
    white = {"type": "diffuse", "reflectance": {"type": "rgb", "value": 1.0}}
    res = args.resolution

    def scene(em, spp):
        sensor = perspective_sensor(camera_origin(90.0, 45.0, 4.0), fov_deg=40.0, width=res,
                                    height=res, spp=spp)
        return mi.load_dict(disc_scene(em, white, sensor))

    def render(sc, seed):
        img = mi.render(sc, seed=seed)
        dr.eval(img)
        return np.array(img, dtype=np.float64)

    scenes = {k: scene(e, args.spp) for k, e in emitters.items()}
    for sc in scenes.values():
        render(sc, 0)                                   # compile
    times = {k: [] for k in scenes}
    for r in range(args.repeats):
        for k, sc in scenes.items():
            t0 = time.perf_counter()
            render(sc, 100 + r)
            times[k].append(time.perf_counter() - t0)

    rows = []
    for k, em in emitters.items():
        chunk = min(args.ref_spp, 256)
        ref_scene = scene(em, chunk)
        ref = np.mean([render(ref_scene, 1000 + i) for i in range(args.ref_spp // chunk)], axis=0)
        errs = [np.sqrt(np.mean((render(scenes[k], 200 + i) - ref) ** 2)) / ref.mean()
                for i in range(3)]
        rows.append((k, float(np.median(times[k])), float(np.mean(errs)), float(ref.mean())))
    base = dict((r[0], r) for r in rows)["sunsky"]
    print("| emitter | time per frame [s] | time / sunsky | relative RMSE | RMSE / sunsky's | "
          "reference mean [W m^-2 sr^-1] |")
    print("|---|---|---|---|---|---|")
    for k, tm, e, m in rows:
        print(f"| {k} | {tm:.3f} | {tm / base[1]:.2f} | {e:.4f} | {e / base[2]:.2f} | {m:.1f} |")
    print(f"\n{res}x{res}, {args.spp} spp, path tracer (max depth 4), median of {args.repeats} "
          f"alternating renders; references {args.ref_spp} spp; RMSE averaged over 3 seeds; "
          f"sun zenith {float(pos.zenith_deg):.1f} deg, azimuth {float(pos.azimuth_deg):.1f} deg.")


if __name__ == "__main__":
    main()
