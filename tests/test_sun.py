"""Sun physics against published and hand-derived values (thesis 4.1)."""
from datetime import datetime, timedelta, timezone
from zoneinfo import ZoneInfo

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skyfit_mi.physics import sun
from skyfit_mi.errors import SkyfitError


def test_spa_worked_example():
    # Reda & Andreas 2004, table A5.1: Golden, Colorado, 2003-10-17 12:30:30 MST (UTC-7),
    # delta_t 67 s, 1830.14 m, 820 mbar, 11 C -> topocentric zenith 50.11162, azimuth 194.34024.
    t = datetime(2003, 10, 17, 12, 30, 30, tzinfo=timezone(timedelta(hours=-7)))
    p = sun.solar_position(t, 39.742476, -105.1786, elevation=1830.14, pressure=82000.0,
                           temperature=11.0, delta_t=67.0)
    assert p.zenith_deg == pytest.approx(50.11162, abs=1e-4)
    assert p.azimuth_deg == pytest.approx(194.34024, abs=1e-4)


def test_thesis_position_agrees_with_spa_within_a_degree():
    tz = ZoneInfo("Europe/London")
    times = [datetime(2026, m, 21, h, tzinfo=tz) for m in (3, 6, 12) for h in (9, 12, 15)]
    spa = sun.solar_position(times, 53.0, -1.0, refraction=False)
    th = sun.solar_position(times, 53.0, -1.0, method="thesis")
    up = spa.zenith_deg < 85
    assert np.max(np.abs(spa.zenith_deg - th.zenith_deg)[up]) < 1.0
    assert np.max(np.abs(spa.azimuth_deg - th.azimuth_deg)[up]) < 1.5


def test_direction_follows_frame():
    # a sun due east on the horizon points along +X; due south, 45 degrees up, -Y/+Z
    d = sun.SolarPosition(np.array([90.0, 45.0]), np.array([90.0, 180.0])).direction()
    np.testing.assert_allclose(d[0], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(d[1], [0, -np.sqrt(0.5), np.sqrt(0.5)], atol=1e-12)


def test_extraterrestrial_irradiance_across_the_year():
    e = sun.ECCENTRICITY
    # eq. 4.6: phi = 0 on D_j = 2 (perihelion) and 180 degrees on D_j = 184.6 (aphelion)
    assert sun.extraterrestrial_irradiance(2) == pytest.approx(1377 * (1 + e) ** 2 / (1 - e**2))
    assert sun.extraterrestrial_irradiance(184.6) == pytest.approx(1377 * (1 - e) ** 2 / (1 - e**2))
    year = sun.extraterrestrial_irradiance(np.arange(1, 366))
    assert year.max() == pytest.approx(1423.8, abs=0.1) and year.min() == pytest.approx(1331.8, abs=0.1)
    # "about 7 per cent higher in January than July" (thesis 4.1.1)
    assert year[20] / year[201] == pytest.approx(1.066, abs=0.003)
    assert sun.extraterrestrial_irradiance(2, sun.SOLAR_CONSTANT_CLASSIC) == pytest.approx(
        1353 * (1 + e) ** 2 / (1 - e**2))


def test_direct_normal_and_tilted_irradiance():
    n_ext = sun.extraterrestrial_irradiance(172)
    assert sun.direct_normal_irradiance(60.0, 172) == pytest.approx(n_ext * np.exp(-0.431 * 2))
    assert sun.direct_normal_irradiance(95.0, 172) == 0.0
    # sun at the zenith on a plane tilted 30 degrees: cos 30 (eq. 4.8)
    assert sun.cos_incidence(0, 0, 30, 180) == pytest.approx(np.cos(np.radians(30)))
    # sun 30 degrees from zenith in the south on a plane tilted 30 degrees south: normal incidence
    assert sun.tilted_direct_irradiance(800.0, 30, 180, 30, 180) == pytest.approx(800.0)
    assert sun.tilted_direct_irradiance(800.0, 30, 180, 90, 0) == 0.0   # behind a north wall


def test_sun_colour_range():
    assert sun.sun_cct(90.0) == 4000.0 and sun.sun_cct(0.0) == 5500.0
    rgb = sun.sun_rgb(np.array([80.0, 20.0]))
    assert rgb @ [0.2126, 0.7152, 0.0722] == pytest.approx([1, 1])
    assert rgb[0, 0] / rgb[0, 2] > rgb[1, 0] / rgb[1, 2] > 1    # low sun is redder


def test_bad_input():
    with pytest.raises(SkyfitError, match="time zone"):
        sun.solar_position(datetime(2026, 6, 21, 12), 40, 0)
    with pytest.raises(SkyfitError, match=r"latitude = 95.*\[-90, 90\]"):
        sun.solar_position(datetime(2026, 6, 21, 12, tzinfo=timezone.utc), 95, 0)
    with pytest.raises(SkyfitError, match="valid values are: 'spa', 'thesis'"):
        sun.solar_position(datetime(2026, 6, 21, 12, tzinfo=timezone.utc), 40, 0, method="x")


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 23 * 60), st.integers(-12 * 4, 14 * 4)), min_size=2,
                max_size=6))
def test_times_of_mixed_utc_offsets_are_the_same_instants(times):
    """Times of several UTC offsets (a day across a change of summer time, photographs from two
    cameras) place the sun as the same instants in UTC do."""
    base = datetime(2026, 3, 29, tzinfo=timezone.utc)
    utc = [base + timedelta(minutes=m) for m, _ in times]
    mixed = [t.astimezone(timezone(timedelta(minutes=15 * q))) for t, (_, q) in zip(utc, times)]
    for method in ("spa", "thesis"):
        a = sun.solar_position(mixed, 51.5, -0.1, method=method)
        b = sun.solar_position(utc, 51.5, -0.1, method=method)
        np.testing.assert_array_equal(a.zenith_deg, b.zenith_deg)
        np.testing.assert_array_equal(a.azimuth_deg, b.azimuth_deg)


def test_unreadable_times_are_named_as_written():
    with pytest.raises(SkyfitError, match=r"cannot read 2026-06-21T12:00:00\+01:00, noon as"):
        sun.solar_position([datetime(2026, 6, 21, 12, tzinfo=timezone(timedelta(hours=1))),
                            "noon"], 51.5, -0.1)
