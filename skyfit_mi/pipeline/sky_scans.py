"""Measured sky scans as a day of ``envmap`` frames: HDR maps and the spec that uses them.

Each scan of the measured clear day (:mod:`skyfit_mi.physics.sky_measurement`) becomes a
lat-long EXR of the sky alone (:func:`skyfit_mi.physics.measured_sky.scan_envmap`: interpolated
radiance, linear sRGB [W m^-2 sr^-1], world frame) and a ``[[sky]]`` table of ``type =
"envmap"`` that names the map and the solar disc's direct normal irradiance.  With a template
spec's scene, materials, camera, sensor and render settings, the result is a spec that
``skyfit render`` renders and whose frames ``skyfit fit`` fits under the measured light.
"""

from pathlib import Path

from ..errors import SkyfitError
from ..files import ensure_dir, write_json, write_text
from ..physics.measured_sky import ROWS, scan_envmap
from ..physics.sky_measurement import SITE_LATITUDE_DEG, SITE_LONGITUDE_DEG
from ..render.image import write_exr
from .spec import SCENES_DIR, SpecError

#: The maps' names, relative to the spec (a ``file`` pattern of the spec's envmap sky).
MAP_FILE = "maps/sky_{time:%H%M}.exr"
#: The written spec's and summary's names in the output folder.
SPEC_FILE, SUMMARY_FILE = "measured_sky.json", "measured_sky.csv"
#: The summary's columns: the scan, whether the scanner rotation was applied, the fitted CIE
#: general sky (indices, zenith luminance [cd m^-2]), the efficacy [lm W^-1], the map's and the
#: data's diffuse horizontal irradiance, the pyranometer's GHI and the disc's DNI [W m^-2].
SUMMARY_COLUMNS = ("time", "capture", "rotated", "gradation", "indicatrix",
                   "zenith_luminance_cd_m2", "efficacy_lm_W", "map_dhi_W_m2", "scan_dhi_W_m2",
                   "ghi_W_m2", "dni_W_m2")
#: Sections of the template that the measured day replaces.
_REPLACED = ("location", "time", "sky")


def _scene(template, template_dir):
    """The template's [scene] with its file as an absolute path (the spec is written
    elsewhere): beside the template first, then the shipped scenes, as a spec looks it up."""
    scene = dict(template.get("scene") or {})
    if "file" not in scene:
        raise SpecError("the template spec has no [scene] file; give one (e.g. file = 'disc.xml').")
    for cand in (Path(template_dir) / scene["file"], SCENES_DIR / scene["file"]):
        if cand.is_file():
            return {**scene, "file": str(cand.resolve())}
    raise SpecError(f"[scene] file {scene['file']!r} of the template is neither beside it nor in "
                    "scenes/; give an existing scene.")


def measured_day(scans, folder, template, template_dir=".", *, rows=ROWS, rotated=True,
                 ground_albedo=0.2, name="measured-sky"):
    """Write the maps of ``scans`` and a spec that renders ``template``'s scene under them.

    Parameters
    ----------
    scans : list of :class:`~skyfit_mi.physics.sky_measurement.Scan`
        The frames, one per scan, in time order.
    folder : path
        Output folder: ``maps/sky_HHMM.exr``, ``measured_sky.json`` (the spec) and
        ``measured_sky.csv`` (one row per scan: the fitted CIE general sky, the efficacy and
        the irradiance split).
    template : dict
        A spec's tables (:func:`~skyfit_mi.pipeline.spec.read_spec`); its scene, materials,
        camera, sensor and render are kept, its location, time and sky replaced.
    template_dir : path
        The template's folder (its scene file is looked up there first).
    rows : int
        Rows of each lat-long map (columns twice as many).
    rotated : bool
        Turn the scanner's directions by the data's fitted rotation
        (:func:`~skyfit_mi.physics.measured_sky.scan_envmap`).
    ground_albedo : float
        The Lambertian ground below the horizon, lit by each map and its sun.
    name : str
        The spec's name.

    Returns
    -------
    Path
        The written spec.
    """
    if not scans:
        raise SkyfitError("no scans to write; give at least one.")
    doc = {k: v for k, v in template.items() if k not in _REPLACED}
    doc.update(name=name, scene=_scene(template, template_dir))
    skies = [scan_envmap(s, rows=rows, rotated=rotated, ground_albedo=ground_albedo)
             for s in scans]          # every map made before any file is written
    out = Path(folder)
    ensure_dir(out / "maps")
    entries, lines = [], [",".join(SUMMARY_COLUMNS)]
    for scan, sky in zip(scans, skies):
        file = MAP_FILE.format(time=scan.time)
        write_exr(out / file, sky.envmap, {"kind": "sky_map", "units": "W m^-2 sr^-1",
                                           "time": scan.time})
        i = sky.info
        entries.append({"type": "envmap", "file": file,
                        "direct_normal_W_m2": round(i["direct_normal_W_m2"], 3),
                        "ground_albedo": ground_albedo})
        lines.append(f"{scan.time.isoformat()},{scan.capture},{int(rotated)},"
                     f"{i['cie_groups'][0]:g},{i['cie_groups'][1]:g},"
                     f"{i['zenith_luminance_cd_m2']:.1f},{i['efficacy_lm_W']:.2f},"
                     f"{i['map_diffuse_horizontal_W_m2']:.2f},{scan.dhi_scan:.2f},"
                     f"{scan.ghi:.2f},{i['direct_normal_W_m2']:.2f}")
    offset = scans[0].time.strftime("%z")
    doc["location"] = {"latitude_deg": SITE_LATITUDE_DEG, "longitude_deg": SITE_LONGITUDE_DEG,
                       "timezone": f"{offset[:3]}:{offset[3:]}"}
    doc["time"] = {"times": [s.time.isoformat() for s in scans]}
    doc["sky"] = entries
    write_text(out / SUMMARY_FILE, "\n".join(lines) + "\n")
    write_json(out / SPEC_FILE, doc)
    return out / SPEC_FILE
