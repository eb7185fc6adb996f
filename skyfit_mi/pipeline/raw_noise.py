"""What developing a camera RAW does to its noise, found by developing the frame again.

A RAW's photosites carry independent read and shot noise, one colour each.  Developing it
(:func:`.photos.develop`: AHD demosaicing, white balance, a far-from-diagonal colour matrix)
mixes neighbours and channels, so a developed pixel's noise is larger than its neighbours'
differences show, correlated with theirs, and set by all three channels.  So the sensor's read
a [raw DN^2] and shot b [raw DN per DN] noise is estimated on the CFA planes
(:func:`cfa_planes`), whose neighbouring sites' noise is independent, and a parametric bootstrap
(:func:`bootstrap`) develops the smoothed photosites with fresh noise :data:`REPLICATES` times,
giving each pixel's variance and the correlations between pixels up to
:data:`.photos.RAW_COLOUR_REACH` apart (:func:`skyfit_mi.fitting.chi2.neighbour_sharing`).
Draws are seeded (:data:`SEED`, frame index).  A RAW without a 2x2 Bayer filter (X-Trans,
Foveon) has no planes: ingest then estimates its noise from the developed frames.
"""

import numpy as np

from .photos import RAW_COLOUR_REACH, develop

#: Developed copies per frame.
REPLICATES = 8
#: Seed of the bootstrap's noise (with the frame's index; recorded in the manifest).
SEED = 20261127
#: Sites per side over which each CFA plane is averaged before the bootstrap adds noise: AHD
#: picks its interpolation directions from the data, and on the noisy frame itself the fresh
#: noise would move those choices and overstate the developed variance.
SMOOTH = 5


def _mosaic(raw):
    """(photosite values above black (H, W) float, their CFA colour indices (H, W), the
    white level above black) of an open rawpy image, over its whole raw buffer."""
    colours = np.asarray(raw.raw_colors)
    black = np.asarray(raw.black_level_per_channel, dtype=float)[colours]
    values = np.asarray(raw.raw_image, dtype=float) - black
    return values, colours, float(raw.white_level) - black


def cfa_planes(path):
    """RAW ``path``'s photosites above black as two (H/2, W/2, 3) images of its 2x2 filter's
    planes ((R, G1, B), (R, G2, B)), NaN where clipped; None without a 2x2 Bayer filter."""
    import rawpy

    with rawpy.imread(str(path)) as raw:
        pattern = np.asarray(raw.raw_pattern)
        if pattern.shape != (2, 2):
            return None
        values, _, white = _mosaic(raw)
        values = np.where(values < white, values, np.nan)
        names = raw.color_desc.decode("ascii", "replace")
        sites = {}
        for i in range(2):
            for j in range(2):
                sites.setdefault(names[pattern[i, j]], []).append(values[i::2, j::2])
    if sorted(sites) != ["B", "G", "R"] or len(sites["G"]) != 2:
        return None
    h = min(p.shape[0] for ps in sites.values() for p in ps)
    w = min(p.shape[1] for ps in sites.values() for p in ps)
    r, b = sites["R"][0][:h, :w], sites["B"][0][:h, :w]
    return [np.stack([r, g[:h, :w], b], axis=-1) for g in sites["G"]]


def _smoothed(values, pattern):
    """Photosite ``values`` (H, W) with each site of the 2x2 CFA ``pattern`` the mean of its
    colour's plane over SMOOTH x SMOOTH of its sites (NaN-free, edges by reflection)."""
    from scipy.ndimage import uniform_filter

    out = np.array(values, dtype=float, copy=True)
    for i in range(2):
        for j in range(2):
            out[i::2, j::2] = uniform_filter(values[i::2, j::2], SMOOTH, mode="reflect")
    return out


def bootstrap(path, noise, seed, frame, replicates=REPLICATES):
    """Draws of RAW ``path``'s developed noise: smoothed photosites with fresh ``noise`` = (a
    [raw DN^2], b [raw DN per DN]) developed as :func:`.photos.read_photo` does, less the
    smoothed sites developed; ``frame`` (H, W, 3) the file as read (clipped pixels left out).

    Returns (variance (H, W, 3) [DN^2] float32, averaged over unclipped SMOOTH x SMOOTH
    neighbours; each channel's correlation between pixels (3, 2 R + 1, 2 R + 1), R =
    RAW_COLOUR_REACH, offsets (dy, dx); the channels' correlations R-G, G-B, B-R)."""
    import rawpy
    from scipy.ndimage import uniform_filter

    rng = np.random.default_rng(seed)
    a, b = noise
    n = RAW_COLOUR_REACH
    clipped = np.any((frame <= 0) | (frame >= 65535), axis=-1)
    with rawpy.imread(str(path)) as raw:
        original = np.array(raw.raw_image, copy=True)
        values = _mosaic(raw)[0]
        black = original - values
        smooth = _smoothed(values, raw.raw_pattern)
        sd = np.sqrt(a + b * np.clip(smooth, 0.0, None))
        top = np.iinfo(original.dtype).max

        def developed(sites):
            raw.raw_image[...] = np.clip(np.rint(sites + black), 0, top).astype(original.dtype)
            out = develop(raw).astype(np.float32)
            return out, np.any((out <= 0) | (out >= 65535), axis=-1)

        base, cut = developed(smooth)
        clipped |= cut
        draws = []
        for _ in range(replicates):
            copy, cut = developed(smooth + rng.normal(size=sd.shape) * sd)
            clipped |= cut
            draws.append(copy - base)
        raw.raw_image[...] = original
    h, w = base.shape[:2]
    square = np.zeros((h, w, 3))
    lag = np.zeros((3, 2 * n + 1, 2 * n + 1, 3))           # sums of d d', d^2, d'^2
    cross = np.zeros((3, 3))
    for d in draws:
        d = np.where(clipped[..., None], 0.0, d)
        square += d ** 2
        for dy in range(-n, n + 1):
            for dx in range(-n, n + 1):
                one = d[max(dy, 0):h + min(dy, 0), max(dx, 0):w + min(dx, 0)]
                two = d[max(-dy, 0):h + min(-dy, 0), max(-dx, 0):w + min(-dx, 0)]
                lag[:, dy + n, dx + n] += np.stack([np.sum(one * two, axis=(0, 1)),
                                                    np.sum(one ** 2, axis=(0, 1)),
                                                    np.sum(two ** 2, axis=(0, 1))], axis=-1)
        cross += np.einsum("hwc,hwk->ck", d, d)
    corr = lag[..., 0] / np.sqrt(lag[..., 1] * lag[..., 2])
    channels = [float(cross[c, (c + 1) % 3] / np.sqrt(cross[c, c] * cross[(c + 1) % 3,
                                                                           (c + 1) % 3]))
                for c in range(3)]
    # mean over unclipped neighbours; where all clip, the frame's most (other channels count)
    keep = (~clipped).astype(float)[..., None]
    size = (SMOOTH, SMOOTH, 1)
    with np.errstate(all="ignore"):
        variance = uniform_filter(square / replicates, size) / uniform_filter(keep, size)
    variance = np.where(np.isfinite(variance), variance,
                        np.nanmax(np.where(np.isfinite(variance), variance, np.nan), axis=(0, 1)))
    # the running sums of uniform_filter can leave -1e-17 where a neighbourhood holds none
    variance = np.maximum(variance, 0.0).astype(np.float32)
    return variance, corr, channels
