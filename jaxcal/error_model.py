"""The differential error model (paper eq. 8-10) and the identification Jacobian.

Parameters are laid out as one flat vector ``x``::

    x = [dtheta_1, dd_1, da_1, dalpha_1, ..., dtheta_n, ..., dalpha_n,   # 4n DH errors
         base twist (6, optional), tool twist (6, optional)]

Base and tool errors are twists ``[v, w]`` applied as ``base <- exp(xi_b) base`` (left, in the
measurement frame) and ``tool <- tool exp(xi_t)`` (right, in the tool frame); see
:func:`perturb`.

Two error representations are provided:

* the paper's 4x4 error matrix ``dT T^{-1} = sum_i T_i Omega_i T_i^{-1}`` (eq. 10), computed
  literally by :func:`error_twist_matrix`;
* its analytic adjoint form: column ``k`` of joint ``i`` is ``Ad(T_i) vee(Omega_k)``
  (:func:`twist_jacobian`), and the identification Jacobian (:func:`identification_jacobian`)
  maps ``x`` to the first-order change of the end *position* (3 rows) and *orientation*
  (3 rows, a rotation vector), both in the measurement (base) frame. Position rows are
  ``dp = v + w x p_end``.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .derivatives import OMEGAS, omega_twists_soa
from .kinematics import _chain, check_q, cross_soa, fk_frames, joint_dh, matmul_soa, rotate_soa
from .lie import inv_transform, se3_exp, so3_log
from .robot import DH_NAMES, Robot

FRAME_NAMES = ("x", "y", "z", "rx", "ry", "rz")


def n_params(robot: Robot, *, base: bool = False, tool: bool = False) -> int:
    return 4 * robot.n_joints + 6 * base + 6 * tool


def param_names(robot: Robot, *, base: bool = False, tool: bool = False) -> list[str]:
    names = [f"{p}{i + 1}" for i in range(robot.n_joints) for p in DH_NAMES]
    names += [f"base_{c}" for c in FRAME_NAMES] if base else []
    names += [f"tool_{c}" for c in FRAME_NAMES] if tool else []
    return names


def perturb(robot: Robot, x: Float[Array, "m"], *, base: bool = False, tool: bool = False) -> Robot:
    """The robot with parameter errors ``x`` applied (exactly, not to first order)."""
    m = n_params(robot, base=base, tool=tool)
    if jnp.ndim(x) != 1 or jnp.shape(x)[0] != m:
        from .errors import DataError

        raise DataError(f"x must have shape ({m},) = {robot.n_joints} joints x 4 DH errors"
                        f"{' + 6 base' if base else ''}{' + 6 tool' if tool else ''}, got {jnp.shape(x)}")
    n4 = 4 * robot.n_joints
    out = robot.with_dh_delta(x[:n4].reshape(robot.n_joints, 4))
    k = n4
    new_base, new_tool = out.base, out.tool
    if base:
        new_base = se3_exp(x[k:k + 6]) @ robot.base
        k += 6
    if tool:
        new_tool = robot.tool @ se3_exp(x[k:k + 6])
    if base or tool:
        import equinox as eqx

        out = eqx.tree_at(lambda r: (r.base, r.tool), out, (new_base, new_tool))
    return out


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


def twist_jacobian(robot: Robot, q: Float[Array, "*b n"], *, base: bool = False,
                   tool: bool = False) -> Float[Array, "*b 6 m"]:
    """Analytic adjoint form of eq. (10): columns ``Ad(T_i) vee(Omega_k)`` (spatial twists
    ``[v, w]`` of ``dT T^{-1}``), plus base and tool twist columns when asked. Jit-compiled."""
    return _twist_jacobian(robot, check_q(robot, q), base=base, tool=tool)


def _columns(robot: Robot, q, *, base: bool, tool: bool, pose_rows: bool, rows: int = 6):
    """The analytic Jacobian, structure-of-arrays (pose axis last, the layout
    :func:`jaxcal.kinematics._chain` explains), transposed once at the end into
    ``(*b, rows, m)``. The spatial twists ``Ad(T_i) vee(Omega_k) = [R v + p x R w; R w]`` of
    each joint are formed inside the loop over links; pose rows add ``w x p_end`` after it."""
    def spatial_twists(R, t, x):
        V, W = omega_twists_soa(robot.convention, *x)  # (4, 3, K)
        w_s = rotate_soa(R, W)
        v_s = rotate_soa(R, V) + cross_soa(jnp.broadcast_to(t, w_s.shape), w_s)
        return jnp.concatenate([v_s, w_s], 1).reshape(24, -1)

    R_n, t_n, Y = _chain(robot, q, frames=True, per_link=spatial_twists)  # Y: (n, 12 + 24, K)
    n, K = robot.n_joints, t_n.shape[1]
    tw = Y[:, 12:].reshape(4 * n, 6, K)
    p_e = rotate_soa(R_n, jnp.broadcast_to(robot.tool[:3, 3, None], (3, K))) + t_n  # end (tool) position
    cols = [tw]
    if base:  # unit twists in the measurement frame itself
        cols.append(jnp.broadcast_to(jnp.eye(6)[:, :, None], (6, 6, K)))
    if tool:  # unit twists in the tool frame: Ad(T_end) e_j, from the columns of R_end
        R_e = matmul_soa(R_n, jnp.broadcast_to(robot.tool[:3, :3, None], R_n.shape))
        Rc = jnp.swapaxes(R_e, 0, 1)  # (3 columns, 3 rows, K)
        z = jnp.zeros_like(Rc)
        along = jnp.concatenate([Rc, z], 1)  # translations: [R e_j; 0]
        about = jnp.concatenate([cross_soa(jnp.broadcast_to(p_e, Rc.shape), Rc), Rc], 1)  # [p x R e_j; R e_j]
        cols += [along, about]
    J = jnp.concatenate(cols, 0)  # (m, 6, K)
    if pose_rows:  # dp = v + w x p_end
        J = jnp.concatenate([J[:, :3] + cross_soa(J[:, 3:], jnp.broadcast_to(p_e, J[:, 3:].shape)), J[:, 3:]], 1)
    J = jnp.transpose(J[:, :rows], (2, 1, 0))  # (K, rows, m)
    return J.reshape(q.shape[:-1] + J.shape[1:])


@eqx.filter_jit
def _twist_jacobian(robot: Robot, q, *, base: bool, tool: bool):
    return _columns(robot, q, base=base, tool=tool, pose_rows=False)


def twist_to_pose_rows(J_twist: Float[Array, "*b 6 m"], p_end: Float[Array, "*b 3"]) -> Float[Array, "*b 6 m"]:
    """Spatial twist columns -> first-order change of end position and orientation:
    ``dp = v + w x p_end = v - skew(p_end) w``, ``dr = w``."""
    v, w = J_twist[..., :3, :], J_twist[..., 3:, :]
    return jnp.concatenate([v + jnp.cross(w, p_end[..., :, None], axisa=-2, axisb=-2, axisc=-2), w], -2)


def identification_jacobian(robot: Robot, q: Float[Array, "*b n"], *, position_only: bool = False,
                            base: bool = False, tool: bool = False) -> Float[Array, "*b r m"]:
    """Identification Jacobian: ``d pose_error(T(x), T(0)) / dx`` at ``x = 0``.

    Rows: 3 position (mm) then 3 rotation (rad) per pose, in the base/measurement frame; only
    the 3 position rows with ``position_only=True``. Columns: see the module docstring.
    Jit-compiled (per robot structure, ``q`` shape and options).
    """
    return _identification_jacobian(robot, check_q(robot, q), position_only=position_only, base=base, tool=tool)


@eqx.filter_jit
def _identification_jacobian(robot: Robot, q, *, position_only: bool, base: bool, tool: bool):
    return _columns(robot, q, base=base, tool=tool, pose_rows=True, rows=3 if position_only else 6)
