"""Import of Radiance ``gensky`` sky descriptions into :class:`~skyfit_mi.physics.sky.Sky`.

``gensky`` prints a small Radiance scene: the sun as a ``light`` on a ``source`` of given angular
diameter, and the sky as a ``brightfunc`` ``skyfunc`` calling ``skybr`` (``skybright.cal``) with
A1 (1 clear, 2 overcast, 3 uniform, 4 intermediate), A2 (zenith brightness), A3 (ground
brightness), A4 (normalisation) and A5-A7 (sun direction).  The import reproduces Radiance's sky
exactly (patterns, horizon blend, sun disc); Radiance's frame and units are the project's.

A ``glow`` modified by ``skyfunc`` (the line a user adds to see the sky) gives the sky its RGB;
otherwise it is grey (1, 1, 1), as the usual ``skyfunc glow sky_mat 0 0 4 1 1 1 0``.
"""

import numpy as np

from ..errors import ParseError
from .sky import Sky
from .sun import SUN_SOLID_ANGLE

#: skybright.cal's A1 -> the Sky pattern it selects.
_SKYBR_TYPES = {1: "clear", 2: "overcast", 3: "uniform", 4: "intermediate"}


def _primitives(text):
    """Parse Radiance scene text into (modifier, type, name, strings, reals) tuples."""
    if not isinstance(text, str):
        raise ParseError(f"gensky text must be a string, got {type(text).__name__}.")
    lines = [ln.split("#", 1)[0] for ln in text.splitlines()]
    toks = " ".join(ln for ln in lines if not ln.lstrip().startswith("!")).split()
    prims, i = [], 0

    def count(what, name):
        nonlocal i
        if i >= len(toks):
            raise ParseError(f"gensky text ends inside primitive {name!r} while reading its "
                             f"{what} count; paste the complete output of gensky.")
        try:
            n = int(toks[i])
        except ValueError:
            raise ParseError(f"expected the {what} count of primitive {name!r}, found "
                             f"{toks[i]!r}; the text is not gensky output.") from None
        i += 1
        if n < 0 or i + n > len(toks):
            raise ParseError(f"primitive {name!r} declares {n} {what} arguments but the text "
                             f"ends first; paste the complete output of gensky.")
        vals = toks[i:i + n]
        i += n
        return vals

    while i < len(toks):
        if i + 3 > len(toks):
            raise ParseError(f"incomplete Radiance primitive at {' '.join(toks[i:])!r}; "
                             "paste the complete output of gensky.")
        mod, typ, name = toks[i:i + 3]
        i += 3
        strs = count("string", name)
        count("integer", name)
        reals = count("real", name)
        try:
            reals = [float(r) for r in reals]
        except ValueError:
            raise ParseError(f"primitive {name!r} has a non-numeric real argument in "
                             f"{reals!r}.") from None
        prims.append((mod, typ, name, strs, reals))
    return prims


def from_gensky(text):
    """Build a :class:`Sky` (``horizon_blend=True``, W m^-2 sr^-1) from the text ``gensky``
    prints (comments and a ``skyfunc glow`` line allowed).  ParseError, saying what is missing,
    without a ``skyfunc`` brightfunc calling ``skybr`` or on malformed numbers."""
    prims = _primitives(text)
    by_name = {p[2]: p for p in prims}
    funcs = [p for p in prims if p[1] == "brightfunc" and "skybr" in p[3]]
    if not funcs:
        raise ParseError("no 'brightfunc' calling skybr (skybright.cal) was found; give the "
                         "text printed by Radiance's gensky, e.g. `gensky 6 21 12 +s`.")
    _, _, func_name, _, a = funcs[0]
    if len(a) < 3:
        raise ParseError(f"skyfunc has {len(a)} real arguments; skybright.cal needs at least 3 "
                         "(type, zenith brightness, ground brightness).")
    kind = _SKYBR_TYPES.get(int(a[0])) if float(a[0]).is_integer() else None
    if kind is None:
        raise ParseError(f"skyfunc sky type A1 = {a[0]:g}; skybright.cal knows 1 (clear), "
                         "2 (overcast), 3 (uniform) and 4 (intermediate).")
    needs_sun = kind in ("clear", "intermediate")
    if needs_sun and len(a) < 7:
        raise ParseError(f"a {kind} skyfunc needs 7 real arguments (type, zenith, ground, "
                         f"normalisation, sun x y z); found {len(a)}.")
    zenith, ground = a[1], a[2]
    norm = a[3] if needs_sun else 1.0
    if norm <= 0:
        raise ParseError(f"skyfunc normalisation A4 = {norm:g} must be positive.")

    colour = np.ones(3)
    for mod, typ, _, _, reals in prims:
        if mod == func_name and typ == "glow":
            if len(reals) < 3:
                raise ParseError("the glow modified by skyfunc needs 4 reals (r g b radius).")
            colour = np.asarray(reals[:3])

    sun_rad, sun_dir, omega = np.zeros(3), None, None
    for mod, typ, name, _, reals in prims:
        if typ == "source" and mod in by_name and by_name[mod][1] == "light":
            light = by_name[mod][4]
            if len(reals) != 4 or len(light) != 3:
                raise ParseError(f"sun source {name!r} needs 4 reals (x y z angle) and its light "
                                 "3 reals (r g b).")
            sun_dir = np.asarray(reals[:3])
            half = np.radians(reals[3]) / 2.0
            omega = 2.0 * np.pi * (1.0 - np.cos(half))
            sun_rad = np.asarray(light)
            break
    if needs_sun:
        sun_dir = np.asarray(a[4:7])            # the sky pattern's sun
    if sun_dir is None:
        sun_dir = np.array([0.0, 0.0, 1.0])     # overcast/uniform: the pattern has no sun
    weights = {kind: colour * zenith / norm}
    info = {"kind": f"radiance-{kind}", "source": "gensky",
            "command": next((ln.strip("# ").strip() for ln in text.splitlines()
                             if ln.lstrip().startswith("#") and "gensky" in ln), None)}
    return Sky(sun_dir, ground=colour * ground, horizon_blend=True, sun_radiance=sun_rad,
               sun_solid_angle=omega if omega is not None else SUN_SOLID_ANGLE, info=info, **weights)
