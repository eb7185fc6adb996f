"""A sky measured in a few directions as an HDR environment map: interpolated, with the sun.

From a sky scanner's luminance and colour in a few dozen directions and a pyranometer's GHI, make
a lat-long table of linear-sRGB radiance over the sky (:mod:`skyfit_mi.physics.envmap`) and the
DNI of the solar disc, so the measured sky lights frames and fits as any ``envmap`` sky.

Interpolation (luminance varies 10-50x over a clear sky, most steeply where points are sparse):

1. A CIE S 011 general sky (continuous gradation and indicatrix indices on a grid of
   :data:`GROUP_STEP`, L_z free) is fitted in log luminance to the points at least
   ``exclude_deg`` from the sun (:func:`fit_general_shape`): it carries the circumsolar peak and
   horizon brightening the points cannot resolve.
2. ln(L / L_model), ln(X / Y) and ln(Z / Y), smooth fields, are interpolated over the sphere by
   an RBF in the unit vectors (:data:`KERNEL` plus a linear polynomial): exact at the points,
   no overshoot, positive everywhere.  The linear polyharmonic spline (phi(r) = -r) does not
   ring between the scanner's rings and beat the thin-plate spline in :func:`leave_one_out`.
3. Below the lowest measured elevation the fields are held at that elevation's values, so the
   luminance follows the model's gradation toward the horizon.

Units: measured XYZ [cd m^-2] becomes linear sRGB (IEC 61966-2-1, out-of-gamut clipped at 0)
over the skylight's luminous efficacy K [lm W^-1], in the pyranometer's units:

.. math:: (R, G, B) = M_{XYZ \\to sRGB} (X, Y, Z) / K

The sun's disc takes what the pyranometer saw that the map does not hold
(:func:`direct_normal_from_global`), so the circumsolar light counts once:

.. math:: E_{bn} = \\frac{E_{gh} - E_{dh,\\,map}}{\\cos\\theta_s}

with E_dh,map the map's diffuse horizontal irradiance (eq. 4.19 by quadrature).

References
----------
J. T. Kider Jr. et al., "A Framework for the Experimental Comparison of Solar and Skydome
Illumination", ACM Transactions on Graphics 33(6), 2014 (the measured day).
ISO 15469:2004 / CIE S 011/E:2003 (the general sky).
G. E. Fasshauer, Meshfree Approximation Methods with MATLAB, World Scientific, 2007, ch. 8
(polyharmonic splines; conditionally positive definite kernels with a polynomial term).
"""

from dataclasses import dataclass

import numpy as np

from skyfit_mi.conventions import angles_from_direction, direction_from_angles, unit_directions
from skyfit_mi.errors import SkyfitError, check_range
from skyfit_mi.physics import cie_general
from skyfit_mi.physics.colour import SRGB_LUMINANCE, XYZ_TO_SRGB
from skyfit_mi.physics.envmap import MeasuredIrradiance, direct_normal_from_global, envmap_sky
from skyfit_mi.physics.latlong import resample

#: RBF kernel of the interpolated fields (scipy.interpolate.RBFInterpolator's name).
KERNEL = "linear"
#: Step of the gradation and indicatrix indices searched by :func:`fit_general_shape` [unitless].
GROUP_STEP = 0.05
#: Points closer than this to the sun are left out of the model's fit [degrees] (the
#: circumsolar peak is undersampled).
EXCLUDE_DEG = 10.0
#: Rows of the lat-long table by default (1.4 degree cells; columns twice as many): reproduces
#: the measured points to 0.6% rms.
ROWS = 128
#: Sub-samples per cell side when the table's cells are averaged (:func:`~.latlong.resample`).
SUPERSAMPLE = 2


def _grid(step):
    g = np.round(np.arange(1.0, 6.0 + 1e-9, step), 6)
    gg, ii = np.meshgrid(g, g, indexing="ij")
    return np.stack([gg.ravel(), ii.ravel()], -1)


def _log_residuals(directions, luminance, sun, step):
    """The grid of (gradation, indicatrix) indices (m, 2) and ln L - ln(L / L_z of each) (m, n)."""
    groups = _grid(step)
    model = cie_general.pattern(directions, sun, cie_general.group_parameters(*groups.T))
    return groups, np.log(luminance)[None, :] - np.log(model)


def fit_general_shape(directions, luminance, sun, exclude_deg=EXCLUDE_DEG, step=GROUP_STEP):
    """The CIE general sky that best fits measured luminance, in log luminance: (indices (2,),
    a..e (5,), L_z [cd m^-2]).

    Minimises over the indices g, i in [1, 6] (a grid of ``step``,
    :func:`~skyfit_mi.physics.cie_general.group_parameters`) and the zenith luminance L_z

    .. math:: \\sum_k \\big(\\ln L_k - \\ln L_z - \\ln P(d_k; g, i)\\big)^2

    over the points at least ``exclude_deg`` [degrees] from the sun; ln L_z is in closed form.
    ``directions`` (n, 3) are world unit vectors above the horizon, ``luminance`` (n,) > 0
    [cd m^-2], ``sun`` (3,) a unit vector.
    """
    d, y, sun = _check_points(directions, luminance, sun)
    keep = _far_from_sun(d, sun, exclude_deg)
    groups, r = _log_residuals(d, y, sun, step)
    c = r[:, keep].mean(axis=1)
    i = int(np.argmin(((r[:, keep] - c[:, None]) ** 2).mean(axis=1)))
    return groups[i], cie_general.group_parameters(*groups[i]), float(np.exp(c[i]))


def _check_points(directions, luminance, sun):
    d = unit_directions(directions)
    y = np.asarray(luminance, dtype=float)
    if d.ndim != 2 or d.shape[1] != 3 or y.shape != (len(d),) or len(d) < 5:
        raise SkyfitError(f"a measured sky needs at least 5 directions (n, 3) with one luminance "
                          f"each, got directions {np.shape(directions)} and luminance "
                          f"{np.shape(luminance)}.")
    if not (np.all(np.isfinite(y)) and np.all(y > 0)):
        raise SkyfitError("every measured luminance must be a positive number [cd m^-2] (the "
                          "sky is interpolated in log luminance); leave out the points that "
                          "are not.")
    if np.any(d[:, 2] <= 0):
        raise SkyfitError("a measured sky's directions must lie above the horizon (z > 0).")
    s = unit_directions(sun)
    return d, y, s


def _far_from_sun(d, sun, exclude_deg):
    keep = d @ sun <= np.cos(np.radians(exclude_deg))
    if keep.sum() < 3:
        raise SkyfitError(f"fewer than 3 measured points lie {exclude_deg:g} degrees or more "
                          "from the sun; measure more of the sky, or lower exclude_deg.")
    return keep


@dataclass(frozen=True)
class MeasuredSky:
    """A sky's luminance and colour interpolated from measurements (module docstring).

    Attributes
    ----------
    sun : ndarray (3,)
        Unit vector toward the sun, world frame.
    groups, params, zenith_luminance
        The fitted CIE general sky's indices (2,), a..e (5,) and L_z [cd m^-2].
    fields : scipy.interpolate.RBFInterpolator
        Unit vectors (..., 3) -> ln(L / L_model), ln(X / Y), ln(Z / Y) [unitless].
    min_elevation : float
        Lowest measured elevation [rad]; below it the fields are held.
    """

    sun: np.ndarray
    groups: np.ndarray
    params: np.ndarray
    zenith_luminance: float
    fields: object
    min_elevation: float

    def model_luminance(self, directions):
        """The fitted CIE general sky's luminance toward ``directions`` (..., 3) [cd m^-2]."""
        d = unit_directions(directions)
        flat = d.reshape(-1, 3)
        return (self.zenith_luminance
                * cie_general.pattern(flat, self.sun, self.params)).reshape(d.shape[:-1])

    def xyz(self, directions):
        """CIE XYZ toward world ``directions`` (..., 3) [cd m^-2]; 0 at and below the horizon."""
        d = unit_directions(directions)
        theta, phi = angles_from_direction(d)
        held = direction_from_angles(np.minimum(theta, np.pi / 2 - self.min_elevation), phi)
        f = self.fields(held.reshape(-1, 3)).reshape(d.shape[:-1] + (3,))
        up = d[..., 2] > 0
        y = np.where(up, self.model_luminance(np.where(up[..., None], d, [0.0, 0.0, 1.0]))
                     * np.exp(f[..., 0]), 0.0)
        return np.stack([y * np.exp(f[..., 1]), y, y * np.exp(f[..., 2])], -1)

    def luminance(self, directions):
        """Luminance toward world ``directions`` (..., 3) [cd m^-2]."""
        return self.xyz(directions)[..., 1]

    def radiance(self, directions, efficacy):
        """Linear-sRGB radiance toward ``directions`` (..., 3) [W m^-2 sr^-1]: XYZ in sRGB
        (negative components clipped), over the luminous ``efficacy`` [lm W^-1]."""
        return np.maximum(self.xyz(directions) @ XYZ_TO_SRGB.T, 0.0) / efficacy


def _fields(xyz, model):
    """ln(L / L_model), ln(X / Y), ln(Z / Y) at the points (n, 3)."""
    y = xyz[:, 1]
    return np.stack([np.log(y) - np.log(model), np.log(xyz[:, 0] / y),
                     np.log(xyz[:, 2] / y)], -1)


def _check_xyz(directions, xyz, sun):
    """Unit directions (n, 3), XYZ (n, 3) and the unit sun (3,), checked."""
    v = np.asarray(xyz, dtype=float)
    n = len(np.asarray(directions))
    if v.shape != (n, 3) or not (np.all(np.isfinite(v)) and np.all(v > 0)):
        raise SkyfitError(f"a measured sky needs positive CIE X, Y, Z [cd m^-2] for each of its "
                          f"{n} directions, got an array of shape {v.shape}.")
    d, _, s = _check_points(directions, v[:, 1], sun)
    return d, v, s


def interpolate_sky(directions, xyz, sun, exclude_deg=EXCLUDE_DEG, step=GROUP_STEP):
    """A :class:`MeasuredSky` through measured CIE XYZ (n, 3) [cd m^-2], > 0, at world unit
    ``directions`` (n, 3) above the horizon; ``exclude_deg`` and ``step`` as
    :func:`fit_general_shape`."""
    from scipy.interpolate import RBFInterpolator

    d, v, s = _check_xyz(directions, xyz, sun)
    groups, params, lz = fit_general_shape(d, v[:, 1], s, exclude_deg, step)
    model = lz * cie_general.pattern(d, s, params)
    fields = RBFInterpolator(d, _fields(v, model), kernel=KERNEL, degree=1)
    return MeasuredSky(s, groups, params, lz, fields, float(np.arcsin(d[:, 2].min())))


def leave_one_out(directions, xyz, sun, exclude_deg=EXCLUDE_DEG, step=GROUP_STEP):
    """Each point's luminance [cd m^-2] predicted from the others, (n,) each: the interpolated
    sky's and the fitted CIE general sky's alone (both refitted without the point)."""
    from scipy.interpolate import RBFInterpolator

    d, v, s = _check_xyz(directions, xyz, sun)
    y = v[:, 1]
    keep = _far_from_sun(d, s, exclude_deg).astype(float)
    groups, r = _log_residuals(d, y, s, step)
    # the model's fit without point j, for every j at once: sums over the kept points less j's
    s0 = keep.sum() - keep
    s1 = (r * keep).sum(axis=1)[:, None] - r * keep
    s2 = (r ** 2 * keep).sum(axis=1)[:, None] - r ** 2 * keep
    best = np.argmin(s2 / s0 - (s1 / s0) ** 2, axis=0)                  # (n,)
    interpolated, model = np.empty(len(d)), np.empty(len(d))
    for j in range(len(d)):
        others = np.arange(len(d)) != j
        params = cie_general.group_parameters(*groups[best[j]])
        lz = np.exp(s1[best[j], j] / s0[j])
        m = lz * cie_general.pattern(d, s, params)
        f = RBFInterpolator(d[others], _fields(v[others], m[others]),
                            kernel=KERNEL, degree=1)
        held = MeasuredSky(s, groups[best[j]], params, lz, f,
                           float(np.arcsin(d[others, 2].min())))
        interpolated[j] = held.luminance(d[j])
        model[j] = m[j]
    return interpolated, model


def sky_table(sky, efficacy, rows=ROWS, supersample=SUPERSAMPLE):
    """The lat-long table (rows, 2 rows, 3) of a :class:`MeasuredSky` [W m^-2 sr^-1], float32
    linear sRGB, each cell the mean of ``supersample`` squared points; the lower half is 0 (a
    ground term lights it).  ``efficacy`` [lm W^-1]: the skylight's, in the band of the
    irradiance the sun is set from."""
    check_range("luminous efficacy", efficacy, 1.0, 683.0, "lm W^-1")
    check_range("envmap rows", rows, 2, 4096)
    return resample(lambda theta, phi: sky.radiance(direction_from_angles(theta, phi), efficacy),
                    int(rows), 0.0, int(supersample))


def measured_envmap(sky, efficacy, ghi, sun_zenith_deg, sun_azimuth_deg, *,
                    ghi_sun_zenith_deg=None, rows=ROWS, ground_albedo=0.0, info=None):
    """The :class:`~skyfit_mi.physics.sky.Sky` of a measured sky: its table
    (:func:`sky_table`) and a solar disc of :func:`direct_normal_from_global`.

    Parameters
    ----------
    sky : MeasuredSky
    efficacy : float
        Luminous efficacy of the skylight [lm W^-1].
    ghi : float
        Measured global horizontal irradiance [W m^-2].
    sun_zenith_deg, sun_azimuth_deg, ghi_sun_zenith_deg : float
        The sun at the measurement, and its zenith when the GHI was read if later [degrees].
    ground_albedo, info
        As :func:`~skyfit_mi.physics.envmap.envmap_sky`'s; ``info`` also gets
        ``direct_normal_W_m2``, ``map_diffuse_horizontal_W_m2``, ``efficacy_lm_W``,
        ``cie_groups`` and ``zenith_luminance_cd_m2``.
    """
    table = sky_table(sky, efficacy, rows)
    dhi = float(envmap_sky(table, sun_zenith_deg, sun_azimuth_deg).sky_horizontal_irradiance()
                @ SRGB_LUMINANCE)
    dni = direct_normal_from_global(ghi, dhi, sun_zenith_deg if ghi_sun_zenith_deg is None
                                    else ghi_sun_zenith_deg)
    info = {"kind": "envmap", "source": "measured", **(info or {}),
            "map_diffuse_horizontal_W_m2": dhi, "global_horizontal_W_m2": float(ghi),
            "efficacy_lm_W": float(efficacy), "cie_groups": sky.groups.tolist(),
            "zenith_luminance_cd_m2": sky.zenith_luminance}
    return envmap_sky(table, sun_zenith_deg, sun_azimuth_deg,
                      measured=MeasuredIrradiance(direct_normal=dni),
                      ground_albedo=ground_albedo, info=info)


def scan_envmap(scan, rows=ROWS, rotated=True, ground_albedo=0.0):
    """The envmap :class:`~skyfit_mi.physics.sky.Sky` of one scan of the measured clear day
    (:class:`~skyfit_testkit.sky_measurement.Scan`, Kider et al. 2014).

    The 81 points (turned by the README's scanner rotation if ``rotated``, so the measured
    circumsolar light surrounds the computed sun) are interpolated; the efficacy is the scan's
    own diffuse illuminance over its 350-2500 nm irradiance; the disc carries the pyranometer's
    GHI less the map's diffuse irradiance, with the sun at the GHI's minute.
    """
    from .sky_measurement import CITATION

    sky = interpolate_sky(scan.directions(rotated), scan.xyz, scan.sun_direction)
    return measured_envmap(sky, scan.diffuse_illuminance_scan / scan.dhi_scan, scan.ghi,
                           scan.sun_zenith_deg, scan.sun_azimuth_deg,
                           ghi_sun_zenith_deg=scan.ghi_sun_zenith_deg, rows=rows,
                           ground_albedo=ground_albedo,
                           info={"capture": scan.capture, "rotated": bool(rotated),
                                 "data": CITATION})
