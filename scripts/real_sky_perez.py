"""Why the Perez sky from irradiance loses to the thesis's CIE clear sky on the measured clear
day (Kider et al. 2014; issue 36): each candidate cause on its own, with the figure of merit
of ``scripts/real_sky.py`` (relative rms error of the luminance pattern, one free scale per
scan, 10 degrees about the sun left out; day mean, nominal / rotated scanner frame).

1. the decomposition of the pyranometer's GHI into DHI and DNI (pvlib's models, a clear-sky
   model's DHI, and the DHI integrated from the scans);
2. the clearness bin and Delta: the best the clear bin can do with Delta free, and the air
   mass model and solar constant of Delta;
3. the circumsolar region: the error as more of the sky about the sun is left out, and the
   measured over modelled luminance by angle from the sun;
4. the luminous efficacy: a factor per scan (no effect on a pattern with a free scale); its
   value against the scans' own illuminance over irradiance.

Prints markdown tables.  Data: Kider et al. 2014, github.com/spectralskylight/sky-measurements-2014,
Apache-2.0.

    .venv/bin/python scripts/real_sky_perez.py [--data FOLDER]
"""

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

#: Angles about the sun left out in the sweep of part 3 [degrees].
EXCLUSIONS_DEG = (5.0, 10.0, 15.0, 20.0, 30.0)
#: Bands of angle from the sun for the circumsolar profile [degrees].
PROFILE_BANDS_DEG = (0, 5, 10, 15, 20, 25, 30, 40, 60, 90, 180)


def day_means(scans, model, exclude_deg=None):
    """Day mean of the relative rms error (nominal, rotated) of ``model``."""
    from skyfit_testkit import sky_measurement as sm

    ex = sm.SUN_EXCLUSION_DEG if exclude_deg is None else exclude_deg
    return tuple(float(np.mean([sm.compare(s, model, rot, ex)["relative_rms"] for s in scans]))
                 for rot in (False, True))


def irradiance_model(name, parts, options=None):
    """A SkyModel: the Perez sky of each scan from ``parts[capture] = (dhi, dni)``, with the
    model choices ``options`` (a PerezOptions; default its defaults)."""
    from skyfit_testkit import sky_measurement as sm
    from skyfit_mi.physics.perez import PerezOptions, perez_sky

    options = PerezOptions() if options is None else options

    def luminance(d, scan, _):
        dhi, dni = parts[scan.capture]
        return perez_sky(scan.sun_zenith_deg, scan.sun_azimuth_deg, scan.day_of_year,
                         dhi=dhi, dni=dni, options=options).luminance(d)[None, :]
    return sm.SkyModel(name, luminance, absolute=True)


def decompositions(scans):
    """{name: {capture: (dhi, dni)}} [W m^-2] for the scans' GHI at their sun: pvlib's
    decomposition models, Ineichen's clear-sky DHI and DNI (pvlib's Linke turbidity
    climatology; no measurement), and the DHI integrated from the scan."""
    import pandas as pd
    import pvlib

    from skyfit_testkit import sky_measurement as sm

    times = pd.DatetimeIndex([s.time for s in scans])
    ghi = pd.Series([s.ghi for s in scans], index=times)
    zen = pd.Series([s.sun_zenith_deg for s in scans], index=times)
    cos_z = np.cos(np.radians(zen.to_numpy()))
    out = {}
    for name in ("erbs", "erbs_driesse", "boland", "orgill_hollands", "louche"):
        r = getattr(pvlib.irradiance, name)(ghi, zen, times)
        out[name] = (r["dhi"].to_numpy(), r["dni"].to_numpy())
    dni = {"disc": pvlib.irradiance.disc(ghi, zen, times)["dni"],
           "dirint (one reading)": pvlib.irradiance.dirint(ghi, zen, times,
                                                           use_delta_kt_prime=False),
           "dirint (the 15 scans as a series)": pvlib.irradiance.dirint(ghi, zen, times)}
    for name, b in dni.items():
        b = b.to_numpy()
        out[name] = (ghi.to_numpy() - b * cos_z, b)
    site = pvlib.location.Location(sm.SITE_LATITUDE_DEG, sm.SITE_LONGITUDE_DEG)
    cs = site.get_clearsky(times, model="ineichen")
    out["Ineichen clear sky (not measured)"] = (cs["dhi"].to_numpy(), cs["dni"].to_numpy())
    dhi = np.array([s.dhi_scan for s in scans])
    out["DHI integrated from the scan"] = (dhi, (ghi.to_numpy() - dhi) / cos_z)
    return {name: {s.capture: (float(h), float(n)) for s, h, n in zip(scans, *v)}
            for name, v in out.items()}


def markdown(rows):
    head = list(rows[0])
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(str(r[k]) for k in head) + " |" for r in rows]
    return "\n".join(lines)


def span(values, fmt):
    return f"{fmt.format(min(values))}-{fmt.format(max(values))}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=None,
                    help="data folder (default: as scripts/real_sky.py)")
    args = ap.parse_args()

    import pandas as pd

    from skyfit_mi.physics import perez as pz
    from skyfit_testkit import sky_measurement as sm

    scans = sm.load_scans(args.data)
    models = {m.name: m for m in sm.MODELS}
    thesis = day_means(scans, models["cie_clear_thesis"])
    print(f"Data: {sm.CITATION}.\n\nthesis's CIE clear sky: {thesis[0]:.3f} / {thesis[1]:.3f} "
          "(day mean, nominal / rotated)\n")

    print("### 1. Decomposition of the GHI\n")
    parts = decompositions(scans)
    rows = []
    for name, p in parts.items():
        skies = [pz.perez_sky(s.sun_zenith_deg, s.sun_azimuth_deg, s.day_of_year,
                              dhi=p[s.capture][0], dni=p[s.capture][1]).info for s in scans]
        err = day_means(scans, irradiance_model(name, p))
        rows.append({"source of DHI, DNI": name,
                     "DHI [W m^-2]": span([i["dhi_w_m2"] for i in skies], "{:.0f}"),
                     "epsilon": span([i["epsilon"] for i in skies], "{:.2f}"),
                     "bins (1-8)": ", ".join(sorted({str(i["clearness_bin"] + 1)
                                                     for i in skies})),
                     "Delta": span([i["delta"] for i in skies], "{:.3f}"),
                     "day mean, nominal / rotated": f"{err[0]:.3f} / {err[1]:.3f}"})
    print(markdown(rows))

    print("\n### 2. Clearness bin and Delta\n")
    rows = []
    for lo in pz.CLEARNESS_BIN_EDGES[:-1]:
        grid = tuple(p for p in sm.PEREZ_SHAPE_GRID if p[0] == lo)
        fit = replace(models["perez_fit"], parameters=grid)
        runs = sm.run_comparison(scans, (fit,))
        by = runs.groupby(["held_out", "rotated"])
        err = by["relative_rms"].mean()
        delta = by["parameter"].agg(lambda p: span(p.str.split().str[1].astype(float), "{:g}"))
        rows.append({"bin (epsilon from)": f"{int(pz.clearness_bin(lo)) + 1} ({lo:g})",
                     "Delta fitted per scan, nominal / rotated":
                         f"{err[False, False]:.3f} / {err[False, True]:.3f}",
                     "held out": f"{err[True, False]:.3f} / {err[True, True]:.3f}",
                     "held-out Delta": f"{delta[True, False]} / {delta[True, True]}"})
    print(markdown(rows))
    scan_parts = parts["DHI integrated from the scan"]
    rows = [{"Delta of the scan's DHI": label,
             "day mean, nominal / rotated": "{:.3f} / {:.3f}".format(*day_means(
                 scans, irradiance_model(label, scan_parts, options)))}
            for label, options in (("Kasten-Young air mass, E0 from 1367 W m^-2 (default)",
                                    pz.PerezOptions()),
                                   ("Kasten 1966 air mass",
                                    pz.PerezOptions(airmass_model="kasten1966")))]
    print("\n" + markdown(rows))

    print("\n### 3. The circumsolar region\n")
    compared = ("cie_clear_thesis", "perez_erbs", "perez_scan")
    rows = []
    for ex in EXCLUSIONS_DEG:
        row = {"left out about the sun [deg]": f"{ex:g}"}
        for name in compared:
            e = day_means(scans, models[name], ex)
            row[name] = f"{e[0]:.3f} / {e[1]:.3f}"
        rows.append(row)
    print(markdown(rows))
    print("\nmedian measured / model luminance by angle from the sun, scanner rotation "
          "applied, scale fitted on points >= 30 deg from the sun:\n")
    recs = []
    for s in scans:
        d = s.directions(True)
        zeta = sm.angle_to_sun_deg(d, s.sun_direction)
        far = zeta >= 30.0
        for name in compared:
            m = models[name].luminance(d, s, [None])[0]
            k = sm.scale_factor(m[far], s.luminance[far])
            recs += [{"model": name, "zeta": z, "ratio": r}
                     for z, r in zip(zeta, s.luminance / (k * m))]
    df = pd.DataFrame(recs)
    band = pd.cut(df["zeta"], PROFILE_BANDS_DEG)
    prof = df.groupby([band, "model"], observed=True)["ratio"].median().unstack()
    prof = prof[list(compared)].round(2)
    prof.insert(0, "points", df[df["model"] == compared[0]].groupby(
        band, observed=True).size())
    prof.index = [f"{b.left:g}-{b.right:g}" for b in prof.index]
    print(markdown(prof.rename_axis("angle from the sun [deg]").reset_index()
                   .to_dict("records")))

    print("\n### 4. Luminous efficacy (Perez 1990) against the scans' own\n")
    rows = []
    for s in scans:
        eff = {src: pz.perez_sky(s.sun_zenith_deg, s.sun_azimuth_deg, s.day_of_year,
                                 **sm.perez_inputs(s, src)).efficacy for src in ("erbs", "scan")}
        rows.append({"time": s.label, "Perez, Erbs [lm/W]": f"{eff['erbs']:.1f}",
                     "Perez, the scan's DHI [lm/W]": f"{eff['scan']:.1f}",
                     "scan: illuminance / irradiance [lm/W]":
                         f"{s.diffuse_illuminance_scan / s.dhi_scan:.1f}",
                     "level measured / Perez (scan's DHI)":
                         f"{sm.compare(s, models['perez_scan'])['scale']:.2f}"})
    print(markdown(rows))


if __name__ == "__main__":
    main()
