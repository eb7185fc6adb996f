"""The prior of a camera's JPEG tone curve against sRGB's, measured from cameras' curves.

darktable's base-curve presets (``src/iop/basecurve.c`` of https://github.com/darktable-org/
darktable, GPL-3; download the file and give its path) are cameras' in-camera JPEG curves: the
camera-specific ones measured by their contributors from RAW and JPEG pairs of one camera
(darktable-curve-tool: the JPEG read through sRGB's curve against the RAW's linear signal), the
makers' generic ones ("canon eos like", ...) drawn by hand to look alike.  Each curve (raw x ->
JPEG-linear y, both fractions of full scale) gives the departure ``skyfit_mi.physics.tone_curve``
models as a function of the value read, d(ln y) = ln y - ln x(y), fitted on its basis by least
squares over y in [Y_RANGE] (ln-uniform).  The prior's second moment is the mean b b^T over the
measured curves; the makers' generic curves and each measured curve left out check it: the
share of the values (y on a grid, calibrated at each of ANCHORS) whose departure lies within
1.96 sd.  Then the curve as grey references measure it (REFERENCE_SETS, photographed over
FRAMES frames): the least posterior floor (``tone_curve.POSTERIOR_FLOOR``) under which each
measured curve left out and the makers' hold 95% of their values within 1.96 sd, read as the
fit reads them (``tone_curve.covered``).  Prints PRIOR_ROOT for ``tone_curve.py``.

    .venv/bin/python scripts/tone_curve_prior.py PATH/basecurve.c
"""

import argparse
import re
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from skyfit_mi.physics import tone_curve as tc  # noqa: E402

#: The values' range [fractions of full scale] each curve is fitted over, and its points.
Y_RANGE, POINTS = (float(np.exp(tc.T_MIN)), 0.9), 200
#: Reference signals [fractions of full scale] the check calibrates at (a grey card at its
#: usual codes, a white reference, a dark one).
ANCHORS = (0.05, 0.18, 0.5)
#: The share of a curve's values the prior's 1.96 sd must hold, and the floors tried.
HOLD, SLOPES = 0.95, np.round(np.arange(0.0, 0.51, 0.01), 2)
#: One preset's line: its name, then its nodes {x, y}.
PRESET = re.compile(r'^\s*\{\s*(?:N_\()?"?([^",)]+)"?\)?\s*,\s*"([^"]*)"')
NODE = re.compile(r"\{\s*([0-9.]+)\s*,\s*([0-9.]+)\s*\}")


def read_presets(path):
    """{'measured' | 'makers': {name: nodes (n, 2)}} from darktable's ``basecurve.c``: the
    camera presets' table, then the makers' (each preset on one line; a curve another preset
    repeats, as the Fujifilm X100T's the X100S's, once)."""
    out, table = {"measured": {}, "makers": {}}, None
    for line in Path(path).read_text().splitlines():
        if "basecurve_camera_presets[]" in line:
            table = "measured"
        elif "basecurve_presets[]" in line:
            table = "makers"
        elif table and line.startswith("};"):
            table = None
        elif table and not line.lstrip().startswith("//"):
            m, nodes = PRESET.match(line), NODE.findall(line)
            if m and len(nodes) >= 4 and m.group(1) not in ("cubic spline", "neutral"):
                xy = np.array(nodes, dtype=float)
                if not any(np.array_equal(xy, seen) for seen in out[table].values()):
                    out[table][m.group(1).strip()] = xy       # one camera's twin kept once
    return out


def departure(nodes, t):
    """d (n,) at ln values ``t`` of a curve's ``nodes`` (x, y), interpolated in ln-ln."""
    x, y = nodes[:, 0], nodes[:, 1]
    ok = (x > 0) & (y > 0)
    return t - np.interp(t, np.log(y[ok]), np.log(x[ok]))


def weights(curves):
    """The basis weights b (N, DEGREE) of each curve and its fit's rms residual (N,)."""
    t = np.log(np.geomspace(*Y_RANGE, POINTS))
    A = tc.basis(t)
    b, res = [], []
    for nodes in curves.values():
        d = departure(nodes, t)
        w, *_ = np.linalg.lstsq(A, d, rcond=None)
        b.append(w)
        res.append(float(np.sqrt(np.mean((A @ w - d) ** 2))))
    return np.array(b), np.array(res)


def root(b, slope=0.0):
    """The prior's root (DEGREE, E) of the second moment mean b b^T (eigen form), and a floor:
    an independent error of ``slope`` in d per unit ln signal (on the linear phi_1), which the
    few curves' second moment may leave too narrow between its nodes."""
    val, vec = np.linalg.eigh(b.T @ b / len(b))
    keep = val > 1e-12 * val.max()
    cols = [vec[:, keep] * np.sqrt(val[keep])]
    if slope > 0:
        floor = np.zeros((b.shape[1], 1))
        floor[0, 0] = slope * -tc.T_MIN / 2.0            # phi_1 = 2 t / -T_MIN
        cols.append(floor)
    return np.concatenate(cols, axis=1)


def least_floor(b, measured, makers):
    """The least floor slope (steps of 0.01) whose prior holds at least HOLD of each measured
    curve left out and of the makers' curves together; with each left-out curve's share."""
    for slope in SLOPES:
        loo = [held({k: measured[k]}, root(np.delete(b, i, axis=0), slope))[0]
               for i, k in enumerate(measured)]
        if min(loo) >= HOLD and (not makers or held(makers, root(b, slope))[0] >= HOLD):
            return float(slope), loo
    return float(SLOPES[-1]), loo


def held(curves, r):
    """The share of each curve's values within 1.96 sd of the prior ``r``, over the grid and
    ANCHORS, and the largest |z|."""
    t = np.log(np.geomspace(*Y_RANGE, 40))
    z = []
    for nodes in curves.values():
        d = departure(nodes, t)
        for a in np.log(ANCHORS):
            da = departure(nodes, np.array([a]))[0]
            z.append(np.abs(d - da) / np.maximum(tc.relative_sd(t, a, r), 1e-12))
    z = np.concatenate(z)
    return float(np.mean(z <= 1.96)), float(z.max())


#: Grey references a user photographs (reflectances): a three-card set (black, the 18% grey,
#: white) and a ColorChecker's six greys; each over FRAMES frames of exposures ln-uniform in
#: EXPOSURES (the white at 40-90% of full scale), read at NOISE (ln).
REFERENCE_SETS = {"three cards": (0.04, 0.18, 0.9),
                  "ColorChecker": (0.031, 0.09, 0.19, 0.36, 0.59, 0.9)}
FRAMES, EXPOSURES, NOISE = 13, (0.45, 1.0), 0.01
#: The posterior floors tried (shares of the prior's sd).
FLOORS = np.round(np.arange(0.0, 0.61, 0.01), 2)


def measured_errors(nodes, r, rho, floor, rng):
    """|error| / sd (frames x grid) of the curve of ``nodes`` as references of reflectances
    ``rho`` measure it (tone_curve.fit_references under prior ``r`` with posterior ``floor``):
    each read value's departure relative to its frame's anchor, over Y_RANGE, as the fit reads
    it: within the references' levels through the measured curve with its posterior's error,
    beyond them at the curve's value at the nearest level with the prior's
    (tone_curve.covered)."""
    x = np.exp(rng.uniform(*np.log(EXPOSURES), size=(FRAMES, 1))) * np.asarray(rho)
    xs, ys = nodes[:, 0], nodes[:, 1]
    ok = (xs > 0) & (ys > 0)
    t = np.interp(np.log(x), np.log(xs[ok]), np.log(ys[ok]))      # ln of the value read
    ratio = t - np.log(rho) + rng.normal(0.0, NOISE, t.shape)
    w, post, phi, _ = tc.fit_references(t, ratio, np.full(t.shape, NOISE), r,
                                        anchor_weight=np.exp(2 * t), floor=floor)
    grid = np.log(np.geomspace(*Y_RANGE, 40))
    aw = np.exp(2 * t) / np.exp(2 * t).sum(axis=1, keepdims=True)
    truth = departure(nodes, grid)[None, :] - np.sum(aw * departure(nodes, t.ravel())
                                                     .reshape(t.shape), axis=1, keepdims=True)
    span = (t.min(), t.max())
    inside = tc.covered(grid, span)
    move = tc.moves_from(grid[None, :], phi[:, None, :], r)                 # (F, grid, E)
    est = tc.moves_from(np.clip(grid, *span)[None, :], phi[:, None, :], r) @ w
    sd = np.sqrt(np.sum(np.square(np.where(inside[:, None], move @ post, move)), axis=-1))
    return np.abs(est - truth) / np.maximum(sd, 1e-12)


def least_posterior_floor(b, measured, makers, slope, seed=0):
    """The least posterior floor (of FLOORS) under which each measured curve left out (the
    prior from the others) and the makers' curves, measured by each of REFERENCE_SETS, hold at
    least HOLD of their values within 1.96 sd; with {set: each left-out curve's share}."""
    for floor in FLOORS:
        shares = {}
        for name, rho in REFERENCE_SETS.items():
            rng = np.random.default_rng(seed)
            shares[name] = [float(np.mean(measured_errors(
                nodes, root(np.delete(b, i, axis=0), slope), rho, floor, rng) <= 1.96))
                for i, nodes in enumerate(measured.values())]
            if makers:
                z = [measured_errors(n, root(b, slope), rho, floor, rng) for n in makers.values()]
                shares[name].append(float(np.mean(np.concatenate(z) <= 1.96)))
        if min(min(v) for v in shares.values()) >= HOLD:
            return float(floor), shares
    return float(FLOORS[-1]), shares


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("basecurve", help="darktable's src/iop/basecurve.c")
    args = ap.parse_args(argv)
    presets = read_presets(args.basecurve)
    measured, makers = presets["measured"], presets["makers"]
    if len(measured) < 3:
        sys.exit(f"{args.basecurve}: {len(measured)} measured camera curves found; give "
                 "darktable's src/iop/basecurve.c")
    b, res = weights(measured)
    print(f"measured cameras: {len(measured)} ({', '.join(measured)}); fit rms residual "
          f"median {np.median(res):.3f}, largest {res.max():.3f}")
    bare = [held({k: measured[k]}, root(np.delete(b, i, axis=0)))[0]
            for i, k in enumerate(measured)]
    print(f"the second moment alone: each measured curve left out, within 1.96 sd: "
          f"{np.mean(bare):.3f} (worst curve {min(bare):.3f})")
    slope, loo = least_floor(b, measured, makers)
    r = root(b, slope)
    print(f"with a floor of {slope:g} per unit ln signal (the least holding {HOLD:.0%} of each "
          f"curve left out and of the makers'): each left out {np.mean(loo):.3f} "
          f"(worst curve {min(loo):.3f})")
    if makers:
        share, zmax = held(makers, r)
        print(f"the makers' generic curves ({len(makers)}), within 1.96 sd: {share:.3f} "
              f"(largest |z| {zmax:.2f})")
    for a in ANCHORS:
        ys = np.array([0.01, 0.03, 0.1, 0.3, 0.9])
        sds = tc.relative_sd(np.log(ys), np.log(a), r)
        print(f"calibrated at {a:g}: sd of ln value at " + ", ".join(
            f"{y:g}: {s:.3f}" for y, s in zip(ys, sds)))
    floor, shares = least_posterior_floor(b, measured, makers, slope)
    print(f"measured by grey references, the posterior's floor holding {HOLD:.0%} of each "
          f"curve left out and of the makers': {floor:g} of the prior's sd (POSTERIOR_FLOOR)")
    for name, share in shares.items():
        print(f"  {name} {REFERENCE_SETS[name]}: each left out {np.mean(share[:len(measured)]):.3f}"
              f" (worst {min(share[:len(measured)]):.3f})"
              + (f", the makers' {share[-1]:.3f}" if makers else ""))
    print("\nPRIOR_ROOT = np.array(" + np.array2string(
        r, precision=4, separator=", ", floatmode="fixed").replace("\n", "\n    ") + ")")


if __name__ == "__main__":
    main()
