"""End to end through the command line: the built-in example."""
import json

import numpy as np

from skyfit_mi.cli import main


def test_demo_renders_a_day(tmp_path, mi):
    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out), "--spp", "16", "--resolution", "48"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["frames"]) == 13 and summary["seed"] == 0
    assert (out / "contact_sheet.png").stat().st_size > 1000
    from skyfit_mi.render.image import read_exr
    img = read_exr(out / summary["frames"][6]["file"])
    assert img.shape == (48, 48, 3) and np.all(np.isfinite(img)) and img.min() >= 0
    # 256 centre pixels x 16 spp: the disc matches E/pi to a few per cent in every frame
    for row in summary["frames"]:
        assert abs(row["disc_radiance_W_m2_sr"] / row["analytic_E_over_pi_W_m2_sr"] - 1) < 0.05


def test_bad_variant_is_a_clear_error(capsys):
    assert main(["demo", "--variant", "scalar_rgb"]) == 2
    assert "valid values are" in capsys.readouterr().err
