"""Small SE(3)/SO(3) helpers on 4x4 homogeneous matrices, built on :mod:`jaxlie`.

Twists are ordered ``[v, w]`` (translation, then rotation), like jaxlie's. Every function
broadcasts over leading axes.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import jaxlie
from jaxtyping import Array, Float


def skew(w: Float[Array, "*b 3"]) -> Float[Array, "*b 3 3"]:
    """``skew(w) @ x == cross(w, x)``."""
    z = jnp.zeros_like(w[..., 0])
    return jnp.stack(
        [
            jnp.stack([z, -w[..., 2], w[..., 1]], -1),
            jnp.stack([w[..., 2], z, -w[..., 0]], -1),
            jnp.stack([-w[..., 1], w[..., 0], z], -1),
        ],
        -2,
    )


def vee(m: Float[Array, "*b 4 4"]) -> Float[Array, "*b 6"]:
    """se(3) matrix ``[[skew(w), v], [0, 0]]`` -> twist ``[v, w]`` (antisymmetric part used)."""
    w = 0.5 * jnp.stack(
        [m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]],
        -1,
    )
    return jnp.concatenate([m[..., :3, 3], w], -1)


def hat(xi: Float[Array, "*b 6"]) -> Float[Array, "*b 4 4"]:
    """Twist ``[v, w]`` -> 4x4 se(3) matrix."""
    top = jnp.concatenate([skew(xi[..., 3:]), xi[..., :3, None]], -1)
    bottom = jnp.zeros(xi.shape[:-1] + (1, 4), xi.dtype)
    return jnp.concatenate([top, bottom], -2)


def make_transform(R: Float[Array, "*b 3 3"], p: Float[Array, "*b 3"]) -> Float[Array, "*b 4 4"]:
    top = jnp.concatenate([R, p[..., :, None]], -1)
    bottom = jnp.broadcast_to(jnp.array([0.0, 0.0, 0.0, 1.0], R.dtype), R.shape[:-2] + (1, 4))
    return jnp.concatenate([top, bottom], -2)


def inv_transform(T: Float[Array, "*b 4 4"]) -> Float[Array, "*b 4 4"]:
    """Inverse of a rigid transform, ``[R^T, -R^T p]``."""
    Rt = jnp.swapaxes(T[..., :3, :3], -1, -2)
    return make_transform(Rt, -jnp.einsum("...ij,...j->...i", Rt, T[..., :3, 3]))


def adjoint(T: Float[Array, "*b 4 4"]) -> Float[Array, "*b 6 6"]:
    """Adjoint of T acting on ``[v, w]`` twists: ``hat(Ad_T xi) == T hat(xi) T^-1``."""
    R, p = T[..., :3, :3], T[..., :3, 3]
    z = jnp.zeros_like(R)
    top = jnp.concatenate([R, skew(p) @ R], -1)
    return jnp.concatenate([top, jnp.concatenate([z, R], -1)], -2)


def se3_exp(xi: Float[Array, "*b 6"]) -> Float[Array, "*b 4 4"]:
    """Exponential map of a ``[v, w]`` twist."""
    return jaxlie.SE3.exp(xi).as_matrix()


def so3_log(R: Float[Array, "*b 3 3"]) -> Float[Array, "*b 3"]:
    """Rotation vector of a rotation matrix (differentiable at the identity)."""
    return jaxlie.SO3.from_matrix(R).log()


def rpy_to_matrix(rpy: Float[Array, "*b 3"]) -> Float[Array, "*b 3 3"]:
    """Roll-pitch-yaw about fixed axes x, y, z: ``R = Rz(yaw) Ry(pitch) Rx(roll)``."""
    rpy = jnp.asarray(rpy)
    fn = lambda r: jaxlie.SO3.from_rpy_radians(r[0], r[1], r[2]).as_matrix()
    for _ in range(rpy.ndim - 1):
        fn = jax.vmap(fn)
    return fn(rpy)


def matrix_to_rpy(R: Float[Array, "*b 3 3"]) -> Float[Array, "*b 3"]:
    """Inverse of :func:`rpy_to_matrix` (pitch in [-pi/2, pi/2])."""
    so3 = jaxlie.SO3.from_matrix(R)
    return jnp.stack([so3.compute_roll_radians(), so3.compute_pitch_radians(),
                      so3.compute_yaw_radians()], -1)


def xyz_rpy_to_transform(xyz, rpy) -> Float[Array, "4 4"]:
    return make_transform(rpy_to_matrix(jnp.asarray(rpy)), jnp.asarray(xyz))


def quat_to_matrix(q_wxyz: Float[Array, "*b 4"]) -> Float[Array, "*b 3 3"]:
    """Unit quaternion, scalar first -> rotation matrix."""
    return jaxlie.SO3(wxyz=q_wxyz).as_matrix()


def matrix_to_quat(R: Float[Array, "*b 3 3"]) -> Float[Array, "*b 4"]:
    """Rotation matrix -> unit quaternion, scalar first."""
    return jaxlie.SO3.from_matrix(R).wxyz


def so3_exp_matrix(w: Float[Array, "*b 3"]) -> Float[Array, "*b 3 3"]:
    """Rotation matrix of a rotation vector."""
    return jaxlie.SO3.exp(w).as_matrix()


def compose(A: Float[Array, "*b 4 4"], B: Float[Array, "*b 4 4"]) -> Float[Array, "*b 4 4"]:
    """``A @ B`` for rigid transforms (bottom rows ``0 0 0 1``), as broadcast multiply-adds.

    On CPU, XLA runs batched 4x4 ``matmul`` as many tiny GEMM calls; this elementwise form
    fuses into one loop and was 2.6x faster for forward kinematics.
    """
    top = (A[..., :3, :3, None] * B[..., None, :3, :]).sum(-2)
    top = top.at[..., :, 3].add(A[..., :3, 3])
    bottom = jnp.broadcast_to(jnp.array([0.0, 0.0, 0.0, 1.0], top.dtype), top.shape[:-2] + (1, 4))
    return jnp.concatenate([top, bottom], -2)


def so3_right_jacobian_inv(phi: Float[Array, "*b 3"]) -> Float[Array, "*b 3 3"]:
    """Inverse right Jacobian of SO(3): ``log(exp(phi) exp(d)) = phi + Jr^-1(phi) d + O(d^2)``.

    ``Jr^-1 = I + K/2 + c K^2`` with ``K = skew(phi)``, ``c = 1/t^2 - (1 + cos t)/(2 t sin t)``
    (``t = |phi|``), and the series ``c = 1/12 + t^2/720`` near ``t = 0``.
    """
    t2 = jnp.sum(phi * phi, -1)
    small = t2 < 1e-8
    t = jnp.sqrt(jnp.where(small, 1.0, t2))
    c_big = 1.0 / (t * t) - (1.0 + jnp.cos(t)) / (2.0 * t * jnp.sin(t))
    c = jnp.where(small, 1.0 / 12.0 + t2 / 720.0, c_big)
    K = skew(phi)
    return jnp.eye(3) + 0.5 * K + c[..., None, None] * (K @ K)
