"""Measured sky scans as a day of ``envmap`` frames: HDR maps and the spec that uses them.

Each scan of the measured clear day (:mod:`skyfit_testkit.sky_measurement`) becomes a
lat-long EXR of the sky alone (:func:`skyfit_testkit.measured_sky.scan_envmap`, linear sRGB
[W m^-2 sr^-1]) and an ``envmap`` ``[[sky]]`` table naming the map and the disc's direct normal
irradiance; with a template's scene, camera, sensor and render settings, a spec to render and
fit under the measured light.
"""

from pathlib import Path

from skyfit_mi.errors import SkyfitError
from skyfit_mi.files import ensure_dir, write_json, write_text
from skyfit_mi.pipeline.spec import SCENES_DIR, SpecError
from skyfit_mi.render.image import write_exr

from .measured_sky import ROWS, scan_envmap
from .sky_measurement import SITE_LATITUDE_DEG, SITE_LONGITUDE_DEG

#: The maps' names, relative to the spec (a ``file`` pattern of the spec's envmap sky).
MAP_FILE = "maps/sky_{time:%H%M}.exr"
#: The written spec's and summary's names in the output folder.
SPEC_FILE, SUMMARY_FILE = "measured_sky.json", "measured_sky.csv"
#: The summary's columns: scan, rotation applied, fitted CIE general sky (indices, zenith
#: luminance [cd m^-2]), efficacy [lm W^-1], map's and data's DHI, GHI and DNI [W m^-2].
SUMMARY_COLUMNS = ("time", "capture", "rotated", "gradation", "indicatrix",
                   "zenith_luminance_cd_m2", "efficacy_lm_W", "map_dhi_W_m2", "scan_dhi_W_m2",
                   "ghi_W_m2", "dni_W_m2")
#: Sections of the template that the measured day replaces.
_REPLACED = ("location", "time", "sky")


def _scene(template, template_dir):
    """The template's [scene] with its file made absolute, looked up as a spec does."""
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
    scans : list of :class:`~skyfit_testkit.sky_measurement.Scan`
        One frame per scan, in time order.
    folder : path
        Output: ``maps/sky_HHMM.exr``, :data:`SPEC_FILE` and :data:`SUMMARY_FILE`.
    template, template_dir : dict, path
        A spec's tables, whose location, time and sky are replaced, and its folder.
    rows : int
        Rows of each lat-long map (columns twice as many).
    rotated, ground_albedo, name : bool, float, str
        Apply the scans' fitted rotation; albedo of the ground below the horizon; spec name.

    Returns the written spec's Path.
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
