"""A sky's shape moved: the skies a fit of the shape mixes (``fit --sky-shape``), and the sky
that fit saw.

A CIE sky moves its gradation and indicatrix (:mod:`~skyfit_mi.physics.cie_general`), a Perez
sky its clearness and brightness (:mod:`~skyfit_mi.physics.perez`), a turbid sky its turbidity
(:mod:`~skyfit_mi.physics.turbid_sky`); each model gives its moves (``shape_moves``) and makes
its own :class:`~skyfit_mi.physics.sky.Sky`, so the choice among them sits here, above all of
them.
"""

from dataclasses import replace

import numpy as np

from . import cie_general, perez, turbid_sky
from .colour import SRGB_LUMINANCE
from ..conventions import direction_from_angles
from ..errors import SkyfitError
from .latlong import MAX_ROWS, resample
from .sky import Sky, hemisphere_integral, perez_pattern

#: Sub-samples per cell side of the environment map of a fitted sky shape (:func:`shaped`).
SHAPED_SUPERSAMPLE = 2


def shape_variants(sky, toward=None):
    """The skies a fit of the sky's shape mixes with ``sky`` (``fit --sky-shape``): one
    index of its pattern moved at a time, lit as that sky's light other than the sun
    (:func:`_pattern_as_sky_part`).  For a CIE sky (the thesis's clear sky, standard type
    12, or a CIE S 011 general sky, :mod:`~skyfit_mi.physics.cie_general`) its gradation,
    then its indicatrix, moved one CIE group on
    (:func:`~skyfit_mi.physics.cie_general.shape_moves`); for a Perez sky
    (:mod:`~skyfit_mi.physics.perez`) its clearness moved one bin and its brightness Delta
    one step (:func:`~skyfit_mi.physics.perez.shape_moves`); for a turbid sky
    (:mod:`~skyfit_mi.physics.turbid_sky`) its turbidity moved one step.  A mix
    (1 - sum(a)) sky + sum a_j V_j moves the shape continuously between them: a_j = 1 is
    variant j's index exactly.

    Parameters
    ----------
    toward : dict, optional
        {index name (``of``): +1 or -1}: the way to move that index, +1 toward the more
        turbid CIE group, the clearer Perez bin, the brighter Delta, the higher turbidity;
        an index not named moves +1 where it can, else -1.

    Returns
    -------
    list of (label, Sky)
        The labels as 'gradation group 5 -> 6'; the skies' info ``kind`` 'shape variant',
        ``of``, ``index``, ``from``, ``to`` and the move's coefficients.  Empty for other
        skies, or a sky black above the horizon.

    Raises
    ------
    SkyfitError
        Where ``toward`` names a way this sky's index cannot move.
    """
    kind = sky.info.get("kind")
    if kind == "clear":
        moves = cie_general.shape_moves(cie_general.standard_parameters(12))
    elif kind == "cie_general":
        moves = cie_general.shape_moves(sky.info["parameters_abcde"])
    elif kind == "perez":
        moves = perez.shape_moves(sky.info)
    elif kind == "turbid":
        moves = turbid_sky.shape_moves(sky.info)
    else:
        return []
    if float(sky.sky_horizontal_irradiance() @ SRGB_LUMINANCE) <= 0:
        return []
    toward = toward or {}
    out = []
    for m in moves:
        sign = toward.get(m["of"], 1 if m["moves"][1] is not None else -1)
        move = m["moves"][sign]
        if move is None:
            where = (f"the {m['of']} of the spec's {kind} sky at sun zenith "
                     f"{np.degrees(np.arccos(sky.sun_direction[2])):.1f} degrees "
                     f"({m['index']} {m['from']:.4g})")
            raise SkyfitError(
                f"{where} cannot move {'up' if sign > 0 else 'down'} as the other frames' "
                "must; fit these frames apart (--frames) or leave out --sky-shape."
                if m["of"] in toward else
                f"{where} has no neighbour either way that the model allows; leave out "
                "--sky-shape.")
        out.append((f"{m['of']} {m['index']} {m['from']:.4g} -> {move['to']:.4g}",
                    _pattern_as_sky_part(sky, move["coefficients"], {
                        "kind": "shape variant", "of": m["of"], "index": m["index"],
                        "from": m["from"], **move})))
    return out


def _pattern_as_sky_part(sky, coefficients, info=None):
    """The Perez-form pattern of ``coefficients`` (a..e, :func:`~.sky.perez_pattern`) lit as
    ``sky``'s light other than the sun: the same horizontal irradiance channel by channel
    (:meth:`~.sky.Sky.sky_horizontal_irradiance`, so the same luminance-weighted irradiance
    and colour), the sky-lit ground (:meth:`~.sky.Sky.split`), the same horizon; no sun, and
    ``info``."""
    c = np.asarray(coefficients, dtype=float)
    total = float(hemisphere_integral(lambda d: perez_pattern(d, sky.sun_direction, c)))
    if not total > 0:
        raise SkyfitError(f"the Perez-form pattern {c.tolist()} is black above the "
                          "horizon; it cannot carry this sky's light.")
    return Sky(sky.sun_direction, perez=sky.sky_horizontal_irradiance() / total,
               perez_coefficients=c, ground=sky.split()[1].ground,
               horizon_blend=sky.horizon_blend, sun_solid_angle=sky.sun_solid_angle,
               info=dict(info or {}))


def shaped(sky, k, mix, variants, departure=(), rows=MAX_ROWS, supersample=SHAPED_SUPERSAMPLE):
    """A copy of ``sky`` lit as a fit of the sky's level and shape saw it (``fit
    --sky-shape``): the sun's light (:meth:`~.sky.Sky.split`) as ``sky``'s, the rest ``k``
    times (1 - sum(mix)) ``sky``'s own plus ``mix[j]`` times ``variants[j]``
    (:func:`shape_variants`' skies); for a
    turbid sky both levels moved too, as its fitted turbidity sets them
    (:func:`~skyfit_mi.physics.turbid_sky.level_factors`).  The variants' patterns have
    Perez coefficients of their own, which one Sky cannot hold beside this one's, so the
    rest becomes an environment map: a lat-long table of ``rows`` rows
    (:mod:`~skyfit_mi.physics.latlong`), each cell the mean over ``supersample`` x
    ``supersample`` directions, the ground below the horizon included
    (its ``ground`` term 0): an ``envmap`` record's sky with the sun's direct normal
    irradiance and no albedo of its own (:func:`~skyfit_mi.physics.envmap.envmap_sky`).
    ``departure``: the weights of the sky's fitted departure from its model (``fit
    --sky-departure``), ``sky``'s own sky above the horizon times their field added as the
    fit mixed it (:func:`~.sky_departure.departure_parts`): its patterns' light times
    sum_j a_j B_j.
    Radiances linear sRGB [W m^-2 sr^-1]; ``k``, ``mix`` and ``departure`` unitless."""
    mix = np.asarray(mix, dtype=float)
    sun, rest = sky.split()
    b = 1.0
    if sky.info.get("kind") == "turbid" and len(mix):     # its turbidity sets the levels
        (a,), (b,) = turbid_sky.level_factors([sky.info], [variants[0].info], mix[0])
        sun = replace(sun, sun_radiance=sun.sun_radiance * a, ground=sun.ground * a)
    parts = [(1.0, sun), (k * b * (1.0 - mix.sum()), rest)] + [
        (k * b * m, v) for m, v in zip(mix, variants)]
    weights = np.asarray(departure, dtype=float)
    if weights.size:                        # the rest's patterns times the field's a_j B_j
        parts += [(k * b, replace(rest, departure=weights)), (-k * b, rest)]

    def lookup(theta, phi):
        d = direction_from_angles(theta, phi)
        return sum(w * p.sky_radiance(d) for w, p in parts if w != 0.0)
    table = np.clip(resample(lookup, int(rows), supersample=supersample), 0.0, None)
    return replace(sun, envmap=table, ground=np.zeros(3),
                   info={**sky.info, "shape_mix": mix.tolist(), "sky_level": float(k),
                         **({"departure": weights.tolist()} if weights.size else {})})
