"""A fit's outputs: ``fit_NAME.json``, the observed/model plot (thesis fig. 7.14), ``fits.csv``."""

import csv
import io
import json
from pathlib import Path

import numpy as np

from ..errors import SkyfitError
from ..files import save_figure, write_json, write_text
from ..pipeline.fit_result import SUMMARY_NAME, read_fit_result
from ..pipeline.manifest import frame_axis


def write_fit(result, prefix):
    """Write ``<prefix>.png`` (observed vs model; annealing's walk), then ``<prefix>.json``,
    which marks the fit done (an interrupted write leaves none); returns their paths (JSON
    first)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    prefix = Path(prefix)
    t, t_label = frame_axis(result["frames"], result["series"]["times"])
    y = np.asarray(result["series"]["observed_DN"])
    m = np.asarray(result["series"]["model_DN"])
    walk = np.asarray(result.get("trace") or [])
    if len(walk) > 1:                     # the annealing walk beside the series (thesis fig. 7.10)
        fig, (ax, ax_w) = plt.subplots(1, 2, figsize=(11, 4), gridspec_kw={"width_ratios": [7, 4]})
        names = list(result["parameters"])
        i, j = names.index("rho_s"), names.index("sigma_alpha")
        ax_w.plot(walk[:, i], walk[:, j], "-", color="0.5", lw=0.8)
        ax_w.plot(*walk[0, [i, j]], "s", color="k", label="start")
        ax_w.plot(*walk[-1, [i, j]], "*", color="r", ms=10, label="end")
        ax_w.set_xlabel("rho_s")
        ax_w.set_ylabel("sigma_alpha")
        ax_w.set_title(f"annealing walk: lowest vertex, {len(walk) - 1} iterations", fontsize=9)
        ax_w.legend(fontsize=7)
    else:
        fig, ax = plt.subplots(figsize=(7, 4))
    for c, col in enumerate("rgb"):
        ax.plot(t, y[..., c].mean(axis=0), "o", color=col, ms=4, label=f"observed {'RGB'[c]}")
        ax.plot(t, m[..., c].mean(axis=0), "-", color=col, label=f"model {'RGB'[c]}")
    p = result["parameters"]
    ax.set_title(f"{result['region']}: " + ", ".join(f"{k}={v:.3f}" for k, v in p.items()),
                 fontsize=9)
    ax.set_xlabel(t_label)
    ax.set_ylabel("region mean pixel value [DN]")
    ax.legend(fontsize=7, ncol=2)
    for label in ax.get_xticklabels():
        label.set_rotation(30)
        label.set_ha("right")
    fig.tight_layout()
    png = save_figure(fig, prefix.with_suffix(".png"))
    return write_json(prefix.with_suffix(".json"), result), png


def read_fits(folder):
    """The fit results (``fit_*.json``) in ``folder`` by region name; files holding none
    (:func:`read_fit_result` refuses them) are skipped."""
    out = {}
    for p in sorted(Path(folder).glob("fit_*.json")):
        try:
            r = read_fit_result(p)
        except SkyfitError:
            continue
        out[r["region"]] = r
    return out


def _ranking(selection, first=5):
    """``fit --model auto``'s first candidates, with held-out chi2, AIC and BIC, in one cell."""
    if not selection:
        return ""
    return " | ".join(f"{r['rank']} {r['normalisation']}/{r['model']}: held-out chi2 "
                      f"{r['held_out_chi2']:.5g}, AIC {r['aic']:.5g}, BIC {r['bic']:.5g}"
                      for r in selection["ranking"][:first])


def write_summary(folder):
    """Write ``folder/fits.csv`` from its ``fit_*.json`` files (one row per region, sorted);
    returns its path.

    Columns: parameters with 95% intervals and readings, chi2/dof, truth, warnings and
    ``fit --model auto``'s ranking. Units: reflectances unitless, sigma_alpha rms slope, times [s].
    """
    fits = read_fits(folder)
    results = [fits[k] for k in sorted(fits)]

    names = list(dict.fromkeys(n for r in results for n in r["parameters"]))
    cols = ["region", "model", "normalisation", "method", "pixels_fitted", "pixels_total"]
    for n in names:
        cols += [n, f"{n}_95_lo", f"{n}_95_hi"]
    cols += ["readings", "chi2_per_dof", "evaluations", "wall_time_s", "truth", "warnings",
             "model_ranking"]
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(cols)
    for r in results:
        n = len(r.get("pixels") or r.get("points") or [])    # pixels, or a table's points
        row = [r["region"], r["model"], r.get("normalisation", "ward"), r["method"], n,
               r.get("region_pixels_total", n)]
        for n in names:
            if n in r["parameters"]:
                row += [f"{r['parameters'][n]:.5f}", *(f"{v:.5f}" for v in r["intervals"][n]["95"])]
            else:
                row += ["", "", ""]
        row += [" | ".join(r.get("readings", [])),
                f"{r['chi2_per_dof']:.4g}", r["evaluations"], f"{r['wall_time_s']:.2f}",
                json.dumps(r["truth"]) if r.get("truth") else "", " | ".join(r["warnings"]),
                _ranking(r.get("model_selection"))]
        w.writerow(row)
    return write_text(Path(folder) / SUMMARY_NAME, buf.getvalue())
