"""The ``cie_sky`` environment emitter: the daylight sky and the sun disc.

It evaluates exactly :meth:`skyfit_mi.physics.sky.Sky.radiance` (the same pattern sum, term by
term) and importance-samples it: the sun disc by a uniform cone, the sky by a piecewise-constant
table over an equal-area (azimuth, cos theta) grid rebuilt whenever its parameters change.  Every
number, an environment map's size included, is an opaque Dr.Jit variable, so changing the sky
from frame to frame (``mi.traverse`` + ``params.update()``) recompiles nothing.

Parameters (all linear sRGB radiance in W m^-2 sr^-1 unless stated; none
differentiable; all exposed by ``traverse`` and updatable):

====================  ========  ==========================  ==========================================
name                  type      default                     meaning
====================  ========  ==========================  ==========================================
``sun_direction``     vector    (0, 0, 1)                   toward the sun, world frame (+X E, +Y N, +Z up)
``sun_radiance``      rgb       0                           radiance of the solar disc
``sun_solid_angle``   float     6e-5                        solar disc solid angle [sr], in [1e-7, 0.5]
``clear``             rgb       0                           weight of the CIE clear pattern
``overcast``          rgb       0                           weight of the CIE overcast pattern
``uniform``           rgb       0                           uniform sky radiance
``intermediate``      rgb       0                           weight of Radiance's intermediate pattern
``perez``             rgb       0                           weight of the Perez all-weather pattern
``perez_a`` .. ``_e`` float     0                           the Perez pattern's coefficients (b <= 0)
``departure_0`` ..    float     0                           weights of the departure field on the
``departure_4``                                             patterns (:mod:`~skyfit_mi.physics.sky_departure`)
``ground``            rgb       0                           radiance below the horizon
``envmap``            tensor    none                        lat-long radiance table (H, W, 3), world
                                                            frame (:mod:`skyfit_mi.physics.latlong`)
``horizon_blend``     bool      false                       Radiance's sky-to-ground blend
``scene_radius``      float     1e4                         distance [scene units] beyond all geometry
====================  ========  ==========================  ==========================================

Build the dictionary from a :class:`~skyfit_mi.physics.sky.Sky` with
:func:`skyfit_mi.render.daylight.sky_dict`; change it with
:func:`skyfit_mi.render.daylight.update_sky`.
"""

import functools

import drjit as dr
import mitsuba as mi
import numpy as np

from ...physics.colour import SRGB_LUMINANCE
from ...physics.latlong import latlong_texel
from ...physics.sky import PEREZ_HORIZON_COS, Sky
from ..daylight import (DEPARTURE_KEYS as _DEPARTURE_KEYS, PEREZ_KEYS as _PEREZ_KEYS,
                        RGB_KEYS as _RGB_KEYS, envmap_table, float_parameters, jit_array,
                        opaque_value)
from .properties import property_values

_FLOAT_KEYS = _PEREZ_KEYS + _DEPARTURE_KEYS

#: Sampling table resolution: azimuth cells x cos(theta) cells.
TABLE_NU, TABLE_NV = 128, 64
#: Sub-samples per cell side when tabulating the sky's luminance.
TABLE_SUPERSAMPLE = 3
#: Share of the sky's sampling density spread uniformly over the sphere.
UNIFORM_FLOOR = 0.02


def _triple(props, name, default):
    a = property_values(props, name, default)
    return np.full(3, a[0]) if a.size == 1 else a


def _sky(value, envmap):
    """The :class:`~skyfit_mi.physics.sky.Sky` of an emitter's parameters, each
    ``value(name, default)`` as a float array, and ``envmap`` table (None or all zero: none)."""
    table = None if envmap is None else np.array(envmap, dtype=np.float32)
    return Sky(value("sun_direction", (0, 0, 1)), **{k: value(k, 0.0) for k in _RGB_KEYS},
               perez_coefficients=[float(value(k, 0.0)[0]) for k in _PEREZ_KEYS],
               departure=[float(value(k, 0.0)[0]) for k in _DEPARTURE_KEYS],
               horizon_blend=bool(value("horizon_blend", False)[0]),
               sun_solid_angle=float(value("sun_solid_angle", 6e-5)[0]),
               envmap=table if np.any(table) else None)


def _table_directions():
    """Sub-sample directions of each table cell, shape (NV*NU, S*S, 3)."""
    s = TABLE_SUPERSAMPLE
    off = (np.arange(s) + 0.5) / s
    u = (np.arange(TABLE_NU)[None, :, None, None] + off[None, None, None, :]) / TABLE_NU
    v = (np.arange(TABLE_NV)[:, None, None, None] + off[None, None, :, None]) / TABLE_NV
    u, v = np.broadcast_arrays(u, v)
    z = 1.0 - 2.0 * v
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    d = np.stack([r * np.cos(2 * np.pi * u), r * np.sin(2 * np.pi * u), z], axis=-1)
    return d.reshape(TABLE_NV * TABLE_NU, s * s, 3)


def _table_directions_jit():
    """:func:`_table_directions` flat as a Dr.Jit Vector3f of the current variant (cached)."""
    return _table_directions_of(mi.variant())


@functools.lru_cache(maxsize=None)
def _table_directions_of(variant):
    d = _table_directions().reshape(-1, 3)
    return jit_array(mi.Vector3f, d[:, 0], d[:, 1], d[:, 2])


def sky_function(p, d, pattern=None):
    """Sky.sky_radiance in Dr.Jit: the radiance without sun or map toward world directions
    ``d`` [W m^-2 sr^-1] for the parameters of ``p`` (an emitter, or any object with its fields,
    scalars or one per lane of ``d``): :func:`sky_pattern` (or the ``pattern`` it gave for a sky
    that differs from ``p`` in its departure weights alone) times the departure's field, blended
    into the ground at the horizon."""
    s = p.sun_direction
    cos_z = dr.clip(dr.dot(d, s), -1.0, 1.0)
    dz = d.z
    sky = sky_pattern(p, d) if pattern is None else pattern
    # the departure's field (sky_departure.basis: u = 2 cos theta - 1, y = cos gamma)
    u = dr.clip(2.0 * dz - 1.0, -1.0, 1.0)
    sky = sky * (1.0 + p.departure_0 * u + p.departure_1 * (1.5 * u * u - 0.5)
                 + p.departure_2 * cos_z + p.departure_3 * (1.5 * cos_z * cos_z - 0.5)
                 + p.departure_4 * u * cos_z)
    a = dr.power(dz + 1.01, 10.0)
    w = a / (a + dr.rcp(a))
    blended = w * sky + (1.0 - w) * p.ground
    sharp = dr.select(dz > 0.0, sky, p.ground)
    return dr.select(p.blend_weight > 0.5, blended, sharp)


def sky_pattern(p, d):
    """The sky's patterns toward ``d`` [W m^-2 sr^-1] at ``p``'s levels (CIE clear eqs. 4.12-4.13,
    overcast eq. 4.16, Radiance's intermediate, Perez et al. 1993 eq. 1), before the departure's
    field and the ground (:func:`sky_function`)."""
    s = p.sun_direction
    cos_z = dr.clip(dr.dot(d, s), -1.0, 1.0)
    zeta = dr.acos(cos_z)
    dz = d.z
    gamma_f = dr.select(dz > 0.01, 1.0 - dr.exp(-0.32 / dr.maximum(dz, 0.01)), 1.0)  # eq. 4.12
    clear = (0.91 + 10.0 * dr.exp(-3.0 * zeta) + 0.45 * cos_z * cos_z) * gamma_f      # eq. 4.13
    overcast = (1.0 + 2.0 * dz) / 3.0                                                 # eq. 4.16
    eta = dr.acos(dr.clip(dz, -1.0, 1.0))
    zt = dr.acos(dr.clip(s.z, -1.0, 1.0))
    inter = (((1.35 * dr.sin(5.631 - 3.59 * eta) + 3.12) * dr.sin(4.396 - 2.6 * zt)
              + 6.37 - eta) / 2.326
             * dr.exp(zeta * -0.563 * ((2.629 - eta) * (1.562 - zt) + 0.812)))
    # Perez et al. 1993 eq. 1, cos theta_p held at 0.01 below it, clamped at 0 (Sky.perez)
    mu = dr.maximum(dz, PEREZ_HORIZON_COS)
    perez = dr.maximum((1.0 + p.perez_a * dr.exp(p.perez_b / mu))
                       * (1.0 + p.perez_c * dr.exp(p.perez_d * zeta)
                          + p.perez_e * cos_z * cos_z), 0.0)
    return p.clear * clear + p.overcast * overcast + p.uniform \
        + p.intermediate * inter + p.perez * perez


class CIESkyEmitter(mi.Emitter):
    """Daylight sky plus sun disc (see the module docstring for parameters)."""

    def __init__(self, props):
        mi.Emitter.__init__(self, props)
        self.m_flags = mi.EmitterFlags.Infinite | mi.EmitterFlags.SpatiallyVarying
        sky = _sky(lambda k, default: _triple(props, k, default),
                   props["envmap"] if "envmap" in props else None)
        self.scene_radius = mi.Float(float(props.get("scene_radius", 1e4)))
        self.sun_direction = mi.Vector3f(*map(float, sky.sun_direction))
        self.sun_solid_angle = mi.Float(float(sky.sun_solid_angle))
        for k in _RGB_KEYS:
            setattr(self, k, mi.Color3f(*map(float, getattr(sky, k))))
        for k, v in float_parameters(sky).items():
            setattr(self, k, mi.Float(v))
        self.horizon_blend = mi.Bool(bool(sky.horizon_blend))
        self.envmap = mi.TensorXf(envmap_table(sky.envmap))
        self._build_sampling(sky)

    # ---- parameters -------------------------------------------------------
    def _build_sampling(self, sky):
        """Rebuild the sampling table from the NumPy twin of the current parameters.

        Only derived data are replaced, all opaque, and no other Python state changes with the
        sky (``dr.freeze`` compares such state by value and would record again for every sky).
        """
        self.sun_chord2 = opaque_value(mi.Float, sky.sun_chord2)
        # a float, not a Bool: a 1-byte field would shift the others' alignment and the
        # kernel's hash from frame to frame
        self.blend_weight = opaque_value(mi.Float, float(sky.horizon_blend))
        # the map as a flat array of RGB triples with its size opaque: any map, one kernel
        self.envmap_data = self.envmap.array
        self.has_map = sky.envmap is not None
        self.envmap_rows = opaque_value(mi.Float, float(self.envmap.shape[0]))
        self.envmap_cols = opaque_value(mi.Float, float(self.envmap.shape[1]))
        for k in ("sun_direction", "sun_solid_angle", "blend_weight", "sun_chord2",
                  "scene_radius") + _RGB_KEYS + _FLOAT_KEYS:
            dr.make_opaque(getattr(self, k))
        # each cell's mean luminance, by the emitter's own sky_eval (one kernel, much faster
        # than the NumPy twin)
        rgb = self.sky_eval(_table_directions_jit())
        lum = sum(w * rgb[c] for c, w in enumerate(SRGB_LUMINANCE.tolist()))
        cell = np.maximum(np.array(dr.block_sum(lum, TABLE_SUPERSAMPLE ** 2), dtype=float)
                          / TABLE_SUPERSAMPLE ** 2, 0.0)
        sky_power = cell.mean() * 4 * np.pi                      # integral of luminance over the sphere
        pmf = cell / cell.sum() if cell.sum() > 0 else np.full(cell.size, 1.0 / cell.size)
        pmf = (1 - UNIFORM_FLOOR) * pmf + UNIFORM_FLOOR / pmf.size
        cdf = np.cumsum(pmf)
        cdf /= cdf[-1]
        sun_power = float(sky.sun_radiance @ SRGB_LUMINANCE) * sky.sun_solid_angle
        total = sun_power + sky_power
        p_sun = sun_power / total if total > 0 else 0.0
        self.pmf = jit_array(mi.Float, pmf)
        self.cdf = jit_array(mi.Float, cdf)
        self.p_sun = opaque_value(mi.Float, p_sun)

    def traverse(self, cb):
        flag = mi.ParamFlags.NonDifferentiable
        cb.put("sun_direction", self.sun_direction, flag)
        cb.put("sun_solid_angle", self.sun_solid_angle, flag)
        for k in _RGB_KEYS + _FLOAT_KEYS:
            cb.put(k, getattr(self, k), flag)
        cb.put("horizon_blend", self.horizon_blend, flag)
        cb.put("envmap", self.envmap, flag)
        cb.put("scene_radius", self.scene_radius, flag)

    def parameters_changed(self, keys=[]):
        self._build_sampling(_sky(lambda k, _: np.array(getattr(self, k), dtype=float).ravel(),
                                  self.envmap))

    # ---- evaluation -------------------------------------------------------
    def sky_eval(self, d):
        """Sky radiance (no sun) toward world directions d [W m^-2 sr^-1]: the light cache's
        control variate (:mod:`..sky_control`)."""
        sky = sky_function(self, d)
        # a sky without a map skips the lookup (costly in the sky integrals): one kernel each
        return sky + self.envmap_eval(d) if self.has_map else sky

    def envmap_eval(self, d):
        """The map's radiance toward world directions d: Sky.envmap's bilinear lookup
        (:func:`~skyfit_mi.physics.latlong.latlong_texel`) [W m^-2 sr^-1]."""
        rows, cols = self.envmap_rows, self.envmap_cols
        i0, i1, fy, j0, j1, fx = latlong_texel(dr.acos(dr.clip(d.z, -1.0, 1.0)),
                                               dr.atan2(d.x, d.y), rows, cols, dr.floor, dr.clip)
        n = mi.UInt32(cols)
        r0, r1, c0, c1 = mi.UInt32(i0) * n, mi.UInt32(i1) * n, mi.UInt32(j0), mi.UInt32(j1)

        def texel(r, c):
            return dr.gather(mi.Color3f, self.envmap_data, r + c)
        return (1.0 - fy) * ((1.0 - fx) * texel(r0, c0) + fx * texel(r0, c1)) \
            + fy * ((1.0 - fx) * texel(r1, c0) + fx * texel(r1, c1))

    def _in_sun(self, d):
        # |d - s|^2 <= 2 (1 - cos alpha): exact for unit vectors and, unlike d.s >= cos alpha,
        # precise in single precision for a disc of 0.25 degree radius
        return dr.squared_norm(d - self.sun_direction) <= self.sun_chord2

    def _radiance(self, d):
        in_sun = self._in_sun(d)
        return self.sky_eval(d) + dr.select(in_sun, self.sun_radiance, 0.0)

    def pdf_sun(self, d):
        """Density [sr^-1] of :meth:`sample_sun` (uniform over the solar disc)."""
        return dr.select(self._in_sun(d), dr.rcp(dr.pi * self.sun_chord2), 0.0)

    def pdf_sky(self, d):
        """Density [sr^-1] of :meth:`sample_sky` (the piecewise-constant table)."""
        u = dr.atan2(d.y, d.x) * dr.inv_two_pi
        u = dr.select(u < 0.0, u + 1.0, u)
        v = (1.0 - d.z) * 0.5
        iu = dr.minimum(mi.UInt32(u * TABLE_NU), TABLE_NU - 1)
        iv = dr.minimum(mi.UInt32(dr.maximum(v, 0.0) * TABLE_NV), TABLE_NV - 1)
        pmf = dr.gather(mi.Float, self.pmf, iv * TABLE_NU + iu)
        return pmf * (TABLE_NU * TABLE_NV) / (4.0 * dr.pi)

    def sample_sun(self, sample):
        """World direction uniform over the solar disc, from a 2D sample."""
        one_minus_cos = sample.x * 0.5 * self.sun_chord2           # uniform in cos theta
        cos_t = 1.0 - one_minus_cos
        sin_t = dr.safe_sqrt(one_minus_cos * (2.0 - one_minus_cos))
        sp, cp = dr.sincos(2.0 * dr.pi * sample.y)
        return mi.Frame3f(self.sun_direction).to_world(mi.Vector3f(sin_t * cp, sin_t * sp, cos_t))

    def sample_sky(self, sample):
        """World direction from the sky table (cell by inverse CDF, then uniform in the cell)."""
        n = TABLE_NU * TABLE_NV
        idx = dr.binary_search(0, n - 1, lambda i: dr.gather(mi.Float, self.cdf, i) <= sample.x)
        c1 = dr.gather(mi.Float, self.cdf, idx)
        p = dr.gather(mi.Float, self.pmf, idx)
        t = dr.clip((sample.x - (c1 - p)) / dr.maximum(p, 1e-12), 0.0, 0.99999)
        u = (mi.Float(idx % TABLE_NU) + t) / TABLE_NU
        v = (mi.Float(idx // TABLE_NU) + sample.y) / TABLE_NV
        z = 1.0 - 2.0 * v
        r = dr.safe_sqrt(1.0 - z * z)
        su, cu = dr.sincos(2.0 * dr.pi * u)
        return mi.Vector3f(r * cu, r * su, z)

    def _pdf(self, d):
        return self.p_sun * self.pdf_sun(d) + (1.0 - self.p_sun) * self.pdf_sky(d)

    def eval(self, si, active=True):
        return dr.select(active, self._radiance(-si.wi), 0.0)

    def eval_direction(self, it, ds, active=True):
        return dr.select(active, self._radiance(ds.d), 0.0)

    def pdf_direction(self, it, ds, active=True):
        return dr.select(active, self._pdf(ds.d), 0.0)

    def sample_direction(self, it, sample, active=True):
        # one 2D sample picks the sun (x < p_sun) or the sky and is reused within the choice
        pick_sun = sample.x < self.p_sun
        x_sun = sample.x / dr.maximum(self.p_sun, 1e-12)
        x_sky = dr.clip((sample.x - self.p_sun) / dr.maximum(1.0 - self.p_sun, 1e-12), 0.0, 1.0)
        d = dr.select(pick_sun, self.sample_sun(mi.Point2f(x_sun, sample.y)),
                      self.sample_sky(mi.Point2f(x_sky, sample.y)))

        radius = dr.maximum(self.scene_radius, dr.norm(it.p))
        dist = 2.0 * radius
        ds = dr.zeros(mi.DirectionSample3f)
        ds.p = it.p + d * dist
        ds.n = -d
        ds.time = it.time
        ds.pdf = self._pdf(d)
        ds.delta = mi.Bool(False)
        ds.emitter = mi.EmitterPtr(self)
        ds.d = d
        ds.dist = dist
        active = mi.Bool(active) & (ds.pdf > 0.0)
        weight = dr.select(active, self._radiance(d) / dr.maximum(ds.pdf, 1e-30), 0.0)
        ds.pdf = dr.select(active, ds.pdf, 0.0)
        return ds, mi.Spectrum(weight)

    def sample_ray(self, time, sample1, sample2, sample3, active=True):
        raise NotImplementedError("cie_sky supports only integrators that sample directions "
                                  "from surfaces (path, prb, direct), not light tracing.")

    def to_string(self):
        return f"CIESkyEmitter[{'with' if self.has_map else 'no'} environment map]"
