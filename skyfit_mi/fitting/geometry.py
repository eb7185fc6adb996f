"""What the sequence's geometry lets the data say about the specular lobe.

Ward's lobe falls as exp(-tan^2 delta / sigma_alpha^2), delta the angle between the normal and
the half vector (thesis eq. 3.19). Only the sun shows a narrow lobe, so the day's smallest delta
(the closest highlight) bounds the roughness it can reveal: a narrower lobe rests on the sky alone.
"""

import numpy as np

#: A lobe leaves "no trace" at the closest highlight when its value there is below this share
#: of a white Lambertian surface's 1 / pi [unitless].
TRACE = 0.01
#: Factor by which a frame's lobe value may exceed the fit's closest highlight's before the
#: highlight lies beyond what the fit measured [unitless].
LOBE_BEYOND = 2.0
#: ... and only this much nearer at least [degrees] (sample positions differ between traces).
NEARER_DEG = 1.0
#: Distance [degrees] in (theta_i, theta_o, phi) from every fitted frame beyond which a frame's
#: sun and view lie beyond what the fit measured (docs/BENCHMARKS.md, "Bands in a new view").
ANGLES_BEYOND_DEG = 30.0


def highlight_geometry(sun_cos):
    """Summary of the sun's light over a region and day.

    ``sun_cos`` (P, T, S, 3): cos(theta_h), cos(theta_d), cos(theta_i) per pixel, frame and
    position, NaN without sun. Returns a JSON-ready dict: the closest highlight's half-angle
    [degrees] overall and per frame, and per frame the medians of (theta_h, theta_d) and of
    (theta_i, theta_o, phi) (:func:`sun_view_angles`); None without sun.
    """
    c = np.asarray(sun_cos, dtype=float)
    per_frame, angles, configs = [], [], []
    for t in range(c.shape[1]):
        v = c[:, t].reshape(-1, 3)
        v = v[np.isfinite(v).all(axis=1)]
        deg = np.degrees(np.arccos(np.clip(v[:, :2], -1, 1)))
        sunlit = len(deg) > 0
        per_frame.append(float(deg[:, 0].min()) if sunlit else None)
        angles.append([float(x) for x in np.median(deg, axis=0)] if sunlit else None)
        configs.append([float(x) for x in np.median(sun_view_angles(v), axis=0)]
                       if sunlit else None)
    lit = [d for d in per_frame if d is not None]
    return {"frames": int(c.shape[1]), "frames_with_sun": len(lit),
            "closest_highlight_half_angle_deg": min(lit) if lit else None,
            "closest_half_angle_per_frame_deg": per_frame,
            "sun_angles_per_frame_deg": angles,
            "sun_view_angles_per_frame_deg": configs}


def sun_view_angles(cos):
    """(theta_i, theta_o, phi) [degrees] (Q, 3) from cos(theta_h), cos(theta_d), cos(theta_i):
    cos theta_o = 2 cos theta_d cos theta_h - cos theta_i, and sun and view lie 2 theta_d apart,
    whence phi (0: sun behind the camera) by the spherical law of cosines."""
    ch, cd, ci = np.clip(np.asarray(cos, dtype=float), -1, 1).T
    co = np.clip(2 * cd * ch - ci, -1, 1)
    sines = np.sqrt((1 - ci**2) * (1 - co**2))
    cphi = np.where(sines > 1e-9, (2 * cd**2 - 1 - ci * co) / np.maximum(sines, 1e-9), 1.0)
    return np.degrees(np.arccos(np.stack([ci, co, np.clip(cphi, -1, 1)], axis=1)))


def angles_beyond(fit_configs, config):
    """Whether a frame's ``config`` [(theta_i, theta_o, phi), degrees] lies more than
    ANGLES_BEYOND_DEG (also with sun and view exchanged) from every one of ``fit_configs``."""
    if config is None:
        return False
    at = np.array([a for a in fit_configs if a is not None], dtype=float).reshape(-1, 3)
    if not len(at):
        return True
    a = np.asarray(config, dtype=float)
    d = np.minimum(np.linalg.norm(at - a, axis=1), np.linalg.norm(at[:, [1, 0, 2]] - a, axis=1))
    return bool(d.min() > ANGLES_BEYOND_DEG)


def highlight_beyond(fit_half_angle_deg, half_angle_deg, sigma_alpha):
    """Whether a frame's closest highlight (half-angle delta [degrees], None without sun) lies so
    much nearer the mirror than ``fit_half_angle_deg`` that the lobe exp(-tan^2 delta / sigma^2)
    (eq. 3.19) exceeds its value there by over LOBE_BEYOND (and by NEARER_DEG at least)."""
    if half_angle_deg is None:
        return False
    if fit_half_angle_deg is None:
        return True
    if half_angle_deg > fit_half_angle_deg - NEARER_DEG:
        return False
    fit_t, t = np.tan(np.radians([fit_half_angle_deg, half_angle_deg]))
    s = max(float(sigma_alpha), 1e-4)
    return bool((fit_t**2 - t**2) / s**2 > np.log(LOBE_BEYOND))


def traceless_roughness(half_angle_deg):
    """The largest sigma_alpha whose lobe, exp(-tan^2 delta / sigma^2) / (4 sigma^2) relative to
    a white Lambertian 1 / pi (Ward's normalisation at normal incidence, thesis eq. 3.19), stays
    below TRACE at delta = ``half_angle_deg``: narrower lobes show no sun at all.  0 at 0."""
    t = np.tan(np.radians(half_angle_deg))
    if t <= 0:
        return 0.0
    sig = np.geomspace(1e-4, 1.0, 4001)
    rel = np.exp(-(t / sig) ** 2) / (4.0 * sig**2)
    dark = rel < TRACE
    # the lobe's value at delta rises with sigma up to sigma = t, then falls
    rising = sig <= t
    idx = np.nonzero(dark & rising)[0]
    return float(sig[idx[-1]]) if idx.size else 0.0


def sky_only_limit(geometry):
    """The roughness below which the day's sun shows no lobe (0 without sun on the surface)."""
    if geometry["frames_with_sun"] == 0:
        return 0.0
    return traceless_roughness(geometry["closest_highlight_half_angle_deg"])


def geometry_warnings(geometry, sigma_alpha, sky_shape_known=True, lowest=None):
    """Warnings for a fit at ``sigma_alpha`` (95% down to ``lowest``) where the sun shows no lobe
    that narrow, leaving the sky's reflection (and, unfitted, its shape) to decide."""
    if geometry["frames_with_sun"] == 0:
        return ["no frame has the sun on this surface (an overcast sky, or the sun behind it): "
                "rho_s and sigma_alpha rest on the sky's reflection alone and are weakly "
                "determined; a sequence with direct sun is needed to measure the lobe."]
    delta = geometry["closest_highlight_half_angle_deg"]
    limit = sky_only_limit(geometry)
    lowest = sigma_alpha if lowest is None else min(lowest, sigma_alpha)
    if lowest >= limit:
        return []
    seen = (f"sigma_alpha: the sun's highlight never comes closer than {delta:.1f} degrees "
            f"(half-angle) to the camera's view, and lobes narrower than sigma_alpha = "
            f"{limit:.3g} show no sun there: "
            + (f"sigma_alpha = {sigma_alpha:.3g} rests" if sigma_alpha < limit else
               f"sigma_alpha = {sigma_alpha:.3g}, its 95% interval down to {lowest:.3g}, rests "
               "there")
            + " on the sky's reflection alone")
    out = [seen + ("; its interval holds as far as the sky's shape near the mirror direction "
                   "is the spec's (a camera nearer the sun's mirror direction would measure it "
                   "from the sun)." if sky_shape_known else
                   f"; treat it as not determined below {limit:.3g}: that reading rests on "
                   "the sky's shape near the mirror direction, which the fit did not measure, "
                   "so its interval's lower end is left open (a camera nearer the sun's mirror "
                   "direction would measure it).")]
    if not sky_shape_known:
        out.append("rho_s rests on the sky's reflection alone (the sun's highlight is never "
                   "seen at this roughness), so it depends on the sky's pattern near the mirror "
                   "direction, which the spec's sky only models and the fit did not measure "
                   "(its level, and a smooth departure where fitted, do not follow it there): "
                   "treat rho_s as that sky model's reading (--sky-shape fits a CIE, turbid or "
                   "Perez sky's shape; a camera nearer the sun's mirror direction measures rho_s "
                   "from the sun).")
    return out
