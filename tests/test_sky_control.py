"""The sky control variate's deterministic integrals against brute force (render/sky_control.py).

The reference is independent of the code under test: the NumPy sky (physics/sky.py) and the
NumPy lobe (physics/ward.py) summed over a fine Cartesian grid of the half vector's slope (the
lobe) or a fine Gauss-Legendre grid of the hemisphere (the diffuse term).
"""
import numpy as np
import pytest

#: Surfaces (tilt of the normal from the zenith, view angle from the normal) [deg]: flat,
#: tilted, vertical, grazing views, and a view near the normal.
SURFACES = [(0, 30), (45, 40), (90, 60), (37, 75), (60, 85), (20, 10)]
SKIES = {"clear": dict(kind="clear"), "overcast": dict(kind="overcast"),
         "intermediate": dict(kind="intermediate", phi=0.5)}


@pytest.fixture(scope="module")
def points(mi):
    """Surface interactions of SURFACES (normals at azimuth 1 rad, views at 0.3 rad)."""
    import drjit as dr

    tilt, view = np.radians(np.array(SURFACES, dtype=float)).T
    n = np.stack([np.sin(tilt) * np.cos(1.0), np.sin(tilt) * np.sin(1.0), np.cos(tilt)])
    wo = np.stack([np.sin(view) * np.cos(0.3), np.sin(view) * np.sin(0.3), np.cos(view)])
    si = dr.zeros(mi.SurfaceInteraction3f, len(SURFACES))
    si.sh_frame = mi.Frame3f(mi.Vector3f(*n))
    si.wi = mi.Vector3f(*wo)
    frame = np.stack([np.array(v, dtype=float).T for v in (si.sh_frame.s, si.sh_frame.t,
                                                            si.sh_frame.n)], axis=1)
    return si, wo.T, frame                                  # frame: (Q, 3 axes, 3)


def _sky(name):
    from skyfit_mi.physics.sky import cie_sky
    return cie_sky(sun_zenith_deg=40.0, sun_azimuth_deg=200.0, **SKIES[name])


def _quadrature(mi, sky, si, sigma=None):
    """The module's integral at every point: I_d, or I_s(sigma) with the 'ward' lobe."""
    from skyfit_mi.render.daylight import sky_dict
    from skyfit_mi.render.sky_control import diffuse_integral, lobe_integral

    emitter = mi.load_dict(sky_dict(sky))
    up = si.to_local(mi.Vector3f(0.0, 0.0, 1.0))
    if sigma is None:
        return diffuse_integral(emitter, si, up)
    return lobe_integral(emitter, si, up, sigma)


def _brute_diffuse(sky, frame, n=1500):
    mu, w = np.polynomial.legendre.leggauss(n)
    mu, w = 0.5 * (mu + 1), 0.5 * w
    phi = (np.arange(2 * n) + 0.5) * np.pi / n
    st = np.sqrt(1 - mu**2)[:, None]
    d = np.stack(np.broadcast_arrays(st * np.cos(phi), st * np.sin(phi), mu[:, None]), -1)
    return np.einsum("ijc,i->c", sky.sky_radiance(d @ frame), w * mu / np.pi) * (np.pi / n)


def _brute_lobe(sky, wo, frame, sigma, n=1200):
    """The lobe's integral on an n x n grid of the half vector's slope over +-6 sigma."""
    from skyfit_mi.physics.ward import specular_lobe

    x = ((np.arange(n) + 0.5) / n - 0.5) * 12 * sigma
    h = np.stack(np.broadcast_arrays(x[:, None], x[None, :], 1.0), -1)
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    oh = h @ wo
    wi = 2 * oh[..., None] * h - wo
    w = 4 * oh * h[..., 2] ** 3 * (12 * sigma / n) ** 2 * (oh > 0)
    f = specular_lobe(wi, np.broadcast_to(wo, wi.shape), sigma) * np.clip(wi[..., 2], 0, None)
    return np.einsum("ij,ijc->c", f * w, sky.sky_radiance(wi @ frame))


# the clear sky (sun's circumsolar peak: the hardest) by default; the others with the slow sweeps
@pytest.mark.parametrize("name", ["clear"] + [pytest.param(k, marks=pytest.mark.slow)
                                             for k in SKIES if k != "clear"])
def test_diffuse_integral_matches_brute_force(mi, points, name):
    si, _, frame = points
    sky = _sky(name)
    got = _quadrature(mi, sky, si)
    want = np.array([_brute_diffuse(sky, frame[q]) for q in range(len(SURFACES))])
    assert np.max(np.abs(got / want - 1)) < 3e-4, got / want - 1          # measured 2e-4


@pytest.mark.parametrize("sigma, tol", [(0.003, 1e-5), pytest.param(0.03, 1e-4, marks=pytest.mark.slow),
                                        (0.1, 2e-4), pytest.param(0.2, 3e-4, marks=pytest.mark.slow),
                                        (0.5, 1e-3)])
def test_lobe_integral_matches_brute_force(mi, points, sigma, tol):
    si, wo, frame = points
    sky = _sky("clear")
    got = _quadrature(mi, sky, si, sigma)
    want = np.array([_brute_lobe(sky, wo[q], frame[q], sigma) for q in range(len(SURFACES))])
    assert np.max(np.abs(got / want - 1)) < tol, got / want - 1


def test_chebyshev_series_interpolates_between_its_roughness_nodes(mi, points):
    """I_s is kept as a series in log sigma: between its nodes it must equal the quadrature
    (to within the quadrature's own error, which changes with its resolution at 0.12 and 0.25:
    3.1e-4 measured at 0.16; up to 1e-3 for the widest lobes, as against brute force)."""
    from skyfit_mi.render.light_cache import SIGMA_TABLE
    from skyfit_mi.render.sky_control import (chebyshev_coefficients, chebyshev_eval,
                                              chebyshev_nodes, chebyshev_x)
    si, _, _ = points
    sky = _sky("clear")
    nodes = chebyshev_nodes(*SIGMA_TABLE)
    coef = chebyshev_coefficients(np.stack([_quadrature(mi, sky, si, s) for s in nodes]))
    for sigma, tol in ((0.0025, 4e-4), (0.013, 4e-4), (0.07, 4e-4), (0.16, 4e-4), (0.41, 1e-3)):
        series = chebyshev_eval(coef, chebyshev_x(sigma, *SIGMA_TABLE, np.log, np.clip))
        direct = _quadrature(mi, sky, si, sigma)
        assert np.max(np.abs(series / direct - 1)) < tol, (sigma, series / direct - 1)


def test_every_frames_integrals_in_one_pass_equal_each_frames_own(mi, points):
    # FrameSkies: each point under its own frame's sky (per-lane parameters) gives what the
    # emitter loaded with that frame's sky gives, for skies of every kind (Perez's too) and a
    # blended horizon
    import dataclasses

    import drjit as dr

    from skyfit_mi.physics.perez import perez_sky
    from skyfit_mi.physics.sky import cie_sky
    from skyfit_mi.render.daylight import sky_dict
    from skyfit_mi.render.sky_control import FrameSkies, quadrature, sky_integrals, to_numpy

    si, _, _ = points
    Q = len(SURFACES)
    skies = [_sky("clear"), _sky("overcast"), _sky("intermediate"),
             dataclasses.replace(cie_sky("clear", 80.0, 100.0), horizon_blend=True),
             perez_sky(50.0, 150.0, 172, dhi=120.0, dni=500.0).to_sky()]
    quad = quadrature(0.002, 0.5, "ward")
    own = []
    for sky in skies:
        d, lobes = sky_integrals(mi.load_dict(sky_dict(sky)), si, quad)
        own.append(np.stack([to_numpy(v) for v in [d, *lobes]]))
    index = mi.UInt32(np.tile(np.arange(Q, dtype=np.uint32), len(skies)))
    every = dr.gather(mi.SurfaceInteraction3f, si, index)
    d, lobes = sky_integrals(FrameSkies(skies, np.repeat(np.arange(len(skies)), Q)), every, quad)
    together = np.stack([to_numpy(v) for v in [d, *lobes]])             # (17, T Q, 3)
    for t, values in enumerate(own):
        part = together[:, t * Q:(t + 1) * Q]
        assert np.allclose(part, values, rtol=1e-5, atol=1e-6 * np.abs(values).max()), t


def test_skies_differing_in_their_departure_alone_share_their_patterns(mi, points):
    # a list of FrameSkies integrated together, where _sky_sum evaluates one pattern for the
    # skies that differ in their departure weights alone (the departure's parts beside the
    # rest), gives each sky's own integrals; skies of other levels, another sun, other Perez
    # coefficients or frames swapped keep their own patterns
    import dataclasses

    from skyfit_mi.physics.perez import perez_sky
    from skyfit_mi.physics.sky import cie_sky
    from skyfit_mi.physics.sky_departure import departure_parts
    from skyfit_mi.render.sky_control import FrameSkies, quadrature, sky_integrals, to_numpy

    si, _, _ = points
    Q = len(SURFACES)
    first = np.zeros(Q)
    _, rest = _sky("intermediate").split()
    perez = perez_sky(50.0, 150.0, 172, dhi=120.0, dni=500.0).to_sky()
    bent = dataclasses.replace(perez, perez_coefficients=perez.perez_coefficients * [1, 1.2, 1,
                                                                                      1, 1])
    other_sun = cie_sky(sun_zenith_deg=50.0, sun_azimuth_deg=200.0, **SKIES["intermediate"])
    lights = [FrameSkies([sky], first) for sky in
              [rest, *(sky for _, sky in departure_parts(_sky("intermediate"))),
               rest.sky_scaled(2.0), other_sun.split()[1], perez, bent]]
    half = np.arange(Q) % 2
    lights += [FrameSkies([rest, perez], half), FrameSkies([rest, perez], 1 - half)]
    assert len({light.patterns_key for light in lights}) == len(lights) - 5
    quad = quadrature(0.002, 0.5, "ward")

    def values(result):
        d, lobes = result
        return np.stack([to_numpy(v) for v in [d, *lobes]])

    d, lobes = sky_integrals(lights, si, quad)
    alone = [values(sky_integrals(light, si, quad)) for light in lights]
    for i, own in enumerate(alone):
        assert np.array_equal(values((d[i], [node[i] for node in lobes])), own), i
    assert np.allclose(alone[6], 2 * alone[0], rtol=1e-6)       # the levels are the rest's x 2
    for i, j in ((7, 0), (9, 8), (11, 10)):        # another sun, Perez's b, the frames swapped
        assert not np.allclose(alone[i], alone[j], rtol=1e-3), i


def _brute_ggx(sky, wo, frame, sigma, name, n=3000, m=720):
    """The GGX lobe's integral by the midpoint rule in log tan delta (from 1e-3 sigma to 60,
    where its D cos^4 delta times the slope area is smooth) and the half vector's azimuth."""
    from skyfit_mi.physics.ward import specular_lobe

    edges = np.linspace(np.log(1e-3 * sigma), np.log(60.0), n + 1)
    lr = 0.5 * (edges[1:] + edges[:-1])
    r = np.exp(lr)[:, None]
    phi = (np.arange(m) + 0.5) * 2 * np.pi / m
    h = np.stack(np.broadcast_arrays(r * np.cos(phi), r * np.sin(phi), 1.0), -1)
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    oh = h @ wo
    wi = 2 * oh[..., None] * h - wo
    area = r * r * np.diff(edges)[:, None] * 2 * np.pi / m           # r dr dphi
    weight = 4 * oh * h[..., 2] ** 3 * area * (oh > 0)
    f = specular_lobe(wi, np.broadcast_to(wo, wi.shape), sigma, name) \
        * np.clip(wi[..., 2], 0, None)
    return np.einsum("ij,ijc->c", f * weight, sky.sky_radiance(wi @ frame))


@pytest.mark.parametrize("sigma, tol", [(0.01, 1e-4), pytest.param(0.05, 2e-4, marks=pytest.mark.slow),
                                        (0.12, 2e-4), pytest.param(0.4, 2e-4, marks=pytest.mark.slow)])
def test_ggx_lobe_integral_matches_brute_force(mi, points, sigma, tol):
    """I_s through a GGX lobe (its long tails: the quadrature's rays reach the surface's horizon)
    under the clear sky against brute force in its own radial variable."""
    from skyfit_mi.render.daylight import sky_dict
    from skyfit_mi.render.sky_control import lobe_integral

    si, wo, frame = points
    sky = _sky("clear")
    emitter = mi.load_dict(sky_dict(sky))
    got = lobe_integral(emitter, si, si.to_local(mi.Vector3f(0.0, 0.0, 1.0)), sigma,
                        "ggx_plastic")
    want = np.array([_brute_ggx(sky, wo[q], frame[q], sigma, "ggx_plastic")
                     for q in range(len(SURFACES))])
    assert np.max(np.abs(got / want - 1)) < tol, got / want - 1
