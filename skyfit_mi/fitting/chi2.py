"""Chi-square between observed pixel values and the model (thesis eq. 6.2), and the data it needs.

chi^2 = sum_i ((y_i - y(x_i; a)) / sigma_i)^2 over every region pixel, frame and channel: y the
sensor's values [DN], sigma their standard deviations (inf: no information), y(x; a) the sensor
model applied to the model's radiance for parameters a.

Values at code 0 or the top code are censored (taken as exact they bias dark channels up and
bright ones down): each contributes -2 ln Phi((0.5 - y(x; a)) / sigma), or
-2 ln Phi((y(x; a) - max + 0.5) / sigma), instead of its squared residual (the Tobit likelihood),
so chi^2 stays -2 ln(likelihood) up to a constant, eq. 6.2 when nothing clips.
"""

import functools
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import log_ndtr, ndtr

from . import uncertainty as unc
from .tone import curve_reading
from ..physics import tone_curve
from ..physics.camera import SensorModel
from ..errors import SkyfitError
from ..physics.colour import SRGB_LUMINANCE
from ..pipeline.manifest import (check_frames, frame_exposure, is_table, load_manifest,
                                 read_frame_pixels, rendered_frames, sensor_from_record)
from ..pipeline.observation_table import table_observations
from ..pipeline.pixels import scene_labels
from ..pipeline.region_edges import colour_mixed, colour_reach
from ..render.light_cache import point_rays

#: Values below this [DN] read as code 0.
LOW_CODE = 0.5
#: Values (sets x pixels x frames x channels) whose radiance :meth:`Problem.chi2_at` holds at
#: once (32 MB).
CHUNK_VALUES = 2**22
#: Largest relative standard error of a region mean (or table value) that counts as measured
#: (:meth:`Problem.measured_range`).
MEASURED_SE = 0.1


@dataclass
class Observations:
    """Observed values of a region across a sequence.

    y, sigma : (P, T, 3) [DN] (sigma inf: no information)
    gain : (P, T, 3) radiance -> signal factor [sr m^2 W^-1] (exposure, white balance, falloff)
    pixels : (P, 2) (x, y), or a table's point names (P,)
    frames, times : manifest frame indices (T,) and ISO times (None for a lab light)
    warnings : what loading noticed (incomplete render, values left out)
    rays : a table's :class:`~skyfit_mi.render.light_cache.PointRays` (None for pixels)
    luminance : the values are luminances (first channel; see :class:`LuminanceModel`)
    """

    pixels: np.ndarray
    frames: list
    times: list
    y: np.ndarray
    sigma: np.ndarray
    gain: np.ndarray
    sensor: SensorModel
    warnings: list = field(default_factory=list)
    rays: object = None
    luminance: bool = False

    def recapture(self, radiance, rng):
        """Replace y and sigma by a noise replicate of ``radiance`` (P, T, 3) [W m^-2 sr^-1]."""
        y, sigma = self.sensor.capture(radiance * self.gain / self.sensor.exposure, rng)
        self.y, self.sigma = y.astype(float), sigma.astype(float)


def parse_region(text):
    """'rect:x0,y0,x1,y1' (inclusive) or 'pixels:x,y;x,y;...' -> (P, 2) array of (x, y)."""
    kind, _, rest = str(text).partition(":")
    try:
        if kind == "rect":
            x0, y0, x1, y1 = (int(v) for v in rest.split(","))
            if x1 < x0 or y1 < y0:
                raise ValueError
            xs, ys = np.meshgrid(np.arange(x0, x1 + 1), np.arange(y0, y1 + 1))
            return np.stack([xs.ravel(), ys.ravel()], axis=1)
        if kind == "pixels":
            px = np.array([[int(v) for v in p.split(",")] for p in rest.split(";") if p], int)
            if len(px) and px.shape[1] == 2:
                return px
    except ValueError:
        pass
    raise SkyfitError(f"region {text!r} is not 'rect:x0,y0,x1,y1' (whole numbers, x1 >= x0, "
                      "y1 >= y0) or 'pixels:x,y;x,y' (at least one pixel).")


def region_from_mask(path, label, shape=None):
    """Pixels of a label-mask image (8- or 16-bit PNG; first channel) equal to ``label``,
    as (P, 2) (x, y); ``shape`` (height, width): the frames', which the mask must have."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            m = np.asarray(im)
    except Exception as exc:          # missing, not an image, damaged: PIL/OS errors
        raise SkyfitError(f"cannot read mask {path} ({str(exc).splitlines()[0]}); give the PNG "
                          "`skyfit labels` wrote, or another label image.") from None
    m = m[..., 0] if m.ndim == 3 else m
    if shape is not None and m.shape != tuple(shape):
        raise SkyfitError(f"mask {path} is {m.shape[1]}x{m.shape[0]} but the frames are "
                          f"{shape[1]}x{shape[0]}; give a label image of the frames' size "
                          "(`skyfit labels` writes one).")
    ys, xs = np.nonzero(m == int(label))
    if len(xs) == 0:
        raise SkyfitError(f"label {label} does not occur in mask {path}; its values are "
                          f"{sorted(set(np.unique(m).tolist()))[:10]}.")
    return np.stack([xs, ys], axis=1)


#: Default most pixels of a region a fit takes (``fit --max-pixels``; a seeded random subset):
#: enough to tell a material well within its intervals, far faster than every pixel.
REGION_PIXELS = 64


def subsample_region(pixels, max_pixels, seed):
    """At most ``max_pixels`` of a region's (P, 2) pixels (or a table's (P,) point names), a
    seeded random subset in their order."""
    pixels = np.asarray(pixels)
    pixels = pixels if pixels.dtype == object else pixels.astype(int).reshape(-1, 2)
    if max_pixels is None or len(pixels) <= max_pixels:
        return pixels
    if max_pixels < 1:
        raise SkyfitError(f"max_pixels = {max_pixels}: give at least 1 (or none to fit every pixel).")
    keep = np.sort(np.random.default_rng(seed).choice(len(pixels), int(max_pixels), replace=False))
    return pixels[keep]


def load_table_observations(manifest_path, region, points=None, frames=None, min_frames=2):
    """A region's values and sigmas from a sequence's observation table
    (:mod:`~skyfit_mi.pipeline.observation_table`), on its sensor's linear scale, with the rays
    that meet its points; ``points`` (names) default to all of the region's.

    A saturated value v reads as an image's clipped pixel: at the top code, with its own gain
    (max - 0.5) / (max v) taking v to the clip point, so its Tobit term is
    -2 ln Phi((L - v) / sigma) for a model radiance L."""
    doc, root = load_manifest(manifest_path)
    rows = table_observations(doc, root, region, points, frames)
    fr = rows.frames
    known = {f["index"]: f for f in rendered_frames(doc)}
    missing = [i for i in fr if i not in known]
    if missing:
        raise SkyfitError(f"frame {missing[0]} is not an observed frame of the sequence; its "
                          f"frames are {sorted(known)}.")
    if len(fr) < min_frames:
        raise SkyfitError(f"region {region!r} is measured in {len(fr)} frame(s); at least "
                          f"{min_frames} are needed: measure it in more frames (or choose more "
                          "frames).")
    sensor = sensor_from_record(doc["sensor"])
    top = float(sensor.max_code)
    sat = rows.saturated
    # radiance -> normalised signal; a saturated value's gain takes it to the clip point
    gain = np.where(sat, (top - LOW_CODE) / (top * np.where(sat, rows.value, 1.0)),
                    sensor.exposure)
    return Observations(np.array(rows.names, dtype=object), fr,
                        [known[i].get("time") for i in fr],
                        np.where(sat, top, rows.value * gain * top), rows.sigma * gain * top,
                        gain, sensor,
                        rays=point_rays(rows.position, rows.view, doc["ingest"]["ray_offset"]),
                        luminance=rows.luminance)


class LuminanceModel:
    """A radiance model whose first output channel is the luminance Y = SRGB_LUMINANCE . (R, G, B)
    [W m^-2 sr^-1] (the others unchanged), for luminance observations: every output the fit uses
    (radiance, variance, Jacobian, basis, gradients) is mixed alike. Other attributes pass
    through to ``model``."""

    def __init__(self, model):
        self.inner = model
        self.mix = np.eye(3)
        self.mix[0] = SRGB_LUMINANCE

    def __getattr__(self, name):
        return getattr(self.__dict__["inner"], name)

    def __setattr__(self, name, value):
        # the wrapped model's counters (evaluations, ...) are reset through the wrapper
        if name in ("inner", "mix"):
            object.__setattr__(self, name, value)
        else:
            setattr(self.inner, name, value)

    def _mix(self, x, axis=-1):
        """x with its channel axis (``axis``) mixed."""
        return np.moveaxis(np.tensordot(self.mix, np.moveaxis(x, axis, 0), axes=1), 0, axis)

    def radiance(self, theta):
        return self._mix(self.inner.radiance(theta))

    def radiances(self, thetas, reduce=None):
        return self._mix(self.inner.radiances(thetas, reduce))

    def radiance_and_variance(self, theta):
        L, var = self.inner.radiance_and_variance(theta)
        # channels share their samples: bound the sum's variance by (sum of sds)^2
        return self._mix(L), self._mix(np.sqrt(var)) ** 2

    def jacobian(self, theta):
        L, J = self.inner.jacobian(theta)
        return self._mix(L), self._mix(J, axis=-2)

    def _pairs(self, out, halves):
        """The (D, G) of ``out`` (a list of them with ``halves``) mixed, a lazy G by its ``map``."""
        mixed = [(self._mix(D), G.map(self._mix) if hasattr(G, "map") else self._mix(G))
                 for D, G in (out if halves else [out])]
        return mixed if halves else mixed[0]

    def basis(self, sigmas, halves=False):
        return self._pairs(self.inner.basis(sigmas, halves), halves)

    def lobes(self, sigmas, halves=False):
        return self._pairs(self.inner.lobes(sigmas, halves), halves)

    def gradient(self, theta, dloss_dL):
        return self.inner.gradient(theta, np.tensordot(dloss_dL, self.mix, axes=1))


def block_sharing(pixels, block=8, offset=(0, 0)):
    """How many of ``pixels`` (P, 2) (x, y) lie in each one's 8x8 JPEG block (P,); blocks start
    at ``offset`` (x, y) (``jpeg_block_offset``)."""
    cells = (np.asarray(pixels, dtype=int).reshape(-1, 2) - np.asarray(offset, dtype=int)) \
        // block
    _, inverse, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    return counts[inverse.ravel()].astype(float)


def neighbour_sharing(pixels, correlation):
    """Kish's design effect of each of ``pixels`` (P, 2) per channel (P, 3), at least 1: 1 plus
    the sum of its error's correlation with the others' within R pixels, ``correlation`` (3,
    2 R + 1, 2 R + 1) by offset (dy, dx) (a RAW frame's ``raw_demosaic.noise_correlation``)."""
    px = np.asarray(pixels, dtype=int).reshape(-1, 2)
    corr = np.asarray(correlation, dtype=float)
    n = corr.shape[-1] // 2
    x, y = px[:, 0] - px[:, 0].min() + n, px[:, 1] - px[:, 1].min() + n
    grid = np.zeros((y.max() + n + 1, x.max() + n + 1), dtype=bool)
    grid[y, x] = True
    out = np.ones((len(px), 3))
    for dy in range(-n, n + 1):
        for dx in range(-n, n + 1):
            if dy or dx:
                out += grid[y + dy, x + dx][:, None] * corr[None, :, dy + n, dx + n]
    return np.maximum(out, 1.0)


@functools.lru_cache(maxsize=4)
def _colour_mixed(root, run_id, reach):
    """:func:`~skyfit_mi.pipeline.pixels.colour_mixed` of the sequence in ``root`` (cached)."""
    return colour_mixed(scene_labels(root)[2], reach)


def chosen_frames(doc, root, frames=None, min_frames=2):
    """The rendered frames (manifest records) of the sequence ``doc`` in ``root`` among
    ``frames`` (indices; None: all); SkyfitError naming one that is not rendered, or if fewer
    than ``min_frames`` remain or all are black."""
    rendered = rendered_frames(doc)
    if frames is not None:
        known = {f["index"] for f in rendered}
        missing = sorted(set(frames) - known)
        if missing:
            raise SkyfitError(f"frame {missing[0]} is not a rendered frame of the sequence; the "
                              f"rendered frames are {sorted(known)}.")
        rendered = [f for f in rendered if f["index"] in set(frames)]
    if len(rendered) < min_frames:
        raise SkyfitError(f"{root} has {len(rendered)} rendered frame(s)"
                          f"{' of those chosen' if frames is not None else ''}; at least "
                          f"{min_frames} are needed: render the sequence (or choose more frames).")
    if all(f.get("dark") for f in rendered):
        raise SkyfitError(f"every {'chosen ' if frames is not None else ''}frame of {root} is "
                          "black (marked dark: no light reached the camera at its exposure); "
                          "render it with a larger exposure, or choose lit frames.")
    return rendered


def load_observations(manifest_path, pixels, frames=None, min_frames=2, one_fit=True):
    """Read a region's pixel values and sigmas from the rendered frames of a manifest.

    ``pixels`` (P, 2) (x, y); ``frames``: manifest frame indices (default every rendered one).
    Non-finite values are left out (counted in ``warnings``; a frame with none finite raises
    SkyfitError). Correlated errors widen sigma by Kish's design effect, sqrt(1 + (k - 1) rho)
    for k region pixels in a JPEG block, sqrt(:func:`neighbour_sharing`) for RAW demosaicing,
    except for per-pixel fits (``one_fit`` False), which also keep the pixels whose colour a
    frame mixes with another material's (else left out with a warning). Where greys of several
    levels measured a camera's own tone curve at ingest, each value's gain is read through it
    (:func:`~.tone.curve_reading`).
    """
    doc, root = load_manifest(manifest_path)
    cam = doc["camera"]
    w, h = cam["width"], cam["height"]
    pixels = np.asarray(pixels, dtype=int).reshape(-1, 2)
    if len(pixels) == 0:
        raise SkyfitError("the region has no pixels; give a region on the material.")
    bad = (pixels[:, 0] < 0) | (pixels[:, 0] >= w) | (pixels[:, 1] < 0) | (pixels[:, 1] >= h)
    if bad.any():
        x, y = pixels[bad][0]
        raise SkyfitError(f"region pixel {x},{y} is outside the {w}x{h} frames; x in [0, {w - 1}],"
                          f" y in [0, {h - 1}].")
    rendered = chosen_frames(doc, root, frames, min_frames)
    warnings = []
    if doc.get("status") != "complete":
        warnings.append("the sequence's render is incomplete (manifest status "
                        f"{doc.get('status')!r}): only {len(rendered)} of its "
                        f"{len(doc['frames'])} frames are fitted; finish it with `skyfit render`.")
    reach = colour_reach(doc)
    mixing = "a RAW's demosaicing" if any("raw_demosaic" in f for f in rendered) \
        else "the JPEGs' subsampled chroma" if any("jpeg_dc" in f and max(
            f["jpeg_dc"]["chroma_subsampling"]) > 1 for f in rendered) \
        else "the frames' registration, resampled"
    mixed = np.zeros(len(pixels), bool)
    if reach and one_fit:
        mixed = _colour_mixed(str(root), doc.get("run_id"), reach)[pixels[:, 1], pixels[:, 0]]
        if mixed.all():
            raise SkyfitError(f"every pixel of the region lies within {reach} pixels of another "
                              f"material, where the frames mix the two's colours ({mixing}); "
                              "give a region further inside the material.")
        if mixed.any():
            warnings.append(f"{int(mixed.sum())} of the region's {len(pixels)} pixels lie within "
                            f"{reach} pixels of another material, where the frames mix the "
                            f"two's colours ({mixing}), and are left out.")
    sensor = sensor_from_record(doc["sensor"])
    falloff = sensor.gain(w, h, cam["fov_deg"])[pixels[:, 1], pixels[:, 0]] / sensor.exposure
    if doc["sensor"].get("flat_field"):         # a measured vignetting (ingest), per pixel
        flat = read_frame_pixels(root, {"index": "flat field", "flat": doc["sensor"]["flat_field"]},
                                 "flat", (h, w, 3), pixels)
        falloff = falloff * flat[:, 0]
    ys, sig, gain = [], [], []
    for f in rendered:
        y = read_frame_pixels(root, f, "sensor", (h, w, 3), pixels)
        s = read_frame_pixels(root, f, "sigma", (h, w, 3), pixels)
        if "jpeg_block_correlation" in f:          # a JPEG's errors shared within its blocks
            shared = block_sharing(pixels, offset=f.get("jpeg_block_offset", (0, 0))) \
                if one_fit else np.ones(len(pixels))
            rho = np.asarray(f["jpeg_block_correlation"], dtype=float)
            s = s * np.sqrt(1.0 + (shared[:, None] - 1.0) * rho[None, :])
        if "raw_demosaic" in f and one_fit:        # a RAW's errors shared by neighbours
            deff = np.ones((len(pixels), 3))
            deff[~mixed] = neighbour_sharing(pixels[~mixed],
                                             f["raw_demosaic"]["noise_correlation"])
            s = s * np.sqrt(deff)
        ok = np.isfinite(y) & ~np.isnan(s) & (s > 0)          # sigma inf: a clipped value's
        if not ok[~mixed].any():
            raise SkyfitError(f"frame {f['index']} ({root / f['sensor']}, {f['sigma']}) has no "
                              "value in the region that is finite with a positive sigma; repair "
                              "or re-render that frame.")
        if not ok[~mixed].all():
            warnings.append(f"frame {f['index']}: {int((~ok[~mixed]).sum())} of the region's "
                            "values are not finite (NaN) or have no positive sigma, and are "
                            "left out.")
        ok[mixed] = False
        ys.append(np.where(ok, y, 0.0))
        sig.append(np.where(ok, s, np.inf))
        gain.append(falloff[:, None] * frame_exposure(doc, f)[None, :])
    obs = Observations(pixels, [f["index"] for f in rendered], [f.get("time") for f in rendered],
                       np.stack(ys, 1).astype(float), np.stack(sig, 1).astype(float),
                       np.stack(gain, 1), sensor, warnings)
    reading = curve_reading(doc, obs)      # a camera's own tone curve, measured at ingest
    if reading is not None:
        obs.gain = obs.gain * np.exp(reading[0])
        obs.sigma = obs.sigma * np.maximum(np.abs(1.0 - reading[1]), tone_curve.SLOPE_FLOOR)
    return obs


def check_regions(manifest_path, regions, frames=None):
    """Check every region [(material, pixels or None)] and its frames before any fit is written."""
    doc, root = load_manifest(manifest_path)
    materials = doc["scene"]["materials"]
    for name, pixels in regions:
        if name not in materials:
            raise SkyfitError(f"region {name!r} names no material of the scene; its materials "
                              f"are: {', '.join(materials)}.")
        if is_table(doc):
            load_table_observations(manifest_path, name, pixels, frames)
        else:
            load_observations(manifest_path, pixels, frames)
    check_frames(doc, root, kinds=(), frames=frames)


def censored_term_moments(a, b):
    """Mean and variance of one value's chi^2 term under pure noise (the Tobit terms above).

    The value is m + sigma e, e standard normal, clipped at a and b (standard units); it
    contributes e^2 between them and -2 ln P at a clipped end of probability P. Truncated
    moments: int_a^b e^2 phi = [Phi - e phi]_a^b, int_a^b e^4 phi = [3 Phi - (e^3 + 3 e) phi]_a^b.
    Returns (mean, variance) arrays; (1, 2) far from both ends.
    """
    a = np.clip(np.asarray(a, float), -40.0, 40.0)
    b = np.clip(np.asarray(b, float), -40.0, 40.0)
    phi = lambda e: np.exp(-0.5 * e * e) / np.sqrt(2.0 * np.pi)  # noqa: E731
    m2 = (ndtr(b) - b * phi(b)) - (ndtr(a) - a * phi(a))
    m4 = (3 * ndtr(b) - (b**3 + 3 * b) * phi(b)) - (3 * ndtr(a) - (a**3 + 3 * a) * phi(a))
    mean, second = m2, m4
    for p in (ndtr(a), ndtr(-b)):                  # the low and the high clipped ends
        t = np.where(p > 0, -2.0 * np.log(np.maximum(p, 1e-300)), 0.0)
        mean = mean + p * t
        second = second + p * t * t
    return mean, np.maximum(second - mean * mean, 0.0)


def usable_values(obs, valid=None):
    """Which of ``obs``'s values (P, T, 3) carry information (finite positive sigma, ``valid``)."""
    ok = np.isfinite(obs.sigma) & (obs.sigma > 0)
    return ok if valid is None else ok & valid[..., None]


class Problem:
    """chi^2(a) for one region: observations, and a radiance model with ``radiance``,
    ``jacobian`` and, for :meth:`chi2_at`, ``radiances``."""

    def __init__(self, obs, model, valid=None, held_out=False):
        """``held_out``: values only predicted (a fold held out), however few."""
        self.obs, self.model, self.valid = obs, model, valid
        ok = self.mask = usable_values(obs, valid)
        self.n_data = int(ok.sum())
        self.n_params = len(model.names)
        if self.n_data <= self.n_params and not held_out:
            raise SkyfitError(f"only {self.n_data} usable pixel values (the rest saturated or off "
                              f"the material) for {self.n_params} parameters; choose a larger "
                              "region or a lower exposure.")
        self.evaluations = 0

    @property
    def dof(self):
        return self.n_data - self.n_params

    def predict(self, radiance):
        """Pixel values [DN] the sensor gives for radiance (P, T, 3)."""
        s = radiance * self.obs.gain
        return self.obs.sensor.respond(s) * self.obs.sensor.max_code

    def slope(self, radiance):
        """d(pixel value) / d(radiance) [DN per W m^-2 sr^-1], shape (P, T, 3)."""
        g = self.obs.gain
        return self.obs.sensor.slope(radiance * g) * self.obs.sensor.max_code * g

    def clipped(self):
        """Boolean masks of the values clipped at the lowest and at the highest code."""
        return self.mask & (self.obs.y <= 0), self.mask & (self.obs.y >= self.obs.sensor.max_code)

    def measured(self):
        """Boolean mask of the usable values not clipped (a clipped one tells only a bound)."""
        low, high = self.clipped()
        return self.mask & ~low & ~high

    def measured_range(self, radiance, means=True):
        """Per channel, the radiance range [lo, hi] [W m^-2 sr^-1] the data measured (None:
        nowhere): from the least region mean (``means``; else value) with nothing clipped at the
        top and relative standard error at most MEASURED_SE, to the greatest unclipped value.
        A prediction beyond it rests on the model alone."""
        _, high = self.clipped()
        slope = self.slope(radiance)
        ok = self.measured() & (slope > 0)
        var = np.where(ok, self.obs.sigma / np.where(ok, slope, 1.0), 0.0) ** 2
        if means:
            n = self.mask.sum(axis=0)
            level = np.where(self.mask, radiance, 0.0).sum(axis=0) / np.maximum(n, 1)
            told = (n > 0) & ~high.any(axis=0) & (np.sqrt(var.sum(axis=0)) / np.maximum(n, 1)
                                                  <= MEASURED_SE * level)
        else:
            level, told = radiance, ok & (np.sqrt(var) <= MEASURED_SE * radiance)
        return [[float(level[..., c][told[..., c]].min()), float(radiance[..., c][ok[..., c]].max())]
                if told[..., c].any() else None for c in range(radiance.shape[-1])]

    def residual_terms(self, radiance, derivative=True):
        """Residuals of every value (P, T, 3) and their derivative d r / d(model value) (None
        without ``derivative``); of several radiances at once (n, P, T, 3) too.

        Measured values: (y - m) / sigma.  Clipped ones: sqrt(-2 ln P(clipped)), with
        z = -(m - 0.5) / sigma at the bottom and (m - max + 0.5) / sigma at the top.
        """
        m = self.predict(radiance)
        sig = self.obs.sigma
        r = (self.obs.y - m) / sig
        dr = np.broadcast_to(-1.0 / sig, r.shape).copy() if derivative else None
        low, high = self.clipped()
        c = low | high
        if c.any():
            sign = np.where(low, -1.0, 1.0)[c]
            z = sign * (m[..., c] - np.where(low, LOW_CODE,
                                             self.obs.sensor.max_code - LOW_CODE)[c]) / sig[c]
            r[..., c] = np.sqrt(-2.0 * log_ndtr(z))
            if derivative:
                # d r / d m = -sign phi(z) / (sigma Phi(z) r)
                dr[..., c] = -sign * np.exp(-0.5 * z * z - 0.5 * np.log(2 * np.pi)
                                            - log_ndtr(z)) / (sig[c] * r[..., c])
        return r, dr

    def noise_chi2(self, theta):
        """Mean and variance of the chi^2 noise alone gives at ``theta``, scaled to the dof (dof
        and 2 dof when nothing can clip; a clipped term expects up to 1.39)."""
        m = self.predict(self.model.radiance(theta))[self.mask]
        sig = self.obs.sigma[self.mask]
        mean, var = censored_term_moments((LOW_CODE - m) / sig,
                                          (self.obs.sensor.max_code - LOW_CODE - m) / sig)
        share = self.dof / self.n_data
        return float(mean.sum() * share), float(var.sum() * share)

    def value_scale(self, theta):
        """Each value's own size [DN] (P, T, 3), by which the model's relative error scales: the
        observed value (a clipped one: the model's at ``theta``), since weights following the
        model's misses keep a misfit fit from settling (cost: a bias of about 2 kappa^2)."""
        measured = self.obs.sensor.linearise(self.obs.y) / self.obs.gain
        low, high = self.clipped()
        L = np.where(low | high, self.model.radiance(theta), measured)
        return L * self.slope(L)

    def model_error(self, theta):
        """The model's relative error beyond the noise (incl. Monte Carlo) at ``theta``, from
        the unclipped values (:func:`~.uncertainty.model_error`)."""
        L, var = self.model.radiance_and_variance(theta)
        use = self.measured()
        return unc.model_error((self.obs.y - self.predict(L))[use],
                               (self.obs.sigma ** 2 + self.slope(L) ** 2 * var)[use],
                               self.value_scale(theta)[use], self.dof)

    def with_model_error(self, kappa, theta):
        """This chi^2 with each value's sigma widened by the model's error, sqrt(sigma^2 +
        (kappa y)^2) (y the value's :meth:`value_scale`; ``theta`` gives a clipped value's)."""
        return Problem(replace(self.obs, sigma=np.hypot(self.obs.sigma,
                                                        kappa * self.value_scale(theta))),
                       self.model, self.valid)

    def chi2s(self, radiances):
        """Chi-square (eq. 6.2) of each of several radiances (n, P, T, 3), at once."""
        r = self.residual_terms(radiances, derivative=False)[0]
        return np.sum(np.where(self.mask, r * r, 0.0), axis=(1, 2, 3))

    def chi2_at(self, thetas):
        """Chi-square (eq. 6.2) at each parameter set of ``thetas`` (n, params), from the model's
        radiances CHUNK_VALUES values at a time."""
        thetas = np.atleast_2d(thetas)
        self.evaluations += len(thetas)
        step = max(1, CHUNK_VALUES // self.obs.y.size)
        return np.concatenate([self.chi2s(self.model.radiances(thetas[start:start + step]))
                               for start in range(0, len(thetas), step)])

    def residuals(self, theta):
        """(y - y(a)) / sigma over usable values, flat."""
        self.evaluations += 1
        return self.residual_terms(self.model.radiance(theta), derivative=False)[0][self.mask]

    def chi2(self, theta):
        """Thesis eq. 6.2."""
        r = self.residuals(theta)
        return float(r @ r)

    def model_noise_chi2(self, theta):
        """Expected share of chi^2 at ``theta`` from the model's own Monte Carlo variance,
        sum var(y(x; a)) / sigma^2; also the size of chi^2's ripples between nearby parameters."""
        L, var = self.model.radiance_and_variance(theta)
        return float(np.sum((self.slope(L) ** 2 * var / self.obs.sigma**2)[self.mask]))

    def jacobian(self, theta, full=False):
        """(residuals, d residuals / d theta) over the usable values, or with ``full`` all."""
        self.evaluations += 1
        L, dL = self.model.jacobian(theta)
        r, dr = self.residual_terms(L)
        J = (dr * self.slope(L))[..., None] * dL
        return (r, J) if full else (r[self.mask], J[self.mask])
