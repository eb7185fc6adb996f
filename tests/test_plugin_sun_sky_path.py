"""The ``sun_sky_path`` integrator: unbiased against Mitsuba's ``path``, and less noisy."""
import numpy as np
import pytest

from skyfit_mi.physics.sky import cie_sky


def highlight_scene(mi, integrator, sky):
    """A Ward plastic disc (radius 2) holding a mirror sphere and a Lambertian cube, seen from
    the sun's mirror direction: a sun highlight on the disc, the sun in the sphere (a Dirac
    path), shadows and light between the objects.  32x32 pixels."""
    from skyfit_mi.render.daylight import sky_dict

    s = np.asarray(sky.sun_direction, dtype=float)
    eye = 5.0 * np.array([-s[0], -s[1], s[2]])
    return mi.load_dict({
        "type": "scene", "integrator": integrator, "sky": sky_dict(sky),
        "disc": {"type": "disk", "to_world": mi.ScalarTransform4f().scale(2.0),
                 "bsdf": {"type": "ward", "model": "two", "rho_s": 0.3, "sigma_alpha": 0.08}},
        "ball": {"type": "sphere", "center": [0.6, 0.3, 0.4], "radius": 0.4,
                 "bsdf": {"type": "ward", "model": "two", "rho_s": 1.0, "sigma_alpha": 0.0}},
        "cube": {"type": "cube", "to_world": mi.ScalarTransform4f().translate([-0.6, -0.4, 0.3])
                 @ mi.ScalarTransform4f().scale(0.3),
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.7}}},
        "sensor": {"type": "perspective", "fov": 40.0,
                   "to_world": mi.ScalarTransform4f().look_at(eye.tolist(), [0, 0, 0], [0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": 32, "height": 32,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 4}}})


def block_means(mi, scene, spp, seeds):
    """Each render's mean over 8x8-pixel blocks (16 blocks x 3 channels), one row per seed."""
    rows = []
    for seed in seeds:
        img = np.array(mi.render(scene, seed=seed, spp=spp), dtype=np.float64)
        rows.append(img.reshape(4, 8, 4, 8, 3).mean(axis=(1, 3)).ravel())
    return np.array(rows)


def chi2_of_difference(a, b):
    """Sum over blocks and channels of (difference of the mean rows)^2 / its squared standard
    error (from each set's scatter over seeds); blocks without scatter (sky only) left out."""
    se2 = a.var(axis=0, ddof=1) / len(a) + b.var(axis=0, ddof=1) / len(b)
    on = se2 > 0
    return float(np.sum((a.mean(axis=0) - b.mean(axis=0))[on] ** 2 / se2[on])), int(on.sum())


@pytest.mark.parametrize("max_depth", [2, 4])
def test_unbiased_against_path_and_less_noisy(mi, max_depth):
    """Direct light only (max_depth 2) and with interreflections (4): block means of the two
    integrators agree within their Monte Carlo error, 12 seeds of 32 spp each.  With standard
    errors estimated from 12 seeds, each of the (at most 48) terms has mean ~1.2 and the sum
    a standard deviation of ~12: the bound 110 is about 4 standard deviations above its mean.
    At equal spp the new integrator's scatter is at most half of ``path``'s.  Fixed seeds."""
    sky = cie_sky("clear", 40.0, 200.0)
    ours = block_means(mi, highlight_scene(
        mi, {"type": "sun_sky_path", "max_depth": max_depth}, sky), 32, range(12))
    theirs = block_means(mi, highlight_scene(mi, {"type": "path", "max_depth": max_depth}, sky),
                         32, range(100, 112))
    chi2, n = chi2_of_difference(ours, theirs)
    assert n >= 30 and chi2 < 110, (chi2, n)
    assert np.sum(ours.var(axis=0)) < 0.5 * np.sum(theirs.var(axis=0))


def test_depth_one_shows_only_what_the_camera_sees(mi):
    """max_depth 1, as in ``path``: the sky and black surfaces, the same image for the same
    seed (the camera's rays use the same samples)."""
    sky = cie_sky("clear", 40.0, 200.0)
    ours = block_means(mi, highlight_scene(mi, {"type": "sun_sky_path", "max_depth": 1}, sky),
                       16, [3])
    theirs = block_means(mi, highlight_scene(mi, {"type": "path", "max_depth": 1}, sky), 16, [3])
    np.testing.assert_allclose(ours, theirs, rtol=1e-5)


def test_refuses_a_depth_below_one(mi):
    with pytest.raises(Exception, match="max_depth = 0; give 1 or more"):
        mi.load_dict({"type": "sun_sky_path", "max_depth": 0})
