"""A rendered day as a camera would have photographed it: JPEG/PNG/TIFF frames with EXIF.

For tests of ``skyfit ingest`` and for the shipped example, a sequence folder written by
``render`` becomes image files degraded the way photographs are: an auto-exposure that
changes from frame to frame (shutter time steps recorded in EXIF, as t ISO / N^2), the cos^4
vignetting of a lens (thesis eq. 5.6), Gaussian read noise and shot noise in linear codes, the
sRGB (or a gamma) encoding, clipping at the top code, quantisation, and JPEG compression.  EXIF
carries DateTimeOriginal with or without OffsetTimeOriginal.  Every random choice is drawn
from ``numpy.random.default_rng([seed, frame index])`` and the seed is written into
``photos.json`` beside the images, with each frame's true exposure [sr m^2 W^-1].
"""

import datetime as dt
from fractions import Fraction
from pathlib import Path

import numpy as np

from ..errors import SkyfitError
from ..files import atomic_write, ensure_dir, write_json
from ..physics.camera import SensorModel
from .manifest import load_manifest, read_frame_image, rendered_frames
from .photos import undo_orientation

#: EXIF tags (the Exif sub-IFD 0x8769) written for each frame.
EXIF_IFD, DATETIME_ORIGINAL, OFFSET_TIME_ORIGINAL = 0x8769, 0x9003, 0x9011
EXPOSURE_TIME, F_NUMBER, ISO = 0x829A, 0x829D, 0x8827
ORIENTATION = 0x0112
#: The simulated camera's aperture and ISO (only their ratio to the exposure time matters).
SIM_F_NUMBER, SIM_ISO = 8.0, 100
#: Shutter times of the auto-exposure [s]: third stops from 1/4000 to 1/15 s.
SHUTTER_STOPS = 2.0 ** (-np.arange(36) / 3.0) / 15.0
FORMATS = {"jpeg": ".jpg", "png": ".png", "tiff": ".tif"}


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


def photograph_day(sequence, out_dir, *, exposure=None, target=0.5, response="srgb", gamma=2.2,
                   read_noise_DN=0.8, shot_gain=0.02, cos4=True, fmt="jpeg", quality=95,
                   offset=True, shutter_error=0.0, orientation=1, subsampling=0, seed=0):
    """Write the rendered frames of ``sequence`` as photographs into ``out_dir``.

    Parameters
    ----------
    sequence : a folder written by ``skyfit render`` (its radiance EXRs are the scene)
    exposure : exposure [sr m^2 W^-1] at 1/15 s, f/8, ISO 100; default: the sequence's sensor
        exposure times 2, so that the auto-exposure has room to shorten
    target : the auto-exposure puts the frame's 99th-percentile linear signal at or below this
        share of full scale, stepping the shutter in thirds of a stop
    response, gamma : the encoding (``srgb``, ``gamma``, ``linear``)
    read_noise_DN, shot_gain : noise in linear 8-bit codes: sigma^2 = read^2 + shot_gain x code
    cos4 : apply the cos^4 vignetting of the camera's field of view
    fmt : 'jpeg', 'png' or 'tiff' (8-bit)
    subsampling : a JPEG's chroma: 0 at full resolution (4:4:4, a camera's finest setting), 1
        halved across (4:2:2), 2 halved both ways (4:2:0, most cameras' and Pillow's default),
        which blurs colour across 2x2 pixels and into a region's edge pixels
    offset : write EXIF OffsetTimeOriginal (without it a reader needs the time zone)
    shutter_error : relative standard deviation of each frame's true exposure about the
        nominal one its EXIF records (a real shutter and aperture miss by a few per cent),
        drawn from numpy.random.default_rng([seed, index, 1]); recorded in photos.json
    orientation : EXIF orientation code: the file holds the frame turned back, as a camera
        held on its side stores it, and the tag says how to show it (the frame as rendered)

    Returns the list of written paths, in time order.
    """
    from PIL import Image

    doc, root = load_manifest(sequence)
    if fmt not in FORMATS:
        raise SkyfitError(f"format {fmt!r}; give one of {', '.join(FORMATS)}.")
    cam = doc["camera"]
    h, w = cam["height"], cam["width"]
    base = 2.0 * float(doc["sensor"]["exposure"]) if exposure is None else float(exposure)
    sensor = SensorModel(exposure=1.0, response=response, gamma=gamma, bits=8)
    falloff = sensor.falloff(w, h, cam["fov_deg"]) if cos4 else np.ones((h, w))
    out = Path(out_dir)
    ensure_dir(out)
    paths, record = [], []
    for f in rendered_frames(doc):
        rng = np.random.default_rng([seed, f["index"]])
        radiance = read_frame_image(root, f, "radiance", (h, w, 3)).astype(float)
        signal = radiance * falloff[..., None]
        p99 = float(np.percentile(signal, 99)) * base
        stops = SHUTTER_STOPS[SHUTTER_STOPS * 15.0 * p99 <= target]
        t = float(stops[0] if len(stops) else SHUTTER_STOPS[-1])
        e = base * t * 15.0                                   # exposure at this shutter time
        miss = float(np.random.default_rng([seed, f["index"], 1]).normal()) * shutter_error
        e_true = e * (1.0 + miss)                             # what the shutter really gave
        lin = np.clip(signal * e_true, 0.0, None) * sensor.max_code
        lin = lin + rng.normal(size=lin.shape) * np.sqrt(read_noise_DN ** 2 + shot_gain * lin)
        codes = np.rint(sensor.respond(lin / sensor.max_code) * sensor.max_code)
        img = Image.fromarray(np.ascontiguousarray(undo_orientation(
            np.clip(codes, 0, 255).astype(np.uint8), orientation)))
        time = dt.datetime.fromisoformat(f["time"])
        path = out / f"IMG_{f['index']:04d}{FORMATS[fmt]}"
        kw = {"quality": quality, "subsampling": subsampling} if fmt == "jpeg" else {}
        atomic_write(path, lambda p, img=img, ex=_exif(time, offset, t, orientation), kw=kw:
                     img.save(p, format=fmt.upper(), exif=ex.tobytes(), **kw))
        paths.append(path)
        record.append({"file": path.name, "time": f["time"], "exposure_time_s": t,
                       "exposure_sr_m2_W": e_true, "nominal_exposure_sr_m2_W": e})
    meta = {"sequence": str(Path(sequence).resolve()), "seed": seed, "response": response,
            "gamma": gamma, "read_noise_DN": read_noise_DN, "shot_gain": shot_gain,
            "cos4": cos4, "format": fmt, "quality": quality, "offset_in_exif": offset,
            **({"subsampling": subsampling} if fmt == "jpeg" else {}),
            "orientation": orientation,
            "shutter_error": shutter_error,
            "exposure_at_1_15_s": base, "f_number": SIM_F_NUMBER, "iso": SIM_ISO,
            "frames": record, "units": "exposure sr m^2 W^-1 (signal = exposure x radiance)"}
    write_json(out / "photos.json", meta)
    return paths
