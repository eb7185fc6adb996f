"""HDR environment maps (physics/envmap.py) and lab lights (physics/sky.py directional_sky):
the lat-long lookup (physics/latlong.py) against hand-derived values, irradiance, rotation,
fisheye resampling, the sun given apart from the map; and the emitter and light cache against
the analytic sky."""
import numpy as np
import pytest

from skyfit_mi.conventions import direction_from_angles
from skyfit_mi.errors import SkyfitError
from skyfit_mi.physics.envmap import MeasuredIrradiance, envmap_sky, fisheye_lookup, latlong_table
from skyfit_mi.physics.latlong import latlong_centres, latlong_lookup
from skyfit_mi.physics.sky import Sky, cie_sky, directional_sky
from skyfit_mi.physics.sun import SunDisc

H, W = 4, 8                                      # rows of 45 degrees, columns of 45 degrees


def row_theta(i):
    return (i + 0.5) * np.pi / H


def col_phi(j):
    return (j + 0.5) * 2 * np.pi / W


def test_a_map_constant_in_azimuth_interpolates_between_rows_and_holds_at_the_poles():
    v = np.array([1.0, 2.0, 4.0, 8.0])
    t = np.repeat(v[:, None, None], W, axis=1).repeat(3, axis=2)
    phi = np.linspace(-7, 7, 29)                                  # any azimuth, wrapped
    for i in range(H):
        assert np.allclose(latlong_lookup(t, row_theta(i), phi), v[i])
    assert np.allclose(latlong_lookup(t, 0.5 * (row_theta(1) + row_theta(2)), phi), 3.0)
    assert np.allclose(latlong_lookup(t, row_theta(2) + 0.25 * np.pi / H, phi), 5.0)
    assert np.allclose(latlong_lookup(t, [0.0, 0.1], phi[:, None]), 1.0)     # zenith: row 0
    assert np.allclose(latlong_lookup(t, np.pi, phi), 8.0)                   # nadir: last row


def test_one_bright_cell_spreads_bilinearly_to_its_neighbours_only():
    t = np.zeros((H, W, 3))
    t[1, 2] = [1.0, 2.0, 3.0]
    assert np.allclose(latlong_lookup(t, row_theta(1), col_phi(2)), [1, 2, 3])
    mid_phi = 0.5 * (col_phi(2) + col_phi(3))
    mid_theta = 0.5 * (row_theta(1) + row_theta(2))
    assert np.allclose(latlong_lookup(t, row_theta(1), mid_phi), [0.5, 1, 1.5])
    assert np.allclose(latlong_lookup(t, mid_theta, col_phi(2)), [0.5, 1, 1.5])
    assert np.allclose(latlong_lookup(t, mid_theta, mid_phi), [0.25, 0.5, 0.75])
    assert np.allclose(latlong_lookup(t, row_theta(1), col_phi(4)), 0.0)
    assert np.allclose(latlong_lookup(t, row_theta(3), col_phi(2)), 0.0)


def test_azimuth_wraps_from_the_last_column_to_the_first():
    t = np.zeros((H, W, 3))
    t[2, 0] = 1.0                                  # the column starting at north
    th = row_theta(2)
    # north (phi = 0) lies midway between the last column's centre and the first's
    assert np.allclose(latlong_lookup(t, th, [0.0, 2 * np.pi, -2 * np.pi]), 0.5)
    assert np.allclose(latlong_lookup(t, th, col_phi(W - 1)), 0.0)
    assert np.allclose(latlong_lookup(t, th, -0.25 * 2 * np.pi / W), 0.25)
    assert np.allclose(latlong_lookup(t, th, 2 * np.pi - 0.25 * 2 * np.pi / W), 0.25)


def test_table_layout_runs_north_east_south_west_from_the_zenith():
    theta, phi = latlong_centres(H, W)
    assert theta[0] < theta[-1] and np.isclose(theta[0], np.pi / 8)
    # a map bright only in its east-facing columns lights directions toward +X
    t = np.zeros((H, W, 3))
    t[:, 2:4] = 1.0                                # azimuths 90..180: east to south
    d = direction_from_angles(np.pi / 2 - 0.01, np.radians(135))       # south-east, horizon
    assert np.allclose(Sky([0, 0, 1], envmap=t).sky_radiance(d), 1.0)
    assert np.allclose(Sky([0, 0, 1], envmap=t).sky_radiance(-d), 0.0)


def test_a_uniform_map_gives_horizontal_irradiance_pi_L():
    L = np.array([1.0, 2.0, 0.5])
    sky = Sky([0, 0, 1], envmap=np.broadcast_to(L, (16, 32, 3)))
    np.testing.assert_allclose(sky.sky_horizontal_irradiance(), np.pi * L, rtol=1e-12)


def test_rotation_moves_a_feature_to_its_compass_azimuth():
    t = np.zeros((32, 64, 3), np.float32)
    t[10, 8] = 1.0                                 # map azimuth (8.5 / 64) 360 = 47.8 deg
    out, invalid = latlong_table(t, "latlong", north_rotation_deg=90.0)
    assert invalid == 0 and out.shape == t.shape
    i, j = np.unravel_index(np.argmax(out[..., 0]), out.shape[:2])
    assert i == 10 and j == 8 + 16                 # + 90 degrees = 16 columns of 5.625
    np.testing.assert_allclose(out.sum(), t.sum(), rtol=1e-6)           # nothing lost
    # and a fraction of a column splits the feature between two
    half, _ = latlong_table(t, "latlong", north_rotation_deg=0.5 * 360 / 64)
    np.testing.assert_allclose(half[10, 8:10, 0], [0.5, 0.5], rtol=1e-6)


def _fisheye_of(sky, n):
    """An equidistant fisheye (n x n) of ``sky``'s radiance (the module's convention, written
    out independently: zenith at the centre, north up, east to the left)."""
    c = (np.arange(n) + 0.5) - n / 2.0
    x, y = np.meshgrid(c, c)                       # x to the right, y down
    r = np.hypot(x, y) / (n / 2.0)
    theta = r * np.pi / 2
    d = np.stack([-x, -y, np.zeros_like(x)], -1)   # left = east (+X), up = north (+Y)
    d = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12) * np.sin(theta)[..., None]
    d[..., 2] = np.cos(theta)
    return np.where((r <= 1)[..., None], sky.sky_radiance(d), 0.0)


def test_fisheye_to_latlong_matches_the_analytic_sky():
    sky = cie_sky("clear", 40.0, 120.0, ground_albedo=0.0)
    img = _fisheye_of(sky, 256)
    table, invalid = latlong_table(img, "fisheye", rows=64)
    assert invalid == 0 and table.shape == (64, 128, 3)
    assert not table[32:].any()                    # the lower half is left to the ground term
    rng = np.random.default_rng(0)
    d = rng.normal(size=(4000, 3))
    d[:, 2] = np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    far = (d[:, 2] > np.sin(np.radians(5))) & (d @ sky.sun_direction < np.cos(np.radians(10)))
    got = Sky([0, 0, 1], envmap=table).sky_radiance(d[far])
    rel = got / sky.sky_radiance(d[far]) - 1
    assert np.sqrt(np.mean(rel ** 2)) < 0.01 and np.abs(rel).max() < 0.05
    # the irradiance, circumsolar peak and horizon included
    np.testing.assert_allclose(Sky([0, 0, 1], envmap=table).sky_horizontal_irradiance(),
                               sky.sky_horizontal_irradiance(), rtol=0.01)


def test_fisheye_lookup_puts_east_left_of_north():
    img = np.zeros((9, 9, 3))
    img[4, 0] = 1.0                                 # the left edge, at the horizon
    assert np.allclose(fisheye_lookup(img, np.pi / 2 * 4 / 4.5, np.pi / 2), 1.0)
    assert np.allclose(fisheye_lookup(img, np.pi / 2 * 4 / 4.5, 3 * np.pi / 2), 0.0)
    assert np.allclose(fisheye_lookup(img, 2.0, np.pi / 2), 0.0)           # below the horizon


def test_invalid_pixels_are_masked_and_counted_and_an_empty_map_refused():
    t = np.ones((8, 16, 3), np.float32)
    t[0, 0] = np.nan
    t[1, 1, 2] = -1.0
    t[2, 2, 0] = np.inf
    out, invalid = latlong_table(t, "latlong")
    assert invalid == 5 and np.all(np.isfinite(out)) and out.min() == 0.0
    with pytest.raises(SkyfitError, match="every value of the environment map"):
        latlong_table(np.full((8, 16, 3), np.nan), "latlong")
    with pytest.raises(SkyfitError, match="unknown envmap projection 'cube'"):
        latlong_table(t, "cube")


def test_sun_given_apart_from_a_clipped_map():
    """A map with a clipped (too dim) sun: the mask fills the sun's cells from the ring around
    them, and the disc carries the measured direct normal irradiance."""
    sky0 = cie_sky("clear", 30.0, 200.0, sun=SunDisc(drawn=False), ground_albedo=0.0)
    theta, phi = latlong_centres(64, 128)
    table = sky0.sky_radiance(direction_from_angles(theta[:, None], phi[None, :])).astype(np.float32)
    near = np.degrees(np.arccos(np.clip(direction_from_angles(theta[:, None], phi[None, :])
                                        @ sky0.sun_direction, -1, 1))) < 3
    table[near] = 50.0                              # the clipped sun and its flare
    sky = envmap_sky(table, 30.0, 200.0, measured=MeasuredIrradiance(direct_normal=800.0),
                     sun_mask_deg=3.0)
    assert sky.info["sun_masked_cells"] == near.sum()
    assert sky.envmap[near].max() < 1.5 * sky0.sky_radiance(sky0.sun_direction).max()
    np.testing.assert_allclose(sky.sun_horizontal_irradiance() @ [0.2126, 0.7152, 0.0722],
                               800.0 * np.cos(np.radians(30)), rtol=1e-9)
    # the ground is black by default (the map's own lower half) and Lambertian when asked
    assert not sky.ground.any()
    lit = envmap_sky(table, 30.0, 200.0, measured=MeasuredIrradiance(direct_normal=800.0),
                     ground_albedo=0.2)
    np.testing.assert_allclose(lit.ground, 0.2 * lit.horizontal_irradiance() / np.pi, rtol=1e-3)
    night = envmap_sky(table, 95.0, 200.0, measured=MeasuredIrradiance(direct_normal=800.0))
    assert not night.sun_radiance.any() and "below the horizon" in night.info["note"]


# ---- directional lab lights ------------------------------------------------------------

def test_directional_light_gives_E_cos_theta_on_a_horizontal_plane():
    theta = np.radians(35.0)
    d = direction_from_angles(theta, np.radians(250.0)) * 3.0          # any length
    sky = directional_sky(d, [100.0, 80.0, 60.0])
    np.testing.assert_allclose(sky.horizontal_irradiance(), np.array([100, 80, 60]) * np.cos(theta),
                               rtol=1e-12)
    assert not sky.ground.any() and not sky.sky_horizontal_irradiance().any()
    assert sky.sun_solid_angle == 6e-5
    assert sky.info["sun_zenith_deg"] == pytest.approx(35.0)
    small = directional_sky(d, 50.0, solid_angle=1e-4)
    np.testing.assert_allclose(small.sun_radiance, 50.0 / 1e-4)


@pytest.mark.parametrize("direction, irradiance, match", [
    ([0, 0, 0], 1.0, "non-zero direction"),
    ([1, 0, -0.1], 1.0, "at or below the horizon"),
    ([1, 0, 0], 1.0, "at or below the horizon"),
    ([0, 0, 1], [1.0, -2.0, 3.0], "directional irradiance = -2"),
    ([0, 0, 1], [1.0, 2.0], "RGB triple"),
])
def test_bad_directional_lights_are_refused_in_one_line(direction, irradiance, match):
    with pytest.raises(SkyfitError, match=match) as e:
        directional_sky(direction, irradiance)
    assert "\n" not in str(e.value)


# ---- the emitter and the light cache against the analytic sky --------------------------

def tabulated(sky, rows=64):
    """``sky`` with its sky patterns replaced by their values at the cell centres of a
    lat-long table (the sun disc and ground kept)."""
    theta, phi = latlong_centres(rows, 2 * rows)
    d = direction_from_angles(theta[:, None], phi[None, :])
    table = np.where(d[..., 2:3] > 0, sky.sky_radiance(d), 0.0)
    return Sky(sky.sun_direction, envmap=table, ground=sky.ground,
               sun_radiance=sky.sun_radiance, sun_solid_angle=sky.sun_solid_angle)


def test_a_tabulated_clear_sky_has_the_analytic_irradiance():
    sky = cie_sky("clear", 35.0, 150.0)
    np.testing.assert_allclose(tabulated(sky).horizontal_irradiance(),
                               sky.horizontal_irradiance(), rtol=3e-3)


def test_the_light_cache_of_a_tabulated_sky_equals_the_analytic_one(mi):
    """The diffuse basis (the control variate's deterministic integral plus the sampled sun)
    of a tilted Lambertian-and-Ward panel: a map the analytic sky was tabulated into gives the
    analytic sky's light within the tabulation error."""
    from skyfit_mi.render.daylight import sky_dict
    from skyfit_mi.render.light_cache import build_light_cache

    sky = cie_sky("clear", 35.0, 150.0)
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 2},
        "sky": sky_dict(sky),
        "board": {"type": "rectangle",
                  "to_world": mi.ScalarTransform4f().rotate([1, 0, 0], -30),
                  "bsdf": {"type": "ward", "id": "panel", "rho_d": 0.5, "rho_s": 0.1,
                           "sigma_alpha": 0.1}},
        "sensor": {"type": "orthographic",
                   "to_world": mi.ScalarTransform4f().look_at([0, -3, 4], [0, 0, 0], [0, 0, 1])
                   @ mi.ScalarTransform4f().scale([0.3, 0.3, 1]),
                   "film": {"type": "hdrfilm", "width": 4, "height": 4}}})
    params = mi.traverse(scene)
    pixels = np.array([[1, 1], [2, 2], [1, 2]])
    cache = build_light_cache(scene, params, [sky, tabulated(sky)], pixels, "panel",
                              positions=4, directions=64, seed=1)
    assert cache.hit.all()
    D = cache.diffuse_basis()                                        # (P, 2 frames, 3)
    np.testing.assert_allclose(D[:, 1], D[:, 0], rtol=3e-3)
    G = cache.specular_basis(0.1)
    np.testing.assert_allclose(G[:, 1], G[:, 0], rtol=0.01)
