"""The measurement model's residual with an analytic JVP, used by the optimistix solvers.

:func:`make_residual` returns ``w * pose_error(measured, T(x, q))`` with a ``jax.custom_jvp``
whose tangent comes from the analytic identification Jacobian (eq. 10, adjoint form), so
optimistix never differentiates through forward kinematics (JAX-NOTES: ~4x faster; measured
4.3x in ``benchmarks/bench_gn_batch.py``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..error_model import jacobian_and_fk, perturb, pose_error
from ..kinematics import fk
from ..lie import so3_right_jacobian_inv
from ..robot import Robot


def row_weights(position_only: bool, sigma_pos: float, sigma_rot: float):
    w = jnp.array([1.0 / sigma_pos] * 3 + [1.0 / sigma_rot] * 3)
    return w[:3] if position_only else w


def make_residual(robot: Robot, *, base: bool, tool: bool, position_only: bool, weights):
    """``r(x, q, measured)``: weighted residual rows ``w * pose_error(measured, T(x, q))``
    flattened, with a ``jax.custom_jvp`` whose tangent is ``J_r(x) @ dx``.

    ``J_r`` is built from the analytic identification Jacobian of the current model (eq. 10):
    position rows ``-J_pos``; rotation rows ``-Jr^{-1}(phi) J_rot`` where ``phi`` is the current
    rotation residual (exact derivative of ``log(R_m R^T)``). Base and tool columns are
    local twists at the current frames, i.e. the exact Jacobian times an invertible matrix
    acting on those columns: Gauss–Newton steps differ, the fixed point does not.
    """
    def error(x, q, measured):
        return pose_error(measured, fk(perturb(robot, x, base=base, tool=tool), q))

    def finish(e):
        if position_only:
            e = e[..., :3]
        return (e * weights).reshape(-1)

    @jax.custom_jvp
    def residual(x, q, measured):
        return finish(error(x, q, measured))

    @residual.defjvp
    def residual_jvp(primals, tangents):
        x, q, measured = primals
        dx = tangents[0]  # not differentiable with respect to q or the measurements (data)
        cal = perturb(robot, x, base=base, tool=tool)
        J, T = jacobian_and_fk(cal, q, base=base, tool=tool, position_only=position_only)  # one pass over the chain
        e = pose_error(measured, T)
        # the residual's Jacobian, formed in the primal (elementwise; a batch of 3x3 @ 3xm
        # matmuls per pose was the slow part), so the tangent is one matrix-vector product:
        # optimistix materialises it by pushing every basis vector through.
        rows = J[..., :3, :]
        if not position_only:
            A = so3_right_jacobian_inv(e[..., 3:])
            rot = sum(A[..., :, j, None] * J[..., None, 3 + j, :] for j in range(3))
            rows = jnp.concatenate([rows, rot], -2)
        Jr = (-rows * weights[:, None]).reshape(-1, rows.shape[-1])
        return finish(e), Jr @ dx

    return residual
