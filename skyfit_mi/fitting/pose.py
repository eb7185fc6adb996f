"""The camera pose's uncertainty in a fit's intervals.

The pose's angles (``[camera] pose_sd_deg`` or ``fit --pose-sd-deg``: azimuth, angle from the
vertical, roll, each 1 sd) are nuisances propagated linearised: for each angle j of sd_j > 0 the
light is traced again with the camera turned by sd_j (on the fit's samples), the residuals move by
Delta r_j, and the parameters by the Gauss-Newton step

    Delta theta_j = -(J^T J)^-1 J^T Delta r_j

whose root sum of squares over j widens every interval. Under a fitted sky the turn also moves the
sky's coefficients, by -H^-1 sum_r Jp_r^T Delta r_r (H their profiled normal matrix, Jp_r region
r's unabsorbed derivatives), and every region with them (:func:`pose_through_sky`). The pose is
not fitted (fitted turns took up the photographs' own errors), so it only widens.
"""

from dataclasses import dataclass, field, replace

import numpy as np

from . import uncertainty as unc
from .sky_fit import doubles_interval, light_response
from ..render.scene import view_centre

#: How each angle of the pose is named in records and warnings.
ANGLE_NAMES = {"azimuth": "in azimuth", "angle": "in angle from the vertical",
               "roll": "in roll"}


@dataclass
class PoseShare:
    """What the camera pose's uncertainty adds to one region's parameters' errors.

    sd_deg : the pose's 1-sd {azimuth, angle, roll} [deg]
    shifts : {angle: (n,) the parameters' shift for a turn of its sd} (empty: none propagated)
    through_sky : {angle: (n,) the part of ``shifts`` through the fitted sky}
    pivot, seconds : the point the camera turns about [m]; the traces' wall time [s]
    """

    sd_deg: dict
    shifts: dict = field(default_factory=dict)
    through_sky: dict = field(default_factory=dict)
    pivot: list = None
    seconds: float = 0.0

    @property
    def sd(self):
        """(n,) sqrt(sum_j shift_j^2), the pose's standard errors (None: nothing propagated)."""
        return np.sqrt(sum(d ** 2 for d in self.shifts.values())) if self.shifts else None

    def sd_of(self, n):
        """The pose's standard errors (n,), zeros where nothing was propagated."""
        return np.zeros(n) if self.sd is None else self.sd

    @property
    def covariance(self):
        """The pose's covariance of the parameters, sum_j shift_j shift_j^T (n, n)."""
        return sum(np.outer(d, d) for d in self.shifts.values())


def turned_residuals(s, problem, theta):
    """{angle: the residuals' change (P, T, 3) at ``theta`` with the camera turned by its sd}, 0
    where unused or off the material."""
    r0, _ = problem.residual_terms(problem.model.radiance(theta), derivative=False)
    out = {}
    for k in s.pose_angles:
        table = s.table_turned(k)
        with np.errstate(all="ignore"):
            r, _ = problem.residual_terms(s.model_on(table).radiance(theta), derivative=False)
        out[k] = np.where(problem.mask & table.hit[..., None], r - r0, 0.0)
    return out


def pose_through_sky(sessions, sky):
    """The sky fit ``sky`` of ``sessions`` with each share's and the record's ``pose_shift``:
    the coefficients' shift per angle, -H^-1 sum_r Jp_r^T Delta r_r
    (:class:`~.sky_fit.FittedLight`'s ``inverse_normal``). Unchanged where the pose is exact or
    the sky's level is not determined."""
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
    """The :class:`PoseShare` of ``fit`` (``J`` (P, T, 3, n) its residuals' derivatives): direct
    and through-sky shifts per angle of sd > 0; empty where every sd is 0 or for a table."""
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
    """Warnings for parameters whose pose share at least doubles their interval."""
    share = fit.pose
    if not share.shifts:
        return []
    big = doubles_interval(fit, share.sd)
    told = ", ".join(f"+-{share.sd_deg[k]:g} deg {ANGLE_NAMES[k]}" for k in s.pose_angles)
    return [f"{p} depends on the pose: its uncertainty ({told}, 1 sd) moves it by "
            f"+-{unc.Z['95'] * share.sd[i]:.3g} (95%), at least doubling its interval, which "
            "includes that; a pose measured better (`skyfit camera` from more marked points, "
            "spread over the image) would narrow it."
            for i, p in enumerate(s.names) if big[i]]
