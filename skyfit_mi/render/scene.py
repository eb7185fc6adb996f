"""Mitsuba scene dictionaries in the project's world frame (+X east, +Y north, +Z up)."""

from contextlib import contextmanager

import numpy as np

from ..conventions import direction_from_angles
from ..errors import SkyfitError, check_range
from .daylight import jit_array


def load_xml(xml):
    """The Mitsuba scene (or object) of XML ``xml`` in the variant set up, every plugin kept
    apart: Mitsuba's default optimisation merges identical objects, so two materials of equal
    parameters (a photographed scene's placeholders, say) would share one BSDF and one id, and
    the label image would lose one of them."""
    import mitsuba as mi

    return mi.load_string(xml, optimize=False)


def camera_origin(azimuth_deg, angle_deg, distance, target=(0.0, 0.0, 0.0)):
    """Camera position at compass ``azimuth_deg`` from the target, ``angle_deg`` from the vertical
    (the thesis's east camera at 45 degrees: ``camera_origin(90, 45, d)``)."""
    check_range("camera angle from the normal", angle_deg, 0.0, 89.0, "degrees")
    check_range("camera distance", distance, 1e-6, np.inf)
    d = direction_from_angles(np.radians(angle_deg), np.radians(azimuth_deg))
    return np.asarray(target, dtype=float) + distance * d


#: The default up vector (+Z).  A view within ~2.6 degrees of it (|cos| > 0.999) uses north.
UP = (0.0, 0.0, 1.0)


def look_at(origin, target, up=None):
    """Camera to_world 4x4 as Mitsuba's look_at builds it (columns: left, up, forward, origin).

    With the default ``up`` a camera looking (nearly) straight up or down takes north (+Y) as
    up.  Raises SkyfitError for a camera at its target or an explicit ``up`` along the view.
    """
    o, t = np.asarray(origin, dtype=float), np.asarray(target, dtype=float)
    u = np.asarray(UP if up is None else up, dtype=float)
    if not (np.all(np.isfinite(o)) and np.all(np.isfinite(t)) and np.all(np.isfinite(u))):
        raise SkyfitError("the camera's origin, target and up must be finite numbers.")
    d = t - o
    if np.linalg.norm(d) <= 1e-9 * max(1.0, np.linalg.norm(o)):
        raise SkyfitError(f"the camera's origin {o.tolist()} is its target; place the camera away "
                          "from what it looks at.")
    d /= np.linalg.norm(d)
    if np.linalg.norm(u) == 0:
        raise SkyfitError("the camera's up vector is zero; give a direction such as [0, 0, 1].")
    if abs(np.dot(d, u / np.linalg.norm(u))) > 0.999:
        if up is not None:
            raise SkyfitError(f"the camera's up {list(up)} lies along its view direction "
                              f"{np.round(d, 3).tolist()}; give an up across the view.")
        u = np.array([0.0, 1.0, 0.0])
    left = np.cross(u, d)
    left /= np.linalg.norm(left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, np.cross(d, left), d, o
    return m


def camera_matrix(cam):
    """The camera's to_world 4x4 from a [camera] table (compass placement, origin + target
    (+ up), or matrix); raises SkyfitError for a degenerate one."""
    if "matrix" in cam:
        m = np.asarray(cam["matrix"], dtype=float)
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise SkyfitError("the camera matrix must be 4 rows of 4 finite numbers (to_world).")
        if abs(np.linalg.det(m[:3, :3])) < 1e-9 or not np.allclose(m[3], [0, 0, 0, 1]):
            raise SkyfitError("the camera matrix is not a camera placement: its 3x3 part is "
                              "singular or its last row is not [0, 0, 0, 1].")
        return m
    target = cam.get("target", (0.0, 0.0, 0.0))
    origin = cam.get("origin")
    if origin is None:
        origin = camera_origin(cam["azimuth_deg"], cam["angle_deg"], cam["distance"], target)
    return look_at(origin, target, cam.get("up"))


#: The pose's angles whose uncertainty a fit propagates (``[camera] pose_sd_deg``): compass
#: azimuth, angle from the vertical and roll (:func:`turn_camera`).
POSE_ANGLES = ("azimuth", "angle", "roll")
#: The largest pose sd taken [deg]: beyond it a linearised shift means little.
POSE_SD_MAX = 10.0


def pose_sd(value):
    """{azimuth, angle, roll}: the pose's 1-sd [deg] from ``value``: one number (azimuth and
    angle; roll 0), a table of some of POSE_ANGLES (the rest 0) or None; each in
    [0, POSE_SD_MAX], else SkyfitError."""
    if value is None:
        value = 0.0
    if not isinstance(value, dict):
        value = {"azimuth": value, "angle": value}
    wrong = sorted(set(value) - set(POSE_ANGLES))
    if wrong:
        raise SkyfitError(f"pose_sd_deg has no angle {wrong[0]!r}; give one number (azimuth and "
                          "angle from the vertical, each 1 sd [deg]) or a table of azimuth, "
                          "angle, roll.")
    out = {}
    for k in POSE_ANGLES:
        v = value.get(k, 0.0)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
            raise SkyfitError(f"pose_sd_deg {k} must be a number of degrees, got {v!r}.")
        out[k] = float(check_range(f"pose_sd_deg {k}", v, 0.0, POSE_SD_MAX, "deg"))
    return out


def turn_camera(to_world, pivot, angle, deg):
    """The camera ``to_world`` (4x4) turned by ``deg`` [deg] about ``pivot`` (3,) [m] in one of
    POSE_ANGLES: ``azimuth`` clockwise seen from above, ``angle`` about the horizontal axis
    across the view (away from the vertical), ``roll`` about the view axis."""
    m = np.asarray(to_world, dtype=float)
    forward = m[:3, 2]
    axis = {"azimuth": np.array([0.0, 0.0, -1.0]), "roll": forward,
            "angle": np.cross(forward, [0.0, 0.0, 1.0])}[angle]
    if np.linalg.norm(axis) < 1e-9:
        raise SkyfitError("the camera looks straight up or down, so its angle from the "
                          "vertical has no axis to turn about; give pose_sd_deg as a table "
                          "without angle.")
    from scipy.spatial.transform import Rotation

    R = Rotation.from_rotvec(np.radians(deg) * axis / np.linalg.norm(axis)).as_matrix()
    p = np.asarray(pivot, dtype=float)
    out = m.copy()
    out[:3, :3] = R @ m[:3, :3]
    out[:3, 3] = p + R @ (m[:3, 3] - p)
    return out


@contextmanager
def camera_at(scene, to_world):
    """Within the block, the scene's first sensor placed at ``to_world`` (4x4), then restored."""
    import mitsuba as mi

    sensor = mi.traverse(scene.sensors()[0])
    nominal = sensor["to_world"]
    sensor["to_world"] = mi.ScalarTransform4f(np.asarray(to_world, dtype=float))
    sensor.update()
    try:
        yield scene
    finally:
        sensor["to_world"] = nominal
        sensor.update()


def view_centre(scene):
    """Where the central ray of the scene's first sensor meets the scene [m] (3,): the pivot
    its pose turns about (:func:`turn_camera`).  Raises SkyfitError where it meets nothing."""
    sensor = scene.sensors()[0]
    w, h = sensor.film().crop_size()
    si = scene.ray_intersect(pixel_rays(sensor, [w / 2, h / 2]))
    if not bool(si.is_valid()[0]):
        raise SkyfitError("the camera's central ray meets nothing in the scene, so there is "
                          "no target for its pose's uncertainty to turn it about; aim the "
                          "camera at the scene or give no pose_sd_deg.")
    return np.array(si.p, dtype=float).ravel()


def perspective_sensor(origin, target=(0.0, 0.0, 0.0), fov_deg=30.0, width=256, height=256, spp=64,
                       up=None):
    """A perspective camera with a box-filtered HDR film and an independent sampler."""
    import mitsuba as mi

    return {"type": "perspective", "fov": float(fov_deg), "fov_axis": "x",
            "to_world": mi.ScalarTransform4f(look_at(origin, target, up)),
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


def pixel_views(scene, pixels, m=8):
    """World unit directions toward the camera from an m x m grid of positions in each of
    ``pixels`` ((P, 2) x, y) of the scene's first sensor: (P, m*m, 3)."""
    g = (np.arange(m) + 0.5) / m
    u = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    ray = pixel_rays(scene.sensors()[0], np.asarray(pixels)[:, None, :] + u[None])
    return -np.array(ray.d, dtype=float).T.reshape(len(pixels), m * m, 3)


def pixel_rays(sensor, xy):
    """The rays of ``sensor`` through film positions ``xy`` (..., 2) [pixels] (x, y; pixel
    (i, j)'s centre at (i + 0.5, j + 0.5)), one Dr.Jit Ray3f."""
    import mitsuba as mi

    w, h = sensor.film().crop_size()
    pos = np.asarray(xy, dtype=float).reshape(-1, 2) / [w, h]
    ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5),
                               jit_array(mi.Point2f, pos[:, 0], pos[:, 1]), mi.Point2f(0.5, 0.5))
    return ray


def shape_index(si, shapes):
    """Index into ``shapes`` of the shape each interaction of ``si`` lies on, -1 elsewhere."""
    import drjit as dr
    import mitsuba as mi

    out = np.full(dr.width(si), -1)
    valid = np.array(si.is_valid())
    for j, shape in enumerate(shapes):
        out[np.array(si.shape == mi.ShapePtr(shape)) & valid] = j
    return out
