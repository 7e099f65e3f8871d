"""The measurement model as a function of the parameter vector, with an analytic JVP.

``pose_model(robot, base, tool)(x, q)`` returns ``base' @ A_1..A_n(dh + dx) @ tool'`` where the
DH chain has a ``jax.custom_jvp`` whose tangent is ``hat(J_twist @ d_dh) @ T`` (eq. 10, the
analytic adjoint form), so optimistix never differentiates through forward kinematics
(JAX-NOTES: ~4x faster). Base and tool twists go through ``exp`` by ordinary autodiff (cheap,
and exact away from zero).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from ..error_model import pose_error, twist_jacobian
from ..kinematics import fk
from ..lie import compose, hat, matmul4, se3_exp
from ..robot import Robot


def _chain(template: Robot):
    """``(dh, q) -> A_1..A_n`` for a template robot with identity base and tool."""

    @jax.custom_jvp
    def chain(dh, q):
        return fk(eqx.tree_at(lambda r: r.dh, template, dh), q)

    @chain.defjvp
    def chain_jvp(primals, tangents):
        dh, q = primals
        ddh, _ = tangents  # not differentiable with respect to q (data)
        r = eqx.tree_at(lambda r: r.dh, template, dh)
        T = fk(r, q)
        tw = twist_jacobian(r, q) @ ddh.reshape(-1)
        return T, matmul4(hat(tw), T)

    return chain


def pose_model(robot: Robot, *, base: bool, tool: bool):
    """``f(x, q) -> (..., 4, 4)``: exact poses of ``perturb(robot, x)`` (same layout as
    :func:`jaxcal.error_model.perturb`), differentiable in ``x`` with an analytic JVP."""
    template = eqx.tree_at(lambda r: (r.base, r.tool), robot, (jnp.eye(4), jnp.eye(4)))
    chain = _chain(template)
    n4 = 4 * robot.n_joints

    def f(x, q):
        T = chain(robot.dh + x[:n4].reshape(robot.n_joints, 4), q)
        k = n4
        B, Tl = robot.base, robot.tool
        if base:
            B = se3_exp(x[k:k + 6]) @ B
            k += 6
        if tool:
            Tl = Tl @ se3_exp(x[k:k + 6])
        return compose(compose(B, T), Tl)

    return f


def weighted_residual(model, x, q, measured, weights, position_only: bool):
    """Rows ``w * pose_error(measured, model(x, q))`` flattened: 3 (position) or 6 per pose."""
    e = pose_error(measured, model(x, q))
    if position_only:
        e = e[..., :3]
    return (e * weights).reshape(-1)


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
    from ..error_model import identification_jacobian, perturb
    from ..lie import so3_right_jacobian_inv

    def parts(x, q, measured):
        cal = perturb(robot, x, base=base, tool=tool)
        e = pose_error(measured, fk(cal, q))
        return cal, e

    def finish(e):
        if position_only:
            e = e[..., :3]
        return (e * weights).reshape(-1)

    @jax.custom_jvp
    def residual(x, q, measured):
        return finish(parts(x, q, measured)[1])

    @residual.defjvp
    def residual_jvp(primals, tangents):
        x, q, measured = primals
        dx = tangents[0]  # not differentiable with respect to q or the measurements (data)
        cal, e = parts(x, q, measured)
        J = identification_jacobian(cal, q, base=base, tool=tool)
        dpos = -(J[..., :3, :] @ dx)
        if position_only:
            de = dpos
        else:
            drot = -(so3_right_jacobian_inv(e[..., 3:]) @ (J[..., 3:, :] @ dx)[..., None])[..., 0]
            de = jnp.concatenate([dpos, drot], -1)
        return finish(e), (de * weights).reshape(-1)

    return residual
