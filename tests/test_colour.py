"""Black-body colours against published chromaticities."""
import numpy as np
import pytest

from skyfit_mi.physics.colour import cct_to_rgb, cct_to_xyz
from skyfit_mi.errors import SkyfitError


@pytest.mark.parametrize("t, xy", [(2856, (0.4476, 0.4074)),     # CIE illuminant A
                                   (6500, (0.3135, 0.3236))])    # Planckian locus, CIE 15
def test_planckian_chromaticity(t, xy):
    xyz = cct_to_xyz(t)
    np.testing.assert_allclose(xyz[:2] / xyz.sum(), xy, atol=0.0015)  # Wyman fit accuracy


def test_rgb_has_unit_luminance_and_orders_by_temperature():
    rgb = cct_to_rgb(np.array([4000.0, 6500.0, 15000.0]))
    np.testing.assert_allclose(rgb @ [0.2126, 0.7152, 0.0722], 1.0)
    assert rgb[0, 2] < rgb[1, 2] < rgb[2, 2]
    with pytest.raises(SkyfitError, match="colour temperature"):
        cct_to_rgb(np.nan)
