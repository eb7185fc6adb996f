"""Check the project's sky models against a measured clear sky (issue 15; Kider et al. 2014).

For each of the 15 scans of 2013-05-27 (Ithaca NY) and each sky (the thesis's CIE clear sky,
the CIE S 011 general sky with fitted turbidity-like indices (fitted to each scan, and
fitted to the other scans: a prediction), Perez from the measured irradiance, the Perez
pattern with its clearness bin and brightness fitted (to each scan, and to the other scans),
Mitsuba's sunsky, a uniform sky): the relative rms error of the luminance pattern
with one free scale per scan, points within 10 degrees of the sun left out, in the nominal
scanner frame and turned by the data README's scanner rotation; then measured against
modelled horizontal irradiance.  Prints markdown tables; writes ``errors.csv``,
``irradiance.csv`` and ``errors.png`` to the output folder.

Data: Kider et al. 2014, github.com/spectralskylight/sky-measurements-2014, Apache-2.0.

    .venv/bin/python scripts/real_sky.py [-o out/real_sky] [--data FOLDER] [--no-sunsky]
"""

import argparse
from pathlib import Path

#: Differences in relative rms error below this are not counted as wins (the tables show
#: three decimals; the CIE general sky's type 12 differs from the thesis's sky by ~1e-4).
VISIBLE = 0.001


def markdown(df, floatfmt="{:.3f}"):
    """A pandas DataFrame as a markdown table (index dropped)."""
    cells = [[floatfmt.format(v) if isinstance(v, float) else str(v) for v in row]
             for row in df.itertuples(index=False)]
    head = "| " + " | ".join(map(str, df.columns)) + " |"
    rule = "|" + "---|" * len(df.columns)
    return "\n".join([head, rule] + ["| " + " | ".join(r) + " |" for r in cells])


def plot(results, path, citation):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13.5, 4.5), sharey=True)
    for ax, rotated in zip(axes, (False, True)):
        sub = results[results["rotated"] == rotated]
        for name, g in sub.groupby("model", sort=False):
            thesis = name == "cie_clear_thesis"     # drawn on top: cie_type equals it here
            ax.plot(g["time"], g["relative_rms"], marker="o", ms=3, label=name,
                    color="black" if thesis else None, ls="--" if thesis else "-",
                    zorder=3 if thesis else 2)
        ax.set_title("scanner rotation applied" if rotated else "nominal scanner frame")
        ax.set_xlabel("scan start, EDT (2013-05-27)")
        ax.tick_params(axis="x", rotation=60)
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("relative rms error of the luminance pattern [-]")
    axes[1].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.text(0.01, 0.01, f"Data: {citation}", fontsize=7)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("out/real_sky"),
                    help="output folder for errors.csv, irradiance.csv, errors.png")
    ap.add_argument("--data", type=Path, default=None,
                    help="data folder (default: $SKYFIT_SKY_DATA, else ../shared/data/"
                         "sky-measurements-2014-05-27 beside the repository)")
    ap.add_argument("--no-sunsky", action="store_true",
                    help="leave out Mitsuba's sunsky (no Mitsuba needed)")
    args = ap.parse_args()

    import pandas as pd

    from skyfit_testkit import sky_measurement as sm

    scans = sm.load_scans(args.data)
    models = sm.MODELS
    if not args.no_sunsky:
        from skyfit_testkit.sunsky_reference import sunsky_model

        models = models[:-1] + (sunsky_model(),) + models[-1:]
    results = sm.run_comparison(scans, models)
    args.out.mkdir(parents=True, exist_ok=True)
    results.to_csv(args.out / "errors.csv", index=False, float_format="%.5f")
    names = list(dict.fromkeys(results["model"]))
    labels = {m.name: m.parameter_name for m in models}
    labels.update({sm.held_out_name(m): m.parameter_name for m in models if m.held_out})

    print(f"Data: {sm.CITATION}.\n")
    print("Models:\n")
    for m in models:
        print(f"- `{m.name}`: {m.description}")
    for rotated in (False, True):
        sub = results[results["rotated"] == rotated]
        table = sub.pivot(index="time", columns="model", values="relative_rms")[names]
        best = sm.best_models(sub).set_index("time")
        table["best (not thesis)"] = best["best"]
        table["margin"] = best["margin"]
        sun = pd.DataFrame({"time": [s.label for s in scans],
                            "sun zen/az [deg]": [f"{s.sun_zenith_deg:.1f}/{s.sun_azimuth_deg:.1f}"
                                                 for s in scans]}).set_index("time")
        print(f"\n### Relative rms error per scan, "
              f"{'scanner rotation applied' if rotated else 'nominal scanner frame'}\n")
        print(markdown(sun.join(table).reset_index()))
        ref = table["cie_clear_thesis"]
        better = {n: int((table[n] <= ref - VISIBLE).sum()) for n in names}
        summary = pd.DataFrame({"model": names, "day mean": [table[n].mean() for n in names],
                                f"scans better than the thesis's sky by >= {VISIBLE}":
                                    [f"{better[n]} of {len(ref)}" for n in names]})
        print("\n" + markdown(summary))
        fitted = sub[sub["parameter"] != ""].pivot(index="time", columns="model",
                                                   values="parameter")
        fitted.columns = [f"{n} ({labels[n]})" for n in fitted.columns]
        print("\nfitted parameters:\n")
        print(markdown(fitted.reset_index()))
        levels = sub[sub["absolute"]].pivot(index="time", columns="model", values="scale")
        print("\nlevel ratio measured / model (absolute models; geometric mean over the "
              "compared points):\n")
        print(markdown(levels.reset_index(), "{:.2f}"))
        wins = int((best["margin"] > 0).sum())
        print(f"\nbest sky other than the thesis's beats it on {wins} of {len(best)} scans "
              f"(smallest margin {best['margin'].min():.3f}).")
        fitted_here = [m.name for m in models if m.held_out]
        predicted = sm.best_models(sub[~sub["model"].isin(fitted_here)])
        wins = int((predicted["margin"] > 0).sum())
        print(f"\nbest sky whose parameters are not fitted to the scored scan "
              f"({', '.join(sorted(set(predicted['best'])))}) beats it on {wins} of "
              f"{len(predicted)} scans (smallest margin {predicted['margin'].min():.3f}).")

    irr = pd.DataFrame([{"time": s.label, **sm.irradiance_comparison(s)} for s in scans])
    irr.to_csv(args.out / "irradiance.csv", index=False, float_format="%.2f")
    print("\n### Horizontal irradiance [W m^-2] and diffuse illuminance [lx]\n")
    shown = irr.assign(cie_ghi_ratio=irr["cie_ghi_ratio"].map("{:.3f}".format))
    print(markdown(shown, "{:.0f}"))
    print("\nratio CIE clear GHI / measured: mean "
          f"{irr['cie_ghi_ratio'].mean():.3f} (range {irr['cie_ghi_ratio'].min():.3f}-"
          f"{irr['cie_ghi_ratio'].max():.3f})")
    plot(results, args.out / "errors.png", sm.CITATION)
    print(f"\nwrote {args.out / 'errors.csv'}, {args.out / 'irradiance.csv'}, "
          f"{args.out / 'errors.png'}")


if __name__ == "__main__":
    main()
