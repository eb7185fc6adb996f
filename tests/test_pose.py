"""The camera pose's uncertainty in a fit's intervals (fitting/pose.py): a narrow lobe fitted
with its camera typed 0.7 deg off misses its roughness unless the pose's sd is propagated, the
linearised shift is a refit's with the camera turned, and where the sky is fitted the pose is
fitted with it: the turn the data tell holds the one the pose was typed off by."""

import json
import shutil

import numpy as np
import pytest

from skyfit_mi.files import write_json
from skyfit_mi.fitting.fit import FitCache, FitSession, fit_region, fit_regions
from skyfit_mi.fitting.light import LightOptions
from skyfit_mi.pipeline.manifest import load_manifest
from skyfit_mi.pipeline.sequence import render_sequence
from skyfit_mi.pipeline.spec import thesis_disc_spec, validate_spec
from skyfit_mi.render.scene import pose_sd, turn_camera

QUIET = {"log": lambda *a: None}
PIXELS = np.array([(x, y) for x in range(2, 6) for y in range(2, 6)])
#: The glossy disc's truth: its lobe narrow enough that 0.7 deg of pose moves it.
RHO_S, SIGMA = 0.5, 0.05


def turned(src, dst, turns):
    """A copy of the day ``src`` whose manifest's camera (record and scene XML) is turned by
    ``turns`` [(angle, deg)] about the origin, where its central ray meets the disc: the pose
    typed off."""
    shutil.copytree(src, dst)
    doc = json.loads((dst / "manifest.json").read_text())
    m = np.asarray(doc["camera"]["to_world"])
    new = m
    for angle, deg in turns:
        new = turn_camera(new, [0.0, 0.0, 0.0], angle, deg)
    text = " ".join(repr(float(x)) for x in m.ravel())
    assert text in doc["scene"]["xml"]
    doc["scene"]["xml"] = doc["scene"]["xml"].replace(
        text, " ".join(repr(float(x)) for x in new.ravel()))
    doc["camera"]["to_world"] = new.tolist()
    write_json(dst / "manifest.json", doc)
    return dst


@pytest.fixture(scope="module")
def day(tmp_path_factory, mi):
    """An afternoon of the glossy disc (8x8, every 20 minutes, 3% noise) seen from the east,
    whose highlight the frames cross; its spec states the pose to 0.7 deg."""
    tmp = tmp_path_factory.mktemp("pose")
    raw = thesis_disc_spec("pose", {"model": "two", "rho_s": RHO_S, "sigma_alpha": SIGMA},
                           size=8, noise_percent=3.0, spp=1024, seed=11, exposure=0.0015)
    raw["time"].update(start="13:00", end="18:00", step_minutes=20)
    raw["camera"]["pose_sd_deg"] = 0.7
    render_sequence(validate_spec(raw, tmp), tmp / "day", progress=False, **QUIET)
    return tmp / "day"


def test_the_manifest_carries_the_pose_sd(day):
    doc, _ = load_manifest(day)
    assert doc["camera"]["pose_sd_deg"] == {"azimuth": 0.7, "angle": 0.7, "roll": 0.0}


def test_a_pose_typed_off_misses_the_roughness_unless_its_sd_is_in_the_intervals(day, tmp_path):
    off = turned(day, tmp_path / "off", [("azimuth", 0.7), ("angle", 0.7)])
    s = FitSession(off, "disc", PIXELS, model="two")          # the manifest's 0.7 deg
    with_pose = s.run(**QUIET)
    s.pose_sd = pose_sd(None)
    without = s.run(**QUIET)
    lo, hi = without["intervals"]["sigma_alpha"]["95"]
    assert not lo <= SIGMA <= hi                  # measured: 0.0475 [0.0442, 0.0486]
    assert "pose" not in without
    lo, hi = with_pose["intervals"]["sigma_alpha"]["95"]
    assert lo <= SIGMA <= hi                      # measured: [0.0411, 0.0532]
    lo, hi = with_pose["intervals"]["rho_s"]["95"]
    assert lo <= RHO_S <= hi
    pose = with_pose["pose"]
    assert set(pose["shift_by_parameter"]["sigma_alpha"]) == {"azimuth", "angle"}
    assert any(w.startswith("sigma_alpha depends on the pose: its uncertainty (+-0.7 deg in "
                            "azimuth, +-0.7 deg in angle from the vertical, 1 sd) moves it by")
               for w in with_pose["warnings"])


def test_the_linearised_shift_is_a_refits_with_the_camera_turned(day, tmp_path):
    """At the true pose (no misfit) and a turn small enough for the data to be fitted still,
    the Gauss-Newton shift of the roughness is the refit's at the turned camera's to 20%."""
    # every other pixel of the 4 x 4: both fits see the same data, so the comparison needs no
    # more, at half the trace (measured, shift / refit's: 0.95 on these 8, 1.00 and 1.03 on
    # other 8s, 1.01 on all 16; 1.25 on 4)
    px = PIXELS[::2]
    cache = FitCache(positions=32, pose_sd_deg={"azimuth": 0.1})
    lin = fit_region(day, "disc", px, model="two", cache=cache, **QUIET)
    refit = fit_region(turned(day, tmp_path / "az", [("azimuth", 0.1)]), "disc", px,
                       model="two", cache=FitCache(positions=32, pose_sd_deg=0.0), **QUIET)
    shift = lin["pose"]["shift_by_parameter"]["sigma_alpha"]["azimuth"]
    finite = refit["parameters"]["sigma_alpha"] - lin["parameters"]["sigma_alpha"]
    assert shift == pytest.approx(finite, rel=0.2)       # measured: 0.000174 and 0.000184
    assert lin["pose"]["error_sd"]["sigma_alpha"] == pytest.approx(abs(shift))


def test_where_the_sky_is_fitted_the_pose_moves_it_and_the_parameters_with_it(day, tmp_path):
    """The camera typed 0.7 deg off in azimuth and angle, its sd 0.7, the sky's level fitted:
    the turn moves the fitted level, and each parameter's shift per angle adds its response to
    that; the intervals hold the truth."""
    off = turned(day, tmp_path / "off", [("azimuth", 0.7), ("angle", 0.7)])
    out = next(fit_regions(off, [("disc", PIXELS)], model="two", cache=FitCache(positions=32),
                           light=LightOptions(sky="prior", terms=1, sun_sd=0.0), **QUIET))
    moved = out["sky"]["pose_shift"]
    assert moved["coefficients"] == ["log k"] and set(moved["by_angle"]) == {"azimuth", "angle"}
    assert all(abs(v[0]) > 1e-4 for v in moved["by_angle"].values())
    pose = out["pose"]
    for p in ("rho_s", "sigma_alpha"):
        assert set(pose["through_sky"][p]) == {"azimuth", "angle"}
        assert pose["error_sd"][p] == pytest.approx(np.hypot(
            *pose["shift_by_parameter"][p].values()))
        lo, hi = out["intervals"][p]["95"]
        assert lo <= {"rho_s": RHO_S, "sigma_alpha": SIGMA}[p] <= hi
