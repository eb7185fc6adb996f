"""Where a material's pixels stop being surely its own: the edges a fit's regions and a
calibration's patches keep away from (:func:`.pixels.material_regions`,
:func:`.ingest.patch_samples`): colour a frame mixes across pixels, a JPEG's blocks ringing at
an edge, and the labels the pose's uncertainty may move."""

import numpy as np
from scipy.ndimage import binary_dilation, maximum_filter, minimum_filter


def colour_reach(doc):
    """How many pixels away a frame of sequence ``doc`` mixes a pixel's colour with others', at
    most over its frames: 0 but for RAWs (AHD's :data:`~.photos.RAW_COLOUR_REACH`) and JPEGs
    with chroma subsampled by f (f, plus one for cameras that smooth chroma first).  At a
    material boundary the mix is a bias, not noise, so fits leave such pixels out
    (:func:`colour_mixed`).  Registration's resampling is ``ingest.registration.erode_px``."""
    frames = doc.get("frames", ())
    factor = max((max(f["jpeg_dc"]["chroma_subsampling"]) for f in frames if "jpeg_dc" in f),
                 default=1)
    jpeg = factor + 1 if factor > 1 else 0
    resampled = int(((doc.get("ingest") or {}).get("registration") or {}).get("erode_px", 0))
    return max([jpeg, resampled] + [int(f["raw_demosaic"]["colour_reach_px"]) for f in frames
                                    if "raw_demosaic" in f])


def colour_mixed(labels, reach):
    """(H, W) bool: pixels of ``labels`` within ``reach`` pixels (a square's half-width) of
    another label, whose colour a frame mixes (:func:`colour_reach`); none for ``reach`` 0."""
    if reach <= 0:
        return np.zeros(labels.shape, dtype=bool)
    size = 2 * int(reach) + 1
    return maximum_filter(labels, size, mode="nearest") \
        != minimum_filter(labels, size, mode="nearest")


#: The fewest of a material's pixels in JPEG blocks of its own (:func:`jpeg_edge_blocks`) a
#: region takes alone; with fewer it keeps the pixels of blocks its edges cross.
JPEG_CLEAN_MIN = 16
#: How far [px] beyond its bilinear footprint a resampled frame's edge block spoils reference
#: pixels: blocks holding an edge's blur ring too, and the frame's motion moves them.
RESAMPLED_BLOCK_REACH = 2
#: A bilinear weight below this [1] draws on no pixel (a frame not resampled takes its own).
_NO_WEIGHT = 1e-6


def jpeg_edge_blocks(labels, doc):
    """(H, W) bool: pixels of ``labels`` in a JPEG coding block (8 f pixels for chroma
    subsampled by f, at each frame's ``jpeg_block_offset``) holding another label too, in any
    frame of ``doc`` below quality 100.  An edge's rounded high orders ring across its block:
    an error of the scene, the same in every frame, that neither noise nor the bootstrap
    describes, and which stops at the block's border.

    For a resampled frame (:mod:`.registration`) a pixel is marked where any of the four
    photograph pixels its bilinear value draws on lies in such a block, and
    RESAMPLED_BLOCK_REACH pixels about those."""
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
    """(u, v, (ox, oy), resampled): where each reference pixel's value was taken in ``frame``'s
    photograph [px] ((H, W) each), its block offset, and whether it was resampled."""
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
    """How many pixels the pose uncertainty may move the scene's labels (``pose_sd_deg``, {angle:
    1 sd [deg]} as :func:`~skyfit_mi.render.scene.pose_sd` reads it; absent: 0): twice (95%) the
    farthest pixel's displacement, f theta for azimuth or angle (f [px]) and radius x theta for
    roll, the angles independent.  Fit regions stay that far inside each material."""
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
