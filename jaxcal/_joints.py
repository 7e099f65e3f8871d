"""Forward kinematics and identification columns of joint-frame robots (URDF chains).

Link ``i`` is ``O_i E_i M_i(q_i + offset_i)`` (:class:`jaxcal.Robot`, ``convention="joint"``).
The chain is one ``lax.scan`` over the joints on ``(K, 4, 4)`` transforms; the columns are the
geometric Jacobian of each joint's seven parameters, exact at any parameter value:

* the offset turns the rest of the chain about (or shifts it along) the joint's axis
  ``u = R_F a`` through ``F_i = G_{i-1} O_i E_i``: a point moves by ``u x (p - t_F)`` (or ``u``);
* the translation ``t_i`` of the correction moves it by ``R_H dt`` (``H_i = G_{i-1} O_i``);
* the rotation vector ``r_i`` turns it about ``t_F`` by ``R_F J_r(r_i) dr``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .lie import make_transform, so3_exp, so3_left_jacobian
from .robot import Robot


def _corrections(robot: Robot):
    """``O_i E_i`` for every joint ``(n, 4, 4)``."""
    E = make_transform(so3_exp(robot.dh[:, 4:7]), robot.dh[:, 1:4])
    return robot.origins @ E


def _motion(axis, value, turn):
    """``M(value)``: a turn about (``turn`` 1) or a shift along (``turn`` 0) the unit ``axis``;
    ``value`` of any shape, the transforms ``(*value.shape, 4, 4)``."""
    v = value[..., None]
    return make_transform(so3_exp(axis * v * turn), axis * v * (1.0 - turn))


def joint_chain(robot: Robot, q: Float[Array, "K n"]):
    """``(F (n, K, 4, 4), R_H (n, K, 3, 3), G (K, 4, 4))``: each joint's frame before its motion
    (correction applied), the rotation before the correction, and ``base O_1 E_1 M_1 ... M_n``."""
    K = q.shape[0]
    OE = _corrections(robot)
    rev = robot.revolute_mask
    val = q.T.astype(jnp.float64) + robot.dh[:, 0:1]  # (n, K): joint value with its offset

    def step(G, xs):
        OE_i, O_i, a_i, r_i, v_i = xs
        F = G @ OE_i
        R_H = G[:, :3, :3] @ O_i[:3, :3]
        return F @ _motion(a_i, v_i, r_i), (F, R_H)

    G0 = jnp.broadcast_to(robot.base, (K, 4, 4))
    G, (F, R_H) = jax.lax.scan(step, G0, (OE, robot.origins, robot.axes, rev, val))
    return F, R_H, G


def joint_fk(robot: Robot, q: Float[Array, "K n"]) -> Float[Array, "K 4 4"]:
    """End pose ``base ... @ tool`` of a joint-frame robot."""
    return joint_chain(robot, q)[2] @ robot.tool


def joint_frames_after(robot: Robot, q: Float[Array, "K n"]) -> Float[Array, "K n 4 4"]:
    """Each joint's frame after its motion (the child link's frame)."""
    F, _, _ = joint_chain(robot, q)
    val = q.T + robot.dh[:, 0:1]  # (n, K)
    M = _motion(robot.axes[:, None, :], val, robot.revolute_mask[:, None, None])
    return jnp.swapaxes(F @ M, 0, 1)


def joint_column_entries(robot: Robot, q: Float[Array, "K n"], points):
    """The columns of the seven parameters of every joint, in the form of
    :func:`jaxcal.error_model.dh_column_entries`: ``(P, W, R_e, p_e, p_pts)`` with ``P[k][j]``
    the 3 position rows of point ``j`` and ``W[k]`` the 3 rotation rows for parameter kind ``k``
    (:data:`jaxcal.robot.JOINT_FRAME_NAMES`), each ``(n, K)``; the tool rotation ``(3, 3, K)``,
    position ``(3, K)`` and the points ``(M, 3, K)`` in the measurement frame. ``points=None``
    gives the twists (the point at the origin)."""
    q = jnp.reshape(q, (-1, robot.n_joints))
    F, R_H, G = joint_chain(robot, q)
    T = G @ robot.tool
    R_e, p_e = T[:, :3, :3], T[:, :3, 3]
    pts = jnp.zeros((1, 3)) if points is None else points
    p = p_e[None] + jnp.einsum("kij,mj->mki", R_e, pts)  # (M, K, 3)
    if points is None:
        p = jnp.zeros_like(p)
    R_F, t_F = F[..., :3, :3], F[..., :3, 3]  # (n, K, 3, 3), (n, K, 3)
    lever = p[:, None] - t_F[None]  # (M, n, K, 3)
    rev = robot.revolute_mask[:, None, None]  # (n, 1, 1)
    u = jnp.einsum("nkij,nj->nki", R_F, robot.axes)  # the joint axes in the measurement frame
    dirs = [(u, rev)]  # (axis, 1 for a turn / 0 for a shift)
    dirs += [(R_H[..., :, c], None) for c in range(3)]
    J_r = jnp.swapaxes(so3_left_jacobian(robot.dh[:, 4:7]), -1, -2)  # right Jacobian, (n, 3, 3)
    dirs += [(jnp.einsum("nkij,nj->nki", R_F, J_r[:, :, c]), 1.0) for c in range(3)]
    P, W = [], []
    for w, turn in dirs:
        if turn is None:  # a shift
            pos = jnp.broadcast_to(w[None], lever.shape)
            rot = None
        else:
            pos = turn * jnp.cross(w[None], lever) + (1.0 - turn) * w[None]
            rot = turn * w
        P.append([[pos[j, ..., r] for r in range(3)] for j in range(pos.shape[0])])
        W.append([0.0] * 3 if rot is None else [rot[..., r] for r in range(3)])
    return P, W, jnp.moveaxis(R_e, 0, -1), p_e.T, jnp.moveaxis(p, 1, -1)
