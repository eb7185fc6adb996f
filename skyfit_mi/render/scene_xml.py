"""Scenes from the Mitsuba XML files in ``scenes/`` plus a spec's materials, sky and camera.

A scene file holds geometry and ``ward`` materials with ids, which the spec may override.  The
loader adds the ``cie_sky`` emitter (id ``sky``), an optional ground plane, the integrator and
the camera.
"""

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..errors import SkyfitError
from ..physics.ward import MODELS, raw_parameters
from .scene import camera_matrix, load_xml

_SCALAR_TAGS = {"float": float, "integer": int, "string": str,
                "boolean": lambda v: v.lower() == "true"}


def _value(el):
    v = el.get("value")
    if el.tag in ("rgb", "vector", "point"):
        return [float(x) for x in v.replace(",", " ").split()]
    return _SCALAR_TAGS[el.tag](v)


def scene_materials(tree):
    """The ``ward`` materials of a parsed scene: {id: {model, normalisation, parameters}}."""
    out = {}
    for el in tree.iter("bsdf"):
        if el.get("type") == "ward" and el.get("id"):
            params = {c.get("name"): _value(c) for c in el if c.tag in (*_SCALAR_TAGS, "rgb")}
            params.setdefault("model", "raw")
            params.setdefault("normalisation", "ward")
            out[el.get("id")] = params
    return out


def resolve_materials(scene_file, overrides):
    """Scene materials with the spec's ``overrides`` applied, validated."""
    try:
        tree = ET.parse(scene_file)
    except ET.ParseError as exc:
        raise SkyfitError(f"scene file {scene_file} is not valid XML ({exc}); repair it or "
                          "choose a shipped scene.") from None
    mats = scene_materials(tree)
    for name, m in overrides.items():
        if name not in mats:
            raise SkyfitError(f"material {name!r} is not a ward material of {scene_file.name}; "
                              f"its materials are: {', '.join(mats) or 'none'}.")
        same_model = m.get("model", mats[name]["model"]) == mats[name]["model"]
        mats[name] = {**mats[name], **m} if same_model else {"normalisation": "ward", **m}
        mats[name].setdefault("source", "spec")
    for name, m in mats.items():
        m.setdefault("source", f"scene {Path(scene_file).name}")
        params = {k: v for k, v in m.items() if k in MODELS[m["model"]]}
        rho_d, rho_s, sigma = raw_parameters(m["model"], **params)
        m["raw"] = {"rho_d": rho_d.tolist(), "rho_s": rho_s.tolist(), "sigma_alpha": sigma}
    return tree, mats


def sub_element(parent, tag, **attrs):
    """A child ``tag`` of ``parent`` with the attributes ``attrs`` (their values as text)."""
    return ET.SubElement(parent, tag, {k: str(v) for k, v in attrs.items()})


def ward_element(el, name, m):
    """Make ``el`` the ``ward`` plugin element ``name`` of material ``m`` (model, normalisation
    and its parameters), its earlier children removed."""
    for child in list(el):
        el.remove(child)
    el.attrib = {"type": "ward", "id": name}
    sub_element(el, "string", name="model", value=m["model"])
    sub_element(el, "string", name="normalisation", value=m["normalisation"])
    for k in MODELS[m["model"]]:
        v = m[k]
        if isinstance(v, (list, tuple)):
            sub_element(el, "string", name=k, value=" ".join(repr(float(x)) for x in v))
        else:
            sub_element(el, "float", name=k, value=repr(float(v)))


def build_scene_xml(spec):
    """The full scene XML of a validated spec, and (materials, camera to_world)."""
    tree, mats = resolve_materials(spec.scene_file, spec.materials)
    root = tree.getroot()
    for el in root.iter("bsdf"):
        if el.get("type") == "ward" and el.get("id") in mats:
            ward_element(el, el.get("id"), mats[el.get("id")])
    ground = spec.raw["scene"].get("ground_albedo")
    if ground is not None:
        g = sub_element(root, "shape", type="rectangle", id="ground")
        tr = sub_element(g, "transform", name="to_world")
        sub_element(tr, "scale", value=1000)
        sub_element(tr, "translate", x=0, y=0, z=-0.002)
        b = sub_element(g, "bsdf", type="diffuse")
        sub_element(b, "rgb", name="reflectance", value=float(ground))
    sub_element(root, "emitter", type="cie_sky", id="sky")
    integ = sub_element(root, "integrator", type=spec.render["integrator"], id="integrator")
    sub_element(integ, "integer", name="max_depth", value=spec.render["max_depth"])
    cam = spec.camera
    to_world = camera_matrix(cam)
    sensor = sub_element(root, "sensor", type="perspective", id="camera")
    sub_element(sensor, "float", name="fov", value=float(cam["fov_deg"]))
    sub_element(sensor, "string", name="fov_axis", value="x")
    tr = sub_element(sensor, "transform", name="to_world")
    sub_element(tr, "matrix", value=" ".join(repr(float(x)) for x in to_world.ravel()))
    film = sub_element(sensor, "film", type="hdrfilm")
    sub_element(film, "integer", name="width", value=int(cam["width"]))
    sub_element(film, "integer", name="height", value=int(cam["height"]))
    sub_element(film, "string", name="pixel_format", value="rgb")
    sub_element(film, "rfilter", type="box")
    sampler = sub_element(sensor, "sampler", type=spec.render["sampler"])
    # the count of each of the render's two passes, which the sampler accepts as it is
    sub_element(sampler, "integer", name="sample_count",
         value=pass_spp(spec.render["spp"], spec.render["sampler"]))
    return ET.tostring(root, encoding="unicode"), mats, to_world


def pass_spp(spp, sampler):
    """Samples per pixel of each of the two passes: half of ``spp``, rounded to a square for
    the stratified samplers."""
    half = max(1, int(spp) // 2)
    if sampler in ("multijitter", "stratified"):
        half = max(1, int(round(np.sqrt(half)))) ** 2
    return half


def load_scene(spec):
    """Load a spec's scene into Mitsuba; returns (scene, params, materials, to_world, xml)."""
    import mitsuba as mi

    xml, mats, to_world = build_scene_xml(spec)
    try:
        scene = load_xml(xml)
    except RuntimeError as exc:
        raise SkyfitError(f"Mitsuba could not load {spec.scene_file.name} with the spec's "
                          f"materials: {str(exc).splitlines()[-1]}") from None
    return scene, mi.traverse(scene), mats, to_world, xml
