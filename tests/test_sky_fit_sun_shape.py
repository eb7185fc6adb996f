"""The sun's level and the sky's shape fitted with the materials (fitting/sky_fit.py, ``fit
--sky prior``, ``--sun-sd``, ``--sky-shape``): tests/test_sky_fit.py's days and region, in a
file of its own so that the two run on two workers."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from skyfit_mi.cli import main
from skyfit_mi.fitting.light import LightOptions
from skyfit_mi.physics import sky_shape

from test_sky_fit import HALF, REGION, TRUTH, traced_once


@pytest.fixture(scope="module")
def once():
    """The module's fits, relights and sessions under :func:`~test_sky_fit.traced_once`: a
    light traced once."""
    with traced_once():
        yield


def test_the_suns_level_is_a_factor_on_the_reflectances_only_where_nothing_anchors_them():
    from skyfit_mi.fitting.sky_fit import light_level_sd
    from skyfit_mi.fitting.uncertainty import widen_relative

    names = ("C_r", "C_g", "C_b", "rho_s", "sigma_alpha")
    np.testing.assert_array_equal(light_level_sd({}, names, 0.2), [0.2] * 4 + [0.0])
    calibrated = {"ingest": {"calibration": {"scale_relative_sd": [0.01] * 3}}}
    relative = {"ingest": {"scale": {"known": False}}}
    for doc in (calibrated, relative):
        assert not light_level_sd(doc, names, 0.2).any()
    assert not light_level_sd({}, ("rho_s", "sigma_alpha"), 0.2).any()   # white: no freedom
    # a factor: e^(+-z sd) about the value, in quadrature (in log) with the data's own
    lo, hi = widen_relative(0.5, (0.5, 0.5), 1.96 * 0.2, 0.0, 1.0)
    assert lo == pytest.approx(0.5 * np.exp(-0.392)) and hi == pytest.approx(0.5 * np.exp(0.392))
    lo, hi = widen_relative(0.5, (0.4, 0.6), 0.3, 0.0, 0.7)
    assert lo == pytest.approx(0.5 * np.exp(-np.hypot(np.log(1.25), 0.3)))
    assert hi == 0.7                                                     # clipped at the bound


def test_which_sky_a_fit_takes_when_not_told():
    from skyfit_mi.fitting.sky_fit import default_sky
    from skyfit_mi.physics.sky import cie_sky, directional_sky

    sunny, overcast = cie_sky("clear", 40.0, 180.0), cie_sky("overcast", 40.0, 180.0)
    lab = directional_sky(np.array([0.0, 0.3, 1.0]), 100.0)
    assert default_sky({"source": "ingest"}, [sunny]) == "prior"
    assert default_sky({"source": "render"}, [sunny]) == "spec"
    assert default_sky({"source": "ingest"}, [overcast]) == "spec"      # no sun to scale against
    assert default_sky({"source": "ingest"}, [lab]) == "spec"            # lab lights: no sky


def test_a_measured_suns_level_is_known_to_the_instruments_accuracy():
    """Where the spec gives the measured direct normal irradiance (a CIE sky's
    direct_normal_W_m2, a Perez sky's dhi and dni, a map's direct_normal) the sun is
    'measured' and a photographed day's fit counts MEASURED_SUN_SD of it, not widened; a split
    of the global irradiance (Erbs; a map's sun from the GHI) or the thesis's eq. 4.7 is a
    model's (SUN_LEVEL_SD), and a rendered day's sun is exact."""
    import datetime as dt

    from skyfit_mi.fitting.sky_fit import default_sun_sd, sun_source
    from skyfit_mi.physics.envmap import MeasuredIrradiance, envmap_sky
    from skyfit_mi.physics.sky import MEASURED_SUN_SD, SUN_LEVEL_SD, cie_sky
    from skyfit_mi.pipeline.illumination import perez_from_irradiance
    from skyfit_mi.pipeline.spec import thesis_disc_spec, validate_spec

    raw = thesis_disc_spec("dni", {"model": "two", "rho_s": 0.5, "sigma_alpha": 0.1})
    scenes = Path(__file__).resolve().parents[1] / "scenes"
    modelled = [f.sky for f in validate_spec(raw, scenes).frames]
    raw["sky"].update(direct_normal_W_m2=700.0, diffuse_horizontal_W_m2=120.0)
    measured = [f.sky for f in validate_spec(raw, scenes).frames]
    t = dt.datetime(2026, 6, 21, 12, tzinfo=dt.timezone.utc)
    perez = perez_from_irradiance({"diffuse_horizontal_W_m2": 120.0,
                                   "direct_normal_W_m2": 700.0}, 30.0, 180.0, t)
    erbs = perez_from_irradiance({"global_horizontal_W_m2": 800.0}, 30.0, 180.0, t)
    table = np.full((16, 32, 3), 20.0, dtype=np.float32)
    mapped = envmap_sky(table, 30.0, 180.0, measured=MeasuredIrradiance(direct_normal=700.0))
    from_ghi = envmap_sky(table, 30.0, 180.0,
                          measured=MeasuredIrradiance(global_horizontal=800.0))
    for skies in (measured, [perez], [mapped]):
        assert sun_source(skies) == "measured"
        assert default_sun_sd({"source": "ingest"}, skies) == MEASURED_SUN_SD
    for skies in (modelled, [erbs], [from_ghi], [cie_sky("clear", 40.0, 180.0)],
                  [perez, erbs]):
        assert sun_source(skies) == "modelled"
        assert default_sun_sd({"source": "ingest"}, skies) == SUN_LEVEL_SD
    assert default_sun_sd({"source": "render"}, measured) == 0.0


@pytest.fixture(scope="module")
def bright_sun(days, tmp_path_factory):
    """The noisy disc day whose manifest's sun is SUN_BRIGHTER times too bright (a modelled
    sun over a hazy day)."""
    out = tmp_path_factory.mktemp("sun") / "day"
    shutil.copytree(days["noisy"], out)
    m = json.loads((out / "manifest.json").read_text())
    for f in m["frames"]:
        il = f["illumination"]
        il["sun_radiance"] = [v * SUN_BRIGHTER for v in il["sun_radiance"]]
    m["source"] = "ingest"          # a photographed day: its spec's sun is a model
    (out / "manifest.json").write_text(json.dumps(m))
    return out


SUN_BRIGHTER = 1.2


def test_a_modelled_suns_level_is_in_the_reflectances_intervals(bright_sun, once):
    """The spec's sun 1.2 times too bright scales every reflectance down by about as much,
    and no data tell (the level trades exactly with them): with the sky taken as exact the
    diffuse colour's interval misses the truth; by default a photographed day's fit counts
    the sun's level (SUN_LEVEL_SD) with the sky's prior, holds every truth, warns that the
    reflectances rest on it, and leaves sigma_alpha's interval as the data make it.  (The
    measured sun's day differs from the modelled one's in its skies' ``info`` alone: its fit
    takes the modelled one's trace, :func:`~test_sky_fit.traced_once`.)"""
    from skyfit_mi.fitting.fit import fit_regions
    from skyfit_mi.fitting.light import LightPlan
    from skyfit_mi.physics.sky import MEASURED_SUN_SD
    from skyfit_mi.pipeline.manifest import frame_sky, load_manifest

    # half the region: the exact sky's C_g (0.79-0.84 on it, 0.79-0.83 on the whole) misses the
    # truth by far
    exact = next(fit_regions(bright_sun, [("disc", HALF)], model="colour", light=LightOptions(sky="spec"),
                             log=lambda *a: None))
    lo, hi = exact["intervals"]["C_g"]["95"]
    assert hi < TRUTH["C_g"], exact["intervals"]["C_g"]
    logs = []
    # the sky's departure, the photographs' default too (resolved below), is left out: it
    # costs its parts' traces and tests/test_sky_departure.py fits it
    r = next(fit_regions(bright_sun, [("disc", REGION)], model="colour", log=logs.append,
                         light=LightOptions(departure=False)))
    assert r["sky"]["prior"]["log_k_sd"] > 0 and r["sky"]["sun_coupling"]["given_sd"] == 0.2
    # the modelled sun's sd widened by the sky's departure from the spec's (SUN_SKY_COUPLING:
    # log k's rms over the frames of the curve)
    log_k = np.log([v[0] for v in r["sky"]["terms"]["k_by_frame"].values()])
    assert r["sky"]["sun_level_sd"] == pytest.approx(np.hypot(0.2, 0.35 * np.sqrt(np.mean(
        log_k ** 2))))
    assert any("the modelled sun's 20% widened" in w for w in r["warnings"]), r["warnings"]
    # a level given to --sun-sd is kept as it is (its source 'given': not widened, as the
    # measured sun's below is not); photographs' sky departs from its model by default
    doc, root = load_manifest(bright_sun)
    skies = [frame_sky(f, root) for f in doc["frames"]]
    assert LightOptions(sun_sd=0.1).resolve(doc, skies, len(skies), log=lambda *a: None) == (
        LightPlan("prior", 0.1, "given", departure=True))
    assert LightOptions(sun_sd=0.1, departure=False).resolve(
        doc, skies, len(skies), log=lambda *a: None) == LightPlan("prior", 0.1, "given")
    assert r["sky"]["sun_source"] == "modelled"
    # a sun whose spec gave its measured direct normal irradiance: known to the instrument's
    # accuracy, not widened
    day = bright_sun.parent / "measured_sun"
    shutil.copytree(bright_sun, day)
    m = json.loads((day / "manifest.json").read_text())
    for f in m["frames"]:
        f["illumination"]["info"]["sun_measured"] = True
    (day / "manifest.json").write_text(json.dumps(m))
    measured = next(fit_regions(day, [("disc", REGION)], model="colour", log=lambda *a: None,
                                light=LightOptions(departure=False)))
    assert measured["sky"]["sun_source"] == "measured" and measured["sky"]["sun_coupling"] is None
    assert measured["sky"]["sun_level_sd"] == MEASURED_SUN_SD
    assert any("the spec's measured direct normal" in w for w in measured["warnings"]), \
        measured["warnings"]
    for p in ("C_r", "C_g", "C_b", "rho_s"):
        assert (np.subtract(*measured["intervals"][p]["95"][::-1])
                < 0.6 * np.subtract(*r["intervals"][p]["95"][::-1])), p
    assert any("--sky prior" in x for x in logs), logs
    for p, v in TRUTH.items():
        lo, hi = r["intervals"][p]["95"]
        assert lo - 1e-9 <= v <= hi + 1e-9, (p, r["intervals"][p], r["parameters"])
    assert r["sky"]["sun_level_error_sd"]["sigma_alpha"] == 0
    assert any("scale with the sun's level" in w for w in r["warnings"]), r["warnings"]


def test_a_cie_skys_shape_variants_keep_its_light_and_move_one_group():
    from skyfit_mi.errors import SkyfitError
    from skyfit_mi.fitting.sky_fit import shape_variants
    from skyfit_mi.physics import cie_general
    from skyfit_mi.physics.sky import cie_general_sky, cie_sky

    sky = cie_sky("clear", 35.0, 160.0)
    variants = sky_shape.shape_variants(sky)
    assert [label for label, _ in variants] == ["gradation group 5 -> 6",
                                                "indicatrix group 4 -> 5"]
    for _, v in variants:
        np.testing.assert_allclose(v.sky_horizontal_irradiance(),
                                   sky.sky_horizontal_irradiance(), rtol=1e-6)
        np.testing.assert_array_equal(v.ground, sky.split()[1].ground)     # the sky-lit ground
        assert not v.sun_radiance.any()
    # the gradation variant is the CIE general sky of groups (6, 4), rescaled
    d = np.random.default_rng(2).normal(size=(200, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.05
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    six = cie_general_sky(cie_general.group_parameters(6, 4), 35.0, 160.0).sky_radiance(d)
    ratio = variants[0][1].sky_radiance(d)[:, 1] / six[:, 1]
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-6)
    # the most turbid group moves toward the clearer
    turbid = cie_general_sky(cie_general.group_parameters(6, 6), 35.0, 160.0)
    assert [label for label, _ in sky_shape.shape_variants(turbid)] == [
        "gradation group 6 -> 5", "indicatrix group 6 -> 5"]
    assert sky_shape.shape_variants(cie_sky("overcast", 35.0, 160.0)) == []
    with pytest.raises(SkyfitError, match="is none of these"):
        shape_variants([sky, cie_sky("overcast", 35.0, 160.0)])


def test_a_perez_skys_shape_variants_keep_its_light_and_move_one_bin_or_one_step():
    """A Perez sky's variants: the next clearness bin (at its centre's epsilon) and Delta one
    step on, each the published pattern of its epsilon and Delta lit as the spec's sky part;
    Delta's floor as perez_sky applies it; every frame moved the same way; no variants for an
    envmap."""
    from skyfit_mi.errors import SkyfitError
    from skyfit_mi.fitting.sky_fit import shape_variants
    from skyfit_mi.physics import perez
    from skyfit_mi.physics.envmap import envmap_sky
    from skyfit_mi.physics.sky import perez_pattern

    d = np.random.default_rng(4).normal(size=(200, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.05
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    step = perez.BRIGHTNESS_STEP
    # clear (epsilon 7.96, the last bin, Delta 0.087): toward the more overcast bin, Delta up
    sky = perez.perez_sky(30.0, 160.0, 172, dhi=100.0, dni=800.0).to_sky()
    eps, delta = sky.info["epsilon"], sky.info["delta"]
    variants = sky_shape.shape_variants(sky)
    assert [label for label, _ in variants] == [
        f"clearness epsilon {eps:.4g} -> 5.35",
        f"brightness Delta {delta:.4g} -> {delta * step:.4g}"]
    for (_, v), (e, dl) in zip(variants, ((5.35, delta), (eps, delta * step))):
        np.testing.assert_allclose(v.sky_horizontal_irradiance(),
                                   sky.split()[1].sky_horizontal_irradiance(), rtol=1e-6)
        np.testing.assert_array_equal(v.ground, sky.split()[1].ground)     # the sky-lit ground
        assert not v.sun_radiance.any() and v.info["kind"] == "shape variant"
        c = perez.coefficients(e, dl, 30.0)
        np.testing.assert_allclose(v.perez_coefficients, c, rtol=1e-12)
        ratio = v.sky_radiance(d) / perez_pattern(d, sky.sun_direction, c)[:, None]
        np.testing.assert_allclose(ratio, ratio[:1].repeat(len(d), axis=0), rtol=1e-9)
    assert variants[0][1].info["clearness_bin"] == 6 and variants[0][1].info["from"] == eps
    # a low sun, where Delta one step up gives b > 0 (the model refuses it): Delta moves down,
    # and a day with both frames moves both down (the mix is shared)
    low = perez.perez_sky(80.0, 250.0, 172, dhi=40.0, dni=900.0).to_sky()
    assert perez.coefficients(low.info["epsilon"], low.info["delta"] * step, 80.0)[1] > 0
    b_low = sky_shape.shape_variants(low)[1][1]
    assert b_low.info["to"] == pytest.approx(low.info["delta"] / step)
    day = shape_variants([sky, low])
    assert [v[1][1].info["to"] < v[1][1].info["from"] for v in day] == [True, True]
    with pytest.raises(SkyfitError, match="cannot move up"):
        sky_shape.shape_variants(low, toward={"clearness": 1})       # no bin above the last
    # Delta 0.055 in the bin of epsilon 1.67 is raised to the floor 0.2 for the coefficients
    # (perez_sky, as Radiance): the variants move from the floor, never below it
    dim = perez.perez_sky(35.0, 160.0, 172, dhi=60.0, dni=50.0).to_sky()
    assert dim.info["delta_coefficients"] == perez.RADIANCE_DELTA_FLOOR
    clearer, brighter = (v for _, v in sky_shape.shape_variants(dim))
    np.testing.assert_allclose(clearer.perez_coefficients,
                               perez.coefficients(2.375, perez.RADIANCE_DELTA_FLOOR, 35.0))
    assert brighter.info["from"] == perez.RADIANCE_DELTA_FLOOR
    with pytest.raises(SkyfitError, match="brightness .* cannot move down"):
        sky_shape.shape_variants(dim, toward={"brightness": -1})
    # an envmap has no shape variants, and --sky-shape refuses it
    mapped = envmap_sky(np.full((8, 16, 3), 5.0, np.float32), 30.0, 160.0)
    assert sky_shape.shape_variants(mapped) == []
    with pytest.raises(SkyfitError, match="none of these .*cie_general, perez or turbid"):
        shape_variants([sky, mapped])


@pytest.fixture(scope="module")
def gradation_4(days, tmp_path_factory):
    """The noisy disc day (rendered under the CIE clear sky: gradation group 5, indicatrix 4)
    whose manifest names the CIE general sky of gradation group 4, indicatrix 4."""
    import datetime as dt

    from measured_light import relabelled

    from skyfit_mi.physics import cie_general
    from skyfit_mi.physics.sky import cie_general_sky

    p = cie_general.group_parameters(4, 4)

    def light(frame, sky):
        return cie_general_sky(p, frame["sun_zenith_deg"], frame["sun_azimuth_deg"],
                               day=dt.datetime.fromisoformat(frame["time"]).timetuple().tm_yday)
    return relabelled(days["noisy"], tmp_path_factory.mktemp("shape") / "day", light)


@pytest.fixture(scope="module")
def shape_fit(gradation_4):
    """The disc of ``gradation_4`` fitted with its sky's level and shape (--sky-shape)."""
    from skyfit_mi.fitting.fit import fit_regions

    return next(fit_regions(gradation_4, [("disc", REGION)], model="colour", light=LightOptions(sky="fit", terms=1, shape=True),
                            log=lambda *a: None))


def test_the_skys_shape_is_fitted_with_the_materials_and_says_what_one_region_cannot_tell(
        shape_fit):
    """The spec's sky one gradation group off: with --sky-shape the fit mixes the CIE
    gradation and indicatrix variants; their indices' 95% intervals hold the truth (5, 4),
    every parameter's interval holds its truth, the record carries the coefficients'
    correlation, and one flat region, which hardly tells the shape, says so."""
    r = shape_fit
    shape = r["sky"]["shape"]
    for name, truth in (("gradation", 5.0), ("indicatrix", 4.0)):
        index, half = shape["index"][name]
        assert abs(index - truth) <= half, (name, shape["index"])
    assert r["sky"]["correlation"]["names"] == ["log k", "mix gradation", "mix indicatrix"]
    for p, v in TRUTH.items():
        lo, hi = r["intervals"][p]["95"]
        assert lo - 1e-9 <= v <= hi + 1e-9, (p, r["intervals"][p], r["parameters"])
    assert any("hardly tell the sky's" in w for w in r["warnings"]), r["warnings"]


def test_relit_images_take_the_fitted_skys_shape(shape_fit, gradation_4, tmp_path, once):
    """relight of the fitted day renders each frame under the fitted shape: an environment
    map of the day's pattern mixed with its variants at level k (sky_maps/, named by the relit
    manifest's envmap record, which reads back as the sky rendered), whose horizontal
    irradiance is the mix's.  Its region means are the fit's own prediction (the light
    tables of the fitted shape, ``--no-images``) within 1%, and closer than to its
    prediction under the day's pattern at the same level."""
    import csv

    from skyfit_mi.files import write_json
    from skyfit_mi.fitting.relight import relight
    from skyfit_mi.pipeline.fit_result import load_fits
    from skyfit_mi.pipeline.manifest import frame_sky, load_manifest
    from skyfit_mi.pipeline.pixels import frame_values

    shape = shape_fit["sky"]["shape"]
    for name, record in (("shaped", shape), ("pattern", None)):
        fits = tmp_path / f"fits_{name}"
        write_json(fits / "fit_disc.json", {**shape_fit, "sky": {**shape_fit["sky"],
                                                                 "shape": record}})
        relight(load_fits([fits]), gradation_4, tmp_path / f"predicted_{name}", images=False,
                log=lambda *a: None, progress=False)
    relight(load_fits([tmp_path / "fits_shaped"]), gradation_4, tmp_path / "shaped",
            log=lambda *a: None, progress=False)
    doc, root = load_manifest(tmp_path / "shaped")
    day_doc, day_root = load_manifest(gradation_4)
    k, mix = shape_fit["sky"]["k"], shape["mix"]
    for f, g in zip(doc["frames"], day_doc["frames"]):
        assert f["illumination"]["kind"] == "envmap", f["illumination"]
        assert (root / f["illumination"]["file"]).parent.name == "sky_maps"
        sky, day_sky = frame_sky(f, root), frame_sky(g, day_root)
        _, rest = day_sky.split()
        variants = [v for _, v in sky_shape.shape_variants(day_sky, toward=shape["toward"])]
        want = k * ((1 - sum(mix)) * rest.sky_horizontal_irradiance()
                    + sum(m * v.sky_horizontal_irradiance() for m, v in zip(mix, variants)))
        assert np.allclose(sky.sky_horizontal_irradiance(), want, rtol=2e-3), f["index"]
        assert np.allclose(sky.sun_radiance, day_sky.sun_radiance, rtol=1e-6)
    miss = {}
    for name in ("shaped", "pattern"):
        rows = list(csv.DictReader((tmp_path / f"predicted_{name}" / "prediction.csv").open()))
        frames = sorted({int(r["frame"]) for r in rows})
        predicted = np.array([[float(r["predicted [W m^-2 sr^-1]"]) for r in rows
                               if int(r["frame"]) == i] for i in frames])          # (T, 3)
        relit = frame_values(tmp_path / "shaped", np.asarray(shape_fit["pixels"]), frames)
        miss[name] = float(np.sqrt(np.mean((relit.mean(axis=0) / predicted - 1) ** 2)))
    assert miss["shaped"] < 0.01 and miss["shaped"] < miss["pattern"], miss


#: The Perez test day: its diffuse horizontal irradiance [W m^-2] (Delta 0.07-0.1 over its
#: frames), the clearness of its sky (the bin 4.5-6.2) and the spec's (the bin 2.8-4.5, at its
#: centre), and the frames' hours (UTC; the sun 27-41 degrees from the zenith).
PEREZ_DHI, PEREZ_TRUTH, PEREZ_SPEC = 100.0, 5.0, 3.65


PEREZ_HOURS = range(9, 16)


def perez_dni(epsilon, sun_zenith_deg):
    """The direct normal irradiance [W m^-2] that gives clearness ``epsilon`` with PEREZ_DHI
    at the sun's zenith (Perez et al. 1990, eq. 1, solved for it)."""
    from skyfit_mi.physics.perez import KAPPA

    return PEREZ_DHI * (epsilon - 1.0) * (1.0 + KAPPA * np.radians(sun_zenith_deg) ** 3)


@pytest.fixture(scope="module")
def perez_day(mi, tmp_path_factory):
    """The sphere (normals to the horizon) in tests/measured_light.py's paint, seen from the
    east at 2% noise under a Perez sky of clearness PEREZ_TRUTH at every frame, in a copy whose
    manifest names the Perez sky of clearness PEREZ_SPEC (one bin more overcast) at the same
    diffuse irradiance (so the same Delta), colour, sun and ground: (the copy, its pixels, every
    other one of the sphere's)."""
    import datetime as dt
    from dataclasses import replace
    from zoneinfo import ZoneInfo

    from measured_light import MATERIAL, relabelled

    from skyfit_mi.physics.perez import perez_sky
    from skyfit_mi.physics.sun import solar_position
    from skyfit_mi.pipeline.pixels import material_regions
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import thesis_disc_spec, validate_spec

    tmp = tmp_path_factory.mktemp("perez")
    raw = thesis_disc_spec("perez-sphere", MATERIAL, size=16, noise_percent=2.0, spp=256,
                           seed=11)
    raw["scene"], raw["materials"] = {"file": "sphere.xml"}, {"sphere": dict(MATERIAL)}
    raw["camera"].update({"distance": 6.0, "fov_deg": 22.0, "target": [0.0, 0.0, 1.0]})
    raw["time"] = {"date": raw["time"]["date"], "times": [f"{h:02d}:00" for h in PEREZ_HOURS]}
    cct = 12000.0                                  # one colour for both skies
    raw["sky"] = []
    for hhmm in raw["time"]["times"]:
        t = dt.datetime.fromisoformat(f"{raw['time']['date']}T{hhmm}").replace(
            tzinfo=ZoneInfo("UTC"))
        z = float(solar_position(t, 40.0, 0.0).zenith_deg)
        raw["sky"].append({"type": "perez", "time": hhmm, "cct": cct,
                           "diffuse_horizontal_W_m2": PEREZ_DHI,
                           "direct_normal_W_m2": perez_dni(PEREZ_TRUTH, z)})
    render_sequence(validate_spec(raw, tmp), tmp / "truth", progress=False,
                    log=lambda *a: None)

    def spec_sky(frame, truth):
        z = frame["sun_zenith_deg"]
        sky = perez_sky(z, frame["sun_azimuth_deg"],
                        dt.datetime.fromisoformat(frame["time"]).timetuple().tm_yday,
                        dhi=PEREZ_DHI, dni=perez_dni(PEREZ_SPEC, z)).to_sky(cct=cct)
        return replace(sky, sun_radiance=truth.sun_radiance, ground=truth.ground)
    day = relabelled(tmp / "truth", tmp / "spec", spec_sky)
    (_, pixels), = material_regions(day)
    return day, pixels[pixels.sum(axis=1) % 2 == 0]


def test_a_perez_skys_clearness_and_brightness_are_fitted_with_the_materials(perez_day):
    """The spec's Perez sky one clearness bin more overcast than the day's: with --sky-shape
    the fit moves its clearness off the spec's, its 95% interval holding the truth's bin
    (5.35 on the fitted scale: the pattern depends on epsilon through the bin alone) and not
    the spec's 3.65; Delta's holds the truth (the spec's own); every material parameter's
    interval holds its truth; the sphere's many normals tell the clearness (no warning)."""
    from measured_light import TRUTH

    from skyfit_mi.fitting.fit import fit_regions
    from skyfit_mi.physics.perez import CLEARNESS_BIN_CENTRES, brightness

    day, pixels = perez_day
    logs = []
    r = next(fit_regions(day, [("sphere", pixels)], model="colour", light=LightOptions(sky="fit", shape=True, terms=1),
                         log=logs.append))
    shape = r["sky"]["shape"]
    assert shape["variants"][0] == f"clearness epsilon {PEREZ_SPEC:.4g} -> 5.35"
    index, half = shape["index"]["clearness"]
    assert PEREZ_SPEC < index - half and abs(index - CLEARNESS_BIN_CENTRES[6]) <= half, shape
    doc = json.loads((day / "manifest.json").read_text())
    delta = np.mean([brightness(PEREZ_DHI, f["sun_zenith_deg"], 172) for f in doc["frames"]])
    index, half = shape["index"]["brightness"]
    assert abs(index - delta) <= half, (delta, shape)
    assert set(shape["index_by_frame"]) == set(r["frames"])             # Delta by frame
    assert r["sky"]["correlation"]["names"] == ["log k", "mix clearness", "mix brightness"]
    assert any("clearness epsilon" in x and "brightness Delta" in x for x in logs), logs
    assert not any("hardly tell the sky's clearness" in w for w in r["warnings"]), r["warnings"]
    for p, v in zip(("C_r", "C_g", "C_b", "rho_s", "sigma_alpha"), TRUTH):
        lo, hi = r["intervals"][p]["95"]
        assert lo - 1e-9 <= v <= hi + 1e-9, (p, r["intervals"][p], r["parameters"])


def test_sky_shape_refuses_a_sky_it_cannot_move_in_one_line(days, tmp_path, capsys):
    """--sky-shape on a day whose spec sky is not CIE, Perez or turbid (here the thesis's
    intermediate sky) is refused before the light is traced, in one line."""
    from measured_light import relabelled

    from skyfit_mi.physics.sky import cie_sky

    day = relabelled(days["clean"], tmp_path / "day", lambda frame, sky: cie_sky(
        "intermediate", frame["sun_zenith_deg"], frame["sun_azimuth_deg"], phi=0.5))
    assert main(["fit", str(day), "--region", "disc=rect:2,2,9,9", "--sky", "fit",
                 "--sky-shape"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "(type clear, cie_general, perez or turbid)" in err, err
    assert not list(day.glob("fit_*"))


def test_a_hand_edited_sky_record_is_refused_in_one_line(tmp_path):
    """relight and chi2map read a fit's sky record (level, curve, shape): one not as `fit`
    writes it is refused naming what it must be; `fit`'s own passes."""
    from skyfit_mi.errors import SkyfitError
    from skyfit_mi.pipeline.fit_result import read_fit_result

    fit = {"region": "disc", "model": "two", "parameters": {"rho_s": 0.1, "sigma_alpha": 0.1},
           "intervals": {"rho_s": {"95": [0.0, 0.2]}, "sigma_alpha": {"95": [0.0, 0.2]}}}
    good = {"k": 1.2, "terms": {"coefficients": [0.1, 0.2], "span_s": [0.0, 3600.0]},
            "shape": {"mix": [0.3, -0.1], "toward": {"gradation": 1, "indicatrix": -1}}}
    path = tmp_path / "fit_disc.json"
    bad = [{"k": 0.0}, {"k": "1"}, {**good, "terms": {"coefficients": []}},
           {**good, "terms": {"coefficients": [0.1], "span_s": [0.0]}},
           {**good, "shape": {"mix": [float("nan")]}},
           {**good, "shape": {"mix": [0.1], "toward": {"gradation": 2}}}, []]
    for sky in bad:
        path.write_text(json.dumps({**fit, "sky": sky}))
        with pytest.raises(SkyfitError, match=r"sky must be \{\"k\": a finite number > 0"):
            read_fit_result(path)
    path.write_text(json.dumps({**fit, "sky": good}))
    assert read_fit_result(path)["sky"]["shape"]["toward"]["indicatrix"] == -1
