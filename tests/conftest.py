import pytest


@pytest.fixture(scope="session")
def mi():
    """Mitsuba with the project's default variant and plugins registered."""
    from skyfit_mi.render import setup

    return setup()


def disc_day(tmp, name, camera_az=90.0, sky="clear", noise=0.0, rho_s=0.3, sigma=0.1, spp=1024):
    raw = {
        "name": name,
        "location": {"latitude_deg": 40.0, "longitude_deg": 0.0, "timezone": "UTC"},
        "time": {"date": "2026-06-21", "start": "06:00", "end": "18:00", "step_minutes": 60},
        "sky": {"type": sky},
        "scene": {"file": "disc.xml"},
        "materials": {"disc": {"model": "two", "rho_s": rho_s, "sigma_alpha": sigma}},
        "camera": {"azimuth_deg": camera_az, "angle_deg": 45.0, "distance": 5.0, "fov_deg": 6.0,
                   "width": 12, "height": 12},
        "sensor": {"exposure": 0.0015, "bits": 12, "noise_percent": noise},
        "render": {"spp": spp, "seed": 11},
    }
    from skyfit_mi.sequence import render_sequence
    from skyfit_mi.spec import validate_spec

    out = tmp / name
    render_sequence(validate_spec(raw, tmp), out, progress=False, log=lambda *a: None)
    return out


@pytest.fixture(scope="session")
def days(tmp_path_factory, mi):
    """Rendered disc days (rho_s 0.3, sigma_alpha 0.1, 12x12) shared by the fitting tests."""
    tmp = tmp_path_factory.mktemp("days")
    return {"clean": disc_day(tmp, "clean"),
            "noisy": disc_day(tmp, "noisy", noise=5.0),
            "south": disc_day(tmp, "south", camera_az=180.0, noise=5.0),
            "overcast": disc_day(tmp, "overcast", sky="overcast", noise=5.0)}
