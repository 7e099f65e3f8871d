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

The identification Jacobian runs the native kernel (:mod:`jaxcal._native`) on the CPU when it
is available, with :func:`_columns_xla` as its pure-JAX reference and fallback.
"""

from __future__ import annotations

from functools import partial

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from . import _native
from .derivatives import OMEGAS, omega_twist_entries
from .kinematics import _chain, _dot3, check_q, fk_frames, is_zero, joint_dh, link_inputs, matmul_soa, rotate_soa
from .lie import inv_transform, make_transform, se3_exp, so3_log
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


def _sparse_cross(u, v):
    """``u x v`` for 3-lists whose entries may be structural zeros (:func:`is_zero`)."""
    def mul(x, y):
        return 0.0 if is_zero(x) or is_zero(y) else x * y

    def sub(x, y):
        return x if is_zero(y) else -y if is_zero(x) else x - y

    return [sub(mul(u[i], v[j]), mul(u[j], v[i])) for i, j in ((1, 2), (2, 0), (0, 1))]


def _frame_columns(R_e, p_e, *, base: bool, tool: bool, pose_rows: bool):
    """Base and tool column blocks, each ``(K, 6, 6)``, from the end rotation ``R_e (K, 3, 3)``
    (tool included) and end position ``p_e (K, 3)``: base twists are unit twists in the
    measurement frame, tool twists unit twists in the tool frame, ``Ad(T_end) e_j``."""
    K = p_e.shape[0]
    eye, z3 = jnp.broadcast_to(jnp.eye(3), (K, 3, 3)), jnp.zeros((K, 3, 3))
    cols = []
    if base:  # twist rows [e_j; 0] and [0; e_j]; pose rows add w x p_end = e_j x p = -(p x e_j)
        rot_dp = -jnp.cross(p_e[:, :, None], eye, axisa=1, axisb=1, axisc=1) if pose_rows else z3
        cols.append(jnp.concatenate([jnp.concatenate([eye, rot_dp], 2), jnp.concatenate([z3, eye], 2)], 1))
    if tool:  # twists [R e_j; 0] and [p x R e_j; R e_j]; pose rows: [R e_j; 0] and [0; R e_j]
        about_v = z3 if pose_rows else jnp.cross(p_e[:, :, None], R_e, axisa=1, axisb=1, axisc=1)
        cols.append(jnp.concatenate([jnp.concatenate([R_e, about_v], 2), jnp.concatenate([z3, R_e], 2)], 1))
    return cols


def _columns(robot: Robot, q, *, base: bool, tool: bool, pose_rows: bool, rows: int = 6, with_pose: bool = False):
    """The analytic Jacobian (and, ``with_pose``, the end pose): :func:`_columns_xla`, or for
    pose rows the native kernel (:mod:`jaxcal._native`) when it is in use, with the base and
    tool columns added here from its end poses."""
    if not (pose_rows and _native.usable(robot)):
        return _columns_xla(robot, q, base=base, tool=tool, pose_rows=pose_rows, rows=rows, with_pose=with_pose)
    J, T = _jac_native(robot, jnp.reshape(q, (-1, robot.n_joints)).astype(jnp.float64), rows)
    if base or tool:
        fc = _frame_columns(T[:, :3, :3], T[:, :3, 3], base=base, tool=tool, pose_rows=True)
        J = jnp.concatenate([J] + [f[:, :rows] for f in fc], -1)
    J = J.reshape(q.shape[:-1] + J.shape[1:])
    if with_pose:
        return J, T.reshape(q.shape[:-1] + (4, 4))
    return J


@partial(jax.custom_jvp, nondiff_argnums=(2,))
def _jac_native(robot: Robot, q2, rows: int):
    return _native.jac_call(robot, q2, rows)


@_jac_native.defjvp
def _jac_native_jvp(rows, primals, tangents):  # derivatives (and their primal) from the pure-JAX form
    return jax.jvp(lambda r, q: _columns_xla(r, q, base=False, tool=False, pose_rows=True, rows=rows, with_pose=True),
                   primals, tangents)


def _columns_xla(robot: Robot, q, *, base: bool, tool: bool, pose_rows: bool, rows: int = 6, with_pose: bool = False):
    """The analytic Jacobian ``(*b, rows, m)`` (and, ``with_pose``, the end pose ``(*b, 4, 4)``
    from the same chain, so a solver needing both does not run the chain twice).

    Two passes: the frames ``T_i = (R_i, t_i)`` from the structure-of-arrays chain
    (:func:`jaxcal.kinematics._chain`, materialised once), then every column at once as
    elementwise expressions over ``(n links, K poses)``: the spatial twist of joint ``i``'s
    error ``k`` is ``Ad(T_i) vee(Omega_k) = [R_i v + t_i x R_i w; R_i w]``
    (:func:`jaxcal.derivatives.omega_twist_entries`, structural zeros skipped), and pose rows
    are ``dp = v_s + w_s x p_end = R_i v + R_i w x (p_end - t_i)``. Forming the twists inside
    the loop over links instead (the previous form) ran the Jacobian ~3x slower on 1e5 poses
    (``benchmarks/bench_roofline.py``).
    """
    n = robot.n_joints
    c, s, d = link_inputs(robot, q)
    R_n, t_n, F = _chain(robot, (c, s, d), frames=True)  # F: (n, 12, K)
    K = t_n.shape[1]
    F = jnp.swapaxes(F, 0, 1)  # (12, n, K)
    R = [[F[3 * r + j] for j in range(3)] for r in range(3)]
    t = [F[9 + r] for r in range(3)]
    p_e = rotate_soa(R_n, jnp.broadcast_to(robot.tool[:3, 3, None], (3, K))) + t_n  # end (tool) position
    lever = [p_e[r][None] - t[r] for r in range(3)]
    blocks = []
    for v, w in omega_twist_entries(robot.convention, c, s, d, robot.dh[:, 2:3], robot.dh[:, 3:4]):
        w_s, v_s = [_dot3(R[r], w) for r in range(3)], [_dot3(R[r], v) for r in range(3)]
        extra = _sparse_cross(w_s, lever) if pose_rows else _sparse_cross(t, w_s)
        rows_k = [x if is_zero(y) else y if is_zero(x) else x + y for x, y in zip(v_s, extra)] + w_s
        blocks.append(jnp.stack([jnp.broadcast_to(e, c.shape) for e in rows_k[:rows]]))
    J = jnp.transpose(jnp.stack(blocks), (3, 1, 2, 0)).reshape(K, rows, 4 * n)  # (K, rows, n, 4)
    if base or tool or with_pose:
        R_e = jnp.moveaxis(matmul_soa(R_n, jnp.broadcast_to(robot.tool[:3, :3, None], R_n.shape)), -1, 0)
    if base or tool:
        fc = _frame_columns(R_e, p_e.T, base=base, tool=tool, pose_rows=pose_rows)
        J = jnp.concatenate([J] + [f[:, :rows] for f in fc], -1)
    J = J.reshape(q.shape[:-1] + J.shape[1:])
    if with_pose:
        return J, make_transform(R_e, p_e.T).reshape(q.shape[:-1] + (4, 4))
    return J


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


def jacobian_and_fk(robot: Robot, q: Float[Array, "*b n"], *, position_only: bool = False, base: bool = False,
                    tool: bool = False) -> tuple[Float[Array, "*b r m"], Float[Array, "*b 4 4"]]:
    """``(identification_jacobian(robot, q, ...), fk(robot, q))`` from one pass over the chain
    (what a Gauss–Newton step needs, instead of running the chain twice). Jit-compiled."""
    return _jacobian_and_fk(robot, check_q(robot, q), position_only=position_only, base=base, tool=tool)


@eqx.filter_jit
def _jacobian_and_fk(robot: Robot, q, *, position_only: bool, base: bool, tool: bool):
    return _columns(robot, q, base=base, tool=tool, pose_rows=True, rows=3 if position_only else 6, with_pose=True)
