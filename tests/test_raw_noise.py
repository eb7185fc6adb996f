"""A developed RAW's noise (skyfit_mi/pipeline/raw_noise.py): the sensor's noise from the mosaic's
CFA planes, the developed noise's variance and correlations by developing the frame again,
against the spread of many frames of one scene, each with its own noise."""

import numpy as np
import pytest

from skyfit_mi.physics.camera import SensorModel
from skyfit_mi.pipeline.ingest import shown_noise
from skyfit_mi.pipeline.photos import read_photo
from skyfit_testkit.photo_sim import (RAW_BITS, RAW_BLACK, _mosaic, colour_matrix_1,
                                      raw_camera_matrix, write_dng)

rawpy = pytest.importorskip("rawpy")
from skyfit_mi.pipeline import raw_noise  # noqa: E402

#: The sensor's read variance [raw DN^2] and shot gain [raw DN per DN]; the frames.
READ, SHOT, FRAMES = 36.0, 0.26, 16


@pytest.fixture(scope="module")
def frames(tmp_path_factory):
    """FRAMES DNGs of one scene (a grey and a saturated blue, each half of 128 x 160 pixels),
    each its own sensor noise, and their developed values."""
    tmp = tmp_path_factory.mktemp("raw_noise")
    a = raw_camera_matrix()
    truth = np.zeros((128, 160, 3))
    truth[:, :80] = 0.3
    truth[:, 80:] = (0.064, 0.12, 0.48)
    clean = _mosaic(truth @ a.T) * (2 ** RAW_BITS - 1 - RAW_BLACK)
    paths = []
    for k in range(FRAMES):
        dn = clean + np.random.default_rng(k).normal(size=clean.shape) * np.sqrt(
            READ + SHOT * clean)
        paths.append(write_dng(tmp / f"{k}.dng", np.rint(dn + RAW_BLACK),
                               colour_matrix_1(np.eye(3), a), a.sum(axis=1)))
    return paths, np.stack([read_photo(p).values.astype(float) for p in paths])


def test_the_sensor_noise_from_the_cfa_planes(frames):
    """Photosites of one colour two pixels apart have independent noise: the frames' planes
    give the sensor's read and shot noise (measured: read 7.6 DN rms for 6, shot 0.252 for
    0.26: the variance at the frames' levels, 1000-4600 DN, within 5%)."""
    planes = [p for path in frames[0][:4] for p in raw_noise.cfa_planes(path)]
    a, b = shown_noise(planes, SensorModel(1.0, "linear", bits=16))
    for level in (1000.0, 4600.0):
        assert a + b * level == pytest.approx(READ + SHOT * level, rel=0.1)


def test_the_bootstrap_gives_the_developed_noise(frames):
    """Developing the frame again with fresh noise gives each pixel's developed variance and
    its correlation with its neighbours as the spread of 16 frames shows them (measured:
    within 5%; adjacent pixels' correlation 0.61 / 0.37 / 0.53 in R / G / B, the frames'
    0.63 / 0.38 / 0.48), where their neighbouring pixels' differences show a fraction."""
    paths, values = frames
    variance, corr, channels = raw_noise.bootstrap(paths[0], (READ, SHOT), [1, 0], values[0])
    spread = np.var(values, axis=0, ddof=1)
    d = values - values.mean(axis=0)
    n = raw_noise.RAW_COLOUR_REACH
    assert corr.shape == (3, 2 * n + 1, 2 * n + 1) and np.allclose(corr[:, n, n], 1.0)
    for cols in (slice(4, 76), slice(84, 156)):                  # the grey; the blue
        inside = (slice(4, -4), cols)
        # the spread of 16 frames: 6% sd per pixel, 0.4% over the half; the bootstrap's mean
        np.testing.assert_allclose(variance[inside].mean(axis=(0, 1)),
                                   spread[inside].mean(axis=(0, 1)), rtol=0.1)
        adjacent = [np.corrcoef(d[:, 4:-4, cols, c].ravel(),
                                d[:, 4:-4, cols.start + 1:cols.stop + 1, c].ravel())[0, 1]
                    for c in range(3)]
        np.testing.assert_allclose(corr[:, n, n + 1], adjacent, atol=0.08)
    assert corr[0, n, n + 1] > 0.5 and np.all(np.abs(channels) < 0.3)
    # what neighbouring pixels differ by, as the noise estimate of other frames reads it
    shown = shown_noise(list(values[:4]), SensorModel(1.0, "linear", bits=16))
    grey = spread[4:-4, 4:76].mean(axis=(0, 1))
    assert shown[0] + shown[1] * 0.3 * 65535 < 0.6 * grey[0]


@pytest.mark.parametrize("offset", [0, 1])
def test_demosaiced_colour_reaches_no_further_than_colour_reach(tmp_path, offset):
    """Saturated paints meeting at straight edges (at an even or odd column, and across the
    rows), photographed as a noise-free RAW and developed as ingest develops it: AHD bleeds
    each paint's colour across the edge -- by a large share of the weak channels beside it --
    but a pixel :func:`colour_mixed` keeps (``colour_reach`` of a frame's ``raw_demosaic``:
    RAW_COLOUR_REACH pixels) develops within 1% of its paint's brightest channel."""
    from skyfit_mi.pipeline.region_edges import colour_mixed, colour_reach

    h, w = 48, 64
    labels = np.ones((h, w), np.int32)
    labels[:, 31 + offset:] = 2
    labels[23 + offset:, :12] = 3
    paint = np.array([[0, 0, 0], [0.70, 0.08, 0.05], [0.08, 0.15, 0.60], [0.85, 0.70, 0.08]])
    a = raw_camera_matrix()
    scene = 0.5 * paint[labels]
    dn = _mosaic(scene @ a.T) * (2 ** RAW_BITS - 1 - RAW_BLACK)
    path = write_dng(tmp_path / "edge.dng", np.rint(dn + RAW_BLACK),
                     colour_matrix_1(np.eye(3), a), a.sum(axis=1))
    developed = read_photo(path).values / 65535.0
    reach = colour_reach({"frames": [{"raw_demosaic": {"colour_reach_px": 2}}, {}]})
    assert reach == raw_noise.RAW_COLOUR_REACH == 2
    err = np.abs(developed - scene).max(axis=-1) / scene.max(axis=-1)
    mixed = colour_mixed(labels, reach)
    inside = np.zeros((h, w), bool)
    inside[3:-3, 3:-3] = True                         # LibRaw's own border
    assert err[mixed & inside].max() > 0.05           # the bleed is real
    assert err[~mixed & inside].max() < 0.01, err[~mixed & inside].max()


def test_a_regions_design_effect_counts_its_correlated_neighbours():
    """Kish's design effect of a pixel: 1 plus its error's correlation with each other pixel of
    the region within reach (by hand: a 3 x 3 block, the centre sees 4 edge neighbours at 0.5
    and 4 corners at 0.25; a corner 2 at 0.5, 1 at 0.25 and 2 two away at 0.1); a pixel alone
    keeps 1."""
    from skyfit_mi.fitting.chi2 import neighbour_sharing

    corr = np.zeros((3, 5, 5))
    corr[:, 2, [1, 3]] = corr[:, [1, 3], 2] = 0.5
    corr[:, 1, 1] = corr[:, 1, 3] = corr[:, 3, 1] = corr[:, 3, 3] = 0.25
    corr[:, 2, [0, 4]] = corr[:, [0, 4], 2] = 0.1
    corr[:, 2, 2] = 1.0
    block = [(x, y) for y in (10, 11, 12) for x in (20, 21, 22)]
    deff = neighbour_sharing(block + [(40, 3)], corr)
    np.testing.assert_allclose(deff[4], 4.0)                 # the centre
    np.testing.assert_allclose(deff[0], 2.45)                # a corner
    np.testing.assert_allclose(deff[-1], 1.0)                # alone
