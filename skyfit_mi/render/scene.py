"""Mitsuba scene dictionaries in the project's world frame (+X east, +Y north, +Z up)."""

import numpy as np

from ..conventions import direction_from_angles
from ..errors import check_range


def camera_origin(azimuth_deg, angle_deg, distance, target=(0.0, 0.0, 0.0)):
    """Camera position at compass ``azimuth_deg`` from the target, ``angle_deg`` from the vertical.

    E.g. the thesis's east camera at 45 degrees: ``camera_origin(90, 45, d)``.
    """
    check_range("camera angle from the normal", angle_deg, 0.0, 89.0, "degrees")
    check_range("camera distance", distance, 1e-6, np.inf)
    d = direction_from_angles(np.radians(angle_deg), np.radians(azimuth_deg))
    return np.asarray(target, dtype=float) + distance * d


def perspective_sensor(origin, target=(0.0, 0.0, 0.0), fov_deg=30.0, width=256, height=256, spp=64,
                       up=(0.0, 0.0, 1.0)):
    """A perspective camera with a box-filtered HDR film and an independent sampler."""
    import mitsuba as mi

    origin = [float(v) for v in origin]
    if abs(np.dot(np.subtract(target, origin) / np.linalg.norm(np.subtract(target, origin)), up)) > 0.999:
        up = (0.0, 1.0, 0.0)          # looking straight down: north is up in the image
    return {"type": "perspective", "fov": float(fov_deg),
            "to_world": mi.ScalarTransform4f().look_at(origin=origin, target=[float(v) for v in target],
                                                       up=[float(v) for v in up]),
            "film": {"type": "hdrfilm", "width": int(width), "height": int(height),
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": int(spp)}}


def disc_scene(emitter, bsdf, sensor, radius=1.0, integrator=None):
    """A horizontal disc of ``radius`` at the origin, facing up, under ``emitter``."""
    import mitsuba as mi

    return {"type": "scene",
            "integrator": integrator or {"type": "path", "max_depth": 4},
            "sky": emitter,
            "disc": {"type": "disk", "to_world": mi.ScalarTransform4f().scale(float(radius)),
                     "bsdf": bsdf},
            "sensor": sensor}
