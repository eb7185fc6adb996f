"""Simulated annealing on chi-square surfaces with known minima (thesis 6.4.4, 7.3)."""
import numpy as np
import pytest

from skyfit_mi.fitting.methods.annealing import on_bounds, simulated_annealing


class _Toy:
    """A chi^2 function of the parameters, shaped like skyfit's problems for the annealer."""

    class obs:
        y = np.zeros((1, 1, 3))                         # one pixel: temperatures as the thesis's

    def __init__(self, f):
        self.chi2 = f


def _valley(x):
    """Minimum on the bound x1 = 0, behind a valley 0.002 wide (like an ideal mirror among
    rough lobes), and a broad local minimum at x1 = 0.2."""
    a, s = x
    return 100.0 * (a - 0.3) ** 2 + min(1000.0 * min(s / 0.002, 1.0), 50.0 + 2000.0 * (s - 0.2) ** 2)


def test_annealing_reaches_a_minimum_on_the_bound():
    lower, upper = np.zeros(2), np.array([1.0, 0.5])
    for seed in range(3):
        r = simulated_annealing(_Toy(_valley), np.array([0.9, 0.4]), lower, upper, seed=seed,
                                schedule=(1e3, 0.7, 10))
        assert r["theta"][1] == 0.0 and r["theta"][0] == pytest.approx(0.3, abs=1e-3)



def test_on_bounds_moves_parameters_onto_faces_edges_and_corners():
    x, lo, hi = np.array([0.3, 0.6, 0.1]), np.zeros(3), np.array([1.0, 1.0, 0.5])
    single = on_bounds(x, lo, hi)
    assert len(single) == 6
    assert all(np.sum(p != x) == 1 for p in single)
    faces = on_bounds(x, lo, hi, every_face=True)
    assert len(faces) == 26 and len({tuple(p) for p in faces}) == 26
    assert any(np.array_equal(p, [1.0, 1.0, 0.0]) for p in faces)       # the white mirror's corner


def _corner_well(x):
    """A broad basin at (0.14, 0.55, 0.23) and the global minimum in the corner (1, 1, 0),
    in a well about 0.02 x 0.02 x 0.01 wide, as for the achromatic mirror of table 7.9."""
    broad = 1e3 + 1e4 * np.sum((x - [0.14, 0.55, 0.23]) ** 2)
    well = 1e3 * np.sum(((x - [1.0, 1.0, 0.0]) / [0.02, 0.02, 0.01]) ** 2)
    return float(min(broad, well))


def test_annealing_finds_a_narrow_well_in_a_corner_of_the_box():
    lower, upper = np.zeros(3), np.array([1.0, 1.0, 0.5])
    for seed in range(3):
        r = simulated_annealing(_Toy(_corner_well), np.array([0.2, 0.3, 0.4]), lower, upper,
                                seed=seed)
        assert np.allclose(r["theta"], [1.0, 1.0, 0.0], atol=1e-4), r["theta"]


def _rule(x):
    """Two branches split at x0 = 0.5, like the colour model's metal and plastic rules: on
    the metal side a broad basin whose minimum lies on the rule (x0 = 0.5, x1 = 0.8), on the
    plastic side the global minimum (0.2, 0.3), whose basin is small and across a jump
    (chi^2 >= 250 on the plastic side at the metal minimum's x1)."""
    if x[0] >= 0.5:
        return float(10.0 + 1e3 * (x[1] - 0.8) ** 2 + 1e2 * (x[0] - 0.5) ** 2)
    return float(1e4 * ((x[0] - 0.2) ** 2 + (x[1] - 0.3) ** 2))


def test_annealing_cools_again_from_the_alternative_readings():
    lower, upper = np.zeros(2), np.ones(2)
    twin = lambda x: [np.array([0.25, 0.33])]           # chi^2 = 34 there: worse than 10
    alone = [simulated_annealing(_Toy(_rule), np.array([0.9, 0.9]), lower, upper, seed=seed)
             for seed in range(3)]
    assert any(abs(r["theta"][0] - 0.5) < 1e-3 for r in alone)     # the metal minimum traps
    for seed in range(3):
        r = simulated_annealing(_Toy(_rule), np.array([0.9, 0.9]), lower, upper, seed=seed,
                                alternatives=twin)
        assert np.allclose(r["theta"], [0.2, 0.3], atol=1e-4), r["theta"]
        assert r["schedule"]["reanneals"] == 1         # a further cooling cycle from the best
        assert r["schedule"]["descents"] == 1          # the twin, tried once


def _two_plastic_basins(x):
    """The rule of :func:`_rule` with a second, broad plastic basin (chi^2 100 at (0.15, 0.05)).
    The global minimum (chi^2 0 at (0.2, 0.6)) is the twin of the metal minimum (0.5, 0.8), but
    the twin of the broad basin is a metal point: as in table 7.10's failing start, whose first
    freeze was a plastic mirror reading (sigma_alpha = 0)."""
    if x[0] >= 0.5:
        return float(10.0 + 1e3 * (x[1] - 0.8) ** 2 + 1e2 * (x[0] - 0.5) ** 2)
    broad = 100.0 + 1e3 * ((x[0] - 0.15) ** 2 + (x[1] - 0.05) ** 2)
    return float(min(broad, 1e5 * ((x[0] - 0.2) ** 2 + (x[1] - 0.6) ** 2)))


def test_annealing_descends_from_the_alternatives_of_every_new_best_point():
    lower, upper = np.zeros(2), np.ones(2)
    twin = lambda x: [np.array([0.5, x[1]]) if x[0] < 0.5 else np.array([0.2, 0.75 * x[1]])]
    # trying only the first freeze's twin ended at the metal minimum from 2 of these 10 runs
    for start in ([0.1, 0.1], [0.9, 0.9]):
        for seed in range(5):
            r = simulated_annealing(_Toy(_two_plastic_basins), np.array(start), lower, upper,
                                    seed=seed, alternatives=twin)
            assert np.allclose(r["theta"], [0.2, 0.6], atol=1e-4), (start, seed, r["theta"])
            assert r["status"] == "converged"           # also at chi^2 = 0
