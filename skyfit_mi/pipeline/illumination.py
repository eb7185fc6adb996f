"""The light of a frame from an ``envmap`` or ``directional`` illumination record.

Manifest records (``docs/MANIFEST.md``) and spec sky tables (``docs/SPEC.md``) of these types
share their fields: both become a :class:`~skyfit_mi.physics.sky.Sky` here, and a frame's record
is written back from the Sky (the map's file and options, never its numbers).

``envmap`` (:mod:`skyfit_mi.physics.envmap`): ``file`` (OpenEXR, Radiance HDR or float TIFF),
``projection`` (``latlong`` or ``fisheye``), ``north_rotation_deg`` (0), ``scale`` (1), ``rows``
(default the map's), ``diffuse_horizontal_W_m2`` (rescale to it), ``direct_normal_W_m2`` (a
solar disc), ``sun_mask_deg`` (fill the clipped sun), ``ground_albedo`` (0),
``sun_solid_angle_sr``.  ``directional``: ``direction`` (toward the source), ``irradiance_W_m2``
(RGB or one number, normal to the beam), ``solid_angle_sr`` (default the sun's).
"""

import os
from pathlib import Path

import numpy as np

from ..conventions import direction_from_angles
from ..errors import SkyfitError
from ..physics.envmap import MeasuredIrradiance, envmap_sky, latlong_table
from ..physics.perez import PerezOptions, perez_sky
from ..physics.sky import GROUND_ALBEDO, Sky, directional_sky
from .photos import read_photo

#: The envmap record's options, as :func:`envmap_sky`, :func:`latlong_table` and
#: :class:`~skyfit_mi.physics.envmap.MeasuredIrradiance` name them.
ENVMAP_OPTIONS = {"projection": "projection", "north_rotation_deg": "north_rotation_deg",
                  "scale": "scale", "rows": "rows",
                  "diffuse_horizontal_W_m2": "diffuse_horizontal",
                  "direct_normal_W_m2": "direct_normal",
                  "global_horizontal_W_m2": "global_horizontal", "sun_mask_deg": "sun_mask_deg",
                  "ground_albedo": "ground_albedo", "sun_solid_angle_sr": "sun_solid_angle",
                  "sun_measured": "sun_measured", "sun_sd": "sun_sd"}
#: The options that give the table (the rest light it).
_TABLE_OPTIONS = ("projection", "north_rotation_deg", "scale", "rows")
#: The options that are measured irradiance (:class:`~skyfit_mi.physics.envmap.MeasuredIrradiance`).
_MEASURED_OPTIONS = ("diffuse_horizontal", "direct_normal", "global_horizontal", "sun_measured",
                     "sun_sd")


def perez_from_irradiance(e, zenith, azimuth, t):
    """The Perez all-weather sky (:func:`~skyfit_mi.physics.perez.perez_sky`) of measured
    irradiance at time ``t`` (aware), sun at ``zenith``, ``azimuth`` [deg].  ``e`` (spec entry or
    manifest record) gives ``diffuse_horizontal_W_m2`` and ``direct_normal_W_m2``, or
    ``global_horizontal_W_m2`` split by ``decomposition`` (default 'erbs'), and optional ``cct``
    [K], ``ground_albedo``, ``sun``.  Black below the horizon; SkyfitError without irradiance."""
    if zenith >= 90.0:              # no daylight model below the horizon: a black sky
        return Sky(direction_from_angles(np.radians(zenith), np.radians(azimuth)),
                   info={"kind": "perez", "sun_zenith_deg": zenith, "sun_azimuth_deg": azimuth,
                         "note": "sun below the horizon: no sky light"})
    dhi, dni = e.get("diffuse_horizontal_W_m2"), e.get("direct_normal_W_m2")
    ghi = e.get("global_horizontal_W_m2")
    if dhi is not None and dni is not None:
        kw = {"dhi": dhi, "dni": dni}
    elif ghi is not None:
        kw = {"ghi": ghi, "options": PerezOptions(decomposition=e.get("decomposition", "erbs"))}
    else:
        raise SkyfitError("a Perez sky needs measured irradiance: "
                          "diffuse_horizontal_W_m2 and direct_normal_W_m2, or "
                          "global_horizontal_W_m2 (split by a decomposition model), or "
                          "irradiance_file.")
    sky = perez_sky(zenith, azimuth, t.timetuple().tm_yday, **kw)
    if ghi is not None and "ghi" not in kw:
        sky.info["ghi_w_m2"] = float(ghi)
    return sky.to_sky(cct=e.get("cct"), ground_albedo=e.get("ground_albedo", GROUND_ALBEDO),
                      sun=e.get("sun", True))


def read_envmap(path):
    """The pixels (N, M, 3) of the HDR map at ``path`` [the file's linear values]; SkyfitError
    naming the file if missing, not an image, or integer codes (not a radiance map)."""
    photo = read_photo(path)
    if photo.kind != "float":
        raise SkyfitError(f"{path}: holds {photo.bits}-bit codes, not the linear floats of an HDR "
                          "environment map; give an OpenEXR, Radiance HDR or float TIFF map.")
    return photo.values


def envmap_from_record(rec, folder, sun_zenith_deg, sun_azimuth_deg):
    """The :class:`~skyfit_mi.physics.sky.Sky` of an ``envmap`` record whose ``file`` is relative
    to ``folder``, with the sun at (``sun_zenith_deg``, ``sun_azimuth_deg``) [degrees]."""
    path = (Path(folder) / rec["file"]).resolve()
    opts = {ENVMAP_OPTIONS[k]: rec[k] for k in ENVMAP_OPTIONS if k in rec}
    table, invalid = latlong_table(read_envmap(path), opts.pop("projection", "latlong"),
                                   **{k: opts.pop(k) for k in _TABLE_OPTIONS if k in opts})
    info = {"file": str(path), "invalid_values": invalid, "rows": int(table.shape[0]),
            **{k: rec[k] for k in _TABLE_OPTIONS if k in rec and k != "rows"}}
    info.setdefault("projection", "latlong")
    measured = MeasuredIrradiance(**{k: opts.pop(k) for k in _MEASURED_OPTIONS if k in opts})
    return envmap_sky(table, sun_zenith_deg, sun_azimuth_deg, measured=measured, info=info,
                      **opts)


def envmap_record(sky, folder):
    """The ``envmap`` record of a Sky made by :func:`envmap_from_record`, relative to ``folder``."""
    info = sky.info
    if "file" not in info:
        raise SkyfitError("this sky's environment map was not read from a file, so a manifest "
                          "cannot refer to it; write the map as EXR and give its file.")
    rec = {"kind": "envmap", "file": os.path.relpath(info["file"], Path(folder).resolve()),
           **{k: info[k] for k in ENVMAP_OPTIONS if k in info},
           "sun_solid_angle_sr": sky.sun_solid_angle}
    return rec


def directional_from_record(rec):
    """The :class:`~skyfit_mi.physics.sky.Sky` of a ``directional`` record."""
    kw = {"solid_angle": rec["solid_angle_sr"]} if "solid_angle_sr" in rec else {}
    return directional_sky(rec["direction"], rec["irradiance_W_m2"], **kw)


def directional_record(sky):
    """The ``directional`` record of a :func:`~skyfit_mi.physics.sky.directional_sky` Sky."""
    return {"kind": "directional", "direction": sky.sun_direction,
            "irradiance_W_m2": sky.sun_radiance * sky.sun_solid_angle,
            "solid_angle_sr": sky.sun_solid_angle}
