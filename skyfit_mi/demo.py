"""The built-in example: a white disc through a clear summer day (thesis 6.2).

A horizontal Lambertian disc at 40 N 0 E on 21 June, seen by the thesis's
east camera (45 degrees from the normal), under the CIE clear sky and sun,
hourly 06:00-18:00 UTC.  Writes one linear EXR per frame, a contact sheet
PNG, and ``summary.json`` comparing the disc's rendered radiance with the
analytic (E_sky + E_sun)/pi of each frame.
"""

import json
import time
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np

from .colour import SRGB_LUMINANCE
from .sky import cie_sky
from .sun import day_of_year, solar_position


def disc_day(out_dir, hours=range(6, 19), latitude=40.0, longitude=0.0, date=(2026, 6, 21),
             width=96, height=96, spp=64, seed=0, variant="llvm_ad_rgb", log=print):
    """Render the example day into ``out_dir``; returns the summary dictionary."""
    from .render import setup
    from .render.image import contact_sheet, write_exr, write_png
    from .render.daylight import sky_dict, update_sky
    from .render.scene import camera_origin, disc_scene, perspective_sensor

    mi = setup(variant)
    out = Path(out_dir)
    times = [datetime(*date, tzinfo=timezone.utc) + timedelta(hours=h) for h in hours]
    pos = solar_position(times, latitude, longitude)
    skies = [cie_sky("clear", z, a, day=int(day_of_year(t)))
             for z, a, t in zip(pos.zenith_deg, pos.azimuth_deg, times)]
    sensor = perspective_sensor(camera_origin(90.0, 45.0, 4.0), fov_deg=40.0, width=width,
                                height=height, spp=spp)
    white = {"type": "diffuse", "reflectance": {"type": "rgb", "value": 1.0}}
    scene = mi.load_dict(disc_scene(sky_dict(skies[0]), white, sensor))
    params = mi.traverse(scene)
    frames, rows = [], []
    t0 = time.perf_counter()
    for i, (t, sky) in enumerate(zip(times, skies)):
        update_sky(params, sky, "sky.")
        img = np.array(mi.render(scene, params, seed=seed + i), dtype=np.float32)
        path = write_exr(out / "frames" / f"frame_{i:03d}.exr", img)
        centre = img[height // 3: 2 * height // 3, width // 3: 2 * width // 3].reshape(-1, 3)
        rendered = float(centre.mean(axis=0) @ SRGB_LUMINANCE)
        analytic = float(sky.horizontal_irradiance() @ SRGB_LUMINANCE / np.pi)
        rows.append({"frame": i, "file": str(path.relative_to(out)), "time": t.isoformat(),
                     "sun_zenith_deg": float(pos.zenith_deg[i]),
                     "sun_azimuth_deg": float(pos.azimuth_deg[i]),
                     "disc_radiance_W_m2_sr": rendered, "analytic_E_over_pi_W_m2_sr": analytic})
        frames.append(img)
        log(f"frame {i + 1}/{len(times)}  {t:%H:%M} UTC  sun zenith {pos.zenith_deg[i]:5.1f} deg  "
            f"disc {rendered:7.2f} (analytic {analytic:7.2f}) W m^-2 sr^-1")
    exposure = 0.18 / max(float(np.mean([f.mean() for f in frames])), 1e-12)
    write_png(out / "contact_sheet.png", contact_sheet(frames, exposure))
    summary = {"description": __doc__.strip().splitlines()[0], "units": "radiance W m^-2 sr^-1",
               "latitude_deg": latitude, "longitude_deg": longitude, "spp": spp, "seed": seed,
               "variant": variant, "width": width, "height": height,
               "wall_time_s": time.perf_counter() - t0, "frames": rows}
    tmp = out / ".summary.json.tmp"
    tmp.write_text(json.dumps(summary, indent=2))
    tmp.replace(out / "summary.json")
    log(f"wrote {len(frames)} EXR frames, contact_sheet.png and summary.json to {out.resolve()}")
    return summary
