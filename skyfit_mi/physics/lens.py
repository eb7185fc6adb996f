"""The camera's lens geometry: a pinhole with a horizontal field of view, and radial distortion.

The pinhole (Hartley and Zisserman 2004, sec. 6.1) has square pixels and its principal point at
the image's centre: a point (X, Y, Z) [m] in the camera's OpenCV frame (x right, y down, z along
the view) falls on pixel

    u = f x_d + (W - 1) / 2,   v = f y_d + (H - 1) / 2,

pixel (0, 0) being the top-left pixel's centre (as OpenCV and Mitsuba), f = (W / 2) /
tan(fov / 2) [px], with Brown's (1966) radial distortion as OpenCV and Zhang (2000) write it on
x = X / Z, y = Y / Z:

    (x_d, y_d) = (x, y) (1 + k1 r^2 + k2 r^4),   r^2 = x^2 + y^2.

Barrel distortion has k1 < 0.  The renderer is a pinhole; a photograph is undistorted
(:func:`skyfit_mi.pipeline.registration.undistort_image`) before comparison.

References: D. C. Brown, "Decentering distortion of lenses", Photogrammetric Engineering 32(3),
444-462, 1966; Z. Zhang, "A flexible new technique for camera calibration", IEEE TPAMI 22(11),
1330-1334, 2000, doi:10.1109/34.888718; R. Hartley and A. Zisserman, "Multiple View Geometry in
Computer Vision", 2nd ed., Cambridge University Press, 2004.
"""

import numpy as np

from ..errors import SkyfitError


#: The horizontal fields of view a camera may have [degrees] (the spec's [camera] fov_deg).
FOV_RANGE = (0.1, 170.0)


def focal_px(fov_deg, width):
    """Focal length [px] of a horizontal field of view ``fov_deg`` [degrees] over ``width`` [px]."""
    return width / 2.0 / np.tan(np.radians(fov_deg) / 2.0)


def fov_deg(focal, width):
    """Horizontal field of view [degrees] of focal length ``focal`` [px] over ``width`` [px]."""
    return float(np.degrees(2.0 * np.arctan(width / 2.0 / focal)))


def intrinsics(focal, width, height):
    """The 3x3 camera matrix K [px] of focal length ``focal`` [px], principal point at the
    centre of a ``width`` x ``height`` image."""
    return np.array([[focal, 0.0, (width - 1) / 2.0], [0.0, focal, (height - 1) / 2.0],
                     [0.0, 0.0, 1.0]])


def check_distortion(k, fov, width, height):
    """Refuse radial distortion ``k`` = [k1] or [k1, k2] that folds the image over itself (the
    distorted radius must grow up to the image's corner at ``fov`` [degrees], ``width`` x
    ``height`` [px], or no undistortion exists).  Returns [k1, k2].
    """
    k1, k2 = (list(k) + [0.0])[:2]
    corner = np.hypot(width, height) / 2.0 / focal_px(fov, width)    # normalised radius
    r = np.linspace(0.0, 10.0 * corner, 20001)
    rd = r * (1.0 + k1 * r ** 2 + k2 * r ** 4)
    slope = 1.0 + 3.0 * k1 * r ** 2 + 5.0 * k2 * r ** 4
    reach = np.nonzero(rd >= corner)[0]
    end = reach[0] if len(reach) else len(r)
    if np.any(slope[:end + 1] <= 0.0) or not len(reach):
        raise SkyfitError(f"distortion = [{k1:g}, {k2:g}] folds the image before its corner "
                          f"(fov {fov:g} deg, {width}x{height} px): the distorted radius stops "
                          "growing; check the values and their signs (OpenCV's convention, "
                          "barrel k1 < 0).")
    return [float(k1), float(k2)]


def distort(x, y, k):
    """Normalised pinhole ``x``, ``y`` moved by the radial distortion ``k`` = [k1] or [k1, k2]
    (Brown 1966, OpenCV's convention): (x, y) (1 + k1 r^2 + k2 r^4)."""
    k1, k2 = (list(k) + [0.0, 0.0])[:2]
    r2 = x * x + y * y
    f = 1.0 + k1 * r2 + k2 * r2 * r2
    return x * f, y * f


def undistort(xd, yd, k, iterations=20):
    """The inverse of :func:`distort`, by Newton's method on the radius (monotonic for a ``k``
    :func:`check_distortion` accepts; 20 steps reach float64 rounding for usual lenses)."""
    k1, k2 = (list(k) + [0.0, 0.0])[:2]
    rd = np.hypot(xd, yd)
    r = rd.copy()
    for _ in range(iterations):
        r = r - (r * (1 + k1 * r ** 2 + k2 * r ** 4) - rd) / (1 + 3 * k1 * r ** 2 + 5 * k2 * r ** 4)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(rd > 0, r / rd, 1.0)
    return xd * s, yd * s
