"""The camera pose's uncertainty in a fit's intervals (a stage of :meth:`~.fit.FitSession.run`,
before :func:`~.intervals.fit_intervals`).

A pose typed or estimated a fraction of a degree off moves every pixel's view and where it
lands, and a narrow lobe's fit with them (a metal of sigma_alpha 0.08 fitted 0.0837 [0.0832,
0.0841] with its camera 0.7 deg off).  The pose's angles (``[camera] pose_sd_deg``, or
``fit --pose-sd-deg``: azimuth, angle from the vertical, roll, each 1 sd) are nuisances
propagated linearised, as the sky's and the calibration's errors are: for each angle j of sd_j
> 0 the light is traced again with the camera turned by sd_j about where its central ray meets
the scene (:func:`~skyfit_mi.render.scene.turn_camera`; the same samples and seed as the fit's
trace, so that their difference is the turn's, not Monte Carlo noise), the residuals at the
fitted parameters move by Delta r_j, and the parameters by the Gauss-Newton step

    Delta theta_j = -(J^T J)^-1 J^T Delta r_j

in the fit's own weighting (J the residuals' Jacobian at the fit).  The pose's covariance
sum_j Delta theta_j Delta theta_j^T; its diagonal's square roots are added in quadrature to
every interval (:func:`~.intervals.fit_intervals`).  Each function takes the region's
:class:`~.fit.FitSession` ``s``.
"""

import time
from dataclasses import dataclass, field

import numpy as np

from . import uncertainty as unc
from .sky_fit import SKY_DOMINATES
from ..render.scene import POSE_ANGLES, turn_camera, view_centre

#: How each angle of the pose is named in records and warnings.
ANGLE_NAMES = {"azimuth": "in azimuth", "angle": "in angle from the vertical",
               "roll": "in roll"}


@dataclass
class PoseShare:
    """What the camera pose's uncertainty adds to one region's parameters' errors.

    sd_deg : the pose's 1-sd {azimuth, angle, roll} [deg]
        (:func:`~skyfit_mi.render.scene.pose_sd`)
    shifts : {angle: (n,) the parameters' shift with the camera turned by its sd} for each
        angle of sd > 0 (empty: nothing propagated)
    sd : (n,) the pose's share of each parameter's standard error, sqrt(sum_j shift_j^2)
        (None: zeros)
    pivot : the point the camera turns about [m] (where its central ray meets the scene)
    seconds : the traces' wall time [s]
    """

    sd_deg: dict
    shifts: dict = field(default_factory=dict)
    sd: np.ndarray = None
    pivot: list = None
    seconds: float = 0.0

    def sd_of(self, n):
        """The pose's standard errors (n,), zeros where nothing was propagated."""
        return np.zeros(n) if self.sd is None else self.sd

    @property
    def covariance(self):
        """The pose's covariance of the parameters, sum_j shift_j shift_j^T (n, n)."""
        return sum(np.outer(d, d) for d in self.shifts.values())


def pose_share(s, fit, J):
    """The :class:`PoseShare` of the fit ``fit`` (:class:`~.fit.FitState`: its problem, theta
    and (J^T J)^-1) with ``J`` (P, T, 3, n) its residuals' derivatives: the parameters' shift
    per angle of the session's ``pose_sd`` above 0, from a trace of the light with the camera
    turned by that angle's sd (:meth:`~.fit.FitSession.radiance_at_pose`).  Nothing is traced
    where every sd is 0, or for an observation table (its points are rays in the world, no
    camera's)."""
    turns = {k: s.pose_sd[k] for k in POSE_ANGLES if s.pose_sd[k] > 0}
    if not turns or s.obs.rays is not None:
        return PoseShare(s.pose_sd)
    t0 = time.perf_counter()
    problem, theta = fit.problem, fit.theta
    to_world = np.asarray(s.doc["camera"]["to_world"], dtype=float)
    pivot = view_centre(s.scene)
    use = problem.mask
    r0, _ = problem.residual_terms(problem.model.radiance(theta), derivative=False)
    shifts = {}
    for k, deg in turns.items():
        L, hit = s.radiance_at_pose(turn_camera(to_world, pivot, k, deg), theta)
        with np.errstate(all="ignore"):
            r, _ = problem.residual_terms(L, derivative=False)
        moved = np.where(use & hit[..., None], r - r0, 0.0)
        shifts[k] = -fit.curvature_inverse @ (J[use].T @ moved[use])
    sd = np.sqrt(sum(d ** 2 for d in shifts.values()))
    return PoseShare(s.pose_sd, shifts, sd, pivot.tolist(), time.perf_counter() - t0)


def pose_record(s, share):
    """The fit JSON's ``pose`` where the pose's uncertainty was propagated, else None."""
    if not share.shifts:
        return None
    names = s.names
    return {"sd_deg": share.sd_deg, "pivot": share.pivot,
            "shift_by_parameter": {p: {k: float(d[i]) for k, d in share.shifts.items()}
                                   for i, p in enumerate(names)},
            "error_sd": dict(zip(names, share.sd.tolist())),
            "covariance": share.covariance.tolist(), "trace_time_s": share.seconds,
            "meaning": "the camera's pose is known to sd_deg (1 sd, each angle independent); "
                       "shift_by_parameter: each parameter's change were the camera turned "
                       "by one sd about the pivot (where its central ray meets the scene), "
                       "linearised from a trace of the light so turned; error_sd: their "
                       "root sum of squares, added in quadrature to every interval"}


def pose_warnings(s, fit):
    """Warnings for the parameters whose pose share at least doubles their interval
    (:data:`~.sky_fit.SKY_DOMINATES`, the sky's rule)."""
    share = fit.pose
    if not share.shifts:
        return []
    own = np.sqrt(np.maximum(np.diag(fit.covariance), 0.0))
    told = ", ".join(f"+-{share.sd_deg[k]:g} deg {ANGLE_NAMES[k]}" for k in share.shifts)
    return [f"{p} depends on the pose: its uncertainty ({told}, 1 sd) moves it by "
            f"+-{unc.Z['95'] * share.sd[i]:.3g} (95%), at least doubling its interval, which "
            "includes that; a pose measured better (`skyfit camera` from more marked points, "
            "spread over the image) would narrow it."
            for i, p in enumerate(s.names) if share.sd[i] > SKY_DOMINATES * own[i]]
