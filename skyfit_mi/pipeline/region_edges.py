"""Where a material's pixels stop being surely its own: the edges a fit's regions and a
calibration's patches keep away from (:func:`.pixels.material_regions`,
:func:`.ingest.patch_samples`): colour a frame mixes across pixels, a JPEG's blocks ringing at
an edge, and the labels the pose's uncertainty may move."""

import numpy as np


def colour_reach(doc):
    """How many pixels from itself a frame of the sequence ``doc`` mixes a pixel's colour
    with others', at most over its frames: 0 but for JPEGs with subsampled chroma and RAWs.
    A RAW's demosaicing draws a pixel's missing colours from photosites around it (AHD's
    reach, :data:`~.photos.RAW_COLOUR_REACH`, recorded in each frame's ``raw_demosaic``).  A
    JPEG of chroma subsampled by f (2 for 4:2:0 and 4:2:2) averages each f x f cell's colour
    into one sample, and the decoder interpolates between neighbouring samples (libjpeg's "fancy"
    upsampling, :func:`~.jpeg_noise.decode`): a pixel's colour then draws on pixels up to f
    away.  One more covers a camera's encoder that smooths its chroma before subsampling.  At
    a boundary between materials the mix is a bias, not noise (measured on a board of
    saturated paints at quality 95, 4:2:0: the blue of yellow paint +26% on the ring next to
    the boundary), so a fit leaves such pixels out (:func:`colour_mixed`).  Registered or
    undistorted photographs (:mod:`.registration`) mix each pixel with its neighbours by their
    resampling, and their motion's uncertainty moves it: ``ingest.registration.erode_px``."""
    frames = doc.get("frames", ())
    factor = max((max(f["jpeg_dc"]["chroma_subsampling"]) for f in frames if "jpeg_dc" in f),
                 default=1)
    jpeg = factor + 1 if factor > 1 else 0
    resampled = int(((doc.get("ingest") or {}).get("registration") or {}).get("erode_px", 0))
    return max([jpeg, resampled] + [int(f["raw_demosaic"]["colour_reach_px"]) for f in frames
                                    if "raw_demosaic" in f])


def colour_mixed(labels, reach):
    """(H, W) bool: the pixels of the label image ``labels`` (:func:`scene_labels`) within
    ``reach`` pixels (a square's half-width) of a pixel of another label, whose colour a
    frame mixes with another material's (:func:`colour_reach`); none for ``reach`` 0."""
    from scipy.ndimage import maximum_filter, minimum_filter

    if reach <= 0:
        return np.zeros(labels.shape, dtype=bool)
    size = 2 * int(reach) + 1
    return maximum_filter(labels, size, mode="nearest") \
        != minimum_filter(labels, size, mode="nearest")


#: The fewest of a material's pixels in JPEG blocks of its own (:func:`jpeg_edge_blocks`) a
#: region takes alone; with fewer it keeps the pixels of blocks its edges cross.
JPEG_CLEAN_MIN = 16
#: How far [px] a resampled frame (:mod:`.registration`) carries an edge block's ringing into
#: its neighbours on the reference's pixels: its block grid, moved by the frame's shift
#: rounded to whole pixels (``jpeg_block_offset``), is off by up to half a pixel, and the
#: bilinear resampling mixes one pixel more.
RESAMPLED_BLOCK_REACH = 2


def jpeg_edge_blocks(labels, doc):
    """(H, W) bool: the pixels of the label image ``labels`` that lie in a JPEG coding block
    holding another label too, in any frame of the sequence ``doc`` whose tables round (a
    luminance DC step above 1: below quality 100).  A JPEG rounds each block's coefficients
    together, so an edge's high orders, rounded, ring across its block: an error of the
    scene's edge, the same in every frame, that neither noise nor the bootstrap's draws
    (:func:`~.jpeg_noise.truth_sampler`, which cannot restore what the file zeroed) describe,
    and which stops at the block's border.  Measured on the sample board at quality 92
    (4:4:4): 1-3% of the signal at 2-3 pixels from an edge, at most 0.3% in blocks of one
    material.  Blocks are 8 pixels, 8 f with chroma subsampled by f, from each frame's
    ``jpeg_block_offset``; a registered frame's resampling carries an edge block's ringing
    RESAMPLED_BLOCK_REACH pixels on (the shaken board, 160 x 120 at quality 92, seed 1: 26 of
    40 pairs held, 2 gross misses, without the reach; as lossless PNGs 38 of 40)."""
    h, w = labels.shape
    out = np.zeros((h, w), dtype=bool)
    grids = {(tuple(f.get("jpeg_block_offset", (0, 0))),
              8 * max(f["jpeg_dc"]["chroma_subsampling"]),
              RESAMPLED_BLOCK_REACH if (f.get("registration") or {}).get("resampled") else 0)
             for f in doc.get("frames", ()) if "jpeg_dc" in f and max(f["jpeg_dc"]["dc_step"]) > 1}
    for (ox, oy), n, reach in grids:
        yy, xx = np.mgrid[0:h, 0:w]
        cell = ((yy - oy) // n) * (w // n + 2) + (xx - ox) // n
        cell = np.unique(cell, return_inverse=True)[1].reshape(h, w)
        lo = np.full(cell.max() + 1, np.iinfo(np.int64).max)
        hi = np.full(cell.max() + 1, np.iinfo(np.int64).min)
        np.minimum.at(lo, cell.ravel(), labels.ravel())
        np.maximum.at(hi, cell.ravel(), labels.ravel())
        ringing = (lo != hi)[cell]
        if reach:
            from scipy.ndimage import binary_dilation
            ringing = binary_dilation(ringing, np.ones((2 * reach + 1,) * 2, bool))
        out |= ringing
    return out


def pose_reach(camera, pose_sd_deg=None):
    """How many pixels the camera's pose uncertainty may move the scene's labels in its frames
    (``pose_sd_deg``, {angle: 1 sd [deg]} as :func:`~skyfit_mi.render.scene.pose_sd` reads
    it, or the ``camera`` record's ``pose_sd_deg``; absent: 0): twice (95%) the
    displacement of the frame's farthest pixel, a turn in azimuth or angle moving the view's
    centre by f theta (f the focal length in pixels) and a roll the corners by their radius
    times it, the angles independent.  The regions a fit takes from the spec's labels stay
    that far inside each material: a pose given to +-1 degree moves a 160-pixel-wide view of
    40 degrees by 4 pixels."""
    from ..physics.lens import focal_px

    sd = pose_sd_deg if pose_sd_deg is not None else camera.get("pose_sd_deg")
    if not sd:
        return 0
    w, h = camera["width"], camera["height"]
    f = focal_px(camera["fov_deg"], w)
    rad = {k: np.radians(float(v)) for k, v in sd.items()}
    move = np.sqrt((f * rad.get("azimuth", 0.0)) ** 2 + (f * rad.get("angle", 0.0)) ** 2
                   + (np.hypot(w, h) / 2.0 * rad.get("roll", 0.0)) ** 2)
    return int(np.ceil(2.0 * move - 1e-9))
