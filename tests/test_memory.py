"""A fit's memory is bounded whatever its points x frames: the light is traced and tabulated in
blocks (render/basis_table.py), so its samples never all exist at once.

Each fit runs in its own process, whose peak resident memory (``VmHWM``) is measured."""

import json
import os
import subprocess
import sys

import pytest

CHILD = r"""
import json, sys
import numpy as np
from skyfit_mi.render import basis_table
from skyfit_mi.fitting.fit import FitCache, FitSession
from skyfit_mi.pipeline.pixels import material_regions

day, count, budget = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
basis_table.CHUNK_SAMPLES = budget
pixels = dict(material_regions(day))["disc"][:count]
s = FitSession(day, "disc", pixels, model="colour", cache=FitCache(16, 256))
r = s.run(log=lambda *a: None)
# the process's own high-water mark (ru_maxrss would carry the forking parent's across exec)
hwm = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM:"))
print(json.dumps({"peak_MB": hwm / 1024,
                  "blocks": s.cache_settings["blocks"], "chi2_per_dof": r["chi2_per_dof"],
                  "samples": len(pixels) * len(s.obs.frames) * 16 * 256}))
"""


def _fit(day, count, budget):
    out = subprocess.run([sys.executable, "-c", CHILD, str(day), str(count), str(budget)],
                         capture_output=True, text=True, env=dict(os.environ), check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(sys.platform != "linux", reason="VmHWM is Linux's /proc")
def test_a_fit_of_many_samples_stays_within_a_small_budget(days):
    """64 pixels x 13 frames x 4096 samples (3.4 million; about 0.35 GB as one cache and its
    Dr.Jit copies) in blocks of 2^18 samples: the peak stays within 150 MB of a one-pixel
    fit's, and well under the one-block fit's."""
    small = _fit(days["clean"], 1, 1 << 18)
    blocks = _fit(days["clean"], 64, 1 << 18)
    whole = _fit(days["clean"], 64, 1 << 30)
    assert blocks["samples"] == 64 * 13 * 4096 and blocks["blocks"] >= 13 and whole["blocks"] == 1
    assert blocks["peak_MB"] - small["peak_MB"] < 150, (small, blocks)
    assert whole["peak_MB"] - blocks["peak_MB"] > 150, (blocks, whole)
