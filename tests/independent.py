"""Sequences the fit's own renderer did not make (issue 13's independent test set).

Each day is first rendered by ``render_sequence`` for its manifest (camera, sky per frame,
sensor); then every frame's radiance is replaced by another renderer's and captured again:

- :func:`radiance_frames`: Radiance (rtrace, from the pyradiance wheel) with gensky's own sky
  and a Radiance ``plastic`` or ``metal`` on a disc or a sphere, each pixel the mean of m x m
  rays over its area (the render's box filter);
- :func:`mitsuba_frames`: Mitsuba's own non-Ward materials (``roughplastic``,
  ``roughconductor``, ``principled``) in place of the region's Ward BSDF, as stand-ins for real
  materials that no Ward model matches exactly.

and :func:`mitsuba_brdf` evaluates such a material at given directions, for observation tables.

Used by tests/test_independent_radiance.py, tests/test_brdf_test_set.py,
scripts/independent_set.py, scripts/sky_test_set.py and scripts/brdf_test_set.py.
"""
import os
import re
import subprocess
from pathlib import Path

import numpy as np

#: Radiance geometry of the project's scenes (scenes/disc.xml, scenes/sphere.xml), material
#: ``mat``: the disc of radius 1 at the origin facing up, the sphere of radius 1 on it.
GEOMETRY = {"disc": "mat ring disc 0 0 8 0 0 0 0 0 1 0 1\n",
            "sphere": "mat sphere ball 0 0 4 0 0 1 1\n"}


def radiance_runner():
    """``run(program, *args, input=None, binary=False)`` -> stdout of a Radiance program of
    the pyradiance wheel (gensky, oconv, rtrace); ImportError where pyradiance is absent."""
    import pyradiance

    root = Path(pyradiance.__file__).parent
    env = dict(os.environ, RAYPATH=f".{os.pathsep}{root / 'lib'}")

    def run(program, *args, input=None, binary=False):
        return subprocess.run([str(root / "bin" / program), *map(str, args)], input=input,
                              capture_output=True, check=True, text=not binary,
                              env=env).stdout
    return run


def gensky_entries(run, date, hours, latitude, longitude, kind="+s"):
    """Spec sky entries of gensky's own descriptions: ``kind`` '+s' clear with sun, '-c'
    overcast, '+i' intermediate with sun; local solar meridian 0 (times in UTC)."""
    month, day = int(date[5:7]), int(date[8:10])
    return [{"type": "gensky",
             "gensky": run("gensky", month, day, h, kind, "-a", latitude, "-o", -longitude,
                           "-m", 0, "-y", int(date[:4]))} for h in hours]


def _copy_frames(out, frames, sensor_seed, trace):
    """Replace each frame's radiance by ``trace(frame)`` (H, W, 3) and capture it again."""
    from skyfit_mi.pipeline.manifest import load_manifest, sensor_from_record
    from skyfit_mi.pipeline.sequence import capture_frame, write_frame

    doc, _ = load_manifest(out)
    sensor = sensor_from_record(doc["sensor"])
    for f, extra in zip(doc["frames"], frames):
        img = trace(f, extra).astype(np.float32)
        values, sigma, _ = capture_frame(sensor, img, None, sensor_seed, f["index"],
                                         doc["camera"]["fov_deg"])
        write_frame(out, f["index"], img, np.zeros_like(img), values, sigma)  # taken as exact


def radiance_frames(run, out, gensky_texts, material, geometry="disc", m=4, sensor_seed=99,
                    region=None):
    """Trace every frame of the sequence folder ``out`` with Radiance: gensky's sky text per
    frame, ``material`` a Radiance primitive named ``mat`` (e.g. 'void plastic mat 0 0 5 r g b
    spec rough'), on GEOMETRY[geometry]; the frames' EXRs and captures are replaced.  With
    ``region`` (x0, y0, x1, y1), inclusive, only its pixels are traced and the others are 0
    (a pixel's noise draw does not depend on the others')."""
    import mitsuba as mi

    from skyfit_mi.pipeline.manifest import load_manifest
    from skyfit_mi.render.scene import pixel_views

    doc, _ = load_manifest(out)
    scene = mi.load_string(doc["scene"]["xml"])
    w, h = doc["camera"]["width"], doc["camera"]["height"]
    x0, y0, x1, y1 = region or (0, 0, w - 1, h - 1)
    px = np.stack(np.meshgrid(np.arange(x0, x1 + 1), np.arange(y0, y1 + 1), indexing="xy"),
                  -1).reshape(-1, 2)
    dirs = -pixel_views(scene, px, m=m).reshape(-1, 3)                 # camera -> scene
    origin = np.asarray(doc["camera"]["to_world"], dtype=float)[:3, 3]
    rays = "".join(f"{origin[0]:.9g} {origin[1]:.9g} {origin[2]:.9g} {d[0]:.9g} {d[1]:.9g} "
                   f"{d[2]:.9g}\n" for d in dirs)
    work = Path(out) / ".radiance"
    work.mkdir(exist_ok=True)

    def trace(frame, sky_text):
        rad = work / "scene.rad"
        rad.write_text(sky_text + "\nskyfunc glow sky_glow 0 0 4 1 1 1 0\n"
                       "sky_glow source sky 0 0 4 0 0 1 360\n" + material + "\n"
                       + GEOMETRY[geometry])
        (work / "scene.oct").write_bytes(run("oconv", rad, binary=True))
        txt = run("rtrace", "-h", "-ab", 1, "-ad", 4096, "-as", 0, "-aa", 0, "-ss", 64,
                  "-st", 0, "-lw", 1e-7, work / "scene.oct", input=rays)
        L = np.array(txt.split(), dtype=float).reshape(len(px), m * m, 3)
        img = np.zeros((h, w, 3))
        img[px[:, 1], px[:, 0]] = L.mean(axis=1)
        return img
    _copy_frames(out, gensky_texts, sensor_seed, trace)


def mitsuba_frames(out, material_id, bsdf_xml, spp=1024, seed=5, sensor_seed=99):
    """Render every frame of ``out`` again with Mitsuba, the material ``material_id``'s Ward BSDF
    replaced by ``bsdf_xml`` (a Mitsuba <bsdf> element without id, e.g. roughplastic)."""
    import mitsuba as mi

    from skyfit_mi.pipeline.manifest import frame_sky, load_manifest
    from skyfit_mi.render.daylight import update_sky
    from skyfit_mi.render.frame import render_with_error

    doc, root = load_manifest(out)
    xml = doc["scene"]["xml"]
    pattern = re.compile(rf'<bsdf type="ward" id="{material_id}">.*?</bsdf>', re.S)
    if not pattern.search(xml):
        raise ValueError(f"no Ward BSDF {material_id!r} in the manifest's scene")
    element = re.sub(r"<bsdf ", f'<bsdf id="{material_id}" ', bsdf_xml.strip(), count=1)
    scene = mi.load_string(pattern.sub(lambda _: element, xml))
    params = mi.traverse(scene)

    def trace(frame, _):
        update_sky(params, frame_sky(frame, root), "sky.")
        img, _ = render_with_error(mi, scene, params, seed + frame["index"], spp // 2)
        return img
    _copy_frames(out, doc["frames"], sensor_seed, trace)


def mitsuba_brdf(bsdf_xml):
    """``reflect(wi, wo, rng)`` -> (P, 3) [sr^-1]: Mitsuba's ``bsdf_xml`` (a <bsdf> element)
    evaluated on a horizontal surface (local frame = world frame) for light arriving from the
    unit directions ``wi`` (P, 3), seen from ``wo`` (P, 3): its ``eval`` (which includes the
    light's cosine) divided by that cosine; the form scripts/bench_core.py ``make_table``
    takes (``rng`` unused: the values are exact)."""
    from skyfit_mi.render import setup

    mi = setup()
    bsdf = mi.load_string(re.sub(r"<bsdf ", '<bsdf version="3.0.0" ', bsdf_xml.strip(),
                                 count=1))

    def reflect(wi, wo, rng):
        wi, wo = (np.asarray(v, dtype=float) for v in (wi, wo))
        si = mi.SurfaceInteraction3f()
        si.n = mi.Vector3f(0.0, 0.0, 1.0)
        si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
        si.wi = mi.Vector3f(*(wo[:, k] for k in range(3)))
        si.uv = mi.Point2f(0.5, 0.5)
        f = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*(wi[:, k] for k in range(3))))
        return np.stack([np.asarray(f[k]) for k in range(3)], axis=1) / wi[:, 2:]
    return reflect


def held_or_warned(names, intervals, warnings, truth):
    """Per parameter: 'in' (its 95% interval holds the truth), 'warned' (outside, but a warning
    names it or says no parameter is reliable), or 'MISSED' (confidently wrong)."""
    out = {}
    for p, t in zip(names, truth):
        lo, hi = intervals[p]["95"]
        out[p] = "in" if lo <= t <= hi else (
            "warned" if any(p in _named(w) or "not reliable" in w for w in warnings)
            else "MISSED")
    return out


def gross_miss(interval, truth):
    """Whether ``truth`` lies beyond the ``interval`` (lo, hi) by more than half its width."""
    lo, hi = interval
    return truth < lo - (hi - lo) / 2 or truth > hi + (hi - lo) / 2


def _named(warning):
    """The parameters a warning opens with ('C_r, rho_s depend on ...': C_r and rho_s)."""
    m = re.match(r"((?:\w+, )*\w+)[ :]", warning)
    return m.group(1).split(", ") if m else []
