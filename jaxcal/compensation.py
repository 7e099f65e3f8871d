"""Compensation: joint commands that make the *calibrated* model reach given targets.

Levenberg–Marquardt inverse kinematics, one small linear solve per pose and step, in a
``lax.while_loop``; jit-compiled (``eqx.filter_jit``) and vmapped over poses. Each step solves

$(N + \\mu (\\mathrm{diag}(N) + \\lambda I))\\,\\Delta q = J^T W e,\\quad N = J^T W J,\\quad
e = \\text{pose\\_error}(T_{target}, T(q))$

and is accepted only if it lowers the error (then ``mu /= 3``, else ``mu *= 4``).

with ``J`` the analytic joint Jacobian (the ``theta`` / ``d`` columns of the identification
Jacobian) and ``W`` weighting rotation rows by ``rot_weight_mm`` mm per rad (a lever arm). The
damping keeps a redundant arm (7 joints for a 6-D target) close to its start, the nominal
command. Targets may be positions only (3 rows) or full poses.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._config import as_f64
from .error_model import identification_jacobian, pose_error
from .errors import DataError
from .kinematics import fk
from .measurements import (ANGLE_UNITS, LENGTH_UNITS, POSITION_COLUMNS, QUAT_COLUMNS, _JOINT_RE, _names, check_column_names,
                           _parse_rows, _unit, open_table)
from .robot import Robot


@dataclasses.dataclass(frozen=True)
class Compensation:
    """What :func:`compensate` returns (one entry per target)."""

    q: np.ndarray                 # (K, n) compensated joint commands (rad; mm for prismatic)
    pos_residual_mm: np.ndarray   # (K,) |p_target - p_calibrated(q)|
    rot_residual_deg: np.ndarray  # (K,) rotation angle of the remaining error (0 if position only)
    converged: np.ndarray         # (K,) bool
    steps: np.ndarray             # (K,)


@eqx.filter_jit
def _ik(robot: Robot, targets, q0, position_only: bool, rot_weight: float, damping: float, max_steps: int,
        tol_mm: float):
    rows = 3 if position_only else 6
    cols = jnp.asarray([4 * i + (0 if t == "R" else 1) for i, t in enumerate(robot.joint_types)])
    w = jnp.asarray([1.0, 1.0, 1.0] + [rot_weight] * 3)[:rows]

    def err(q, T):
        return pose_error(T, fk(robot, q))[:rows] * w

    def one(T, q0):
        def body(c):
            q, mu, i, _ = c
            e = err(q, T)
            J = identification_jacobian(robot, q)[:rows][:, cols] * w[:, None]
            N = J.T @ J
            dq = jnp.linalg.solve(N + mu * (jnp.diag(jnp.diag(N)) + damping * jnp.eye(N.shape[0])), J.T @ e)
            e_new = err(q + dq, T)
            accept = jnp.sum(e_new ** 2) < jnp.sum(e ** 2)
            q = jnp.where(accept, q + dq, q)
            mu = jnp.where(accept, mu / 3.0, mu * 4.0)
            return q, mu, i + 1, jnp.max(jnp.abs(err(q, T))) < tol_mm

        def cond(c):
            return (c[2] < max_steps) & ~c[3] & (c[1] < 1e12)

        init = (q0, jnp.asarray(1e-3), jnp.asarray(0), jnp.max(jnp.abs(err(q0, T))) < tol_mm)
        q, _, steps, done = jax.lax.while_loop(cond, body, init)
        e = pose_error(T, fk(robot, q))
        return q, jnp.linalg.norm(e[:3]), jnp.linalg.norm(e[3:]), done & jnp.all(jnp.isfinite(q)), steps

    return jax.vmap(one)(targets, q0)


def compensate(calibrated: Robot, targets, q_start, *, position_only: bool = False, rot_weight_mm: float = 1000.0,
               damping: float = 1e-6, max_steps: int = 50, tol_mm: float = 1e-7) -> Compensation:
    """Joint commands ``q`` with ``fk(calibrated, q) ~ targets``, starting from ``q_start``.

    **Arguments**: ``targets`` ``(K, 4, 4)`` (mm; only the position is used with
    ``position_only``); ``q_start`` ``(K, n)``, e.g. the nominal commands; ``rot_weight_mm``
    mm per rad of rotation error; ``damping`` the Levenberg term (mm^2); convergence when every
    weighted residual row is below ``tol_mm``.

    **Returns** a :class:`Compensation` (residuals and a converged flag per pose; never raises
    for a pose that did not converge).
    """
    targets = as_f64(targets, "targets")
    q_start = as_f64(q_start, "q_start")
    if q_start.ndim != 2 or q_start.shape[1] != calibrated.n_joints:
        raise DataError(f"q_start must have shape (K, {calibrated.n_joints}), got {q_start.shape}")
    if targets.shape != (q_start.shape[0], 4, 4):
        raise DataError(f"targets must have shape ({q_start.shape[0]}, 4, 4), got {targets.shape}")
    for name, a in (("targets", targets), ("q_start", q_start)):
        bad = ~np.isfinite(np.asarray(a))
        if bad.any():
            raise DataError(f"{name}: non-finite value at index {tuple(int(i) for i in np.argwhere(bad)[0])}")
    if not position_only:
        R = np.asarray(targets)[:, :3, :3]
        err = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max((1, 2))
        bad = (err > 1e-6) | (np.linalg.det(R) < 0)
        if bad.any():
            raise DataError(f"targets[{int(np.argmax(bad))}]: rotation is not a proper rotation matrix; "
                            "use position_only=True for position targets")
    for name, v in (("rot_weight_mm", rot_weight_mm), ("damping", damping), ("tol_mm", tol_mm)):
        if not (np.isfinite(v) and v > 0):
            raise DataError(f"{name} must be a finite positive number, got {v!r}")
    if int(max_steps) < 1:
        raise DataError(f"max_steps must be >= 1, got {max_steps!r}")
    q, ep, er, ok, steps = _ik(calibrated, targets, q_start, bool(position_only), float(rot_weight_mm),
                               float(damping), int(max_steps), float(tol_mm))
    return Compensation(q=np.asarray(q), pos_residual_mm=np.asarray(ep),
                        rot_residual_deg=np.degrees(np.asarray(er)) * (not position_only),
                        converged=np.asarray(ok), steps=np.asarray(steps))


@dataclasses.dataclass(frozen=True)
class Targets:
    """A targets file: ``q`` (nominal commands, or None), ``poses`` (or None), ``position_only``."""

    q: np.ndarray | None
    poses: np.ndarray | None
    position_only: bool
    rows: np.ndarray


def read_targets(path, robot: Robot, *, length_unit=None, angle_unit=None) -> Targets:
    """Read a targets CSV: ``x, y, z`` [``qw, qx, qy, qz``] target poses and/or ``q1..qN``
    nominal joint commands (both: the commands are the starting point; commands only: the
    targets are where the nominal model puts them). Errors name the row and column."""
    lu, _ = _unit(length_unit, LENGTH_UNITS, "length_unit", "mm")
    au, _ = _unit(angle_unit, ANGLE_UNITS, "angle_unit", "rad")
    path, src, records, header = open_table(
        path, f"expected a header with q1..q{robot.n_joints} and/or x, y, z")
    n = robot.n_joints
    expected = f"expected x, y, z [qw, qx, qy, qz] and/or q1..q{n}"
    seen = check_column_names(header, src, expected)
    joints = sorted(int(_JOINT_RE.fullmatch(c).group(1)) for c in header if _JOINT_RE.fullmatch(c))
    if joints and joints != list(range(1, n + 1)):
        raise DataError(f"{src}: joint columns {_names(f'q{j}' for j in joints)} do not match the robot's "
                        f"{n} joints (q1..q{n})")
    pos = [c for c in POSITION_COLUMNS if c in seen]
    if pos and len(pos) < 3:
        raise DataError(f"{src}: missing column(s) {_names(c for c in POSITION_COLUMNS if c not in seen)}; {expected}")
    quat = [c for c in QUAT_COLUMNS if c in seen]
    if quat and (len(quat) < 4 or not pos):
        raise DataError(f"{src}: quaternion columns need all of qw, qx, qy, qz and x, y, z; {expected}")
    if not pos and not joints:
        raise DataError(f"{src}: no target columns; {expected}")
    if len(records) == 1:
        raise DataError(f"{src}: header only, no data rows")
    values, rows, lines = _parse_rows(records[1:], header, src)
    q = None
    if joints:
        scale = np.array([lu if t == "P" else au for t in robot.joint_types])
        q = values[:, [seen[f"q{j}"] for j in range(1, n + 1)]] * scale
    poses = None
    if pos:
        poses = np.broadcast_to(np.eye(4), (len(values), 4, 4)).copy()
        poses[:, :3, 3] = values[:, [seen[c] for c in POSITION_COLUMNS]] * lu
        if quat:
            from scipy.spatial.transform import Rotation

            qq = values[:, [seen[c] for c in QUAT_COLUMNS]]
            norm = np.linalg.norm(qq, axis=1)
            bad = np.flatnonzero(np.abs(norm - 1.0) > 1e-3)
            if bad.size:
                k = bad[0]
                raise DataError(f"{src}: row {rows[k]} (line {lines[k]}): quaternion (qw, qx, qy, qz) has norm "
                                f"{norm[k]:.6g}, not 1")
            qq = qq / norm[:, None]
            poses[:, :3, :3] = Rotation.from_quat(qq[:, [1, 2, 3, 0]]).as_matrix()
    return Targets(q=q, poses=poses, position_only=bool(pos) and not quat if pos else False, rows=rows)


def compensate_targets(calibrated: Robot, targets: Targets, *, nominal: Robot | None = None, **kw):
    """Resolve a :class:`Targets` file into ``(target poses, start q)`` and compensate.

    Commands only: targets are ``fk(nominal, q)`` (full poses; ``nominal`` required). Poses
    without commands: the start is the middle of the joint limits."""
    if targets.poses is None:
        if nominal is None:
            raise DataError("targets given as joint commands only: the nominal robot is needed (--nominal) "
                            "to know where they were meant to go")
        if nominal.n_joints != calibrated.n_joints:
            raise DataError(f"nominal robot has {nominal.n_joints} joints, calibrated {calibrated.n_joints}")
        poses = np.asarray(fk(nominal, jnp.asarray(targets.q)))
        position_only = False
    else:
        poses, position_only = targets.poses, targets.position_only
    q0 = targets.q if targets.q is not None else np.tile(np.asarray(calibrated.q_limits).mean(axis=1), (len(poses), 1))
    return poses, compensate(calibrated, poses, q0, position_only=position_only, **kw)
