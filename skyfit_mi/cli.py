"""The ``skyfit`` command: thin argument parsing over the package.

Every user error ends in one line on stderr naming the input and what is allowed, exit
code 2; Ctrl-C exits 130 (SIGTERM: 143), keeps what was finished and says what running the
command again does (:data:`_AGAIN`: a render resumes, fits already written stay);
``--debug`` shows the traceback of any error.
"""

import argparse
import os
import re
import signal
import sys
import threading
from contextlib import contextmanager
from pathlib import Path

#: NumPy's BLAS on one thread unless the environment says otherwise, set before NumPy loads:
#: Dr.Jit's pool uses every core, and OpenBLAS's spinning threads took CPU time from it.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402 -- after the BLAS setting

from . import __version__  # noqa: E402
from .errors import SetupError, SkyfitError  # noqa: E402
from .files import FolderLock, check_dir, write_json  # noqa: E402
from .physics.sky import MEASURED_SUN_SD, SKY_CHOICES, SUN_LEVEL_SD  # noqa: E402
from .fitting.chi2 import REGION_PIXELS  # noqa: E402
from .physics.ward import NORMALISATIONS  # noqa: E402
from .pipeline.sky_series import (BRACKET_GAP_S, CARD_MAX_GAP_S, CARD_REFLECTANCE,  # noqa: E402
                                  CARD_SD, LENSES, SERIES_NAME)
from .render.light_cache import DIRECTIONS, POSITIONS  # noqa: E402
from .render.variant import VARIANTS  # noqa: E402
# The modules above are light; each command imports its heavy ones when it runs, so that
# `skyfit --help` loads neither Mitsuba nor matplotlib.

DESCRIPTION = ("Render daylight image sequences, fit Ward reflection models to them, and map "
               "the materials a camera sees.")
#: A region's name becomes part of file names (fit_NAME.json): letters, digits, _ . -
REGION_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")


class _Parser(argparse.ArgumentParser):
    """argparse with its errors as one line: what was wrong and where to read more."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see `{self.prog} --help`)\n")


# ---- argument types: each raises ArgumentTypeError, which argparse turns into one line -------
def _int_in(lo, hi=None):
    def parse(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
        if v < lo or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(
                f"{v} is outside [{lo}, {hi}]" if hi is not None else f"{v} is below {lo}")
        return v
    parse.__name__ = "whole number"
    return parse


def _numbers(text):
    try:
        values = [float(v) for v in text.split(",")]
        if not all(abs(v) < float("inf") for v in values):          # NaN fails too
            raise ValueError
        return values
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not comma-separated finite numbers "
                                         "(e.g. 0.5,0.1)") from None


def _pose_sd(text):
    """``--pose-sd-deg``: one number of degrees, checked as the spec's pose_sd_deg."""
    from .render.scene import pose_sd

    try:
        return pose_sd(float(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc) if isinstance(exc, SkyfitError)
                                         else f"{text!r} is not a number of degrees") from None


def _named(text, what="NAME=VALUE"):
    name, sep, value = text.partition("=")
    if not sep or not REGION_NAME.match(name):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not {what} with NAME of letters, digits, '_', '.' or '-'")
    return name, value


def _label(text):
    name, value = _named(text)
    try:
        v = int(value)
        if not 0 < v < 65536:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: the label VALUE must be a whole number "
                                         "1-65535 (a mask value)") from None
    return name, v


def _region(text):
    from .fitting.chi2 import parse_region

    if "=" not in text and REGION_NAME.match(text):
        return text, None                                 # a region of an observation table
    name, value = _named(text, "NAME=rect:x0,y0,x1,y1 or NAME=pixels:x,y;x,y")
    try:
        return name, parse_region(value)
    except SkyfitError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _frame_list(text):
    """'0-6,9' -> [0, 1, ..., 6, 9] (manifest frame indices)."""
    out = set()
    for part in text.split(","):
        m = re.fullmatch(r"\s*(\d+)\s*(?:-\s*(\d+)\s*)?", part)
        if not m or (m.group(2) is not None and int(m.group(2)) < int(m.group(1))):
            raise argparse.ArgumentTypeError(f"{text!r} is not a frame list; give indices and "
                                             "ranges such as 0-6,9.")
        out.update(range(int(m.group(1)), int(m.group(2) or m.group(1)) + 1))
    return sorted(out)


# ---- commands ---------------------------------------------------------------------------------
def _render(args):
    from .pipeline.sequence import render_sequence
    from .pipeline.spec import read_spec, validate_spec

    raw = read_spec(args.spec)
    if args.variant:                      # over the spec's [render] variant
        raw["render"] = {**raw.get("render", {}), "variant": args.variant}
    render_sequence(validate_spec(raw, Path(args.spec).parent), args.output,
                    overwrite=args.overwrite, progress=not args.quiet)


def _reflectance(text):
    """MATERIAL=RHO[+-SD]: (name, rho (3,), sd (3,) or None); RHO one number or R,G,B, SD an
    absolute reflectance or N% of RHO."""
    name, value = _named(text, "MATERIAL=REFLECTANCE[+-SD]")
    value, pm, err = value.partition("+-")
    try:
        rho = [float(v) for v in value.split(",")]
        if len(rho) not in (1, 3) or not all(0.0 < v <= 1.0 for v in rho):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give the reference's reflectance as one "
                                         "number or R,G,B, each in (0, 1]") from None
    rho = rho * 3 if len(rho) == 1 else rho
    if not pm:
        return name, rho, None
    try:
        sd = [float(err[:-1]) / 100.0 * r for r in rho] if err.endswith("%") \
            else [float(err)] * 3
        if not all(0.0 <= e < r for e, r in zip(sd, rho)):          # NaN fails too
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give the reflectance's standard error after "
                                         "+- as a number below it or a percentage (e.g. "
                                         f"{name}=0.18+-0.005 or {name}=0.18+-3%)") from None
    return name, rho, sd


def _ingest(args):
    from .pipeline.ingest import ingest

    for name, n in (("--site", (2, 3)), ("--noise", (2,))):
        v = getattr(args, name[2:])
        if v is not None and len(v) not in n:
            raise SkyfitError(f"{name} takes {' or '.join(map(str, n))} comma-separated numbers, "
                              f"got {len(v)}.")
    if args.site is not None and not (abs(args.site[0]) <= 90 and abs(args.site[1]) <= 180):
        raise SkyfitError(f"--site {args.site[0]:g},{args.site[1]:g}: give the latitude in "
                          "[-90, 90] (north) and the longitude in [-180, 180] (east), degrees.")
    if args.table is not None:
        from .pipeline.observation_table import ingest_table

        photo_only = [k for k in ("times", "name_pattern", "response", "gamma", "exposure",
                                  "colorchecker", "noise", "colour_matrix_error",
                                  "register_limit") if getattr(args, k) is not None]
        photo_only += ["vignetting"] * (args.vignetting != "none") + \
            ["no_register"] * args.no_register
        if args.photos or photo_only:
            what = "photographs" if args.photos else "--" + photo_only[0].replace("_", "-")
            raise SkyfitError(f"--table takes no {what}: the table gives frames, values and "
                              "sigmas; give either photographs or --table.")
        rho, sd = _references(args.calibrate)
        ingest_table(args.table, args.spec, args.output, tz=args.tz, site=args.site,
                     calibrate=rho, reference_sd=sd, scale_unknown=args.unknown_scale,
                     overwrite=args.overwrite)
        return
    if args.unknown_scale:
        raise SkyfitError("--unknown-scale belongs to --table (photographs take their scale "
                          "from --exposure, --calibrate or --colorchecker).")
    if not args.photos:
        raise SkyfitError("give photographs (files or folders), or --table OBS.csv.")
    rho, sd = _references(args.calibrate)
    ingest(args.photos, args.spec, args.output, times_csv=args.times,
           name_pattern=args.name_pattern, tz=args.tz, site=args.site, response=args.response,
           gamma=args.gamma, exposure=args.exposure, calibrate=rho, reference_sd=sd,
           colorchecker=args.colorchecker, vignetting=args.vignetting, noise=args.noise,
           colour_matrix_error=args.colour_matrix_error, register=not args.no_register,
           exact_curve=args.exact_curve,
           **({} if args.register_limit is None else {"register_limit_px": args.register_limit}),
           overwrite=args.overwrite, progress=not args.quiet)


def _references(triples):
    """``--calibrate`` as ({name: rho}, {name: sd} of those given one); SkyfitError if a name
    comes twice."""
    names = [t[0] for t in triples or []]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise SkyfitError(f"--calibrate names {', '.join(twice)} more than once; give each "
                          "reference's reflectance once.")
    return ({n: rho for n, rho, _ in triples or []},
            {n: sd for n, _, sd in triples or [] if sd is not None})


def _pixels(args):
    from .pipeline.pixels import parse_pixel, write_pixels

    paths = write_pixels(args.manifest, [parse_pixel(p) for p in args.pixel], args.output,
                         args.source)
    print("wrote " + " and ".join(str(p) for p in paths))


def _fit_regions(args):
    """(name, pixels) of every region the arguments ask for, checked before any fitting."""
    from .pipeline.manifest import is_table, load_manifest

    doc = load_manifest(args.manifest)[0]
    regions = list(args.region or [])
    if args.label and args.mask is None:
        raise SkyfitError("--label NAME=VALUE needs --mask PNG (a label image of the frames' size).")
    if args.mask is not None and not args.label:
        raise SkyfitError("--mask needs at least one --label NAME=VALUE (which mask value is "
                          "which material).")
    if args.label:
        from .fitting.chi2 import region_from_mask
        cam = doc["camera"]
        regions += [(name, region_from_mask(args.mask, value, (cam["height"], cam["width"])))
                    for name, value in args.label]
    if args.all:
        from .pipeline.pixels import material_regions
        regions += material_regions(args.manifest, getattr(args, "pose_sd_deg", None), log=print)
    if is_table(doc):
        if any(px is not None for _, px in regions):
            raise SkyfitError("the sequence is an observation table: name its regions alone "
                              "(--region NAME, or --all), without pixels or a mask.")
    elif any(px is None for _, px in regions):
        name = next(n for n, px in regions if px is None)
        raise SkyfitError(f"--region {name} names no pixels; give {name}=rect:x0,y0,x1,y1 or "
                          f"{name}=pixels:x,y;... (a bare name is for observation tables).")
    if not regions:
        raise SkyfitError("give at least one --region NAME=rect:... (or --mask and --label, or --all).")
    names = [n for n, _ in regions]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise SkyfitError(f"region {twice[0]!r} is given twice; give each region once (its "
                          f"fit is written to fit_{twice[0]}.json).")
    return regions


def _fit(args):
    from .fitting.chi2 import chosen_frames, subsample_region
    from .fitting.fit import FitCache, fit_regions
    from .fitting.light import LightOptions
    from .fitting.report import write_fit, write_summary
    from .pipeline.fit_result import check_fit_folder
    from .pipeline.manifest import is_table, load_manifest
    from .render.fit_model import BY_COUNT, check_fit_normalisation, check_start

    auto = args.model == "auto"
    model = "two" if auto else BY_COUNT[int(args.model)]
    check_fit_normalisation(args.normalisation)          # before the costly light cache
    if auto and (args.sky_shape or args.method != "global" or args.start is not None):
        raise SkyfitError("--model auto ranks every lobe and parameter count by the global "
                          "method, on the spec's sky's shape: leave out --sky-shape, --method "
                          "and --start (or give a model: 2, 3 or 5).")
    doc, root = load_manifest(args.manifest)
    if args.start is not None:
        check_start(model, args.start)
    if args.frames is not None and not is_table(doc):
        chosen_frames(doc, root, args.frames)            # before any region's line
    map_only = [f"--{k.replace('_', '-')}" for k in ("patch", "workers", "scheduler", "chunk")
                if getattr(args, k) not in (None, 1)] + (["--overwrite"] if args.overwrite else [])
    if map_only and not args.per_pixel:
        raise SkyfitError(f"{map_only[0]} belongs to a map: add --per-pixel (or leave it out).")
    region_only = [f"--{k.replace('_', '-')}" for k, default in (
                       ("frames", None), ("positions", None), ("directions", DIRECTIONS),
                       ("method", "global"), ("start", None), ("pose_sd_deg", None))
                   if getattr(args, k) != default]
    if region_only and args.per_pixel:
        raise SkyfitError(f"{region_only[0]} belongs to region fits; a map fits every frame "
                          "by its own grid and light cache: leave out --per-pixel or "
                          f"{region_only[0]}.")
    regions = _fit_regions(args)
    if args.per_pixel and (args.sky_shape or args.sky_departure):
        given = "--sky-shape" if args.sky_shape else "--sky-departure"
        raise SkyfitError(f"{given} belongs to region fits; a map takes the spec's sky's "
                          "shape at the level its regions fit (leave out --per-pixel or "
                          f"{given}).")
    light = LightOptions(args.sky, args.sun_sd, args.sky_terms, args.sky_shape,
                         False if args.per_pixel else args.sky_departure)
    if args.per_pixel:
        from .fitting.pixel_map import CHUNK, ClusterOptions, MapOptions, run_map

        if any(px is None for _, px in regions):
            raise SkyfitError("an observation table has no pixels to map; fit its regions "
                              "without --per-pixel.")
        out = Path(args.output) if args.output else root / "pixel_map"
        options = MapOptions("auto" if auto else model, args.normalisation, args.seed,
                             args.patch, args.chunk or CHUNK, variant=args.variant, light=light,
                             light_pixels=args.max_pixels)
        cluster = ClusterOptions(args.workers, args.scheduler, dask_logs=args.debug)
        s = run_map(args.manifest, regions, out, options, cluster, overwrite=args.overwrite,
                    progress=not args.quiet)
        for name, r in s["regions"].items():
            med = ", ".join(f"{k} = {v:.4g}" for k, v in r["median"].items() if v is not None)
            kind = f" ({r['normalisation']} {r['model']})" if auto else ""
            each = ", ".join(f"{k} {v}" for k, v in r["determined_by_parameter"].items())
            print(f"{name}{kind}: {r['determined']} of {r['mapped']} pixels determined in "
                  f"every parameter ({each})" + (f"; medians {med}" if med else ""))
        print(f"wrote the maps and map_summary.json in {out} ({s['wall_time_s']:.1f} s)")
        return
    out = check_dir(Path(args.output) if args.output else root)
    with FolderLock(out):                # one fit at a time into a folder
        check_fit_folder(out, doc.get("run_id"), [name for name, _ in regions])
        kept = {}
        for name, pixels in regions:
            kept[name] = pixels if pixels is None else subsample_region(
                pixels, args.max_pixels or None, args.seed)
            if pixels is not None and len(kept[name]) < len(pixels):
                print(f"{name}: fitting {len(kept[name])} of its {len(pixels)} pixels "
                      f"(--max-pixels, seed {args.seed})")
        cache = FitCache(args.positions, args.directions, pose_sd_deg=args.pose_sd_deg)
        # every region's light traced together, and checked before the first is written
        if auto:
            from .fitting.selection import fit_auto

            results = fit_auto(args.manifest, list(kept.items()), seed=args.seed, cache=cache,
                               frames=args.frames, variant=args.variant, light=light)
        else:
            results = fit_regions(args.manifest, list(kept.items()), model=model,
                                  method=args.method, normalisation=args.normalisation,
                                  seed=args.seed, start=args.start, cache=cache, frames=args.frames,
                                  variant=args.variant, light=light)
        for (name, pixels), res in zip(regions, results):
            res["region_pixels_total"] = int(len(res.get("pixels") or res["points"])
                                             if pixels is None else len(pixels))
            paths = write_fit(res, out / f"fit_{name}")
            summary = write_summary(out)              # after each region: agrees with the JSONs
            print("wrote " + " and ".join(str(p) for p in paths) + f"; updated {summary}")


def _relight(args):
    from .fitting.relight import relight
    from .pipeline.fit_result import load_fits

    relight(load_fits(args.fits), args.target, args.output, images=not args.no_images,
            draws=args.draws, seed=args.seed, overwrite=args.overwrite, progress=not args.quiet,
            reference=args.reference)


def _export(args):
    from .pipeline.export import export

    export(args.fits, args.output, args.format, overwrite=args.overwrite)


def _chi2map(args):
    from .fitting.fit import FitCache, FitSession
    from .fitting.landscape import (chi2_map, map_axes, map_prefix, profiled_map,
                                    truth_parameters, write_chi2_map)
    from .pipeline.fit_result import check_fit_sequence, read_fit_result
    from .pipeline.manifest import load_manifest
    from .render.fit_model import PARAMETERS

    doc, root = load_manifest(args.manifest)
    r = read_fit_result(args.fit)
    check_fit_sequence(r, args.fit, doc, args.manifest)
    names = list(PARAMETERS[r["model"]])
    xs, ys = map_axes(r["model"], args.x, args.y, args.x_range, args.y_range, args.n,
                      args.profile)
    name = f"chi2map_{r['region']}_{args.x}_{args.y}"
    prefix = map_prefix(args.output or root, name, args.overwrite)
    with FolderLock(prefix.parent):      # one map at a time into a folder
        s = FitSession.from_fit(r, args.manifest, cache=FitCache(seed=args.seed),
                                frames=r.get("frames"))
        theta = np.array([r["parameters"][k] for k in names])
        chi2 = (profiled_map(s, theta, args.x, args.y, xs, ys) if args.profile
                else chi2_map(s, theta, args.x, args.y, xs, ys))
        ix, iy = names.index(args.x), names.index(args.y)
        j, i = np.unravel_index(np.argmin(chi2), chi2.shape)
        marks = {"fit": (theta[ix], theta[iy]), "map minimum": (xs[i], ys[j])}
        truth = truth_parameters(r.get("truth"), r["model"], names, r.get("normalisation", "ward"))
        if truth is not None:
            marks["truth"] = (truth[ix], truth[iy])
        walk = np.asarray(r.get("trace") or [], dtype=float)
        walk = walk[:, [ix, iy]] if args.walk and walk.ndim == 2 and len(walk) > 1 else None
        others = "at their best" if args.profile else "at the fit"
        paths = write_chi2_map(prefix, args.x, args.y, xs, ys, chi2, marks, walk, others,
                               record={"region": r["region"], "fit": str(args.fit),
                                       "sequence": str(root), "seed": args.seed,
                                       "profile": bool(args.profile),
                                       "frames": r.get("frames")})
        print(f"{r['region']}: chi2 minimum {chi2.min():.6g} at {args.x} = {xs[i]:.4g}, "
              f"{args.y} = {ys[j]:.4g} (the fit: {theta[ix]:.4g}, {theta[iy]:.4g}); wrote "
              + " and ".join(str(p) for p in paths))


def _range(text):
    v = _numbers(text)
    if len(v) != 2:
        raise argparse.ArgumentTypeError(f"{text!r}: give a range as LO,HI.")
    return v


def _labels(args):
    from .pipeline.pixels import scene_labels
    from .render.image import write_png

    out = Path(args.output) if args.output else None
    if out is not None and out.suffix.lower() != ".png":
        raise SkyfitError(f"-o {args.output}: the label mask is a PNG (lossless); give a path "
                          "ending in .png.")
    _, root, labels, ids = scene_labels(args.manifest)
    out = out or root / "labels.png"
    write_png(out, np.repeat(labels[..., None], 3, axis=2).astype(np.uint8))
    legend = {name: k + 1 for k, name in enumerate(ids)}
    write_json(out.with_suffix(".json"), {"labels": legend, "0": "no material"})
    print(f"wrote {out} (pixel value = material label) and {out.with_suffix('.json')}: "
          + ", ".join(f"{k}={v}" for k, v in legend.items()))


def _camera(args):
    from .pipeline.camera_pose import estimate_camera, point_text, read_points, write_camera
    from .pipeline.photos import read_photo

    if args.photo:
        photo = read_photo(args.photo)
        width, height = photo.width, photo.height
    elif args.width and args.height:
        width, height = args.width, args.height
    else:
        raise SkyfitError("give the photograph's size: --photo PHOTO, or --width and --height "
                          "[px].")
    if args.distortion is not None and len(args.distortion) not in (1, 2):
        raise SkyfitError("--distortion takes K1 or K1,K2 (OpenCV's radial terms).")
    if args.target is not None and len(args.target) != 3:
        raise SkyfitError("--target takes X,Y,Z [m] (east, north, up).")
    points = read_points(args.points, width, height)
    est = estimate_camera(points, width, height, args.fov_deg, args.distortion, args.marking_px,
                          args.target)
    if args.photo:
        from dataclasses import replace

        est = replace(est, photo=Path(args.photo).name)
    toml, report = write_camera(est, args.output, args.overwrite, str(args.points))
    p = est.placement()
    fov = (f"{p['fov_deg'][0]:.2f} deg (given)" if "focal" not in est.free else
           f"{p['fov_deg'][0]:.2f} +- {p['fov_deg'][1]:.2f} deg")
    err = np.hypot(*est.residuals.T)
    print(f"camera from {len(err)} points: azimuth {p['azimuth_deg'][0]:.2f} +- "
          f"{p['azimuth_deg'][1]:.2f} deg, {p['angle_deg'][0]:.2f} +- {p['angle_deg'][1]:.2f} "
          f"deg from vertical, {p['distance_m'][0]:.3f} +- {p['distance_m'][1]:.3f} m from "
          f"{point_text(est.target)}, fov {fov} "
          "(1 sigma, marks "
          f"{est.sigma_px:.2g} px); "
          f"reprojection rms {np.sqrt(np.mean(err ** 2)):.2f} px, max {err.max():.2f} px "
          f"({est.points.names[int(np.argmax(err))]}); wrote {toml} and {report}")


_MANIFEST_HELP = "folder written by `skyfit render` (or its manifest.json)"


def _add_run_folder(parser):
    """The output folder of a run that writes a sequence folder: -o, --overwrite, -q."""
    parser.add_argument("-o", "--output", required=True, help="output folder (created if needed)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace another run's output in the folder (starts clean)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")


def _add_render(sub, common):
    """The ``render`` sub-command: a spec -> a sequence folder."""
    render = sub.add_parser(
        "render", parents=[common], help="render the day a sequence spec describes",
        description="Render the day a sequence spec describes into a folder (frames, manifest, "
        "contact sheet); an interrupted run resumes. Reference: docs/cli.md.")
    render.add_argument("spec", help="sequence spec (.toml or .json), e.g. "
                        "scenes/specs/disc_clear_east.toml")
    _add_run_folder(render)
    render.add_argument("--variant", choices=VARIANTS,
                        help="Mitsuba variant, over the spec's [render] variant (cuda_ad_rgb: GPU)")
    render.set_defaults(func=_render)


def _add_ingest(sub, common):
    """The ``ingest`` sub-command: photographs (or a table) -> a sequence folder."""
    ing = sub.add_parser(
        "ingest", parents=[common], help="photographs of a day -> a sequence folder",
        description="Turn photographs of a day, or a table of measured radiances, into the "
        "sequence folder `render` writes, for fit, relight and chi2map. Reference: docs/cli.md.")
    ing.add_argument("spec", help="spec (.toml/.json) with [location], [camera], [scene], [sky]; "
                     "the photographs give the times")
    ing.add_argument("photos", nargs="*",
                     help="image files or folders (EXR, HDR, TIFF, PNG, JPEG, camera RAW)")
    ing.add_argument("--table", metavar="CSV",
                     help="measured radiances instead of photographs (format: docs/MANIFEST.md)")
    _add_run_folder(ing)
    ing.add_argument("--times", metavar="CSV",
                     help="CSV file,time of each frame's time (instead of EXIF DateTimeOriginal)")
    ing.add_argument("--name-pattern", metavar="PATTERN",
                     help="times from the file names, e.g. 'IMG_%%Y%%m%%d_%%H%%M%%S.jpg'")
    ing.add_argument("--tz", help="time zone of times without an offset (IANA name such as "
                     "'Europe/London', or '+01:00')")
    ing.add_argument("--site", type=_numbers, metavar="LAT,LON[,ALT]",
                     help="site in degrees (north, east) and metres, overriding the spec's")
    ing.add_argument("--response", choices=("srgb", "gamma", "linear", "fit"),
                     help="the encoding to invert (default the spec's [sensor], else the files'; "
                     "fit: from the greys)")
    ing.add_argument("--gamma", type=float, help="exponent of a gamma response")
    ing.add_argument("--exact-curve", action="store_true",
                     help="the codes follow the response's curve exactly (written from linear "
                     "values by software); default for codes read through a curve: a camera's "
                     "own tone curve, whose error the intervals count")
    ing.add_argument("--exposure", type=float,
                     help="absolute exposure of the first frame [sr m^2 W^-1]")
    ing.add_argument("--calibrate", action="append", type=_reflectance,
                     metavar="MATERIAL=REFLECTANCE[+-SD]", help="a grey Lambertian scene "
                     "material of this reflectance (or R,G,B) to calibrate by, and its standard "
                     "error (absolute, or N%%), which the intervals count; repeatable")
    ing.add_argument("--unknown-scale", action="store_true",
                     help="with --table: values in the instrument's units, put on a relative scale")
    ing.add_argument("--colorchecker", metavar="MATERIAL",
                     help="calibrate by a ColorChecker Classic lying on this scene material")
    ing.add_argument("--vignetting", default="none", metavar="none|corrected|cos4|FLAT",
                     help="none (not corrected: its error counted), corrected (by the camera), "
                     "the cos^4 law, or a flat-field image (default none)")
    ing.add_argument("--noise", type=_numbers, metavar="READ,SHOT",
                     help="read variance [DN^2] and shot gain [DN] (default estimated from frames)")
    ing.add_argument("--colour-matrix-error", type=float, metavar="SD",
                     help="relative error of each colour matrix entry (default 0.03 RAW, else 0)")
    ing.add_argument("--no-register", action="store_true",
                     help="take the frames as aligned (default: their shifts and turns are undone)")
    ing.add_argument("--register-limit", type=float, metavar="PX",
                     help="refuse a frame that moved more than this [px] (default 5)")
    ing.set_defaults(func=_ingest)


def _add_camera(sub, common):
    """The ``camera`` sub-command: marked points of a photograph -> the spec's [camera]."""
    cam = sub.add_parser(
        "camera", parents=[common], help="the camera's pose and lens from marked points",
        description="Estimate the camera's pose, field of view and radial distortion, with their "
        "uncertainty, from points marked in one photograph whose scene positions were measured; "
        "writes the spec's [camera] table (TOML) and a JSON report. Reference: docs/cli.md.")
    cam.add_argument("points", help="CSV: name (optional), x_px, y_px (column, row), X, Y, Z "
                     "(east, north, up [m])")
    cam.add_argument("--photo", help="the photograph marked (gives the image size; ingest "
                     "registers the frames on it)")
    cam.add_argument("--width", type=_int_in(1, 16384), help="image width [px] (without --photo)")
    cam.add_argument("--height", type=_int_in(1, 16384), help="image height [px]")
    cam.add_argument("--fov-deg", type=float,
                     help="horizontal field of view [deg] if known (4 points; else fitted, from 6)")
    cam.add_argument("--distortion", type=_numbers, metavar="K1[,K2]",
                     help="known radial distortion, refused where the marks reach half-way to "
                     "the corners and fitting k1 lowers their chi-square by over 9. Without it, "
                     "k1 (and k2 from 10 points reaching 70%%) is fitted when the marks reach "
                     "half-way to the corners, with --fov-deg only if that lowers their "
                     "chi-square by over 9; else 0")
    cam.add_argument("--marking-px", type=float, default=0.5,
                     help="standard deviation of a mark [px] (default 0.5)")
    cam.add_argument("--target", type=_numbers, metavar="X,Y,Z",
                     help="point the pose is given from [m] (default the points' centroid)")
    cam.add_argument("-o", "--output", required=True,
                     help="camera TOML path (the JSON report is written beside it)")
    cam.add_argument("--overwrite", action="store_true", help="replace existing output files")
    cam.set_defaults(func=_camera)


def _sky_series(args):
    from .pipeline.sky_series import CardOptions, ShotOptions, sky_series

    card = None
    if args.card:
        if args.card_box is None:
            raise SkyfitError("--card needs --card-box X0,Y0,X1,Y1: the card's pixels in its "
                              "shots.")
        if len(args.card_box) != 4:
            raise SkyfitError(f"--card-box takes four numbers X0,Y0,X1,Y1, got "
                              f"{len(args.card_box)}.")
        if any(v != int(v) for v in args.card_box):
            raise SkyfitError("--card-box takes whole pixels X0,Y0,X1,Y1.")
        card = CardOptions(tuple(args.card), tuple(int(v) for v in args.card_box),
                           args.card_reflectance, args.card_max_gap_s, args.card_sd)
    elif args.card_box is not None:
        raise SkyfitError("--card-box belongs to --card (the grey card's shots).")
    doc = sky_series(args.photos, args.output, card=card, tz=args.tz, times_csv=args.times,
                     shots=ShotOptions(args.flat, args.lens, args.exact_curve),
                     gap_s=args.bracket_gap_s, overwrite=args.overwrite,
                     log=(lambda *a: None) if args.quiet else print)
    lines = [f"{len(doc['maps'])} sky maps in {args.output}; in the spec:", "[sky]",
             'type = "envmap"',
             f'file = "{(Path(args.output) / SERIES_NAME).resolve().as_posix()}"  # or relative '
             "to the spec's folder",
             "north_rotation_deg = 0.0  # the compass azimuth of the maps' top: measure it"]
    if doc["sun_mask_deg"]:
        lines.append(f"# sun_mask_deg = {doc['sun_mask_deg']} from the clipped sun (the default)")
    if card is None:
        lines.append('# the sun is clipped: give its level, irradiance_file = "irradiance.csv" '
                     "(dhi and dni, or ghi), or photograph a grey card (--card)")
    print("\n".join(lines))


def _add_sky_series(sub, common):
    """The ``sky-series`` sub-command: bracketed fisheye shots of the sky -> linear maps."""
    sky = sub.add_parser(
        "sky-series", parents=[common], help="merge bracketed fisheye shots of the sky into maps",
        description="Merge each exposure bracket of an upward equidistant fisheye into a linear "
        f"EXR map, the sun's level from a grey card; writes {SERIES_NAME} for the spec's [sky] "
        "file. Reference: docs/cli.md.")
    sky.add_argument("photos", nargs="+", help="the sky's shots: files or folders")
    sky.add_argument("-o", "--output", required=True,
                     help=f"output folder (the maps and {SERIES_NAME})")
    sky.add_argument("--tz", help="time zone of EXIF times without an offset (e.g. Europe/Berlin "
                     "or +01:00)")
    sky.add_argument("--times", help="CSV file,time of the shots (and the card's), instead of EXIF")
    sky.add_argument("--flat", help="flat field through the fisheye: a photograph of a uniform "
                     "field, or its linear map (default none)")
    sky.add_argument("--bracket-gap-s", type=float, default=BRACKET_GAP_S,
                     help=f"a gap over this [s] starts a new bracket (default {BRACKET_GAP_S:g})")
    sky.add_argument("--card", nargs="+", help="shots of a horizontal grey card in the sun, one "
                     "near each bracket (files or folders)")
    sky.add_argument("--card-box", type=_numbers, metavar="X0,Y0,X1,Y1",
                     help="the card's pixels in its shots (columns X0..X1-1, rows Y0..Y1-1)")
    sky.add_argument("--card-reflectance", type=float, default=CARD_REFLECTANCE,
                     help=f"the card's reflectance (default {CARD_REFLECTANCE:g})")
    sky.add_argument("--card-max-gap-s", type=float, default=CARD_MAX_GAP_S, help="the longest "
                     f"time between a bracket and its card shot [s] (default {CARD_MAX_GAP_S:g})")
    sky.add_argument("--card-sd", type=float, default=CARD_SD, help="relative sd of the card's "
                     f"reading of the global irradiance (default {CARD_SD:g})")
    sky.add_argument("--lens", choices=LENSES, default="equidistant",
                     help="the fisheye's projection (the maps are written equidistant)")
    sky.add_argument("--exact-curve", action="store_true",
                     help="the JPEGs' codes follow their stated curve (sRGB's) exactly, as "
                     "software writes them from linear values; by default a camera's own tone "
                     "curve is measured on the brackets' overlaps and the shots read through it")
    sky.add_argument("--overwrite", action="store_true", help="replace an existing series")
    sky.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    sky.set_defaults(func=_sky_series)


def _add_pixels(sub, common):
    """The ``pixels`` sub-command: chosen pixels across a sequence."""
    pixels = sub.add_parser(
        "pixels", parents=[common], help="values of chosen pixels across a rendered sequence",
        description="Write chosen pixels' values across a sequence as CSV and a plot. "
        "Reference: docs/cli.md.")
    pixels.add_argument("manifest", help=_MANIFEST_HELP)
    pixels.add_argument("--pixel", action="append", required=True, metavar="X,Y",
                        help="pixel column,row from the top left; repeat for more pixels")
    pixels.add_argument("--source", choices=("radiance", "sensor"), default="radiance",
                        help="radiance (default): the linear radiance frames [W m^-2 sr^-1]; "
                        "sensor: the sensor model's pixel values [DN]")
    pixels.add_argument("-o", "--output",
                        help="output path prefix (default: MANIFEST/pixels_SOURCE)")
    pixels.set_defaults(func=_pixels)


def _add_labels(sub, common):
    """The ``labels`` sub-command: a label-mask PNG of the materials."""
    labels = sub.add_parser(
        "labels", parents=[common], help="label-mask PNG of the materials each pixel sees",
        description="Write a label-mask PNG (pixel value = material) and its legend JSON, for "
        "`skyfit fit --mask`. Reference: docs/cli.md.")
    labels.add_argument("manifest", help=_MANIFEST_HELP)
    labels.add_argument("-o", "--output", help="PNG path (default: MANIFEST/labels.png)")
    labels.set_defaults(func=_labels)


def _add_fit(sub, common):
    """The ``fit`` sub-command: Ward parameters of material regions."""
    fit = sub.add_parser(
        "fit", parents=[common], help="fit Ward parameters to material regions of a sequence",
        description="Fit Ward reflection parameters, with 95% intervals and warnings, to "
        "material regions of a rendered sequence. Reference: docs/cli.md.")
    fit.add_argument("manifest", help=_MANIFEST_HELP)
    fit.add_argument("--region", action="append", type=_region, metavar="NAME=rect:x0,y0,x1,y1",
                     help="a material region (NAME = the material id; the rect's columns x0 to x1 and "
                     "rows y0 to y1, both ends included); also NAME=pixels:x,y;x,y")
    fit.add_argument("--mask", help="label-mask PNG (values per material), with --label")
    fit.add_argument("--label", action="append", type=_label, metavar="NAME=VALUE",
                     help="the mask value of material NAME")
    fit.add_argument("--all", action="store_true",
                     help="fit every Ward material the camera sees (regions from the label image)")
    fit.add_argument("--variant", choices=VARIANTS,
                     help="Mitsuba variant of the fit (default the sequence's; cuda_ad_rgb: GPU)")
    fit.add_argument("--per-pixel", action="store_true",
                     help="material maps: every pixel of the regions (or --patch) its own fit")
    fit.add_argument("--patch", type=_int_in(1, 4096), default=1, metavar="N",
                     help="with --per-pixel: fit N x N blocks of pixels (default 1)")
    fit.add_argument("--workers", type=_int_in(1, 1024), default=None,
                     help="with --per-pixel: local Dask workers (default one per core, as memory "
                     "allows)")
    fit.add_argument("--scheduler", metavar="ADDRESS",
                     help="with --per-pixel: an existing Dask scheduler, e.g. tcp://host:8786")
    fit.add_argument("--chunk", type=_int_in(1, 1 << 20), default=None, metavar="N",
                     help="with --per-pixel: fits per Dask task (default 1024, about 1.1 GB a "
                     "worker)")
    fit.add_argument("--overwrite", action="store_true",
                     help="with --per-pixel: replace another map in the output folder")
    fit.add_argument("-q", "--quiet", action="store_true", help="with --per-pixel: no progress bar")
    fit.add_argument("--max-pixels", type=_int_in(0), default=REGION_PIXELS,
                     help="fit at most this many pixels of a region, a seeded random subset "
                     f"(default {REGION_PIXELS}; 0 = every pixel)")
    fit.add_argument("--model", choices=("2", "3", "5", "auto"), default="5",
                     help="5 (default): C, rho_s, sigma_alpha; 3: R, rho_s, sigma_alpha; "
                     "2: rho_s, sigma_alpha; auto: ranked")
    fit.add_argument("--sky", choices=SKY_CHOICES, default=None,
                     help="spec: as given; fit: the sky's level fitted; prior: that with a prior "
                     "(default prior for photos, else spec)")
    fit.add_argument("--sky-terms", type=int, default=None,
                     help="with --sky fit or prior: Legendre terms of the level over the day, "
                     "1 (one level) to 4 (default 3, the frames less 2 below 5 frames, 1 where "
                     "ingest's --calibrate or --colorchecker set the frames' scale)")
    fit.add_argument("--sky-shape", action="store_true",
                     help="with --sky fit or prior and a CIE, turbid or Perez sky: fit its shape "
                     "too")
    fit.add_argument("--sky-departure", action=argparse.BooleanOptionalAction, default=None,
                     help="with --sky fit or prior: fit the sky's departure from its model "
                     "(default on for photos, off for renders)")
    fit.add_argument("--sun-sd", type=float, default=None,
                     help="with --sky fit or prior: sun level's relative sd (default "
                     f"{SUN_LEVEL_SD}, {MEASURED_SUN_SD} with measured DNI, 0 for renders)")
    fit.add_argument("--method", choices=("global", "lm", "anneal", "adam"), default="global",
                     help="global (default: grid over sigma_alpha, then Levenberg-Marquardt), "
                     "lm, anneal or adam")
    fit.add_argument("--normalisation", choices=NORMALISATIONS, default="ward",
                     help="the specular lobe (default ward; radiance renders but cannot be fitted)")
    fit.add_argument("--start", type=_numbers, metavar="A,B,...",
                     help="starting parameters in the model's order (lm, anneal, adam; default a "
                     "seeded random start)")
    fit.add_argument("--seed", type=_int_in(0, 2**32 - 1), default=0,
                     help="seed of the light cache, random starts and subsets (default 0)")
    fit.add_argument("--positions", type=_int_in(1, 4096), default=None,
                     help=f"light-cache positions per pixel (default {POSITIONS}, grown as the "
                     "data need)")
    fit.add_argument("--directions", type=_int_in(1, 1 << 16), default=DIRECTIONS,
                     help=f"light-cache directions per position (default {DIRECTIONS})")
    fit.add_argument("--pose-sd-deg", type=_pose_sd, default=None, metavar="DEG",
                     help="camera pose's sd in azimuth and in angle from vertical [deg] (default "
                     "the manifest's, else 0)")
    fit.add_argument("--frames", type=_frame_list, metavar="LIST",
                     help="fit only these frames (manifest indices, e.g. 0-6,9; default all)")
    fit.add_argument("-o", "--output", help="output folder (default: the manifest's folder)")
    fit.set_defaults(func=_fit)


def _add_relight(sub, common):
    """The ``relight`` sub-command: render a target with fitted materials."""
    relit = sub.add_parser(
        "relight", parents=[common], help="render a day, sky or camera with fitted materials",
        description="Render a target (a spec, or a sequence folder) with the materials of fits "
        "and, against the target's frames, report the prediction error. Reference: docs/cli.md.")
    relit.add_argument("fits", nargs="+",
                       help="fit_NAME.json files, a fits.csv, or the folder `skyfit fit` wrote")
    relit.add_argument("--target", required=True,
                       help="spec file (.toml/.json) or sequence folder to relight")
    _add_run_folder(relit)
    relit.add_argument("--no-images", action="store_true",
                       help="predict the regions' values only (prediction.csv, relight.json, "
                       "relight.csv)")
    relit.add_argument("--reference", action="store_true",
                       help="a synthetic target: also render its materials with other seeds")
    relit.add_argument("--draws", type=_int_in(2, 100000), default=200,
                       help="parameter draws for the 95%% band (default 200)")
    relit.add_argument("--seed", type=_int_in(0, 2**32 - 1), default=0,
                       help="seed of the parameter draws and the light cache (default 0)")
    relit.set_defaults(func=_relight)


def _add_chi2map(sub, common):
    """The ``chi2map`` sub-command: chi-square over two parameters."""
    cmap = sub.add_parser(
        "chi2map", parents=[common], help="chi-square over two parameters of a fitted region",
        description="Map chi-square over two parameters of a fitted region, the others at the "
        "fit (thesis figs 6.5-6.21, 7.10): CSV and PNG. Reference: docs/cli.md.")
    cmap.add_argument("manifest", help=_MANIFEST_HELP)
    cmap.add_argument("fit", help="the region's fit_NAME.json (its pixels, model and frames)")
    cmap.add_argument("--x", default="rho_s", help="parameter on the x axis (default rho_s)")
    cmap.add_argument("--y", default="sigma_alpha",
                      help="parameter on the y axis (default sigma_alpha)")
    cmap.add_argument("--x-range", type=_range, metavar="LO,HI",
                      help="x axis range (default the parameter's bounds)")
    cmap.add_argument("--y-range", type=_range, metavar="LO,HI",
                      help="y axis range (default the parameter's bounds)")
    cmap.add_argument("--n", type=_int_in(2, 1000), default=60,
                      help="grid points per axis (default 60)")
    cmap.add_argument("--profile", action="store_true",
                      help="every other parameter at its best for each point, not at the fit")
    cmap.add_argument("--walk", action="store_true",
                      help="overlay the fit's walk (its trace, e.g. annealing's)")
    cmap.add_argument("--seed", type=_int_in(0, 2**32 - 1), default=0,
                      help="seed of the light cache (default 0)")
    cmap.add_argument("-o", "--output", help="output path prefix, or a folder to write into "
                      "(default MANIFEST/chi2map_REGION_X_Y)")
    cmap.add_argument("--overwrite", action="store_true",
                      help="replace files of the prefix's names that are not an earlier map's")
    cmap.set_defaults(func=_chi2map)


def _add_export(sub, common):
    """The ``export`` sub-command: fitted materials for other renderers."""
    ex = sub.add_parser(
        "export", parents=[common],
        help="write fitted materials for Mitsuba 3, Radiance and glTF/Blender",
        description="Write fitted materials as Mitsuba 3 XML, Radiance and glTF 2.0, each with "
        "its error against the fit, and export.json. Reference: docs/cli.md.")
    ex.add_argument("fits", nargs="+", help="fit_NAME.json files, a fits.csv, the folder "
                    "`skyfit fit` wrote, or a per-pixel map's folder")
    ex.add_argument("-o", "--output", required=True, help="output folder (created if needed)")
    ex.add_argument("--format", nargs="+", choices=("mitsuba", "radiance", "gltf"),
                    default=["mitsuba", "radiance", "gltf"], help="formats to write (default all)")
    ex.add_argument("--overwrite", action="store_true",
                    help="replace another export in the folder")
    ex.set_defaults(func=_export)


def build_parser():
    """The ``skyfit`` argument parser."""
    parser = _Parser(prog="skyfit", description=DESCRIPTION)
    parser.add_argument("--version", action="version", version=f"skyfit-mi {__version__}")
    debug_help = "show the full traceback of an error, and a map's Dask log (for bug reports)"
    parser.add_argument("--debug", action="store_true", help=debug_help)
    common = _Parser(add_help=False)               # --debug also after the command
    common.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=debug_help)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_render(sub, common)
    _add_ingest(sub, common)
    _add_camera(sub, common)
    _add_sky_series(sub, common)
    _add_pixels(sub, common)
    _add_labels(sub, common)
    _add_fit(sub, common)
    _add_relight(sub, common)
    _add_chi2map(sub, common)
    _add_export(sub, common)
    return parser


def _oneline(exc):
    return " ".join(str(exc).split())


#: The signals that stop a command as Ctrl-C does (SIGTERM: timeout, docker stop, batch
#: systems), with the word its line says; it exits 128 + the signal's number (130, 143).
STOP_SIGNALS = {signal.SIGINT: "interrupted", signal.SIGTERM: "terminated (SIGTERM)"}


@contextmanager
def _ctrl_c_noted():
    """Ctrl-C (or SIGTERM) raises KeyboardInterrupt, so that the run unwinds as on Ctrl-C
    (temporary files removed, locks released), and is noted in the list yielded, so that an
    error raised while it unwinds (e.g. a C++ extension's) is reported as the stop.  In the main
    thread only."""
    pressed = []
    if threading.current_thread() is not threading.main_thread():
        yield pressed
        return

    def on_stop(signum, frame):
        pressed.append(signum)
        raise KeyboardInterrupt

    previous = {s: signal.signal(s, on_stop) for s in STOP_SIGNALS}
    try:
        yield pressed
    except Exception as exc:
        if pressed:
            raise KeyboardInterrupt from exc
        raise
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


#: What an interrupted command keeps and what running it again does, by command.
_AGAIN = {_render: "the finished frames are kept: run the same command again to resume",
          _fit: "the finished regions' fits (and a per-pixel map's chunks) are kept: run the same "
                "command again (a map resumes; regions are fitted again)",
          _relight: "run the same command again (a relit render resumes)",
          None: "nothing unfinished was kept as done: run the same command again to start over"}


#: A comma list of numbers starting with a minus ('-0.1,0.02', a southern latitude), which
#: argparse would take for an option's name.
_NEGATIVE_LIST = re.compile(r"^-[\d.][\deE.+-]*(,[\deE.+-]+)+$")


def _join_negative_lists(parser, argv):
    """``argv`` with each option of comma-separated numbers (type :func:`_numbers`) joined to
    a value starting with a minus (``--site -33.9,151.2`` as ``--site=-33.9,151.2``)."""
    takes = {o for sub in parser._subparsers._group_actions for p in sub.choices.values()
             for a in p._actions if a.type is _numbers for o in a.option_strings}
    out = []
    for a in argv:
        if out and out[-1] in takes and _NEGATIVE_LIST.match(a):
            out[-1] = f"{out[-1]}={a}"
        else:
            out.append(a)
    return out


def main(argv=None):
    """Run ``skyfit`` with ``argv``; returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(_join_negative_lists(
            parser, sys.argv[1:] if argv is None else list(argv)))
    except SystemExit as exc:              # --help, --version, or a usage error (already printed)
        return exc.code
    try:
        with _ctrl_c_noted() as stopped:
            args.func(args)
    except KeyboardInterrupt:
        if args.debug:
            raise
        signum = stopped[0] if stopped else signal.SIGINT
        print(f"skyfit: {STOP_SIGNALS[signum]}; {_AGAIN.get(args.func, _AGAIN[None])}.",
              file=sys.stderr)
        return 128 + signum
    except (SkyfitError, SetupError) as exc:
        if args.debug:
            raise
        print(f"skyfit: error: {_oneline(exc)}", file=sys.stderr)
        return 2
    except OSError as exc:                 # a path the package did not anticipate
        if args.debug:
            raise
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"skyfit: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except Exception as exc:               # a bug: one line, the traceback with --debug
        if args.debug:
            raise
        print(f"skyfit: internal error ({type(exc).__name__}: {_oneline(exc)}); run again with "
              "--debug for the traceback and report it.", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
