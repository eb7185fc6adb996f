import os
from collections.abc import Mapping

# NumPy's BLAS on one thread, as the `skyfit` command runs it (skyfit_mi/cli.py), set before any
# test module loads NumPy: the test modules import NumPy before skyfit_mi.cli, so without this
# each xdist worker's OpenBLAS spins a thread per core beside Dr.Jit's pool and the other
# worker's
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import pytest
from hypothesis import settings

# property tests draw the same examples on every run (a failure in CI is one anyone can rerun)
settings.register_profile("skyfit", derandomize=True)
settings.load_profile("skyfit")


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


class _Days(Mapping):
    """The disc days by name, each rendered when first asked for (a worker renders only the
    days its tests read)."""

    def __init__(self, tmp, options):
        self._tmp, self._options, self._rendered = tmp, options, {}

    def __getitem__(self, name):
        if name not in self._rendered:
            self._rendered[name] = disc_day(self._tmp, name, **self._options[name])
        return self._rendered[name]

    def __iter__(self):
        return iter(self._options)

    def __len__(self):
        return len(self._options)


@pytest.fixture(scope="session")
def days(tmp_path_factory, mi):
    """Rendered disc days (rho_s 0.3, sigma_alpha 0.1, 12x12) shared by the fitting tests."""
    return _Days(tmp_path_factory.mktemp("days"),
                 {"clean": {}, "noisy": {"noise": 5.0},
                  "south": {"camera_az": 180.0, "noise": 5.0},
                  "overcast": {"sky": "overcast", "noise": 5.0}})


@pytest.fixture(scope="session")
def radiance():
    """Runs a program of the Radiance that the pyradiance wheel ships (the independent
    reference: gensky, oconv, rtrace): ``radiance("rtrace", "-h", octree, input=rays)`` ->
    its stdout (bytes when ``binary``); tests using it skip where pyradiance is absent."""
    pytest.importorskip("pyradiance")
    from independent import radiance_runner
    return radiance_runner()
