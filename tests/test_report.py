"""A fit's files (`fit_NAME.json`, its plot, `fits.csv`): the JSON marks a fit done, so a fit
interrupted while written leaves no JSON for relight, export or fits.csv to take."""

import json

import numpy as np
import pytest

from skyfit_mi.errors import OutputError
from skyfit_mi.fitting import report


def _result():
    """A two-parameter fit of one region over three frames (pixels x frames x RGB series)."""
    observed = np.full((2, 3, 3), 100.0)
    return {"region": "disc", "model": "two", "method": "global", "pixels": [[1, 1], [2, 2]],
            "parameters": {"rho_s": 0.3, "sigma_alpha": 0.1},
            "intervals": {"rho_s": {"95": [0.2, 0.4]}, "sigma_alpha": {"95": [0.05, 0.15]}},
            "chi2_per_dof": 1.0, "evaluations": 10, "wall_time_s": 0.5, "truth": None,
            "warnings": [], "frames": [0, 1, 2],
            "series": {"times": ["2026-06-21T09:00:00+00:00", "2026-06-21T12:00:00+00:00",
                                 "2026-06-21T15:00:00+00:00"],
                       "observed_DN": observed.tolist(), "model_DN": (observed + 1).tolist()}}


def test_the_json_is_written_last_and_a_failed_plot_leaves_none(tmp_path, monkeypatch):
    paths = report.write_fit(_result(), tmp_path / "fit_disc")
    assert [p.name for p in paths] == ["fit_disc.json", "fit_disc.png"]
    assert json.loads(paths[0].read_text())["region"] == "disc"
    assert report.write_summary(tmp_path).read_text().count("\n") == 2      # header and disc

    def full(*a, **kw):
        raise OutputError("cannot write 'fit_rim.png': No space left on device.")

    monkeypatch.setattr(report, "save_figure", full)
    with pytest.raises(OutputError, match="No space left"):
        report.write_fit({**_result(), "region": "rim"}, tmp_path / "fit_rim")
    assert not (tmp_path / "fit_rim.json").exists()            # not done: nothing marks it so
    assert set(report.read_fits(tmp_path)) == {"disc"}
