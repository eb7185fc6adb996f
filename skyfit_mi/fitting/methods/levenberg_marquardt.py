"""Levenberg-Marquardt (thesis 6.4.3, eq. 6.12; Press et al., Numerical Recipes ch. 15.5).

The thesis's baseline: solve (alpha + lambda diag alpha) delta = beta with alpha = J^T J (the
curvature matrix) and beta = -J^T r; accept the step if chi^2 falls (lambda /= 10), else raise
lambda (x 10). Steps are clipped to the bounds, and a parameter at a bound that chi-square
presses on is held for the step. A singular alpha at the start (e.g. sigma_alpha at
rho_s = 0) fails, as in the thesis's tables, with its reason; reached by steps, the determined
parameters have converged. Parameters in ``fixed`` keep their start values (:mod:`.profile`).
"""

import numpy as np

#: Condition number above which the curvature matrix counts as singular.
SINGULAR_CONDITION = 1e12
#: A parameter whose Jacobian column is below this share of the largest changes nothing.
NO_EFFECT = 1e-9


def levenberg_marquardt(problem, start, lower, upper, max_iterations=100, lam0=1e-3,
                        tol_chi2=1e-6, fixed=(), **_):
    """Minimise chi^2 from ``start`` over the parameters not in ``fixed``; returns a result dict."""
    theta = np.clip(np.asarray(start, dtype=float), lower, upper)
    free = np.ones(len(theta), dtype=bool)
    free[list(fixed)] = False
    r, J = problem.jacobian(theta)
    chi2 = float(r @ r)
    if not free.any():
        return {"theta": theta, "chi2": chi2, "status": "converged",
                "message": "every parameter held", "trace": [theta.tolist()], "jacobian": J}
    lam = lam0
    trace = [theta.tolist()]
    status, message = "max_iterations", "stopped after the iteration limit"
    small = 0
    for _ in range(max_iterations):
        step = free & ~_held_at_bound(theta, -J.T @ r, lower, upper)
        if not step.any():
            status, message = "converged", "every free parameter at a bound chi-square presses on"
            break
        Jf = J[:, step]
        alpha = Jf.T @ Jf
        beta = -Jf.T @ r
        a = alpha + lam * np.diag(np.diag(alpha))
        if not np.all(np.isfinite(a)) or np.linalg.cond(a) > SINGULAR_CONDITION:
            if len(trace) > 1:
                # steps led here (e.g. rho_s = 0): the determined parameters have converged
                status = "converged"
                message = ("stopped where the curvature matrix became singular (a parameter no "
                           "longer changes chi-square, e.g. sigma_alpha at rho_s = 0)")
                break
            status = "failed"
            message = ("curvature matrix singular (a parameter does not change chi-square here, "
                       "e.g. sigma_alpha when rho_s = 0): the thesis's 'Fail'")
            break
        trial = theta.copy()
        trial[step] += np.linalg.solve(a, beta)
        trial = np.clip(trial, lower, upper)
        r_t = problem.residuals(trial)
        chi2_t = float(r_t @ r_t)
        if chi2_t < chi2:
            improvement = chi2 - chi2_t
            theta, chi2 = trial, chi2_t
            r, J = problem.jacobian(theta)
            lam = max(lam / 10.0, 1e-12)
            trace.append(theta.tolist())
            small = small + 1 if improvement < tol_chi2 * max(chi2, 1.0) else 0
            if small >= 2:
                status, message = "converged", "chi-square stopped decreasing"
                break
        else:
            lam *= 10.0
            if small >= 1:                   # a tiny gain, then no gain: at the minimum
                status, message = "converged", "chi-square stopped decreasing"
                break
            if lam > 1e10:
                status, message = "converged", "no step lowers chi-square (lambda > 1e10)"
                break
    if status == "max_iterations":
        status, message = _at_the_limit(problem, trace, chi2, max_iterations)
    return {"theta": theta, "chi2": chi2, "status": status, "message": message, "trace": trace,
            "jacobian": J}


def _held_at_bound(theta, beta, lower, upper):
    """Parameters at a bound that the descent direction ``beta`` (-J^T r) presses on: held for
    the step, so that clipping them does not shorten every other parameter's step (a projected
    Gauss-Newton step; without it the search crawls along a bound, lambda rising and falling).
    One that changes nothing (beta 0) is not held: its singular curvature stays the thesis's
    'Fail' (:func:`polish` holds sigma_alpha at rho_s = 0)."""
    return ((theta <= lower) & (beta < 0)) | ((theta >= upper) & (beta > 0))


#: Accepted steps over which a search stopped at its limit is judged, and the chi-square fall
#: below which it has converged (far below the 1 that moves a 68% interval's end).
LIMIT_STEPS, LIMIT_CHI2 = 10, 0.01


def _at_the_limit(problem, trace, chi2, max_iterations):
    """(status, message) of a search stopped after ``max_iterations``: converged where its last
    LIMIT_STEPS steps lowered chi-square by under LIMIT_CHI2, else how fast it still fell."""
    if len(trace) > LIMIT_STEPS:
        fall = problem.chi2(np.asarray(trace[-LIMIT_STEPS - 1])) - chi2
        if fall < LIMIT_CHI2:
            return "converged", (f"the iteration limit ({max_iterations}) reached along a flat "
                                 f"valley: chi-square fell by {fall:.2g} over the last "
                                 f"{LIMIT_STEPS} steps")
        return "max_iterations", (f"stopped at the iteration limit ({max_iterations}) with "
                                  f"chi-square still falling ({fall:.3g} over the last "
                                  f"{LIMIT_STEPS} steps): the minimum may lie further on")
    return "max_iterations", f"stopped at the iteration limit ({max_iterations})"


def polish(problem, start, lower, upper, fixed=(), **options):
    """Levenberg-Marquardt for polishing and constrained fits: where the curvature is singular at
    the start because sigma_alpha changes nothing (rho_s = 0), sigma_alpha is held and the rest
    fitted, instead of the thesis's 'Fail'. Any other singular start fails: holding a parameter
    that changes chi-square would narrow its profile interval."""
    res = levenberg_marquardt(problem, start, lower, upper, fixed=fixed, **options)
    last = len(lower) - 1
    if res["status"] == "failed" and last not in fixed:
        norms = np.linalg.norm(res["jacobian"], axis=0)
        if norms[last] <= NO_EFFECT * norms.max():
            held = levenberg_marquardt(problem, start, lower, upper, fixed=(*fixed, last),
                                       **options)
            if held["status"] != "failed":
                return {**held, "message": f"{held['message']}; sigma_alpha held at its start "
                        "(it does not change chi-square there)"}
    return res
