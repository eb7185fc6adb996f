"""The sky's departure from its model: a smooth field over the sky that no model family holds.

Real clear skies depart from their best CIE fit in smooth patterns about the sun and the horizon
(``docs/BENCHMARKS.md``, "Sky models against a measured clear sky"); a fit taking the spec's sky
as exact puts that into the materials.  Here it is a multiplicative field over the sky,

    L_sky(d) = L_model(d) (1 + sum_j a_j B_j(d)),

on a low-order basis (:data:`BASIS`) of the zenith angle theta and the angle gamma from the sun
(thesis eq. 4.14): with u = 2 cos(theta) - 1 and y = cos(gamma), B = (P1(u), P2(u), P1(y),
P2(y), u y), P_n the Legendre polynomials.  Every |B_j| <= 1 above the horizon, so each sky lit
by 1 + B_j is a light (:func:`departure_parts`), and the a_j are weights of traced parts, as the
shape variants' mix.  The ground is not moved.

The weights' prior N(0, diag :data:`PRIOR_SD` ^2) is measured against the thesis's CIE clear
sky (:func:`scan_departure`; ``scripts/sky_departure_prior.py``) on the Kider et al. 2014 scans
of a clear day (``skyfit_testkit.sky_measurement``) and on published models fitted to many
measured skies: Preetham et al.'s clear skies of turbidity 2-7 and the CIE general skies from
partly cloudy to turbid cloudless (types 7-15).  A sky further from its model than those shows
as a weight beyond it (:func:`conflict`).
"""

from dataclasses import replace

import numpy as np

from ..conventions import direction_from_angles, unit_directions

#: The field's basis functions by name (:func:`basis`).
BASIS = ("zenith P1", "zenith P2", "sun P1", "sun P2", "zenith x sun")
#: Prior sd of each weight a_j [unitless]: the sds expectation-maximisation finds over the
#: scans and the two kinds of published model, each kind weighing alike, times the least factor
#: (steps of 0.1; 1.4) whose 95% region holds at least 90% of each kind
#: (``scripts/sky_departure_prior.py``).
PRIOR_SD = np.array([0.60, 0.15, 0.20, 0.33, 0.20])


def basis(directions, sun):
    """The basis B (..., J) [unitless, |B| <= 1 above the horizon] toward world ``directions``
    (..., 3) for the unit ``sun`` (3,): :data:`BASIS` of u = 2 cos(theta) - 1 and
    y = cos(gamma)."""
    d = unit_directions(directions)
    u = np.clip(2.0 * d[..., 2] - 1.0, -1.0, 1.0)
    y = np.clip(d @ (np.asarray(sun, dtype=float) / np.linalg.norm(sun)), -1.0, 1.0)
    return np.stack([u, 1.5 * u * u - 0.5, y, 1.5 * y * y - 0.5, u * y], axis=-1)


def field_factor(directions, sun, weights):
    """The multiplicative field 1 + sum_j a_j B_j (...,) at ``weights`` a (J,) [unitless]."""
    return 1.0 + basis(directions, sun) @ np.asarray(weights, dtype=float)


def least_field(weights, suns, steps=(46, 72)):
    """The least field 1 + sum_j a_j B_j [unitless] over directions above the horizon for each
    unit sun of ``suns`` (n, 3) at ``weights`` a (J,), on a grid of ``steps`` (zenith angles
    0-90 degrees, azimuths): (n,).  Below zero the field makes the sky's radiance negative
    there, which no sky is."""
    theta = np.radians(np.linspace(0.0, 90.0, steps[0]))
    phi = np.radians(np.linspace(0.0, 360.0, steps[1], endpoint=False))
    d = direction_from_angles(*np.meshgrid(theta, phi, indexing="ij"))
    return np.array([field_factor(d, sun, weights).min() for sun in np.atleast_2d(suns)])


def departure_parts(sky):
    """The lights carrying the field's basis for ``sky``'s light other than the sun
    (:meth:`~.sky.Sky.split`): for each B_j that rest with its patterns times 1 + B_j
    (``departure`` = e_j), ground and map unchanged.  A mix (1 - sum a) rest + sum a_j part_j
    is the rest's patterns times the field at a.  Returns [(name from :data:`BASIS`, Sky)],
    info ``kind`` 'departure'.
    """
    _, rest = sky.split()
    return [(name, replace(rest, departure=np.eye(len(BASIS))[j],
                           info={"kind": "departure", "basis": name}))
            for j, name in enumerate(BASIS)]


def scan_departure(directions, measured, model, sun):
    """Weights a (J,) that best fit ``measured`` luminance (n,) as k ``model`` (n,)
    (1 + sum_j a_j B_j), k free, by linear least squares in measured / model; and the rms
    relative residual before (scale only) and after."""
    r = np.asarray(measured, dtype=float) / np.asarray(model, dtype=float)
    X = np.column_stack([np.ones(len(r)), basis(directions, sun)])
    b, *_ = np.linalg.lstsq(X, r, rcond=None)
    before = np.sqrt(np.mean((r / np.mean(r) - 1.0) ** 2))
    after = np.sqrt(np.mean(((X @ b) / r - 1.0) ** 2))
    return b[1:] / b[0], float(before), float(after)


def conflict(weights, sd=PRIOR_SD):
    """The fitted field's distance from its prior: sum_j (a_j / sd_j)^2, chi-square with J
    degrees of freedom under the prior [unitless]."""
    return float(np.sum((np.asarray(weights, dtype=float) / sd) ** 2))
