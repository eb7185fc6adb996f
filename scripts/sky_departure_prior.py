"""The prior of the sky's departure field, measured from real skies and published sky models.

Each sky is fitted as k M (1 + sum_j a_j B_j) (``skyfit_mi/physics/sky_departure.py``), M the
thesis's CIE clear sky toward the sky's points, 10 degrees about the sun left out:
- the 15 scans of a clear day (Kider et al. 2014, ``skyfit_testkit/sky_measurement.py``), the
  scanner's fitted rotation applied (``--nominal``: its nominal directions);
- published models fitted to many measured skies, at the sun :data:`ZENITHS` degrees from the
  zenith: Preetham et al.'s (1999) clear skies of turbidity 2-7 (:data:`TURBIDITIES`), and the
  CIE general skies (CIE S 011/E:2003) from the partly cloudy to the turbid cloudless types
  (:data:`CIE_TYPES`).
Shown per group: each weight's prior sd by expectation-maximisation (the weights' own
least-squares covariance taken out) and the share of the group within the 95% region of the
prior the other groups give (one kind of sky does not tell another's departure); then the
prior the three groups give, each weighing alike, times the least factor (steps of 0.1) whose
95% region holds at least 90% of each group, which
:data:`~skyfit_mi.physics.sky_departure.PRIOR_SD` takes.

    .venv/bin/python scripts/sky_departure_prior.py [--nominal]
"""

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.stats import chi2

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from skyfit_mi.conventions import direction_from_angles  # noqa: E402
from skyfit_mi.physics import cie_general, sky_departure as sd, turbid_sky  # noqa: E402
from skyfit_mi.physics.sky import clear_pattern, perez_pattern  # noqa: E402
from skyfit_testkit import sky_measurement as sm  # noqa: E402

#: Expectation-maximisation iterations of the prior's variances.
ITERATIONS = 300
#: Factors on the EM prior tried for the least that holds 90% of every group.
FACTORS = np.round(np.arange(1.0, 3.01, 0.1), 1)
#: The published models' suns: zenith angles [deg] (azimuth 180).
ZENITHS = (20, 35, 50, 65, 75)
#: Preetham's turbidities, and the CIE general sky types (7-10 partly cloudy, 11-15 cloudless).
TURBIDITIES = (2, 3, 4, 5, 6, 7)
CIE_TYPES = tuple(range(7, 16))
#: Points over the sky the models are compared at (uniform, seeded) and their seed.
MODEL_POINTS, SEED = 4000, 0


def _fit(d, measured, model, sun):
    """(weights a (J,), their covariance from the residual's scatter, rms residual before,
    after) of ``measured`` against ``model`` toward ``d`` (:func:`sd.scan_departure`)."""
    a, before, after = sd.scan_departure(d, measured, model, sun)
    X = np.column_stack([np.ones(len(d)), sd.basis(d, sun)])
    return a, after ** 2 * np.linalg.inv(X.T @ X)[1:, 1:], before, after


def departures(scans, rotated=True):
    """Every scan against the thesis's CIE clear sky: [:func:`_fit`]."""
    model = next(m for m in sm.MODELS if m.name == "cie_clear_thesis")
    out = []
    for s in scans:
        d = s.directions(rotated)
        keep = sm.angle_to_sun_deg(d, s.sun_direction) > sm.SUN_EXCLUSION_DEG
        M = model.luminance(d[keep], s, model.parameters)[0]
        out.append(_fit(d[keep], s.luminance[keep], M, s.sun_direction))
    return out


def model_departures(pattern, kinds):
    """Each published sky ``pattern(d, sun, kind)`` of ``kinds`` at every :data:`ZENITHS`
    against the thesis's CIE clear sky on :data:`MODEL_POINTS` seeded points above 3 degrees
    of elevation: [:func:`_fit`]."""
    v = np.random.default_rng(SEED).normal(size=(MODEL_POINTS, 3))
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    v = v[v[:, 2] > np.sin(np.radians(3.0))]
    out = []
    for z in ZENITHS:
        sun = direction_from_angles(np.radians(z), np.pi)
        d = v[sm.angle_to_sun_deg(v, sun) > sm.SUN_EXCLUSION_DEG]
        out += [_fit(d, pattern(d, sun, kind), clear_pattern(d, sun), sun) for kind in kinds]
    return out


def groups(rotated=True):
    """{name: [:func:`_fit`]}: the scans, Preetham's skies and the CIE general skies."""
    return {"scans (Kider et al. 2014)": departures(sm.load_scans(), rotated),
            "Preetham T 2-7": model_departures(
                lambda d, sun, t: perez_pattern(d, sun, turbid_sky.coefficients(t)),
                TURBIDITIES),
            "CIE general 7-15": model_departures(
                lambda d, sun, t: cie_general.pattern(d, sun, cie_general.standard_parameters(t)),
                CIE_TYPES)}


def fit_prior(*groups):
    """Each weight's prior sd (J,) by expectation-maximisation over ``groups`` of fits, each
    group weighing alike: each sky's weights a ~ N(0, diag v) seen through least squares with
    covariance V (the basis nearly collinear when the sun is high), v the mean over the groups
    of their skies' mean posterior second moments."""
    v = np.full(len(groups[0][0][0]), 0.04)
    for _ in range(ITERATIONS):
        by_group = []
        for fits in groups:
            moments = []
            for a, V, *_ in fits:
                post = np.linalg.inv(np.linalg.inv(V) + np.diag(1.0 / v))
                mean = post @ np.linalg.solve(V, a)
                moments.append(mean ** 2 + np.diag(post))
            by_group.append(np.mean(moments, axis=0))
        v = np.mean(by_group, axis=0)
    return np.sqrt(v)


def within(fits, prior_sd):
    """The share of ``fits`` whose weights fall within the 95% region of a prior of sds
    ``prior_sd`` (their predicted covariance the prior's plus the sky's own)."""
    P = np.diag(np.broadcast_to(prior_sd, (len(fits[0][0]),)) ** 2)
    return float(np.mean([a @ np.linalg.solve(P + V, a) <= chi2.ppf(0.95, len(a))
                          for a, V, *_ in fits]))


def prior(by_group):
    """(the prior's sds (J,), their factor on the groups' EM prior, :func:`fit_prior`): the
    least factor of :data:`FACTORS` whose 95% region holds at least 90% of each group."""
    base = fit_prior(*by_group.values())
    factor = next((m for m in FACTORS
                   if all(within(fits, m * base) >= 0.9 for fits in by_group.values())), None)
    if factor is None:
        raise SystemExit(f"no factor up to {FACTORS[-1]:g} holds 90% of every kind of sky")
    return np.round(factor * base, 2), factor


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--nominal", action="store_true",
                    help="the scanner's nominal directions (default: its fitted rotation)")
    args = ap.parse_args(argv)
    by_group = groups(not args.nominal)
    print(f"data: {sm.CITATION}")
    print(f"basis: {', '.join(sd.BASIS)}\n")
    print("| skies | n | rms residual, scale only / with the field | sd by EM | held out: "
          "within the other groups' prior | the prior holds |")
    print("|---|---|---|---|---|---|")
    sds, factor = prior(by_group)
    for name, fits in by_group.items():
        before, after = (np.mean([f[k] for f in fits]) for k in (2, 3))
        others = fit_prior(*(x for g, x in by_group.items() if g != name))
        print(f"| {name} | {len(fits)} | {before:.3f} / {after:.3f} | "
              f"{', '.join(f'{v:.2f}' for v in fit_prior(fits))} | {within(fits, others):.0%} | "
              f"{within(fits, sds):.0%} |")
    print(f"\nthe prior: {factor:g} x the groups' EM sd = {', '.join(f'{v:.2f}' for v in sds)}"
          f" (in use: {', '.join(f'{v:g}' for v in sd.PRIOR_SD)})")


if __name__ == "__main__":
    main()
