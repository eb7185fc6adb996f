"""The prior of the sky's departure field, measured from the shared scans of a clear day.

Each of the 15 scans (Kider et al. 2014, ``skyfit_testkit/sky_measurement.py``) is fitted
as k M (1 + sum_j a_j B_j) (``skyfit_mi/physics/sky_departure.py``), M a model sky's luminance
toward the scan's points (10 degrees about the sun left out), the scanner's fitted rotation
applied (``--nominal``: its nominal directions).  Shown: one prior sd for every weight by
expectation-maximisation (the weights' own least-squares covariance taken out), and how many
scans fall within its 95% region when it is fitted on the other two thirds of the scans; the
least sd (steps of 0.05) whose 95% region holds at least 90% of the scans, which
:data:`~skyfit_mi.physics.sky_departure.PRIOR_SD` takes for the thesis's CIE clear sky; and the
share of scans that prior holds.

    .venv/bin/python scripts/sky_departure_prior.py [--nominal]
"""

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.stats import chi2

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from skyfit_mi.physics import sky_departure as sd  # noqa: E402
from skyfit_testkit import sky_measurement as sm  # noqa: E402

#: Reference skies: the scan's model M (sky_measurement.MODELS' names).
REFERENCES = ("cie_clear_thesis", "cie_groups_fit")


#: EM iterations of the prior's variance.
ITERATIONS = 200
#: Priors' sd tried for the least that holds 90% of the scans.
SD_GRID = np.arange(0.05, 1.0, 0.05)


def departures(scans, name, rotated):
    """Every scan against model ``name`` (its parameter, if any, the scan's best: least
    relative rms): [(least-squares weights a (J,), their covariance (J, J) from the residual's
    scatter, rms residual before, after)]."""
    model = next(m for m in sm.MODELS if m.name == name)
    out = []
    for s in scans:
        d = s.directions(rotated)
        keep = sm.angle_to_sun_deg(d, s.sun_direction) > sm.SUN_EXCLUSION_DEG
        M = model.luminance(d[keep], s, model.parameters)
        M = M[int(np.argmin(sm.relative_rms(M, s.luminance[keep])))]
        a, before, after = sd.scan_departure(d[keep], s.luminance[keep], M, s.sun_direction)
        X = np.column_stack([np.ones(keep.sum()), sd.basis(d[keep], s.sun_direction)])
        V = after ** 2 * np.linalg.inv(X.T @ X)[1:, 1:]
        out.append((a, V, before, after))
    return out


def fit_prior(fits):
    """The prior's variance of the weights (one for all, the basis's functions all bounded by 1)
    by expectation-maximisation: each scan's weights a_s ~ N(0, v I) seen through least squares
    with covariance V_s (the basis nearly collinear when the sun is high: 12:15's weights run to
    1.5 while its field stays within 20%), v the mean of the weights' posterior second moments."""
    v = 0.04
    J = len(fits[0][0])
    for _ in range(ITERATIONS):
        moments = []
        for a, V, *_ in fits:
            post = np.linalg.inv(np.linalg.inv(V) + np.eye(J) / v)
            mean = post @ np.linalg.solve(V, a)
            moments.append(np.mean(mean ** 2 + np.diag(post)))
        v = float(np.mean(moments))
    return v


def within(fits, sd):
    """The share of scans whose weights fall within the 95% region of a prior of ``sd`` (their
    predicted covariance the prior's plus the scan's own)."""
    J = len(fits[0][0])
    inside = [a @ np.linalg.solve(sd ** 2 * np.eye(J) + V, a) <= chi2.ppf(0.95, J)
              for a, V, *_ in fits]
    return float(np.mean(inside))


def held_out(fits, folds=3):
    """The share of scans within the 95% region of the prior fitted (:func:`fit_prior`) on the
    scans of the other folds."""
    test = np.arange(len(fits)) % folds
    return float(np.mean([within([x], np.sqrt(fit_prior([y for y, g in zip(fits, test)
                                                         if g != f])))
                          for x, f in zip(fits, test)]))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--nominal", action="store_true",
                    help="the scanner's nominal directions (default: its fitted rotation)")
    args = ap.parse_args(argv)
    scans = sm.load_scans()
    print(f"data: {sm.CITATION}")
    print("| reference sky | rms residual, scale only / with the field | sd by EM (held out: "
          "scans within its 95% region) | least sd holding 90% of the scans | the prior "
          f"{sd.PRIOR_SD:g} holds |")
    print("|---|---|---|---|---|")
    for name in REFERENCES:
        fits = departures(scans, name, not args.nominal)
        before, after = (np.array([f[k] for f in fits]) for k in (2, 3))
        least = next(v for v in SD_GRID if within(fits, v) >= 0.9)
        print(f"| {name} | {before.mean():.3f} / {after.mean():.3f} | "
              f"{np.sqrt(fit_prior(fits)):.2f} ({held_out(fits):.0%}) | {least:.2f} | "
              f"{within(fits, sd.PRIOR_SD):.0%} |")


if __name__ == "__main__":
    main()
