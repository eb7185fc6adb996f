"""Make the lab example's observation table, ``scenes/lab/observations.csv`` (and its settings,
``observations.json``), from a render of ``scenes/lab/lab_disc.toml``: the disc under twelve
directional lab lights, measured at nine points (a 3 x 3 grid of pixel centres) with 1% noise
by an instrument that clips at 45 W m^-2 sr^-1 (the brightest light's highlight saturates).

    .venv/bin/python scripts/lab_example.py [--render DIR] [--table CSV]

``tests/test_lab.py`` makes the table again the same way and checks it against the shipped one.
"""

import argparse
import tempfile
from pathlib import Path

from skyfit_mi.pipeline.sequence import render_sequence
from skyfit_mi.pipeline.spec import load_spec
from skyfit_testkit.table_sim import measure_table

LAB = Path(__file__).resolve().parents[1] / "scenes" / "lab"
#: The measured pixels (x, y), the noise [relative], its seed, the instrument's clip level
#: [W m^-2 sr^-1].
PIXELS = [(x, y) for y in (3, 8, 12) for x in (3, 8, 12)]
NOISE, SEED, SATURATE = 0.01, 0, 45.0


def make_table(render_dir, table):
    """Render the example spec into ``render_dir`` and measure it into ``table``."""
    render_sequence(load_spec(LAB / "lab_disc.toml"), render_dir, progress=False,
                    log=lambda *a: None)
    return measure_table(render_dir, PIXELS, table, noise=NOISE, seed=SEED, saturate=SATURATE)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--render", type=Path, help="folder for the render (default: a temporary one)")
    ap.add_argument("--table", type=Path, default=LAB / "observations.csv")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        print("wrote", make_table(args.render or Path(tmp) / "render", args.table))


if __name__ == "__main__":
    main()
