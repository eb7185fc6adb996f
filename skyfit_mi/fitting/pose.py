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
every interval (:func:`~.intervals.fit_intervals`).

Where the sky is fitted with the day's regions (:mod:`~.sky_fit`), the turn moves every
region's residuals, so the shared sky's coefficients (by -H^-1 sum_r Jp_r^T Delta r_r, H their
profiled normal matrix, Jp_r region r's derivatives in them that its parameters cannot absorb),
and every region's parameters with them: that part joins each Delta theta_j
(:func:`pose_through_sky`).  A camera 0.3 deg off moved the sample board's sky level from 1.02
to 1.09 and every C with it by 2-12%, beyond intervals that held the direct part alone.  The
pose is not fitted: the turns fitted as coefficients of the light with the sky's took up the
photographs' own errors (the board photographed with its pose exact read a turn of 0.17 +-
0.08 deg, and 21 of 40 pairs held against 38 without), so it only widens.  Each function takes
the region's :class:`~.fit.FitSession` ``s``.
"""

from dataclasses import dataclass, field, replace

import numpy as np

from . import uncertainty as unc
from .sky_fit import SKY_DOMINATES, light_response
from ..render.scene import view_centre

#: How each angle of the pose is named in records and warnings.
ANGLE_NAMES = {"azimuth": "in azimuth", "angle": "in angle from the vertical",
               "roll": "in roll"}


@dataclass
class PoseShare:
    """What the camera pose's uncertainty adds to one region's parameters' errors.

    sd_deg : the pose's 1-sd {azimuth, angle, roll} [deg]
        (:func:`~skyfit_mi.render.scene.pose_sd`)
    shifts : {angle: (n,) the parameters' shift with the camera turned by its sd, directly and
        through the fitted sky} for each angle of sd > 0 (empty: nothing propagated)
    through_sky : {angle: (n,) the part of ``shifts`` through the fitted sky}
    pivot : the point the camera turns about [m] (where its central ray meets the scene)
    seconds : the traces' wall time [s]
    """

    sd_deg: dict
    shifts: dict = field(default_factory=dict)
    through_sky: dict = field(default_factory=dict)
    pivot: list = None
    seconds: float = 0.0

    @property
    def sd(self):
        """(n,) the pose's share of each parameter's standard error, sqrt(sum_j shift_j^2)
        (None: nothing propagated)."""
        return np.sqrt(sum(d ** 2 for d in self.shifts.values())) if self.shifts else None

    def sd_of(self, n):
        """The pose's standard errors (n,), zeros where nothing was propagated."""
        return np.zeros(n) if self.sd is None else self.sd

    @property
    def covariance(self):
        """The pose's covariance of the parameters, sum_j shift_j shift_j^T (n, n)."""
        return sum(np.outer(d, d) for d in self.shifts.values())


def turned_residuals(s, problem, theta):
    """{angle: the residuals' change (P, T, 3) at ``theta`` under ``problem`` (the region's
    chi-square) with the camera turned by that angle's sd (:meth:`~.fit.FitSession.table_turned`),
    0 where a value is not used or its position lands off the material} for each of the
    session's angles of sd above 0."""
    r0, _ = problem.residual_terms(problem.model.radiance(theta), derivative=False)
    out = {}
    for k in s.pose_angles:
        table = s.table_turned(k)
        with np.errstate(all="ignore"):
            r, _ = problem.residual_terms(s.model_on(table).radiance(theta), derivative=False)
        out[k] = np.where(problem.mask & table.hit[..., None], r - r0, 0.0)
    return out


def pose_through_sky(sessions, sky):
    """The sky fit ``sky`` (:class:`~.sky_fit.SkyFit` of ``sessions``, the day's regions, each
    lit at it) with each region's share's ``pose_shift``: the sky's coefficients' shift per
    angle of the pose, -H^-1 sum_r Jp_r^T Delta r_r over the regions at their parameters of
    the sky fit (:class:`~.sky_fit.FittedLight`'s ``inverse_normal``), and the
    record's ``pose_shift``.  ``sky`` as it is where the pose is exact or the sky's level is
    not determined."""
    angles = sorted({k for s in sessions for k in s.pose_angles})
    lights = {s.name: sky.shares[s.name].light for s in sessions if s.name in sky.shares}
    if not angles or not lights or any(v is None for v in lights.values()):
        return sky
    pull = {}
    for s in sessions:
        light = lights[s.name]
        Jp = light_response(s, light, light.theta)[0]
        for k, moved in turned_residuals(s, s.problem, light.theta).items():
            pull[k] = pull.get(k, 0.0) + Jp.T @ moved[s.problem.mask]
    light = next(iter(lights.values()))
    shift = {k: -light.inverse_normal @ v for k, v in pull.items()}
    record = {**sky.record, "pose_shift": {
        "meaning": "the sky's coefficients' change were the camera turned by the pose's sd in "
                   "each angle (linearised: every region's residuals moved by the turn), which "
                   "each region's parameters follow in its pose's error",
        "coefficients": light.coefficients.names,
        "by_angle": {k: v.tolist() for k, v in shift.items()}}}
    return replace(sky, record=record, shares={
        name: replace(share, record=record, pose_shift=shift)
        for name, share in sky.shares.items()})


def pose_share(s, fit, J):
    """The :class:`PoseShare` of the fit ``fit`` (:class:`~.fit.FitState`: its problem, theta,
    (J^T J)^-1 and sky share) with ``J`` (P, T, 3, n) its residuals' derivatives: the
    parameters' shift per angle of the session's ``pose_sd`` above 0, from the light traced
    with the camera turned by that angle's sd (:func:`turned_residuals`), and through the sky
    fitted with it (its response to the sky's ``pose_shift``, :func:`pose_through_sky`).
    Nothing where every sd is 0, or for an observation table (its points are rays in the
    world, no camera's)."""
    if not s.pose_angles:
        return PoseShare(s.pose_sd)
    use = fit.problem.mask
    sky = fit.sky
    through = {k: sky.response @ d for k, d in sky.pose_shift.items()} \
        if sky.response is not None else {}
    shifts = {k: -fit.curvature_inverse @ (J[use].T @ moved[use]) + through.get(k, 0.0)
              for k, moved in turned_residuals(s, fit.problem, fit.theta).items()}
    return PoseShare(s.pose_sd, shifts, through, view_centre(s.scene).tolist(), s.turn_time)


def pose_record(s, share):
    """The fit JSON's ``pose`` where the pose's uncertainty was propagated, else None."""
    if not share.shifts:
        return None
    names = s.names

    def by_parameter(shifts):
        return {p: {k: float(d[i]) for k, d in shifts.items()} for i, p in enumerate(names)}

    return {"sd_deg": share.sd_deg, "pivot": share.pivot,
            "shift_by_parameter": by_parameter(share.shifts),
            **({"through_sky": by_parameter(share.through_sky)} if share.through_sky else {}),
            "error_sd": dict(zip(names, share.sd.tolist())),
            "covariance": share.covariance.tolist(), "trace_time_s": share.seconds,
            "meaning": "the camera's pose is known to sd_deg (1 sd, each angle independent); "
                       "shift_by_parameter: each parameter's change were the camera turned "
                       "by one sd about the pivot (where its central ray meets the scene), "
                       "linearised from a trace of the light so turned, through_sky its part "
                       "through the sky fitted with every region of the day; error_sd: their "
                       "root sum of squares, added in quadrature to every interval"}


def pose_warnings(s, fit):
    """Warnings for the parameters whose pose share at least doubles their interval
    (:data:`~.sky_fit.SKY_DOMINATES`, the sky's rule)."""
    share = fit.pose
    if not share.shifts:
        return []
    own = np.sqrt(np.maximum(np.diag(fit.covariance), 0.0))
    told = ", ".join(f"+-{share.sd_deg[k]:g} deg {ANGLE_NAMES[k]}" for k in s.pose_angles)
    return [f"{p} depends on the pose: its uncertainty ({told}, 1 sd) moves it by "
            f"+-{unc.Z['95'] * share.sd[i]:.3g} (95%), at least doubling its interval, which "
            "includes that; a pose measured better (`skyfit camera` from more marked points, "
            "spread over the image) would narrow it."
            for i, p in enumerate(s.names) if share.sd[i] > SKY_DOMINATES * own[i]]
