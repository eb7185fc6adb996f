"""What the sequence's geometry lets the data say about the specular lobe.

Ward's lobe falls as exp(-tan^2 delta / sigma_alpha^2) with delta the angle between the surface
normal and the half vector of the light and view directions (thesis eq. 3.19).  The sun is the
only light bright enough to show a narrow lobe, so the smallest delta the sun reaches over the
day (the closest highlight) bounds the roughness the sun can reveal: a lobe narrow enough to be
dark at that angle leaves no trace of the sun, and its roughness rests on the sky alone.
"""

import numpy as np

#: A lobe leaves "no trace" at the closest highlight when its value there is below this share
#: of a white Lambertian surface's 1 / pi [unitless].
TRACE = 0.01
#: A frame's sun highlight lies beyond what a fit measured where the lobe there exceeds its
#: value at the fit's closest highlight by more than this factor [unitless].
LOBE_BEYOND = 2.0
#: ... and only where it lies this much nearer at least [degrees]: the closest half-angle is
#: read from the light cache's sample positions, which differ between traces.
NEARER_DEG = 1.0
#: A frame's sun and view lie beyond the angles a fit measured where their (theta_i, theta_o,
#: phi) lies this far from every frame's of the fit [degrees]: on measured materials relit
#: from one camera into others, values beyond it missed by twice as much (median 1.6% against
#: 0.8%, 95th percentile 12.7% against 5.3%: docs/BENCHMARKS.md, "Bands in a new view").
ANGLES_BEYOND_DEG = 30.0


def highlight_geometry(sun_cos):
    """Summary of the sun's light over a region and day.

    ``sun_cos`` (P, T, S, 3): cos(theta_h), cos(theta_d) and cos(theta_i) per pixel, frame
    and position (the half vector's angle from the normal and from the sun, the sun's from the
    normal), NaN where the frame's sun gives no light
    (:class:`~skyfit_mi.render.light_cache.LightCache`).  Returns a JSON-ready dict: frames,
    frames_with_sun, closest_highlight_half_angle_deg (None without sun), its value per frame,
    and per frame, as medians over the region's lit positions [degrees] (None without sun), the
    sun's (theta_h, theta_d), the two angles an isotropic reflection depends on most, and
    (theta_i, theta_o, phi) (:func:`sun_view_angles`): what light and view the frame's values
    measured.
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
    """The sun's and view's configuration (theta_i, theta_o, phi) [degrees] (Q, 3), from
    cos(theta_h), cos(theta_d), cos(theta_i) (Q, 3) (:func:`highlight_geometry`): the view is
    the sun mirrored about the half vector, so cos theta_o = 2 cos theta_d cos theta_h -
    cos theta_i, and the angle between them is 2 theta_d, whence phi, the angle between their
    azimuths (0 with the sun behind the camera, 180 in the mirror plane ahead), by the
    spherical law of cosines."""
    ch, cd, ci = np.clip(np.asarray(cos, dtype=float), -1, 1).T
    co = np.clip(2 * cd * ch - ci, -1, 1)
    sines = np.sqrt((1 - ci**2) * (1 - co**2))
    cphi = np.where(sines > 1e-9, (2 * cd**2 - 1 - ci * co) / np.maximum(sines, 1e-9), 1.0)
    return np.degrees(np.arccos(np.stack([ci, co, np.clip(cphi, -1, 1)], axis=1)))


def angles_beyond(fit_configs, config):
    """Whether a frame's sun and view ``config`` [(theta_i, theta_o, phi), degrees; None
    without sun] lie more than ANGLES_BEYOND_DEG from every frame's of the fit, ``fit_configs``
    (a list, None per frame without sun), in Euclidean distance over the three angles, each
    also with the sun and view exchanged (reciprocity): light and view the fit's data never
    took together, where a model's lobe is its shape's alone.  False without sun in the
    frame; True where no frame of the fit had sun."""
    if config is None:
        return False
    at = np.array([a for a in fit_configs if a is not None], dtype=float).reshape(-1, 3)
    if not len(at):
        return True
    a = np.asarray(config, dtype=float)
    d = np.minimum(np.linalg.norm(at - a, axis=1), np.linalg.norm(at[:, [1, 0, 2]] - a, axis=1))
    return bool(d.min() > ANGLES_BEYOND_DEG)


def highlight_beyond(fit_half_angle_deg, half_angle_deg, sigma_alpha):
    """Whether a frame's closest sun highlight (its half-angle delta [degrees], None where its
    sun gives no light) lies nearer the mirror direction than the fit's data saw (their closest,
    ``fit_half_angle_deg``, None without sun) by so much that Ward's lobe of roughness
    ``sigma_alpha``, exp(-tan^2 delta / sigma^2) (eq. 3.19), exceeds its value at the fit's
    closest by more than LOBE_BEYOND (and nearer by NEARER_DEG at least): a lobe peak the data
    never showed, the model's alone."""
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
    """The roughness below which the day's sun shows no lobe to the camera
    (:func:`traceless_roughness` of the closest highlight), 0 on a day without sun on the
    surface (its lobe is the sky's alone at any roughness: :func:`geometry_warnings`)."""
    if geometry["frames_with_sun"] == 0:
        return 0.0
    return traceless_roughness(geometry["closest_highlight_half_angle_deg"])


def geometry_warnings(geometry, sigma_alpha, sky_shape_known=True, lowest=None):
    """Warnings from the day's geometry for a fit at ``sigma_alpha`` whose 95% interval
    reaches down to ``lowest`` (None: the fit alone): no sun on the surface at all, or a
    closest highlight too far from the camera's view for the sun to show a lobe this narrow
    (the fit's, or the narrowest its interval allows: where the sun shows no lobe, chi-square
    is flat, and the fit may lie anywhere along it).  Then the lobe is seen in the sky's
    reflection alone, and where the sky's shape
    is a model the fit has not fitted (``sky_shape_known`` False: a sky fitted or held by
    its prior in level only), so is rho_s: its reading depends on the sky's pattern near the
    mirror direction (a disc under a measured sky, its highlight never seen: rho_s 0, 95% up
    to 0.074, truth 0.08)."""
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
                   "a sky shape the fit did not fit, so its interval's lower end is left open "
                   "(a camera nearer the sun's mirror direction would measure it).")]
    if not sky_shape_known:
        out.append("rho_s rests on the sky's reflection alone (the sun's highlight is never "
                   "seen at this roughness), so it depends on the sky's pattern near the mirror "
                   "direction, which the spec's sky only models and the fit did not fit (its "
                   "level only): treat rho_s as that sky model's reading (--sky-shape fits a "
                   "CIE or Perez sky's shape; a camera nearer the sun's mirror direction "
                   "measures rho_s from the sun).")
    return out
