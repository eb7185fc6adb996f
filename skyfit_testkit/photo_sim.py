"""A rendered day as a camera would have photographed it: JPEG/PNG/TIFF/DNG frames with EXIF.

For tests of ``skyfit ingest`` and the shipped example, a ``render`` sequence folder becomes
image files degraded as photographs are: auto-exposure (shutter steps in EXIF), cos^4 vignetting
(thesis eq. 5.6), read and shot noise in linear codes, sRGB or gamma encoding, clipping,
quantisation and JPEG compression.  Or a camera RAW (``fmt="dng"``): the scene in the camera's
RGB (:data:`RAW_XYZ_TO_CAMERA`) through an RGGB Bayer filter, noisy raw codes above a black
level, in a DNG whose ColorMatrix1 lets LibRaw develop it back to linear sRGB (with
``matrix_error``, through a matrix that errs).  Random draws use
``numpy.random.default_rng([seed, frame index])``; the seed and each frame's true exposure
[sr m^2 W^-1] are written to ``photos.json``.
"""

import datetime as dt
import struct
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from skyfit_mi.errors import SkyfitError
from skyfit_mi.files import atomic_write, ensure_dir, write_json
from skyfit_mi.physics.camera import SensorModel
from skyfit_mi.physics.colour import XYZ_TO_SRGB
from skyfit_mi.pipeline.manifest import load_manifest, read_frame_image, rendered_frames
from skyfit_mi.pipeline.orientation import undo_orientation

#: EXIF tags (the Exif sub-IFD 0x8769) written for each frame.
EXIF_IFD, DATETIME_ORIGINAL, OFFSET_TIME_ORIGINAL = 0x8769, 0x9003, 0x9011
EXPOSURE_TIME, F_NUMBER, ISO = 0x829A, 0x829D, 0x8827
ORIENTATION = 0x0112
#: The simulated camera's aperture and ISO (only their ratio to the exposure time matters).
SIM_F_NUMBER, SIM_ISO = 8.0, 100
#: Shutter times of the auto-exposure [s]: 36 third stops down from 1/15 s.
SHUTTER_STOPS = 2.0 ** (-np.arange(36) / 3.0) / 15.0
#: A camera's shutter labels [s] (``nominal_exif``): the rounded nominal third-stop series,
#: 1/8000 to 1/15 s; the simulated shutter's times (:data:`SHUTTER_STOPS`) lie 0-6% off them.
NOMINAL_SHUTTER = 1.0 / np.array([8000, 6400, 5000, 4000, 3200, 2500, 2000, 1600, 1250, 1000,
                                  800, 640, 500, 400, 320, 250, 200, 160, 125, 100, 80, 60, 50,
                                  40, 30, 25, 20, 15])
#: The largest relative offset of a nominal label from the time it stands for.
NOMINAL_REACH = 0.07
FORMATS = {"jpeg": ".jpg", "png": ".png", "tiff": ".tif", "dng": ".dng"}
#: The RAW camera of ``fmt="dng"``: XYZ (D65) -> camera RGB of the Canon EOS 5D Mark II (Adobe's
#: ColorMatrix, LibRaw's ``adobe_coeff`` x 10^-4), far from diagonal as a real sensor's is.
RAW_XYZ_TO_CAMERA = np.array([[4716, 603, -830], [-7798, 15474, 2480],
                              [-1496, 1937, 6651]]) / 1e4
#: The RAW sensor: bits, black level [DN] (the 5D Mark II's), read noise [DN rms] and shot noise
#: [DN^2 per DN] (a 60000-electron full well over the 15360 DN above black).
RAW_BITS, RAW_BLACK, RAW_READ_NOISE_DN, RAW_SHOT_GAIN = 14, 1024, 6.0, 0.26
#: DNG tags written (TIFF/EP and DNG 1.4 specifications).
_DNG_CFA_REPEAT, _DNG_CFA_PATTERN, _DNG_VERSION, _DNG_BACKWARD = 33421, 33422, 50706, 50707
_DNG_MODEL, _DNG_BLACK, _DNG_WHITE = 50708, 50714, 50717
_DNG_COLOR_MATRIX_1, _DNG_ILLUMINANT_1, _DNG_NEUTRAL = 50721, 50778, 50728
_TIFF_MAKE, _TIFF_MODEL, _TIFF_ORIENTATION = 271, 272, 274
#: CalibrationIlluminant1: D65 (EXIF LightSource 21), the white of linear sRGB.
_D65 = 21


def raw_camera_matrix(xyz_to_camera=RAW_XYZ_TO_CAMERA):
    """A (3, 3) with raw RGB = A @ linear sRGB for an XYZ (D65) -> camera matrix, green's row
    summing to 1."""
    a = np.asarray(xyz_to_camera, dtype=float) @ np.linalg.inv(XYZ_TO_SRGB)
    return a / a[1].sum()


def matrix_error_mix(matrix_error, seed):
    """(3, 3) mix with developed linear sRGB = mix @ true linear sRGB for a DNG colour matrix off
    by ``matrix_error``: I + matrix_error G, G's off-diagonal entries N(0, 1) from
    default_rng(seed), its rows summing to 0 (LibRaw keeps a grey grey)."""
    g = np.random.default_rng(seed).normal(size=(3, 3))
    np.fill_diagonal(g, 0.0)
    g -= np.diag(g.sum(axis=1))
    return np.eye(3) + float(matrix_error) * g


def colour_matrix_1(mix, to_camera=None):
    """The DNG ColorMatrix1 (XYZ -> camera) through which LibRaw develops camera ``to_camera``
    (:func:`raw_camera_matrix`) into ``mix`` @ linear sRGB, white-balanced by AsShotNeutral."""
    a = raw_camera_matrix() if to_camera is None else to_camera
    return a @ np.linalg.inv(mix) @ XYZ_TO_SRGB


def _mosaic(camera):
    """(H, W) of an (H, W, 3) camera image sampled through an RGGB Bayer filter."""
    h, w = camera.shape[:2]
    channel = np.array([[0, 1], [1, 2]])[np.arange(h)[:, None] % 2, np.arange(w)[None, :] % 2]
    return np.take_along_axis(camera, channel[..., None], axis=2)[..., 0]


def _rationals(values, den=1_000_000):
    return [x for v in np.ravel(values) for x in (int(round(float(v) * den)), den)]


def _ifd(entries, start):
    """A little-endian TIFF IFD at offset ``start`` of ``entries`` [(tag, type, count, bytes)]."""
    head = struct.pack("<H", len(entries))
    data, table = b"", b""
    tail = start + 2 + 12 * len(entries) + 4
    for tag, kind, count, value in sorted(entries):
        if len(value) <= 4:
            table += struct.pack("<HHI", tag, kind, count) + value.ljust(4, b"\0")
        else:
            table += struct.pack("<HHII", tag, kind, count, tail + len(data))
            data += value + b"\0" * (len(value) % 2)
    return head + table + struct.pack("<I", 0) + data


def _exif(time, offset, exposure_time, orientation=1):
    from PIL import Image
    from PIL.TiffImagePlugin import IFDRational

    ex = Image.Exif()
    ifd = ex.get_ifd(EXIF_IFD)
    ifd[DATETIME_ORIGINAL] = time.strftime("%Y:%m:%d %H:%M:%S")
    if offset:
        ifd[OFFSET_TIME_ORIGINAL] = time.isoformat()[-6:]
    fr = Fraction(exposure_time).limit_denominator(100000)
    ifd[EXPOSURE_TIME] = IFDRational(fr.numerator, fr.denominator)
    ifd[F_NUMBER] = IFDRational(int(SIM_F_NUMBER * 10), 10)
    ifd[ISO] = SIM_ISO
    if orientation != 1:
        ex[ORIENTATION] = int(orientation)
    return ex


def _exif_entries(time, offset, exposure_time):
    """The EXIF sub-IFD's entries [(tag, type, count, bytes)] of :func:`_exif`'s fields."""
    def ascii(text):
        b = text.encode("ascii") + b"\0"
        return (2, len(b), b)
    fr = Fraction(exposure_time).limit_denominator(100000)
    entries = [(EXPOSURE_TIME, 5, 1, struct.pack("<II", fr.numerator, fr.denominator)),
               (F_NUMBER, 5, 1, struct.pack("<II", int(SIM_F_NUMBER * 10), 10)),
               (ISO, 3, 1, struct.pack("<H", SIM_ISO)),
               (DATETIME_ORIGINAL, *ascii(time.strftime("%Y:%m:%d %H:%M:%S")))]
    if offset:
        entries.append((OFFSET_TIME_ORIGINAL, *ascii(time.isoformat()[-6:])))
    return entries


def write_dng(path, mosaic, xyz_to_camera, neutral, *, black=RAW_BLACK, white=2 ** RAW_BITS - 1,
              exif=(), orientation=1):
    """A DNG of one RGGB CFA image ``mosaic`` (H, W) [raw DN] with the tags LibRaw needs
    (ColorMatrix1 ``xyz_to_camera``, AsShotNeutral ``neutral``, levels, ``exif`` entries,
    ``orientation``); returns ``path``.  tifffile cannot write the EXIF pointer (0x8769), so
    the sub-IFD is appended with a copy of IFD0 pointing to it, and the header to that copy."""
    import tifffile

    tags = [(_TIFF_MAKE, "s", 0, "Skyfit", True), (_TIFF_MODEL, "s", 0, "Simulated RAW", True),
            (_TIFF_ORIENTATION, "H", 1, int(orientation), True),
            (_DNG_CFA_REPEAT, "H", 2, (2, 2), True), (_DNG_CFA_PATTERN, "B", 4, (0, 1, 1, 2), True),
            (_DNG_VERSION, "B", 4, (1, 4, 0, 0), True), (_DNG_BACKWARD, "B", 4, (1, 1, 0, 0), True),
            (_DNG_MODEL, "s", 0, "Skyfit Simulated RAW", True),
            (_DNG_BLACK, "H", 1, int(black), True), (_DNG_WHITE, "H", 1, int(white), True),
            (_DNG_COLOR_MATRIX_1, "2i", 9, _rationals(xyz_to_camera), True),
            (_DNG_ILLUMINANT_1, "H", 1, _D65, True),
            (_DNG_NEUTRAL, "2I", 3, _rationals(neutral), True)]
    tifffile.imwrite(path, np.asarray(mosaic, np.uint16), photometric=32803, subfiletype=0,
                     byteorder="<", bigtiff=False, extratags=tags)
    if not exif:
        return path
    with open(path, "r+b") as fh:
        data = fh.read()
        ifd0 = struct.unpack_from("<I", data, 4)[0]
        n = struct.unpack_from("<H", data, ifd0)[0]
        entries = [data[ifd0 + 2 + 12 * k:ifd0 + 14 + 12 * k] for k in range(n)]
        following = data[ifd0 + 2 + 12 * n:ifd0 + 6 + 12 * n]
        start = len(data) + len(data) % 2                # the copy of IFD0, word aligned
        sub = start + 2 + 12 * (n + 1) + 4                # the EXIF IFD after it
        entries.append(struct.pack("<HHII", EXIF_IFD, 4, 1, sub))
        entries.sort(key=lambda e: struct.unpack_from("<H", e)[0])
        fh.seek(len(data))
        fh.write(b"\0" * (start - len(data)) + struct.pack("<H", n + 1) + b"".join(entries)
                 + following + _ifd(list(exif), sub))
        fh.seek(4)
        fh.write(struct.pack("<I", start))
    return path


@dataclass(frozen=True)
class PhotoSettings:
    """The camera of :func:`photograph_day` and how it writes its photographs.

    exposure : [sr m^2 W^-1] at 1/15 s, f/8, ISO 100; default twice the sequence's
    target : largest share of full scale for the 99th-percentile linear signal
    response, gamma : the encoding (``srgb``, ``gamma``, ``linear``; not a RAW's)
    read_noise_DN, shot_gain : sigma^2 = read^2 + shot_gain x code (:meth:`noise`)
    cos4, offset : apply cos^4 vignetting; write EXIF OffsetTimeOriginal
    fmt, quality : 'jpeg', 'png' or 'tiff' (8-bit), or 'dng' (RAW_BITS); JPEG quality (1-100)
    shutter_error : relative sd of each frame's true exposure about its EXIF one
    nominal_exif : label each shutter time in EXIF as a camera does, with the nearest of the
        nominal series (:data:`NOMINAL_SHUTTER`: 0-6% off the time the shutter gave; a time
        beyond the series raises ValueError)
    orientation : EXIF orientation code; the file holds the frame turned back
    subsampling : JPEG chroma: 0 (4:4:4), 1 (4:2:2) or 2 (4:2:0, Pillow's default)
    matrix_error : a RAW's ColorMatrix1 error (:func:`matrix_error_mix`)
    motion : {frame index: (dx [px], dy [px], rotation [degrees])}: the camera nudged
        (:mod:`.registration`'s convention), before vignetting and noise
    distortion : (k1[, k2]) radial lens distortion (:func:`~skyfit_mi.physics.lens.distort`)
    tone_curve : a camera's own tone curve's strength A: the linear signal x becomes
        x exp(D(ln x)) before the response encodes it, D(t) = A (g(t) - g(0)) with g a Gaussian
        of width TONE_WIDTH about ln TONE_MIDDLE (:func:`camera_tone`); 0: none
    """

    exposure: float | None = None
    target: float = 0.5
    response: str = "srgb"
    gamma: float = 2.2
    read_noise_DN: float | None = None
    shot_gain: float | None = None
    cos4: bool = True
    fmt: str = "jpeg"
    quality: int = 95
    offset: bool = True
    shutter_error: float = 0.0
    nominal_exif: bool = False
    orientation: int = 1
    subsampling: int = 0
    matrix_error: float = 0.0
    motion: dict | None = None
    distortion: tuple = ()
    tone_curve: float = 0.0

    def noise(self):
        """(read noise [DN rms], shot gain [DN]) in the format's codes: as given, else 0.8
        and 0.02 of 8-bit codes, for a RAW RAW_READ_NOISE_DN and RAW_SHOT_GAIN."""
        raw = self.fmt == "dng"
        return (self.read_noise_DN if self.read_noise_DN is not None
                else RAW_READ_NOISE_DN if raw else 0.8,
                self.shot_gain if self.shot_gain is not None
                else RAW_SHOT_GAIN if raw else 0.02)


def _lens(radiance, motion, k, fov):
    """``radiance`` (H, W, 3) as seen by a camera moved by ``motion`` (dx, dy, rotation_deg, or
    None) through a lens of distortion ``k`` (bicubic, edges repeated)."""
    if motion is None and not any(k):
        return radiance
    import cv2

    from skyfit_mi.physics.lens import focal_px, undistort

    h, w = radiance.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    c = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    if any(k):
        f = focal_px(fov, w)
        x, y = undistort((xx - c[0]) / f, (yy - c[1]) / f, k)
        xx, yy = f * x + c[0], f * y + c[1]
    if motion is not None:
        dx, dy, deg = motion
        t = np.radians(deg)
        px, py = xx - c[0] - dx, yy - c[1] - dy           # q = R^T (p - c - d) + c
        xx = np.cos(t) * px + np.sin(t) * py + c[0]
        yy = -np.sin(t) * px + np.cos(t) * py + c[1]
    return cv2.remap(radiance, xx.astype(np.float32), yy.astype(np.float32), cv2.INTER_CUBIC,
                     borderMode=cv2.BORDER_REPLICATE).astype(float)


#: The simulated camera's tone curve (:func:`camera_tone`): its middle [fraction of full scale]
#: and width [in ln signal], a bump in ln signal like cameras' measured curves' (a brighter
#: middle, a toe and a shoulder) but none of them.
TONE_MIDDLE, TONE_WIDTH = 0.15, 1.2


def camera_tone(x, strength):
    """Linear signal ``x`` [fraction of full scale] through a camera's own tone curve of
    ``strength`` A (:class:`PhotoSettings`): x exp(A (g(ln x) - g(0))), monotone for A < 1.6,
    1 at full scale."""
    if not strength:
        return x
    def g(t):
        return np.exp(-0.5 * ((t - np.log(TONE_MIDDLE)) / TONE_WIDTH) ** 2)
    with np.errstate(divide="ignore"):
        t = np.log(np.clip(x, 1e-12, None))
    return x * np.exp(strength * (g(t) - g(0.0)))


def photograph_day(sequence, out_dir, settings=None, seed=0):
    """Photograph ``sequence``'s rendered frames into ``out_dir`` as ``settings`` says; returns
    the paths in time order."""
    from PIL import Image

    photo = settings or PhotoSettings()
    fmt, orientation, offset = photo.fmt, photo.orientation, photo.offset
    doc, root = load_manifest(sequence)
    if fmt not in FORMATS:
        raise SkyfitError(f"format {fmt!r}; give one of {', '.join(FORMATS)}.")
    raw = fmt == "dng"
    read_noise_DN, shot_gain = photo.noise()
    if raw:
        white = 2 ** RAW_BITS - 1
        to_camera = raw_camera_matrix()
        mix = matrix_error_mix(photo.matrix_error, seed)
        written = colour_matrix_1(mix, to_camera)
        neutral = to_camera.sum(axis=1)                   # the raw response to white
    cam = doc["camera"]
    h, w = cam["height"], cam["width"]
    base = (2.0 * float(doc["sensor"]["exposure"]) if photo.exposure is None
            else float(photo.exposure))
    sensor = SensorModel(exposure=1.0, response=photo.response, gamma=photo.gamma, bits=8)
    falloff = sensor.falloff(w, h, cam["fov_deg"]) if photo.cos4 else np.ones((h, w))
    out = Path(out_dir)
    ensure_dir(out)
    paths, record = [], []
    for f in rendered_frames(doc):
        rng = np.random.default_rng([seed, f["index"]])
        radiance = _lens(read_frame_image(root, f, "radiance", (h, w, 3)).astype(np.float32),
                         (photo.motion or {}).get(f["index"]), photo.distortion, cam["fov_deg"])
        signal = radiance * falloff[..., None]
        p99 = float(np.percentile(signal, 99)) * base
        stops = SHUTTER_STOPS[SHUTTER_STOPS * 15.0 * p99 <= photo.target]
        t = float(stops[0] if len(stops) else SHUTTER_STOPS[-1])
        e = base * t * 15.0                                   # exposure at this shutter time
        miss = float(np.random.default_rng([seed, f["index"], 1]).normal()) * photo.shutter_error
        e_true = e * (1.0 + miss)                             # what the shutter really gave
        time = dt.datetime.fromisoformat(f["time"])
        label = float(NOMINAL_SHUTTER[np.argmin(np.abs(np.log(NOMINAL_SHUTTER / t)))]) \
            if photo.nominal_exif else t                     # the EXIF shutter time
        if abs(np.log(label / t)) > NOMINAL_REACH:
            raise ValueError(f"no nominal shutter label within {NOMINAL_REACH:.0%} of {t:.3g} s")
        path = out / f"IMG_{f['index']:04d}{FORMATS[fmt]}"
        if raw:
            camera = np.clip(signal * e_true @ to_camera.T, 0.0, None) * (white - RAW_BLACK)
            dn = _mosaic(undo_orientation(camera, orientation))
            dn = dn + rng.normal(size=dn.shape) * np.sqrt(read_noise_DN ** 2 + shot_gain * dn)
            mosaic = np.clip(np.rint(dn + RAW_BLACK), 0, white)
            atomic_write(path, lambda p, m=mosaic, ex=_exif_entries(time, offset, label):
                         write_dng(p, m, written, neutral, exif=ex, orientation=orientation))
        else:
            lin = np.clip(signal * e_true, 0.0, None) * sensor.max_code
            lin = lin + rng.normal(size=lin.shape) * np.sqrt(read_noise_DN ** 2
                                                             + shot_gain * lin)
            codes = np.rint(sensor.respond(np.clip(camera_tone(
                lin / sensor.max_code, photo.tone_curve), 0.0, 1.0)) * sensor.max_code)
            img = Image.fromarray(np.ascontiguousarray(undo_orientation(
                np.clip(codes, 0, 255).astype(np.uint8), orientation)))
            kw = ({"quality": photo.quality, "subsampling": photo.subsampling} if fmt == "jpeg"
                  else {})
            atomic_write(path, lambda p, img=img, ex=_exif(time, offset, label, orientation), kw=kw:
                         img.save(p, format=fmt.upper(), exif=ex.tobytes(), **kw))
        paths.append(path)
        record.append({"file": path.name, "time": f["time"], "exposure_time_s": t,
                       "exif_exposure_time_s": label,
                       "exposure_sr_m2_W": e_true, "nominal_exposure_sr_m2_W": e})
    meta = {"sequence": str(Path(sequence).resolve()), "seed": seed, "response": photo.response,
            "gamma": photo.gamma, "read_noise_DN": read_noise_DN, "shot_gain": shot_gain,
            "cos4": photo.cos4, "format": fmt, "quality": photo.quality, "offset_in_exif": offset,
            **({"subsampling": photo.subsampling} if fmt == "jpeg" else {}),
            "orientation": orientation,
            "shutter_error": photo.shutter_error, "nominal_exif": photo.nominal_exif,
            "tone_curve": photo.tone_curve,
            "motion": {str(i): list(m) for i, m in (photo.motion or {}).items()},
            "distortion": list(photo.distortion),
            **({"raw": {"bits": RAW_BITS, "black_DN": RAW_BLACK, "white_DN": white,
                        "cfa": "RGGB", "camera_from_linear_srgb": to_camera.tolist(),
                        "matrix_error": float(photo.matrix_error),
                        "developed_from_true_linear_srgb": mix.tolist(),
                        "color_matrix_1": written.tolist(), "as_shot_neutral": neutral.tolist(),
                        "source": "XYZ -> camera of the Canon EOS 5D Mark II (Adobe DNG "
                                  "Converter, via dcraw's adobe_coeff)"}} if raw else {}),
            "exposure_at_1_15_s": base, "f_number": SIM_F_NUMBER, "iso": SIM_ISO,
            "frames": record, "units": "exposure sr m^2 W^-1 (signal = exposure x radiance)"}
    write_json(out / "photos.json", meta)
    return paths
