"""Radiance gensky import: exact reproduction of skybright.cal, and Radiance's own irradiance."""

import numpy as np
import pytest

from skyfit_mi.errors import ParseError
from skyfit_mi.physics.gensky import from_gensky

CLEAR = """# gensky 6 21 12 +s -a 40 -o 0 -m 0
# Solar altitude and azimuth: 73.4 -1.1

void light solar
0
0
3 7.166e+06 7.166e+06 7.166e+06

solar source sun
0
0
4 0.005614 -0.284825 0.958563 0.5

void brightfunc skyfunc
2 skybr skybright.cal
0
7 1 2.775e+01 2.971e+01 1.514e+00 0.005614 -0.284825 0.958563
"""


def test_clear_import_matches_skybright_by_hand():
    s = from_gensky(CLEAR)
    sun = np.array([0.005614, -0.284825, 0.958563])
    sun /= np.linalg.norm(sun)   # printed to 6 digits; the Sky keeps a unit vector
    # zenith: sunnysky = A2 (.91 + 10 e^-3g + .45 cos^2 g)(1 - e^-.32)/A4, blended with A3
    cg = sun[2]
    g = np.arccos(cg)
    sunny = 27.75 * (0.91 + 10 * np.exp(-3 * g) + 0.45 * cg * cg) * (1 - np.exp(-0.32)) / 1.514
    a = 2.01 ** 10
    expected = (a * sunny + 29.71 / a) / (a + 1 / a)
    np.testing.assert_allclose(s.sky_radiance(np.array([0.0, 0.0, 1.0])), expected, rtol=1e-12)
    # straight down: essentially the ground brightness A3
    np.testing.assert_allclose(s.radiance(np.array([0.0, 0.0, -1.0])), 29.71, rtol=1e-9)
    np.testing.assert_allclose(s.sun_radiance, 7.166e6)
    assert s.sun_solid_angle == pytest.approx(2 * np.pi * (1 - np.cos(np.radians(0.25))))
    assert s.horizon_blend and s.info["command"].startswith("gensky 6 21 12 +s")


def test_glow_colour_multiplies_sky():
    s = from_gensky(CLEAR + "\nskyfunc glow sky_glow\n0\n0\n4 0.9 1.0 1.1 0\n")
    grey = from_gensky(CLEAR)
    d = np.array([0.3, 0.4, 0.866])
    np.testing.assert_allclose(s.sky_radiance(d), grey.sky_radiance(d) * [0.9, 1.0, 1.1])


@pytest.mark.parametrize("text, match", [
    ("", "no 'brightfunc' calling skybr"),
    ("void light solar\n0\n0\n3 1 1", "ends first"),
    (CLEAR.replace("7 1 2.775e+01", "7 9 2.775e+01"), "knows 1 .clear."),
    (CLEAR.replace("7 1 2.775e+01 2.971e+01 1.514e+00 0.005614 -0.284825 0.958563",
                   "3 1 2.775e+01 2.971e+01"), "needs 7 real arguments"),
    (CLEAR.replace("3 7.166e+06", "3 x"), "non-numeric"),
])
def test_malformed_gensky(text, match):
    with pytest.raises(ParseError, match=match):
        from_gensky(text)


# ---- Radiance cross-check ---------------------------------------------------

def _rtrace_irradiance(text, radiance, tmp_path, ab):
    """Horizontal irradiance [W m^-2] at the origin under the gensky ``text``, by rtrace -I."""
    rad = tmp_path / "sky.rad"
    rad.write_text(text + "\nskyfunc glow sky_glow 0 0 4 1 1 1 0\nsky_glow source sky 0 0 4 0 0 1 360\n")
    (tmp_path / "sky.oct").write_bytes(radiance("oconv", rad, binary=True))
    out = radiance("rtrace", "-h", "-I", "-ab", ab, "-ad", "20000", "-as", "0", "-aa", "0",
                   "-lw", "1e-6", tmp_path / "sky.oct", input="0 0 0 0 0 1\n")
    return np.array(out.split()[:3], dtype=float)


@pytest.mark.parametrize("args", [["6", "21", "12", "+s"], ["6", "21", "8.5", "+s"],
                                  ["8", "16", "15", "+i"], ["12", "21", "12", "-c"]])
def test_horizontal_irradiance_matches_rtrace(args, radiance, tmp_path):
    text = radiance("gensky", *args, "-a", "40", "-o", "0", "-m", "0", "-y", "2026")
    s = from_gensky(text)
    ref_sun = _rtrace_irradiance(text, radiance, tmp_path, ab=0)
    ref_all = _rtrace_irradiance(text, radiance, tmp_path, ab=1)
    np.testing.assert_allclose(s.sun_horizontal_irradiance(), ref_sun, rtol=1e-3)
    np.testing.assert_allclose(s.horizontal_irradiance(), ref_all, rtol=0.02)
