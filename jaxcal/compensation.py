r"""Compensation: joint commands that make the *calibrated* model reach given targets.

Inverse kinematics on the one engine (:func:`jaxcal.solvers.least_squares`, optimistix
Gauss–Newton), vmapped over targets: per target it minimises

$$|W\,e(q)|^2 + \lambda\,|q - q_0|^2,\qquad e = \text{pose\_error}(T_{target}, T(q))$$

with the analytic joint Jacobian (the joint columns of eq. 10), ``W`` weighting rotation rows by
``rot_weight_mm`` mm per rad (a lever arm), and a light pull ``lambda`` (``damping``) toward the
starting command ``q_0``, which keeps a redundant arm, or a position-only target, near the
nominal command instead of anywhere on its self-motion, and keeps every step well posed. A
prismatic joint's millimetres are scaled by the revolute joints' mean lever (the tool's distance
from their axes), so that the least step weighs a lift and a turn by how far they move the tool.

A command is then put on the branch of its starting command (revolute joints within pi of it:
no whole-turn jumps), a joint beyond limits of its own there turned by whole turns into them
where it fits and its start lies beyond them too (or no command was given), and checked against
the robot's joint limits. A target is reached
(``converged``) when its residual is below ``tol_mm`` (whether or not the solver's own stopping
rule was met: near a singularity it creeps on at nanometres); a
command outside the limits (``within_limits``) or one that left its starting command's branch,
a joint turned by more than :data:`MAX_MOVE_DEG` (``on_branch``), is flagged, never silently
written.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._config import as_f64
from .calibration import check_angles, check_units
from .error_model import point_jacobian, pose_error
from .errors import DataError
from .kinematics import deflected, fk
from .lie import so3_right_jacobian_inv
from .measurements import (
    ANGLE_UNITS,
    LENGTH_UNITS,
    joint_columns,
    measurement_columns,
    parse_rows,
    quaternions_to_rotations,
    read_table,
    require_rows,
    rotations_without,
    unit_scale,
)
from .robot import Robot
from .solvers import least_squares

FAR_REACHES = 1.5
"""Targets given without commands whose median distance from the robot's base is beyond this many
times its reach (:meth:`jaxcal.Robot.reach`, an upper bound) are refused: none can be reached."""
LIMIT_TOL = 1e-9
"""Slack (rad or mm) of the joint-limit check, for commands that land on a limit."""
MAX_MOVE_DEG = 20.0
"""A revolute joint turned further than this from its starting command has left that command's
branch: the solve went round to another solution of the arm's inverse kinematics (an elbow or a
wrist flipped), or through a singularity, where a calibration's corrections are a fraction of a
degree. Such a command reaches its target but is not the one meant (``on_branch``)."""


@dataclasses.dataclass(frozen=True)
class Compensation:
    """What :func:`compensate` returns (one entry per target)."""

    q: np.ndarray
    """``(K, n)`` compensated joint commands (rad; mm for prismatic joints)."""
    pos_residual_mm: np.ndarray
    """``(K,)`` ``|p_target - p_calibrated(q)|``."""
    rot_residual_deg: np.ndarray
    """``(K,)`` rotation angle of the remaining error (0 for position targets)."""
    converged: np.ndarray
    """``(K,)`` the target is reached (its residual below ``tol_mm``)."""
    outside: np.ndarray
    """``(K, n)`` the joints of each command beyond the robot's limits."""
    steps: np.ndarray
    on_branch: np.ndarray
    """``(K,)`` no revolute joint turned more than :data:`MAX_MOVE_DEG` from its starting command."""

    @property
    def within_limits(self) -> np.ndarray:
        """``(K,)`` every joint of the command is within the robot's joint limits."""
        return ~self.outside.any(-1)

    @property
    def ok(self) -> np.ndarray:
        """Reached, within the limits and on the starting command's branch: the commands that may
        be sent to the robot."""
        return self.converged & self.within_limits & self.on_branch


def _wrap(d):
    """Angle differences into (-pi, pi]."""
    return d - 2 * jnp.pi * jnp.ceil((d - jnp.pi) / (2 * jnp.pi))


def _into_limits(q, lim, revolute):
    """A revolute joint (``revolute``: a mask of the joints, or of each command's) outside its
    limits on the starting command's branch is moved by whole turns into them where a turn fits
    (the same pose: a joint's range may span more than one turn)."""
    q = q.copy()
    lo, hi = lim[:, 0] - LIMIT_TOL, lim[:, 1] + LIMIT_TOL
    for k in range(1, 4):  # up to three turns either way (limits of +-2 turns and more exist)
        for s in (k, -k):
            moved = q + s * 2 * np.pi
            fix = revolute & ((q < lo) | (q > hi)) & (moved >= lo) & (moved <= hi)
            q = np.where(fix, moved, q)
    return q


@eqx.filter_jit
def _ik(robot: Robot, targets, q0, position_only: bool, rot_weight, damping, max_steps: int):
    rows = 3 if position_only else 6
    n = robot.n_joints
    # each joint's offset column: theta (DH revolute), d (DH prismatic), the offset (joint frames)
    p, dh = robot.n_kinds, robot.convention != "joint"
    cols = jnp.asarray([p * i + (1 if dh and t == "P" else 0) for i, t in enumerate(robot.joint_types)])
    w = jnp.asarray([1.0, 1.0, 1.0] + [rot_weight] * 3)[:rows]
    sd = jnp.sqrt(damping)
    rigid = eqx.tree_at(lambda r: r.compliance, robot, None, is_leaf=lambda x: x is None)

    prismatic = jnp.asarray([t == "P" for t in robot.joint_types])

    def columns(q):
        # a compliant arm reaches its deflected values: the columns there (the moments' own
        # derivative is second order, as in the identification Jacobian)
        P, W, T = point_jacobian(rigid, deflected(robot, q[None]), jnp.zeros((1, 3)))
        return P[0, 0][:, cols], W[0][:, cols], T[0]

    def rj(y, args):
        # solved in y = q / scale: a step of 1 is a radian or the millimetres that move the tool
        # about as far, so the least step does not leave a prismatic joint still (mm and rad mixed)
        T_target, y_start, sd, scale = args
        Jp, Jw, T = columns(y * scale)
        e = pose_error(T_target, T)
        rot = so3_right_jacobian_inv(e[3:]) @ Jw
        J = -jnp.concatenate([Jp, rot])[:rows] * w[:, None] * scale
        r = jnp.concatenate([e[:rows] * w, sd * (y - y_start)])
        return r, jnp.concatenate([J, sd * jnp.eye(n)])

    def one(T, q_start):
        # the lever of a revolute joint: its position column's norm, the tool's distance from its axis
        lever = jnp.linalg.norm(columns(q_start)[0], axis=0)
        n_rev = jnp.maximum(jnp.sum(~prismatic), 1)
        reach = jnp.maximum(jnp.sum(jnp.where(prismatic, 0.0, lever)) / n_rev, 1.0)
        scale = jnp.where(prismatic, reach, 1.0)
        y0 = q_start / scale
        y, _, steps = least_squares(
            rj, y0, (T, y0, sd, scale), method="gn", max_steps=max_steps, rtol=1e-10, atol=1e-10
        )
        # the pull leaves a residual of about damping x the move (mm for a prismatic joint's tens
        # of mm): once more, pulled toward that solution instead (the bias is then damping x the
        # last small move; a redundant arm stays where the first solve put it)
        y, _, more = least_squares(rj, y, (T, y, sd, scale), method="gn", max_steps=max_steps, rtol=1e-10, atol=1e-10)
        q, steps = y * scale, steps + more
        q = jnp.where(prismatic, q, q_start + _wrap(q - q_start))  # the branch of the starting command
        e = pose_error(T, fk(robot, q))
        return q, jnp.linalg.norm(e[:3]), jnp.linalg.norm(e[3:]), steps

    return jax.vmap(one)(targets, q0)


def compensate(
    calibrated: Robot,
    targets,
    q_start,
    *,
    position_only: bool = False,
    rot_weight_mm: float = 1000.0,
    damping: float = 1e-6,
    max_steps: int = 100,
    tol_mm: float = 1e-3,
    branch: bool = True,
) -> Compensation:
    """Joint commands ``q`` with ``fk(calibrated, q) ~ targets``, starting from ``q_start``.

    **Arguments**: ``targets`` ``(K, 4, 4)`` in the calibrated model's frame (mm; only the
    position is used with ``position_only``); ``q_start`` ``(K, n)``, e.g. the nominal
    commands; ``rot_weight_mm`` mm per rad of rotation error; ``damping`` the pull toward
    ``q_start`` (mm^2 per rad^2, a prismatic joint's move counted in the revolute joints' mean
    lever: its pull is that lever squared weaker per mm); a target counts as reached when its position residual is below
    ``tol_mm`` (a micron by default, far below any arm's repeatability) and its rotation residual
    below ``tol_mm / rot_weight_mm``; ``branch``: ``q_start``
    are the commands meant, whose branch a command must keep (``on_branch``; False: a start only).

    **Returns** a :class:`Compensation` (residuals, ``converged`` and ``within_limits`` per
    target; never raises for a target that was not reached).
    """
    targets = np.array(as_f64(targets, "targets"))
    q_start = np.array(as_f64(q_start, "q_start"))
    if q_start.ndim != 2 or q_start.shape[1] != calibrated.n_joints:
        raise DataError(f"q_start must have shape (K, {calibrated.n_joints}), got {q_start.shape}", option="q_start")
    if targets.shape != (q_start.shape[0], 4, 4):
        raise DataError(f"targets must have shape ({q_start.shape[0]}, 4, 4), got {targets.shape}", option="targets")
    for name, a in (("targets", targets), ("q_start", q_start)):
        bad = ~np.isfinite(a)
        if bad.any():
            raise DataError(
                f"{name}: non-finite value at index {tuple(int(i) for i in np.argwhere(bad)[0])}", option=name
            )
    if not position_only:
        R = targets[:, :3, :3]
        err = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max((1, 2))
        bad = (err > 1e-6) | (np.linalg.det(R) < 0)
        if bad.any():
            raise DataError(
                f"targets[{int(np.argmax(bad))}]: rotation is not a proper rotation matrix; "
                "use position_only=True for position targets",
                option="targets",
            )
    for name, v in (("rot_weight_mm", rot_weight_mm), ("damping", damping), ("tol_mm", tol_mm)):
        if not (np.isfinite(v) and v > 0):
            raise DataError(f"{name} must be a finite positive number, got {v!r}", option=name)
    if int(max_steps) < 1:
        raise DataError(f"max_steps must be >= 1, got {max_steps!r}", option="max_steps")
    q, ep, er, steps = _ik(
        calibrated.stripped(),
        jnp.asarray(targets),
        jnp.asarray(q_start),
        bool(position_only),
        float(rot_weight_mm),
        float(damping),
        int(max_steps),
    )
    q, ep, er = np.asarray(q), np.asarray(ep), np.asarray(er) * (not position_only)
    lim = np.asarray(calibrated.q_limits)
    # not for default limits: a continuous joint (no limits) would be sent a turn round instead;
    # and only where the start is no command meant or lies beyond the limits itself (a reading a
    # whole turn off): from a command within them, a whole turn is a turn the joint would make
    given = np.array([t == "R" for t in calibrated.joint_types]) & calibrated.limits_given()
    start_out = (q_start < lim[:, 0] - LIMIT_TOL) | (q_start > lim[:, 1] + LIMIT_TOL)
    q = _into_limits(q, lim, given & (start_out | (not branch)))
    reached = (ep < tol_mm) & (er < tol_mm / rot_weight_mm) & np.all(np.isfinite(q), -1)
    # a joint given no limits has none to be outside of (its defaults are a sampling range)
    outside = ((q < lim[:, 0] - LIMIT_TOL) | (q > lim[:, 1] + LIMIT_TOL)) & calibrated.limits_given()
    rev = np.array([t == "R" for t in calibrated.joint_types])
    turned = np.abs(np.asarray(_wrap(q - q_start)))[:, rev]  # a whole turn into the limits is no move
    return Compensation(
        q=q,
        pos_residual_mm=ep,
        rot_residual_deg=np.degrees(er),
        converged=reached,
        outside=outside,
        steps=np.asarray(steps),
        on_branch=np.all(turned <= np.radians(MAX_MOVE_DEG), -1) | (not branch),
    )


@dataclasses.dataclass(frozen=True)
class Targets:
    """A targets file: nominal commands ``q`` (or None), target ``poses`` (or None), whether the
    targets are positions only, and the data rows."""

    q: np.ndarray | None
    poses: np.ndarray | None
    position_only: bool
    rows: np.ndarray
    joint_columns: tuple[str, ...] = ()
    """The file's joint column names in joint order (``q1..qN`` or the joint names; empty: none):
    the commands written for it are headed the same, so they read back where the targets did."""


def read_targets(path, robot: Robot, *, length_unit=None, angle_unit=None) -> Targets:
    """Read a targets CSV: ``x, y, z`` [``qw, qx, qy, qz``] target poses and/or joint columns
    (``q1..qN`` or the joint names) with the nominal commands (both: the commands are the
    starting point; commands only: the targets are where the nominal model puts them). Units
    follow the robot file unless given. Errors name the row and column."""
    lu, _ = unit_scale(length_unit, LENGTH_UNITS, "length_unit", robot.units[0])
    au, _ = unit_scale(angle_unit, ANGLE_UNITS, "angle_unit", robot.units[1])
    n = robot.n_joints
    expected = f"expected x, y, z [qw, qx, qy, qz] and/or q1..q{n}"
    src, header, records = read_table(path, expected, "target")
    jcols = joint_columns(header, robot, src, required=False)
    points, quat = measurement_columns(header, src, required=False)
    if len(points) > 1:
        raise DataError(f"{src}: targets are one point (x, y, z) per row, the file has {len(points)}")
    if not points and not jcols:
        raise DataError(f"{src}: no target columns; {expected}")
    pcols = points[0] if points else []
    require_rows(records, src)
    values, rows, lines = parse_rows(records, header, (jcols or []) + pcols + (quat or []), src)
    q = None
    if jcols:
        q = values[:, :n] * np.array([lu if t == "P" else au for t in robot.joint_types])
    poses = None
    if points:
        k = n if jcols else 0
        poses = np.broadcast_to(np.eye(4), (len(values), 4, 4)).copy()
        poses[:, :3, 3] = values[:, k : k + 3] * lu
        if quat:
            poses[:, :3, :3] = quaternions_to_rotations(values[:, k + 3 :], rows, lines, src)
    return Targets(
        q=q, poses=poses, position_only=bool(points) and not quat, rows=rows, joint_columns=tuple(jcols or ())
    )


QUATERNION_HINT_DEG = 10.0
"""Target orientations whose median angle from where the commands put the calibrated tool is
beyond this are checked for a quaternion written in another order (:func:`quaternion_note`)."""


def quaternion_note(calibrated: Robot, targets: Targets) -> str:
    """A hint for target orientations far from where their commands put the calibrated tool
    (median beyond :data:`QUATERNION_HINT_DEG`) that a quaternion order or sign mistake brings
    within a quarter of that and of the limit (:func:`jaxcal.measurements.rotations_without`).
    Empty otherwise, and for targets without commands or orientations."""
    if targets.q is None or targets.poses is None or targets.position_only:
        return ""
    R_fk = np.asarray(fk(calibrated, jnp.asarray(targets.q)))[:, :3, :3]

    def median_deg(R):
        c = (np.trace(np.swapaxes(R_fk, -1, -2) @ R, axis1=-2, axis2=-1) - 1.0) / 2.0
        return float(np.degrees(np.median(np.arccos(np.clip(c, -1.0, 1.0)))))

    given = median_deg(targets.poses[:, :3, :3])
    if given <= QUATERNION_HINT_DEG:
        return ""
    best, name = min((median_deg(R), m) for m, R in rotations_without(targets.poses[:, :3, :3]).items())
    if best > min(0.25 * given, 0.25 * QUATERNION_HINT_DEG):
        return ""
    return (
        f"the target orientations lie a median {given:.3g} deg from where their commands put the tool, "
        f"{best:.3g} deg without a {name}: check the quaternion columns (qw is the scalar part)"
    )


FAR_FROM_COMMANDS = 0.1
"""Targets whose median distance from where their commands put the calibrated tool is beyond
this share of the reach get a hint when some are missed (:func:`frame_note`): a calibration moves
the tool by millimetres, not by a tenth of the arm."""


def frame_note(calibrated: Robot, targets: Targets) -> str:
    """A hint for target positions far from where their commands put the calibrated tool
    (median beyond :data:`FAR_FROM_COMMANDS` of the reach): given in another frame or unit.
    Empty otherwise, and for targets without commands or positions."""
    if targets.q is None or targets.poses is None:
        return ""
    at = np.asarray(fk(calibrated, jnp.asarray(targets.q)))[:, :3, 3]
    d = float(np.median(np.linalg.norm(targets.poses[:, :3, 3] - at, axis=1)))
    if d <= FAR_FROM_COMMANDS * calibrated.reach():
        return ""
    return (
        f"the targets lie a median {d:.4g} mm from where their commands put the calibrated tool, where a "
        "calibration moves it by millimetres: are they in the calibrated model's frame (its base, the measurement "
        "frame it was fitted in) and units?"
    )


def check_orientation(n_points: int, targets: Targets, name: str) -> None:
    """Refuse target orientations given to a model calibrated from measured points (``n_points``
    > 0, the model file ``name``): its tool's orientation was never measured, and the commands
    would be flagged as reaching orientations the arm may miss by degrees. Position targets (x,
    y, z alone) compensate what it calibrated."""
    if n_points and targets.poses is not None and not targets.position_only:
        raise DataError(
            f"{name} was calibrated from measured points: its tool's orientation was never measured (the nominal "
            "one), so the targets' orientations cannot be reached to any known accuracy; give x, y, z targets "
            "(drop qw, qx, qy, qz) to compensate the positions, or calibrate from measured poses",
            option="targets",
        )


OTHER_TOOL_MM, OTHER_TOOL_DEG = 5.0, 2.0
"""A calibrated tool further than this from the nominal one is taken for another frame
(:func:`tool_note`): calibration corrects a tool by a few millimetres and a degree or so."""


def tool_note(n_points: int, calibrated: Robot, nominal: Robot | None, name: str, *, commands_only: bool) -> str:
    """A warning for joint commands alone (targets where the ``nominal`` robot puts its tool)
    given to a model calibrated from measured points (``n_points`` > 0, the model file ``name``):
    no tool centre point was measured, and the commands bring the model's tool frame to the
    targets, at its distance from the nominal tool on the flange; or to a pose model whose tool
    is beyond :data:`OTHER_TOOL_MM` / :data:`OTHER_TOOL_DEG` from the nominal one. Empty
    otherwise."""
    if nominal is None or not commands_only:
        return ""
    d = float(np.linalg.norm(np.asarray(calibrated.tool)[:3, 3] - np.asarray(nominal.tool)[:3, 3]))
    if not n_points:
        dR = np.asarray(calibrated.tool)[:3, :3].T @ np.asarray(nominal.tool)[:3, :3]
        turn = float(np.degrees(np.arccos(np.clip((np.trace(dR) - 1.0) / 2.0, -1.0, 1.0))))
        if d <= OTHER_TOOL_MM and turn <= OTHER_TOOL_DEG:  # a calibration's correction of the same tool
            return ""
        return (
            f"{name}'s tool is {d:.4g} mm and {turn:.3g} deg from the nominal robot's: more than a calibration "
            f"corrects ({OTHER_TOOL_MM:g} mm, {OTHER_TOOL_DEG:g} deg), so probably another frame (the measured "
            f"body, not the tool the commands were taught with). The commands bring the calibrated tool to "
            f"where the nominal one was; give the targets as poses of the calibrated tool where that is wrong"
        )
    return (
        f"{name} was calibrated from measured points, not a tool centre point: the commands' targets are where "
        f"the nominal robot puts its tool, and the compensated commands bring the model's tool frame there, "
        f"{d:.4g} mm from the nominal robot's tool on the flange (a one-point model written by --out-robot has it "
        "at the point); right only where that frame is the tool centre point, otherwise give x, y, z targets "
        "for the point (--point)"
    )


def compensate_targets(calibrated: Robot, targets: Targets, *, nominal: Robot | None = None, **kw):
    """Resolve a :class:`Targets` file into ``(target poses, start q)`` and compensate.

    Commands only: the targets are where the nominal robot puts its tool, ``fk(nominal, q)``, in
    the nominal robot's base frame; they are moved into the calibrated model's frame by its own
    base (``calibrated.base @ nominal.base^-1``), so an estimated measurement frame carries
    them along. Poses are taken in the calibrated model's frame. Without commands, the start is
    the middle of the joint limits."""
    if targets.poses is None:
        if nominal is None:
            raise DataError(
                "targets given as joint commands only: the nominal robot is needed (nominal) to know "
                "where they were meant to go",
                option="nominal",
            )
        if nominal.n_joints != calibrated.n_joints:
            raise DataError(
                f"nominal robot has {nominal.n_joints} joints, calibrated {calibrated.n_joints}", option="nominal"
            )
        frame = np.asarray(calibrated.base) @ np.linalg.inv(np.asarray(nominal.base))
        poses = frame @ np.asarray(fk(nominal, jnp.asarray(targets.q)))
        position_only = False
    else:
        if nominal is not None:
            raise DataError(
                "nominal: the targets file gives the target positions (x, y, z) itself; the nominal robot is for a "
                "file of joint commands only (its targets: where the nominal robot puts its tool there)",
                option="nominal",
            )
        poses, position_only = targets.poses, targets.position_only
    if targets.q is not None:  # the units checks calibrate and evaluate make, on the commands
        q = np.asarray(targets.q)
        check_angles(calibrated, q, targets.rows)
        model = np.asarray(fk(calibrated, q))[:, :3, 3]
        check_units(
            calibrated, q, poses, 0, batched=False, model_positions=model, robust=True, what="targets",
            model="the calibrated model",
        )  # fmt: skip
    else:  # no commands to compare with: targets beyond any reach are likely in another unit
        far = np.median(np.linalg.norm(np.asarray(poses)[:, :3, 3] - np.asarray(calibrated.base)[:3, 3], axis=1))
        if far > FAR_REACHES * calibrated.reach():
            raise DataError(
                f"targets: their median distance from the robot's base is {far:.4g} mm, {far / calibrated.reach():.3g} "
                f"times its reach ({calibrated.reach():.4g} mm): written in another length unit (length_unit), or "
                "in another frame than the calibrated model's?",
                option="length_unit",
            )
    q0 = targets.q if targets.q is not None else np.tile(np.asarray(calibrated.q_limits).mean(axis=1), (len(poses), 1))
    # without commands the start is no command of the user's: there is no branch to keep
    branch = targets.q is not None
    return poses, compensate(calibrated, poses, q0, position_only=position_only, branch=branch, **kw)
