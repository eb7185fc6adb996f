"""Radiance reflected by a horizontal Ward surface under an open daylight sky, by quadrature.

A deterministic NumPy reference for the renderers: the surface (normal +Z, world frame)
sees the whole upper hemisphere of a :class:`~skyfit_mi.sky.Sky`, nothing occludes it, and
light reflects once, so the radiance toward ``wo`` is the rendering equation's single
integral (thesis eq. 3.1 with the Ward BRDF, eq. 3.19):

    L(wo) = integral over the hemisphere of f_r(wi, wo) cos(theta_i) L_sky+sun(wi) dwi

split into the solar disc (the whole BRDF, Gauss-Legendre in the angle from the sun's
centre), the diffuse part over the sky (Gauss-Legendre in cos theta) and the lobe over the
sky (a cap around the mirror direction holding all but e^-100 of it).  Used to arbitrate
between the light cache and the path-traced frames (``scripts/diagnose_narrow_lobe.py``).
"""

import numpy as np

from .ward import specular_lobe


def _gauss(n, a, b):
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (b - a) * x + 0.5 * (b + a), 0.5 * (b - a) * w


def cap_quadrature(axis, radius, n_r=48, n_phi=96):
    """Directions (n, 3) and solid-angle weights (n,) [sr] of a Gauss-Legendre (angle) x
    trapezoid (azimuth) rule over the cap of angular ``radius`` [rad] around unit ``axis``."""
    axis = np.asarray(axis, dtype=float)
    t = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(axis, t)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    th, wt = _gauss(n_r, 0.0, radius)
    ph = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    T, F = np.meshgrid(th, ph, indexing="ij")
    d = (np.cos(T)[..., None] * axis + np.sin(T)[..., None]
         * (np.cos(F)[..., None] * e1 + np.sin(F)[..., None] * e2))
    return d.reshape(-1, 3), (wt[:, None] * np.sin(T) * (2 * np.pi / n_phi)).ravel()


def hemisphere_quadrature(n_t=96, n_phi=192):
    """Directions and weights [sr] over the upper hemisphere (Gauss-Legendre in cos theta)."""
    c, wc = _gauss(n_t, 0.0, 1.0)
    ph = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    C, F = np.meshgrid(c, ph, indexing="ij")
    s = np.sqrt(1 - C**2)
    d = np.stack([s * np.cos(F), s * np.sin(F), C], axis=-1)
    return d.reshape(-1, 3), np.repeat(wc, n_phi) * (2 * np.pi / n_phi)


def reflected_radiance(sky, wo, rho_d, rho_s, sigma_alpha, normalisation="ward"):
    """Radiance [W m^-2 sr^-1], RGB (3,), leaving a horizontal Ward surface toward world unit
    ``wo`` under ``sky``; raw parameters (``ward.raw_parameters``), sigma_alpha >= 0.001."""
    wo = np.asarray(wo, dtype=float)
    rho_d, rho_s = np.broadcast_to(rho_d, (3,)), np.broadcast_to(rho_s, (3,))
    d, w = cap_quadrature(sky.sun_direction, np.arccos(1 - sky.sun_chord2 / 2))
    f = rho_d / np.pi + rho_s * specular_lobe(d, wo, sigma_alpha, normalisation)[:, None]
    out = np.sum(f * (np.clip(d[:, 2], 0, None) * w)[:, None], axis=0) * sky.sun_radiance
    d, w = hemisphere_quadrature()
    out = out + rho_d / np.pi * np.sum(sky.sky_radiance(d) * (d[:, 2] * w)[:, None], axis=0)
    mirror = np.array([-wo[0], -wo[1], wo[2]])
    d, w = cap_quadrature(mirror, min(np.pi, 20 * sigma_alpha), n_r=96, n_phi=128)
    lobe = specular_lobe(d, wo, sigma_alpha, normalisation) * np.clip(d[:, 2], 0, None)
    return out + rho_s * np.sum(sky.sky_radiance(d) * (lobe * w)[:, None], axis=0)
