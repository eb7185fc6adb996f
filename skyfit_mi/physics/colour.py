"""Colour of daylight from a correlated colour temperature (CCT).

Rendering is in linear sRGB (Rec. 709 primaries, D65 white), as Mitsuba's ``*_rgb`` variants.
Colours here have luminance 0.2126 R + 0.7152 G + 0.0722 B = 1, so times a broadband radiometric
quantity they keep it as the triple's luminance-weighted value.
"""

import numpy as np

from ..errors import check_range

#: XYZ -> linear sRGB (IEC 61966-2-1).
XYZ_TO_SRGB = np.array([[3.2406, -1.5372, -0.4986],
                        [-0.9689, 1.8758, 0.0415],
                        [0.0557, -0.2040, 1.0570]])
#: Luminance weights of linear sRGB (row 2 of the inverse of XYZ_TO_SRGB).
SRGB_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

_WAVELENGTHS = np.arange(360.0, 831.0, 1.0)  # [nm]


def _lobe(lam, mu, s1, s2):
    s = np.where(lam < mu, s1, s2)
    return np.exp(-0.5 * ((lam - mu) / s) ** 2)


def cie1931_cmf(lam):
    """CIE 1931 2-degree colour matching functions (..., 3) at ``lam`` [nm], by the
    piecewise-Gaussian fit of C. Wyman, P.-P. Sloan, P. Shirley, "Simple analytic
    approximations to the CIE XYZ color matching functions", JCGT 2(2), 1-11, 2013."""
    lam = np.asarray(lam, dtype=float)
    x = (1.056 * _lobe(lam, 599.8, 37.9, 31.0) + 0.362 * _lobe(lam, 442.0, 16.0, 26.7)
         - 0.065 * _lobe(lam, 501.1, 20.4, 26.2))
    y = 0.821 * _lobe(lam, 568.8, 46.9, 40.5) + 0.286 * _lobe(lam, 530.9, 16.3, 31.1)
    z = 1.217 * _lobe(lam, 437.0, 11.8, 36.0) + 0.681 * _lobe(lam, 459.0, 26.0, 13.8)
    return np.stack([x, y, z], axis=-1)


def planck(lam_nm, temperature):
    """Black-body spectral radiance (relative), Planck's law; ``lam_nm`` [nm], T [K]."""
    c2 = 1.4388e-2  # second radiation constant [m K]
    lam = np.asarray(lam_nm, dtype=float) * 1e-9
    t = np.asarray(temperature, dtype=float)[..., None]
    return lam**-5 / np.expm1(c2 / (lam * t))


def cct_to_xyz(temperature):
    """CIE XYZ of a black body at ``temperature`` [K], normalised to Y = 1."""
    check_range("colour temperature", temperature, 1000, 1e6, "K")
    spd = planck(_WAVELENGTHS, temperature)
    xyz = spd @ cie1931_cmf(_WAVELENGTHS)
    return xyz / xyz[..., 1:2]


def cct_to_rgb(temperature):
    """Linear-sRGB colour (..., 3) of a black body at ``temperature`` [K], in [1000, 1e6], with
    luminance 1; out-of-gamut components are clipped at 0 before normalising."""
    rgb = np.maximum(cct_to_xyz(temperature) @ XYZ_TO_SRGB.T, 0.0)
    return rgb / (rgb @ SRGB_LUMINANCE)[..., None]
