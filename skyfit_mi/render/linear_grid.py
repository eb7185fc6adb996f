"""The global method's closed-form grid, on the device: Ward's model linear in its reflectances.

Given sigma_alpha, Ward's model is linear in rho_d and rho_s (thesis eq. 3.19), so on the basis
L = rho_d D + rho_s G(sigma) a model's remaining linear parameter (R, or C per channel) has a
closed-form bounded least-squares value at every (sigma_alpha, rho_s) grid point.
:func:`linear_form` is that algebra (for NumPy or Dr.Jit arrays); :func:`grid_on_device` scores
every pixel's grid in one double-precision Dr.Jit kernel on the current variant's device.
"""

import numpy as np

from ..physics.ward import METAL_THRESHOLD


def linear_form(metal, r2, a, b, c, yd, yg, yy):
    """(zz, yh, hh) of a linear parameter L at rho_s = r2 from the weighted sums over frames
    a = <D,D>, b = <D,G>, c = <G,G>, yd = <y,D>, yg = <y,G>, yy = <y,y> (radiance^2, weights
    1/sigma^2), so that chi^2 = zz - 2 L yh + L^2 hh (dimensionless): a metal's (and the
    achromatic model's R, thesis 7.1) L = C ((1 - r2) D + r2 G), a plastic's
    L = C (1 - r2) D + r2 G (its lobe does not scale with C; thesis eq. 3.19, 7.1)."""
    r1 = 1 - r2
    if metal:
        return yy, r1 * yd + r2 * yg, r1 * r1 * a + r2 * (2 * r1 * b + r2 * c)
    # residual (y - r2 G) - C r1 D
    return yy - r2 * (2 * yg - r2 * c), r1 * (yd - r2 * b), r1 * r1 * a


def grid_on_device(sums, rho, achromatic):
    """Every pixel's chi^2 and bounded linear parameters L in [0, 1] at every (sigma, rho_s)
    grid point, in one double-precision Dr.Jit kernel.

    ``sums`` = (a, b, c, yd, yg, yy) of :func:`linear_form`: a, yd, yy (P, groups), b, c, yg
    (K, P, groups) (groups: 1 for R, 3 for C); ``rho`` (R,) the rho_s grid; ``achromatic``: the
    metal form everywhere.  Returns chi2 (K, R, P) and L (K, R, P, groups), NumPy float64.
    """
    import drjit as dr
    import mitsuba as mi

    F = mi.Float64
    a, b, c, yd, yg, yy = sums
    K, P, groups = b.shape
    R = len(rho)
    i = dr.arange(mi.UInt32, K * R * P)
    p = i % P
    kp = (i // (R * P)) * P + p
    r2 = dr.gather(F, F(np.asarray(rho, dtype=float)), (i // P) % R)
    metal = (r2 >= METAL_THRESHOLD) | achromatic

    def at(v, index, g):
        return dr.gather(F, F(np.ascontiguousarray(v[..., g], dtype=float).ravel()), index)
    chi2, out = F(0.0), []
    for g in range(groups):
        args = (r2, at(a, p, g), at(b, kp, g), at(c, kp, g), at(yd, p, g), at(yg, kp, g),
                at(yy, p, g))
        zz, yh, hh = (dr.select(metal, m, q)
                      for m, q in zip(linear_form(True, *args), linear_form(False, *args)))
        L = dr.clip(yh / dr.maximum(hh, 1e-300), 0.0, 1.0)
        chi2 = chi2 + zz - L * (2 * yh - L * hh)
        out.append(L)
    dr.eval(chi2, *out)
    return (np.array(chi2, dtype=float).reshape(K, R, P),
            np.stack([np.array(L, dtype=float) for L in out], axis=-1).reshape(K, R, P, groups))
