"""The thesis's figures 6.5-6.21, 7.10 and 7.13-7.14 on skyfit's sequences (issue 14).

Run through ``scripts/reproduce_thesis.py --part figures`` (which writes the section into
docs/THESIS_TABLES.md), or alone, which prints the section:

    .venv/bin/python scripts/thesis_figures.py [--figures-dir out/thesis_figures]

Chi-square topologies (figs 6.5-6.10, 6.12-6.13, 6.15, 6.18-6.21): for each figure's scene (the
disc or the sphere, sky, camera side, sensor noise, times) and each of its materials (the
two-parameter model), a synthetic day is rendered (40 N 0 E, 21 June, hourly 06:00-18:00
unless the figure says otherwise; 12-bit sensor, 1024 spp) and chi-square of the figure's
pixels (the disc's centre; four pixels; five across the sphere) is mapped over the thesis's
axes, rho_s 0-1 and sigma_alpha 0-0.2, with the fit's cached model
(:func:`skyfit_mi.fitting.landscape.chi2_map`).  Each panel's topology is summarised in numbers
(where the minimum is, local minima, how much chi-square changes with roughness) beside the
thesis's description of the figure.  Pixel series (6.11, 6.14, 6.17) and the sphere's images
(6.16) come from the same renders.  Fig 7.10 is an annealing walk (table 7.6's smooth metal
disc seen from the east, started in the local minimum) over its map.  Figs 7.13-7.14 are the
sample board (``scenes/specs/board_east_37.toml``) fitted per sample and relit with ``skyfit
relight``: the thesis's were a real sequence; ours is synthetic, its truth known.
"""

import argparse
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: The thesis's chi-square axes: rho_s 0-1, sigma_alpha 0-0.2.
RHO = np.linspace(0.0, 1.0, 41)
SIGMA = np.linspace(0.0, 0.2, 41)
LAMBERTIAN, SMOOTH_METAL, ROUGH_METAL = (0.0, 0.0), (1.0, 0.0), (1.0, 0.2)
TRIPLE = (LAMBERTIAN, SMOOTH_METAL, ROUGH_METAL)
#: (figure, scene, sky, camera azimuth, pixels, noise %, (start, end) hours, materials, what
#: the thesis says of it)
MAPS = [
    ("6.5", "disc", "clear", 0, "centre", 0, None, (LAMBERTIAN,),
     "one minimum, at the truth"),
    ("6.6", "disc", "clear", 0, "centre", 0, None, (SMOOTH_METAL, (0.8, 0.1), ROUGH_METAL),
     "a single minimum, at the truth in each case"),
    ("6.7", "disc", "clear", 90, "centre", 0, None, TRIPLE,
     "ridged, steep around the global minimum; plateaux and local minima away from it (a "
     "non-optimal minimum in (b))"),
    ("6.8", "disc", "clear", 180, "centre", 0, None, TRIPLE,
     "featureless: gloss is told (low chi2 at the right rho_s) but roughness is not, (a) and "
     "(b) do not vary with sigma_alpha"),
    ("6.9", "disc", "intermediate", 90, "centre", 0, None, TRIPLE,
     "like 6.7 with a smaller overall gradient; (b) has a clear local minimum well above the "
     "global one"),
    ("6.10", "disc", "overcast", 90, "centre", 0, None, TRIPLE,
     "low chi2 values, similar surfaces for different materials; (a), (b) slope to a minimum "
     "that covers a region; in (c) minimisation gives the wrong parameters"),
    ("6.12", "disc", "clear", 90, "centre", 5, None, TRIPLE,
     "topology as 6.7; noise lowers chi2 and its gradient"),
    ("6.13", "disc", "clear", 90, "centre", 10, None, TRIPLE,
     "topology still as 6.7; lower values and gradient again"),
    ("6.15", "disc", "clear", 90, "four", 0, None, TRIPLE,
     "as 6.7 but steeper and smoother (more pixels)"),
    ("6.18", "sphere", "clear", 90, "five", 0, None, TRIPLE,
     "similar to 6.7 and 6.15"),
    ("6.19", "sphere", "clear", 180, "five", 0, None, TRIPLE,
     "more detail than the disc from the south (6.8): the metals' roughness is now observable"),
    ("6.20", "sphere", "overcast", 90, "five", 0, None, TRIPLE,
     "smoothed by more pixels, but for the rough metal the minimum is not at (1, 0.2)"),
    ("6.21", "disc", "clear", 0, "centre", 0, (12, 16), TRIPLE,
     "a short sequence (12:00-16:00): compare 6.5-6.6"),
]
PANELS = "abc"


def spec(scene, sky, azimuth, noise, hours, material, seed):
    """The raw spec of one case: the thesis's disc experiment, or the sphere (radius 1, seen
    from 8 m at 45 degrees, 32x32 pixels over 20 degrees)."""
    from skyfit_mi.pipeline.spec import thesis_disc_spec

    m = {"model": "two", "rho_s": material[0], "sigma_alpha": material[1]}
    raw = thesis_disc_spec(f"fig-{scene}-{seed}", m, camera_azimuth_deg=azimuth,
                           noise_percent=noise, seed=seed,
                           sky="intermediate" if sky == "intermediate" else sky)
    if sky == "intermediate":
        raw["sky"]["phi"] = 0.5                     # thesis 6.9: phi = 0.5
    if hours is not None:
        raw["time"].update(start=f"{hours[0]:02d}:00", end=f"{hours[1]:02d}:00")
    if scene == "sphere":
        raw["scene"] = {"file": "sphere.xml"}
        raw["materials"] = {"sphere": m}
        raw["camera"].update(distance=8.0, target=[0.0, 0.0, 1.0], fov_deg=20.0, width=32,
                             height=32)
    return raw


class Renders:
    """Each case rendered once (by its spec), into a work folder."""

    def __init__(self, work):
        self.work, self.done = Path(work), {}

    def get(self, *case):
        from skyfit_mi.pipeline.sequence import render_sequence
        from skyfit_mi.pipeline.spec import validate_spec

        if case not in self.done:
            out = self.work / f"seq{len(self.done):03d}"
            raw = spec(*case, seed=len(self.done))
            render_sequence(validate_spec(raw, self.work), out, progress=False,
                            log=lambda *a: None, overwrite=True)
            self.done[case] = out
        return self.done[case]


def pixels(kind, seq, material_id):
    """The figure's pixels: the image centre, four around it, or five across the sphere
    (its centre and half a radius up, down, left and right of it, from the label image)."""
    from skyfit_mi.pipeline.pixels import scene_labels

    if kind == "centre":
        return np.array([[8, 8]])
    if kind == "four":
        return np.array([[5, 5], [10, 5], [5, 10], [10, 10]])
    _, _, labels, ids = scene_labels(seq)
    ys, xs = np.nonzero(labels == ids.index(material_id) + 1)
    cx, cy, r = xs.mean(), ys.mean(), 0.5 * np.sqrt(len(xs) / np.pi)
    return np.array([[round(cx + dx * r), round(cy + dy * r)]
                     for dx, dy in ((0, 0), (-1, 0), (1, 0), (0, -1), (0, 1))])


def topology(chi2, truth, sigma=SIGMA):
    """Numbers that describe a map (rows sigma_alpha ``sigma``, columns rho_s RHO): where its
    minimum is and whether that is the truth (sigma_alpha not counted when rho_s = 0, where it
    has no meaning), its other local minima (lower than their 8 neighbours, 2 cells or more
    from the global one, higher than it by more than 1; the lowest one's chi2 above the
    global minimum), and how much chi2 changes with
    sigma_alpha at the truth's rho_s, relative to the map's range."""
    from scipy.ndimage import minimum_filter

    j, i = np.unravel_index(np.argmin(chi2), chi2.shape)
    dr, ds = RHO[1] - RHO[0], sigma[1] - sigma[0]
    at_truth = abs(RHO[i] - truth[0]) <= dr + 1e-9 and (
        truth[0] == 0 or abs(sigma[j] - truth[1]) <= ds + 1e-9)
    lo = chi2.min()
    local = (chi2 <= minimum_filter(chi2, size=3, mode="nearest")) & (chi2 > lo + 1.0)
    jj, ii = np.nonzero(local)
    far = np.maximum(np.abs(jj - j), np.abs(ii - i)) >= 2
    others = sorted(zip(chi2[jj[far], ii[far]], RHO[ii[far]], sigma[jj[far]]))
    col = chi2[:, int(np.argmin(np.abs(RHO - truth[0])))]
    span = max(chi2.max() - lo, 1e-300)
    return {"minimum": (float(RHO[i]), float(sigma[j])), "at_truth": bool(at_truth),
            "chi2_min": float(lo), "chi2_median": float(np.median(chi2)),
            "local_minima": len(others),
            "lowest_local": (others[0][1], others[0][2], float(others[0][0] - lo))
            if others else None,
            "sigma_sensitivity": float((col.max() - col.min()) / span)}


def describe(t):
    text = (f"min at ({t['minimum'][0]:.3f}, {t['minimum'][1]:.3f})"
            f"{' = truth' if t['at_truth'] else ' (NOT the truth)'}; chi2 min {t['chi2_min']:.3g}, "
            f"median {t['chi2_median']:.3g}; ")
    if t["local_minima"]:
        r, s, rise = t["lowest_local"]
        text += (f"{t['local_minima']} other local minima (lowest at ({r:.3f}, {s:.3f}), "
                 f"{rise:.3g} above the global one); ")
    else:
        text += "no other local minimum; "
    return text + f"roughness changes chi2 by {t['sigma_sensitivity']:.1%} of the range at the truth's rho_s"


def panel_figure(path, title, maps, truths, walk=None, sigma=SIGMA):
    """One PNG of a figure's panels (:func:`~skyfit_mi.fitting.landscape.draw_chi2_map` over
    rho_s and ``sigma``), the truth and each map's minimum marked."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from skyfit_mi.files import save_figure
    from skyfit_mi.fitting.landscape import draw_chi2_map

    fig, axes = plt.subplots(1, len(maps), figsize=(4.4 * len(maps), 3.8), squeeze=False,
                             layout="constrained")
    for k, (ax, chi2, truth) in enumerate(zip(axes[0], maps, truths)):
        j, i = np.unravel_index(np.argmin(chi2), chi2.shape)
        draw_chi2_map(fig, ax, "rho_s", "sigma_alpha", RHO, sigma, chi2,
                      {"truth": truth, "map minimum": (RHO[i], sigma[j])}, walk)
        ax.set_title(f"({PANELS[k]}) rho_s = {truth[0]}, sigma_alpha = {truth[1]}", fontsize=8)
    fig.suptitle(title, fontsize=9)
    save_figure(fig, path)


def series_figure(path, title, panels, ylabel="pixel value [DN]"):
    """Pixel values through the day: one panel per entry (label, times, {curve: values})."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from skyfit_mi.files import save_figure

    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.2), squeeze=False)
    for ax, (label, hours, curves) in zip(axes[0], panels):
        for name, v in curves.items():
            ax.plot(hours, v, "o-", ms=3, label=name)
        ax.set_title(label, fontsize=8)
        ax.set_xlabel("hour (UTC)")
        ax.set_ylabel(ylabel)
        ax.legend(fontsize=6)
    fig.suptitle(title, fontsize=9)
    save_figure(fig, path)


def _green(seq, px):
    """The sensor's green value [DN] of pixels ``px`` through the day, (P, T), and the hours."""
    from skyfit_mi.pipeline.manifest import load_manifest, rendered_frames
    from skyfit_mi.pipeline.pixels import frame_values

    doc, _ = load_manifest(seq)
    frames = rendered_frames(doc)
    hours = [int(f["time"][11:13]) + int(f["time"][14:16]) / 60 for f in frames]
    return frame_values(seq, px, [f["index"] for f in frames], "sensor")[..., 1], hours


def chi2_maps(renders, out, log):
    """The topology figures; returns markdown rows and the maps by (figure, panel)."""
    from skyfit_mi.fitting.fit import FitCache, FitSession
    from skyfit_mi.fitting.landscape import chi2_map

    rows, maps = [], {}
    for fig, scene, sky, az, kind, noise, hours, materials, says in MAPS:
        panel_maps = []
        for k, m in enumerate(materials):
            seq = renders.get(scene, sky, az, noise, hours, m)
            px = pixels(kind, seq, scene)
            s = FitSession(seq, scene, px, model="two", cache=FitCache(seed=0))
            chi2 = chi2_map(s, np.array(m), "rho_s", "sigma_alpha", RHO, SIGMA)
            panel_maps.append(chi2)
            maps[fig, k] = (chi2, seq, px)
            t = topology(chi2, m)
            label = f"{fig}({PANELS[k]})" if len(materials) > 1 else fig
            rows.append(f"| {label} | {scene}, {sky}, camera {_side(az)}, {len(px)} px, "
                        f"{noise}% noise{'' if hours is None else f', {hours[0]}-{hours[1]} h'}"
                        f" | ({m[0]}, {m[1]}) | {says if k == 0 else '〃'} | {describe(t)} |")
            log(rows[-1])
        panel_figure(out / f"fig_{fig.replace('.', '_')}.png",
                     f"Fig. {fig}: chi2 over (rho_s, sigma_alpha), {scene}, {sky} sky, camera "
                     f"{_side(az)}, {len(px)} pixel(s), {noise}% noise", panel_maps, materials)
    return rows, maps


def _side(azimuth):
    return {0: "north", 90: "east", 180: "south"}[azimuth]


def series(renders, maps, out):
    """Figs 6.11, 6.14, 6.16, 6.17 from the maps' renders; returns markdown rows."""
    from skyfit_mi.pipeline.manifest import load_manifest, read_frame_image
    from skyfit_mi.render.image import to_srgb8, write_png

    rows = []
    curves = {}
    for fig, noise in (("6.7", 0), ("6.12", 5), ("6.13", 10)):
        v, hours = _green(maps[fig, 2][1], maps[fig, 2][2])
        curves[f"{noise}% noise"] = v[0]
    series_figure(out / "fig_6_11.png", "Fig. 6.11: a pixel of the rough metal disc (camera "
                  "east) at 0, 5 and 10% noise", [("(1.0, 0.2)", hours, curves)])
    rows.append("| 6.11 | the rough metal disc's centre pixel at 0, 5, 10% noise | noisy values "
                "scatter about the clean series | " + _spread(curves) + " |")
    for fig, source, n in (("6.14", "6.15", 4), ("6.17", "6.18", 5)):
        panels, peaks = [], []
        for k, m in enumerate(TRIPLE):
            v, hours = _green(maps[source, k][1], maps[source, k][2])
            panels.append((f"({PANELS[k]}) {m}", hours,
                           {f"pixel {tuple(p)}": row for p, row in zip(maps[source, k][2], v)}))
            peaks.append(f"({PANELS[k]}) peak hours {sorted(set(hours[i] for i in v.argmax(axis=1)))}"
                         f", spread across pixels {np.ptp(v, axis=0).max() / max(v.max(), 1):.1%}"
                         " of the peak")
        series_figure(out / f"fig_{fig.replace('.', '_')}.png",
                      f"Fig. {fig}: {n} pixels through the day", panels)
        rows.append(f"| {fig} | {n} pixels of fig {source}'s {'disc' if n == 4 else 'sphere'} | "
                    + ("Lambertian: no difference; smooth metal: slight; rough metal: peaks in "
                       "different frames" if n == 4 else "Lambertian: shading varies; smooth "
                       "metal: highlight missed; rough metal: sampled, peaks differ")
                    + " | " + "; ".join(peaks) + " |")
    seq = maps["6.18", 0][1]
    doc, root = load_manifest(seq)
    shape = (doc["camera"]["height"], doc["camera"]["width"], 3)
    frames = [f for f in doc["frames"] if f["time"][11:16] in ("08:00", "12:00", "14:00", "18:00")]
    images = [read_frame_image(root, f, "radiance", shape) for f in frames]
    scale = 0.8 / max(np.percentile(np.concatenate([i.ravel() for i in images]), 99), 1e-12)
    write_png(out / "fig_6_16.png", np.concatenate([to_srgb8(i, scale) for i in images], axis=1))
    rows.append("| 6.16 | the Lambertian sphere from the east at 08, 12, 14, 18 h | shading "
                "varies across the sphere | fig_6_16.png (one exposure for all four) |")
    return rows


def _spread(curves):
    clean = curves["0% noise"]
    return "; ".join(f"{k}: rms difference from the clean {np.sqrt(np.mean((v - clean) ** 2)):.1f} DN"
                     for k, v in curves.items() if k != "0% noise")


def random_walk(renders, out):
    """Fig 7.10: annealing over the 4x4-pixel map of table 7.6's smooth metal disc (camera
    east), started in its local minimum; returns a markdown row."""
    from skyfit_mi.fitting.chi2 import parse_region
    from skyfit_mi.fitting.fit import FitCache, FitSession
    from skyfit_mi.fitting.landscape import chi2_map

    seq = renders.get("disc", "clear", 90, 0, None, SMOOTH_METAL)
    s = FitSession(seq, "disc", parse_region("rect:6,6,9,9"), model="two", cache=FitCache(seed=0))
    start = (0.2, 0.2)
    r = s.run("anneal", start=start, seed=0, log=lambda *a: None)
    walk = np.asarray(r["trace"], dtype=float)
    wide = np.linspace(0.0, float(s.upper[-1]), 51)         # the walk's whole range
    chi2 = chi2_map(s, np.array(SMOOTH_METAL), "rho_s", "sigma_alpha", RHO, wide)
    panel_figure(out / "fig_7_10.png", "Fig. 7.10: an annealing walk over chi2 (smooth metal "
                 "disc, camera east, 16 pixels), from (0.2, 0.2)", [chi2], [SMOOTH_METAL], walk,
                 wide)
    end = [r["parameters"][k] for k in ("rho_s", "sigma_alpha")]
    return (f"| 7.10 | annealing over table 7.6's map, from the local minimum (0.2, 0.2) | "
            f"escapes the local minimum and finds the global one | {len(walk)} simplex steps "
            f"recorded; ends at ({end[0]:.3f}, {end[1]:.3f}), truth (1, 0); "
            f"{describe(topology(chi2, SMOOTH_METAL, wide))} |")


def board(work, out, log):
    """Figs 7.13-7.14: the sample board fitted per sample (colour model, 64 pixels each) and
    relit onto its own day; returns markdown rows."""
    from skyfit_mi.cli import main
    from skyfit_mi.pipeline.spec import read_spec

    seq, fits, relit = work / "board", work / "board_fits", work / "board_relit"
    raw = read_spec(ROOT / "scenes" / "specs" / "board_east_37.toml")
    (work / "board.json").write_text(json.dumps({**raw, "scene": {
        "file": str(ROOT / "scenes" / raw["scene"]["file"])}}))
    for args in (["render", work / "board.json", "-o", seq, "-q", "--overwrite"],
                 ["fit", seq, "--all", "-o", fits],
                 ["relight", fits, "--target", seq, "-o", relit, "-q", "--overwrite"]):
        if main([str(a) for a in args]) != 0:
            raise SystemExit(f"skyfit {args[0]} failed")
    from skyfit_mi.fitting.landscape import truth_parameters

    shutil.copy(relit / "contact_sheet.png", out / "fig_7_13.png")
    shutil.copy(relit / "prediction.png", out / "fig_7_14.png")
    for name in ("fits.csv", "relight.json"):
        shutil.copy((fits if name == "fits.csv" else relit) / name, out / f"board_{name}")
    errors = json.loads((relit / "relight.json").read_text())
    rows = []
    for region, e in sorted(errors["regions"].items()):
        r = json.loads((fits / f"fit_{region}.json").read_text())
        names = list(r["parameters"])
        p, t = r["parameters"], truth_parameters(r.get("truth"), r["model"], names,
                                                 r.get("normalisation", "ward"))
        outside = [] if t is None else [n for n, v in zip(names, t)
                                        if not r["intervals"][n]["95"][0] - 1e-9 <= v
                                        <= r["intervals"][n]["95"][1] + 1e-9]
        truth = r.get("truth") or {}
        rows.append(f"| {region} | C ({p['C_r']:.3f}, {p['C_g']:.3f}, {p['C_b']:.3f}), rho_s "
                    f"{p['rho_s']:.3f}, sigma_alpha {p['sigma_alpha']:.3f} | C {truth.get('C')},"
                    f" rho_s {truth.get('rho_s')}, sigma_alpha {truth.get('sigma_alpha')} | "
                    + ("?" if t is None else "yes" if not outside else "no: " + ", ".join(outside))
                    + f" | {e['rel_rms']:.2%} | {len(r['warnings'])}: "
                    + " / ".join(w.split(":")[0][:70] for w in r["warnings"]) + " |")
        log(rows[-1])
    rows.append(f"| all | | | | {errors['rel_rms']:.2%}; observed region means in the 95% "
                f"band: {errors['band_coverage']['share']:.0%} of "
                f"{errors['band_coverage']['values']} | |")
    return rows


def figures(work, out, log=print):
    """Every figure into ``out``; returns the markdown section."""
    out.mkdir(parents=True, exist_ok=True)
    renders = Renders(work)
    map_rows, maps = chi2_maps(renders, out, log)
    other_rows = series(renders, maps, out)
    other_rows.append(random_walk(renders, out))
    log(other_rows[-1])
    board_rows = board(Path(work), out, log)
    return ["## Figures 6.5-6.21, 7.10, 7.13-7.14", "",
            f"PNGs in `{out.relative_to(ROOT) if out.is_relative_to(ROOT) else out}` (not in "
            "git; the command regenerates them). Chi-square maps over rho_s 0-1 x sigma_alpha "
            "0-0.2 (41 x 41), the two-parameter model; 'range' is the map's chi2 max - min. "
            "Method in `scripts/thesis_figures.py`.", "",
            "| figure | scene | truth (rho_s, sigma_alpha) | the thesis says | ours |",
            "|---|---|---|---|---|", *map_rows, "",
            "| figure | what | the thesis shows | ours |", "|---|---|---|---|", *other_rows, "",
            "### Figs 7.13-7.14: the sample board, fitted and relit", "",
            "The thesis's figures are of its real board sequence; ours is the synthetic board of "
            "`scenes/specs/board_east_37.toml` (its materials are the truth); photographs of a "
            "real board are read by `skyfit ingest SPEC PHOTOS...` and fitted and relit the same "
            "way ([cli.md](cli.md)). fig_7_13.png is the relit day's contact "
            "sheet, fig_7_14.png each sample's predicted series with its 95% band and the "
            "observed values.", "",
            "| sample | fitted | truth | truth in the 95% intervals | relit vs observed (rel. "
            "RMS; the relit day shares the target's seeds) | warnings (their first words) |",
            "|---|---|---|---|---|---|", *board_rows, ""]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--figures-dir", default="out/thesis_figures",
                    help="folder of the figures' PNGs (default out/thesis_figures)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        section = figures(Path(tmp), Path(args.figures_dir).resolve())
    print("\n".join(section))


if __name__ == "__main__":
    main()
