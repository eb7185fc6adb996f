"""Gradient descent through the differentiable model with Adam (Kingma and Ba, ICLR 2015).

The gradient of chi-square comes from Dr.Jit's reverse mode (``WardModel.gradient``);
parameters are clipped to their bounds after each step; learning rate in units of each range.
"""

import numpy as np


def adam(problem, start, lower, upper, iterations=300, learning_rate=0.02, beta1=0.9, beta2=0.999,
         eps=1e-8, **_):
    """Minimise chi^2 from ``start`` by Adam; returns a result dict with the path."""
    span = np.asarray(upper) - np.asarray(lower)
    x = np.clip(np.asarray(start, dtype=float), lower, upper)
    m = np.zeros_like(x)
    v = np.zeros_like(x)
    best_x, best_f = x.copy(), np.inf
    trace = []
    model = problem.model
    for k in range(1, iterations + 1):
        L = model.radiance(x)
        r, dr_dm = problem.residual_terms(L)
        r = np.where(problem.mask, r, 0.0)
        f = float(np.sum(r**2))
        if f < best_f:
            best_x, best_f = x.copy(), f
        dloss_dl = np.where(problem.mask, 2.0 * r * dr_dm * problem.slope(L), 0.0)
        g = model.gradient(x, dloss_dl) * span          # in units of the range
        m = beta1 * m + (1 - beta1) * g
        v = beta2 * v + (1 - beta2) * g * g
        step = learning_rate * (m / (1 - beta1**k)) / (np.sqrt(v / (1 - beta2**k)) + eps)
        x = np.clip(x - step * span, lower, upper)
        trace.append(x.tolist())
        problem.evaluations += 2
    return {"theta": best_x, "chi2": best_f, "status": "iterations",
            "message": f"{iterations} Adam steps", "trace": trace}
