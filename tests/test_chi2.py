"""Chi-square: values clipped at either end of the sensor's range are censored, not exact
(Tobit likelihood); label masks."""
import numpy as np
import pytest
from scipy.optimize import minimize_scalar
from scipy.stats import norm

from skyfit_mi.errors import SkyfitError
from skyfit_mi.physics.camera import SensorModel
from skyfit_mi.fitting.chi2 import LOW_CODE, Observations, Problem


class _Flat:
    """Radiance a (the one parameter) at every pixel, frame and channel."""

    names = ("a",)

    def __init__(self, shape):
        self.shape = shape

    def radiance(self, theta):
        return np.full(self.shape, float(theta[0]))

    def jacobian(self, theta):
        return self.radiance(theta), np.ones(self.shape + (1,))

    def radiances(self, thetas):
        return np.stack([self.radiance(t) for t in thetas])


def _problem(mean_dn, noise_percent=10.0, n=4000, seed=0):
    sensor = SensorModel(exposure=1.0, bits=8, noise_percent=noise_percent)
    rng = np.random.default_rng(seed)
    shape = (n, 1, 3)
    y = np.clip(np.rint(mean_dn + rng.normal(0, sensor.sigma, shape)), 0, sensor.max_code)
    obs = Observations(np.zeros((n, 2), int), [0], ["t"], y, np.full(shape, sensor.sigma),
                       np.ones(shape), sensor)
    return Problem(obs, _Flat(shape)), sensor


@pytest.mark.parametrize("mean_dn, side", [(10.0, 0), (245.0, 1)])
def test_censored_residuals_and_jacobian(mean_dn, side):
    problem, sensor = _problem(mean_dn, n=50)
    clipped = problem.clipped()[side]
    assert clipped.any() and not clipped.all() and not problem.clipped()[1 - side].any()
    m = mean_dn + 2.0
    theta = np.array([m / sensor.max_code])
    r, J = problem.jacobian(theta)
    edge = (LOW_CODE - m) if side == 0 else (m - sensor.max_code + LOW_CODE)
    expected = np.sqrt(-2 * norm.logcdf(edge / sensor.sigma))
    assert np.allclose(r[clipped[problem.mask]], expected)
    h = 1e-6
    fd = (problem.residuals(theta + h) - problem.residuals(theta - h)) / (2 * h)
    assert np.allclose(J[:, 0], fd, rtol=1e-5, atol=1e-8)


@pytest.mark.parametrize("mean_dn", [10.0, 128.0])
def test_chi2_of_many_radiances_at_once_is_each_ones(mean_dn):
    """Problem.chi2s (the draws' likelihood) gives chi2 of each radiance, values clipped at
    the bottom (censored terms) or none."""
    problem, sensor = _problem(mean_dn, n=50)
    assert problem.clipped()[0].any() == (mean_dn == 10.0)
    thetas = np.linspace(0.5, 1.5, 7)[:, None] * mean_dn / sensor.max_code
    radiances = np.stack([problem.model.radiance(t) for t in thetas])
    np.testing.assert_allclose(problem.chi2s(radiances), [problem.chi2(t) for t in thetas],
                               rtol=1e-12)


def test_chi2_at_many_parameter_sets_in_chunks_is_each_ones(monkeypatch):
    """Problem.chi2_at (the global search's ranking, the draws' likelihood): chi2 of each set,
    the sets' radiances taken a few at a time where they would not fit at once."""
    from skyfit_mi.fitting import chi2

    problem, sensor = _problem(10.0, n=50)
    monkeypatch.setattr(chi2, "CHUNK_VALUES", 2 * problem.obs.y.size)
    thetas = np.linspace(0.5, 1.5, 7)[:, None] * 10.0 / sensor.max_code
    np.testing.assert_allclose(problem.chi2_at(thetas), [problem.chi2(t) for t in thetas],
                               rtol=1e-12)


@pytest.mark.parametrize("mean_dn, side", [(10.0, 0), (245.0, 1)])
def test_clipped_values_give_an_unbiased_estimate(mean_dn, side):
    # a channel 10 DN from either end under noise of sigma 25.5 DN: a third of its values clip
    problem, sensor = _problem(mean_dn)
    assert 0.25 < problem.clipped()[side].mean() < 0.45
    fit = minimize_scalar(lambda a: problem.chi2([a / sensor.max_code]), bounds=(0, 300),
                          method="bounded")
    se = sensor.sigma / np.sqrt(problem.n_data)
    assert fit.x == pytest.approx(mean_dn, abs=4 * se)              # about 1.4 DN
    naive = problem.obs.y.mean()                                     # clipped values taken as measured
    assert abs(naive - mean_dn) > 10 * se


def test_captured_saturation_is_censored_and_unbiased():
    """The sensor model's own capture near full scale: about half the values read the top code
    (saturated by the captured value, sigma finite); the censored fit recovers the radiance."""
    sensor = SensorModel(exposure=1.0, bits=8, noise_percent=4.0)
    n, level = 3000, 0.99
    values, sigma = sensor.capture(np.full((n, 1, 3), level), np.random.default_rng(5))
    y = values.astype(float)
    obs = Observations(np.zeros((n, 2), int), [0], ["t"], y, sigma.astype(float),
                       np.ones(y.shape), sensor)
    problem = Problem(obs, _Flat(y.shape))
    assert problem.n_data == y.size and 0.3 < problem.clipped()[1].mean() < 0.6
    fit = minimize_scalar(lambda a: problem.chi2([a]), bounds=(0.8, 1.0), method="bounded")
    se = sensor.sigma / sensor.max_code / np.sqrt(y.size)
    assert fit.x == pytest.approx(level, abs=5 * se)


def test_label_masks_of_8_and_16_bits(tmp_path):
    from PIL import Image

    from skyfit_mi.fitting.chi2 import region_from_mask

    m16 = np.zeros((4, 5), np.uint16)
    m16[1, 2] = m16[3, 0] = 300                        # beyond 8 bits: many materials
    Image.fromarray(m16).save(tmp_path / "m16.png")
    assert sorted(map(tuple, region_from_mask(tmp_path / "m16.png", 300))) == [(0, 3), (2, 1)]
    m8 = np.zeros((4, 5, 3), np.uint8)
    m8[2, 3] = 7
    Image.fromarray(m8).save(tmp_path / "m8.png")
    assert region_from_mask(tmp_path / "m8.png", 7).tolist() == [[3, 2]]
    with pytest.raises(SkyfitError, match="label 8 does not occur in mask"):
        region_from_mask(tmp_path / "m8.png", 8)


@pytest.mark.parametrize("mean_dn", [10.0, 128.0, 245.0])
def test_noise_alone_gives_the_censored_chi2_expectation(mean_dn):
    """chi^2 at the truth over noise replicates has the mean and spread of noise_chi2, which is
    (dof, 2 dof) where nothing clips and larger where a third of the values clip (so the misfit
    test does not read clipping as misfit)."""
    values = []
    for seed in range(40):
        problem, sensor = _problem(mean_dn, n=500, seed=seed)
        values.append(problem.chi2([mean_dn / sensor.max_code]))
    mean, var = problem.noise_chi2([mean_dn / sensor.max_code])
    assert np.mean(values) == pytest.approx(mean, abs=4 * np.sqrt(var / len(values)))
    assert np.var(values, ddof=1) == pytest.approx(var, rel=0.5)
    if mean_dn == 128.0:
        assert (mean, var) == pytest.approx((problem.dof, 2 * problem.dof), rel=1e-4)
    else:
        assert mean > problem.dof + 6 * np.sqrt(var)       # dof alone would read as misfit


def test_censored_term_moments_match_sampling():
    from scipy.special import ndtr

    from skyfit_mi.fitting.chi2 import censored_term_moments
    e = np.random.default_rng(3).standard_normal(400_000)
    for a, b in ((0.0, np.inf), (-1.0, 1.0), (1.5, np.inf), (-np.inf, 0.3), (-0.3, 2.0)):
        low = -2 * np.log(ndtr(a)) if np.isfinite(a) else 0.0
        high = -2 * np.log(ndtr(-b)) if np.isfinite(b) else 0.0
        t = np.where(e < a, low, np.where(e > b, high, e * e))
        mean, var = censored_term_moments(a, b)
        assert mean == pytest.approx(t.mean(), abs=5 * t.std() / np.sqrt(t.size))
        assert var == pytest.approx(t.var(), rel=0.03)


class _ByFrame(_Flat):
    """Radiance ``levels[t]`` in frame t at every pixel and channel (no parameter used)."""

    def __init__(self, levels, shape):
        super().__init__(shape)
        self.levels = np.asarray(levels, dtype=float)

    def radiance(self, theta):
        return np.broadcast_to(self.levels[None, :, None], self.shape).copy()


def test_the_measured_range_runs_from_the_dimmest_mean_told_to_the_brightest_value_measured():
    """Three frames at 2, 100 and 254 DN of 255 (1% noise, 16 pixels): the dim one's mean is
    not told to 10% (standard error 32% of it), the bright one holds values clipped at the top
    code, so the region means' range runs from the middle frame's level to the brightest
    value below the top code; each value on its own (a table's points) alike.  relight's
    beyond_data places a prediction against it."""
    from skyfit_mi.fitting.relight import beyond_data

    sensor = SensorModel(exposure=1.0, bits=8, noise_percent=1.0)
    levels = np.array([2.0, 100.0, 254.0])
    shape = (16, 3, 3)
    rng = np.random.default_rng(2)
    y = np.clip(np.rint(levels[None, :, None] + rng.normal(0, sensor.sigma, shape)), 0,
                sensor.max_code)
    assert (y[:, 2] >= sensor.max_code).any() and (y[:, 2] < sensor.max_code).any()
    obs = Observations(np.zeros((16, 2), int), [0, 1, 2], ["a", "b", "c"], y,
                       np.full(shape, sensor.sigma), np.ones(shape), sensor)
    radiance = levels / sensor.max_code
    problem = Problem(obs, _ByFrame(radiance, shape))
    L = problem.model.radiance(None)
    for means in (True, False):
        ranges = problem.measured_range(L, means=means)
        assert ranges == [[pytest.approx(radiance[1]), pytest.approx(radiance[2])]] * 3
    result = {"measured_range": {"by_channel": {"R": [1.0, 2.0], "G": None}}}
    assert [beyond_data(result, "R", v) for v in (0.5, 1.5, 3.0)] == ["below", "", "above"]
    assert beyond_data(result, "G", 1.5) == "unmeasured" and beyond_data({}, "R", 9.0) == ""
    # a sun highlight the data never saw outranks the radiance's mark: what it misses is the peak
    assert beyond_data(result, "R", 0.5, "highlight") == "highlight"
    assert beyond_data(result, "R", 0.5, "angles") == "below"
    assert beyond_data(result, "R", 1.5, "angles") == "angles"


def test_a_highlight_is_beyond_the_data_if_any_lobe_the_interval_allows_peaks_there():
    """A roughness fitted at its bound 0.5 with the interval [0, 0.5] (the lobe unseen): a frame
    whose highlight lies 5 degrees nearer the mirror than any fitted frame's is beyond the data,
    since a sharp lobe the data allow peaks there; at the fit's own sigma it would not be."""
    from skyfit_mi.fitting.geometry import highlight_beyond
    from skyfit_mi.fitting.relight import sharpest_roughness

    result = {"parameters": {"sigma_alpha": 0.5}, "intervals": {"sigma_alpha": {"95": [0.0, 0.5]}}}
    assert sharpest_roughness(result) == 0.0
    assert highlight_beyond(12.0, 7.0, sharpest_roughness(result))
    assert not highlight_beyond(12.0, 7.0, 0.5)
    assert sharpest_roughness({"parameters": {"sigma_alpha": 0.2}}) == 0.2
    assert sharpest_roughness({"parameters": {"C_r": 0.5}}) == 0.0
