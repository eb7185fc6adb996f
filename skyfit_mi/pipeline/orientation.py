"""EXIF orientation: a photograph's pixels turned as its orientation code asks, and back.

Frames are stored in the sensor's layout, EXIF tag 0x0112 saying how to turn them for display;
:mod:`.photos` reads them as displayed, and :mod:`.jpeg_noise` turns them back to the file's
layout, where a JPEG's blocks start at the top left.
"""

import numpy as np

#: EXIF orientation codes and what they mean (TIFF/EP, EXIF 2.3 tag 0x0112).
ORIENTATIONS = {1: "as stored", 2: "mirrored left-right", 3: "rotated 180",
                4: "mirrored top-bottom", 5: "transposed", 6: "rotated 90 CW",
                7: "transversed", 8: "rotated 90 CCW"}


def apply_orientation(values, orientation):
    """Turn an (H, W, ...) array as EXIF ``orientation`` asks (as Pillow's
    ``ImageOps.exif_transpose``; 1 = unchanged); a view where possible."""
    if orientation in (None, 1):
        return values
    turn = {
        2: lambda a: a[:, ::-1],
        3: lambda a: a[::-1, ::-1],
        4: lambda a: a[::-1],
        5: lambda a: a.swapaxes(0, 1),
        6: lambda a: np.rot90(a, -1),
        7: lambda a: a[::-1, ::-1].swapaxes(0, 1),
        8: lambda a: np.rot90(a, 1),
    }
    return turn[orientation](values)


def undo_orientation(values, orientation):
    """The inverse of :func:`apply_orientation`: a displayed array back in the file's layout."""
    return apply_orientation(values, {6: 8, 8: 6}.get(orientation, orientation))
