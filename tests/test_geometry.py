"""The day's highlight geometry: the closest sun half-angle, the roughness it can reveal, and
the warnings drawn from them."""
import numpy as np
import pytest

from skyfit_mi.fitting.geometry import (ANGLES_BEYOND_DEG, TRACE, angles_beyond,
                                        geometry_warnings, highlight_geometry, sun_view_angles,
                                        traceless_roughness)
from skyfit_mi.fitting.uncertainty import misfit


def test_highlight_geometry_takes_the_closest_lit_approach_per_frame():
    c = np.full((2, 3, 4, 3), np.nan)                  # 2 pixels, 3 frames, 4 positions
    c[0, 0, :, 0] = np.cos(np.radians([20, 25, 30, 35]))
    c[1, 0, 0, 0] = np.cos(np.radians(12.0))
    c[0, 0, :, 1] = np.cos(np.radians([40, 41, 42, 43]))
    c[1, 0, 0, 1] = np.cos(np.radians(50.0))
    c[:, 0, :, 2] = np.cos(np.radians(30.0))
    c[:, 2, 1] = np.cos(np.radians([40.0, 10.0, 45.0]))     # frame 1 has no sun
    g = highlight_geometry(c)
    assert g["frames"] == 3 and g["frames_with_sun"] == 2
    assert g["closest_half_angle_per_frame_deg"][1] is None
    assert g["closest_half_angle_per_frame_deg"][0] == pytest.approx(12.0)
    assert g["closest_highlight_half_angle_deg"] == pytest.approx(12.0)
    # the median of the five lit positions' (theta_h, theta_d); none without sun
    np.testing.assert_allclose(g["sun_angles_per_frame_deg"][0], [25.0, 42.0])
    np.testing.assert_allclose(g["sun_angles_per_frame_deg"][2], [40.0, 10.0])
    assert g["sun_angles_per_frame_deg"][1] is None
    assert g["sun_view_angles_per_frame_deg"][1] is None
    assert g["sun_view_angles_per_frame_deg"][2][0] == pytest.approx(45.0)
    none = highlight_geometry(np.full((2, 3, 4, 3), np.nan))
    assert none["frames_with_sun"] == 0 and none["closest_highlight_half_angle_deg"] is None


def test_sun_view_angles_are_those_of_the_directions_they_came_from():
    """(theta_i, theta_o, phi) recovered from the half vector's cosines and the sun's, as the
    light cache keeps them, equal those read off random sun and view directions directly, and
    exchanging sun and view exchanges theta_i and theta_o alone."""
    rng = np.random.default_rng(3)
    ti, to = np.radians(rng.uniform(1, 89, (2, 200)))
    pi_, po = rng.uniform(-np.pi, np.pi, (2, 200))
    sun = np.stack([np.sin(ti) * np.cos(pi_), np.sin(ti) * np.sin(pi_), np.cos(ti)], axis=1)
    view = np.stack([np.sin(to) * np.cos(po), np.sin(to) * np.sin(po), np.cos(to)], axis=1)

    def cosines(s, v):
        h = (s + v) / np.linalg.norm(s + v, axis=1, keepdims=True)
        return np.stack([h[:, 2], np.sum(s * h, axis=1), s[:, 2]], axis=1)
    phi = np.abs((pi_ - po + np.pi) % (2 * np.pi) - np.pi)
    expected = np.degrees(np.stack([ti, to, phi], axis=1))
    np.testing.assert_allclose(sun_view_angles(cosines(sun, view)), expected, atol=1e-5)
    np.testing.assert_allclose(sun_view_angles(cosines(view, sun)), expected[:, [1, 0, 2]],
                               atol=1e-5)


def test_angles_beyond_the_fits_are_those_far_from_every_pair_it_saw():
    """A frame's sun and view are beyond the fit's where every fitted frame's (theta_i,
    theta_o, phi) lies over ANGLES_BEYOND_DEG away, with sun and view exchanged as well; never
    without sun in the frame, always where the fit saw no sun."""
    fitted = [[60.0, 45.0, 20.0], None, [30.0, 45.0, 90.0]]
    assert not angles_beyond(fitted, [62.0, 45.0, 30.0])
    assert not angles_beyond(fitted, [45.0, 60.0, 20.0])             # reciprocity
    assert angles_beyond(fitted, [60.0, 45.0, 20.0 + ANGLES_BEYOND_DEG + 1])
    assert angles_beyond(fitted, [75.0, 45.0, 150.0])
    assert not angles_beyond(fitted, None)
    assert angles_beyond([None, None], [30.0, 45.0, 90.0])


@pytest.mark.parametrize("delta", [1.0, 5.0, 16.0, 30.0])
def test_traceless_roughness_is_where_the_lobe_at_the_closest_approach_reaches_the_trace(delta):
    """Ward's lobe at normal incidence relative to a white Lambertian, exp(-tan^2 d/s^2)/(4 s^2),
    equals TRACE (1%) at the returned roughness, and is below it for every narrower lobe."""
    s = traceless_roughness(delta)
    t = np.tan(np.radians(delta))
    rel = lambda sig: np.exp(-(t / sig) ** 2) / (4 * sig**2)
    assert rel(s) < TRACE < rel(s * 1.01)
    assert np.all(rel(np.geomspace(1e-3, s, 50)) < TRACE)
    assert traceless_roughness(0.0) == 0.0


def test_hand_value_of_the_traceless_roughness():
    # delta = 16 deg: tan = 0.2867; sigma = 0.1028 gives exp(-7.78) / 0.0423 = 0.0099
    assert traceless_roughness(16.0) == pytest.approx(0.1028, abs=5e-4)


def test_geometry_warnings():
    sunless = {"frames": 5, "frames_with_sun": 0, "closest_highlight_half_angle_deg": None}
    assert "no frame has the sun" in geometry_warnings(sunless, 0.1)[0]
    far = {"frames": 5, "frames_with_sun": 5, "closest_highlight_half_angle_deg": 20.0}
    w = geometry_warnings(far, 0.05)
    assert len(w) == 1 and "never comes closer than 20.0 degrees" in w[0]
    assert w[0].startswith("sigma_alpha")                 # names what it warns about
    assert geometry_warnings(far, 0.3) == []
    # a sky whose shape the fit took from a model: rho_s too rests on the sky's reflection
    # (with the spec's sky as exact, its interval stands: no "not determined" beside it)
    assert "not determined" not in w[0] and "its interval holds as far as" in w[0]
    modelled = geometry_warnings(far, 0.05, sky_shape_known=False)
    assert modelled[0].startswith(w[0].split("; its interval")[0])
    assert "treat it as not determined below" in modelled[0]
    assert modelled[1].startswith("rho_s rests on the sky's reflection")
    assert geometry_warnings(far, 0.3, sky_shape_known=False) == []
    # a fit above the limit whose interval reaches below it: chi-square is flat there
    reach = geometry_warnings(far, 0.3, lowest=0.0)
    assert len(reach) == 1 and "its 95% interval down to 0" in reach[0]
    assert geometry_warnings(far, 0.3, lowest=0.29) == []
    near = {"frames": 5, "frames_with_sun": 5, "closest_highlight_half_angle_deg": 1.0}
    assert geometry_warnings(near, 0.01) == []


def test_misfit_counts_the_models_own_noise_and_grades_the_excess():
    dof = 600
    assert misfit(620.0, dof, 1.03) == []                       # p = 0.27
    mild = misfit(1.25 * dof, dof, 1.25)
    assert len(mild) == 1 and "more misfit than the noise explains" in mild[0]
    bad = misfit(4.0 * dof, dof, 4.0)
    assert "does not describe these data" in bad[0] and "not reliable" in bad[0]
    # the same chi-square is expected when the model's Monte Carlo error adds 3 dof's worth
    assert misfit(4.0 * dof, dof, 4.0, model_noise=3.0 * dof) == []
    # clipping near code 0: noise alone expects 1.2 dof (and a narrower spread), so 1.21 dof
    # is no misfit, while against dof it is (the overcast test day at 5% noise)
    assert misfit(1.21 * dof, dof, 1.0, noise=(1.2 * dof, 1.1 * dof)) == []
    assert misfit(1.21 * dof, dof, 1.21) != []


@pytest.mark.parametrize("value, interval, expected", [
    (0.1, (0.09, 0.11), "sigma_alpha = 0.1 (95%: 0.09-0.11)"),
    (0.003, (0.0, 0.0965), "sigma_alpha < 0.0965 (95%); lower end not determined"),
    (0.0, (0.0, 0.01), "sigma_alpha < 0.01 (95%); lower end not determined"),
    (0.45, (0.3, 0.5), "sigma_alpha > 0.3 (95%); upper end not determined"),
    (0.2, (0.0, 0.5), "sigma_alpha not determined (its 95% interval spans 0-0.5)"),
])
def test_one_sided_results_read_as_limits(value, interval, expected):
    from skyfit_mi.fitting.uncertainty import reading
    assert reading("sigma_alpha", value, interval, 0.0, 0.5) == expected


def test_a_frames_highlight_is_beyond_the_fits_where_the_lobe_there_doubles():
    """Hand values: the fit's closest highlight at 13.5 deg, a frame's at 12 deg: Ward's lobe
    rises by exp((tan^2 13.5 - tan^2 12) / sigma^2), e^1.94 = 7x for sigma 0.08 (beyond),
    e^0.14 for 0.3 (within LOBE_BEYOND = 2); a frame farther off, or without sun, is within;
    any sunlit frame is beyond a fit that saw no sun; nearer by under NEARER_DEG is within."""
    from skyfit_mi.fitting.geometry import LOBE_BEYOND, highlight_beyond

    rise = (np.tan(np.radians(13.5)) ** 2 - np.tan(np.radians(12.0)) ** 2) / 0.08**2
    assert rise == pytest.approx(1.94, abs=0.01) and np.exp(rise) > LOBE_BEYOND
    assert highlight_beyond(13.5, 12.0, 0.08)
    assert not highlight_beyond(13.5, 12.0, 0.3)
    assert not highlight_beyond(13.5, 20.0, 0.08) and not highlight_beyond(13.5, None, 0.08)
    assert highlight_beyond(None, 40.0, 0.2) and not highlight_beyond(None, None, 0.2)
    assert highlight_beyond(13.5, 12.0, 0.0)                 # a mirror: any nearer approach,
    assert not highlight_beyond(13.5, 13.0, 0.0)             # beyond NEARER_DEG


def test_a_roughness_interval_reaching_sky_only_lobes_is_open_below():
    """The roughness's lower end is left open where its 95% interval reaches lobes the sun
    does not show (below the sky-only limit, 0.076 at a closest highlight of 12.4 degrees) in
    photographs or under a sky shape only modelled, also where the reading itself lies above
    that limit (the hazy board's gloss paint: 0.085, 0.067-0.103, for 0.02); not where the
    whole interval lies above it, nor for rendered frames under their own sky's shape, nor
    for a table's points."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.geometry import sky_only_limit
    from skyfit_mi.fitting.intervals import sky_only_reach

    geometry = {"frames": 13, "frames_with_sun": 13, "closest_highlight_half_angle_deg": 12.4}
    assert sky_only_limit(geometry) == pytest.approx(0.076, abs=1e-3)

    def session(source="ingest", rays=None):
        return SimpleNamespace(doc={"source": source}, obs=SimpleNamespace(rays=rays),
                               names=("C_r", "C_g", "C_b", "rho_s", "sigma_alpha"),
                               geometry=geometry)

    def iv(lo, hi):
        return {"sigma_alpha": {"95": (lo, hi)}}
    assert "photographs' shared errors" in sky_only_reach(session(), True, iv(0.067, 0.103))
    assert sky_only_reach(session(), True, iv(0.080, 0.103)) == ""
    assert sky_only_reach(session("render"), True, iv(0.067, 0.103)) == ""
    assert "sky's shape not fitted" in sky_only_reach(session("render"), False, iv(0.067, 0.1))
    assert sky_only_reach(session(rays=np.zeros(3)), True, iv(0.067, 0.103)) == ""


class _Lobe:
    """Radiance a (1 + u_t) + b w_pt (P, T, 3): a the level over the day's curve u, b the
    last parameter (a lobe's stand-in) times a shape w that is either a pattern across the
    region alone (zero mean in every frame) or a curve over the day (the same in every
    pixel)."""

    names = ("a", "sigma_alpha")

    def __init__(self, w):
        T = w.shape[1]
        self.u = np.linspace(-0.2, 0.2, T)[None, :, None]
        self.w = w[..., None]

    def radiance(self, theta):
        return theta[0] * (1 + self.u) + theta[1] * self.w + 0.0 * self.u

    def radiance_and_variance(self, theta):
        L = self.radiance(theta)
        return L, np.zeros_like(L)

    def jacobian(self, theta):
        L = self.radiance(theta)
        J = np.stack([np.broadcast_to(1 + self.u, L.shape),
                      np.broadcast_to(self.w, L.shape)], axis=-1)
        return L, J


def test_a_lobe_told_apart_only_by_its_pattern_across_the_region_leaves_the_lower_end_open():
    """In photographs the roughness's lower end is open where the region's mean in each frame
    does not exclude a lobe at the sky-only limit (intervals.frame_means_admit): a last
    parameter that moves only the pattern across the region, which the pixels (64, 13 frames,
    0.5% noise) pin to a Delta chi^2 of hundreds, is left open from the means, and one that
    moves the day's curve of the means is not."""
    from types import SimpleNamespace

    from skyfit_mi.fitting.chi2 import Observations, Problem
    from skyfit_mi.fitting.intervals import frame_means_admit, sky_only_reach
    from skyfit_mi.fitting.methods.levenberg_marquardt import levenberg_marquardt
    from skyfit_mi.physics.camera import SensorModel

    rng = np.random.default_rng(4)
    P, T = 64, 13
    sensor = SensorModel(exposure=1.0, bits=16, noise_percent=0.5)
    pattern = rng.normal(size=(P, T))
    pattern -= pattern.mean(axis=0)
    curve = np.broadcast_to(np.linspace(0, 1, T) ** 2, (P, T))
    geometry = {"frames": T, "frames_with_sun": T, "closest_highlight_half_angle_deg": 12.4}
    limit = 0.076                                 # sky_only_limit of that geometry
    for w, admitted in ((pattern, True), (curve, False)):
        model = _Lobe(0.05 * w)
        L = model.radiance([0.5, 0.2])
        y = np.rint(L * sensor.max_code * (1 + 0.005 * rng.standard_normal(L.shape)))
        obs = Observations(np.zeros((P, 2), int), list(range(T)), None, y,
                           0.005 * y, np.ones(L.shape), sensor)
        problem = Problem(obs, model)
        lower, upper = np.zeros(2), np.ones(2)
        res = levenberg_marquardt(problem, np.array([0.4, 0.1]), lower, upper)
        theta = np.asarray(res["theta"])
        assert theta[1] == pytest.approx(0.2, abs=0.01)
        s = SimpleNamespace(doc={"source": "ingest", "frames": [], "sensor": {}},
                            obs=obs, names=model.names, lower=lower, upper=upper,
                            geometry=geometry)
        fit = SimpleNamespace(problem=problem, theta=theta)
        held = levenberg_marquardt(problem, np.array([theta[0], limit]), lower, upper,
                                   fixed=(1,))
        assert held["chi2"] - res["chi2"] > 100          # the pixels exclude the limit's lobe
        assert frame_means_admit(s, fit, limit) is admitted
        intervals = {"sigma_alpha": {"95": (theta[1] - 0.01, theta[1] + 0.01)}}
        assert bool(sky_only_reach(s, True, intervals, fit)) is admitted
