"""The ``cie_sky`` emitter against the NumPy sky, chi-square sampling, irradiance and recompilation."""
from dataclasses import replace

import numpy as np
import pytest

from skyfit_mi.conventions import direction_from_angles
from skyfit_mi.physics.envmap import MeasuredIrradiance, envmap_sky
from skyfit_mi.physics.latlong import latlong_centres
from skyfit_mi.physics.gensky import from_gensky
from skyfit_mi.physics.perez import PerezOptions, perez_sky
from skyfit_mi.physics.sky import cie_sky
from skyfit_mi.physics.sun import SunDisc
from test_gensky import CLEAR


def clear_map(rows):
    """A CIE clear sky (sun at 30 degrees from the zenith, azimuth 200) tabulated at the cell
    centres of a lat-long map, black below the horizon."""
    sky = cie_sky("clear", 30, 200, sun=SunDisc(drawn=False), ground_albedo=0.0)
    theta, phi = latlong_centres(rows, 2 * rows)
    return sky.sky_radiance(direction_from_angles(theta[:, None], phi[None, :])) \
        * (theta < np.pi / 2)[:, None, None]


def patchy_map(rows, seed=3):
    """A map of independent cells (gamma-distributed, some 20x the median), sky and ground."""
    rng = np.random.default_rng(seed)
    return rng.gamma(0.7, 20.0, size=(rows, 2 * rows, 3))

#: A departure's weights (its field 0.1-1.9 over the sky).
DEPARTED = np.array([0.2, -0.1, 0.3, -0.2, 0.1])

SKIES = {
    "clear-high": lambda: cie_sky("clear", 20, 170),
    "clear-low": lambda: cie_sky("clear", 80, 250),
    "overcast": lambda: cie_sky("overcast", 50, 120),
    "intermediate-high": lambda: cie_sky("intermediate", 25, 200, phi=0.5),
    "intermediate-low": lambda: cie_sky("intermediate", 84, 95, phi=0.5),
    "gensky-clear": lambda: from_gensky(CLEAR),
    # a fit's departure from the model (physics/sky_departure.py) on a pattern, sharp and
    # blended at the horizon
    "clear-departed": lambda: replace(cie_sky("clear", 40, 150), departure=DEPARTED),
    "gensky-departed": lambda: replace(from_gensky(CLEAR), departure=-DEPARTED),
    # Perez all-weather skies from measured irradiance: clear (bin 8), intermediate, overcast
    "perez-clear": lambda: perez_sky(30, 150, 172, dhi=90, dni=850).to_sky(),
    "perez-intermediate": lambda: perez_sky(60, 230, 100, dhi=200, dni=300).to_sky(),
    "perez-overcast": lambda: perez_sky(45, 100, 300, ghi=150, options=PerezOptions(decomposition="erbs")).to_sky(),
    # HDR environment maps (physics/envmap.py), the sun given apart from the map
    "envmap-clear": lambda: envmap_sky(clear_map(32), 30, 200, measured=MeasuredIrradiance(direct_normal=700),
                                       ground_albedo=0.2),
    "envmap-patchy": lambda: envmap_sky(patchy_map(12), 50, 80, measured=MeasuredIrradiance(direct_normal=300)),
    "envmap-patchy-2": lambda: envmap_sky(patchy_map(12, seed=4), 60, 300),
    "envmap-large": lambda: envmap_sky(patchy_map(20, seed=5), 20, 10,
                                        measured=MeasuredIrradiance(direct_normal=500)),
}


def vec(mi, a):
    return mi.Vector3f(*[np.ascontiguousarray(a[:, k]) for k in range(3)])


def emitter(mi, sky, **over):
    from skyfit_mi.render.daylight import sky_dict
    return mi.load_dict({**sky_dict(sky), **over})


@pytest.mark.parametrize("name", SKIES)
def test_eval_equals_numpy_sky(mi, name):
    import drjit as dr
    sky = SKIES[name]()
    rng = np.random.default_rng(1)
    d = rng.normal(size=(5000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    # some directions inside the solar disc
    d[:50] = sky.sun_direction + 1e-3 * rng.normal(size=(50, 3)) * 2e-3
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    em = emitter(mi, sky)
    si = dr.zeros(mi.SurfaceInteraction3f, len(d))
    si.wi = vec(mi, -d)
    got = np.array(em.eval(si)).T
    np.testing.assert_allclose(got, sky.radiance(d), rtol=2e-4, atol=1e-4 * sky.radiance(d).max())


@pytest.mark.parametrize("name", SKIES)
def test_chi2_sampling_of_the_sky(mi, name):
    """Mitsuba's chi-square test of sample_direction against pdf_direction.

    The sky patterns keep their sun-oriented shapes (circumsolar peak included)
    but the disc is switched off here: a disc edge cuts histogram cells, whose
    pdf integral then converges too slowly for the test (PDF sum 0.990 at 8x8,
    1.0002 at 32x32 points per cell for a 0.01 sr disc).  The disc's sampling is
    tested exactly below (test_sun_cone_is_uniform, test_real_sun_sampling).
    """
    from mitsuba.chi2 import ChiSquareTest, EmitterAdapter, SphericalDomain
    from skyfit_mi.render.daylight import sky_dict
    d = sky_dict(SKIES[name]())
    d["sun_radiance"] = mi.ScalarVector3f(0.0, 0.0, 0.0)
    sample, pdf = EmitterAdapter("cie_sky", d)
    chi2 = ChiSquareTest(domain=SphericalDomain(), sample_func=sample, pdf_func=pdf,
                         sample_dim=2, res=101, ires=8, seed=5)
    assert chi2.run(), chi2.messages


@pytest.mark.parametrize("name", ["clear-high", "clear-low"])
def test_sun_cone_is_uniform(mi, name):
    """Samples in the disc are uniform in (1 - cos theta') and azimuth around the sun."""
    import drjit as dr
    from scipy.stats import kstest
    sky = SKIES[name]()
    em = emitter(mi, sky)
    n = 100_000
    rng = np.random.default_rng(4)
    p_sun = float(np.array(em.p_sun)[0])
    ds, _ = em.sample_direction(dr.zeros(mi.Interaction3f, n),
                                mi.Point2f(rng.random(n) * p_sun, rng.random(n)))
    d = np.array(ds.d, dtype=float).T
    s = sky.sun_direction
    c = 1 - d @ s
    frac = c / (sky.sun_solid_angle / (2 * np.pi))
    assert kstest(frac, "uniform").pvalue > 0.01
    t = np.cross(s, [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t)
    b = np.cross(s, t)
    az = (np.arctan2(d @ b, d @ t) / (2 * np.pi)) % 1.0
    assert kstest(az, "uniform").pvalue > 0.01
    # the disc's density p_sun / Omega dominates the sky table's there
    np.testing.assert_allclose(np.array(ds.pdf), p_sun / sky.sun_solid_angle, rtol=0.01)


@pytest.mark.parametrize("name", ["clear-high", "clear-low", "intermediate-high"])
def test_real_sun_sampling(mi, name):
    """With the real 6e-5 sr disc: share of sun samples, pdf and weight = radiance/pdf."""
    import drjit as dr
    sky = SKIES[name]()
    em = emitter(mi, sky)
    n = 200_000
    rng = np.random.default_rng(2)
    it = dr.zeros(mi.Interaction3f, n)
    ds, w = em.sample_direction(it, mi.Point2f(rng.random(n), rng.random(n)))
    d = np.array(ds.d, dtype=float).T
    in_sun = sky.sun_mask(d)
    chord2 = np.sum((d - sky.sun_direction) ** 2, axis=1)
    clear_of_edge = np.abs(chord2 / sky.sun_chord2 - 1) > 1e-3   # float32 vs float64 at the rim
    p_sun = float(np.array(em.p_sun)[0])
    assert in_sun.mean() == pytest.approx(p_sun, abs=4 * np.sqrt(p_sun * (1 - p_sun) / n) + 1e-4)
    np.testing.assert_allclose(np.array(w).T[clear_of_edge],
                               (sky.radiance(d) / np.array(ds.pdf)[:, None])[clear_of_edge], rtol=1e-3)
    # Monte Carlo irradiance on a horizontal plane from the sampler equals the quadrature
    e = (np.array(w).T * np.maximum(d[:, 2:3], 0)).mean(axis=0)
    np.testing.assert_allclose(e, sky.horizontal_irradiance(), rtol=0.01)


@pytest.mark.parametrize("integrator", ["direct", "sun_sky_path"])
def test_sky_changes_without_recompilation(mi, integrator):
    """A new frame's sky reuses the kernels: the sky's numbers live in memory, never in a
    kernel as literals (with Mitsuba's ``direct`` and with the frames' ``sun_sky_path``, which
    reads the emitter's parameters itself).  Measured by kernel hashes, not by the on-disk cache's hits, so
    the test means the same with an empty kernel cache (a fresh machine) or a warm one.

    Dr.Jit packs the emitter's fields into the virtual call's data buffer in an order that
    varies between frames, and the field alignment it deduces from the offsets is part of
    the render kernel: that kernel has two variants (seen: always both within the first
    three frames).  A sky baked in as constants would give one per distinct sky (seven here).
    """
    import drjit as dr
    from skyfit_mi.render.daylight import sky_dict, update_sky
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": integrator},
        "sky": sky_dict(SKIES["clear-high"]()),
        "disc": {"type": "disk", "bsdf": {"type": "ward", "rho_d": 0.6, "rho_s": 0.2,
                                          "sigma_alpha": 0.1}},
        "sensor": {"type": "orthographic",
                   "to_world": mi.ScalarTransform4f().look_at([0, 0, 2], [0, 0, 0], [0, 1, 0])
                   @ mi.ScalarTransform4f().scale([0.5, 0.5, 1]),
                   "film": {"type": "hdrfilm", "width": 8, "height": 8},
                   "sampler": {"type": "independent", "sample_count": 4}}})
    params = mi.traverse(scene)
    day = ["clear-low", "overcast", "clear-high", "gensky-clear", "intermediate-low", "overcast",
           "perez-clear", "intermediate-high", "perez-overcast", "clear-low", "gensky-clear",
           "clear-high", "envmap-patchy", "envmap-patchy-2", "envmap-large", "envmap-clear",
           "clear-low"]
    means, kernels = [], []
    dr.kernel_history()                                   # drop earlier tests' entries
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        for i, name in enumerate(day):
            update_sky(params, SKIES[name](), "sky.")
            img = mi.render(scene, params, seed=i)
            means.append(float(np.mean(np.array(img))))
            kernels.append([(k["hash"], k["size"]) for k in dr.kernel_history()
                            if k["type"] == dr.KernelType.JIT])
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    pixels = 8 * 8 * 4                                    # the render kernel: one lane per sample
    render = {h for frame in kernels for h, size in frame if size == pixels}
    assert render
    assert len(render) <= 2, f"{len(render)} render kernels for {len(set(day))} skies"
    # every other kernel (sampling-table uploads and the like) is one of a fixed few; a sky
    # baked in as literals adds new ones with every new sky
    small = {h for frame in kernels for h, size in frame if size != pixels}
    assert len(small) <= 12, f"{len(small)} distinct small kernels in a day of {len(day)} frames"
    assert means[1] != means[2] and means[1] == pytest.approx(means[5], rel=0.05)


@pytest.mark.parametrize("name", ["clear-high", "intermediate-low", "overcast", "gensky-clear",
                                  "perez-clear", "perez-overcast", "envmap-clear",
                                  "envmap-patchy"])
def test_lambertian_disc_radiance_equals_irradiance_over_pi(mi, name):
    """A white Lambertian horizontal disc: pixel radiance = (E_sky + E_sun)/pi.

    64x64 orthographic pixels on the disc, 256 spp, seed 0 (1M samples); MIS
    direct lighting.  Tolerance 1%; the observed error is reported on failure.
    """
    from skyfit_mi.render.daylight import sky_dict
    sky = SKIES[name]()
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sky": sky_dict(sky),
        "disc": {"type": "disk", "to_world": mi.ScalarTransform4f().scale(10),
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 1.0}}},
        "sensor": {"type": "orthographic",
                   "to_world": mi.ScalarTransform4f().look_at([0, 0, 5], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 64, "height": 64,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 256}}})
    img = np.array(mi.render(scene, seed=0)).reshape(-1, 3)
    expected = sky.horizontal_irradiance() / np.pi
    np.testing.assert_allclose(img.mean(axis=0), expected, rtol=0.01)


def test_the_sampling_tables_directions_follow_the_variant(mi, monkeypatch):
    # the table's directions are made once per variant: an emitter of another variant (a GPU
    # after a CPU render in one process) must not get the first variant's array
    from skyfit_mi.render.plugins import cie_sky

    a = cie_sky._table_directions_jit()
    assert cie_sky._table_directions_jit() is a
    monkeypatch.setattr(cie_sky.mi, "variant", lambda: "cuda_ad_rgb")
    try:
        assert cie_sky._table_directions_jit() is not a          # made anew for that variant
    finally:
        cie_sky._table_directions_of.cache_clear()   # the stand-in is not a CUDA array
