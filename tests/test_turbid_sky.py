"""The turbid clear sky (skyfit_mi/physics/turbid_sky.py): Preetham's pattern, Ineichen and
Perez's levels, the spec's [sky] type 'turbid' and its shape variants."""
import numpy as np
import pytest

from skyfit_mi.errors import SkyfitError
from skyfit_mi.fitting.light import LightOptions
from skyfit_mi.physics import sky_shape
from skyfit_mi.physics.colour import SRGB_LUMINANCE
from skyfit_mi.physics.turbid_sky import (TURBIDITY_RANGE, coefficients, levels, shape_moves,
                                          turbid_sky)


def test_preethams_coefficients_are_linear_in_the_turbidity():
    """Appendix A.2 of Preetham et al. 1999 by hand: at T = 2, A = 0.1787 x 2 - 1.4630 =
    -1.1056, B = -0.2833, C = 5.2797, D = -2.3359, E = 0.2363; at T = 5, B = -1.3495."""
    np.testing.assert_allclose(coefficients(2.0), [-1.1056, -0.2833, 5.2797, -2.3359, 0.2363],
                               atol=1e-12)
    assert coefficients(5.0)[1] == pytest.approx(-1.3495, abs=1e-12)
    np.testing.assert_allclose(coefficients([2.0, 5.0]), [coefficients(2.0), coefficients(5.0)])
    for bad in (TURBIDITY_RANGE[0] - 0.1, TURBIDITY_RANGE[1] + 0.1, float("nan")):
        with pytest.raises(SkyfitError, match="turbidity"):
            coefficients(bad)


def test_the_levels_are_ineichen_and_perez_s():
    """With the sun at the zenith at sea level (air mass 1), Ineichen and Perez 2002 give
    DNI = b I0 exp(-0.09 (T_L - 1)), b = 0.664 + 0.163 = 0.827 (their eq. 8 with fh1 = 1);
    by hand at T_L 3 and 5.  Haze moves light from the sun's beam into the sky, the more the
    lower the sun (the beam's longer path), and nothing is left with the sun below the
    horizon."""
    import pvlib.irradiance

    i0 = float(pvlib.irradiance.get_extra_radiation(172))
    for t in (3.0, 5.0):
        dni, dhi = levels(t, 0.0, 172)
        assert dni == pytest.approx(0.827 * i0 * np.exp(-0.09 * (t - 1.0)), rel=2e-3)
        assert dhi > 0
    for z in (20.0, 50.0, 75.0):
        (dni3, dhi3), (dni5, dhi5) = levels(3.0, z, 172), levels(5.0, z, 172)
        assert dni5 < dni3 and dhi5 > dhi3
    ratio = [levels(5.0, z, 172)[0] / levels(3.0, z, 172)[0] for z in (20.0, 50.0, 75.0)]
    assert ratio[0] > ratio[1] > ratio[2]
    assert levels(3.0, 95.0, 172) == (0.0, 0.0)
    # a higher site sees more of the sun
    assert levels(3.0, 40.0, 172, elevation_m=2000.0)[0] > levels(3.0, 40.0, 172)[0]


def test_a_turbid_sky_carries_its_levels_and_its_pattern():
    """The sky's luminance-weighted horizontal irradiance is the model's diffuse irradiance,
    the sun's disc its direct normal, the ground a Lambertian reflector of both; the radiance
    follows Preetham's pattern (ratios between directions as the Perez form's)."""
    from skyfit_mi.physics.sky import perez_pattern

    sky = turbid_sky(4.0, 35.0, 160.0, day=172)
    dni, dhi = levels(4.0, 35.0, 172)
    assert float(sky.sky_horizontal_irradiance() @ SRGB_LUMINANCE) == pytest.approx(dhi,
                                                                                     rel=1e-6)
    assert float(sky.sun_radiance @ SRGB_LUMINANCE) * sky.sun_solid_angle == pytest.approx(
        dni, rel=1e-9)
    np.testing.assert_allclose(sky.ground, 0.2 * sky.horizontal_irradiance() / np.pi)
    d = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, 0.96, 0.28]])
    want = perez_pattern(d, sky.sun_direction, coefficients(4.0))
    got = sky.sky_radiance(d) @ SRGB_LUMINANCE
    np.testing.assert_allclose(got / got[0], want / want[0], rtol=1e-9)
    assert sky.info["kind"] == "turbid" and sky.info["turbidity"] == 4.0
    night = turbid_sky(4.0, 100.0, 160.0)
    assert not night.lit_by_sky and not np.any(night.sun_radiance)
    assert not turbid_sky(4.0, 35.0, 160.0, sun=False).sun_radiance.any()


def test_a_turbid_skys_shape_variant_keeps_its_light_and_moves_one_step():
    """--sky-shape mixes the pattern one turbidity step on (down at the range's top), lit
    with the sky's own horizontal irradiance channel by channel."""
    sky = turbid_sky(3.0, 35.0, 160.0)
    (label, variant), = sky_shape.shape_variants(sky)
    assert label == "turbidity T 3 -> 4"
    np.testing.assert_allclose(variant.perez_coefficients, coefficients(4.0))
    np.testing.assert_allclose(variant.sky_horizontal_irradiance(),
                               sky.sky_horizontal_irradiance(), rtol=1e-9)
    assert not variant.sun_radiance.any()
    top = turbid_sky(TURBIDITY_RANGE[1], 35.0, 160.0)
    assert [lab for lab, _ in sky_shape.shape_variants(top)] == [
        f"turbidity T {TURBIDITY_RANGE[1]:g} -> {TURBIDITY_RANGE[1] - 1:g}"]
    assert shape_moves({"turbidity": TURBIDITY_RANGE[0]})[0]["moves"][-1] is None


def test_a_fitted_turbidity_moves_both_levels_and_a_shaped_sky_takes_them():
    """level_factors at mix 0 leave each frame's light as it is; at mix 1 they are the
    levels of the variant's turbidity over the spec's, the sun's falling more for the lower
    sun; a turbid sky shaped at that mix lights its sun and sky at them."""
    from skyfit_mi.physics.turbid_sky import level_factors

    skies = [turbid_sky(3.0, z, 120.0, day=200) for z in (20.0, 50.0, 75.0)]
    variants = [sky_shape.shape_variants(s)[0][1] for s in skies]
    infos, vinfos = [s.info for s in skies], [v.info for v in variants]
    np.testing.assert_allclose(level_factors(infos, vinfos, 0.0), np.ones((2, 3)))
    sun, sky = level_factors(infos, vinfos, 1.0)
    for a, b, z in zip(sun, sky, (20.0, 50.0, 75.0)):
        (dni4, dhi4), (dni3, dhi3) = levels(4.0, z, 200), levels(3.0, z, 200)
        assert (a, b) == pytest.approx((dni4 / dni3, dhi4 / dhi3))
    assert sun[0] > sun[1] > sun[2] and np.all(sky > 1)
    shaped = sky_shape.shaped(skies[1], 0.9, [1.0], [variants[1]], rows=32)
    np.testing.assert_allclose(shaped.sun_radiance, skies[1].sun_radiance * sun[1])
    want = 0.9 * sky[1] * float(variants[1].sky_horizontal_irradiance() @ SRGB_LUMINANCE)
    got = float(shaped.sky_horizontal_irradiance() @ SRGB_LUMINANCE)
    assert got == pytest.approx(want, rel=0.02)        # the map's cells, a 32-row table


def test_a_spec_takes_a_turbid_sky_and_says_what_is_wrong_in_one_line(tmp_path):
    """[sky] type = 'turbid' with its turbidity lights each frame by the site's sun and
    elevation; a missing or out-of-range turbidity, or another type's key, is one SpecError
    naming the fix."""
    from skyfit_mi.pipeline.spec import SpecError, thesis_disc_spec, validate_spec

    raw = thesis_disc_spec("turbid", {"model": "two", "rho_s": 0.5, "sigma_alpha": 0.1})
    raw["sky"] = {"type": "turbid", "turbidity": 4.5}
    raw["location"]["elevation_m"] = 1500.0
    spec = validate_spec(raw, tmp_path)
    skies = [f.sky for f in spec.frames]
    warm = validate_spec({**raw, "sky": {**raw["sky"], "cct": 9000.0}}, tmp_path).frames[6].sky
    assert not np.allclose(warm.perez / warm.perez.sum(), skies[6].perez / skies[6].perez.sum())
    assert all(s.info["kind"] == "turbid" and s.info["turbidity"] == 4.5 for s in skies)
    noon = min(skies, key=lambda s: s.info["sun_zenith_deg"])
    dni, _ = levels(4.5, noon.info["sun_zenith_deg"], 172, elevation_m=1500.0)
    assert noon.info["direct_normal_W_m2"] == pytest.approx(dni)
    for sky, match in (({"type": "turbid"}, "needs turbidity"),
                       ({"type": "turbid", "turbidity": 12}, "outside"),
                       ({"type": "turbid", "turbidity": 3, "cie_type": 12}, "cie_type"),
                       ({"type": "clear", "turbidity": 3}, "only type = 'turbid'")):
        with pytest.raises(SpecError, match=match) as err:
            validate_spec({**raw, "sky": sky}, tmp_path)
        assert "\n" not in str(err.value)


def test_a_turbid_skys_turbidity_is_fitted_with_the_materials(mi, tmp_path):
    """The sphere in tests/measured_light.py's paint under a turbid sky of T 4.5, in a copy
    whose manifest names T 3, its sun too (13-25% too bright over the day, which the spec's
    sky as it is puts into C: 0.543, 0.537-0.550, truth 0.6): ``--sky fit --sky-shape``
    moves the sun's level and the sky's with the fitted turbidity, whose 95% interval holds
    4.5; the sky's level k over that holds 1, and every material parameter's interval holds its
    truth, with warnings that C depends on the sky.  5 frames, a quarter of the sphere's
    pixels: about 15 s."""
    import datetime as dt

    from measured_light import MATERIAL, TRUTH, relabelled

    from skyfit_mi.fitting.fit import fit_regions
    from skyfit_mi.pipeline.pixels import material_regions
    from skyfit_mi.pipeline.sequence import render_sequence
    from skyfit_mi.pipeline.spec import thesis_disc_spec, validate_spec

    raw = thesis_disc_spec("turbid-sphere", MATERIAL, size=16, noise_percent=2.0, spp=256,
                           seed=11)
    raw["scene"], raw["materials"] = {"file": "sphere.xml"}, {"sphere": dict(MATERIAL)}
    raw["camera"].update({"distance": 6.0, "fov_deg": 22.0, "target": [0.0, 0.0, 1.0]})
    raw["time"] = {"date": raw["time"]["date"], "times": ["09:00", "11:00", "12:00", "13:00",
                                                          "15:00"]}
    raw["sky"] = {"type": "turbid", "turbidity": 4.5}
    render_sequence(validate_spec(raw, tmp_path), tmp_path / "truth", progress=False,
                    log=lambda *a: None)

    def spec_sky(frame, truth):
        return turbid_sky(3.0, frame["sun_zenith_deg"], frame["sun_azimuth_deg"],
                          day=dt.datetime.fromisoformat(frame["time"]).timetuple().tm_yday)
    day = relabelled(tmp_path / "truth", tmp_path / "spec", spec_sky)
    (_, pixels), = material_regions(day)
    logs = []
    r = next(fit_regions(day, [("sphere", pixels[pixels.sum(axis=1) % 2 == 0][::2])],
                         model="colour", light=LightOptions(sky="fit", shape=True, terms=1),
                             log=logs.append))
    assert any("turbidity T" in x and "puts the sun's light at 0." in x for x in logs), logs
    assert r["sky"]["shape"]["variants"] == ["turbidity T 3 -> 4"]
    index, half = r["sky"]["shape"]["index"]["turbidity"]
    assert abs(index - 4.5) <= half, r["sky"]["shape"]
    lo, hi = r["sky"]["interval95"]
    assert lo < 1.0 < hi, r["sky"]
    levels_by_frame = r["sky"]["shape"]["levels_by_frame"]
    sun = [levels_by_frame["frames"][i]["sun"] for i in r["frames"]]
    assert all(0.7 < a < 0.95 for a in sun) and sun[0] < max(sun), levels_by_frame
    assert any(w.startswith("C_r") and " on the sky: " in w for w in r["warnings"]), r["warnings"]
    for p, v in zip(("C_r", "C_g", "C_b", "rho_s", "sigma_alpha"), TRUTH):
        lo, hi = r["intervals"][p]["95"]
        assert lo - 1e-9 <= v <= hi + 1e-9, (p, r["intervals"][p], r["parameters"])
