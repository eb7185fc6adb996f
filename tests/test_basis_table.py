"""The fit's tabulated model (render/basis_table.py) against the Dr.Jit model it tabulates, and
the light traced in blocks of bounded size."""

import numpy as np
import pytest

from skyfit_mi.fitting.chi2 import parse_region

REGION = parse_region("rect:4,4,7,7")          # 16 pixels, all on the disc

#: Relative agreement of the same table values computed in another order: float32 rounding
#: accumulated over a sum (the table is float32).
FLOAT32_RTOL = 1e-5


@pytest.fixture(scope="module")
def traced(days):
    """A session's raw light cache, the Dr.Jit model on it and its table."""
    from skyfit_mi.fitting.fit import FitCache, FitSession
    from skyfit_mi.render.basis_table import tabulate
    from skyfit_mi.render.fit_model import WardModel

    s = FitSession(days["clean"], "disc", REGION, model="colour",
                   cache=FitCache(positions=8, directions=128, seed=2), light=None)
    cache = s.light_cache()
    wm = WardModel(cache, "colour")
    return s, cache, wm, tabulate(cache, wm)


# every piece, its ends, the mirror's interpolation and the mirror itself
SIGMAS = [0.0, 1e-4, 0.001, 0.002, 0.0031, 0.011, 0.035, 0.042, 0.05, 0.07, 0.13, 0.31, 0.5]


@pytest.mark.parametrize("sigma", SIGMAS)
def test_table_equals_the_dr_jit_model(traced, sigma):
    from skyfit_mi.render.basis_table import TableModel

    _, _, wm, table = traced
    theta = np.array([0.7, 0.4, 0.2, 0.3, sigma])
    a, b = wm.radiance(theta), TableModel(table, "colour").radiance(theta)
    # float32 evaluation on both sides; the interpolation adds < 1e-6 (DEGREES)
    assert np.max(np.abs(a - b)) <= 2e-6 * np.max(np.abs(a)), sigma


@pytest.mark.parametrize("sigma", [0.001, 0.004, 0.02, 0.045, 0.2])
def test_table_jacobian_matches_its_finite_differences(traced, sigma):
    from skyfit_mi.render.basis_table import TableModel

    from dataclasses import replace

    t = traced[3]
    # in double precision, so that small steps see the derivative, not float32's rounding
    m = TableModel(replace(t, D=t.D.astype(float), G0=t.G0.astype(float),
                           G1=t.G1.astype(float), coef=[c.map(lambda a: a.astype(float)) for c in t.coef]),
                   "colour")
    theta = np.array([0.6, 0.5, 0.3, 0.2, sigma])
    L, J = m.jacobian(theta)
    assert np.allclose(L, m.radiance(theta))
    for i, h in enumerate([1e-4] * 4 + [1e-4 * sigma]):
        d = np.zeros(5)
        d[i] = h
        fd = (m.radiance(theta + d) - m.radiance(theta - d)) / (2 * h)
        assert np.max(np.abs(J[..., i] - fd)) <= 1e-4 * np.max(np.abs(fd)) + 1e-9, i


def test_halves_are_the_caches_halves_and_the_spread_its_positions(traced):
    """The table's halves are the LightCache's halves; its variance is the Dr.Jit model's
    (the spread of the positions' estimates): exact at the roughness values it keeps,
    interpolated between them (geometrically: the variance climbs steeply where a lobe starts
    to take in the sun)."""
    from skyfit_mi.render.basis_table import TableModel, variance_sigmas
    from skyfit_mi.render.fit_model import WardModel

    _, cache, wm, table = traced
    m = TableModel(table, "colour")
    theta = np.array([0.5, 0.5, 0.5, 0.2, 0.08])
    for j, half in zip((1, 2), cache.halves()):
        a = WardModel(half, "colour").radiance(theta)
        b = m.half(j).radiance(theta)
        assert np.max(np.abs(a - b)) <= 2e-6 * np.max(np.abs(a))
    for sigma in variance_sigmas()[::3]:
        theta[-1] = sigma
        (a, va), (b, vb) = wm.radiance_and_variance(theta), m.radiance_and_variance(theta)
        assert np.allclose(vb, va, rtol=1e-3, atol=1e-6 * va.max()), sigma
    ratios = []
    for sigma in np.geomspace(0.0025, 0.5, 30):
        theta[-1] = sigma
        ratios.append(m.radiance_and_variance(theta)[1].sum()
                      / wm.radiance_and_variance(theta)[1].sum())
    assert 0.7 < min(ratios) and max(ratios) < 1.4, np.round(ratios, 2)


def test_blocks_cover_every_point_and_frame_once_within_the_budget():
    from skyfit_mi.render.basis_table import chunks

    for P, T, per, budget in ((16, 13, 256, 10**9), (400, 96, 4096, 1 << 23), (5, 7, 100, 250),
                              (3, 2, 1000, 10)):
        seen = np.zeros((P, T), int)
        for rows, frames in chunks(P, T, per, budget):
            seen[rows, frames] += 1
            n = (rows.stop - rows.start) * (frames.stop - frames.start)
            assert n == 1 or n * per <= budget
        assert (seen == 1).all()
    assert len(chunks(16, 13, 256, 10**9)) == 1


def test_light_traced_in_blocks_agrees_with_one_block(traced):
    """A small budget splits the trace into blocks of points and frames, each with its own
    seed: the table has the same layout, and its radiance agrees with the one-block table's
    within their Monte Carlo errors."""
    from skyfit_mi.render.basis_table import TableModel, trace_basis
    from skyfit_mi.render.light_cache import CacheOptions

    s, _, _, table = traced
    opts = s._cache_options()
    budget = 5 * 13 * opts["positions"] * opts["directions"]        # 5 pixels of all frames
    (blocks,), _, n = trace_basis(s.scene, s.params, [s.skies], s.obs.pixels, "disc",
                                  CacheOptions(**opts), budget, "colour")
    assert n == 4 and blocks.shape == table.shape and blocks.hit.all()
    theta = np.array([0.5, 0.6, 0.7, 0.25, 0.1])
    (a, va), (b, vb) = (TableModel(t, "colour").radiance_and_variance(theta)
                        for t in (table, blocks))
    # region means per frame and channel
    z = (a.mean(axis=0) - b.mean(axis=0)) / np.sqrt((va.sum(axis=0) + vb.sum(axis=0))
                                                    / len(a) ** 2)
    assert np.all(np.abs(z) < 5) and np.sqrt(np.mean(z**2)) < 2.5, z


def test_regions_take_views_of_a_table_traced_in_blocks(traced):
    """Regions traced together take their rows of one table without copying it, also where a
    region's rows cross the blocks of the trace (each keeping its own series)."""
    from skyfit_mi.render.basis_table import BasisTable, TableModel

    _, _, _, table = traced
    P, T = table.shape
    # the same table as four blocks: 2 x 2 of pixels and frames
    blocks = BasisTable.empty(P, T, table.sun_cos.shape[2], table.normalisation)
    for rows in (slice(0, 5), slice(5, P)):
        for frames in (slice(0, 4), slice(4, T)):
            blocks.place(table.subset(rows, frames), rows, frames)
    assert [len(c.blocks) for c in blocks.coef] == [4] * len(table.coef)
    theta = np.array([0.5, 0.6, 0.7, 0.25, 0.03])
    whole = TableModel(table, "colour").radiance_and_variance(theta)
    for t in (table, blocks):
        view = t.subset(slice(3, 9), slice(2, 7))
        assert view.shape == (6, 5)
        assert np.shares_memory(view.D, t.D) and all(
            any(np.shares_memory(b, c) for _, _, c in t.coef[i].blocks)
            for i, series in enumerate(view.coef) for _, _, b in series.blocks)
        # the same values to float32 rounding: the series' float32 matrix products block a
        # view's rows otherwise than the whole array's (on some machines)
        for got, want in zip(TableModel(view, "colour").radiance_and_variance(theta), whole):
            np.testing.assert_allclose(got, want[3:9, 2:7], rtol=FLOAT32_RTOL)
        np.testing.assert_array_equal(view.D, t.D[:, 3:9, 2:7])     # the rows themselves
        L, J = TableModel(view, "colour").jacobian(theta)
        J_whole = TableModel(t, "colour").jacobian(theta)[1][3:9, 2:7]
        np.testing.assert_allclose(J, J_whole, rtol=FLOAT32_RTOL,
                                   atol=FLOAT32_RTOL * np.abs(J_whole).max())


def test_a_fit_beyond_the_machines_memory_is_refused_up_front_with_its_estimate(days,
                                                                                monkeypatch):
    from skyfit_mi.errors import SkyfitError
    from skyfit_mi.fitting.fit import FitCache, FitSession
    from skyfit_mi.render import basis_table

    monkeypatch.setattr("skyfit_mi.fitting.fit.available_memory", lambda: 100 << 20)
    need = basis_table.memory_estimate(16, 13, 8, 128)
    assert need > 100 << 20
    with pytest.raises(SkyfitError, match=r"needs up to 0\.\d GB, but this machine has 0\.1 GB "
                                          r"available; fit fewer pixels \(--max-pixels\)") as e:
        FitSession(days["clean"], "disc", REGION, cache=FitCache(positions=8, directions=128))
    assert "\n" not in str(e.value)


def test_many_parameter_sets_at_once_equal_each_set(traced):
    """A prediction's draws through the table's basis, a few roughness values at a time, give
    each set's radiance, and a linear reduction (a region's mean) applied to the basis the
    same means."""
    from skyfit_mi.render.basis_table import TableModel

    m = TableModel(traced[3], "colour")
    rng = np.random.default_rng(3)
    sets = np.column_stack([rng.uniform(0.1, 0.9, (40, 3)), rng.uniform(0.0, 0.3, 40),
                            np.exp(rng.uniform(np.log(1e-4), np.log(0.4), 40))])
    sets[5:10, -1] = sets[0, -1]                               # repeated roughness values
    direct = np.stack([m.radiance(t) for t in sets])
    # to float32 rounding (the table's): batches and single sets take float32 matrix
    # products of other shapes
    np.testing.assert_allclose(m.radiances(sets), direct, rtol=FLOAT32_RTOL, atol=0)
    np.testing.assert_allclose(m.radiances(sets, lambda L: L.mean(axis=0)),
                               direct.mean(axis=1), rtol=FLOAT32_RTOL)


def test_a_mix_of_lights_traced_with_shared_samples_keeps_their_covariances(days):
    """The rest of a sky and its two shape variants traced with one trace's samples
    (tabulate_group): their mix (basis_table.mixed, with their Covariances, every pair) is the
    table of the mixed light's own cache (the model is linear in each light's arrays), its
    positions' spread too; adding their variances as if independent would not be."""
    from dataclasses import replace

    from skyfit_mi.fitting.fit import FitSession
    from skyfit_mi.fitting.light import LightPlan
    from skyfit_mi.render.basis_table import mixed, tabulate, tabulate_group
    from skyfit_mi.render.fit_model import WardModel
    from skyfit_mi.render.light_cache import OWN_ARRAYS, build_light_cache

    s = FitSession(days["clean"], "disc", REGION, model="colour", light=None)
    _, rest, *variants = (light[3:6] for light in
                              s._sky_parts(LightPlan("fit", shape=True)).values())
    caches = build_light_cache(s.scene, s.params, rest, s.obs.pixels[:8], "disc",
                               positions=8, directions=64, seed=5, others=variants)
    tables, cov = tabulate_group(caches, "colour")
    assert cov.pairs == [(0, 1), (0, 2), (1, 2)]
    w = [0.7, np.array([0.2, 0.5, 0.9]), -0.3]                  # one weight per frame too

    def per_frame(x, ndim):
        return np.reshape(x, (1, -1) + (1,) * (ndim - 2)) if np.ndim(x) else x
    mix = replace(caches[0], **{k: sum(per_frame(wj, getattr(c, k).ndim) * getattr(c, k)
                                       for wj, c in zip(w, caches)) for k in OWN_ARRAYS})
    want = tabulate(mix, WardModel(mix, "colour"))
    got = mixed(tables[0], tables[1:], w[1:], w[0], cov)
    for k in ("D", "G0", "G1"):
        x, y = getattr(got, k), getattr(want, k)
        assert np.allclose(x, y, rtol=FLOAT32_RTOL, atol=FLOAT32_RTOL * np.abs(y).max()), k
    for sigma in (0.004, 0.04, 0.3):
        y = want.lobe(sigma)
        assert np.allclose(got.lobe(sigma), y, rtol=FLOAT32_RTOL,
                           atol=FLOAT32_RTOL * np.abs(y).max())
    # the spread is ~1e-5 of each position's estimate, whose float32 rounding (the mix's own
    # trace rounds its sums in another order) moves it by ~0.3% (measured 0.2% of the largest
    # at most with two lights); as if independent, 13-50% off (median; measured)
    apart = mixed(tables[0], tables[1:], w[1:], w[0])
    for k in ("VDD", "VDG", "VGG"):
        x, y, z = getattr(got, k), getattr(want, k), getattr(apart, k)
        assert np.allclose(x, y, rtol=0.01, atol=0.01 * np.abs(y).max()), k
        assert np.median(np.abs(z - y) / np.maximum(np.abs(y), 1e-30)) > 0.1, k
    # mixed where first used: one roughness's variances, and a subset, as the whole mix's
    part, whole = mixed(tables[0], tables[1:], w[1:], w[0], cov), np.asarray(got.VGG)
    np.testing.assert_allclose(part.VGG[3], whole[3])
    np.testing.assert_allclose(np.asarray(part.subset(slice(2, 5), slice(1, 3)).VDG),
                               np.asarray(got.VDG)[:, 2:5, 1:3])
    np.testing.assert_allclose(part.subset(slice(2, 5)).lobe(0.04), got.lobe(0.04)[:, 2:5])
    # a subset of pixels and frames mixes its own blocks' halves, with its frames' weights
    np.testing.assert_allclose(part.subset(slice(2, 5), slice(1, 3)).lobe(0.04, part=1),
                               got.lobe(0.04, part=1)[:, 2:5, 1:3])
    tint = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(part.tinted(tint).lobe(0.3), got.lobe(0.3) * tint, rtol=1e-6)


def test_a_tinted_table_is_the_light_times_its_factor_per_channel(traced):
    """A table tinted by a factor per channel (the light calibrated again on a reference,
    fitting.fit.reference_factor) models that light: every radiance, at every roughness, is the
    factor times the table's, and the Monte Carlo variance its square."""
    from skyfit_mi.render.basis_table import TableModel

    table, f = traced[3], np.array([1.07, 0.98, 0.91])
    a, b = TableModel(table, "colour"), TableModel(table.tinted(f), "colour")
    for sigma in (0.0, 0.003, 0.05, 0.3):
        theta = np.array([0.7, 0.4, 0.2, 0.3, sigma])
        np.testing.assert_allclose(b.radiance(theta), a.radiance(theta) * f, rtol=1e-5)
    rho_d, spec = np.array([0.5, 0.3, 0.2]), np.array([0.04, 0.04, 0.04])
    np.testing.assert_allclose(table.tinted(f).variance(rho_d, spec, 0.05),
                               table.variance(rho_d, spec, 0.05) * f ** 2, rtol=1e-5)
