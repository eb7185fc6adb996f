"""HDR environment maps as sky light: a tabulated radiance on a latitude-longitude grid.

A measured sky enters a :class:`~skyfit_mi.physics.sky.Sky` as the term ``Sky.envmap``: a
world-frame table of linear-sRGB radiance [W m^-2 sr^-1] over the sphere (layout and lookup:
:mod:`~skyfit_mi.physics.latlong`).  This module converts captured maps into it and makes the
map a Sky's light (:func:`envmap_sky`).

Captured maps:

* ``latlong``: an equirectangular image in the table's layout (top row at the zenith, left
  edge at the map's azimuth origin, azimuth increasing to the right).
* ``fisheye``: an equidistant ("angular") fisheye of the upper hemisphere, as Radiance's
  ``rpict -vta -vd 0 0 1 -vu 0 1 0`` and all-sky cameras: the centred circle of radius
  R = min(rows, columns)/2 holds the hemisphere, zenith angle theta at r = R theta/(pi/2); the
  image's top is the azimuth origin, azimuth counter-clockwise (the sky seen from below).  Its
  table's lower half is zero (the ``ground`` term lights it).
* ``north_rotation_deg``: compass azimuth of the map's azimuth origin [degrees].
* ``scale``: multiplies the map's values into W m^-2 sr^-1 (a photograph's calibration).

A photographed sun is almost always clipped, so :func:`envmap_sky` takes the sun separately
(position from time and site, measured DNI) and can fill the map's cells near it from the
ring around them.
"""

from dataclasses import dataclass

import numpy as np

from ..conventions import direction_from_angles
from ..errors import SkyfitError, check_choice, check_range
from .colour import SRGB_LUMINANCE
from .latlong import MAX_ROWS, latlong_centres, latlong_lookup, resample
from .sun import SUN_SOLID_ANGLE

#: The map projections :func:`envmap_sky` reads.
PROJECTIONS = ("latlong", "fisheye")
#: Sub-samples per cell side at most when a map is averaged onto the table.
MAX_SUPERSAMPLE = 8
#: Largest sun zenith [degrees] at which :func:`direct_normal_from_global` is used: nearer the
#: horizon 1 / cos theta_s magnifies the pyranometer's error beyond use.
MAX_ZENITH_FROM_GLOBAL_DEG = 89.0


def fisheye_lookup(image, theta, phi):
    """Radiance (..., 3) of an equidistant fisheye ``image`` (N, M, 3) at zenith ``theta`` and
    map azimuth ``phi`` [rad], bilinear between pixel centres (clamped at the edges); 0 below
    the horizon."""
    img = np.asarray(image)
    N, M = img.shape[:2]
    R = min(N, M) / 2.0
    theta, phi = np.broadcast_arrays(np.asarray(theta, dtype=float), np.asarray(phi, dtype=float))
    r = R * theta / (np.pi / 2)
    # image x to the right, y down; the map's azimuth origin up, azimuth counter-clockwise
    x = M / 2.0 - r * np.sin(phi) - 0.5
    y = N / 2.0 - r * np.cos(phi) - 0.5
    x, y = np.clip(x, 0.0, M - 1.0), np.clip(y, 0.0, N - 1.0)
    c0, r0 = np.floor(x).astype(int), np.floor(y).astype(int)
    c1, r1 = np.minimum(c0 + 1, M - 1), np.minimum(r0 + 1, N - 1)
    fx, fy = (x - c0)[..., None], (y - r0)[..., None]
    v = ((1 - fy) * ((1 - fx) * img[r0, c0] + fx * img[r0, c1])
         + fy * ((1 - fx) * img[r1, c0] + fx * img[r1, c1]))
    return np.where((theta <= np.pi / 2)[..., None], v, 0.0)


def valid_pixels(image):
    """``image`` with NaN, infinite and negative values set to 0, and their count (per
    channel)."""
    img = np.asarray(image, dtype=np.float32)
    bad = ~np.isfinite(img) | (img < 0)
    return np.where(bad, np.float32(0.0), img), int(bad.sum())


def mask_sun(table, sun_direction, radius_deg):
    """``table`` with the cells within ``radius_deg`` [degrees] of the world unit
    ``sun_direction`` filled with the per-channel median of the ring out to twice that (0 if
    empty), and the count filled: a clipped sun and its flare become the sky around it, the
    sun's light then coming from the solar disc."""
    t = np.array(table, dtype=np.float32)
    theta, phi = latlong_centres(*t.shape[:2])
    d = direction_from_angles(theta[:, None], phi[None, :])
    angle = np.degrees(np.arccos(np.clip(d @ np.asarray(sun_direction, dtype=float), -1, 1)))
    inner = angle <= radius_deg
    ring = (angle > radius_deg) & (angle <= 2 * radius_deg)
    fill = np.median(t[ring], axis=0) if ring.any() else np.zeros(3, np.float32)
    t[inner] = fill
    return t, int(inner.sum())


def latlong_table(image, projection, north_rotation_deg=0.0, scale=1.0, rows=None):
    """A captured map (``image`` (N, M, 3), linear, in its ``projection``) as the world-frame
    lat-long table [W m^-2 sr^-1] of a Sky, float32 (rows, columns, 3), and the count of
    invalid values set to 0.

    An unrotated lat-long map of at most ``rows`` rows keeps its cells; otherwise (always for a
    fisheye) it is averaged onto ``rows`` x 2 ``rows`` cells (default: its own resolution, at
    most :data:`~skyfit_mi.physics.latlong.MAX_ROWS`).
    """
    check_choice("envmap projection", projection, PROJECTIONS)
    check_range("envmap scale", scale, 1e-30, 1e30)
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3 or min(img.shape[:2]) < 2:
        raise SkyfitError(f"an environment map must be an RGB image of at least 2x2 pixels, got "
                          f"an array of shape {img.shape}.")
    img, invalid = valid_pixels(img)
    if invalid == img.size:
        raise SkyfitError("every value of the environment map is NaN, infinite or negative; "
                          "give a linear HDR map (EXR or Radiance HDR).")
    N = img.shape[0] if projection == "latlong" else 2 * (min(img.shape[:2]) // 2)
    if rows is None:
        rows = min(N, MAX_ROWS)
    check_range("envmap rows", rows, 2, 4096)
    if rows != int(rows):
        raise SkyfitError(f"envmap rows must be a whole number, got {rows!r}.")
    rows = int(rows)
    if projection == "latlong" and rows == N and north_rotation_deg == 0.0:
        table = img
    else:
        lookup = (latlong_lookup if projection == "latlong" else fisheye_lookup)
        k = int(np.clip(np.ceil(N / rows), 1, MAX_SUPERSAMPLE))
        table = resample(lambda th, ph: lookup(img, th, ph), rows, north_rotation_deg, k)
    return (table * np.float32(scale)).astype(np.float32), invalid


def direct_normal_from_global(ghi, diffuse_horizontal, sun_zenith_deg):
    """Direct normal irradiance (GHI - DHI) / cos theta_s [W m^-2] from the measured ``ghi``
    and the map's own ``diffuse_horizontal`` [W m^-2], at the GHI's ``sun_zenith_deg`` (< 90);
    SkyfitError if GHI < DHI."""
    check_range("global horizontal irradiance", ghi, 0.0, 2000.0, "W m^-2")
    check_range("sun zenith", sun_zenith_deg, 0.0, MAX_ZENITH_FROM_GLOBAL_DEG, "degrees")
    if ghi < diffuse_horizontal:
        raise SkyfitError(f"the measured GHI ({ghi:.4g} W m^-2) is below the measured sky's own "
                          f"diffuse horizontal irradiance ({diffuse_horizontal:.4g} W m^-2): the "
                          "sun was hidden, or the two are on different scales or times; give "
                          "the direct normal irradiance measured, or check the efficacy.")
    return float((ghi - diffuse_horizontal) / np.cos(np.radians(sun_zenith_deg)))


@dataclass(frozen=True)
class MeasuredIrradiance:
    """The irradiance measured beside a captured map [W m^-2], setting its level and its sun's
    (checked by :func:`envmap_sky`); None where not measured.

    Attributes
    ----------
    diffuse_horizontal : float or None
        DHI: the map (after the sun's mask) is scaled to it, luminance-weighted.
    direct_normal : float or None
        DNI, in [0, 1500]: a solar disc of radiance DNI / Omega in the sun's colour (none with
        the sun below the horizon).
    global_horizontal : float or None
        GHI, in [0, 2000], instead of ``direct_normal``: the sun takes (GHI - E_map) / cos
        theta_s (:func:`direct_normal_from_global`).
    sun_measured : bool or None
        Whether the sun's level was measured, not modelled (the Sky's ``info["sun_measured"]``,
        setting a fit's prior); None: whether it is given.
    sun_sd : float or None
        The measured sun's sd of log level, if known (``info["sun_sd"]``, for the fit).
    """

    diffuse_horizontal: float = None
    direct_normal: float = None
    global_horizontal: float = None
    sun_measured: bool = None
    sun_sd: float = None


def envmap_sky(table, sun_zenith_deg, sun_azimuth_deg, *, measured=MeasuredIrradiance(),
               sun_mask_deg=None, ground_albedo=0.0, sun_solid_angle=None, info=None):
    """A :class:`~skyfit_mi.physics.sky.Sky` lit by a world-frame lat-long ``table``
    (:func:`latlong_table`) [W m^-2 sr^-1], with the sun given apart from the map.

    Parameters
    ----------
    table : ndarray (H, W, 3)
        The map's radiance [W m^-2 sr^-1], world frame.
    sun_zenith_deg, sun_azimuth_deg : float
        The sun's position [degrees], placing the solar disc and the mask.
    measured : MeasuredIrradiance
        Sets the map's level and the disc's (default: the map as it is, no disc).
    sun_mask_deg : float, optional
        Fill the map's cells within this angle of the sun [degrees] (:func:`mask_sun`).
    ground_albedo : float
        Reflectance of a Lambertian ground below the horizon lit by map and sun, added to the
        map's own lower half.
    sun_solid_angle, info : optional
        The disc's solid angle [sr] (default the sun's); a dict recorded in the Sky's ``info``.
    """
    from .sky import Sky            # not at the top: sky imports this module

    check_range("sun zenith", sun_zenith_deg, 0.0, 180.0, "degrees")
    check_range("ground albedo", ground_albedo, 0.0, 1.0)
    s = direction_from_angles(np.radians(sun_zenith_deg), np.radians(sun_azimuth_deg))
    info = {"kind": "envmap", **(info or {}), "sun_zenith_deg": float(sun_zenith_deg),
            "sun_azimuth_deg": float(sun_azimuth_deg), "ground_albedo": float(ground_albedo)}
    if sun_mask_deg is not None:
        check_range("sun_mask_deg", sun_mask_deg, 0.0, 45.0, "degrees")
        table, info["sun_masked_cells"] = mask_sun(table, s, sun_mask_deg)
        info["sun_mask_deg"] = float(sun_mask_deg)
    sky = Sky(s, envmap=table, sun_solid_angle=SUN_SOLID_ANGLE if sun_solid_angle is None
              else sun_solid_angle, info=info)
    diffuse_horizontal, direct_normal = measured.diffuse_horizontal, measured.direct_normal
    global_horizontal, sun_measured = measured.global_horizontal, measured.sun_measured
    if diffuse_horizontal is not None:
        info["diffuse_horizontal_W_m2"] = float(diffuse_horizontal)
        sky = sky.scaled(diffuse_horizontal=diffuse_horizontal)
    if global_horizontal is not None:
        if direct_normal is not None:
            raise SkyfitError("give the sun's direct normal irradiance or the global horizontal "
                              "irradiance it is found from, not both.")
        info["global_horizontal_W_m2"] = float(global_horizontal)
        if sun_zenith_deg <= MAX_ZENITH_FROM_GLOBAL_DEG:
            dni = direct_normal_from_global(
                global_horizontal, float(sky.sky_horizontal_irradiance() @ SRGB_LUMINANCE),
                sun_zenith_deg)
            info["direct_normal_from_global_W_m2"] = dni
            if sun_measured:
                info["sun_measured"] = True
            if measured.sun_sd is not None:
                info["sun_sd"] = float(check_range("sun_sd", measured.sun_sd, 0.0, 10.0))
            sky = sky.scaled(direct_normal=dni)
        else:
            info["note"] = ("sun within 1 degree of the horizon: its direct light is not found "
                            "from the global irradiance, no solar disc")
    if direct_normal is not None:
        info["direct_normal_W_m2"] = float(direct_normal)
        info["sun_measured"] = True if sun_measured is None else bool(sun_measured)
        if sun_zenith_deg < 90.0:
            sky = sky.scaled(direct_normal=direct_normal)
        else:
            info["note"] = "sun below the horizon: no solar disc"
    return sky.with_ground(ground_albedo)
