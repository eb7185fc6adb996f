"""The lat-long table: a radiance over the whole sphere on a latitude-longitude grid.

A measured or fitted sky's light enters a :class:`~skyfit_mi.physics.sky.Sky` as such a table,
``Sky.envmap``.  This module holds the table's convention, its lookup (shared with the
``cie_sky`` emitter through :func:`latlong_texel`) and the resampling of any lookup onto it.

A table ``T`` of shape (H, W, 3):

* row ``i`` covers zenith angles [i pi/H, (i + 1) pi/H]: row 0 touches the zenith, row H - 1
  the nadir.
* column ``j`` covers compass azimuths (``docs/CONVENTIONS.md``) [j 2 pi/W, (j + 1) 2 pi/W]:
  column 0 begins at north, running north, east, south, west (a panorama turning clockwise).
* between cell centres the radiance is bilinear in (phi, theta), periodic in azimuth, and held
  at the first (last) row's values toward the zenith (nadir).
"""

import numpy as np

from ..conventions import angles_from_direction

#: Most rows a map is resampled to (columns twice as many); larger maps are averaged down.
#: 256 rows: 0.7 degree cells, 1.5 MB per frame in float32.
MAX_ROWS = 256
#: Table rows resampled at once (bounds the memory :func:`resample` takes).
RESAMPLE_BLOCK = 16


def latlong_texel(theta, phi, rows, cols, floor, clip):
    """The bilinear lookup of the lat-long table at zenith ``theta`` and compass azimuth ``phi``
    [rad] (wrapping): rows i0, i1, the weight ``fy`` of i1, columns j0, j1 (wrapped), the
    weight ``fx`` of j1, all floats.  ``floor`` and ``clip`` come from NumPy or Dr.Jit so the
    NumPy sky and the emitter share this definition; ``rows``, ``cols`` may be Dr.Jit values.
    """
    y = clip(theta * (rows / np.pi) - 0.5, 0.0, rows - 1.0)
    i0 = floor(y)
    i1 = clip(i0 + 1.0, 0.0, rows - 1.0)
    x = phi * (cols / (2.0 * np.pi)) - 0.5
    j = floor(x)
    j0 = j - cols * floor(j / cols)
    j1 = j0 + 1.0
    j1 = j1 - cols * floor(j1 / cols)
    return i0, i1, y - i0, j0, j1, x - j


def latlong_lookup(table, theta, phi):
    """Radiance (..., 3) of the lat-long ``table`` (H, W, 3) at zenith ``theta`` and compass
    azimuth ``phi`` [rad] (broadcast), bilinear."""
    t = np.asarray(table)
    H, W = t.shape[:2]
    i0, i1, fy, j0, j1, fx = (np.asarray(a) for a in latlong_texel(
        np.asarray(theta, dtype=float), np.asarray(phi, dtype=float), float(H), float(W),
        np.floor, np.clip))
    i0, i1, j0, j1 = (a.astype(int) for a in (i0, i1, j0, j1))
    fy, fx = fy[..., None], fx[..., None]
    return ((1 - fy) * ((1 - fx) * t[i0, j0] + fx * t[i0, j1])
            + fy * ((1 - fx) * t[i1, j0] + fx * t[i1, j1]))


def latlong_radiance(table, directions):
    """Radiance of the lat-long ``table`` toward world ``directions`` (..., 3), shape (..., 3)."""
    theta, phi = angles_from_direction(directions)
    return latlong_lookup(table, theta, phi)


def latlong_centres(rows, cols):
    """Zenith angles (rows,) and compass azimuths (cols,) of the table's cell centres [rad]."""
    return (np.arange(rows) + 0.5) * np.pi / rows, (np.arange(cols) + 0.5) * 2 * np.pi / cols


def resample(lookup, rows, north_rotation_deg=0.0, supersample=1):
    """A world-frame lat-long table (rows, 2 rows, 3): each cell the mean of ``lookup(theta,
    phi_map)`` over ``supersample``^2 evenly spaced points, phi_map = phi - north_rotation the
    map's own azimuth [rad].  ``lookup`` is a lookup function bound to a map.
    """
    k = int(supersample)
    cols = 2 * int(rows)
    off = (np.arange(k) + 0.5) / k
    phi = ((np.arange(cols)[:, None] + off[None, :]) * 2 * np.pi / cols).ravel() \
        - np.radians(north_rotation_deg)
    out = np.empty((rows, cols, 3), np.float32)
    for start in range(0, rows, RESAMPLE_BLOCK):
        i = np.arange(start, min(start + RESAMPLE_BLOCK, rows))
        theta = ((i[:, None] + off[None, :]) * np.pi / rows).ravel()
        v = lookup(theta[:, None], phi[None, :])
        out[i] = v.reshape(len(i), k, cols, k, 3).mean(axis=(1, 3))
    return out
