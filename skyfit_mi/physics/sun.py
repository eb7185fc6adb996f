"""The sun: position, irradiance and colour (thesis section 4.1).

Angles are in degrees at this module's boundary (``*_deg``), per ``docs/CONVENTIONS.md``:
zenith from the vertical, compass azimuth from north toward east.  Times must carry a zone.
"""

from dataclasses import dataclass
import datetime as _dt

import numpy as np

from .colour import cct_to_rgb
from ..conventions import direction_from_angles
from ..errors import SkyfitError, check_choice, check_range

#: Mean solid angle of the solar disc seen from the earth [sr] (thesis 4.1.1).
SUN_SOLID_ANGLE = 6e-5
#: Solar constant after Rapp, the thesis's default [W m^-2] (thesis 4.1.2).
SOLAR_CONSTANT = 1377.0
#: The traditional solar constant [W m^-2] (thesis 4.1.2), selectable.
SOLAR_CONSTANT_CLASSIC = 1353.0
#: Eccentricity of the earth's orbit (thesis eq. 4.5).
ECCENTRICITY = 0.01672
#: Broadband extinction coefficient of a clear atmosphere (thesis eq. 4.7).
EXTINCTION_CLEAR = 0.431


@dataclass(frozen=True)
class SunDisc:
    """The solar disc of the thesis's skies (section 4.1), of finite solid angle and eq. 4.7's
    normal irradiance; values are checked where used.

    Attributes
    ----------
    drawn : bool
        Whether the sky has the disc (False: sky light only).
    extinction, solar_constant : float
        Extinction coefficient beta of eq. 4.7 [unitless], >= 0, and S of eq. 4.5 [W m^-2]
        (Rapp's 1377; :data:`SOLAR_CONSTANT_CLASSIC` 1353).
    solid_angle : float
        The disc's solid angle [sr].
    """

    drawn: bool = True
    extinction: float = EXTINCTION_CLEAR
    solar_constant: float = SOLAR_CONSTANT
    solid_angle: float = SUN_SOLID_ANGLE


@dataclass(frozen=True)
class SolarPosition:
    """Solar zenith and compass azimuth [degrees], arrays of equal shape."""

    zenith_deg: np.ndarray
    azimuth_deg: np.ndarray

    def direction(self):
        """Unit vector(s) toward the sun in the world frame, shape (..., 3)."""
        return direction_from_angles(np.radians(self.zenith_deg), np.radians(self.azimuth_deg))


def _times(time):
    """Return a tz-aware pandas DatetimeIndex, or raise SkyfitError."""
    import pandas as pd

    if isinstance(time, (_dt.datetime, pd.Timestamp)):
        time = [time]
    try:
        idx = pd.DatetimeIndex(time)
    except (TypeError, ValueError) as exc:
        idx = _mixed_offsets(time)
        if idx is None:
            raise SkyfitError(f"cannot read {_shown(time)} as times: {exc}") from None
    if idx.tz is None:
        raise SkyfitError(
            "time has no time zone; give a time-zone-aware time, e.g. "
            "datetime(2026, 6, 21, 12, tzinfo=ZoneInfo('Europe/London')) or '2026-06-21T12:00+01:00'."
        )
    return idx


def _mixed_offsets(time):
    """Aware times of several UTC offsets (e.g. across a summer-time change) as one UTC
    DatetimeIndex; None unless every time reads as an aware instant."""
    import pandas as pd

    try:
        stamps = [pd.Timestamp(t) for t in time]
    except (TypeError, ValueError):
        return None
    if not stamps or any(t.tz is None for t in stamps):
        return None
    return pd.DatetimeIndex([t.tz_convert("UTC") for t in stamps])


def _shown(time):
    """Times as the user wrote them (ISO 8601), not as Python's repr."""
    try:
        return ", ".join(t.isoformat() if hasattr(t, "isoformat") else str(t) for t in time)
    except TypeError:
        return repr(time)


def _shape_like(time, values):
    import pandas as pd

    if isinstance(time, (_dt.datetime, pd.Timestamp)):
        return float(values[0])
    return np.asarray(values, dtype=float)


# ---- Solar position ----

def spa_solar_position(time, latitude_deg, longitude_deg, elevation=0.0, pressure=101325.0,
                       temperature=12.0, delta_t=67.0, refraction=True):
    """Solar position (:class:`SolarPosition`) by the NREL SPA algorithm via pvlib (I. Reda,
    A. Andreas, "Solar position algorithm for solar radiation applications", Solar Energy 76(5),
    577-589, 2004, doi:10.1016/j.solener.2003.12.003).

    Parameters
    ----------
    time : datetime or sequence of datetimes, time-zone aware
    latitude_deg, longitude_deg : float
        North and east positive [degrees], in [-90, 90] and [-180, 180].
    elevation : float
        Height above sea level [m].
    pressure, temperature : float
        Mean air pressure [Pa] and temperature [degrees C], for refraction.
    delta_t : float
        TT - UT1 [s].
    refraction : bool
        Apparent (refracted) zenith if True, else geometric.
    """
    from pvlib.solarposition import spa_python

    check_range("latitude", latitude_deg, -90, 90, "degrees")
    check_range("longitude", longitude_deg, -180, 180, "degrees")
    idx = _times(time)
    sp = spa_python(idx, latitude_deg, longitude_deg, altitude=elevation, pressure=pressure,
                    temperature=temperature, delta_t=delta_t)
    zen = sp["apparent_zenith" if refraction else "zenith"].to_numpy()
    return SolarPosition(_shape_like(time, zen), _shape_like(time, sp["azimuth"].to_numpy()))


def equation_of_time(day):
    """Equation of time [minutes] for day of year ``day`` (1-366), to about 0.5 minute, for the
    local solar time of thesis eq. 4.1: Spencer's Fourier series (J. W. Spencer, "Fourier
    series representation of the position of the sun", Search 2(5), 172, 1971)."""
    b = 2 * np.pi * (np.asarray(day, dtype=float) - 1) / 365.0
    return 229.18 * (0.000075 + 0.001868 * np.cos(b) - 0.032077 * np.sin(b)
                     - 0.014615 * np.cos(2 * b) - 0.040849 * np.sin(2 * b))


def thesis_declination_sine(day):
    """sin of the solar declination, thesis eq. 4.3 [unitless], for day of year ``day``
    (1 = 1 January; the thesis's D_s starts at 1 on 21 December)."""
    d_s = np.mod(np.asarray(day, dtype=float) - 355.0, 365.0) + 1.0
    return -np.cos(np.radians((d_s - 1.0) * 180.0 / 182.6)) * np.sin(np.radians(23.45))


def thesis_solar_position(time, latitude_deg, longitude_deg):
    """Solar position (:class:`SolarPosition`) by the thesis's eqs. 4.1-4.4 (after Rapp).

    Local solar time = UTC + longitude/15 h + equation of time (Spencer); hour angle
    h = (LST - 12) * 15 degrees (eq. 4.1); zenith by eq. 4.2 with eq. 4.3's declination;
    azimuth by eq. 4.4, west of the meridian in the afternoon.  No refraction; up to about a
    degree off SPA (the declination formula is approximate).
    """
    check_range("latitude", latitude_deg, -90, 90, "degrees")
    check_range("longitude", longitude_deg, -180, 180, "degrees")
    idx = _times(time)
    utc = idx.tz_convert("UTC")
    doy_utc = utc.day_of_year.to_numpy()
    hours = (utc.hour + utc.minute / 60 + utc.second / 3600).to_numpy()
    lst = hours + longitude_deg / 15.0 + equation_of_time(doy_utc) / 60.0
    h = np.radians((lst - 12.0) * 15.0)                                   # eq. 4.1
    sin_d = thesis_declination_sine(doy_utc)                              # eq. 4.3
    cos_d = np.sqrt(1 - sin_d**2)
    lat = np.radians(latitude_deg)
    cos_zen = sin_d * np.sin(lat) + cos_d * np.cos(lat) * np.cos(h)      # eq. 4.2
    zen = np.arccos(np.clip(cos_zen, -1, 1))
    with np.errstate(invalid="ignore", divide="ignore"):
        cos_az = (sin_d - np.sin(lat) * cos_zen) / (np.cos(lat) * np.sin(zen))  # eq. 4.4
    az = np.arccos(np.clip(np.nan_to_num(cos_az, nan=1.0), -1, 1))
    # Eq. 4.4 gives the angle from north in [0, pi]; afternoon suns lie west.
    az = np.where(np.sin(h) > 0, 2 * np.pi - az, az)
    return SolarPosition(_shape_like(time, np.degrees(zen)), _shape_like(time, np.degrees(az)))


#: Solar-position methods by name.
SOLAR_POSITION_METHODS = {"spa": spa_solar_position, "thesis": thesis_solar_position}


def solar_position(time, latitude_deg, longitude_deg, method="spa", **kwargs):
    """Solar zenith and azimuth [degrees] at a place and time-zone-aware time, by ``method``
    ``'spa'`` (default) or ``'thesis'`` (eqs. 4.1-4.4); ``kwargs`` go to the method."""
    check_choice("solar position method", method, tuple(SOLAR_POSITION_METHODS))
    return SOLAR_POSITION_METHODS[method](time, latitude_deg, longitude_deg, **kwargs)


# ---- Irradiance ----

def extraterrestrial_irradiance(day, solar_constant=SOLAR_CONSTANT):
    """Extraterrestrial solar irradiance N_ext [W m^-2] normal to the sun's rays, thesis eqs.
    4.5-4.6, for (Julian) day of year D_j ``day`` (1-366) and solar constant S [W m^-2]."""
    check_range("day of year", day, 1, 366)
    check_range("solar constant", solar_constant, 0, np.inf, "W m^-2")
    phi = np.radians((np.asarray(day, dtype=float) - 2.0) * 360.0 / 365.2)       # eq. 4.6
    e = ECCENTRICITY
    return solar_constant * (1 + e * np.cos(phi)) ** 2 / (1 - e**2)             # eq. 4.5


def direct_normal_irradiance(zenith_deg, day, extinction=EXTINCTION_CLEAR,
                             solar_constant=SOLAR_CONSTANT):
    """Direct solar irradiance N [W m^-2] normal to the sun, thesis eq. 4.7:
    N = N_ext exp(-beta sec(theta_h)); zero for the sun on or below the horizon.

    ``zenith_deg`` [degrees], ``day`` of year (1-366), ``extinction`` beta >= 0 [unitless]
    (0.431: clear), ``solar_constant`` [W m^-2].
    """
    check_range("extinction coefficient", extinction, 0, np.inf)
    z = np.radians(np.asarray(zenith_deg, dtype=float))
    up = np.cos(z) > 0
    airmass = np.where(up, 1.0 / np.where(up, np.cos(z), 1.0), np.inf)
    n = extraterrestrial_irradiance(day, solar_constant) * np.exp(-extinction * airmass)
    return np.where(up, n, 0.0)


def cos_incidence(sun_zenith_deg, sun_azimuth_deg, tilt_deg, plane_azimuth_deg):
    """Cosine of the sun's angle to a tilted plane's normal, thesis eq. 4.8, not clamped;
    ``tilt_deg`` is the normal's zenith (0: horizontal), ``plane_azimuth_deg`` its azimuth."""
    zs, as_, zn, an = (np.radians(np.asarray(a, dtype=float))
                       for a in (sun_zenith_deg, sun_azimuth_deg, tilt_deg, plane_azimuth_deg))
    return np.cos(zn) * np.cos(zs) + np.sin(zn) * np.sin(zs) * np.cos(as_ - an)


def tilted_direct_irradiance(normal_irradiance, sun_zenith_deg, sun_azimuth_deg, tilt_deg,
                             plane_azimuth_deg):
    """Direct solar irradiance on a tilted plane, thesis eq. 4.9 [W m^-2]: D_T = N cos(theta_T),
    zero when the sun is behind the plane."""
    c = cos_incidence(sun_zenith_deg, sun_azimuth_deg, tilt_deg, plane_azimuth_deg)
    return np.asarray(normal_irradiance, dtype=float) * np.maximum(c, 0.0)


# ---- Colour ----

def sun_cct(zenith_deg):
    """Correlated colour temperature of terrestrial sunlight [K] (thesis 4.1.3: about 4000 K
    low, 5500 K high): this project's 4000 + 1500 sin(altitude), clamped."""
    alt = np.radians(90.0 - np.asarray(zenith_deg, dtype=float))
    return 4000.0 + 1500.0 * np.clip(np.sin(alt), 0.0, 1.0)


def sun_rgb(zenith_deg):
    """Linear-sRGB colour of sunlight with luminance Y = 1, shape (..., 3)."""
    return cct_to_rgb(sun_cct(zenith_deg))
