"""Fitted materials out: Mitsuba 3 XML, Radiance and glTF 2.0 files, with the fit beside them.

``skyfit export FITS -o OUT`` takes fit results (``fit_NAME.json``, a ``fits.csv`` or a ``skyfit
fit`` folder) or a per-pixel map's folder and writes, in ``OUT``:

* ``materials.xml`` (Mitsuba 3): a ``blendbsdf`` of ``diffuse`` and ``roughconductor`` (exact
  for the microfacet lobes); ``materials_ward.xml``: the exact ``ward`` plugin (Python only,
  after ``skyfit_mi.render.setup()``); ``preview.xml``: the materials on spheres;
* ``materials.rad`` (Radiance): ``plastic`` or ``metal`` (exact for the ``balanced`` and
  ``radiance`` lobes); ``preview.rad``;
* ``materials.gltf`` (glTF 2.0): metallic-roughness with ``KHR_materials_specular``;
* ``export.json``: each fit and, per format, whether exact, the parameters and the nearest
  form's error (:mod:`~skyfit_mi.physics.material_match`).

A map's planes become textures (``textures/``, u right, v down), Radiance taking each region's
median.  Nothing is written until all is made, and ``export.json`` last; another export's
folder is refused unless ``overwrite``, which replaces only that export's files (an export that
did not finish is replaced as well).
"""

import base64
import json
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import SkyfitError, listed
from ..files import FolderLock, to_json, write_text
from ..physics.material_match import FORMS, GLTF_F0, nearest, nearest_maps
from ..physics.ward import raw_reflectances
from ..render.fit_model import PARAMETERS, material_dict, reflectances
from ..render.image import read_exr, to_srgb8, write_exr, write_png
from ..render.scene_xml import sub_element, ward_element
from .fit_result import MAP_SUMMARY, load_fits

#: The files an export writes (besides ``textures/``), per format, and the sidecar.
FILES = {"mitsuba": "materials.xml", "radiance": "materials.rad", "gltf": "materials.gltf"}
#: skyfit's own ``ward`` plugin elements (with the mitsuba format).
WARD_FILE = "materials_ward.xml"
#: The preview scenes beside them: the materials on spheres (a map on a square) in a row on a
#: grey ground, under a uniform sky and a sun, the same in both renderers.
PREVIEWS = {"mitsuba": "preview.xml", "radiance": "preview.rad"}
#: The preview's sun direction (toward it; azimuth 135, elevation 45 degrees), irradiance
#: [W m^-2] and sky radiance [W m^-2 sr^-1], RGB; ground reflectance; camera position, target [m].
PREVIEW_SUN = np.array([0.5, -0.5, np.sqrt(0.5)])
#: The preview sun's angular diameter [degrees] (Radiance's ``source``; Mitsuba's: directional).
PREVIEW_SUN_DEG = 0.533
PREVIEW_LIGHT = {"sun_irradiance": 600.0, "sky_radiance": 30.0, "ground": 0.2,
                 "camera": (0.0, -6.0, 3.0), "target": (0.0, 0.0, 0.4)}
SIDECAR = "export.json"
#: An export holds this in its folder from its first file until the sidecar, its last, is
#: written: the files of an export that failed or was stopped, which the next one replaces.
UNFINISHED = ".export_unfinished"
#: The name of a map's textured material (its regions' medians keep theirs).
MAP_NAME = "pixel_map"


@dataclass(frozen=True)
class Material:
    """One fitted material: region, model, lobe, parameters and fit record; ``maps``: a map's
    texel arrays (rho_d (N, 3), s (N, 3), sigma (N,)) and (H, W) mask, or None."""
    name: str
    model: str
    normalisation: str
    parameters: dict
    intervals: dict = field(default_factory=dict)
    warnings: tuple = ()
    source: str = ""
    maps: dict = None

    def raw(self):
        """(rho_d (3,), s (3,), sigma_alpha) of the fitted parameters (thesis 7.1)."""
        theta = [self.parameters[k] for k in PARAMETERS[self.model]]
        rho_d, s = reflectances(self.model, theta)[:2]
        return rho_d, s, float(theta[-1])


def read_materials(paths):
    """The materials of fit results (:func:`~.fit_result.load_fits`' paths) or a map folder."""
    paths = [Path(p) for p in paths]
    if len(paths) == 1 and (paths[0] / MAP_SUMMARY).is_file():
        return read_map(paths[0])
    return [Material(region, r["model"], r.get("normalisation", "ward"), dict(r["parameters"]),
                     {k: v["95"] for k, v in r["intervals"].items()},
                     tuple(r.get("warnings", [])), str(path))
            for region, (path, r) in load_fits(paths).items()]


#: A region's median material from fewer determined pixels than this is warned of.
MEDIAN_PIXELS = 10


def read_map(folder):
    """The per-pixel map in ``folder`` as materials: its texels, and each region's median."""
    summary = json.loads((folder / MAP_SUMMARY).read_text(encoding="utf-8"))
    regions = summary.get("regions") or {}
    lobes = {r.get("normalisation", "ward") for r in regions.values()}
    if len(lobes) != 1:
        raise SkyfitError(f"the map in {folder} mixes lobes ({', '.join(sorted(lobes))}); "
                          "export its regions' fits instead (fit_NAME.json).")
    lobe = lobes.pop()
    planes = {n: read_exr(folder / f"{n}.exr") for n in summary["parameters"]}
    shape = next(iter(planes.values())).shape[:2]
    rho_d, s = np.zeros(shape + (3,)), np.zeros(shape + (3,))
    sigma, mask = np.zeros(shape), np.zeros(shape, bool)
    for model, names in sorted(PARAMETERS.items(), key=lambda kv: -len(kv[1])):   # colour first
        if not set(names) <= set(planes):
            continue
        theta = np.stack([planes[n] for n in names], axis=-1)
        here = np.all(np.isfinite(theta), axis=-1) & ~mask
        th = theta[here].astype(float)
        first = {"two": None, "achromatic": th[:, 0], "colour": th[:, :3]}[model]
        rho_d[here], s[here] = raw_reflectances(model, th[:, -2], first)
        sigma[here] = th[:, -1]
        mask |= here
    if not mask.any():
        raise SkyfitError(f"the map in {folder} has no mapped pixel; map the regions again.")
    unsure = np.zeros(shape, bool)
    if (folder / "warnings.exr").is_file() and "undetermined_bits" in summary:
        bits = np.nan_to_num(read_exr(folder / "warnings.exr"), nan=0.0).astype(np.int64)
        unsure = mask & ((bits & int(summary["undetermined_bits"])) > 0)
    notes = ((f"{int(unsure.sum())} of {int(mask.sum())} texels are not determined (a parameter "
              f"the data do not fix): their values are the fits' best, flagged in "
              f"{UNDETERMINED_FILE}",) if unsure.any() else ())
    if MAP_NAME in regions:
        raise SkyfitError(f"the map in {folder} has a region named {MAP_NAME!r}, the name its "
                          "textured material takes; export that region's fit (fit_NAME.json).")
    out, lacking = [], []
    for name, r in regions.items():
        med, names = r.get("median") or {}, PARAMETERS[r["model"]]
        counts = r.get("determined_by_parameter") or {}
        if not set(names) <= {k for k, v in med.items() if v is not None}:
            lacking.append(name)
            continue
        few = [f"{k} ({counts[k]})" for k in names if counts.get(k, MEDIAN_PIXELS) < MEDIAN_PIXELS]
        out.append(Material(
            name, r["model"], lobe, {k: med[k] for k in names},
            warnings=(f"medians of fewer than {MEDIAN_PIXELS} determined pixels: "
                      f"{', '.join(few)}; export the region's fit (fit_NAME.json) for a value "
                      "with its interval",) if few else (),
            source=f"{folder}: each parameter the median of region {name}'s pixels that "
                   "determine it (map_summary.json's determined_by_parameter)"))
    if lacking:
        notes += (f"{listed(lacking)}: no median material (a parameter no pixel determines); "
                  "export the region's fit (fit_NAME.json)",)
    return [Material(MAP_NAME, "raw", lobe, {}, warnings=notes, source=str(folder),
                     maps={"rho_d": rho_d, "s": s, "sigma": sigma, "mask": mask,
                           "undetermined": unsure})] + out


def export_files():
    """Every file an export may write, relative to its folder."""
    return {SIDECAR, WARD_FILE, UNDETERMINED_FILE, *FILES.values(), *PREVIEWS.values(),
            *(f"textures/{form}_error.exr" for form in FORMS),
            *(n for files in TEXTURE_FILES.values() for n in files.values())}


def check_output(out, overwrite):
    """Refuse a folder holding another export (:func:`export_files`) unless ``overwrite``; an
    export's that did not finish (:data:`UNFINISHED`) is replaced."""
    held = sorted(n for n in export_files() if (Path(out) / n).exists())
    if held and not overwrite and not (Path(out) / UNFINISHED).exists():
        raise SkyfitError(f"{out} holds another export ({held[0]}); give another -o, or pass "
                          "--overwrite to replace it.")


def export(paths, out, formats=FORMS, overwrite=False, log=print):
    """Write the materials of ``paths`` in ``formats`` into ``out``; returns the sidecar."""
    bad = [f for f in formats if f not in FORMS]
    if bad or not formats:
        raise SkyfitError(f"unknown export format {bad[0] if bad else '(none)'!r}; give some of "
                          f"{', '.join(FORMS)}.")
    out = Path(out)
    with FolderLock(out):                # one export at a time into a folder
        check_output(out, overwrite)
        materials = read_materials(paths)
        matches = {m.name: {f: _match(m, f) for f in formats} for m in materials}
        record = {"formats": list(formats),
                  "materials": {m.name: _record(m, matches[m.name]) for m in materials},
                  "error": "relative error of the radiance a material reflects from a distant "
                           "light, light and view within 80 degrees of the normal (rms and "
                           "largest over a grid of such pairs; albedo_max: the directional "
                           "albedo's largest), against the fitted BRDF"}
        files = {}
        if "mitsuba" in formats:
            files[FILES["mitsuba"]] = mitsuba_xml(materials, matches)
            files[WARD_FILE] = mitsuba_ward_xml(materials)
            files[PREVIEWS["mitsuba"]] = mitsuba_preview(materials)
        if "radiance" in formats:
            files[FILES["radiance"]] = radiance_text(materials, matches)
            files[PREVIEWS["radiance"]] = radiance_preview([m for m in materials
                                                            if m.maps is None])
        if "gltf" in formats:
            files[FILES["gltf"]] = gltf_json(materials, matches)
        images = {name: image for m in materials if m.maps is not None
                  for name, image in texture_images(m, matches[m.name]).items()}
        write_text(out / UNFINISHED, "")           # until the sidecar, written last, is
        for name, image in images.items():
            (write_exr if name.endswith(".exr") else write_png)(out / name, image)
        for name, text in files.items():
            write_text(out / name, text)
        write_text(out / SIDECAR, to_json(record) + "\n")
        for stale in export_files() - {SIDECAR, *files, *images}:   # an earlier export's
            (out / stale).unlink(missing_ok=True)
        if (out / "textures").is_dir() and not any((out / "textures").iterdir()):
            (out / "textures").rmdir()
        (out / UNFINISHED).unlink()
        for m in materials:
            _log_material(m, matches[m.name], log)
        log(f"wrote {', '.join(files)} and {SIDECAR} in {out}")
        return record


def _match(m, form):
    """The nearest ``form`` of material ``m`` (per texel for a map, errors summarised by largest
    and median), or a line naming what the form cannot express; None for a map in Radiance."""
    try:
        if m.maps is None:
            rho_d, s, sigma = m.raw()
            r = nearest(form, rho_d, s, sigma, m.normalisation)
            return {"params": r.params, "error": r.error, "exact": r.exact}
        if form == "radiance":
            return None
        k = m.maps["mask"]
        params, error = nearest_maps(form, m.maps["rho_d"][k], m.maps["s"][k],
                                     m.maps["sigma"][k], m.normalisation)
        summary = {"max": float(np.max(error["max"])), "rms": float(np.median(error["rms"])),
                   "albedo_max": float(np.max(error["albedo_max"])), "domain": error["domain"],
                   "notes": error["notes"], "over_texels": "largest max and albedo_max, median "
                   f"rms; each texel's max in textures/{form}_error.exr"}
        return {"params": params, "error": summary, "exact": bool(error["exact"]),
                "texel_error": error["max"]}
    except SkyfitError as exc:
        raise SkyfitError(f"material {m.name!r}: {str(exc).rstrip('.')} ({form}).") from None


def _record(m, matches):
    """The sidecar's record of material ``m`` and its ``matches`` per format."""
    rec = {"source": m.source, "model": m.model, "normalisation": m.normalisation,
           "parameters": m.parameters, "intervals_95": m.intervals, "warnings": list(m.warnings)}
    if m.maps is not None:
        rec["texels"] = int(m.maps["mask"].sum())
    rec["exports"] = {f: {"exact": r["exact"], "error": r["error"],
                          **({} if m.maps is not None else {"params": r["params"]})}
                      if r is not None else "the regions' medians (Radiance's plastic and metal "
                      "take one roughness per surface)" for f, r in matches.items()}
    if "mitsuba" in matches and m.maps is None:
        rec["exports"]["mitsuba_ward"] = {"exact": True, "id": f"{m.name}_ward",
                                          "file": WARD_FILE}
    return rec


def _log_material(m, matches, log):
    parts = [f"{f} {_how(r, 'nearest, ')}" for f, r in matches.items() if r is not None]
    log(f"{m.name}: " + "; ".join(parts))
    for w in m.warnings:
        log(f"  warning ({m.name}'s fit; kept in {SIDECAR}): {w}")


def _how(r, nearest="the nearest: "):
    """'exact', or how far off the nearest form of match ``r`` is, after ``nearest``."""
    e = r["error"]
    return "exact" if r["exact"] else (
        f"{nearest}reflected radiance off by up to {100 * e['max']:.3g}% (rms "
        f"{100 * e['rms']:.3g}%)" + (f", its albedo (the light it returns under a uniform sky) by "
                                     f"up to {100 * e['albedo_max']:.3g}%"
                                     if e.get("albedo_max") is not None else ""))


def _numbers(v):
    return ", ".join(f"{float(x):.6g}" for x in np.atleast_1d(v))


#: The roughness standing for an ideal mirror in a ``blendbsdf``: Mitsuba 3.9's blend loses
#: much of a smooth ``conductor``'s light (a uniform sky: 0.26-0.29 for 0.34 at weight 0.5),
#: which a ``roughconductor`` this smooth does not.
MIRROR_ALPHA = 1e-3


def _blend(parent, name, p, textures=None):
    """A ``blendbsdf`` of ``diffuse`` and ``roughconductor`` for ``p`` (``textures``: bitmaps)."""
    textures = textures or {}

    def value(el, tag, key):
        name = "reflectance" if key == "diffuse_reflectance" else key    # the plugin's name
        if key in textures:
            t = sub_element(el, "texture", type="bitmap", name=name)
            sub_element(t, "string", name="filename", value=textures[key])
            sub_element(t, "boolean", name="raw", value="true")
            sub_element(t, "string", name="filter_type", value="nearest")
        else:
            sub_element(el, tag, name=name, value=_numbers(p[key]))

    b = sub_element(parent, "bsdf", type="blendbsdf", id=name)
    value(b, "float", "weight")
    d = sub_element(b, "bsdf", type="diffuse")
    value(d, "rgb", "diffuse_reflectance")
    if p["distribution"] == "mirror":   # an ideal mirror: a rough conductor barely rough
        c = sub_element(b, "bsdf", type="roughconductor")
        sub_element(c, "string", name="distribution", value="ggx")
        sub_element(c, "float", name="alpha", value=f"{MIRROR_ALPHA:g}")
    else:
        c = sub_element(b, "bsdf", type="roughconductor")
        sub_element(c, "string", name="distribution", value=p["distribution"])
        value(c, "float", "alpha")
    value(c, "rgb", "specular_reflectance")
    if p["material"] == "none":
        sub_element(c, "string", name="material", value="none")
    else:
        sub_element(c, "float", name="eta", value=f"{p['material']['eta']:.6g}")
        sub_element(c, "float", name="k", value=f"{p['material']['k']:.6g}")


def mitsuba_xml(materials, matches):
    """``materials.xml``: a Mitsuba 3 scene of the materials' built-in BSDFs (module doc)."""
    root = ET.Element("scene", version="3.0.0")
    for m in materials:
        r = matches[m.name]["mitsuba"]
        root.append(ET.Comment(f" {m.name} ({m.source}): built-in plugins, {_how(r)} "))
        _blend(root, m.name, r["params"], TEXTURE_FILES["mitsuba"] if m.maps is not None else None)
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n"


def mitsuba_ward_xml(materials):
    """``materials_ward.xml``: the materials as the exact ``ward`` plugin, ids ``NAME_ward``."""
    root = ET.Element("scene", version="3.0.0")
    root.append(ET.Comment(" skyfit's ward plugin: import skyfit_mi; skyfit_mi.render.setup() "
                           "registers it before mitsuba.load_file "))
    for m in materials:
        if m.maps is None:
            theta = [m.parameters[k] for k in PARAMETERS[m.model]]
            ward_element(sub_element(root, "bsdf"), f"{m.name}_ward",
                         material_dict(m.model, theta, m.normalisation))
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n"


def _row(materials):
    """(material, x position [m]) of the preview's row, centred on x = 0, 1 m apart."""
    return [(m, i - 0.5 * (len(materials) - 1)) for i, m in enumerate(materials)]


def _view(materials):
    """The preview camera's fields of view [degrees] and image size [pixels] holding the row."""
    width = max(2.0, len(materials) + 1.0)                 # the row's width in view [m]
    fov_h = 2 * np.degrees(np.arctan(0.6 * width / 6.7))
    w, h = int(120 * width), 240
    return fov_h, 2 * np.degrees(np.arctan(np.tan(np.radians(fov_h / 2)) * h / w)), w, h


def mitsuba_preview(materials):
    """``preview.xml``: ``materials.xml`` in the preview scene (``mitsuba preview.xml``)."""
    L, sun = PREVIEW_LIGHT, PREVIEW_SUN
    fov_h, _, w, h = _view(materials)
    shapes = "".join(
        (f'    <shape type="rectangle"><transform name="to_world"><scale x="0.4" y="-0.4"/>'
         f'<translate x="{x:g}" y="0" z="0.01"/></transform><ref id="{m.name}"/></shape>\n'
         if m.maps is not None else
         f'    <shape type="sphere"><point name="center" x="{x:g}" y="0" z="0.4"/>'
         f'<float name="radius" value="0.4"/><ref id="{m.name}"/></shape>\n')
        for m, x in _row(materials))
    return f"""<!-- skyfit export: the materials of materials.xml on spheres (a map on a square) under
     a uniform sky and a sun; render with `mitsuba preview.xml` (writes preview.exr) -->
<scene version="3.0.0">
    <default name="spp" value="256"/>
    <include filename="materials.xml"/>
    <integrator type="path"><integer name="max_depth" value="4"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="{fov_h:.4g}"/>
        <transform name="to_world"><lookat origin="{_numbers(L['camera'])}" target="{_numbers(L['target'])}" up="0, 0, 1"/></transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="{w}"/><integer name="height" value="{h}"/></film>
    </sensor>
    <emitter type="constant"><rgb name="radiance" value="{L['sky_radiance']:g}"/></emitter>
    <emitter type="directional"><vector name="direction" value="{_numbers(-sun)}"/><rgb name="irradiance" value="{L['sun_irradiance']:g}"/></emitter>
    <shape type="rectangle"><transform name="to_world"><scale value="50"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="{L['ground']:g}"/></bsdf></shape>
{shapes}</scene>
"""


def radiance_name(name):
    """``name`` as a Radiance identifier: one word of ASCII letters, digits and ``_.-`` (a
    material "dïsc é" was written as two words, which oconv refuses)."""
    return re.sub(r"[^A-Za-z0-9_.\-]", "_", name)


def radiance_preview(materials):
    """``preview.rad``: ``materials.rad`` in the preview scene, its render command in the header."""
    L, sun = PREVIEW_LIGHT, PREVIEW_SUN
    cam, target = np.array(L["camera"]), np.array(L["target"])
    fov_h, fov_v, w, h = _view(materials)
    view = (f"-vp {' '.join(f'{v:g}' for v in cam)} -vd "
            f"{' '.join(f'{v:.6g}' for v in target - cam)} -vu 0 0 1 -vh {fov_h:.4g} "
            f"-vv {fov_v:.4g} -x {w} -y {h}")
    omega = 2 * np.pi * (1 - np.cos(np.radians(PREVIEW_SUN_DEG / 2)))   # the sun's disc [sr]
    lines = ["# skyfit export: the materials of materials.rad on spheres under a uniform sky and "
             "a sun; render with",
             f"#   oconv materials.rad preview.rad > preview.oct && rpict {view} -ab 2 -ad 1024 "
             "preview.oct > preview.hdr",
             "void light sun_light 0 0 3 " + " ".join([f"{L['sun_irradiance'] / omega:.6g}"] * 3),
             f"sun_light source sun 0 0 4 {' '.join(f'{v:.6g}' for v in sun)} {PREVIEW_SUN_DEG:g}",
             f"void glow sky_glow 0 0 4 {L['sky_radiance']:g} {L['sky_radiance']:g} "
             f"{L['sky_radiance']:g} 0",
             "sky_glow source sky 0 0 4 0 0 1 360",
             f"void plastic ground_mat 0 0 5 {L['ground']:g} {L['ground']:g} {L['ground']:g} 0 0",
             "ground_mat polygon ground 0 0 12 -50 -50 0 50 -50 0 50 50 0 -50 50 0"]
    lines += [f"{radiance_name(m.name)} sphere {radiance_name(m.name)}_sphere 0 0 4 {x:g} 0 0.4 "
              "0.4" for m, x in _row(materials)]
    return "\n".join(lines) + "\n"


def radiance_text(materials, matches):
    """``materials.rad``: a Radiance ``plastic`` or ``metal`` per material (map: region medians)."""
    lines = ["# skyfit export: Radiance 6 plastic/metal (balanced Ward lobe), "
             "colour C, specularity, roughness (rms slope)"]
    names = {}
    for m in materials:
        other = names.setdefault(radiance_name(m.name), m.name)
        if other != m.name:
            raise SkyfitError(f"materials {other!r} and {m.name!r} are both "
                              f"{radiance_name(m.name)!r} as Radiance identifiers (one word of "
                              "ASCII letters, digits and _.-); rename one.")
    for m in materials:
        if m.maps is not None:
            continue
        r = matches[m.name]["radiance"]
        p = r["params"]
        lines += [f"# {m.name} ({m.source}): {_how(r)}",
                  f"void {p['type']} {radiance_name(m.name)}\n0\n0\n5 "
                  f"{_numbers(p['colour']).replace(',', '')} "
                  f"{p['spec']:.6g} {p['roughness']:.6g}"]
    return "\n".join(lines) + "\n"


#: A map's texels whose fits did not determine a parameter (white), relative to the folder.
UNDETERMINED_FILE = "textures/undetermined.png"
#: A map's texture files, relative to the export folder, per format.
TEXTURE_FILES = {"mitsuba": {k: f"textures/{k}.exr" for k in
                             ("diffuse_reflectance", "specular_reflectance", "alpha")},
                 "gltf": {"baseColorTexture": "textures/base_colour.png",
                          "metallicRoughnessTexture": "textures/metallic_roughness.png",
                          "specularTexture": "textures/specular.png",
                          "specularColorTexture": "textures/specular_colour.png"}}


def _image(m, values):
    """A map's texel values (N, ...) scattered onto its (H, W, ...) image, 0 outside it."""
    values = np.asarray(values, dtype=float)
    img = np.zeros(m.maps["mask"].shape + values.shape[1:])
    img[m.maps["mask"]] = values
    return img


def texture_images(m, matches):
    """The texture images of map material ``m`` for ``matches``, each form's largest error per
    texel (``textures/FORM_error.exr``) and the undetermined texels (:data:`UNDETERMINED_FILE`),
    by file name (EXR or PNG by suffix)."""
    unsure = np.repeat(m.maps["undetermined"][..., None], 3, axis=2).astype(np.uint8) * 255
    images = {UNDETERMINED_FILE: unsure}
    for form, r in matches.items():
        if r is not None:
            images[f"textures/{form}_error.exr"] = _image(m, r["texel_error"]).astype(np.float32)
    if "mitsuba" in matches:
        p = matches["mitsuba"]["params"]
        images.update({path: _image(m, p[key]).astype(np.float32)
                       for key, path in TEXTURE_FILES["mitsuba"].items()})
    if "gltf" in matches:
        p, files = matches["gltf"]["params"], TEXTURE_FILES["gltf"]
        mr = np.stack([np.zeros(len(p["roughnessFactor"])), p["roughnessFactor"],
                       p["metallicFactor"]], axis=-1)
        spec = p["KHR_materials_specular"]
        f = np.asarray(spec["specularFactor"], dtype=float)
        f = np.repeat((f / max(float(f.max()), 1e-12))[:, None], 4, axis=1)   # times the factor
        colour = np.asarray(spec["specularColorFactor"], dtype=float) / GLTF_SPECULAR_COLOUR
        images[files["baseColorTexture"]] = to_srgb8(
            _image(m, np.asarray(p["baseColorFactor"])[:, :3]), 1.0)
        images[files["metallicRoughnessTexture"]] = _linear8(_image(m, mr))
        images[files["specularTexture"]] = _linear8(_image(m, f))                  # its A
        images[files["specularColorTexture"]] = to_srgb8(_image(m, colour), 1.0)
    return images


#: The factor of a map's glTF specular colour texture: material_match's dielectric takes
#: specularColorFactor s / (max(s) GLTF_F0) (F0 = F90), above a texture's range of 0-1.
GLTF_SPECULAR_COLOUR = 1.0 / GLTF_F0


def _linear8(img):
    return np.round(np.clip(img, 0.0, 1.0) * 255).astype(np.uint8)


#: A unit square in glTF's frame (+Y up) facing up, with texture coordinates (u right, v down
#: as the photographs' pixels): positions, normals, uvs and two triangles.
_SQUARE = (np.array([[-.5, 0, -.5], [.5, 0, -.5], [.5, 0, .5], [-.5, 0, .5]], np.float32),
           np.tile(np.array([0, 1, 0], np.float32), (4, 1)),
           np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32),
           np.array([0, 2, 1, 0, 3, 2], np.uint16))


def gltf_json(materials, matches):
    """``materials.gltf``: glTF 2.0, each material on a unit square in a row (data-URI geometry)."""
    pos, nor, uv, idx = _SQUARE
    blob = b"".join(a.tobytes() for a in (pos, nor, uv, idx))
    views, offset = [], 0
    for a, target in ((pos, 34962), (nor, 34962), (uv, 34962), (idx, 34963)):
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": a.nbytes,
                      "target": target})
        offset += a.nbytes
    accessors = [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                  "min": pos.min(0).tolist(), "max": pos.max(0).tolist()},
                 {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"},
                 {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"},
                 {"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}]
    doc = {"asset": {"version": "2.0", "generator": "skyfit-mi export"},
           "extensionsUsed": ["KHR_materials_specular"], "scene": 0,
           "scenes": [{"nodes": list(range(len(materials)))}], "nodes": [], "meshes": [],
           "materials": [], "accessors": accessors, "bufferViews": views,
           "buffers": [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                        + base64.b64encode(blob).decode()}]}
    for i, m in enumerate(materials):
        p = matches[m.name]["gltf"]["params"]
        doc["materials"].append(_gltf_material(doc, m, p))
        doc["meshes"].append({"name": m.name, "primitives": [{
            "attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3,
            "material": i}]})
        doc["nodes"].append({"name": m.name, "mesh": i, "translation": [1.2 * i, 0.0, 0.0]})
    return json.dumps(doc, indent=1) + "\n"


def _gltf_material(doc, m, p):
    """A glTF material of the gltf match ``p``; a map's textures are added to ``doc``."""
    spec = p["KHR_materials_specular"]
    if m.maps is None:
        return {"name": m.name, "pbrMetallicRoughness": {
                    "baseColorFactor": [float(v) for v in p["baseColorFactor"]],
                    "metallicFactor": float(p["metallicFactor"]),
                    "roughnessFactor": float(p["roughnessFactor"])},
                "extensions": {"KHR_materials_specular": {
                    "specularFactor": float(spec["specularFactor"]),
                    "specularColorFactor": [float(v) for v in spec["specularColorFactor"]]}}}
    doc.setdefault("samplers", [{"magFilter": 9728, "minFilter": 9728}])
    tex = {}
    for key, uri in TEXTURE_FILES["gltf"].items():
        doc.setdefault("images", []).append({"uri": uri})
        doc.setdefault("textures", []).append({"sampler": 0, "source": len(doc["images"]) - 1})
        tex[key] = {"index": len(doc["textures"]) - 1}
    return {"name": m.name, "pbrMetallicRoughness": {
                "baseColorTexture": tex["baseColorTexture"],
                "metallicRoughnessTexture": tex["metallicRoughnessTexture"]},
            "extensions": {"KHR_materials_specular": {
                "specularFactor": float(np.max(spec["specularFactor"])),
                "specularTexture": tex["specularTexture"],
                "specularColorFactor": [GLTF_SPECULAR_COLOUR] * 3,
                "specularColorTexture": tex["specularColorTexture"]}}}
