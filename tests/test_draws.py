"""Draws from a fit's likelihood (skyfit_mi.fitting.draws): against the exact posterior of a
linear model, and along a curved ridge (a grey plastic's metal twin) that the intervals'
Gaussian misses."""

import numpy as np
import pytest

from skyfit_mi.fitting.draws import DRAWS, interval_covariance, likelihood_draws
from skyfit_mi.fitting.uncertainty import Z


class _Model:
    """Radiance (n, P, T, 3) of parameter sets from a function of the sets (n, k) -> (n, m)."""

    def __init__(self, f):
        self.f = f

    def radiances(self, thetas):
        return self.f(np.atleast_2d(thetas)).reshape(len(thetas), -1, 1, 3)


class _Problem:
    """Chi-square of values y with noise sigma (the one method the draws use)."""

    def __init__(self, f, y, sigma):
        self.model, self.y, self.sigma = _Model(f), y, sigma

    def chi2_at(self, thetas):
        r = (self.y - self.model.radiances(thetas).reshape(len(thetas), -1)) / self.sigma
        return np.sum(r * r, axis=1)


def _intervals(theta, sd, lower, upper):
    return np.clip(np.stack([theta - Z["95"] * sd, theta + Z["95"] * sd], axis=1),
                   lower[:, None], upper[:, None])


def test_draws_of_a_linear_model_have_its_posterior_mean_and_covariance():
    """y = A theta + noise: the draws' mean and covariance are the least-squares estimate and
    (A^T A)^-1 sigma^2 s (s the scale), within their Monte Carlo error, from the intervals'
    Gaussian and from one 3 times too wide alike; from one 30 or 100 times too wide (errors
    the data share can widen the intervals so) too, beside the curvature's Gaussian
    (``local``); without it, from 100 times too wide, too few effective draws are found, and
    none are given rather than a few sets repeated."""
    rng = np.random.default_rng(1)
    A = rng.normal(size=(60, 3))
    A[:, 2] *= 0.2                                   # a poorly determined last parameter
    truth, sigma, scale = np.array([0.4, 0.3, 0.2]), 0.05, 1.5
    y = A @ truth + sigma * rng.standard_normal(60)
    theta = np.linalg.lstsq(A, y, rcond=None)[0]
    cov = np.linalg.inv(A.T @ A) * sigma**2 * scale
    problem = _Problem(lambda th: th @ A.T, y, sigma)
    chi2 = float(np.sum(((y - A @ theta) / sigma) ** 2))
    lower, upper = np.zeros(3) - 5, np.ones(3) * 5
    for widen in (1.0, 3.0, 30.0, 100.0):
        start = interval_covariance(_intervals(theta, widen * np.sqrt(np.diag(cov)), lower,
                                               upper), cov)
        local = cov if widen > 3 else None
        d = likelihood_draws(problem, theta, chi2, scale, start, (lower, upper), seed=2, n=400,
                             local=local)
        if widen == 100.0:
            assert likelihood_draws(problem, theta, chi2, scale, start, (lower, upper), seed=2,
                                    n=400) is None
        assert d.effective_size >= 400 and d.values.shape == (400, 3)
        se = np.sqrt(np.diag(cov) / 400)
        assert np.all(np.abs(d.values.mean(axis=0) - theta) < 4 * se), widen
        ratio = np.sqrt(np.diag(np.cov(d.values.T)) / np.diag(cov))
        assert np.all((ratio > 0.85) & (ratio < 1.15)), (widen, ratio)


def test_a_nearly_singular_curvature_beside_the_intervals_still_draws():
    """Two parameters that trade off almost exactly: the curvature's covariance is vast (1e10
    and more), its Gaussian capped at the bounds' range beside the intervals' (uncapped,
    rounding left some kernels indefinite and their Cholesky factorisation failed, 14 of 100
    such days); every set drawn fits y to about its noise."""
    done = 0
    for seed in range(40):
        rng = np.random.default_rng(seed)
        A = rng.normal(size=(60, 4))
        A[:, 3] = A[:, 2] + 1e-8 * rng.normal(size=60)
        y = A @ np.array([0.4, 0.3, 0.2, 0.1]) + 0.05 * rng.standard_normal(60)
        theta = np.linalg.lstsq(A, y, rcond=1e-6)[0]            # the pair at its least norm
        try:
            local = np.linalg.inv(A.T @ A) * 0.05**2
        except np.linalg.LinAlgError:
            continue
        assert np.max(np.abs(local)) > 1e10
        problem = _Problem(lambda th: th @ A.T, y, 0.05)
        chi2 = float(np.sum(((y - A @ theta) / 0.05) ** 2))
        start = interval_covariance([[0.3, 0.5], [0.2, 0.4], [-5, 5], [-5, 5]], local)
        d = likelihood_draws(problem, theta, chi2, 1.0, start, (-5 * np.ones(4), 5 * np.ones(4)),
                             seed, local=local)
        done += 1
        if d is not None:                    # each set fits y to about its noise
            assert np.sqrt(np.mean((d.values @ A.T - y) ** 2, axis=1)).max() < 0.065
    assert done >= 20


def test_draws_follow_a_curved_ridge_and_predict_the_data_as_the_fit_does():
    """A product model y = a b x (a metal's C times its specular, read the same along
    a b = const): the intervals' Gaussian, broad along the ridge, gives predictions far
    wider than the data allow; the draws stay on the ridge (a b within its noise) and
    spread along it as its likelihood does within the bounds (flat in a and b, so a's
    density along a b = 0.3 goes as 1/a on [0.3, 1]: quantile q at 0.3 (1/0.3)^q)."""
    rng = np.random.default_rng(3)
    x = np.linspace(0.5, 1.5, 90)
    sigma, ab = 0.01, 0.3
    y = ab * x + sigma * rng.standard_normal(len(x))
    problem = _Problem(lambda th: (th[:, 0] * th[:, 1])[:, None] * x, y, sigma)
    theta = np.array([0.6, 0.5])
    theta[1] = float(x @ y / (x @ x)) / theta[0]
    chi2 = float(np.sum(((y - theta[0] * theta[1] * x) / sigma) ** 2))
    lower, upper = np.array([0.3, 0.3]), np.array([1.0, 1.0])
    start = interval_covariance([[0.3, 1.0], [0.3, 1.0]])       # "not determined" along it
    d = likelihood_draws(problem, theta, chi2, 1.0, start, (lower, upper), seed=4)
    assert d.effective_size >= DRAWS
    products = d.values[:, 0] * d.values[:, 1]
    se = sigma / np.sqrt(x @ x)
    assert np.std(products) < 2 * se and abs(np.mean(products) - theta[0] * theta[1]) < 3 * se
    q = np.percentile(d.values[:, 0], [5, 50, 95])                   # along the ridge
    assert 0.3 < q[0] < 0.4 and 0.47 < q[1] < 0.65 and q[2] > 0.85, q
    naive = theta + rng.standard_normal((DRAWS, 2)) @ np.linalg.cholesky(start).T
    assert np.std(naive[:, 0] * naive[:, 1]) > 20 * se


def test_no_draws_where_the_likelihood_cannot_be_found():
    """A chi-square that is nowhere finite, or bounds that no proposal meets: no draws (relight
    then takes the intervals)."""
    problem = _Problem(lambda th: np.full((len(th), 3), np.nan), np.zeros(3), 1.0)
    cov = np.eye(2) * 0.01
    lower, upper = np.zeros(2), np.ones(2)
    assert likelihood_draws(problem, np.array([0.5, 0.5]), 0.0, 1.0, cov, (lower, upper),
                            seed=0) is None
    assert likelihood_draws(problem, np.array([0.5, 0.5]), 0.0, 1.0, cov, (lower + 5,
                            upper + 5), seed=0) is None


def test_interval_covariance_takes_the_intervals_widths_and_the_covariances_correlations():
    cov = np.array([[4.0, -1.0], [-1.0, 1.0]])
    c = interval_covariance([[0.0, 2 * Z["95"]], [1.0, 1.0 + 6 * Z["95"]]], cov)
    assert np.allclose(np.diag(c), [1.0, 9.0]) and np.isclose(c[0, 1], -0.5 * 3)
    assert np.allclose(interval_covariance([[0, 1], [0, 1]], np.full((2, 2), np.nan)),
                       np.eye(2) / (2 * Z["95"]) ** 2)


def test_relight_draws_keep_to_the_likelihood_and_widen_by_the_shared_errors_elsewhere():
    """A fit whose likelihood draws lie on a curved ridge (two parameters trading as
    x1 = 1 - x0^2, as a grey plastic and its metal twin do): on its own sequence relight's
    draws are those sets widened by added_sd; on another target also by shared_rows (the
    light's, calibration's and pose's errors), and they stay on the ridge as far as those allow,
    where the intervals' Gaussian fills the box around it; a fit without shared_rows, or over an
    undetermined sky level, draws from its intervals."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.relight import draws_source, parameter_draws

    rng = np.random.default_rng(1)
    x0 = rng.uniform(0.2, 0.9, 400)
    values = np.stack([x0, 1 - x0**2], axis=1)
    result = {"parameters": {"a": 0.5, "b": 0.75}, "sequence_run_id": "day",
              "intervals": {"a": {"95": [0.2, 0.9], "from": "profile"},
                            "b": {"95": [0.19, 0.96], "from": "profile"}},
              "covariance": {"names": ["a", "b"], "matrix": [[1.0, -0.9], [-0.9, 1.0]]},
              "draws": {"values": values.tolist(), "added_sd": [0.001, 0.001],
                        "shared_rows": [[0.01, 0.0], [0.0, 0.02]]}}
    s = SimpleNamespace(names=("a", "b"), lower=np.zeros(2), upper=np.ones(2), run_id="day")

    def off_ridge(d):
        return np.abs(d[1:, 1] - (1 - d[1:, 0] ** 2))

    own = parameter_draws(result, s, 4000, np.random.default_rng(2))
    assert np.allclose(own[0], [0.5, 0.75]) and np.percentile(off_ridge(own), 99) < 0.005
    assert draws_source(result, s) == "its likelihood draws"
    s.run_id = "another day"
    assert "widened by its day's light" in draws_source(result, s)
    other = parameter_draws(result, s, 4000, np.random.default_rng(2))
    assert np.median(off_ridge(own)) < np.median(off_ridge(other)) < 0.02  # the rows' only
    assert np.std(other[1:, 1] - own[1:, 1]) == pytest.approx(0.02, rel=0.15)
    for old in ({k: v for k, v in result["draws"].items() if k != "shared_rows"}, None):
        box = parameter_draws({**result, "draws": old}, s, 4000, np.random.default_rng(2))
        assert np.median(off_ridge(box)) > 0.05                   # the intervals' Gaussian
        assert draws_source({**result, "draws": old}, s).startswith("its intervals (")
    result["sky"] = {"undetermined_span": {"a": [0.2, 0.9]}}
    assert "sky level its data left undetermined" in draws_source(result, s)
    assert np.median(off_ridge(parameter_draws(result, s, 4000, np.random.default_rng(2)))) \
        > 0.05


def test_draws_find_a_sharp_lobe_the_data_allow_at_the_far_end_of_the_interval():
    """A roughness fitted at its bound 0.5 whose data allow any value over 0.28 and, apart from
    those, a sharp lobe at 0.05 (sd 0.01; a tenth of the likelihood's mass, by integration):
    the draws find that mode in every seed, in about its share (from the fit's end alone they
    found it in two of four seeds)."""
    class Problem:
        def chi2_at(self, x):
            broad = np.where(x[:, 0] > 0.28, 0.0, ((x[:, 0] - 0.28) / 0.02) ** 2)
            sharp = ((x[:, 0] - 0.05) / 0.01) ** 2
            return np.minimum(broad, sharp) + ((x[:, 1] - 0.5) / 0.01) ** 2

    a = np.linspace(0, 0.5, 200001)
    like = np.exp(-0.5 * Problem().chi2_at(np.stack([a, np.full_like(a, 0.5)], axis=1)))
    share = like[a < 0.15].sum() / like.sum()
    assert 0.08 < share < 0.11
    iv = np.array([[0.0, 0.5], [0.48, 0.52]])
    for seed in range(4):
        d = likelihood_draws(Problem(), np.array([0.5, 0.5]), 0.0, 1.0, interval_covariance(iv),
                             (np.zeros(2), np.array([0.5, 1.0])), seed, centre=iv.mean(axis=1))
        assert abs(np.mean(d.values[:, 0] < 0.15) - share) < 0.05


def test_the_shared_errors_a_fit_records_for_its_draws_are_its_intervals_signed_rows():
    """A fit JSON's draws carry the errors its sequence shares as signed rows, one per
    independent error: each source's rows give its standard errors in the intervals (root sum
    of squares), keep the signs with which one error moves several parameters (the sky's level
    against the sun's: up in one, down in the other), and each parameter's column is at most
    its 95% interval's Gaussian sd (a sky level's linear share at a roughness on its bound 0.5
    came out 0.72, beyond the parameter's whole range), its signs kept."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.draws import Draws
    from skyfit_mi.fitting.fit_record import draws_record
    from skyfit_mi.fitting.sky_fit import _carried_sd
    from skyfit_mi.fitting.uncertainty import rows_sd

    response = np.array([[0.04, 0.01], [-0.5, -0.5]])           # (n, coefficients)
    light_cov = np.array([[1.0, 0.5], [0.5, 2.0]])
    calibration = np.array([[0.03, 0.0], [0.01, 0.0]])
    fit = SimpleNamespace(
        draws=Draws(np.zeros((4, 2)), 300.0, 1000, 3), theta=np.array([0.5, 0.5]),
        calibration_rows=calibration, matrix_rows=np.zeros((0, 2)),
        sky=SimpleNamespace(response=response, light=SimpleNamespace(covariance=light_cov)),
        sun_level_rows=np.array([[0.02, 0.0]]), pose=SimpleNamespace(shifts={"yaw": np.array(
            [0.01, -0.01])}), cache_sd=np.zeros(2), jpeg_shared_sd=np.zeros(2),
        intervals={"R": {"95": [0.3, 0.7]}, "sigma_alpha": {"95": [0.0, 0.5]}})
    d = draws_record(fit, ["R", "sigma_alpha"])
    rows, sources = np.array(d["shared_rows"]), np.array(d["shared_sources"])
    assert sorted(set(sources)) == ["calibration", "pose", "sky", "sun_level"]
    cap = np.array([0.4, 0.5]) / (2 * Z["95"])
    sky_sd = _carried_sd(response, light_cov)
    assert rows_sd(rows[sources == "calibration"])[0] == pytest.approx(np.hypot(0.03, 0.01))
    assert rows_sd(rows[sources == "sky"])[0] == pytest.approx(sky_sd[0])
    assert rows_sd(rows[sources == "sun_level"]) == pytest.approx([0.02, 0.0])
    assert rows_sd(rows)[0] == pytest.approx(np.sqrt(0.03**2 + 0.01**2 + sky_sd[0]**2 + 0.02**2
                                                     + 0.01**2))
    assert rows_sd(rows)[1] == pytest.approx(cap[1])           # the roughness at its interval's
    sky_rows = rows[sources == "sky"]
    assert np.all(sky_rows[:, 0] * sky_rows[:, 1] < 0)           # the sky's signs kept
    pose = rows[sources == "pose"][0]
    assert pose[0] == pytest.approx(0.01) and pose[1] < 0      # scaled, not flipped


def test_a_level_error_moves_every_reflectance_alike_whatever_their_correlation():
    """Under other light a 5% level error (the grey card's: one shared row, level_rows) moves
    C_r and C_g by one factor: a value proportional to C_r + C_g keeps a 5% spread though the
    data anticorrelate them (-0.8; drawn as the covariance says, a level's spread fell to
    1.6%). A metal's rho_s (a fraction of C, thesis 7.1) takes its share apart, a plastic's
    (its highlight's reflectance) moves with C; the roughness does not move."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.relight import parameter_draws
    from skyfit_mi.fitting.uncertainty import level_rows

    names = ("C_r", "C_g", "rho_s", "sigma_alpha")
    s = SimpleNamespace(names=names, lower=np.zeros(4), upper=np.ones(4), run_id="another day")
    for rho_s, together in ((0.6, False), (0.1, True)):
        theta = np.array([0.5, 0.5, rho_s, 0.1])
        rows = level_rows([0.05] * 3, names, theta, independent=False)
        result = {"parameters": dict(zip(names, theta)), "sequence_run_id": "day",
                  "intervals": {k: {"95": [0.0, 1.0]} for k in names},
                  "covariance": {"names": list(names), "matrix": [
                      [1.0, -0.8, 0.5, 0.2], [-0.8, 1.0, -0.5, 0.0], [0.5, -0.5, 1.0, 0.0],
                      [0.2, 0.0, 0.0, 1.0]]},
                  "draws": {"values": [theta.tolist()], "added_sd": [0] * 4,
                            "shared_rows": rows.tolist()}}
        d = parameter_draws(result, s, 20000, np.random.default_rng(3))[1:]
        assert np.std(d[:, 0] + d[:, 1]) == pytest.approx(0.05, rel=0.05)
        assert np.std(d[:, 2]) == pytest.approx(0.05 * rho_s, rel=0.05)
        r = np.corrcoef(d[:, 0], d[:, 2])[0, 1]
        assert r > 0.99 if together else abs(r) < 0.05
        assert np.all(d[:, 3] == theta[3])


def test_a_roughness_open_below_spreads_over_its_reach_in_other_light():
    """A roughness whose interval was opened down to its bound (the sun's highlight unseen: the
    data told 0.26-0.34, the interval reads 0-0.34): under other light a share of the draws as
    large as that reach's share of the interval spreads evenly over it, so a sharp lobe's
    highlight can show in the band; on the fitted sequence the draws stay as the data put
    them."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.relight import parameter_draws

    rng = np.random.default_rng(0)
    values = np.stack([np.full(400, 0.5), rng.uniform(0.264, 0.338, 400)], axis=1)
    result = {"parameters": {"rho_s": 0.5, "sigma_alpha": 0.3}, "sequence_run_id": "day",
              "intervals": {"rho_s": {"95": [0.45, 0.55]},
                            "sigma_alpha": {"95": [0.0, 0.34], "open_below": 0.26}},
              "draws": {"values": values.tolist(), "added_sd": [0, 0], "shared_rows": []}}
    s = SimpleNamespace(names=("rho_s", "sigma_alpha"), lower=np.zeros(2),
                        upper=np.array([1.0, 0.5]), run_id="day")
    own = parameter_draws(result, s, 4000, np.random.default_rng(1))[1:, 1]
    assert own.min() >= 0.264
    s.run_id = "another day"
    other = parameter_draws(result, s, 4000, np.random.default_rng(1))[1:, 1]
    assert np.mean(other < 0.264) == pytest.approx(0.264 / 0.34, abs=0.03)
    assert np.mean(other < 0.1) == pytest.approx(0.1 / 0.34, abs=0.03)
    del result["intervals"]["sigma_alpha"]["open_below"]
    assert parameter_draws(result, s, 4000, np.random.default_rng(1))[1:, 1].min() >= 0.264


def test_a_shared_error_that_carries_a_lobe_past_its_bound_holds_it_there_and_moves_the_rest():
    """A roughness fitted on its bound 0.5, a shared error's row moving it and rho_s up
    together: a draw the row carries past the bound keeps the roughness at 0.5 and moves rho_s
    as the data answer the roughness held (minus the excess times cov[rho, sigma] /
    cov[sigma, sigma]), not up alone as a clip would leave it; draws within the bounds are
    as the rows put them."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.relight import parameter_draws

    names = ("rho_s", "sigma_alpha")
    theta = np.array([0.1, 0.5])
    cov = [[4e-4, 8e-4], [8e-4, 4e-3]]                 # rho_s rises with a broader lobe
    result = {"parameters": dict(zip(names, theta)), "sequence_run_id": "day",
              "intervals": {"rho_s": {"95": [0.06, 0.14]}, "sigma_alpha": {"95": [0.38, 0.5]}},
              "covariance": {"names": list(names), "matrix": cov},
              "draws": {"values": [theta.tolist()], "added_sd": [0, 0],
                        "shared_rows": [[0.01, 0.05]]}}
    s = SimpleNamespace(names=names, lower=np.zeros(2), upper=np.array([1.0, 0.5]),
                        run_id="another day")
    d = parameter_draws(result, s, 4000, np.random.default_rng(0))[1:]
    z = (d[:, 0] - 0.1) / 0.01
    up, down = d[:, 1] >= 0.5 - 1e-12, d[:, 1] < 0.5 - 1e-12
    assert 0.4 < up.mean() < 0.6
    np.testing.assert_allclose(d[down, 1], 0.5 + 0.05 * z[down])       # as the row says
    # past the bound: excess 0.05 z held back, rho_s by 0.01 z - 0.05 z * 0.2 = 0
    np.testing.assert_allclose(d[up, 0], 0.1, atol=1e-12)
    np.testing.assert_allclose(d[up, 1], 0.5)
    del result["covariance"]                            # without one: clipped as before
    d = parameter_draws(result, s, 4000, np.random.default_rng(0))[1:]
    assert np.all(d[:, 1] <= 0.5) and d[d[:, 1] >= 0.5, 0].max() > 0.11
