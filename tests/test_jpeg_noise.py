"""A JPEG's effect on a photograph's noise (skyfit_mi.pipeline.jpeg_noise; issue 15).

Smooth frames (shaded patches of a grey and a red, read and shot noise in linear codes, 8-bit
sRGB) are compressed as cameras do; each pixel's sigma must describe its decoded value's error
about the noise-free codes: the rms of (decoded - clean) / sigma near 1.  The tables' bound
(every coefficient rounded with a uniform error), used before, gave 0.3-0.6 at quality 95.
"""

import io

import numpy as np
import pytest
from PIL import Image

from skyfit_mi.physics.camera import SensorModel
from skyfit_mi.pipeline import jpeg_noise as jn
from skyfit_mi.pipeline.ingest import estimate_noise, pixel_sigma, shown_noise

SENSOR = SensorModel(1.0, response="srgb", bits=8)
NOISE = (0.64, 0.02)                     # read [DN^2] and shot [DN] of the linear codes
SEAM = 99                                # the column where the patches meet (inside a block)


def _frames(quality, subsampling, n=3, seed=0):
    """n frames (128x192) of two smooth patches (grey, red) under a falloff, meeting inside a
    JPEG block, their clean codes and the JPEG files' settings."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:128, 0:192] / 128.0
    shade = 1.0 - 0.25 * ((xx - 0.75) ** 2 + (yy - 0.5) ** 2)
    colour = np.where((xx < SEAM / 128.0)[..., None], [0.35, 0.33, 0.31], [0.55, 0.10, 0.08])
    frames, clean, settings = [], [], []
    for level in np.linspace(0.5, 1.0, n):
        lin = level * 255.0 * shade[..., None] * colour
        clean.append(SENSOR.respond(lin / 255.0) * 255.0)
        noisy = lin + rng.normal(size=lin.shape) * np.sqrt(NOISE[0] + NOISE[1] * lin)
        codes = np.clip(np.rint(SENSOR.respond(noisy / 255.0) * 255.0), 0, 255).astype(np.uint8)
        buf = io.BytesIO()
        Image.fromarray(codes).save(buf, format="JPEG", quality=quality, subsampling=subsampling)
        buf.seek(0)
        frames.append(jn.decode(buf.getvalue()))          # as ingest reads a JPEG
        buf.seek(0)
        settings.append(jn.jpeg_settings(buf))
    return frames, clean, settings


def _patch_jpeg(colour, size, seed):
    """A size x size patch of one colour (its codes, before noise) with read and shot noise in
    linear codes, 8-bit sRGB: its codes (uint8) and the JPEG of them (quality 95, 4:4:4)."""
    rng = np.random.default_rng(seed)
    lin = SENSOR.linearise(np.array(colour)) * 255.0 * np.ones((size, size, 3))
    noisy = lin + rng.normal(size=lin.shape) * np.sqrt(NOISE[0] + NOISE[1] * lin)
    codes = np.clip(np.rint(SENSOR.respond(noisy / 255.0) * 255.0), 0, 255).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(codes).save(buf, format="JPEG", quality=95, subsampling=0)
    return codes, buf


def _z(frames, clean, sigmas):
    """rms of (decoded - clean) / sigma per channel, away from the patches' seam and edges."""
    z = [((f - c) / s)[8:-8, 8:-8] for f, c, s in zip(frames, clean, sigmas)]
    keep = np.ones(z[0].shape[:2], bool)
    keep[:, SEAM - 12:SEAM + 12] = False                 # the seam between the patches
    return np.sqrt(np.mean(np.concatenate([x[keep] for x in z]) ** 2, axis=0))


def _sigmas(frames, settings, noise):
    shown = shown_noise(frames, SENSOR)
    return [pixel_sigma(f, SENSOR, noise, {"variance": jn.bootstrap_variance(
        f, s, SENSOR, noise, [jn.SEED, i])[0], "shown": shown, "settings": s})[0]
        for i, (f, s) in enumerate(zip(frames, settings))]


@pytest.mark.parametrize("quality, subsampling", [(100, 0), (95, 0), (95, 2)])
def test_sigma_from_the_estimated_noise_describes_the_decoded_error(quality, subsampling):
    """Measured: z rms 0.95-0.99 at quality 100 (noise 0.641 / 0.020 against 0.64 / 0.02),
    about 1.05-1.2 at 95 (read 0.80-0.83, its shot noise hidden by the compression)."""
    frames, clean, settings = _frames(quality, subsampling)
    warnings = []
    noise = estimate_noise(frames, SENSOR, settings, log=warnings.append)
    z = _z(frames, clean, _sigmas(frames, settings, noise))
    assert np.all((0.85 < z) & (z < 1.25)), (quality, subsampling, z, noise)
    if quality == 100:
        assert noise == pytest.approx(NOISE, rel=0.1) and not warnings


@pytest.mark.parametrize("quality, subsampling", [(90, 1), (85, 2), (75, 0)])
def test_coarser_jpegs_hide_the_noise_but_given_noise_gives_sigma(quality, subsampling):
    """Below quality 95 the frames show a tenth of the noise or less between neighbouring
    pixels: the estimate says it cannot tell it.  With the camera's noise given the sigma
    holds the error (measured z rms 0.8-1.0 at 90, 0.7-0.85 at 85, 0.44-0.69 at 75, where the
    low orders' content is overstated)."""
    frames, clean, settings = _frames(quality, subsampling)
    warnings = []
    estimate_noise(frames, SENSOR, settings, log=warnings.append)
    assert len(warnings) == 1 and "give --noise" in warnings[0]
    z = _z(frames, clean, _sigmas(frames, settings, NOISE))
    assert np.all((0.4 < z) & (z < 1.15)), (quality, subsampling, z)


@pytest.mark.parametrize("quality", [100, 95, 85])
def test_an_edge_inside_a_block_takes_the_tables_bound(quality):
    """Where the patches meet inside a block the JPEG rings, content the bootstrap cannot
    draw: the block is told an edge and its sigma takes the tables' bound, so it holds the
    error there (measured z rms 0.9-0.97 at 100, 0.45-0.55 at 95, 0.55-0.97 at 85 4:4:4).
    Subsampled chroma (4:2:x) also blurs a colour edge by a pixel, which is not modelled:
    pixels beside an edge are kept out of fits (regions are eroded)."""
    frames, clean, settings = _frames(quality, 0)
    sigmas = _sigmas(frames, settings, NOISE)
    z = np.concatenate([((f - c) / sg)[8:-8, SEAM - 4:SEAM + 4].reshape(-1, 3)
                        for f, c, sg in zip(frames, clean, sigmas)])
    assert np.all(np.sqrt(np.mean(z ** 2, axis=0)) < 1.1)
    bound = jn.tables_bound(settings[0])
    assert bound.shape == (3,) and np.all(bound > 0)


def test_settings_round_trip_and_non_jpeg_files(tmp_path):
    frames, _, settings = _frames(90, 2, n=1)
    st = settings[0]
    assert st["subsampling"] == 2 and jn.block_size(st) == 16
    assert set(st["qtables"]) == {0, 1} and all(len(t) == 64 for t in st["qtables"].values())
    # compressing a frame again with its own settings changes it little (same tables)
    again, _ = jn.recompress(frames[0], st, SENSOR, (0.0, 0.0), np.random.default_rng(1))
    assert np.sqrt(np.mean((again - frames[0]) ** 2)) < 1.0
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(tmp_path / "a.png")
    assert jn.jpeg_settings(tmp_path / "a.png") is None


def test_a_draw_of_the_scene_moves_only_the_coefficients_with_content():
    # A flat grey frame keeps only its blocks' means: a draw moves the low orders (mean,
    # gradients, curvature) within their rounding intervals and nothing else.
    from scipy.fft import dctn

    flat = np.full((32, 32, 3), 120.0)
    settings = _frames(75, 0, n=1)[2][0]
    draw = jn.truth_sampler(flat, settings)(np.random.default_rng(2))
    y = (draw - flat) @ np.array([0.299, 0.587, 0.114])
    coeff = dctn(y.reshape(4, 8, 4, 8), axes=(1, 3), norm="ortho")
    high = ~jn.LOW_ORDER[None, :, None, :] & np.ones(coeff.shape, bool)
    assert np.abs(coeff[high]).max() < 1e-9
    q = np.asarray(settings["qtables"][0], float).reshape(8, 8)[None, :, None, :]
    low = np.broadcast_to(jn.LOW_ORDER[None, :, None, :], coeff.shape)
    assert np.all(np.abs(coeff[low]) <= np.broadcast_to(q, coeff.shape)[low] / 2 + 1e-9)
    assert np.abs(coeff[low]).max() > 0.1


def test_the_bootstrap_is_seeded():
    frames, _, settings = _frames(95, 0, n=1)
    a = jn.bootstrap_variance(frames[0], settings[0], SENSOR, NOISE, [7, 0], replicates=2)
    b = jn.bootstrap_variance(frames[0], settings[0], SENSOR, NOISE, [7, 0], replicates=2)
    for x, y in zip(a, b):                           # variance, correlation, mean error
        np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("colour", [(101.4, 94.1, 92.7), (60.3, 80.2, 120.6),
                                    (158.0, 56.0, 51.0)])
def test_the_bootstrap_finds_the_compressions_mean_error(colour):
    """A uniform patch with noise at quality 95: what the compression shifts the mean of the
    patch's linear signal by (its colour conversion and rounding, and its smoothing of the
    noise through the curve; measured up to -0.44% in blue) the bootstrap's mean error takes
    out, to within 0.1% in each channel, also at the dark channels of a red paint (codes
    51-56, where taking out the copies' mean error against their draws in codes, which holds
    the noise's own shift through the curve, biased them high by 0.3-0.7%)."""
    from skyfit_mi.pipeline.ingest import _unbiased

    before, after = [], []
    for seed in (11, 12, 13):
        codes, buf = _patch_jpeg(colour, 96, seed)
        decoded = jn.decode(buf.getvalue())
        _, _, bias = jn.bootstrap_variance(decoded, jn.jpeg_settings(buf), SENSOR, NOISE,
                                           [3, 0])
        sent = SENSOR.linearise(codes.astype(float)).mean(axis=(0, 1))  # what the camera coded
        before.append(SENSOR.linearise(decoded).mean(axis=(0, 1)) / sent - 1.0)
        after.append(SENSOR.linearise(_unbiased(decoded, bias, 255)).mean(axis=(0, 1)) / sent
                     - 1.0)
    before, after = np.mean(before, axis=0), np.mean(after, axis=0)
    assert np.max(np.abs(before)) > 0.001, before              # there is a bias to take out
    assert np.all(np.abs(after) < 0.001), (before, after)


def test_pixels_sharing_a_block_widen_their_sigma(tmp_path):
    """A region's pixels in one 8x8 block share its JPEG errors (correlation rho): a fit
    widens their sigma by sqrt(1 + (k - 1) rho), Kish's design effect; a map (each pixel its
    own fit) does not."""
    from skyfit_mi.fitting.chi2 import block_sharing

    px = np.array([[0, 0], [7, 7], [8, 0], [3, 12], [4, 13], [100, 100]])
    np.testing.assert_array_equal(block_sharing(px), [2, 2, 1, 2, 2, 1])


@pytest.mark.parametrize("subsampling", [0, 1, 2])
@pytest.mark.parametrize("shape", [(48, 64), (49, 71)])
def test_the_float_decoder_agrees_with_libjpeg_to_its_rounding(subsampling, shape):
    """jn.decode against Pillow's libjpeg decode of the same file (odd sizes: the padding of
    the chroma's coding unit unused): they differ by libjpeg's rounding of three planes and of
    R, G, B to whole codes (max ~2.5 DN), not systematically; a grey JPEG stays one channel."""
    rng = np.random.default_rng(3)
    codes = np.clip(rng.normal(120, 20, shape + (3,)), 0, 255).astype(np.uint8)
    for image in (codes, codes[..., 0]):
        buf = io.BytesIO()
        Image.fromarray(image).save(buf, format="JPEG", quality=90, subsampling=subsampling)
        ours = jn.decode(buf.getvalue())
        with Image.open(buf) as im:
            theirs = np.asarray(im, dtype=float).reshape(ours.shape)
        d = ours - theirs
        assert ours.shape[:2] == shape and ours.shape[2] == image.reshape(shape + (-1,)).shape[2]
        assert np.abs(d).max() < 3.0 and np.sqrt(np.mean(d ** 2)) < 1.2
        assert np.all(np.abs(d.mean(axis=(0, 1))) < 0.1)


@pytest.mark.parametrize("colour", [(101.4, 94.1, 92.7), (175.2, 76.4, 69.7), (60.3, 80.2, 120.6)])
def test_a_smooth_patch_decodes_without_a_shared_error(colour):
    """A uniform patch with noise, compressed at quality 95: the noise is gone from the decoded
    planes, so libjpeg's rounding of them to whole codes puts one error on every pixel (measured
    -0.45 DN in blue on the first colour, a grey card's, and +0.46 on the third); decoded in
    floating point the patch's mean error stays within a sixth of a code (measured <= 0.17)."""
    codes, buf = _patch_jpeg(colour, 128, 5)
    err = (jn.decode(buf.getvalue()) - codes).mean(axis=(0, 1))
    assert np.all(np.abs(err) < 0.25), err


def test_a_file_the_decoder_cannot_read_gives_none(tmp_path):
    """Not a JPEG (or a damaged one): None, and the reader falls back to Pillow's codes."""
    assert jn.decode(b"not a jpeg at all") is None
    assert jn.decode(tmp_path / "missing.jpg") is None


def test_a_camera_jpeg_decodes_as_libjpeg_does_to_its_rounding():
    """A JPEG this project did not write (matplotlib's sample photograph, 512x600, 4:2:0):
    decoded in floating point it agrees with libjpeg but for libjpeg's rounding (measured rms
    0.60 DN, mean -0.03 / +0.02 / -0.13) and a few pixels at the gamut's edge, where one
    channel clips at 0 (0.13% differ by more than 3 DN)."""
    import matplotlib.cbook

    path = matplotlib.cbook.get_sample_data("grace_hopper.jpg", asfileobj=False)
    ours = jn.decode(path)
    with Image.open(path) as im:
        theirs = np.asarray(im.convert("RGB"), dtype=float)
    d = ours - theirs
    assert ours.shape == theirs.shape == (600, 512, 3)
    assert np.sqrt(np.mean(d ** 2)) < 0.8 and np.mean(np.abs(d).max(axis=2) > 3) < 0.005
    assert np.all(np.abs(d.mean(axis=(0, 1))) < 0.2)


def test_rgb_coded_and_progressive_jpegs_decode_as_libjpeg_does(tmp_path):
    """A JPEG coded in R, G, B (no YCbCr transform: Adobe's files, written here with jpeglib)
    is taken as it is, not converted from YCbCr (which put it 107 DN rms off); a progressive
    JPEG reads like a baseline one."""
    import jpeglib

    rng = np.random.default_rng(5)
    codes = np.clip(rng.normal(120, 15, (32, 48, 3)) + [0, 60, -60], 0, 255).astype(np.uint8)
    rgb = jpeglib.from_spatial(codes)
    rgb.jpeg_color_space = jpeglib.Colorspace.JCS_RGB
    rgb.write_spatial(str(tmp_path / "rgb.jpg"), qt=95)
    Image.fromarray(codes).save(tmp_path / "progressive.jpg", quality=90, progressive=True)
    for name in ("rgb.jpg", "progressive.jpg"):
        ours = jn.decode(tmp_path / name)
        with Image.open(tmp_path / name) as im:
            theirs = np.asarray(im, dtype=float)
        assert np.sqrt(np.mean((ours - theirs) ** 2)) < 0.8, name


def test_a_jpeg_the_float_decoder_misreads_falls_back_to_libjpeg(tmp_path, monkeypatch):
    """Should the floating-point decoder disagree with libjpeg beyond its rounding (a coding
    it does not follow), the reader keeps libjpeg's codes and says why in the metadata."""
    from skyfit_mi.pipeline import photos

    Image.fromarray(np.full((16, 16, 3), 90, np.uint8)).save(tmp_path / "a.jpg", quality=95)
    monkeypatch.setattr(jn, "decode", lambda path: np.full((16, 16, 3), 200.0))
    photo = photos.read_photo(tmp_path / "a.jpg")
    assert "disagrees with libjpeg by 110 DN rms" in photo.metadata["decoder"]
    assert photo.values.max() < 100


@pytest.mark.parametrize("orientation", range(1, 9))
def test_a_turned_frames_block_grid_is_the_files(orientation):
    """block_offset against the file's blocks carried through the turn itself (odd sizes, so
    every reversed axis moves the grid), and stored() undoes what the reader applied."""
    from skyfit_mi.fitting.chi2 import block_sharing
    from skyfit_mi.pipeline.photos import apply_orientation

    h, w = 21, 30                                          # the file's
    yy, xx = np.mgrid[0:h, 0:w]
    block_of = apply_orientation((yy // 8) * 100 + xx // 8, orientation)    # displayed
    ox, oy = jn.block_offset(orientation, block_of.shape)
    dy, dx = np.mgrid[0:block_of.shape[0], 0:block_of.shape[1]]
    ours = ((dy - oy) // 8) * 1000 + (dx - ox) // 8
    # the same partition of the displayed pixels into blocks
    pairs = {(int(a), int(b)) for a, b in zip(block_of.ravel(), ours.ravel())}
    assert len(pairs) == len(np.unique(block_of)) == len(np.unique(ours))
    px = np.stack([dx.ravel(), dy.ravel()], axis=1)
    counts = np.unique(block_of, return_counts=True)[1]
    np.testing.assert_array_equal(np.sort(block_sharing(px, offset=(ox, oy))),
                                  np.sort(np.repeat(counts, counts)))
    settings = {"orientation": orientation}
    values = np.arange(h * w * 3.0).reshape(h, w, 3)
    np.testing.assert_array_equal(jn.stored(jn.displayed(values, settings), settings), values)


def test_the_bootstrap_of_a_turned_frame_is_the_files_turned():
    """A frame shown turned (EXIF 6, size not a multiple of 8) is bootstrapped in the file's
    layout, where its blocks are: the result is the unturned frame's, turned."""
    from skyfit_mi.pipeline.photos import apply_orientation

    codes, buf = _patch_jpeg((101.4, 94.1, 92.7), 44, 5)
    values = jn.decode(buf.getvalue())[:, :37]
    settings = jn.jpeg_settings(buf)
    plain = jn.bootstrap_variance(values, settings, SENSOR, NOISE, [4, 0], replicates=2)
    turned = jn.bootstrap_variance(apply_orientation(values, 6), {**settings, "orientation": 6},
                                   SENSOR, NOISE, [4, 0], replicates=2)
    for a, b in zip(plain, turned):
        np.testing.assert_array_equal(apply_orientation(a, 6) if np.ndim(a) == 3 else a, b)


@pytest.mark.parametrize("quality, subsampling", [(85, 2), (90, 2), (95, 2)])
def test_shared_error_sd_is_the_error_of_a_region_mean(quality, subsampling):
    """A patch of one colour, photographed again and again at random levels: the error of its
    mean over 4096 pixels (linearised, as fits take it) is the rounding of its blocks' means,
    shared by all of them, not the
    pixels' errors over sqrt(pixels); shared_error_sd (with the pixels' own errors over
    sqrt(pixels)) predicts its size: the measured rms is 0.9-1.06 times it at quality 85
    (4:2:0), where the shared error is 4-7x the independent one; at 95, 1.3-1.6 times (0.04-0.07
    DN: a remainder the rounding of the blocks' means does not explain)."""
    rng = np.random.default_rng(1)
    got, want, independent = [], [], []
    for _ in range(40):
        colour = rng.choice([[0.62, 0.12, 0.10], [0.10, 0.45, 0.12], [0.55, 0.68, 0.85]])
        lin = np.broadcast_to(rng.uniform(0.3, 0.9) * 255.0 * np.asarray(colour), (64, 64, 3))
        noisy = lin + rng.normal(size=lin.shape) * np.sqrt(NOISE[0] + NOISE[1] * lin)
        codes = np.clip(np.rint(SENSOR.respond(noisy / 255.0) * 255.0), 0, 255).astype(np.uint8)
        buf = io.BytesIO()
        Image.fromarray(codes).save(buf, format="JPEG", quality=quality, subsampling=subsampling)
        buf.seek(0)
        decoded = jn.decode(buf.getvalue())
        with Image.open(io.BytesIO(buf.getvalue())) as im:
            settings = {"qtables": {k: list(v) for k, v in im.quantization.items()},
                        "subsampling": subsampling}
        _, _, bias = jn.bootstrap_variance(decoded, settings, SENSOR, NOISE, 7)
        values = (decoded - bias).reshape(-1, 3)             # as ingest takes them
        var = pixel_sigma(values, SENSOR, NOISE)[0] ** 2
        # the mean's error in linear signal (where fits take it: the noise's shift through the
        # curve cancels there), in codes at the patch's level
        taken = SENSOR.linearise(decoded - bias) * 255.0
        got.append((np.mean(taken, axis=(0, 1)) - lin[0, 0])
                   * SENSOR.slope(lin[0, 0] / 255.0))
        want.append(jn.YCC_TO_RGB ** 2 @ jn.shared_error_sd(values, var, jn.dc_record(settings)) ** 2)
        independent.append(np.mean(var, axis=0) / values.shape[0])
    rms = np.sqrt(np.mean(np.square(got), axis=0))
    independent = np.mean(independent, axis=0)
    predicted = np.sqrt(np.mean(want, axis=0) + independent)
    assert np.all(rms > 1.3 * np.sqrt(independent))                    # not 1 / sqrt(pixels)
    np.testing.assert_allclose(predicted, rms, rtol=0.2 if quality == 85 else 0.45)


def test_a_shared_error_reaches_a_mean_whole():
    """A mean fitted to P pixels of T frames, each frame's pixels sharing an error of sd s in
    one channel: the mean's standard error from it is s / sqrt(T) however many pixels, and
    the YCbCr mixing takes a Cb error to B by 1.772 and to G by -0.344, each frame's error
    moving them opposite ways (its signed row)."""
    from skyfit_mi.fitting.uncertainty import covariance, rows_sd, shared_error_rows

    P, T, sigma, s = 400, 4, 2.0, 0.3
    J = np.zeros((P, T, 3, 3))
    for c in range(3):
        J[:, :, c, c] = -1.0 / sigma                       # r = (y - theta_c) / sigma
    usable = np.ones((P, T, 3), bool)
    shared = np.tile([0.0, s, 0.0], (T, 1))                # Cb only
    rows = shared_error_rows(J, usable, np.full((P, T, 3), sigma), shared, jn.YCC_TO_RGB,
                             covariance(J.reshape(-1, 3)))
    sd = rows_sd(rows)
    cb = rows[np.abs(rows).sum(axis=1) > 0]
    assert len(cb) == T and np.all(cb[:, 1] * cb[:, 2] < 0)
    np.testing.assert_allclose(sd, np.abs(jn.YCC_TO_RGB[:, 1]) * s / np.sqrt(T), atol=1e-12)
    assert sd[2] > 5 * sigma / np.sqrt(P * T)             # far above the pixels' own error


@pytest.mark.parametrize("subsampling, offset", [(2, 0), (2, 1), (1, 0), (1, 1)])
def test_subsampled_colour_reaches_no_further_than_colour_reach(subsampling, offset):
    """Two saturated paints meeting at a straight edge (at an even or odd column, and across
    the rows), coded at quality 100 with chroma subsampled (4:2:0, 4:2:2) and decoded as
    ingest does: the colour bleeds across the edge -- by tens of codes on the pixels beside
    it -- but a pixel :func:`colour_mixed` keeps (``colour_reach``: 2 + 1 pixels) decodes
    within 2 codes of its paint, as a pixel of a plain patch does; without subsampling the
    reach is 0."""
    from skyfit_mi.pipeline.region_edges import colour_mixed, colour_reach

    h, w = 48, 64
    labels = np.ones((h, w), np.int32)
    labels[:, 31 + offset:] = 2
    labels[23 + offset:, :8] = 3                        # an edge across the rows too
    paint = np.array([[0, 0, 0], [200, 30, 20], [40, 60, 190], [230, 200, 30]], np.uint8)
    codes = paint[labels]
    buf = io.BytesIO()
    Image.fromarray(codes).save(buf, format="JPEG", quality=100, subsampling=subsampling)
    decoded = jn.decode(buf.getvalue())
    factors = jn._factors(jn.jpeg_settings(io.BytesIO(buf.getvalue())))
    doc = {"frames": [{"jpeg_dc": {"chroma_subsampling": list(factors)}}, {}]}
    reach = colour_reach(doc)
    assert reach == 3
    err = np.abs(decoded - codes).max(axis=-1)
    mixed = colour_mixed(labels, reach)
    assert err[mixed].max() > 20                       # the bleed is real
    assert err[~mixed].max() < 2.5, err[~mixed].max()
    assert colour_reach({"frames": [{"jpeg_dc": {"chroma_subsampling": [1, 1]}}]}) == 0
    assert not colour_mixed(labels, 0).any()
