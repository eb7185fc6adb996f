"""Where a material's pixels stop being surely its own: the edges a fit's regions and a
calibration's patches keep away from (:func:`.pixels.material_regions`,
:func:`.ingest.patch_samples`): colour a frame mixes across pixels, a JPEG's blocks ringing at
an edge, and the labels the pose's uncertainty may move."""

import numpy as np
from scipy.ndimage import binary_dilation, maximum_filter, minimum_filter


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
    if reach <= 0:
        return np.zeros(labels.shape, dtype=bool)
    size = 2 * int(reach) + 1
    return maximum_filter(labels, size, mode="nearest") \
        != minimum_filter(labels, size, mode="nearest")


#: The fewest of a material's pixels in JPEG blocks of its own (:func:`jpeg_edge_blocks`) a
#: region takes alone; with fewer it keeps the pixels of blocks its edges cross.
JPEG_CLEAN_MIN = 16
#: How far [px] beyond its pixel map's bilinear footprint a resampled frame's edge block
#: spoils the reference's pixels: the blocks about an edge whose labels are one material but
#: whose values hold the edge's blur (a lens's, a renderer's pixel filter) ring too, and the
#: frame's motion moves them over the scene.
RESAMPLED_BLOCK_REACH = 2
#: A bilinear weight below this [1] draws on no pixel (a frame not resampled takes its own).
_NO_WEIGHT = 1e-6


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
    ``jpeg_block_offset``.

    A frame resampled onto the reference's pinhole pixels (registered or undistorted,
    :mod:`.registration`) has its blocks where its pixel map puts them: a pixel is marked where
    any of the four photograph pixels its bilinear value draws on lies in a block that holds
    two labels (the labels carried to the photograph by the nearest pixel), and
    RESAMPLED_BLOCK_REACH pixels about those.  Measured on the shaken board (160 x 120,
    quality 92, seed 1): 26 of 40 pairs held with 2 gross misses with the blocks alone (moved
    by the frame's shift rounded, or by its map), 36 with no gross miss with the reach; as
    lossless PNGs 38 of 40."""
    h, w = labels.shape
    out = np.zeros((h, w), dtype=bool)
    grids = {}                                   # frames that share a grid are marked once
    for f in doc.get("frames", ()):
        if "jpeg_dc" in f and max(f["jpeg_dc"]["dc_step"]) > 1:
            reg = f.get("registration") or {}
            moved = tuple(reg.get(k) for k in ("dx_px", "dy_px", "rotation_deg")) \
                if reg.get("resampled") else None
            n = 8 * max(f["jpeg_dc"]["chroma_subsampling"])
            grids.setdefault((tuple(f.get("jpeg_block_offset", (0, 0))), n, moved), f)
    for (_, n, _), f in grids.items():
        u, v, (ox, oy), resampled = _photograph_pixels(f, doc, w, h)
        x0, y0 = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
        x1, y1 = x0 + (u - x0 > _NO_WEIGHT), y0 + (v - y0 > _NO_WEIGHT)   # bilinear's others
        # blocks numbered over the map's reach (u, v within one pixel of the nearest)
        bx0 = int((np.floor(u.min()) - 1 - ox) // n)
        by0 = int((np.floor(v.min()) - 1 - oy) // n)
        across = int((np.ceil(u.max()) + 1 - ox) // n) - bx0 + 1

        def block(x, y):
            return ((y - oy) // n - by0) * across + (x - ox) // n - bx0
        near = block(np.rint(u).astype(np.int64), np.rint(v).astype(np.int64))
        lo = np.full(near.max() + 1, np.iinfo(np.int64).max)
        hi = np.full(near.max() + 1, np.iinfo(np.int64).min)
        np.minimum.at(lo, near.ravel(), labels.ravel())
        np.maximum.at(hi, near.ravel(), labels.ravel())
        edge = np.append(lo < hi, False)               # two labels in a block; beyond: none
        ringing = np.zeros((h, w), dtype=bool)
        for x, y in ((x0, y0), (x0, y1), (x1, y0), (x1, y1)):
            ringing |= edge[np.minimum(block(x, y), len(edge) - 1)]
        if resampled:
            reach = 2 * RESAMPLED_BLOCK_REACH + 1
            ringing = binary_dilation(ringing, np.ones((reach, reach), bool))
        out |= ringing
    return out


def _photograph_pixels(frame, doc, w, h):
    """(u, v, (ox, oy), resampled): where each reference pixel's value was taken in
    ``frame``'s photograph [px] ((H, W) each; the pixel itself unless the frame was resampled,
    moved or undistorted), the photograph's own block offset, and whether it was resampled."""
    from .registration import NO_MOTION, motion_of_record, pixel_map

    ox, oy = frame.get("jpeg_block_offset", (0, 0))
    reg = frame.get("registration") or {}
    k = ((doc.get("ingest") or {}).get("registration") or {}).get("distortion_undone") or []
    moved = bool(reg.get("resampled"))
    if not moved and not any(k):
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
        return xx, yy, (ox, oy), False
    M = NO_MOTION
    if moved:                 # the record's offset was moved by the shift, rounded: undone
        ox, oy = (int(o + round(reg[d])) % 8 for o, d in zip((ox, oy), ("dx_px", "dy_px")))
        M = motion_of_record(reg, w, h)
    u, v = pixel_map(M, {**doc["camera"], "width": w, "height": h, "distortion": k})
    return u.astype(np.float64), v.astype(np.float64), (ox, oy), True


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
