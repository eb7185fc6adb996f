"""Benchmark: the 13-frame thesis disc day, skyfit vs Radiance rpict at equal noise (issue: sequences).

1. `skyfit render` of scenes/specs/disc_clear_east.toml at 256x256, 64 spp, in a fresh process:
   wall time (imports and JIT compilation included) and peak memory (max RSS); with the spec's
   smooth metal disc, a white Lambertian disc and a glossy Ward plastic (rho_s 0.1, sigma_alpha
   0.1), each with both integrators a spec may choose (``path``, the old default, and
   ``sun_sky_path``), back to back in the same run.
2. The Lambertian day in Radiance (pyradiance's rpict): the same CIE clear sky (our Sky written as a
   colorfunc .cal), the same sun disc, disc and camera, sun by direct calculation, sky by
   ambient sampling without caching (-ab 1 -aa 0 -as 0), pixel centres (-pj 0 -ps 1).
   skyfit uses the spec's sampler (multijitter).
3. Equal noise: relative RMSE (RMSE / reference mean) over the disc's interior pixels against
   each renderer's own high-sample reference (skyfit's: sun_sky_path at --ref-spp, its own
   radiance_sigma removed; Radiance's: -ad --ref-ad, whose noise is left in: at -ad 4096 it is
   under 1% of the compared RMSE), at noon and, for the glossy disc, also at 16:00 (the
   lobe toward the camera).  For each skyfit integrator Radiance's -ad is the smallest of a
   ladder whose noise is at most skyfit's 64-spp noise, and that day is timed with two rpict
   processes in parallel (the machine has two cores, which Mitsuba uses).

    .venv/bin/python scripts/bench_day.py [--ref-spp 1024] [--ref-ad 4096]
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SPEC = ROOT / "scenes" / "specs" / "disc_clear_east.toml"
CAL = """{ skyfit CIE clear pattern with a sharp horizon: A1-A3 clear weight, A4-A6 ground, A7-A9 sun }
cosz = Dx*A7 + Dy*A8 + Dz*A9;
cz = if(cosz - 1, 1, if(-1 - cosz, -1, cosz));
gam = if(Dz - .01, 1 - exp(-.32/Dz), 1);
pat = (.91 + 10*exp(-3*Acos(cz)) + .45*cz*cz) * gam;
skr = if(Dz, A1*pat, A4);
skg = if(Dz, A2*pat, A5);
skb = if(Dz, A3*pat, A6);
"""


def skyfit_day(spec_raw, out, spp, integrator, times=None):
    """Render in a child process (only ``times``, 'HH:MM', if given); returns (wall seconds,
    peak RSS MiB of the children so far, manifest)."""
    spec_raw = json.loads(json.dumps(spec_raw))
    spec_raw["render"].update(spp=spp, integrator=integrator)
    if times is not None:
        spec_raw["time"] = {"date": spec_raw["time"]["date"], "times": times}
    spec_raw["camera"].update(width=256, height=256)
    path = Path(out) / "spec.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(spec_raw))
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "skyfit_mi.cli", "render", str(path), "-o",
                    str(Path(out) / "run"), "-q", "--overwrite"], check=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return wall, rss, json.loads((Path(out) / "run" / "manifest.json").read_text())


def radiance_frame(frame, manifest, tmp, ad, tag):
    """Render one frame with rpict; returns the image (H, W, 3) [W m^-2 sr^-1]."""
    import pyradiance
    bindir = Path(pyradiance.__file__).parent / "bin"
    env = dict(os.environ, RAYPATH=f".{os.pathsep}{Path(pyradiance.__file__).parent / 'lib'}")
    s = frame["illumination"]
    sd = s["sun_direction"]
    diam = float(np.degrees(2 * np.arccos(1 - s["sun_solid_angle_sr"] / (2 * np.pi))))
    args9 = [*s["clear"], *s["ground"], *sd]
    rad = (f"void colorfunc skyfunc\n4 skr skg skb skyfit.cal\n0\n9 {' '.join(map(repr, args9))}\n"
           "skyfunc glow sky_glow 0 0 4 1 1 1 0\nsky_glow source sky 0 0 4 0 0 1 360\n"
           f"void light solar 0 0 3 {' '.join(map(repr, s['sun_radiance']))}\n"
           f"solar source sun 0 0 4 {sd[0]!r} {sd[1]!r} {sd[2]!r} {diam!r}\n"
           "void plastic white 0 0 5 1 1 1 0 0\nwhite ring disc 0 0 8 0 0 0 0 0 1 0 1\n")
    d = Path(tmp) / f"{tag}_{frame['index']}"
    d.mkdir(parents=True, exist_ok=True)
    (d / "skyfit.cal").write_text(CAL)
    (d / "scene.rad").write_text(rad)
    octree = subprocess.run([bindir / "oconv", "scene.rad"], cwd=d, env=env, capture_output=True,
                            check=True).stdout
    (d / "scene.oct").write_bytes(octree)
    m = np.array(manifest["camera"]["to_world"])
    o, fwd, up = m[:3, 3], m[:3, 2], m[:3, 1]
    fov = manifest["camera"]["fov_deg"]
    view = ["-vtv", "-vp", *map(str, o), "-vd", *map(str, fwd), "-vu", *map(str, up),
            "-vh", str(fov), "-vv", str(fov)]
    pic = subprocess.run([bindir / "rpict", *view, "-x", "256", "-y", "256", "-pa", "0", "-pj", "0",
                          "-ps", "1", "-pt", "0", "-ab", "1", "-ad", str(ad), "-as", "0", "-aa", "0",
                          "-lw", "1e-5", "-dj", "0", "-ds", "0", "scene.oct"], cwd=d, env=env,
                         capture_output=True, check=True).stdout
    txt = subprocess.run([bindir / "pvalue", "-h", "-H", "-d", "-o"], input=pic, env=env,
                         capture_output=True, check=True).stdout.decode()
    return np.array(txt.split(), dtype=float).reshape(256, 256, 3)


def disc_interior(ref):
    """Pixels at least 2 pixels inside the disc's edge (both renderers estimate the same smooth
    radiance there; edge pixels measure anti-aliasing, which rpict -pj 0 does not do)."""
    lum = ref.mean(axis=2)
    inside = lum > 0.5 * (np.percentile(lum, 5) + np.percentile(lum, 95))
    for _ in range(2):
        inside = inside & np.roll(inside, 1, 0) & np.roll(inside, -1, 0) \
            & np.roll(inside, 1, 1) & np.roll(inside, -1, 1)
    return inside


def rel_rmse(img, ref, mask, ref_sd=0.0):
    """RMSE / mean over the pixels of ``mask``, the reference's own noise (its standard error
    ``ref_sd``, per pixel or one number) removed."""
    ref_var = np.broadcast_to(np.square(ref_sd), ref.shape)[mask]
    mse = np.mean((img[mask] - ref[mask]) ** 2) - np.mean(ref_var)
    return float(np.sqrt(max(mse, 0.0)) / ref[mask].mean())


def frame_at(man, run, clock, kind="radiance"):
    """The image ``kind`` of the frame of manifest ``man`` (folder ``run``) at 'HH:MM'."""
    from skyfit_mi.render.image import read_exr
    f = next(f for f in man["frames"] if f["time"][11:16] == clock)
    return read_exr(Path(run) / f[kind])


LADDER = (2, 3, 4, 6, 8, 11, 16, 23, 32, 45, 64, 90, 128)
INTEGRATORS = ("path", "sun_sky_path")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--ref-ad", type=int, default=4096)
    args = ap.parse_args()
    import tomllib

    raw = tomllib.loads(SPEC.read_text())
    raw["sensor"]["exposure"] = 0.01
    discs = {"smooth metal (spec)": raw["materials"]["disc"],
             "white Lambertian": {"model": "two", "rho_s": 0.0, "sigma_alpha": 0.0},
             "Ward plastic rho_s 0.1, sigma 0.1": {"model": "two", "rho_s": 0.1,
                                                   "sigma_alpha": 0.1}}
    specs = {}
    for name, m in discs.items():
        specs[name] = json.loads(json.dumps(raw))
        specs[name]["materials"]["disc"] = m
    lamb, glossy = "white Lambertian", "Ward plastic rho_s 0.1, sigma 0.1"
    clocks = {lamb: ["12:00"], glossy: ["12:00", "16:00"]}
    rows, errors, rss = [], {}, 0.0
    with tempfile.TemporaryDirectory() as tmp:
        refs = {}
        for name in clocks:
            out = Path(tmp) / f"ref_{len(refs)}"
            refs[name] = (out / "run", skyfit_day(specs[name], out, args.ref_spp, "sun_sky_path",
                                                  clocks[name])[2])
        mask = disc_interior(frame_at(refs[lamb][1], refs[lamb][0], "12:00"))
        for k, (name, s) in enumerate(specs.items()):
            for integ in INTEGRATORS:
                out = Path(tmp) / f"day_{k}_{integ}"
                wall, rss, man = skyfit_day(s, out, 64, integ)
                calls = sum(f.get("render_seconds", 0.0) for f in man["frames"])
                steady = 13 * float(np.median([f["render_seconds"] for f in man["frames"][1:]]))
                err = {}
                for clock in clocks.get(name, []):
                    run, mref = refs[name]
                    err[clock] = rel_rmse(frame_at(man, out / "run", clock),
                                          frame_at(mref, run, clock), mask,
                                          frame_at(mref, run, clock, "radiance_sigma"))
                errors[name, integ] = err
                rows.append((f"skyfit {integ}", name, "64 spp", wall, calls, steady, err))
                if name == lamb:
                    man_lamb = man

        # Radiance: the noon frame's reference and a ladder of -ad; the day at each equal -ad
        noon = next(f for f in man_lamb["frames"] if f["time"][11:16] == "12:00")
        rad_ref = radiance_frame(noon, man_lamb, tmp, args.ref_ad, "ref")
        probes = {}
        for ad in LADDER:
            probes[ad] = rel_rmse(radiance_frame(noon, man_lamb, tmp, ad, f"probe{ad}"), rad_ref,
                                  mask)
            if probes[ad] <= min(e["12:00"] for (n, _), e in errors.items() if n == lamb):
                break
        rad = {}
        for integ in INTEGRATORS:
            target = errors[lamb, integ]["12:00"]
            ad_eq = next((a for a in probes if probes[a] <= target), max(probes))
            t0 = time.perf_counter()
            with ThreadPoolExecutor(2) as pool:
                list(pool.map(lambda fr: radiance_frame(fr, man_lamb, tmp, ad_eq, f"day{ad_eq}"),
                              man_lamb["frames"]))
            rad[integ] = (ad_eq, time.perf_counter() - t0)
            rows.append((f"Radiance rpict (2 processes), equal noise to skyfit {integ}", lamb,
                         f"-ad {ad_eq}", rad[integ][1], None, None, {"12:00": probes[ad_eq]}))
        mean_ratio = float(rad_ref[mask].mean()
                           / frame_at(refs[lamb][1], refs[lamb][0], "12:00")[mask].mean())

    print("| renderer | disc | samples | wall time [s] | render calls [s] | 13 x median call [s] | "
          "relative RMSE 12:00 | 16:00 |")
    print("|---|---|---|---|---|---|---|---|")
    for who, disc, samples, wall, calls, steady, err in rows:
        cells = [f"{v:.1f}" if v is not None else "" for v in (wall, calls, steady)]
        cells += [f"{err[c]:.4f}" if c in err else "" for c in ("12:00", "16:00")]
        print(f"| {who} | {disc} | {samples} | {' | '.join(cells)} |")
    print(f"\nPeak RSS of the render processes: {rss:.0f} MiB.")
    for integ in INTEGRATORS:
        r = next(x for x in rows if x[0] == f"skyfit {integ}" and x[1] == lamb)
        ad_eq, t_rad = rad[integ]
        print(f"Radiance / skyfit {integ} time at equal noise (-ad {ad_eq}): "
              f"{t_rad / r[3]:.2f} (whole process), {t_rad / r[4]:.2f} (render calls), "
              f"{t_rad / r[5]:.2f} (compiled); above 1 means skyfit is faster.")
    print(f"Mean radiance of the two noon references (Radiance / skyfit): {mean_ratio:.4f}. "
          f"Probes (-ad: relative RMSE): {', '.join(f'{k}: {v:.4f}' for k, v in probes.items())}; "
          f"references: skyfit sun_sky_path {args.ref_spp} spp, Radiance -ad {args.ref_ad}. "
          "skyfit wall times are whole processes (imports and JIT compilation included).")


if __name__ == "__main__":
    main()
