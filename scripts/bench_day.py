"""Benchmark: the 13-frame thesis disc day, skyfit vs Radiance rpict at equal noise (issue: sequences).

1. `skyfit render` of scenes/specs/disc_clear_east.toml at 256x256, 64 spp, in a fresh process:
   wall time (imports and JIT compilation included) and peak memory (max RSS); once with the
   spec's smooth metal disc and once with a white Lambertian disc.
2. The Lambertian day in Radiance (pyradiance's rpict): the same CIE clear sky (our Sky written as a
   colorfunc .cal), the same sun disc, disc and camera, sun by direct calculation, sky by
   ambient sampling without caching (-ab 1 -aa 0 -as 0), pixel centres (-pj 0 -ps 1).
   skyfit uses the spec's sampler (multijitter).
3. Equal noise: relative RMSE (RMSE / reference mean) over the disc's interior pixels in the
   noon frame against each renderer's own high-sample reference, corrected for the reference's
   own noise. Radiance's -ad is the smallest of a ladder whose noise is at most skyfit's 64-spp
   noise, and its day is timed with two rpict processes in parallel (the machine has two
   cores, which Mitsuba uses).

    .venv/bin/python scripts/bench_day.py [--ref-spp 4096] [--ref-ad 4096]
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


def skyfit_day(spec_raw, out, spp):
    """Render in a child process; returns (wall seconds, peak RSS MiB, manifest)."""
    spec_raw = json.loads(json.dumps(spec_raw))
    spec_raw["render"]["spp"] = spp
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


def rel_rmse(img, ref, n_img, n_ref):
    """RMSE / mean over the disc interior, removing the reference's own noise (variance ~ 1/n)."""
    m = disc_interior(ref)
    mse = np.mean((img[m] - ref[m]) ** 2) / (1 + n_img / n_ref)
    return float(np.sqrt(mse) / ref[m].mean())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--ref-ad", type=int, default=4096)
    args = ap.parse_args()
    import tomllib
    from skyfit_mi.render.image import read_exr

    raw = tomllib.loads(SPEC.read_text())
    lamb = json.loads(json.dumps(raw))
    lamb["materials"]["disc"] = {"model": "two", "rho_s": 0.0, "sigma_alpha": 0.0}
    lamb["sensor"]["exposure"] = 0.01
    raw["sensor"]["exposure"] = 0.01
    with tempfile.TemporaryDirectory() as tmp:
        t_metal, rss, _ = skyfit_day(raw, Path(tmp) / "metal", 64)
        t_lamb, rss2, man = skyfit_day(lamb, Path(tmp) / "lamb", 64)
        _, _, man_ref = skyfit_day(lamb, Path(tmp) / "lamb_ref", args.ref_spp)
        frame_s = sum(f.get("render_seconds", 0.0) for f in man["frames"])
        steady = 13 * float(np.median([f["render_seconds"] for f in man["frames"][1:]]))
        noon = 6
        ours = read_exr(Path(tmp) / "lamb" / "run" / man["frames"][noon]["radiance"])
        ours_ref = read_exr(Path(tmp) / "lamb_ref" / "run" / man_ref["frames"][noon]["radiance"])
        e_ours = rel_rmse(ours, ours_ref, 64, args.ref_spp)

        f = man["frames"][noon]
        rad_ref = radiance_frame(f, man, tmp, args.ref_ad, "ref")
        # Radiance's stratified ambient sampling does not follow 1/sqrt(ad): probe a ladder of -ad
        # and take the smallest whose noise is at most skyfit's
        probes = {}
        for ad in (2, 3, 4, 6, 8, 11, 16, 23, 32, 45, 64):
            img = radiance_frame(f, man, tmp, ad, f"probe{ad}")
            probes[ad] = rel_rmse(img, rad_ref, ad, args.ref_ad)
            if probes[ad] <= e_ours:
                break
        ad_eq = ad
        t0 = time.perf_counter()
        with ThreadPoolExecutor(2) as pool:
            imgs = list(pool.map(lambda fr: radiance_frame(fr, man, tmp, ad_eq, "day"), man["frames"]))
        t_rad = time.perf_counter() - t0
        e_rad = rel_rmse(imgs[noon], rad_ref, ad_eq, args.ref_ad)
        mean_ratio = float(rad_ref.mean() / ours_ref.mean())

    print("| renderer | disc | frames | resolution | samples | wall time [s] | peak RSS [MiB] | "
          "relative RMSE (noon) |")
    print("|---|---|---|---|---|---|---|---|")
    print(f"| skyfit (Mitsuba, llvm_ad_rgb) | smooth metal (spec) | 13 | 256x256 | 64 spp | "
          f"{t_metal:.1f} | {rss:.0f} | |")
    print(f"| skyfit (Mitsuba, llvm_ad_rgb) | white Lambertian | 13 | 256x256 | 64 spp | {t_lamb:.1f} |"
          f" {max(rss, rss2):.0f} | {e_ours:.4f} |")
    print(f"| skyfit, render calls only | white Lambertian | 13 | 256x256 | 64 spp | {frame_s:.1f} | | |")
    print(f"| skyfit, 13 x median render call after the first (compiled) | white Lambertian | 13 | "
          f"256x256 | 64 spp | {steady:.1f} | | |")
    print(f"| Radiance rpict (2 processes) | white Lambertian | 13 | 256x256 | -ad {ad_eq} | {t_rad:.1f} |"
          f" | {e_rad:.4f} |")
    print(f"\nRadiance / skyfit wall time at equal noise: {t_rad / t_lamb:.2f} (whole process), "
          f"{t_rad / frame_s:.2f} (skyfit's render calls only), {t_rad / steady:.2f} (compiled). "
          f"Mean radiance of the two references (Radiance / skyfit): {mean_ratio:.4f}. "
          f"Probes (-ad: relative RMSE): {', '.join(f'{k}: {v:.4f}' for k, v in probes.items())}; "
          f"references {args.ref_spp} spp and "
          f"-ad {args.ref_ad}. skyfit times are whole processes (imports and JIT compilation "
          f"included); peak RSS is the render process's.")


if __name__ == "__main__":
    main()
