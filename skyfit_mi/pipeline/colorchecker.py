"""A ColorChecker in the photographs: found, oriented, and its swatches as calibration patches.

``skyfit ingest --colorchecker MATERIAL`` calibrates a day of photographs from an X-Rite
ColorChecker Classic (24 swatches, 4 rows of 6) lying on the scene surface ``MATERIAL``.  The
chart is found once, in the median of the normalised frames: ``colour-checker-detection``
(Mansencal et al., colour-science) finds chart-shaped clusters of swatches, a homography maps
the 6 x 4 grid onto each, and the orientation and cluster best matching the reference colours
win.  A swatch's pixels are the middle :data:`INNER` of its cell.

The six neutral swatches (spectrally flat, so independent of the camera's sensitivities) are the
calibration's grey steps (:func:`skyfit_mi.pipeline.ingest.fit_response`,
:func:`~skyfit_mi.pipeline.ingest.calibrate_exposure`), as the thesis's IT8 target's greys; the
chromatic ones orient the chart and check the calibration (:func:`swatch_check`).

Reference reflectances: the linear-sRGB values of ``colour-checker-detection`` (colour-science's
"ColorChecker24 - After November 2014", X-Rite's post-2014 formulation, D50, Bradford-adapted to
sRGB's D65), unitless.
"""

import numpy as np

from ..errors import SkyfitError

#: Swatch columns and rows of a ColorChecker Classic (row 1 dark skin ... cyan, row 4 the
#: neutrals white 9.5 ... black 2).
COLUMNS, ROWS = 6, 4
#: The neutral swatches' indices (0-based, row by row).
NEUTRAL = tuple(range(18, 24))
#: Names of the 24 swatches, for messages and records.
NAMES = ("dark skin", "light skin", "blue sky", "foliage", "blue flower", "bluish green",
         "orange", "purplish blue", "moderate red", "purple", "yellow green", "orange yellow",
         "blue", "green", "red", "yellow", "magenta", "cyan",
         "white 9.5", "neutral 8", "neutral 6.5", "neutral 5", "neutral 3.5", "black 2")
#: Share of a swatch's cell (per side, centred) whose pixels are sampled [unitless].
INNER = 0.5
#: Least pixels a sampled swatch needs.
MIN_SWATCH_PIXELS = 4
#: Aspect ratios of a chart's outline the segmentation accepts: wider than the library's
#: default, since a chart seen obliquely is foreshortened.
ASPECT_RANGE = (1.0, 3.0)
#: Rms log ratio of the sampled swatches to the reference (scale per channel free) above which
#: a detection is not accepted as the chart [unitless, ~ relative].
MATCH_MAX = 0.35
#: Least swatches measured in every channel for the match's mixing (:func:`_match`): four
#: times its nine coefficients' worth of values.
MIN_MIXING_SWATCHES = 12
#: Reference reflectances below this are left out of the match (the cyan swatch lies outside
#: sRGB: its red is negative).
_MATCH_FLOOR = 0.01
#: The chart's outline in grid coordinates (columns, rows), clockwise from the first swatch.
_GRID_CORNERS = np.array([[0, 0], [COLUMNS, 0], [COLUMNS, ROWS], [0, ROWS]], float)


def _library():
    try:
        from colour_checker_detection.detection import segmentation
    except ImportError as exc:                        # pragma: no cover - depends on the install
        raise SkyfitError(f"--colorchecker needs the colour-checker-detection package ({exc}); "
                          "install it: pip install 'skyfit-mi[photo]'.") from None
    return segmentation


def reference_rgb():
    """(24, 3) linear-sRGB reflectance of the chart's swatches, row by row [unitless]."""
    return np.array(_library().SETTINGS_SEGMENTATION_COLORCHECKER_CLASSIC["reference_values"],
                    dtype=float)


def _cell_centres():
    """(24, 2) grid coordinates (column + 0.5, row + 0.5) of the swatches, row by row."""
    r, c = np.divmod(np.arange(COLUMNS * ROWS), COLUMNS)
    return np.stack([c + 0.5, r + 0.5], axis=1).astype(float)


def _homography(src, dst):
    """3x3 H with dst ~ H src (least squares, direct linear transform with normalisation)."""
    import cv2

    h, _ = cv2.findHomography(np.asarray(src, np.float64), np.asarray(dst, np.float64), 0)
    return h


def _apply(h, pts):
    p = np.c_[np.asarray(pts, float), np.ones(len(pts))] @ h.T
    return p[:, :2] / p[:, 2:3]


def _to_image(points, shape, working_width):
    """Segmentation working-image coordinates (resized, portrait turned) -> frame pixels."""
    h, w = shape
    pts = np.asarray(points, float).reshape(-1, 2)
    if w < h:                                          # rotated: (x, y) -> (h - 1 - y, x)
        scale = h / working_width
        x, y = pts[:, 0] * scale, pts[:, 1] * scale
        return np.stack([y, h - x], axis=1)
    scale = w / working_width
    return pts * scale


def _sample(image, h):
    """Median colour (24, 3) of each swatch's inner pixels, and its pixel count (24,)."""
    labels = swatch_labels(h, image.shape[:2])
    out = np.full((COLUMNS * ROWS, 3), np.nan)
    n = np.bincount(labels.ravel(), minlength=COLUMNS * ROWS + 1)[1:]
    for k in np.flatnonzero(n):
        out[k] = np.median(image[labels == k + 1], axis=0)
    return out, n


def _match(sampled, reference, mixing=False):
    """Rms log ratio of sampled to reference swatches, one scale per channel free; with
    ``mixing``, the reference first mixed by the least-squares 3x3 matrix, for cameras whose
    colour matrix errs (:func:`matrix_error`)."""
    if mixing:
        rows = np.all((reference > _MATCH_FLOOR) & np.isfinite(sampled), axis=1)
        if rows.sum() >= MIN_MIXING_SWATCHES:
            m, *_ = np.linalg.lstsq(reference[rows], sampled[rows], rcond=None)
            reference = reference @ m
    ok = (reference > _MATCH_FLOOR) & (sampled > 0) & np.isfinite(sampled)
    if ok.sum() < 30:
        return np.inf
    d = np.where(ok, np.log(np.where(ok, sampled, 1.0)) - np.log(np.where(ok, reference, 1.0)),
                 np.nan)
    d = d - np.nanmedian(d, axis=0)
    return float(np.sqrt(np.nanmean(d ** 2)))


def swatch_labels(h, shape):
    """(H, W) int: 1 + swatch index of pixels mapping (by ``h``'s inverse) into the middle
    :data:`INNER` of a swatch's cell, else 0."""
    rows, cols = shape
    out = np.zeros(shape, np.int32)
    # only the chart's bounding box can hold swatch pixels
    corners = _apply(h, _GRID_CORNERS)
    (x0, y0), (x1, y1) = np.floor(corners.min(axis=0)), np.ceil(corners.max(axis=0))
    x0, x1 = int(np.clip(x0, 0, cols)), int(np.clip(x1 + 1, 0, cols))
    y0, y1 = int(np.clip(y0, 0, rows)), int(np.clip(y1 + 1, 0, rows))
    if x1 <= x0 or y1 <= y0:
        return out
    ys, xs = np.mgrid[y0:y1, x0:x1]
    g = _apply(np.linalg.inv(h), np.c_[xs.ravel() + 0.5, ys.ravel() + 0.5])
    col, row = np.floor(g[:, 0]), np.floor(g[:, 1])
    inside = (col >= 0) & (col < COLUMNS) & (row >= 0) & (row < ROWS)
    half = INNER / 2
    central = (np.abs(g[:, 0] - col - 0.5) < half) & (np.abs(g[:, 1] - row - 0.5) < half)
    k = np.where(inside & central, row * COLUMNS + col + 1, 0).astype(np.int32)
    out[y0:y1, x0:x1] = k.reshape(y1 - y0, x1 - x0)
    return out


def _fit_grid(quad, centres, image, reference):
    """Best homography grid -> image for one cluster: every corner order of ``quad`` as a
    first guess, refined on the detected swatch ``centres``; (match, h)."""
    corners = _GRID_CORNERS
    cells = _cell_centres()
    best = (np.inf, None)
    for flip in (False, True):
        q = quad[::-1] if flip else quad
        for shift in range(4):
            h = _homography(corners, np.roll(q, shift, axis=0))
            for _ in range(3):                          # refine on the swatches found
                if len(centres) < 8:
                    break
                guess = _apply(h, cells)
                d = np.linalg.norm(guess[:, None, :] - centres[None, :, :], axis=2)
                pitch = np.median(np.linalg.norm(np.diff(guess.reshape(ROWS, COLUMNS, 2),
                                                         axis=1), axis=2))
                near = d.argmin(axis=1)
                use = d[np.arange(len(cells)), near] < 0.35 * pitch
                if use.sum() < 8:
                    break
                h = _homography(cells[use], centres[near[use]])
            score = _match(_sample(image, h)[0], reference)
            if score < best[0]:
                best = (score, h)
    return best


def find_chart(images, log=print):
    """Find the ColorChecker in a static camera's ``images`` (H, W, 3) (linear, any scale, NaN
    allowed): {``homography`` (grid (column, row) -> pixel (x, y)), ``labels`` (H, W)
    (:func:`swatch_labels`), ``pixels`` (24,) per swatch, ``match`` (rms log ratio to the
    reference), ``corners`` (4, 2) [pixels]}; SkyfitError if none is found fit to calibrate."""
    seg = _library()
    stack = []
    for im in images:
        im = np.asarray(im, dtype=float)
        m = np.nanmedian(im)
        stack.append(im / m if m > 0 else im)
    image = np.nanmedian(np.stack(stack), axis=0)
    image = np.clip(np.nan_to_num(image / np.nanpercentile(image, 99.5)), 0.0, 1.0)
    settings = dict(seg.SETTINGS_SEGMENTATION_COLORCHECKER_CLASSIC)
    settings.update(aspect_ratio_minimum=ASPECT_RANGE[0], aspect_ratio_maximum=ASPECT_RANGE[1])
    found = seg.segmenter_default(image.astype(np.float32), additional_data=True, **settings)
    shape = image.shape[:2]
    swatches = [_to_image(s, shape, settings["working_width"]) for s in found.swatches]
    centres = np.array([s.mean(axis=0) for s in swatches]).reshape(-1, 2)
    reference = reference_rgb()
    best = (np.inf, None)
    for quad in found.rectangles:
        q = _to_image(quad, shape, settings["working_width"])
        best = min(best, _fit_grid(q, centres, image, reference), key=lambda b: b[0])
    if best[1] is None:
        raise SkyfitError("no ColorChecker was found in the frames (no cluster of square "
                          "swatches shaped like a chart); frame it larger (its swatches at "
                          "least ~8 pixels wide), unoccluded and in focus, or calibrate from a "
                          "scene material with --calibrate.")
    match, h = best
    if match > MATCH_MAX:
        # a camera's colours mixed (colour matrix off): judged with the reference mixed alike
        mixed = _match(_sample(image, h)[0], reference, mixing=True)
        if mixed > MATCH_MAX:
            raise SkyfitError(f"the chart-like object found matches a ColorChecker's colours "
                              f"only to {match:.0%} rms ({mixed:.0%} with the channels mixed; "
                              f"at most {MATCH_MAX:.0%} accepted); is it a ColorChecker "
                              "Classic, fully visible and lit?")
        log(f"the chart's colours match the reference to {match:.0%} rms with a scale per "
            f"channel, {mixed:.1%} with the channels mixed: the camera's colours are mixed")
        match = mixed
    labels = swatch_labels(h, shape)
    n = np.bincount(labels.ravel(), minlength=COLUMNS * ROWS + 1)[1:]
    few = [NAMES[k] for k in NEUTRAL if n[k] < MIN_SWATCH_PIXELS]
    if few:
        raise SkyfitError(f"the ColorChecker's {', '.join(few)} swatch(es) cover fewer than "
                          f"{MIN_SWATCH_PIXELS} pixels; frame the chart larger.")
    corners = _apply(h, _GRID_CORNERS)
    log(f"ColorChecker found: outline {np.round(corners).astype(int).tolist()} px, neutral "
        f"swatches {min(n[k] for k in NEUTRAL)}-{max(n[k] for k in NEUTRAL)} px each, colours "
        f"matching the reference to {match:.1%} rms")
    return {"homography": h, "labels": labels, "pixels": n, "match": match,
            "corners": corners}


def swatch_check(ratio):
    """How far the calibrated chromatic swatches lie from their references: ``ratio`` (24, 3)
    observed over predicted -> ``{"rms", "worst": [name, error], "per_swatch"}`` of ratio - 1
    over chromatic swatches above the match floor (``rms`` None if none)."""
    ref = reference_rgb()
    e = np.asarray(ratio, dtype=float) - 1.0
    ok = (ref > _MATCH_FLOOR) & np.isfinite(e)
    chromatic = [k for k in range(COLUMNS * ROWS) if k not in NEUTRAL and ok[k].any()]
    if not chromatic:
        return {"rms": None, "worst": None, "per_swatch": {}}
    worst = max(chromatic, key=lambda k: np.max(np.abs(e[k][ok[k]])))
    return {"rms": float(np.sqrt(np.mean(np.concatenate([e[k][ok[k]] for k in chromatic]) ** 2))),
            "worst": [NAMES[worst], float(np.max(np.abs(e[worst][ok[worst]])))],
            "per_swatch": {NAMES[k]: [float(x) if o else None for x, o in zip(e[k], ok[k])]
                           for k in chromatic}}


def matrix_error(ratio, predicted):
    """The colour matrix's error the chromatic swatches show, as a white-preserving mixing: the
    camera reads L as (I + G) L, G's rows summing to 0, so swatch k's channel c has ratio
    1 + sum_(j != c) G_cj (L_kj / L_kc - 1) to its prediction.  From ``ratio`` (24, 3) and
    ``predicted`` (24, 3) signals, by least squares per channel: ``{"mixing": G (3, 3),
    "standard_error": (3, 3), "residual_rms"}``, or None with fewer than 4 usable swatches."""
    ratio = np.asarray(ratio, dtype=float)
    L = np.asarray(predicted, dtype=float)
    ok = np.all(reference_rgb() > _MATCH_FLOOR, axis=1) & np.all(np.isfinite(ratio), axis=1) \
        & np.all(L > 0, axis=1)
    ok[list(NEUTRAL)] = False
    if ok.sum() < 4:
        return None
    G, se, res = np.zeros((3, 3)), np.zeros((3, 3)), []
    for c in range(3):
        others = [j for j in range(3) if j != c]
        X = L[ok][:, others] / L[ok][:, [c]] - 1.0
        y = ratio[ok, c] - 1.0
        coef, *_ = np.linalg.lstsq(X, y, rcond=None)
        r = y - X @ coef
        dof = max(len(y) - len(others), 1)
        cov = np.linalg.pinv(X.T @ X) * float(r @ r) / dof
        G[c, others], se[c, others] = coef, np.sqrt(np.clip(np.diag(cov), 0, None))
        G[c, c] = -coef.sum()
        se[c, c] = float(np.sqrt(np.clip(cov.sum(), 0, None)))
        res.append(r)
    return {"mixing": G, "standard_error": se,
            "residual_rms": float(np.sqrt(np.mean(np.concatenate(res) ** 2)))}
