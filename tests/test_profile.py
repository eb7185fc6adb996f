"""Profile chi-square edges on the true chi-square (skyfit_mi.fitting.methods.profile)."""
import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from skyfit_mi.fitting.chi2 import parse_region

LEVELS = [1.0, 3.841458820694124]


@pytest.fixture(scope="module")
def noisy_fit(days):
    """A global fit of the noisy two-parameter day (rho_s 0.3, sigma_alpha 0.1)."""
    from skyfit_mi.fitting.fit import FitCache, FitSession
    from skyfit_mi.fitting.methods.global_search import global_search

    s = FitSession(days["noisy"], "disc", parse_region("rect:4,4,7,7"), model="two",
                   cache=FitCache(positions=2, directions=512))
    g = global_search(s.problem, None, s.lower, s.upper, profile=False,
                      grid_basis=s.grid_bases()[0])
    r, J = s.problem.jacobian(g["theta"])
    return s, np.asarray(g["theta"]), float(r @ r), np.linalg.inv(J.T @ J)


def brute_profile(s, k, x):
    """P_k(x): the other parameter on a grid of 201 values, then Brent's method between the
    best one's neighbours."""
    j = 1 - k

    def f(v):
        th = np.empty(2)
        th[k], th[j] = x, v
        return s.problem.chi2(th)
    grid = np.linspace(s.lower[j], s.upper[j], 201)
    i = int(np.argmin([f(v) for v in grid]))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    return minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": 1e-8}).fun


@pytest.mark.parametrize("k", [0, 1])
def test_edges_sit_where_the_profile_crosses_the_threshold(noisy_fit, k):
    from skyfit_mi.fitting.methods.profile import profile_edges

    s, theta, chi2, cinv = noisy_fit
    edges, fits, _, _ = profile_edges(s.problem, theta, chi2, k, LEVELS, s.lower, s.upper,
                                      cinv)
    assert fits <= 4 * 6
    for (lo, hi), thr in zip(edges, LEVELS):
        assert lo < theta[k] < hi
        for x in (lo, hi):
            rise = brute_profile(s, k, x) - chi2
            assert np.sqrt(max(rise, 0)) == pytest.approx(np.sqrt(thr), rel=0.06), (x, rise, thr)
    (lo68, hi68), (lo95, hi95) = edges
    assert lo95 < lo68 and hi68 < hi95


def test_levenberg_marquardt_holds_fixed_parameters(noisy_fit):
    from skyfit_mi.fitting.methods.levenberg_marquardt import levenberg_marquardt

    s, theta, chi2, _ = noisy_fit
    start = theta + [0.03, 0.02]
    res = levenberg_marquardt(s.problem, start, s.lower, s.upper, fixed=[0])
    assert res["theta"][0] == start[0]
    assert res["chi2"] == pytest.approx(brute_profile(s, 0, start[0]), rel=1e-4, abs=0.05)


def test_a_search_at_its_iteration_limit_has_converged_where_chi2_no_longer_falls():
    """Stopped at the iteration limit: converged where the last 10 steps lowered chi-square by
    under 0.01 (a crawl along a flat valley moves no interval), else a warning saying how much
    it was still falling; and on a curved valley stopped after 3 iterations, that warning."""
    from skyfit_mi.fitting.methods.levenberg_marquardt import _at_the_limit, levenberg_marquardt

    class Flat:
        def chi2(self, t):
            return float(t[0])

    crawl = [[100.0 - 1e-4 * i] for i in range(12)]
    assert _at_the_limit(Flat(), crawl, crawl[-1][0], 100)[0] == "converged"
    falling = [[100.0 - 0.5 * i] for i in range(12)]
    status, message = _at_the_limit(Flat(), falling, falling[-1][0], 100)
    assert status == "max_iterations" and "still falling (5 over the last 10 steps)" in message
    res = levenberg_marquardt(_Banana(), [0.9, -0.9], [-2, -2], [2, 2], max_iterations=3)
    assert res["status"] == "max_iterations" and "iteration limit (3)" in res["message"]


def test_levenberg_marquardt_holds_a_parameter_at_the_bound_it_is_pressed_against():
    """A valley whose minimum lies beyond a's lower bound, a and b nearly interchangeable: held
    at a = 0 for its steps, the search reaches the constrained minimum (b by least squares at
    a = 0) exactly, not crawling along the bound as clipped steps do; a parameter that changes
    nothing at its bound (sigma_alpha at rho_s = 0) is not held, so that start still fails."""
    from skyfit_mi.fitting.methods.levenberg_marquardt import levenberg_marquardt

    class Valley(_Banana):
        A = np.array([[1.0, 1.0], [1.0, 1.05], [0.0, 0.01]]) / 0.01
        y = A @ np.array([-1.0, 3.0])

        def residuals(self, t):
            return self.A @ t - self.y

        def jacobian(self, t):
            return self.residuals(t), self.A.copy()

    p = Valley()
    res = levenberg_marquardt(p, [0.5, 0.5], [0.0, -10.0], [10.0, 10.0])
    b = np.linalg.lstsq(p.A[:, 1:], p.y, rcond=None)[0][0]
    assert res["status"] == "converged" and res["theta"][0] == 0.0
    assert res["theta"][1] == pytest.approx(b, abs=1e-6) and len(res["trace"]) <= 15

    class Corner(_Banana):                   # rho_s exp(-sigma): sigma idle at rho_s = 0
        def residuals(self, t):
            return np.array([t[0] * np.exp(-t[1]) - 0.5, t[0] - 0.4, 0.0])

        def jacobian(self, t):
            e = np.exp(-t[1])
            return self.residuals(t), np.array([[e, -t[0] * e], [1.0, 0.0], [0.0, 0.0]])

    assert levenberg_marquardt(Corner(), [0.0, 0.0], [0, 0], [1, 1])["status"] == "failed"


class _Banana:
    """chi^2 along a curved ridge a = b^2: residuals (a - b^2) / 0.01 and (b - 0.5) / 0.2.
    The profile of a rises as ((sqrt(a) - 0.5) / 0.2)^2, so its 95% interval is
    a in [(0.5 - 0.392)^2, (0.5 + 0.392)^2] = [0.0117, 0.796]; the covariance at the minimum
    (a quadratic) puts the upper edge at 0.25 + 0.392 = 0.642."""
    evaluations = 0

    def residuals(self, t):
        return np.array([(t[0] - t[1] ** 2) / 0.01, (t[1] - 0.5) / 0.2])

    def jacobian(self, t):
        return self.residuals(t), np.array([[1 / 0.01, -2 * t[1] / 0.01], [0.0, 1 / 0.2]])

    def chi2(self, t):
        r = self.residuals(t)
        return float(r @ r)


def test_edges_follow_a_curved_ridge_and_its_points_widen_the_others():
    """The profile's fits continue along their own path, so the edges of a sit where the
    curved ridge's profile crosses the threshold (not the covariance's quadratic), and the
    points walked give b an interval covering its own 95% profile interval's core."""
    from skyfit_mi.fitting.methods.profile import ProfileOptions, profile_edges, ridge_intervals

    p = _Banana()
    theta, lower, upper = np.array([0.25, 0.5]), np.zeros(2), np.array([1.0, 1.5])
    r, J = p.jacobian(theta)
    cov = np.linalg.inv(J.T @ J)
    assert 0.25 + 1.96 * np.sqrt(cov[0, 0]) == pytest.approx(0.642, abs=0.002)
    edges, _, walked, _ = profile_edges(p, theta, 0.0, 0, LEVELS, lower, upper, cov,
                                     ProfileOptions(rtol=0.01, iterations=40))
    lo, hi = edges[1]
    assert lo == pytest.approx(0.0117, abs=0.002) and hi == pytest.approx(0.796, rel=0.02)
    b_lo, b_hi = (v[1] for v in ridge_intervals(walked, 0.0, LEVELS[1]))
    assert b_lo < 0.15 and b_hi > 0.85                   # b's own 95%: 0.108-0.892
    assert ridge_intervals(walked, 0.0, -1.0) is None


def test_a_fit_failing_from_its_extrapolated_start_is_retried_from_the_nearest_fit(
        noisy_fit, monkeypatch):
    """A constrained fit whose start, stepped along the profile's path, lands where the
    curvature is singular (the grey card's C_r under a hazy sky: rho_s clipped to 0 beside
    sigma_alpha 0) is fitted again from the nearest fit, x in its place; before, every such x
    counted as outside while searching and the edge then fell to the bound."""
    from skyfit_mi.fitting.methods import profile

    s, theta, chi2, cinv = noisy_fit
    want, _, _, _ = profile.profile_edges(s.problem, theta, chi2, 0, LEVELS, s.lower, s.upper,
                                          cinv)
    real, calls = profile.polish, []

    def singular_when_stepped(problem, start, *args, **kwargs):
        # every x's first start fails, as a singular corner would
        calls.append(float(start[0]))
        if calls.count(float(start[0])) == 1:
            return {"theta": np.asarray(start), "chi2": problem.chi2(start), "status": "failed",
                    "message": "curvature matrix singular"}
        return real(problem, start, *args, **kwargs)
    monkeypatch.setattr(profile, "polish", singular_when_stepped)
    got, _, _, _ = profile.profile_edges(s.problem, theta, chi2, 0, LEVELS, s.lower, s.upper,
                                         cinv)
    np.testing.assert_allclose(np.array(got, dtype=float), np.array(want, dtype=float),
                               rtol=0.02)


def test_an_edge_the_fits_cannot_reach_is_taken_to_the_bound_and_said_to_be_the_searchs(
        noisy_fit, monkeypatch):
    """Every constrained fit below a point between the fit and its lower 95% edge fails (as at
    a singular corner), however started: that edge is the bound, the other as before, and
    profile_edges says where it gave up, which the fit's warnings then name as the search's
    limit rather than the data's."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.fit_warnings import search_warnings
    from skyfit_mi.fitting.intervals import _search_open
    from skyfit_mi.fitting.methods import profile

    s, theta, chi2, cinv = noisy_fit
    want, _, _, none = profile.profile_edges(s.problem, theta, chi2, 0, LEVELS, s.lower,
                                             s.upper, cinv)
    assert none == {}
    wall = theta[0] - 0.3 * (theta[0] - want[1][0])
    real = profile.polish

    def failing_below(problem, start, *args, **kwargs):
        if start[0] < wall:
            return {"theta": np.asarray(start), "chi2": problem.chi2(start), "status": "failed",
                    "message": "curvature matrix singular"}
        return real(problem, start, *args, **kwargs)
    monkeypatch.setattr(profile, "polish", failing_below)
    got, _, _, gave_up = profile.profile_edges(s.problem, theta, chi2, 0, LEVELS, s.lower,
                                               s.upper, cinv)
    assert got[1][0] == s.lower[0] and got[1][1] == pytest.approx(want[1][1], rel=0.02)
    assert set(gave_up) >= {(1, 0)} and s.lower[0] < gave_up[1, 0] < theta[0]
    fit = SimpleNamespace(search_open={})
    _search_open(fit, s.names[0], ["68", "95"], gave_up, want[1], s.lower[0], s.upper[0])
    assert fit.search_open == {s.names[0]: [("lower", gave_up[1, 0])]}
    said, = search_warnings(fit.search_open)
    assert f"farthest point found inside, {s.names[0]} = {gave_up[1, 0]:.4g}" in said
    assert "the lower end of its 95% interval is taken to the bound" in said
    # where the interval's other source reaches the bound too, the data leave it open: no word
    fit.search_open = {}
    _search_open(fit, s.names[0], ["68", "95"], gave_up, (s.lower[0], want[1][1]), s.lower[0],
                 s.upper[0])
    assert fit.search_open == {}


def test_a_fit_failing_inside_the_68_edge_does_not_stop_the_95_search(monkeypatch):
    """chi^2 = a^2 + (b - 0.5)^2 / 0.01, constrained fits failing for a in (-1.2, -0.9) only:
    such a failure lies outside the 68% edge (a = -1) but inside the 95% one (-1.96), where its
    start's chi-square (an upper bound) says so; the 95% search steps past it to -1.96 and
    does not give up (before, the 68% search's failure blocked it, and the edge fell to the
    bound of -10)."""
    from skyfit_mi.fitting.methods import profile

    class Bowl(_Banana):
        def residuals(self, t):
            return np.array([t[0], (t[1] - 0.5) / 0.1])

        def jacobian(self, t):
            return self.residuals(t), np.array([[1.0, 0.0], [0.0, 10.0]])

    real = profile.polish

    def failing_in_a_window(problem, start, *args, **kwargs):
        if -1.2 < start[0] < -0.9:
            return {"theta": np.asarray(start), "chi2": problem.chi2(start), "status": "failed",
                    "message": "curvature matrix singular"}
        return real(problem, start, *args, **kwargs)
    monkeypatch.setattr(profile, "polish", failing_in_a_window)
    lower, upper = np.array([-10.0, -10.0]), np.array([10.0, 10.0])
    edges, _, _, gave_up = profile.profile_edges(Bowl(), np.array([0.0, 0.5]), 0.0, 0,
                                                 [1.0, 3.84], lower, upper, np.diag([1, 0.01]))
    assert edges[1][0] == pytest.approx(-1.96, abs=0.03), edges
    assert (1, 0) not in gave_up, gave_up          # the 68% edge's own search may give up
