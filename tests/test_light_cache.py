"""The fitting model: the light cache against a render, its sampling, and the mirror limit."""
import numpy as np
import pytest

from skyfit_mi.fitting.chi2 import parse_region

REGION = parse_region("rect:4,4,7,7")          # 16 pixels, all on the disc


def test_stratified_samples_cover_the_square_uniformly():
    # n = 38 fills 38 of the 42 cells of a 7 x 6 grid; the cells left out must vary, or the
    # same corner stays unsampled and every estimate is biased
    from skyfit_mi.render.light_cache import _stratified
    rng = np.random.default_rng(3)
    u = _stratified(rng, 38, 3000).reshape(-1, 2)                 # 3000 independent sets
    assert _stratified(rng, 38).shape == (38, 2)
    hist, _, _ = np.histogram2d(u[:, 0], u[:, 1], bins=7, range=[[0, 1], [0, 1]])
    expected = len(u) / 49
    assert np.all(np.abs(hist / expected - 1) < 0.1), hist / expected      # sd 2.1%


def test_radiance_normalisation_is_refused_by_the_basis():
    """'radiance' (Radiance's Fresnel term for an ideal mirror) is outside the basis
    L = rho_d D + rho_s G(sigma): the NumPy basis and the Dr.Jit model refuse it in one line,
    before touching the cache."""
    from skyfit_mi.errors import SkyfitError
    from skyfit_mi.render.fit_model import WardModel
    from skyfit_mi.render.light_cache import LightCache
    for call in (lambda: LightCache.__new__(LightCache).specular_basis(0.0, "radiance"),
                 lambda: WardModel(None, "two", "radiance")):
        with pytest.raises(SkyfitError, match="normalisation 'radiance' cannot be fitted") as e:
            call()
        assert "\n" not in str(e.value)


def _raw(session):
    """What these tests need of a FitSession, with its raw light cache (samples kept) and the
    Dr.Jit model on it (a fit itself keeps only the cache's table)."""
    from types import SimpleNamespace

    from skyfit_mi.render.fit_model import WardModel
    cache = session.light_cache()
    return SimpleNamespace(obs=session.obs, scene=session.scene, params=session.params,
                           skies=session.skies, cache=cache,
                           wm=WardModel(cache, session.model, session.normalisation))


@pytest.fixture(scope="module")
def session(days):
    from skyfit_mi.fitting.fit import FitCache, FitSession
    return _raw(FitSession(days["clean"], "disc", REGION, model="two",
                           cache=FitCache(seed=5), light=None))


def test_cache_matches_the_render_without_bias(session, days):
    from skyfit_mi.pipeline.pixels import frame_values

    rendered = frame_values(days["clean"], session.obs.pixels, session.obs.frames)
    model = session.wm.radiance([0.3, 0.1])                   # the day's truth
    rel = model / rendered - 1
    # both are Monte Carlo estimates (1024 spp render; 32 x 128 cache samples per pixel), so
    # single values differ by about 0.4%; averages over the region must agree closely
    assert np.sqrt(np.mean(rel**2)) < 0.01
    assert np.all(np.abs(rel.mean(axis=(0, 2))) < 0.006), rel.mean(axis=(0, 2))   # per frame
    assert abs(rel.mean()) < 0.001


def test_model_is_continuous_down_to_the_mirror(session):
    from skyfit_mi.render.light_cache import SIGMA_RESOLVED
    wm = session.wm
    L = {s: wm.radiance([0.8, s]) for s in (0.0, 1e-7, SIGMA_RESOLVED * (1 - 1e-6), SIGMA_RESOLVED)}
    assert np.allclose(L[1e-7], L[0.0], rtol=1e-4)
    assert np.allclose(L[SIGMA_RESOLVED * (1 - 1e-6)], L[SIGMA_RESOLVED], rtol=1e-4)
    # halfway: the linear interpolation, also in the NumPy basis of the global method
    half = wm.radiance([0.8, SIGMA_RESOLVED / 2])
    assert np.allclose(half, 0.5 * (L[0.0] + L[SIGMA_RESOLVED]), rtol=1e-4)
    basis = 0.2 * session.cache.diffuse_basis() + 0.8 * session.cache.specular_basis(SIGMA_RESOLVED / 2)
    assert np.allclose(basis, half, rtol=1e-3)


@pytest.mark.parametrize("sigma", [0.01, 0.042])
def test_numpy_basis_with_the_control_variate_equals_the_model(session, sigma):
    # the NumPy twin (ward.specular_lobe, ward.lobe_albedo) and the Dr.Jit model (the plugin)
    basis = 0.2 * session.cache.diffuse_basis() + 0.8 * session.cache.specular_basis(sigma)
    assert np.allclose(basis, session.wm.radiance([0.8, sigma]), rtol=1e-4)


def test_narrow_lobe_matches_an_independent_quadrature(session):
    # sigma_alpha = 0.01, four times the sun's radius: the cache (with its control variate)
    # against reflection.reflected_radiance on a 4x4 grid of positions per pixel.  Without
    # the control variate this cache is off by up to 0.74% in a frame, 0.83% rms per value
    from skyfit_mi.physics.reflection import reflected_radiance
    from skyfit_mi.render.scene import pixel_views
    views = pixel_views(session.scene, session.obs.pixels, m=4)
    quad = np.stack([reflected_radiance(sky, views, 0.2, 0.8, 0.01).mean(axis=1)
                     for sky in session.skies], axis=1)
    model = session.wm.radiance([0.8, 0.01])
    per_frame = model.sum(axis=(0, 2)) / quad.sum(axis=(0, 2)) - 1
    assert np.all(np.abs(per_frame) < 2.5e-3), per_frame                # 0.14% with it
    assert np.sqrt(np.mean((model / quad - 1) ** 2)) < 0.004                 # 0.21%



def test_wide_nodes_are_each_halfs_mean_of_a_few_positions_and_narrow_ones_every_positions(
        session):
    """A fit's cache (a plan's wide_share) on a plane: the diffuse integral and the lobe's nodes of roughness
    >= WIDE_SIGMA are each half's mean over its first two positions (random ones: unbiased),
    the narrower nodes every position's own, with the same samples as a cache of every
    position's integrals."""
    from skyfit_mi.render.light_cache import SIGMA_TABLE, WIDE_SIGMA, SkyPlan, build_light_cache
    from skyfit_mi.render.sky_control import chebyshev_coefficients, chebyshev_nodes

    args = (session.scene, session.params, session.skies[4:7], session.obs.pixels[:6], "disc")
    few = build_light_cache(*args, positions=8, directions=32, seed=3,
                            plan=SkyPlan("half", wide_share=0.5))
    every = build_light_cache(*args, positions=8, directions=32, seed=3, plan="every")
    assert np.array_equal(few.weight, every.weight) and np.array_equal(few.wi, every.wi)
    n = every.lobe_sky.shape[3]
    x = np.cos(np.pi * (np.arange(n) + 0.5) / n)
    values = np.einsum("jk,ptskc->ptsjc", np.cos(np.outer(np.arccos(x), np.arange(n))),
                       every.lobe_sky.astype(float))                      # at the nodes
    wide = chebyshev_nodes(*SIGMA_TABLE) >= WIDE_SIGMA
    assert 0 < wide.sum() < n
    want_d = np.empty_like(every.diffuse_sky, dtype=float)
    want_v = values.copy()
    for half, first in ((slice(0, 4), 0), (slice(4, 8), 4)):
        want_d[:, :, half] = every.diffuse_sky[:, :, first:first + 2].mean(axis=2, keepdims=True)
        want_v[:, :, half][..., wide, :] = \
            values[:, :, first:first + 2][..., wide, :].mean(axis=2, keepdims=True)
    assert np.allclose(few.diffuse_sky, want_d, rtol=1e-5)
    want = chebyshev_coefficients(want_v, axis=3)
    tol = dict(rtol=1e-4, atol=1e-5 * np.abs(want).max())
    assert np.allclose(few.lobe_sky, want, **tol)
    assert not np.allclose(every.lobe_sky, want, **tol)     # the positions' values do differ


def test_the_suns_part_takes_every_node_at_a_few_positions(days):
    """The sun's part of a split light (Sky.split: its sky function the sun-lit ground alone,
    uniform below the horizon) on a plane tilted 60 degrees toward the camera, which sees the
    ground: every lobe node, not only the wide ones, is each half's mean over a few
    positions (unbiased), the same samples as every position's own; the pixels' means differ
    from those by under 1% of the ground's integrals (measured 0.3%: the ground changes
    across a pixel only for lobes that straddle the horizon), the diffuse one not at all."""
    import mitsuba as mi

    from skyfit_mi.fitting.fit import FitSession
    from skyfit_mi.render.light_cache import SkyPlan, build_light_cache

    s = FitSession(days["clean"], "disc", REGION, model="two", light=None)
    xml = s.doc["scene"]["xml"].replace(
        '<shape type="disk" id="disc_shape">', '<shape type="disk" id="disc_shape"><transform '
        'name="to_world"><rotate y="1" angle="60"/></transform>')
    assert xml != s.doc["scene"]["xml"]
    scene = mi.load_string(xml)
    sun = [sky.split()[0] for sky in s.skies[4:7]]
    assert all(k.ground_only for k in sun) and not any(k.ground_only for k in s.skies)
    args = (scene, mi.traverse(scene), sun, s.obs.pixels[:6], "disc")
    few = build_light_cache(*args, positions=8, directions=32, seed=3,
                            plan=SkyPlan("half", wide_share=0.5))
    every = build_light_cache(*args, positions=8, directions=32, seed=3, plan="every")
    assert np.array_equal(few.weight, every.weight)
    assert np.abs(every.diffuse_sky).max() > 0 and np.abs(every.lobe_sky[..., 0, :]).max() > 0
    for half, first in ((slice(0, 4), 0), (slice(4, 8), 4)):
        want = every.lobe_sky[:, :, first:first + 2].astype(float).mean(axis=2)
        assert np.allclose(few.lobe_sky[:, :, half], want[:, :, None], rtol=1e-5,
                           atol=1e-6 * np.abs(want).max())
    means = [c.lobe_sky[..., 0, :].astype(float).mean(axis=2) for c in (few, every)]
    assert np.abs(means[0] - means[1]).max() < 0.01 * np.abs(means[1]).max()
    assert np.allclose(few.diffuse_sky.mean(axis=2), every.diffuse_sky.mean(axis=2), rtol=1e-5)


def test_a_curved_or_coarse_footprint_keeps_the_wide_parts_at_every_position():
    """_small_footprints: a plane seen in a fine pixel passes; normals or mirror directions
    spread by more than WIDE_SPREAD_DEG in one pixel (a sphere, a coarse pixel), or a position
    off every surface, send the cache back to every position's integrals."""
    from skyfit_mi.render.light_cache import WIDE_SPREAD_DEG, _small_footprints

    rng = np.random.default_rng(2)
    P, S = 5, 8

    def spread(deg):                 # directions within deg of +z, per pixel and position
        a = np.radians(deg) * np.sqrt(rng.random((P, S)))
        phi = 2 * np.pi * rng.random((P, S))
        return np.stack([np.sin(a) * np.cos(phi), np.sin(a) * np.sin(phi), np.cos(a)],
                        axis=-1).reshape(P * S, 3)
    plane, fine = np.tile([0.0, 0.0, 1.0], (P * S, 1)), spread(0.3 * WIDE_SPREAD_DEG)
    assert _small_footprints(plane, fine, P, S)
    assert not _small_footprints(spread(3 * WIDE_SPREAD_DEG), fine, P, S)     # curved
    assert not _small_footprints(plane, spread(3 * WIDE_SPREAD_DEG), P, S)    # coarse
    off = plane.copy()
    off[7] = 0.0                                                  # a position that missed
    assert not _small_footprints(off, fine, P, S)

def _fd_tolerance(L, fd, h):
    """What a derivative may differ from the central difference ``fd`` of step ``h``: 0.2% of
    its scale, plus the difference quotient's own error, single-precision rounding of L / 2 h."""
    return 2e-3 * np.max(np.abs(fd)) + 4 * np.finfo(np.float32).eps * np.max(np.abs(L)) / (2 * h)


@pytest.mark.parametrize("sigma", [0.001, 0.02, 0.042, 0.05])
def test_jacobian_matches_finite_differences(session, sigma):
    # 0.001: the linear interpolation to the mirror (a step inside it); 0.02: with the control
    # variate; 0.042: where its weight falls; 0.05: without it
    wm = session.wm
    theta = np.array([0.6, sigma])
    L, J = wm.jacobian(theta)
    for i, h in enumerate((1e-3, 9e-4 if sigma < 0.002 else 1e-4)):
        d = np.zeros(2)
        d[i] = h
        fd = (wm.radiance(theta + d) - wm.radiance(theta - d)) / (2 * h)
        assert np.max(np.abs(J[..., i] - fd)) < _fd_tolerance(L, fd, h), i


def test_new_parameters_reuse_the_compiled_kernels(session):
    # parameters enter the kernels as inputs, not literals: an evaluation at a new theta
    # must not compile anything (that cost 7x the evaluation itself)
    import drjit as dr
    wm = session.wm
    for theta in ([0.3, 0.1], [0.3, 0.02]):                  # without and with the control variate
        wm.radiance(theta)
        wm.jacobian(theta)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()                                   # clears it
        wm.radiance([0.55, 0.21])
        wm.jacobian([0.61, 0.07])
        wm.radiance([0.45, 0.013])
        wm.jacobian([0.71, 0.03])
        jit = [k for k in dr.kernel_history() if "cache_hit" in k]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert jit and all(k["cache_hit"] for k in jit), [(k["size"], k.get("operation_count")) for k in jit if not k["cache_hit"]]


@pytest.mark.parametrize("model, theta", [("colour", [0.25, 0.5, 0.75, 0.2, 0.05]),
                                          ("colour", [0.3, 0.6, 0.9, 0.7, 0.001]),
                                          ("achromatic", [0.5, 0.3, 0.02])])
def test_jacobian_through_the_basis_matches_the_plugin(session, model, theta):
    # L = rho_d D + s G(sigma): the value must be the plugin's own radiance, the columns of
    # the linear parameters exact secants, those of rho_s and sigma finite differences
    from skyfit_mi.render.fit_model import WardModel
    wm = WardModel(session.cache, model)
    theta = np.array(theta)
    L, J = wm.jacobian(theta)
    assert np.allclose(L, wm.radiance(theta), rtol=1e-5)
    n_lin = len(theta) - 2
    for i in range(n_lin):
        hi, lo = theta.copy(), theta.copy()
        hi[i], lo[i] = 1.0, 0.0
        secant = wm.radiance(hi) - wm.radiance(lo)
        assert np.allclose(J[..., i], secant, atol=1e-5 * np.max(np.abs(secant)))
    for i, h in ((n_lin, 1e-3), (n_lin + 1, 5e-4 if theta[-1] < 0.002 else 1e-4)):
        d = np.zeros(len(theta))
        d[i] = h
        fd = (wm.radiance(theta + d) - wm.radiance(theta - d)) / (2 * h)
        assert np.max(np.abs(J[..., i] - fd)) < _fd_tolerance(L, fd, h), i


@pytest.mark.slow
def test_full_render_model_replays_new_parameters_and_agrees_with_the_cache(session, days):
    """The full-render baseline of the benchmarks (scripts/bench_fit.py), 36 s of frozen-function
    recordings: run with the benchmarks (``pytest -m slow``), not by default."""
    from skyfit_mi.render.fit_model import RegionRenderModel
    from skyfit_mi.pipeline.manifest import load_manifest

    doc, _ = load_manifest(days["clean"])

    def model():
        return RegionRenderModel(doc["scene"]["xml"], "disc", session.skies, session.obs.pixels,
                                 "two", spp=64, seed=1)
    a = model()
    a.radiance([0.3, 0.1])                               # records the frozen frames
    replayed = a.radiance([0.7, 0.05])                   # replays them with new parameters
    # parameters on the bounds (annealing's probes) replay too: no new recordings
    c = RegionRenderModel(doc["scene"]["xml"], "disc", session.skies[:2], session.obs.pixels,
                          "colour", spp=4, seed=1)
    c.radiance([0.3, 0.4, 0.5, 0.2, 0.1])
    c.radiance([0.31, 0.4, 0.5, 0.2, 0.1])
    recorded = c._frame.n_recordings
    for theta in ([0.0, 0.4, 0.5, 0.2, 0.1], [0.3, 0.4, 0.5, 0.0, 0.1], [1.0, 1.0, 1.0, 1.0, 0.0]):
        c.radiance(theta)
    assert c._frame.n_recordings == recorded
    fresh = model().radiance([0.7, 0.05])
    assert np.allclose(replayed, fresh, rtol=1e-5)
    cached = session.wm.radiance([0.7, 0.05])
    assert abs(np.mean(replayed / cached) - 1) < 0.01


def test_the_sky_control_variate_makes_an_overcast_cache_nearly_exact(days):
    """Under a sky without sun the light is almost all the sky function, which the control
    variate integrates deterministically: the cache's own Monte Carlo error (its half caches'
    difference) falls from 0.62% rms per value (plain sampling, no sun directions) to 0.03%,
    no direction is spent on a sun that is not there, and the radiance agrees with the render."""
    from skyfit_mi.fitting.fit import FitCache, FitSession
    from skyfit_mi.pipeline.pixels import frame_values
    from skyfit_mi.render import light_cache
    from skyfit_mi.render.fit_model import WardModel

    assert light_cache._components(128, False).min() == 1          # no sun component
    session = _raw(FitSession(days["overcast"], "disc", REGION,
                              cache=FitCache(positions=8, directions=256, seed=3), light=None))
    for sigma in (0.01, 0.1, 0.3):
        a, b = (WardModel(c, "two").radiance([0.3, sigma]) for c in session.cache.halves())
        assert np.sqrt(np.mean(((a - b) / (a + b)) ** 2)) < 1e-3, sigma
    rendered = frame_values(days["overcast"], session.obs.pixels, session.obs.frames)
    assert abs((session.wm.radiance([0.3, 0.1]) / rendered - 1).mean()) < 0.003


def test_plastic_metal_rule_agrees_in_single_precision_at_the_threshold(days):
    """A rho_s just below 0.5 is a plastic in NumPy; in the float32 plugin it rounded up to 0.5,
    a metal: a dark glossy colour fit then saw a model 20-260x off at the threshold. The Dr.Jit
    model and the NumPy basis agree on either side of it."""
    from skyfit_mi.fitting.fit import FitCache, FitSession
    from skyfit_mi.render.fit_model import reflectances

    s = FitSession(days["clean"], "disc", REGION, model="colour",
                   cache=FitCache(positions=2, directions=128))
    D, G = s.wm.basis(np.array([0.05]))
    for rho_s in (0.4999, 0.49999999, float(np.nextafter(0.5, 0)), 0.5):
        theta = np.array([0.02, 0.03, 0.05, rho_s, 0.05])
        rho_d, spec, _, _ = reflectances("colour", theta)
        np.testing.assert_allclose(s.wm.radiance(theta), rho_d * D + spec * G[0], rtol=1e-4,
                                   atol=1e-6 * np.max(D), err_msg=str(rho_s))


def test_new_frames_reuse_the_compiled_kernels(session):
    """A light cache of other frames (other samples, other skies) compiles nothing: every
    per-frame value reaches the kernels from memory, opaque (the sky, the seeds) or in an
    aligned buffer (the samples: a NumPy buffer's alignment varies with its address, and a
    kernel is compiled for it; measured 4 compilations, 1.3 s, in one of six builds)."""
    import drjit as dr

    from skyfit_mi.render.light_cache import build_light_cache

    def build(seed, skies):
        build_light_cache(session.scene, session.params, skies, session.obs.pixels[:5], "disc",
                          positions=2, directions=32, seed=seed, plan="anchors")
    build(0, session.skies[:2])
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()                                   # clears it
        for seed in (1, 2, 3):
            build(seed, session.skies[seed:seed + 2])
        jit = [k for k in dr.kernel_history() if "cache_hit" in k]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert jit and all(k["cache_hit"] for k in jit), [(k["size"], k.get("operation_count")) for k in jit if not k["cache_hit"]]


def test_lights_traced_with_shared_samples_each_take_their_own_radiance(days):
    """A light's shape variants traced with the rest's samples (build_light_cache's
    ``others``): the first light's cache is the one it traces alone, a copy of it traced
    alongside is identical, and a variant's sky integrals and mirror rays (the same positions
    and random numbers) are those of its own trace with the seed; only the sampled
    directions' weights differ (its own trace samples its own sky)."""
    from skyfit_mi.fitting.fit import FitSession
    from skyfit_mi.fitting.light import LightPlan
    from skyfit_mi.render.light_cache import OWN_ARRAYS, build_light_cache

    s = FitSession(days["clean"], "disc", REGION, model="two", light=None)
    _, rest, variant, _ = (light[3:6] for light in
                              s._sky_parts(LightPlan("fit", shape=True)).values())
    args = (s.scene, s.params)
    where = (s.obs.pixels[:6], "disc")
    options = dict(positions=8, directions=32, seed=3)
    shared = build_light_cache(*args, rest, *where, others=[rest, variant], **options)
    alone = build_light_cache(*args, rest, *where, **options)
    own = build_light_cache(*args, variant, *where, **options)
    fields = ("wo", "wi", "weight", "inv_pdf", "mirror", "mirror_sky", "mirror_cos", "hit",
              "diffuse_sky", "lobe_sky")
    for k in fields:
        assert np.array_equal(getattr(shared[0], k), getattr(alone, k)), k
        assert np.array_equal(getattr(shared[1], k), getattr(alone, k)), k
    for k in ("mirror", "mirror_sky", "diffuse_sky", "lobe_sky"):
        a, b = getattr(shared[2], k), getattr(own, k)
        assert np.allclose(a, b, rtol=1e-5, atol=1e-6 * np.abs(b).max()), k
    # (the variant keeps the sky's horizontal irradiance: the level disc's I_d hardly moves)
    assert not np.allclose(shared[2].lobe_sky[..., 0, :], alone.lobe_sky[..., 0, :], rtol=1e-2)
    assert not np.array_equal(shared[2].wi, own.wi)            # its own trace samples its sky
    assert set(OWN_ARRAYS) < set(fields)
    with pytest.raises(ValueError, match="one sky without a map per frame"):
        build_light_cache(*args, rest, *where, others=[variant[:2]], **options)


def test_a_scene_hiding_part_of_the_sky_matches_the_render(tmp_path, days, monkeypatch):
    """Paths are traced only along directions the scene hides (a wall north of the disc: its
    shadow and its light), the rest take the emitter's own light: the cache still agrees with a
    full render, and a scene hiding nothing traces no path."""
    from pathlib import Path

    from skyfit_mi.fitting.fit import FitCache, FitSession
    from skyfit_mi.pipeline.pixels import frame_values
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import SCENES_DIR, thesis_disc_spec, validate_spec
    from skyfit_mi.render import light_cache

    wall = ('    <shape type="rectangle" id="wall">\n'
            '        <bsdf type="diffuse"><rgb name="reflectance" value="0.8"/></bsdf>\n'
            '        <transform name="to_world"><scale x="4" y="2"/><rotate x="1" angle="90"/>'
            '<translate y="1.5" z="2"/></transform>\n    </shape>\n</scene>')
    xml = (Path(SCENES_DIR) / "disc.xml").read_text().replace("</scene>", wall)
    (tmp_path / "walled.xml").write_text(xml)
    raw = thesis_disc_spec("walled", {"model": "two", "rho_s": 0.3, "sigma_alpha": 0.1},
                           size=12, seed=11, exposure=0.0015)
    raw["scene"]["file"] = "walled.xml"
    raw["time"].update(start="07:00", end="17:00", step_minutes=150)
    render_sequence(validate_spec(raw, tmp_path), tmp_path / "day", progress=False,
                    log=lambda *a: None)
    traced, paths = [], light_cache._paths

    def counting(*args):
        traced.append(1)
        return paths(*args)
    monkeypatch.setattr(light_cache, "_paths", counting)
    FitSession(days["clean"], "disc", REGION, model="two", cache=FitCache(seed=5),
               light=None).light_cache()
    assert not traced, "the disc alone hides nothing, yet paths were traced"
    s = _raw(FitSession(tmp_path / "day", "disc", REGION, model="two",
                        cache=FitCache(seed=5), light=None))
    assert traced, "the wall hides part of the sky, yet no path was traced"
    rendered = frame_values(tmp_path / "day", s.obs.pixels, s.obs.frames)
    rel = s.wm.radiance([0.3, 0.1]) / rendered - 1
    assert np.sqrt(np.mean(rel**2)) < 0.01
    assert np.all(np.abs(rel.mean(axis=(0, 2))) < 0.006), rel.mean(axis=(0, 2))   # per frame
    assert abs(rel.mean()) < 0.002
