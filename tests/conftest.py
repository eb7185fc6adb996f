from collections.abc import Mapping

import pytest


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


def _trace_key(session, at, bsdf_id, light):
    """What :meth:`~skyfit_mi.fitting.fit.FitSession._trace` reads, as bytes: the scene, the
    renderer's settings, the frames' skies, the model and lobe, the cache's options, the points,
    their materials and how the light is split (the sun's, the rest's, the shape's variants).
    A sky's ``sun_measured`` (where the spec's sun's level came from, read by the fit's
    uncertainty, :func:`~skyfit_mi.fitting.sky_fit.sun_source`) is not part of the light."""
    import json
    import pickle
    from dataclasses import replace

    import numpy as np

    skies = [replace(s, info={k: v for k, v in s.info.items() if k != "sun_measured"})
             for s in session.skies]
    points = (np.asarray(at).tobytes() if not hasattr(at, "origins")
              else at.origins.tobytes() + at.directions.tobytes())
    return pickle.dumps((session.doc["scene"]["xml"], json.dumps(session.doc["render"],
                                                                 sort_keys=True),
                         skies, session.model, session.normalisation,
                         sorted(session._cache_options().items()), points,
                         np.asarray(bsdf_id).tolist(), light.split, light.shape))


@pytest.fixture(scope="module")
def light_traced_once():
    """Within a module, each light cache is traced once: a trace of the same scene, skies,
    points, cache options and split of the light (:func:`_trace_key`) as one already made is
    a copy of it.  A trace is deterministic (the same options, points and lights give the same
    samples and the same cache: CacheOptions, tests/test_light_cache.py), so a fit, a session
    made again from a fit and a relight see exactly the light they would trace; only the
    time is saved (a fit's trace is 85-90% of its time).  A trace of anything else is made.
    A copy takes no time: the session's ``cache_time`` (the record's timings, and the time
    budget of an automatically sized cache's growth) is then its own load's alone.  Not for
    tests of the trace itself, its timing or its memory."""
    import copy

    from skyfit_mi.fitting.fit import FitSession

    traced, original = {}, FitSession._trace

    def _trace(self, at, bsdf_id, light):
        key = _trace_key(self, at, bsdf_id, light)
        if key not in traced:
            traced[key] = copy.deepcopy(original(self, at, bsdf_id, light))
        return copy.deepcopy(traced[key])

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(FitSession, "_trace", _trace)
        yield traced
