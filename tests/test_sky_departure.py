"""The sky's departure from its model (physics/sky_departure.py): its basis, its parts, its prior
measured from the shared scans, and a fit that takes it under a measured sky."""
import sys
from pathlib import Path

import numpy as np
import pytest

from skyfit_mi.physics import sky_departure as sd
from skyfit_mi.physics.sky import cie_sky
from skyfit_mi.physics.sky_shape import shaped

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))


def directions(n, seed=0):
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_the_basis_is_bounded_by_one_above_the_horizon_and_is_what_it_says():
    """Every B_j lies in [-1, 1] over the sky (so 1 + B_j is a light); with the sun at the
    zenith, toward the zenith u = y = 1 and every P1, P2 and product is 1; toward the horizon
    opposite the sun u = -1 and y = -cos(its altitude)."""
    sun = np.array([0.0, 0.6, 0.8])
    d = directions(20000)
    B = sd.basis(d[d[:, 2] > 0], sun)
    assert B.shape[1] == len(sd.BASIS) and np.all(np.abs(B) <= 1.0 + 1e-12)
    np.testing.assert_allclose(sd.basis([0, 0, 1], [0, 0, 1]), np.ones(5))
    np.testing.assert_allclose(sd.basis([0, -1, 0], sun), [-1.0, 1.0, -0.6, 1.5 * 0.36 - 0.5, 0.6])
    np.testing.assert_allclose(sd.field_factor(d, sun, np.zeros(5)), 1.0)


def test_the_parts_mix_to_the_rest_times_the_field_and_leave_the_ground():
    """(1 - sum a) rest + sum a_j part_j is the rest's sky times 1 + sum a_j B_j above the
    horizon and the rest's ground below it; a relit sky (shaped) with the weights is the
    sun's light plus that, level k included."""
    sky = cie_sky("clear", 40.0, 150.0, ground_albedo=0.2)
    sun, rest = sky.split()
    a = np.array([0.1, -0.05, 0.2, 0.1, -0.1])
    d = directions(3000, seed=1)
    parts = sd.departure_parts(sky)
    assert [n for n, _ in parts] == list(sd.BASIS)
    assert all(p.sun_radiance.max() == 0 and p.info["kind"] == "departure" for _, p in parts)
    mix = (1 - a.sum()) * rest.sky_radiance(d) + sum(w * p.sky_radiance(d)
                                                     for w, (_, p) in zip(a, parts))
    up = d[:, 2:] > 0
    want = np.where(up, rest.sky_radiance(d) * sd.field_factor(d, sky.sun_direction, a)[:, None],
                    rest.ground)
    np.testing.assert_allclose(mix, want, rtol=1e-9, atol=1e-9)
    relit = shaped(sky, 0.8, [], [], a, rows=64)
    far = d[(d[:, 2] > 0.2) & (d @ sky.sun_direction < 0.9)]
    np.testing.assert_allclose(relit.sky_radiance(far), 0.8 * rest.sky_radiance(far)
                               * sd.field_factor(far, sky.sun_direction, a)[:, None]
                               + sun.sky_radiance(far), rtol=0.03)


def test_the_prior_holds_nine_in_ten_of_measured_skies_and_published_models():
    """The prior's sds recomputed (scripts/sky_departure_prior.py) from the shared scans and
    the published models (Preetham T 2-7, CIE general 7-15) against the thesis's CIE clear
    sky: the field halves the scans' residual and takes the models' to under a fifth; the prior
    in use is EM's sds over the three kinds, each weighing alike, times the least factor that
    holds 90% of each kind, and it holds them; a prior from the other kinds alone holds fewer
    than 90% of the CIE skies (so one kind of sky does not tell another's departure)."""
    from sky_departure_prior import fit_prior, groups, prior, within

    try:
        by_group = groups()
    except Exception as e:            # the shared data beside the repository
        pytest.skip(f"shared scans not found: {e}")
    scans, preetham, cie = by_group.values()
    for fits, most in ((scans, 0.6), (preetham, 0.2), (cie, 0.2)):
        before, after = (np.mean([f[k] for f in fits]) for k in (2, 3))
        assert after < most * before, (before, after)
    sds, factor = prior(by_group)
    np.testing.assert_allclose(sds, sd.PRIOR_SD)
    assert 1.0 < factor < 2.0
    assert all(within(fits, sd.PRIOR_SD) >= 0.9 for fits in by_group.values())
    assert within(cie, fit_prior(scans, preetham)) < 0.9


def test_a_fit_under_measured_skies_holds_the_truth_with_the_departure_and_not_without(
        tmp_path, mi):
    """The disc (1% noise, 100 pixels) rendered under five of the measured scans as maps,
    fitted with the thesis's CIE clear sky at the measured levels as the spec (the sun as the
    spec gives it), the sky's level fitted under its prior: with the spec's shape taken as
    exact every C misses; with the departure fitted every parameter's interval holds its
    truth, the record carries the weights within a few prior sd, and C's median half-width is
    at most 2x that of the fit given the true sky (the maps, the level fitted as for
    photographs; issue 52's sharpness goal)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from measured_light import TRUTH, measured_disc_day, relabelled, thesis_clear_scaled

    from skyfit_mi.fitting.chi2 import parse_region
    from skyfit_mi.fitting.fit import fit_regions
    from skyfit_mi.fitting.light import LightOptions
    from skyfit_testkit.sky_measurement import load_scans

    try:
        scans = load_scans()
    except Exception as e:
        pytest.skip(f"shared scans not found: {e}")
    day = measured_disc_day(tmp_path, scans[::3], size=16, noise_percent=1.0, spp=128)
    spec = relabelled(day, tmp_path / "as_clear", thesis_clear_scaled)
    names = ("C_r", "C_g", "C_b", "rho_s", "sigma_alpha")
    held, half = {}, {}
    for light, departure in ((day, False), (spec, False), (spec, True)):
        r = next(fit_regions(light, [("disc", parse_region("rect:3,3,12,12"))], model="colour",
                             light=LightOptions(sky="prior", sun_sd=0.0, departure=departure),
                             log=lambda *a: None))
        held[light, departure] = {n: r["intervals"][n]["95"][0] <= v <= r["intervals"][n]["95"][1]
                                  for n, v in zip(names, TRUTH)}
        half[light, departure] = np.median([np.diff(r["intervals"][n]["95"])[0] / 2 / v
                                            for n, v in zip(names[:3], TRUTH)])
    held, half = ({True if k == (spec, True) else False if k == (spec, False) else "truth": v
                   for k, v in d.items()} for d in (held, half))
    assert not any(held[False][n] for n in ("C_r", "C_g", "C_b")), held
    assert all(held[True].values()), (held, r["intervals"])
    rec = r["sky"]["departure"]
    assert rec["basis"] == list(sd.BASIS) and rec["prior_sd"] == sd.PRIOR_SD.tolist()
    assert np.all(np.abs(rec["weights"]) < 3 * sd.PRIOR_SD) and rec["conflict_p"] > 1e-3
    assert r["sky"]["correlation"]["names"][-5:] == [f"departure {b}" for b in sd.BASIS]
    assert all(held["truth"].values()), held
    assert half[True] <= 2.0 * half["truth"], half


def test_the_least_field_over_the_day_and_its_warning():
    """The field's least value above the horizon, hand-derived: 1 + 0.5 u is least at the
    horizon (u = -1), 1 - 1.2 u at the zenith; 1 + 0.5 cos(gamma) is 1 with the sun at the
    zenith and 0.5 with it on the horizon (the opposite horizon); below zero the fit warns that
    no sky is like that, above it not."""
    from skyfit_mi.fitting.sky_fit import _departure_record, _departure_warnings

    zenith, horizon = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    e = np.eye(len(sd.BASIS))
    np.testing.assert_allclose(sd.least_field(0.5 * e[0], [zenith]), [0.5], atol=1e-12)
    np.testing.assert_allclose(sd.least_field(-1.2 * e[0], [zenith]), [-0.2], atol=1e-12)
    np.testing.assert_allclose(sd.least_field(0.5 * e[2], [zenith, horizon]), [1.0, 0.5],
                               atol=1e-12)
    small = np.diag(np.full(len(sd.BASIS), 0.01))
    for weights, negative in ((-1.2 * e[0], True), (0.5 * e[0], False)):
        rec = _departure_record(weights, small, np.array([zenith, horizon]))
        said = " ".join(_departure_warnings(rec))
        assert (rec["least_field"] < 0) == negative
        assert ("negative" in said) == negative, said
    assert rec["least_field_sun_zenith_deg"] in (0.0, 90.0)
