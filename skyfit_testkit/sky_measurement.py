"""Sky models against a measured sky: the Kider et al. (2014) scans of a clear day.

The data (``../shared/data/sky-measurements-2014-05-27/`` beside the repository, or
``$SKYFIT_SKY_DATA``) are 15 scans of spectral sky radiance in 81 directions over Ithaca NY on
2013-05-27, 09:30-13:30 EDT (UTC-4), with a pyranometer's GHI.  Per the README, azimuths are
compass (from north toward east), elevations above the horizon [degrees], and luminance is
683 lm/W times the ybar-weighted spectral radiance [cd m^-2].

A model matches a scan by the rms relative residual (:func:`relative_rms`) of its pattern
with one free scale per scan, fitted in log luminance (:func:`scale_factor`); points within
:data:`SUN_EXCLUSION_DEG` of the sun are left out (the grid undersamples the circumsolar
peak); optionally the scanner frame is turned by the README's fitted rotation
(:data:`SCANNER_ROTATION_DEG`).  The sun is NREL SPA at the scan's label (start) time.

Data: J. T. Kider Jr., D. Knowlton, J. Newlin, Y. K. Li, D. P. Greenberg, "A Framework for
the Experimental Comparison of Solar and Skydome Illumination", ACM Transactions on Graphics
33(6), 2014; <https://github.com/spectralskylight/sky-measurements-2014>, Apache License 2.0.
"""

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skyfit_mi.conventions import direction_from_angles, unit_directions
from skyfit_mi.errors import SkyfitError, check_choice
from skyfit_mi.physics import cie_general, turbid_sky
from skyfit_mi.physics.colour import SRGB_LUMINANCE
from skyfit_mi.physics.perez import CLEARNESS_BIN_EDGES, PerezOptions, coefficients, perez_sky
from skyfit_mi.physics.sky import EFFICACY_CLEAR, cie_sky, perez_pattern
from skyfit_mi.physics.sun import solar_position

#: Environment variable naming the data folder, overriding :data:`DEFAULT_DATA_DIR`.
DATA_ENV = "SKYFIT_SKY_DATA"
#: The data's place relative to the repository: ``../shared/data/...`` beside its root.
DEFAULT_DATA_DIR = (Path(__file__).resolve().parents[1].parent / "shared" / "data"
                    / "sky-measurements-2014-05-27")
#: Citation and license of the data, for every output that shows results from it.
CITATION = ("Kider et al. 2014, 'A Framework for the Experimental Comparison of Solar and "
            "Skydome Illumination', ACM TOG 33(6); data "
            "github.com/spectralskylight/sky-measurements-2014, Apache-2.0")
#: Roof of Rhodes Hall, Cornell University, Ithaca NY (the data's README) [degrees].
SITE_LATITUDE_DEG = 42.443449
SITE_LONGITUDE_DEG = -76.481962
#: Rotation vector about (east, north, up) [degrees] the README fits to all scans: true
#: direction = R(rotation) nominal (azimuth about +11.5 degrees, ~1.5 degree tilt).
SCANNER_ROTATION_DEG = (1.473, -0.45, -11.521)
#: Points closer than this to the sun are left out of every comparison [degrees].
SUN_EXCLUSION_DEG = 10.0
_RADIANCE_COLUMNS = ["capture", "time_local", "point_index", "azimuth_deg", "elevation_deg",
                     "luminance_cd_m2", "X", "Y", "Z"]
_DHI_COLUMN = "diffuse_horizontal_irradiance_350_2500nm_W_m2_est"
_ILLUMINANCE_COLUMN = "diffuse_horizontal_illuminance_lx_est"


def data_dir(folder=None):
    """The data folder: ``folder``, else ``$SKYFIT_SKY_DATA``, else :data:`DEFAULT_DATA_DIR`;
    SkyfitError if it has no ``sky_radiance.csv``."""
    path = Path(folder or os.environ.get(DATA_ENV) or DEFAULT_DATA_DIR)
    if not (path / "sky_radiance.csv").is_file():
        raise SkyfitError(f"no sky_radiance.csv in {path}: put the Kider et al. 2014 data "
                          f"there (../shared/data/ beside the repository) or set {DATA_ENV} "
                          "to its folder.")
    return path


def rotation_matrix(rotvec_deg):
    """Rotation matrix (3, 3), acting on column vectors, of a rotation vector [degrees]
    (right-handed, as scipy's ``Rotation.from_rotvec``), by Rodrigues' formula:

    .. math:: R = I + \\sin\\theta\\, K + (1 - \\cos\\theta) K^2

    with theta = |rotvec| [rad] and K the cross-product matrix of the unit axis.
    """
    v = np.radians(np.asarray(rotvec_deg, dtype=float))
    theta = np.linalg.norm(v)
    if theta == 0.0:
        return np.eye(3)
    x, y, z = v / theta
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + np.sin(theta) * k + (1.0 - np.cos(theta)) * (k @ k)


@dataclass(frozen=True)
class Scan:
    """One scan of the sky (81 points) with its sun and pyranometer reading.

    Attributes
    ----------
    capture : str
        The archive's name, e.g. ``2013-05-27___09.30.00``.
    time : pandas.Timestamp
        Scan start (its label), EDT.
    azimuth_deg, elevation_deg : ndarray (81,)
        Nominal directions of the points [degrees].
    luminance, xyz : ndarray (81,); ndarray (81, 3) or None
        Measured luminance and CIE 1931 X, Y, Z [cd m^-2].
    sun_zenith_deg, sun_azimuth_deg : float
        Apparent sun position at ``time`` (NREL SPA) [degrees].
    ghi : float
        Pyranometer GHI, mean over the first minute of the scan's log [W m^-2].
    ghi_time, ghi_sun_zenith_deg
        Middle of that minute (13:00:30 for the 13:30 scan), and the sun zenith then [degrees].
    dhi_scan, diffuse_illuminance_scan : float
        The data's sky-only DHI (350-2500 nm) [W m^-2] and illuminance [lx] from the scan.
    note : str
        The data's note on the scan ("" if none).
    """

    capture: str
    time: object
    azimuth_deg: np.ndarray
    elevation_deg: np.ndarray
    luminance: np.ndarray
    sun_zenith_deg: float
    sun_azimuth_deg: float
    ghi: float
    ghi_time: object
    ghi_sun_zenith_deg: float
    dhi_scan: float
    diffuse_illuminance_scan: float
    note: str = ""
    xyz: np.ndarray = None

    @property
    def label(self):
        """The scan's local clock time, e.g. ``09:30``."""
        return self.time.strftime("%H:%M")

    @property
    def day_of_year(self):
        """Day of the year of the local date (147 for 2013-05-27)."""
        return int(self.time.day_of_year)

    @property
    def sun_direction(self):
        """Unit vector toward the sun, world frame."""
        return direction_from_angles(np.radians(self.sun_zenith_deg),
                                     np.radians(self.sun_azimuth_deg))

    def directions(self, rotated=False):
        """World unit vectors (81, 3) of the points, turned by :data:`SCANNER_ROTATION_DEG`
        if ``rotated``."""
        d = direction_from_angles(np.radians(90.0 - self.elevation_deg),
                                  np.radians(self.azimuth_deg))
        return d @ rotation_matrix(SCANNER_ROTATION_DEG).T if rotated else d


def load_scans(folder=None):
    """The 15 scans of the data (:func:`data_dir`), in time order, as :class:`Scan` s, from
    ``sky_radiance.csv``, ``captures.csv`` and ``irradiance.csv``."""
    import pandas as pd

    path = data_dir(folder)
    rad = pd.read_csv(path / "sky_radiance.csv", usecols=_RADIANCE_COLUMNS)
    caps = pd.read_csv(path / "captures.csv", keep_default_na=False).set_index("capture")
    irr = pd.read_csv(path / "irradiance.csv")
    irr["capture"] = irr["radiance_archive"].str.removesuffix(".7z")
    irr = irr.set_index("capture")
    groups = [(name, g.sort_values("point_index")) for name, g in rad.groupby("capture")]
    if any(len(g) != 81 for _, g in groups) or set(caps.index) != {n for n, _ in groups}:
        raise SkyfitError(f"{path} does not hold 81 points for each scan of captures.csv; "
                          "restore the data files as published (see their README).")
    times = [pd.Timestamp(g["time_local"].iloc[0]) for _, g in groups]
    ghi_times = [pd.Timestamp(irr.loc[n, "window_start_local"]) + pd.Timedelta(seconds=30)
                 for n, _ in groups]
    sun = solar_position(times, SITE_LATITUDE_DEG, SITE_LONGITUDE_DEG)
    sun_ghi = solar_position(ghi_times, SITE_LATITUDE_DEG, SITE_LONGITUDE_DEG)
    return [Scan(capture=name, time=t,
                 azimuth_deg=g["azimuth_deg"].to_numpy(float),
                 elevation_deg=g["elevation_deg"].to_numpy(float),
                 luminance=g["luminance_cd_m2"].to_numpy(float),
                 sun_zenith_deg=float(sun.zenith_deg[i]),
                 sun_azimuth_deg=float(sun.azimuth_deg[i]),
                 ghi=float(irr.loc[name, "ghi_mean_W_m2"]), ghi_time=ghi_times[i],
                 ghi_sun_zenith_deg=float(sun_ghi.zenith_deg[i]),
                 dhi_scan=float(caps.loc[name, _DHI_COLUMN]),
                 diffuse_illuminance_scan=float(caps.loc[name, _ILLUMINANCE_COLUMN]),
                 note=str(caps.loc[name, "note"]),
                 xyz=g[["X", "Y", "Z"]].to_numpy(float))
            for i, ((name, g), t) in enumerate(zip(groups, times))]


# ---- The figure of merit ----

def angle_to_sun_deg(directions, sun):
    """Angle zeta between world ``directions`` (..., 3) and the unit vector ``sun`` (3,)
    (thesis eq. 4.14) [degrees]."""
    return np.degrees(np.arccos(np.clip(unit_directions(directions) @ sun, -1.0, 1.0)))


def _positive(model, measured):
    m, y = np.asarray(model, dtype=float), np.asarray(measured, dtype=float)
    if not (np.all(m > 0) and np.all(y > 0)):
        raise SkyfitError("the model and the measured luminance must be positive at every "
                          "compared point (the scale is fitted in log luminance); leave out "
                          "points where the model is 0.")
    return m, y


def scale_factor(model, measured):
    """The scale k [cd m^-2 per model unit], shape (...), that best fits ``model`` M (..., n)
    (one fit per row, M_i > 0) to ``measured`` L (n,) [cd m^-2] in log luminance:

    .. math:: k = \\exp\\Big(\\frac{1}{n}\\sum_i \\ln\\frac{L_i}{M_i}\\Big)

    the least-squares solution of ln L_i = ln k + ln M_i (the geometric mean of the ratios).
    """
    m, y = _positive(model, measured)
    return np.exp(np.mean(np.log(y) - np.log(m), axis=-1))


def relative_rms(model, measured):
    """Relative rms error [unitless], shape (...), of a model pattern ``model`` (..., n) against
    ``measured`` (n,) with its scale free (inputs as :func:`scale_factor`):

    .. math:: \\epsilon = \\sqrt{\\frac{1}{n}\\sum_i \\Big(\\frac{k M_i - L_i}{L_i}\\Big)^2}

    with k from :func:`scale_factor`.  This definition, rather than rms residual over rms
    luminance or k fitted in linear luminance, reproduces the published figures
    (``docs/BENCHMARKS.md``, "Sky models against a measured clear sky").
    """
    m, y = _positive(model, measured)
    k = scale_factor(m, y)[..., None]
    return np.sqrt(np.mean(((k * m - y) / y) ** 2, axis=-1))


# ---- The skies compared ----

@dataclass(frozen=True)
class SkyModel:
    """A sky model for :func:`compare`: a luminance pattern, maybe with a fitted parameter.

    Attributes
    ----------
    name, description : str
        Short name (a table column) and one line for tables.
    luminance : callable
        ``luminance(directions (n, 3), scan, parameters (k,))`` -> (k, n) [cd m^-2 if
        ``absolute``, else any unit].
    parameters : tuple
        Values tried; the best (lowest :func:`relative_rms`) is kept.  ``(None,)`` if none.
    parameter_name : str
        Name of the fitted parameter ("" if none).
    absolute : bool
        The luminance is in cd m^-2, so the scale k is the measured level over the model's.
    held_out : bool
        Also score the model as a prediction (:func:`compare_held_out`).
    """

    name: str
    luminance: object
    parameters: tuple = (None,)
    parameter_name: str = ""
    absolute: bool = False
    description: str = ""
    held_out: bool = False


def thesis_clear_luminance(directions, scan, parameters):
    """The thesis's CIE clear sky (eqs. 4.10-4.15) at 150 lm/W [cd m^-2], shape (1, n)."""
    sky = cie_sky("clear", scan.sun_zenith_deg, scan.sun_azimuth_deg, day=scan.day_of_year)
    return (sky.sky_radiance(directions) @ SRGB_LUMINANCE * EFFICACY_CLEAR)[None, :]


def perez_inputs(scan, source):
    """Irradiance for the Perez sky of ``scan`` as keywords of :func:`perez_sky`.

    ``source`` is ``'erbs'`` (the pyranometer GHI split by Erbs et al. 1982) or ``'scan'``
    (DHI from the scan, DNI = (GHI - DHI) / cos Z, Z the sun at the scan).  The 13:30 scan's
    GHI is from 13:00, the nearest pyranometer samples.
    """
    check_choice("Perez irradiance source", source, ("erbs", "scan"))
    if source == "erbs":
        return {"ghi": scan.ghi, "options": PerezOptions(decomposition="erbs")}
    cos_z = np.cos(np.radians(scan.sun_zenith_deg))
    return {"dhi": scan.dhi_scan, "dni": (scan.ghi - scan.dhi_scan) / cos_z}


def perez_luminance(source):
    """Luminance function [cd m^-2] of the Perez (1993) sky driven by the irradiance
    ``source`` (:func:`perez_inputs`), at the scan's sun, for :class:`SkyModel`."""
    def luminance(directions, scan, parameters):
        sky = perez_sky(scan.sun_zenith_deg, scan.sun_azimuth_deg, scan.day_of_year,
                        **perez_inputs(scan, source))
        return sky.luminance(directions)[None, :]
    return luminance


def perez_shape_luminance(directions, scan, parameters):
    """The Perez (1993) pattern l_v for (epsilon, Delta) pairs (k, 2) at the scan's sun, (k, n),
    from :func:`~skyfit_mi.physics.perez.coefficients` (no Delta floor).  Pairs with b > 0
    give NaN rows, which :func:`compare` passes over."""
    eps, delta = np.asarray(parameters, dtype=float).T
    c = coefficients(eps, delta, scan.sun_zenith_deg)                      # (k, 5)
    values = perez_pattern(np.asarray(directions, dtype=float), scan.sun_direction,
                           c[:, None, :])
    return np.where(c[:, 1:2] > 0.0, np.nan, values)


def cie_type_luminance(directions, scan, parameters):
    """CIE general sky L / L_z (:func:`skyfit_mi.physics.cie_general.pattern`) for clear-sky
    type indices t (:func:`~skyfit_mi.physics.cie_general.clear_parameters`), (k, n)."""
    params = cie_general.clear_parameters(np.asarray(parameters, dtype=float))
    return cie_general.pattern(directions, scan.sun_direction, params)


def cie_groups_luminance(directions, scan, parameters):
    """CIE general sky L / L_z for (gradation, indicatrix) index pairs (k, 2)
    (:func:`~skyfit_mi.physics.cie_general.group_parameters`), (k, n)."""
    g, i = np.asarray(parameters, dtype=float).T
    params = cie_general.group_parameters(g, i)
    return cie_general.pattern(directions, scan.sun_direction, params)


def turbid_luminance(directions, scan, parameters):
    """Preetham's turbid-sky pattern (:func:`~skyfit_mi.physics.turbid_sky.coefficients`) for
    turbidities (k,) at the scan's sun, (k, n)."""
    c = turbid_sky.coefficients(np.asarray(parameters, dtype=float))            # (k, 5)
    return perez_pattern(np.asarray(directions, dtype=float), scan.sun_direction, c[:, None, :])


def uniform_luminance(directions, scan, parameters):
    """A sky of uniform luminance, (1, n) ones."""
    return np.ones((1, len(directions)))


#: Step of the turbidity fitted per scan [unitless].
TURBIDITY_GRID_STEP = 0.05
#: Step of the continuous CIE general-sky indices fitted per scan [unitless].
INDEX_STEP = 0.01
_LO, _HI = cie_general.CLEAR_GROUPS
_GROUP_STEPS = np.round(np.arange(_LO, _HI + 1e-9, 2 * INDEX_STEP), 2)

#: Step and range of the Perez brightness Delta fitted per scan [unitless]: gendaylit's
#: [0.01, 0.6], the range of the model's data.
PEREZ_DELTA_STEP = 0.005
_PEREZ_DELTAS = np.round(np.arange(0.01, 0.6 + 1e-9, PEREZ_DELTA_STEP), 3)
#: (epsilon, Delta) pairs tried by ``perez_fit``: each clearness bin by its lower edge (the
#: pattern depends on epsilon only through its bin) with every Delta step.
PEREZ_SHAPE_GRID = tuple((float(e), float(d)) for e in CLEARNESS_BIN_EDGES[:-1]
                         for d in _PEREZ_DELTAS)

#: The NumPy skies the project offers, in table order (Mitsuba's sunsky is in
#: :mod:`skyfit_testkit.sunsky_reference`).
MODELS = (
    SkyModel("cie_clear_thesis", thesis_clear_luminance, absolute=True,
             description="thesis CIE clear sky (eqs. 4.10-4.15), Kittler zenith luminance, "
                         "150 lm/W"),
    SkyModel("cie_type", cie_type_luminance,
             parameters=tuple(float(t) for t in cie_general.CLEAR_TYPES),
             parameter_name="type",
             description="CIE S 011 general sky, best of the clear types 11-15 per scan"),
    SkyModel("cie_type_fit", cie_type_luminance,
             parameters=tuple(float(t) for t in np.round(np.arange(
                 cie_general.CLEAR_TYPES[0], cie_general.CLEAR_TYPES[-1] + 1e-9,
                 INDEX_STEP), 2)),
             parameter_name="t", held_out=True,
             description="CIE S 011 general sky, type index t in [11, 15] fitted per scan "
                         f"(step {INDEX_STEP}; a, b, c, d, e linear between types)"),
    SkyModel("cie_groups_fit", cie_groups_luminance,
             parameters=tuple((float(g), float(i)) for g in _GROUP_STEPS for i in _GROUP_STEPS),
             parameter_name="gradation, indicatrix", held_out=True,
             description="CIE S 011 general sky, gradation index (IV-VI) and indicatrix index "
                         f"(4-6) fitted per scan (step {2 * INDEX_STEP}; linear between groups)"),
    SkyModel("perez_erbs", perez_luminance("erbs"), absolute=True,
             description="Perez 1993, pyranometer GHI split by Erbs (primary)"),
    SkyModel("perez_scan", perez_luminance("scan"), absolute=True,
             description="Perez 1993, DHI from the scan, DNI = (GHI - DHI) / cos Z"),
    SkyModel("perez_fit", perez_shape_luminance, parameters=PEREZ_SHAPE_GRID,
             parameter_name="epsilon bin's lower edge, Delta", held_out=True,
             description="Perez 1993 pattern, clearness bin and brightness Delta fitted per "
                         f"scan (Delta 0.01-0.6, step {PEREZ_DELTA_STEP}; no irradiance)"),
    SkyModel("turbid_fit", turbid_luminance,
             parameters=tuple(float(t) for t in np.round(np.arange(
                 turbid_sky.TURBIDITY_RANGE[0], turbid_sky.TURBIDITY_RANGE[1] + 1e-9,
                 TURBIDITY_GRID_STEP), 2)),
             parameter_name="turbidity", held_out=True,
             description="Preetham 1999 turbid-sky pattern, turbidity fitted per scan "
                         f"(2-10, step {TURBIDITY_GRID_STEP})"),
    SkyModel("uniform", uniform_luminance, description="uniform luminance"),
)


def _errors(scan, model, rotated, exclude_deg):
    """:func:`relative_rms` and :func:`scale_factor`, each (k,), of every parameter value of
    ``model`` on ``scan`` (points >= ``exclude_deg`` from the sun), and the number of points.
    A value whose model is not positive and finite everywhere gets error inf, scale NaN."""
    d = scan.directions(rotated)
    keep = angle_to_sun_deg(d, scan.sun_direction) >= exclude_deg
    values = np.asarray(model.luminance(d[keep], scan, model.parameters), dtype=float)
    values = np.atleast_2d(values)
    valid = np.all(np.isfinite(values) & (values > 0.0), axis=-1)
    if not valid.any():
        raise SkyfitError(f"the sky model {model.name!r} is not positive at every compared "
                          f"point of the scan {scan.label} for any of its parameter values; "
                          "give values for which it is.")
    err = np.full(len(values), np.inf)
    scale = np.full(len(values), np.nan)
    err[valid] = relative_rms(values[valid], scan.luminance[keep])
    scale[valid] = scale_factor(values[valid], scan.luminance[keep])
    return err, scale, int(keep.sum())


def compare(scan, model, rotated=False, exclude_deg=SUN_EXCLUSION_DEG):
    """How well ``model`` matches ``scan`` (points >= ``exclude_deg`` [degrees] from the sun,
    directions turned if ``rotated``): a dict of ``relative_rms`` and ``scale`` (k) of the
    parameter value of least :func:`relative_rms`, that ``parameter`` (None if the model has
    none) and ``n_points`` compared."""
    err, scale, n = _errors(scan, model, rotated, exclude_deg)
    i = int(np.argmin(err))
    return {"relative_rms": float(err[i]), "scale": float(scale[i]),
            "parameter": model.parameters[i], "n_points": n}


def held_out_name(model):
    """Table name of ``model`` scored with its parameter chosen on the other scans."""
    return model.name + "_heldout"


def compare_held_out(scans, model, rotated=False, exclude_deg=SUN_EXCLUSION_DEG):
    """``model`` as a prediction: each scan scored at the parameter value of lowest mean
    :func:`relative_rms` over the other scans (leave-one-out), its scale k still free; a list
    of :func:`compare` dicts, one per scan."""
    if len(scans) < 2:
        raise SkyfitError("a held-out comparison needs at least two scans; give more.")
    runs = [_errors(s, model, rotated, exclude_deg) for s in scans]
    err = np.array([r[0] for r in runs])                  # (scans, parameters)
    out = []
    for j, (e, k, n) in enumerate(runs):
        others = np.delete(err, j, axis=0).mean(axis=0)
        i = int(np.argmin(others))
        out.append({"relative_rms": float(e[i]), "scale": float(k[i]),
                    "parameter": model.parameters[i], "n_points": n})
    return out


def irradiance_comparison(scan):
    """Measured against modelled horizontal irradiance at the pyranometer's minute.

    Models with absolute levels, at the sun of ``scan.ghi_time``: the thesis's CIE clear sky
    (sky by eq. 4.19 at 150 lm/W, sun by eq. 4.7 times cos Z; their sum against the measured
    GHI) and the Perez sky from the GHI split by Erbs (its GHI is the measured by construction).

    Returns
    -------
    dict
        Irradiance [W m^-2] and illuminance [lx]: ``ghi_measured``, ``dhi_scan``,
        ``illuminance_scan``, ``cie_sky_dhi``, ``cie_sun_horizontal``, ``cie_ghi``,
        ``cie_ghi_ratio`` (model / measured), ``cie_sky_illuminance``, ``perez_dhi``,
        ``perez_dni``, ``perez_illuminance``.
    """
    z = scan.ghi_sun_zenith_deg
    # Horizontal irradiance does not depend on the sun's azimuth: 0 stands for it.
    sky = cie_sky("clear", z, 0.0, day=scan.day_of_year)
    e_sky = float(sky.sky_horizontal_irradiance() @ SRGB_LUMINANCE)
    e_sun = float(sky.sun_horizontal_irradiance() @ SRGB_LUMINANCE)
    perez = perez_sky(z, 0.0, scan.day_of_year, ghi=scan.ghi,
                      options=PerezOptions(decomposition="erbs"))
    return {"ghi_measured": scan.ghi, "dhi_scan": scan.dhi_scan,
            "illuminance_scan": scan.diffuse_illuminance_scan,
            "cie_sky_dhi": e_sky, "cie_sun_horizontal": e_sun, "cie_ghi": e_sky + e_sun,
            "cie_ghi_ratio": (e_sky + e_sun) / scan.ghi,
            "cie_sky_illuminance": e_sky * EFFICACY_CLEAR,
            "perez_dhi": perez.info["dhi_w_m2"], "perez_dni": perez.info["dni_w_m2"],
            "perez_illuminance": perez.info["dhi_w_m2"] * perez.efficacy}


def run_comparison(scans, models=MODELS, rotations=(False, True), exclude_deg=SUN_EXCLUSION_DEG):
    """:func:`compare` for every scan, model and rotation choice, as one long table; models
    marked ``held_out`` also as predictions (:func:`compare_held_out`), right after their fit.

    Returns
    -------
    pandas.DataFrame
        One row per (rotated, model, scan): ``rotated``, ``model``, ``capture``, ``time``,
        ``relative_rms``, ``scale`` (k), ``absolute``, ``held_out``, ``parameter`` (as text),
        ``n_points``.
    """
    import pandas as pd

    rows = []
    for rotated in rotations:
        for model in models:
            runs = [(model.name, False, [compare(s, model, rotated, exclude_deg)
                                         for s in scans])]
            if model.held_out and len(model.parameters) > 1 and len(scans) > 1:
                runs.append((held_out_name(model), True,
                             compare_held_out(scans, model, rotated, exclude_deg)))
            for name, held_out, results in runs:
                for scan, r in zip(scans, results):
                    p = r["parameter"]
                    rows.append({"rotated": bool(rotated), "model": name,
                                 "capture": scan.capture, "time": scan.label,
                                 "relative_rms": r["relative_rms"], "scale": r["scale"],
                                 "absolute": model.absolute, "held_out": held_out,
                                 "parameter": "" if p is None else " ".join(
                                     f"{v:g}" for v in np.atleast_1d(p)),
                                 "n_points": r["n_points"]})
    return pd.DataFrame(rows)


def best_models(results, reference="cie_clear_thesis"):
    """Per scan and rotation choice, the best model other than ``reference`` against it.

    ``results`` is a :func:`run_comparison` table.  Returns a pandas.DataFrame with
    ``rotated``, ``time``, ``best`` (model name), ``best_rms``, ``reference_rms`` and
    ``margin`` = reference_rms - best_rms (> 0: the best beats the reference).
    """
    if reference not in set(results["model"]):
        raise SkyfitError(f"reference model {reference!r} is not in the results; give one of "
                          f"{', '.join(sorted(set(results['model'])))}.")
    ref = results[results["model"] == reference].set_index(["rotated", "time"])["relative_rms"]
    others = results[results["model"] != reference]
    best = others.loc[others.groupby(["rotated", "time"])["relative_rms"].idxmin()]
    out = best.set_index(["rotated", "time"])[["model", "relative_rms"]]
    out = out.rename(columns={"model": "best", "relative_rms": "best_rms"})
    out["reference_rms"] = ref
    out["margin"] = out["reference_rms"] - out["best_rms"]
    return out.reset_index()
