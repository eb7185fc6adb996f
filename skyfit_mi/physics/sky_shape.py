"""A sky's shape moved: the skies a sky-shape fit (``fit --sky-shape``) mixes, and the sky it saw.

Each sky model gives its moves (``shape_moves``: CIE gradation and indicatrix, Perez clearness
and brightness, turbidity) and its own :class:`~skyfit_mi.physics.sky.Sky`; the choice among
them sits here, above them all.
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
    """The skies (label, Sky) a sky-shape fit mixes with ``sky``: one index of its pattern moved
    at a time (the model's ``shape_moves``), lit as ``sky``'s light other than the sun.  A mix
    (1 - sum(a)) sky + sum a_j V_j moves the shape continuously; a_j = 1 is variant j's index.
    Labels read 'gradation group 5 -> 6'; info ``kind`` 'shape variant', ``of``, ``index``,
    ``from``, ``to`` and the move's coefficients.  Empty for other skies or a black sky.

    Parameters
    ----------
    toward : dict, optional
        {index name (``of``): +1 or -1}: +1 toward the more turbid CIE group, the clearer Perez
        bin, the brighter Delta, the higher turbidity; an unnamed index moves +1 where it can.
        SkyfitError where the named way is impossible.
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
    """The Perez-form pattern of ``coefficients`` (a..e) lit as ``sky``'s light other than the
    sun: the same horizontal irradiance per channel, the sky-lit ground, the same horizon; no
    sun; ``info``."""
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
    """A copy of ``sky`` lit as a fit of the sky's level and shape saw it: the sun's light as
    ``sky``'s, the rest ``k`` times (1 - sum(mix)) ``sky``'s own plus ``mix[j]`` times
    ``variants[j]``, plus, with ``departure`` weights a_j, the rest's patterns times
    sum_j a_j B_j (:func:`~.sky_departure.departure_parts`).  A turbid sky's levels move with
    its fitted turbidity (:func:`~skyfit_mi.physics.turbid_sky.level_factors`).

    The variants have Perez coefficients of their own, which one Sky cannot hold, so the rest
    becomes a lat-long envmap of ``rows`` rows (``supersample``^2 directions a cell), ground
    included (``ground`` term 0).  Radiances linear sRGB [W m^-2 sr^-1]; ``k``, ``mix`` and
    ``departure`` unitless."""
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
