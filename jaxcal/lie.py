"""SO(3)/SE(3) helpers on rotation matrices and 4x4 homogeneous transforms.

Twists are ordered ``[v, w]`` (translation, then rotation). Every function broadcasts over
leading axes. The rotation maps used inside fits (:func:`so3_exp`, :func:`so3_log`, the SO(3)
Jacobians) are closed forms written here rather than taken from jaxlie: they are a handful of
operations each, which keeps the compiled calibration small, and they accept NumPy arrays too
(evaluated by NumPy, nothing compiled), as do the roll-pitch-yaw and quaternion-to-matrix
conversions of the file formats. jaxlie serves the rest (matrix to quaternion, the SE(3)
exponential).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float


def _xp(a):
    return np if isinstance(a, (np.ndarray, np.generic)) else jnp


def skew(w: Float[Array, "*b 3"]) -> Float[Array, "*b 3 3"]:
    """``skew(w) @ x == cross(w, x)``."""
    xp = _xp(w)
    z = xp.zeros_like(w[..., 0])
    return xp.stack(
        [
            xp.stack([z, -w[..., 2], w[..., 1]], -1),
            xp.stack([w[..., 2], z, -w[..., 0]], -1),
            xp.stack([-w[..., 1], w[..., 0], z], -1),
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


def _series(t2, big, coeffs, where_small):
    """``big`` where the angle is not small, else the Taylor series ``sum c_k t2^k``."""
    xp = _xp(t2)
    small = coeffs[0] + t2 * (coeffs[1] + t2 * coeffs[2])
    return xp.where(where_small, small, big)


def _angle(w):
    xp = _xp(w)
    t2 = xp.sum(w * w, -1)
    small = t2 < 1e-6
    t = xp.sqrt(xp.where(small, 1.0, t2))
    return xp, t2, t, small


def so3_exp(w: Float[Array, "*b 3"]) -> Float[Array, "*b 3 3"]:
    """Rotation matrix of a rotation vector (Rodrigues)."""
    xp, t2, t, small = _angle(w)
    a = _series(t2, xp.sin(t) / t, (1.0, -1 / 6, 1 / 120), small)
    b = _series(t2, 2 * xp.sin(t / 2) ** 2 / (t * t), (0.5, -1 / 24, 1 / 720), small)
    K = skew(w)
    return xp.eye(3) + a[..., None, None] * K + b[..., None, None] * (K @ K)


def so3_left_jacobian(w: Float[Array, "*b 3"]) -> Float[Array, "*b 3 3"]:
    """``exp(w + d) = exp(J_l(w) d) exp(w)`` to first order; ``J_r(w) = J_l(w)^T``."""
    xp, t2, t, small = _angle(w)
    b = _series(t2, 2 * xp.sin(t / 2) ** 2 / (t * t), (0.5, -1 / 24, 1 / 720), small)
    c = _series(t2, (t - xp.sin(t)) / (t * t * t), (1 / 6, -1 / 120, 1 / 5040), small)
    K = skew(w)
    return xp.eye(3) + b[..., None, None] * K + c[..., None, None] * (K @ K)


def so3_log(R: Float[Array, "*b 3 3"]) -> Float[Array, "*b 3"]:
    """Rotation vector of a rotation matrix, accurate at every angle: from the antisymmetric part
    (``sin(angle) axis``) and the trace, and near half a turn, where that part vanishes, the
    axis from the symmetric part."""
    xp = _xp(R)
    s = 0.5 * xp.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    c = 0.5 * (R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0)
    ss = xp.sum(s * s, -1)
    pos = ss > 0
    sn = xp.where(pos, xp.sqrt(xp.where(pos, ss, 1.0)), 0.0)  # every branch kept finite, for derivatives
    theta = xp.arctan2(sn, c)
    near_zero = ss < 1e-14
    generic = xp.where(near_zero, 1.0 + theta * theta / 6.0, theta / xp.where(near_zero, 1.0, sn))[..., None] * s
    # near pi: (R + R^T)/2 - c I = (1 - c) a a^T; its largest diagonal entry gives a stable column
    near_pi = c < -0.99
    e0 = xp.asarray([[2.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    cp = xp.where(near_pi, c, -1.0)
    B = xp.where(near_pi[..., None, None], 0.5 * (R + xp.swapaxes(R, -1, -2)) - cp[..., None, None] * xp.eye(3), e0)
    d = xp.stack([B[..., 0, 0], B[..., 1, 1], B[..., 2, 2]], -1)
    pick = (xp.arange(3) == xp.argmax(d, -1)[..., None]).astype(R.dtype)
    col = xp.sum(B * pick[..., None, :], -1)
    dk = xp.sum(d * pick, -1, keepdims=True)
    a = col / xp.sqrt(dk * (1.0 - cp[..., None]))
    a = xp.where(xp.sum(a * s, -1, keepdims=True) < 0, -a, a)
    return xp.where(near_pi[..., None], theta[..., None] * a, generic)


def so3_right_jacobian_inv(phi: Float[Array, "*b 3"]) -> Float[Array, "*b 3 3"]:
    """Inverse right Jacobian of SO(3): ``log(exp(phi) exp(d)) = phi + Jr^-1(phi) d + O(d^2)``.

    ``Jr^-1 = I + K/2 + c K^2`` with ``K = skew(phi)``, ``c = 1/t^2 - (1 + cos t)/(2 t sin t)``
    (``t = |phi|``), and the series ``c = 1/12 + t^2/720`` near ``t = 0``.
    """
    xp = _xp(phi)
    t2 = xp.sum(phi * phi, -1)
    small = t2 < 1e-8
    t = xp.sqrt(xp.where(small, 1.0, t2))
    c_big = 1.0 / (t * t) - (1.0 + xp.cos(t)) / (2.0 * t * xp.sin(t))
    c = xp.where(small, 1.0 / 12.0 + t2 / 720.0, c_big)
    K = skew(phi)
    return xp.eye(3) + 0.5 * K + c[..., None, None] * (K @ K)


def se3_exp(xi: Float[Array, "*b 6"]) -> Float[Array, "*b 4 4"]:
    """Exponential map of a ``[v, w]`` twist."""
    import jaxlie  # imported when needed: it is slow to import and off the hot path

    return jaxlie.SE3.exp(xi).as_matrix()


def rpy_to_matrix(rpy: Float[Array, "*b 3"]) -> Float[Array, "*b 3 3"]:
    """Roll-pitch-yaw about fixed axes x, y, z: ``R = Rz(yaw) Ry(pitch) Rx(roll)``."""
    xp = _xp(rpy)
    s, c = xp.sin(rpy), xp.cos(rpy)
    sr, sp, sy = s[..., 0], s[..., 1], s[..., 2]
    cr, cp, cy = c[..., 0], c[..., 1], c[..., 2]
    rows = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    return xp.stack([xp.stack(r, -1) for r in rows], -2)


def matrix_to_rpy(R: Float[Array, "*b 3 3"]) -> Float[Array, "*b 3"]:
    """Inverse of :func:`rpy_to_matrix` (pitch in [-pi/2, pi/2]; at pitch +-pi/2, where only yaw
    -+ roll is defined, roll 0)."""
    xp = _xp(R)
    cp = xp.sqrt(R[..., 2, 1] ** 2 + R[..., 2, 2] ** 2)
    locked = cp < 1e-12
    pitch = xp.arctan2(-R[..., 2, 0], cp)
    roll = xp.where(locked, 0.0, xp.arctan2(R[..., 2, 1], R[..., 2, 2]))
    yaw = xp.where(locked, xp.arctan2(-R[..., 0, 1], R[..., 1, 1]), xp.arctan2(R[..., 1, 0], R[..., 0, 0]))
    return xp.stack([roll, pitch, yaw], -1)


def xyz_rpy_to_transform(xyz, rpy) -> Float[Array, "4 4"]:
    return make_transform(rpy_to_matrix(jnp.asarray(rpy)), jnp.asarray(xyz))


def quat_to_matrix(q_wxyz: Float[Array, "*b 4"]) -> Float[Array, "*b 3 3"]:
    """Unit quaternion, scalar first -> rotation matrix."""
    xp = _xp(q_wxyz)
    w, x, y, z = (q_wxyz[..., i] for i in range(4))
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return xp.stack([xp.stack(r, -1) for r in rows], -2)


def matrix_to_quat(R: Float[Array, "*b 3 3"]) -> Float[Array, "*b 4"]:
    """Rotation matrix -> unit quaternion, scalar first."""
    import jaxlie  # imported when needed: it is slow to import and off the hot path

    return jaxlie.SO3.from_matrix(R).wxyz


def compose(A: Float[Array, "*b 4 4"], B: Float[Array, "*b 4 4"]) -> Float[Array, "*b 4 4"]:
    """``A @ B`` for rigid transforms (bottom rows ``0 0 0 1``), as broadcast multiply-adds: on
    CPU, XLA runs batched 4x4 ``matmul`` as many tiny GEMM calls; this form fuses into one loop."""
    top = (A[..., :3, :3, None] * B[..., None, :3, :]).sum(-2)
    top = top.at[..., :, 3].add(A[..., :3, 3])
    bottom = jnp.broadcast_to(jnp.array([0.0, 0.0, 0.0, 1.0], top.dtype), top.shape[:-2] + (1, 4))
    return jnp.concatenate([top, bottom], -2)
