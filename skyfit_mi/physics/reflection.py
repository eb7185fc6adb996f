"""Radiance reflected by a horizontal Ward surface under an open daylight sky, by quadrature.

A deterministic NumPy reference for the renderers: the surface (normal +Z) sees the whole upper
hemisphere of a :class:`~skyfit_mi.physics.sky.Sky` unoccluded and light reflects once, so the
radiance toward ``wo`` is the single integral (thesis eq. 3.1 with the Ward BRDF, eq. 3.19)

    L(wo) = integral over the hemisphere of f_r(wi, wo) cos(theta_i) L_sky+sun(wi) dwi

split into the solar disc (the whole BRDF, Gauss-Legendre about the sun's centre), the diffuse
part over the sky (its horizontal irradiance) and the lobe over the sky (a cap around the mirror
direction holding all but e^-100 of it).
"""

import numpy as np

from .ward import specular_lobe


def _gauss(n, a, b):
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (b - a) * x + 0.5 * (b + a), 0.5 * (b - a) * w


def cap_quadrature(axis, radius, n_r=48, n_phi=96):
    """Directions (..., n, 3) and solid-angle weights (n,) [sr] of a Gauss-Legendre (angle) x
    trapezoid (azimuth) rule over the cap of angular ``radius`` [rad] around each unit
    ``axis`` (..., 3)."""
    axis = np.asarray(axis, dtype=float)
    t = np.where((np.abs(axis[..., :1]) < 0.9), [1.0, 0, 0], [0, 1.0, 0])
    e1 = np.cross(axis, t)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(axis, e1)
    th, wt = _gauss(n_r, 0.0, radius)
    ph = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    T, F = (v.ravel() for v in np.meshgrid(th, ph, indexing="ij"))
    local = np.stack([np.sin(T) * np.cos(F), np.sin(T) * np.sin(F), np.cos(T)], axis=-1)
    d = local @ np.stack([e1, e2, axis], axis=-2)                  # (..., n, 3)
    return d, np.repeat(wt, n_phi) * np.sin(T) * (2 * np.pi / n_phi)


def reflected_radiance(sky, wo, rho_d, rho_s, sigma_alpha, normalisation="ward"):
    """Radiance [W m^-2 sr^-1], RGB (..., 3), leaving a horizontal Ward surface toward world
    unit directions ``wo`` (..., 3) under ``sky``; raw parameters (``ward.raw_parameters``),
    sigma_alpha >= 0.001."""
    wo = np.asarray(wo, dtype=float)
    rho_d, rho_s = np.broadcast_to(rho_d, (3,)), np.broadcast_to(rho_s, (3,))
    wo_n = wo[..., None, :]
    # the solar disc: the whole BRDF
    d, w = cap_quadrature(sky.sun_direction, np.arccos(1 - sky.sun_chord2 / 2))
    lobe = specular_lobe(d, wo_n, sigma_alpha, normalisation) * np.clip(d[:, 2], 0, None) * w
    sun = (rho_d / np.pi * np.sum(np.clip(d[:, 2], 0, None) * w)
           + rho_s * np.sum(lobe, axis=-1)[..., None]) * sky.sun_radiance
    # the sky: the diffuse part (the same for every wo), and the lobe over its cap
    diffuse = rho_d / np.pi * sky.sky_horizontal_irradiance()
    mirror = wo * [-1.0, -1.0, 1.0]
    d, w = cap_quadrature(mirror, min(np.pi, 20 * sigma_alpha), n_r=64, n_phi=96)
    lobe = specular_lobe(d, wo_n, sigma_alpha, normalisation) * np.clip(d[..., 2], 0, None) * w
    glossy = rho_s * np.einsum("...n,...nc->...c", lobe, sky.sky_radiance(d))
    return sun + diffuse + glossy
