"""The CIE standard general sky: 15 relative sky luminance distributions (CIE S 011/E:2003).

ISO 15469:2004 / CIE S 011/E:2003 gives the luminance of a sky element relative to the zenith's

    L / L_z = f(zeta) phi(theta_p) / (f(theta_s) phi(0)),

with the gradation phi(theta_p) = 1 + a exp(b / cos theta_p) (phi(pi/2) = 1) of the element's
zenith angle, and the indicatrix f(zeta) = 1 + c (exp(d zeta) - exp(d pi/2)) + e cos^2 zeta of
its angle to the sun.  Six gradations (a, b) and six indicatrices (c, d, e) make the 15 standard
types (Table 1, :data:`STANDARD_PARAMETERS`), from 1 (overcast, steep gradation) to 15
(white-blue turbid, broad corona).  Types 11-15 are cloudless, clearest first (Darula and Kittler
2002); type 12 is the thesis's clear sky (eqs. 4.12-4.14; its 0.91 = 1 - 10 exp(-3 pi/2) to 2e-4).

Continuous indices for fitting a cloudless sky (this project's, not the standard's):
:func:`clear_parameters` (t in [11, 15], linear between clear types) and
:func:`group_parameters` (gradation and indicatrix indices, linear between groups).

Names follow ``docs/CONVENTIONS.md``: ``theta_p`` is the standard's Z, ``zeta`` its chi,
``theta_s`` its Z_s; angles in radians.

References
----------
ISO 15469:2004(E) / CIE S 011/E:2003, Spatial distribution of daylight - CIE standard general
sky, CIE Central Bureau, Vienna, 2003 (Table 1: the parameters a-e of the 15 types).

S. Darula, R. Kittler, "CIE general sky standard defining luminance distributions", Proc.
eSim 2002, Montreal, 2002.

R. Kittler, R. Perez, S. Darula, "A set of standard skies characterizing daylight conditions
for computer and energy conscious design", final report, US SK 92 052, Bratislava, 1998.
"""

import numpy as np

from ..conventions import unit_directions
from ..errors import SkyfitError, check_range

#: Gradation groups I-VI (row i is group i + 1): a, b of phi [unitless] (Table 1).
GRADATION_GROUPS = np.array([
    [4.0, -0.70],      # I    overcast, steep gradation
    [1.1, -0.80],      # II   overcast, moderate gradation
    [0.0, -1.00],      # III  no gradation (uniform toward the zenith)
    [-1.0, -0.55],     # IV   clear-sky gradation, steep
    [-1.0, -0.32],     # V    CIE clear sky (the thesis's gamma, eq. 4.12)
    [-1.0, -0.15],     # VI   turbid, strongest brightening toward the horizon
])
#: Indicatrix groups 1-6 (row i is group i + 1): c, d [rad^-1], e of f (Table 1).
INDICATRIX_GROUPS = np.array([
    [0.0, -1.0, 0.00],     # 1  no brightening toward the sun
    [2.0, -1.5, 0.15],     # 2  slight brightening
    [5.0, -2.5, 0.30],     # 3  brighter circumsolar region
    [10.0, -3.0, 0.45],    # 4  distinct solar corona (the thesis's f, eq. 4.13)
    [16.0, -3.0, 0.30],    # 5  polluted atmosphere
    [24.0, -2.8, 0.15],    # 6  turbid, broad solar corona
])
#: (gradation group, indicatrix group) of standard types 1-15 (Table 1; entry i is type i + 1).
STANDARD_TYPES = ((1, 1), (1, 2), (2, 1), (2, 2), (3, 1), (3, 2), (3, 3), (3, 4),
                  (4, 2), (4, 3), (4, 4), (5, 4), (5, 5), (6, 5), (6, 6))
#: a, b, c, d, e of the standard sky types 1-15 (row i is type i + 1).
STANDARD_PARAMETERS = np.array([np.concatenate([GRADATION_GROUPS[g - 1],
                                                INDICATRIX_GROUPS[i - 1]])
                                for g, i in STANDARD_TYPES])

#: The cloudless standard types, clearest first (Darula and Kittler 2002).
CLEAR_TYPES = (11, 12, 13, 14, 15)
#: The gradation and indicatrix groups of the cloudless types (IV-VI and 4-6).
CLEAR_GROUPS = (4, 6)


def _between(table, x, name, lo, hi):
    """Rows of ``table`` at 1-based continuous positions ``x`` in [lo, hi], linear between
    consecutive rows; shape (..., columns)."""
    x = np.asarray(check_range(name, x, lo, hi), dtype=float)
    below = np.minimum(np.floor(x), hi - 1).astype(int)
    w = (x - below)[..., None]
    return (1.0 - w) * table[below - 1] + w * table[below]


def standard_parameters(sky_type):
    """a, b, c [unitless], d [rad^-1], e [unitless] (5,) of standard sky type 1-15 (Table 1);
    SkyfitError unless ``sky_type`` is an integer in 1-15."""
    if isinstance(sky_type, bool) or not float(sky_type).is_integer() or not 1 <= sky_type <= 15:
        raise SkyfitError(f"CIE standard sky type {sky_type!r} does not exist; give an integer "
                          "from 1 (overcast) to 15 (turbid cloudless).")
    return STANDARD_PARAMETERS[int(sky_type) - 1].copy()


def clear_parameters(t):
    """a, b, c, d, e (..., 5) along the clear types: type t's at integer t in [11, 15], linear
    between (this project's continuation, not the standard's)."""
    return _between(STANDARD_PARAMETERS, t, "clear-sky type index t", CLEAR_TYPES[0],
                    CLEAR_TYPES[-1])


def group_parameters(gradation_group, indicatrix_group):
    """a, b, c, d, e (..., 5) of continuous gradation (1-6 for I-VI) and indicatrix (1-6)
    indices, broadcast together: any pair of the standard's groups, linear between (this
    project's continuation).  Over the clear groups (IV-VI, 4-6) both grow with turbidity.
    """
    g, i = np.broadcast_arrays(np.asarray(gradation_group, dtype=float),
                               np.asarray(indicatrix_group, dtype=float))
    n = len(GRADATION_GROUPS)
    return np.concatenate([_between(GRADATION_GROUPS, g, "gradation group", 1, n),
                           _between(INDICATRIX_GROUPS, i, "indicatrix group", 1, n)], axis=-1)


def gradation(cos_theta_p, a, b):
    """Gradation phi(theta_p) = 1 + a exp(b / cos theta_p), CIE S 011/E:2003 [unitless].

    ``a``, ``b`` (b < 0) broadcast against ``cos_theta_p``.  The horizon limit phi = 1 is also
    used below it, where the standard does not define the sky; NaN stays NaN.
    """
    c = np.asarray(cos_theta_p, dtype=float)
    up = c > 0.0
    return np.where(up, 1.0 + a * np.exp(b / np.where(up, c, 1.0)),
                    np.where(c <= 0.0, 1.0, np.nan))


def indicatrix(zeta, c, d, e):
    """Scattering indicatrix f(zeta) = 1 + c (exp(d zeta) - exp(d pi/2)) + e cos^2 zeta,
    CIE S 011/E:2003 [unitless]; ``zeta`` [rad] in [0, pi], ``d`` [rad^-1], f(pi/2) = 1."""
    zeta = np.asarray(zeta, dtype=float)
    return 1.0 + c * (np.exp(d * zeta) - np.exp(d * np.pi / 2)) + e * np.cos(zeta) ** 2


def relative_luminance(cos_theta_p, zeta, sun_zenith, params):
    """Sky luminance relative to the zenith's, L / L_z [unitless], CIE S 011/E:2003.

    .. math:: \\frac{L}{L_z} = \\frac{f(\\zeta)\\, \\varphi(\\theta_p)}
                                    {f(\\theta_s)\\, \\varphi(0)}

    Parameters
    ----------
    cos_theta_p, zeta : array_like
        Cosine of the element's zenith angle, and its angle to the sun [rad] in [0, pi].
    sun_zenith : array_like
        Solar zenith theta_s [rad], in [0, pi/2].
    params : array_like, shape (..., 5)
        a, b, c, d, e, broadcast against the angles.
    """
    a, b, c, d, e = np.moveaxis(np.asarray(params, dtype=float), -1, 0)
    return (indicatrix(zeta, c, d, e) * gradation(cos_theta_p, a, b)
            / (indicatrix(sun_zenith, c, d, e) * gradation(1.0, a, b)))


def pattern(directions, sun, params):
    """L / L_z [unitless] toward world ``directions`` (n, 3) for the unit vector ``sun`` (3,);
    ``params`` (5,) give (n,), (k, 5) give (k, n)."""
    d = unit_directions(directions)
    zeta = np.arccos(np.clip(d @ sun, -1.0, 1.0))
    theta_s = np.arccos(np.clip(sun[2], -1.0, 1.0))
    p = np.asarray(params, dtype=float)
    return relative_luminance(d[..., 2], zeta, theta_s, p[..., None, :] if p.ndim > 1 else p)


def perez_form(params):
    """The general sky's pattern in the Perez (1993, eq. 1) form the ``cie_sky`` emitter
    renders: f(zeta) phi(theta_p) = k (1 + a e^{b / cos theta_p})(1 + c' e^{d zeta} +
    e' cos^2 zeta).

    As f(zeta) = k + c e^{d zeta} + e cos^2 zeta with k = 1 - c e^{d pi / 2}, c' = c / k and
    e' = e / k; k > 0 for every standard group and blend.  Returns (k, array of a, b, c', d, e')
    for :func:`skyfit_mi.physics.sky.perez_relative_luminance`; SkyfitError unless k > 0, b < 0.
    """
    a, b, c, d, e = np.asarray(params, dtype=float)
    k = 1.0 - c * np.exp(d * np.pi / 2)
    if not k > 0 or not b < 0:
        raise SkyfitError(f"CIE general sky parameters {list(map(float, params))} have no "
                          "positive pattern (need b < 0 and c exp(d pi/2) < 1); use a standard "
                          "type or group indices.")
    return float(k), np.array([a, b, c / k, d, e / k])


def shape_moves(params):
    """The moves of a general sky's shape that a sky-shape fit mixes with it
    (:func:`~skyfit_mi.physics.sky_shape.shape_variants`): its gradation (a, b), then its
    indicatrix (c, d, e), from the nearest group to the next toward the more turbid (+1) or
    the clearer (-1), the rest of ``params`` (5,) kept.

    Returns
    -------
    list of dict
        One per index: ``of`` ('gradation', 'indicatrix'), ``index`` ('group'), ``from``
        (the nearest group, 1-6) and ``moves`` {+1, -1: None beyond groups 1-6, else ``to``,
        ``parameters_abcde`` and ``coefficients`` (:func:`perez_form`)}.
    """
    p0 = np.asarray(params, dtype=float)
    out = []
    for name, table, at in (("gradation", GRADATION_GROUPS, slice(0, 2)),
                            ("indicatrix", INDICATRIX_GROUPS, slice(2, 5))):
        group = int(np.argmin(np.abs(table - p0[at]).sum(axis=1))) + 1
        moves = {}
        for sign in (1, -1):
            to = group + sign
            if not 1 <= to <= len(table):
                moves[sign] = None
                continue
            p = p0.copy()
            p[at] = table[to - 1]
            moves[sign] = {"to": to, "parameters_abcde": p.tolist(),
                           "coefficients": perez_form(p)[1].tolist()}
        out.append({"of": name, "index": "group", "from": group, "moves": moves})
    return out
