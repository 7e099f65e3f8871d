"""The differential error model (paper eq. 8-10) and the identification Jacobian.

Parameters are laid out as one flat vector ``x``::

    x = [dtheta_1, dd_1, da_1, dalpha_1, ..., dtheta_n, ..., dalpha_n,   # 4n DH errors
         base twist (6, optional), tool twist (6, optional)]

Base and tool errors are a translation ``v`` and a rotation vector ``w`` each: the base frame
moves by ``v`` and turns by ``w`` about its own origin, both in the measurement frame's axes
(``t_B <- t_B + v``, ``R_B <- exp(w) R_B``); the tool frame moves by ``v`` and turns by ``w`` in
its own axes (``tool <- tool [exp(w) | v]``). So ``base_x`` is the base's translation in mm and
``base_rz`` its turn about the measurement frame's z axis, numbers a controller can take; see
:func:`perturb`.

Two error representations are provided:

* the paper's 4x4 error matrix ``dT T^{-1} = sum_i T_i Omega_i T_i^{-1}`` (eq. 10), computed
  literally by :func:`error_twist_matrix`;
* its analytic adjoint form: column ``k`` of joint ``i`` is ``Ad(T_i) vee(Omega_k)``
  (:func:`twist_jacobian`), and the identification Jacobian (:func:`identification_jacobian`)
  maps ``x`` to the first-order change of the end *position* (3 rows) and *orientation*
  (3 rows, a rotation vector), both in the measurement (base) frame. Position rows are
  ``dp = v + w x p_end``.

:func:`point_jacobian` gives the DH columns for any points fixed to the tool (several markers on
one rigid body); the measurement model (:mod:`jaxcal.model`) adds the frame columns.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._chain import chain, dot3, is_zero, link_inputs, matmul_soa, rotate_soa
from ._joints import joint_column_entries
from .derivatives import OMEGAS, omega_twist_entries
from .errors import DataError
from .kinematics import check_q, fk_frames, joint_dh
from .lie import inv_transform, make_transform, skew, so3_exp, so3_log
from .robot import Robot

FRAME_NAMES = ("x", "y", "z", "rx", "ry", "rz")


def n_params(robot: Robot, *, base: bool = False, tool: bool = False) -> int:
    return robot.n_kinds * robot.n_joints + 6 * base + 6 * tool


def param_names(robot: Robot, *, base: bool = False, tool: bool = False) -> list[str]:
    names = robot.param_names()
    names += [f"base_{c}" for c in FRAME_NAMES] if base else []
    names += [f"tool_{c}" for c in FRAME_NAMES] if tool else []
    return names


def perturb(robot: Robot, x: Float[Array, " m"], *, base: bool = False, tool: bool = False) -> Robot:
    """The robot with parameter errors ``x`` applied (exactly, not to first order)."""
    m = n_params(robot, base=base, tool=tool)
    if jnp.ndim(x) != 1 or jnp.shape(x)[0] != m:
        raise DataError(
            f"x must have shape ({m},) = {robot.n_joints} joints x {robot.n_kinds} "
            f"{'joint-frame' if robot.convention == 'joint' else 'DH'} errors"
            f"{' + 6 base' if base else ''}{' + 6 tool' if tool else ''}, got {jnp.shape(x)}"
        )
    x = jnp.asarray(x)
    n4 = robot.n_kinds * robot.n_joints
    out = robot.with_dh_delta(x[:n4].reshape(robot.n_joints, robot.n_kinds))
    if not (base or tool):
        return out
    new_base, new_tool = robot.base, robot.tool
    if base:
        B, v, w = robot.base, x[n4 : n4 + 3], x[n4 + 3 : n4 + 6]
        new_base = make_transform(so3_exp(w) @ B[:3, :3], B[:3, 3] + v)
    if tool:
        X, v, w = robot.tool, x[n4 + 6 * base : n4 + 6 * base + 3], x[n4 + 6 * base + 3 : n4 + 6 * base + 6]
        new_tool = make_transform(X[:3, :3] @ so3_exp(w), X[:3, 3] + X[:3, :3] @ v)
    return eqx.tree_at(lambda r: (r.base, r.tool), out, (new_base, new_tool))


@eqx.filter_jit
def pose_error(T_a: Float[Array, "*b 4 4"], T_b: Float[Array, "*b 4 4"]) -> Float[Array, "*b 6"]:
    """Pose of ``T_a`` relative to ``T_b`` in the common (base) frame:
    ``[p_a - p_b, log(R_a R_b^T)]`` (mm, rad)."""
    dR = T_a[..., :3, :3] @ jnp.swapaxes(T_b[..., :3, :3], -1, -2)
    return jnp.concatenate([T_a[..., :3, 3] - T_b[..., :3, 3], so3_log(dR)], -1)


def error_twist_matrix(robot: Robot, q: Float[Array, "*b n"], delta: Float[Array, "n 4"]) -> Float[Array, "*b 4 4"]:
    """Paper eq. (10), literally: ``dT T^{-1} = sum_i T_i Omega_i T_i^{-1}`` with
    ``Omega_i = sum_k Omega_{i,k} delta_{i,k}`` and ``T_i = base A_1 ... A_i``."""
    frames = fk_frames(robot, q)
    p = joint_dh(robot, q)
    om = OMEGAS[robot.convention](p[..., 0], p[..., 1], p[..., 2], p[..., 3])  # (..., n, 4, 4, 4)
    omega_i = jnp.einsum("...nkij,nk->...nij", om, delta)
    return jnp.sum(frames @ omega_i @ inv_transform(frames), axis=-3)


def _sparse_cross(u, v):
    """``u x v`` for 3-lists whose entries may be structural zeros (:func:`jaxcal._chain.is_zero`)."""

    def mul(x, y):
        return 0.0 if is_zero(x) or is_zero(y) else x * y

    def sub(x, y):
        return x if is_zero(y) else -y if is_zero(x) else x - y

    return [sub(mul(u[i], v[j]), mul(u[j], v[i])) for i, j in ((1, 2), (2, 0), (0, 1))]


def _add(x, y):
    return x if is_zero(y) else y if is_zero(x) else x + y


def dh_column_entries(robot: Robot, q: Float[Array, "*b n"], points):
    """The DH columns of eq. (10) entry by entry, and the tool pose, from one pass over the chain.

    The frames ``T_i = (R_i, t_i)`` come from :func:`jaxcal._chain.chain`; then every column as
    elementwise expressions over ``(n links, K poses)``, the links' structural zeros skipped
    (:func:`jaxcal.derivatives.omega_twist_entries`): the spatial twist of joint ``i``'s error
    ``k`` is ``Ad(T_i) vee(Omega_k) = [R_i v + t_i x R_i w; R_i w]``, and a point ``p`` fixed to
    the tool moves by ``dp = R_i v + R_i w x (p - t_i)``; ``points=None`` gives the twists
    themselves (``p = 0``). A caller stacks the entries once into the layout it needs: XLA then
    writes the Jacobian in one pass, where dense intermediate blocks and their concatenations and
    transposes cost more than the kinematics.

    **Returns** ``(P, W, R_e, p_e, p_pts)``: ``P[k][j]`` the 3 position rows of point ``j`` and
    ``W[k]`` the 3 rotation rows for error kind ``k`` (``theta, d, a, alpha``), each entry an
    array broadcastable to ``(n, K)`` or the Python float ``0.0``; the tool rotation ``(3, 3, K)``,
    position ``(3, K)`` and the points ``(M, 3, K)``, all in the measurement frame.

    A joint-frame robot's columns come from :func:`jaxcal._joints.joint_column_entries`, in the
    same form with seven kinds.
    """
    if robot.convention == "joint":
        return joint_column_entries(robot, q, points)
    c, s, d = link_inputs(robot, q)
    R_n, t_n, F = chain(robot, (c, s, d), frames=True)  # F: (n, 12, K)
    K = t_n.shape[1]
    F = jnp.swapaxes(F, 0, 1)  # (12, n, K)
    R = [[F[3 * r + j] for j in range(3)] for r in range(3)]
    t = [F[9 + r] for r in range(3)]
    R_e = matmul_soa(R_n, jnp.broadcast_to(robot.tool[:3, :3, None], R_n.shape))
    p_e = rotate_soa(R_n, jnp.broadcast_to(robot.tool[:3, 3, None], (3, K))) + t_n
    if points is None:
        pts = jnp.zeros((1, 3, K))
        levers = [[-t[r] for r in range(3)]]
    else:
        pts = jnp.stack([rotate_soa(R_e, jnp.broadcast_to(pt[:, None], (3, K))) + p_e for pt in points])
        levers = [[pt[r][None] - t[r] for r in range(3)] for pt in pts]
    P, W = [], []
    for v, w in omega_twist_entries(robot.convention, c, s, d, robot.dh[:, 2:3], robot.dh[:, 3:4]):
        w_s, v_s = [dot3(R[r], w) for r in range(3)], [dot3(R[r], v) for r in range(3)]
        P.append([[_add(a, b) for a, b in zip(v_s, _sparse_cross(w_s, lev))] for lev in levers])
        W.append(w_s)
    return P, W, R_e, p_e, pts


def stack_columns(kinds, n: int, K: int):
    """Entries ``kinds[k][r]`` (``k`` the error kind, ``r`` a row) as ``(p n, rows, K)`` for ``p``
    kinds: column ``p i + k`` is joint ``i``'s error ``k``."""
    blocks = [jnp.stack([jnp.broadcast_to(e, (n, K)) for e in rows], 1) for rows in kinds]  # (n, rows, K)
    return jnp.stack(blocks, 1).reshape(len(kinds) * n, len(kinds[0]), K)


def _dh_columns(robot: Robot, q, points):
    """:func:`dh_column_entries` stacked: ``P (M, 3, 4n, K)``, ``W (3, 4n, K)``, ``R_e``, ``p_e``."""
    P, W, R_e, p_e, _ = dh_column_entries(robot, q, points)
    n, K = robot.n_joints, p_e.shape[1]
    kinds = range(robot.n_kinds)
    Ps = jnp.stack([jnp.swapaxes(stack_columns([P[k][j] for k in kinds], n, K), 0, 1) for j in range(len(P[0]))])
    return Ps, jnp.swapaxes(stack_columns(W, n, K), 0, 1), R_e, p_e


def _frame_columns(R_e, p_e, t_B, *, base: bool, tool: bool, pose_rows: bool):
    """Base and tool column blocks, each ``(K, 6, 6)``, from the end rotation ``R_e (K, 3, 3)``
    (tool included), end position ``p_e (K, 3)`` and base origin ``t_B (3,)`` (module
    docstring: the base turns about its origin, the tool in its own frame)."""
    K = p_e.shape[0]
    eye, z3 = jnp.broadcast_to(jnp.eye(3), (K, 3, 3)), jnp.zeros((K, 3, 3))
    cols = []
    if base:  # pose rows: dp = v + w x (p - t_B); twist rows: [v + t_B x w; w]
        rot_dp = -skew(p_e - t_B) if pose_rows else jnp.broadcast_to(skew(t_B), (K, 3, 3))
        cols.append(jnp.concatenate([jnp.concatenate([eye, rot_dp], 2), jnp.concatenate([z3, eye], 2)], 1))
    if tool:  # twists [R e_j; 0] and [p x R e_j; R e_j]; pose rows: [R e_j; 0] and [0; R e_j]
        about_v = z3 if pose_rows else jnp.cross(p_e[:, :, None], R_e, axisa=1, axisb=1, axisc=1)
        cols.append(jnp.concatenate([jnp.concatenate([R_e, about_v], 2), jnp.concatenate([z3, R_e], 2)], 1))
    return cols


def _columns(robot: Robot, q, *, base: bool, tool: bool, pose_rows: bool, rows: int = 6, with_pose: bool = False):
    """The analytic Jacobian ``(*b, rows, m)`` (and, ``with_pose``, the end pose ``(*b, 4, 4)``
    from the same chain, so a solver needing both does not run the chain twice)."""
    # twists are the position rows of the point at the origin: v_s = R v + t x R w
    P, W, R_e, p_e = _dh_columns(robot, q, jnp.zeros((1, 3)) if pose_rows else None)
    J = jnp.moveaxis(jnp.concatenate([P[0], W])[:rows], -1, 0)  # (K, rows, 4n)
    R_e, p_e = jnp.moveaxis(R_e, -1, 0), p_e.T
    if base or tool:
        fc = _frame_columns(R_e, p_e, robot.base[:3, 3], base=base, tool=tool, pose_rows=pose_rows)
        J = jnp.concatenate([J] + [f[:, :rows] for f in fc], -1)
    J = J.reshape(q.shape[:-1] + J.shape[1:])
    if with_pose:
        return J, make_transform(R_e, p_e).reshape(q.shape[:-1] + (4, 4))
    return J


def twist_jacobian(
    robot: Robot, q: Float[Array, "*b n"], *, base: bool = False, tool: bool = False
) -> Float[Array, "*b 6 m"]:
    """Analytic adjoint form of eq. (10): columns ``Ad(T_i) vee(Omega_k)`` (spatial twists
    ``[v, w]`` of ``dT T^{-1}``), plus base and tool twist columns when asked. Jit-compiled."""
    return _twist_jacobian(robot.stripped(), check_q(robot, q), base=base, tool=tool)


@eqx.filter_jit
def _twist_jacobian(robot: Robot, q, *, base: bool, tool: bool):
    return _columns(robot, q, base=base, tool=tool, pose_rows=False)


def twist_to_pose_rows(J_twist: Float[Array, "*b 6 m"], p_end: Float[Array, "*b 3"]) -> Float[Array, "*b 6 m"]:
    """Spatial twist columns -> first-order change of end position and orientation:
    ``dp = v + w x p_end = v - skew(p_end) w``, ``dr = w``."""
    v, w = J_twist[..., :3, :], J_twist[..., 3:, :]
    return jnp.concatenate([v + jnp.cross(w, p_end[..., :, None], axisa=-2, axisb=-2, axisc=-2), w], -2)


def identification_jacobian(
    robot: Robot, q: Float[Array, "*b n"], *, position_only: bool = False, base: bool = False, tool: bool = False
) -> Float[Array, "*b r m"]:
    """Identification Jacobian: ``d pose_error(T(x), T(0)) / dx`` at ``x = 0``.

    Rows: 3 position (mm) then 3 rotation (rad) per pose, in the base/measurement frame; only
    the 3 position rows with ``position_only=True``. Columns: see the module docstring.
    Jit-compiled (per robot structure, ``q`` shape and options).
    """
    return _identification_jacobian(
        robot.stripped(), check_q(robot, q), position_only=position_only, base=base, tool=tool
    )


@eqx.filter_jit
def _identification_jacobian(robot: Robot, q, *, position_only: bool, base: bool, tool: bool):
    return _columns(robot, q, base=base, tool=tool, pose_rows=True, rows=3 if position_only else 6)


def jacobian_and_fk(
    robot: Robot, q: Float[Array, "*b n"], *, position_only: bool = False, base: bool = False, tool: bool = False
) -> tuple[Float[Array, "*b r m"], Float[Array, "*b 4 4"]]:
    """``(identification_jacobian(robot, q, ...), fk(robot, q))`` from one pass over the chain
    (what a Gauss–Newton step needs, instead of running the chain twice). Jit-compiled."""
    return _jacobian_and_fk(robot.stripped(), check_q(robot, q), position_only=position_only, base=base, tool=tool)


@eqx.filter_jit
def _jacobian_and_fk(robot: Robot, q, *, position_only: bool, base: bool, tool: bool):
    return _columns(robot, q, base=base, tool=tool, pose_rows=True, rows=3 if position_only else 6, with_pose=True)


def point_jacobian_soa(robot: Robot, q: Float[Array, "K n"], points: Float[Array, "M 3"]):
    """:func:`point_jacobian` with the pose axis last: ``P (M, 3, 4n, K)``, ``W (3, 4n, K)``, the
    tool rotation ``(3, 3, K)`` and position ``(3, K)``."""
    return _dh_columns(robot, q, points)


def point_jacobian(robot: Robot, q: Float[Array, "K n"], points: Float[Array, "M 3"]):
    """DH columns for points fixed to the tool frame, and the tool pose, from one pass.

    **Arguments**: ``q`` ``(K, n)``; ``points`` ``(M, 3)`` in the tool frame (static count).

    **Returns** ``(P, W, T)``: ``P (K, M, 3, 4n)`` the first-order motion of each point in the
    measurement frame per DH error, ``W (K, 3, 4n)`` the tool's rotation (a rotation vector in
    the measurement frame), ``T (K, 4, 4)`` the tool pose. With ``points = [[0, 0, 0]]``,
    ``[P[:, 0]; W]`` is :func:`identification_jacobian` without frame columns.
    """
    P, W, R_e, p_e = _dh_columns(robot, q, points)
    return (jnp.moveaxis(P, -1, 0), jnp.moveaxis(W, -1, 0), make_transform(jnp.moveaxis(R_e, -1, 0), p_e.T))
