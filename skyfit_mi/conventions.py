"""World frame and angle conventions (see ``docs/CONVENTIONS.md``).

* World frame (Radiance's): +X east, +Y north, +Z up (right-handed).
* Zenith angle ``theta`` [rad]: angle from +Z.  Altitude = pi/2 - theta.
* Azimuth ``phi`` [rad]: compass bearing from north (+Y) toward east (+X), so east is pi/2,
  south pi; the solar azimuth convention of NREL SPA / pvlib and of the thesis (eq. 4.4).
* Degrees only at the user boundary (arguments named ``*_deg``, spec files, outputs).
* Smooth curves over a day: Legendre polynomials of the time mapped onto [-1, 1] over the
  frames' span (:func:`time_legendre`).
"""

import numpy as np


def direction_from_angles(theta, phi):
    """Unit world vector(s) (..., 3) for zenith ``theta`` [rad] and compass azimuth ``phi``
    [rad]."""
    theta, phi = np.broadcast_arrays(np.asarray(theta, dtype=float), np.asarray(phi, dtype=float))
    s = np.sin(theta)
    return np.stack([s * np.sin(phi), s * np.cos(phi), np.cos(theta)], axis=-1)


def unit_directions(d):
    """World vector(s) ``d`` (..., 3) divided by their lengths, as a float array."""
    d = np.asarray(d, dtype=float)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def angles_from_direction(d):
    """Zenith and compass azimuth [rad] of world vector(s) ``d`` (..., 3); the azimuth is in
    [0, 2 pi), 0 for a vertical vector."""
    d = unit_directions(d)
    theta = np.arccos(np.clip(d[..., 2], -1.0, 1.0))
    phi = np.mod(np.arctan2(d[..., 0], d[..., 1]), 2 * np.pi)
    return theta, phi


def time_legendre(seconds, span, terms):
    """(n, ``terms``) Legendre polynomials P_0.. of ``seconds`` (n,) [s] mapped onto [-1, 1]
    over ``span`` (first, last) [s], held beyond it."""
    t0, t1 = span
    x = np.clip(2.0 * (np.asarray(seconds, dtype=float) - t0) / max(t1 - t0, 1.0) - 1.0,
                -1.0, 1.0)
    return np.polynomial.legendre.legvander(x, terms - 1)
