import pytest

#: The test files that take longest (1-5 minutes each on 2 cores), run first: the suite runs on
#: every core (pytest-xdist, ``-n auto --dist loadfile`` in pyproject.toml), each file on one
#: worker, and the rest then packs around them instead of one of them running alone at the end.
LONGEST_FIRST = ("test_sky_fit.py", "test_pixel_map.py", "test_families.py", "test_ingest.py",
                 "test_sky_control.py", "test_colorchecker.py", "test_chi2map.py")


def pytest_collection_modifyitems(items):
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONGEST_FIRST)))    # stable


@pytest.fixture(scope="session")
def mi():
    """Mitsuba with the project's default variant and plugins registered."""
    from skyfit_mi.render import setup

    return setup()


def disc_day(tmp, name, camera_az=90.0, sky="clear", noise=0.0, rho_s=0.3, sigma=0.1, spp=1024):
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import thesis_disc_spec, validate_spec

    raw = thesis_disc_spec(name, {"model": "two", "rho_s": rho_s, "sigma_alpha": sigma},
                           camera_azimuth_deg=camera_az, size=12, noise_percent=noise, spp=spp,
                           seed=11, sky=sky, exposure=0.0015)
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


@pytest.fixture(scope="session")
def radiance():
    """Runs a program of the Radiance that the pyradiance wheel ships (the independent
    reference: gensky, oconv, rtrace): ``radiance("rtrace", "-h", octree, input=rays)`` ->
    its stdout (bytes when ``binary``); tests using it skip where pyradiance is absent."""
    pytest.importorskip("pyradiance")
    from independent import radiance_runner
    return radiance_runner()
