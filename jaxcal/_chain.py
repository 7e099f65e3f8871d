"""The structure-of-arrays product ``base @ A_1 ... A_n`` shared by forward kinematics and the
identification Jacobian (paper eq. 2).

The pose axis is last: each of the 12 entries of the running transform is a ``(K,)`` vector, and
each link's structural zeros (eq. 1 or the MDH link) are skipped as Python ``0.0`` entries, so
XLA sees only the arithmetic that is needed. Written with the poses leading and ``(K, 4, 4)``
matrix products instead, XLA CPU ran batched tiny GEMMs and fused the chain into every output
entry; this form materialises each link once.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .robot import Robot
from .trig import sincos


def is_zero(x) -> bool:
    """A structural zero: the Python float 0.0 in an entry list (never an array)."""
    return isinstance(x, float) and x == 0.0


def dot3(row, col):
    """``sum_j row[j] col[j]``, skipping structural zeros of ``col``; 0.0 if every term is one."""
    terms = [row[j] * col[j] for j in range(3) if not is_zero(col[j])]
    return sum(terms[1:], terms[0]) if terms else 0.0


def rotate_soa(R, v):
    """``R @ v`` with the pose axis last: ``R (..., 3, 3, K)``, ``v (..., 3, K)``, as broadcast
    multiply-adds (XLA CPU runs them several times faster than a reduction)."""
    return sum(R[..., :, j, :] * v[..., j : j + 1, :] for j in range(3))


def matmul_soa(A, B):
    """``A @ B`` for ``(3, 3, K)`` blocks, pose axis last, as broadcast multiply-adds."""
    return sum(A[:, j : j + 1, :] * B[None, j, :, :] for j in range(3))


def link_entries(convention: str, c, s, d, a, alpha):
    """Rotation and translation of one link as nested lists of ``(K,)`` entries, with Python
    zeros where the link has a structural zero (eq. 1 or the MDH link)."""
    ca, sa = jnp.cos(alpha), jnp.sin(alpha)
    if convention == "sdh":
        return [[c, -s * ca, s * sa], [s, c * ca, -c * sa], [0.0, sa, ca]], [a * c, a * s, d]
    return [[c, -s, 0.0], [s * ca, c * ca, -sa], [s * sa, c * sa, ca]], [a, -sa * d, ca * d]


def link_inputs(robot: Robot, q: Float[Array, "*b n"]):
    """cos and sin of every joint's theta and its d, pose axis last: three ``(n, K)`` arrays
    (K poses, the leading axes of ``q`` flattened)."""
    qT = jnp.reshape(q, (-1, robot.n_joints)).T.astype(jnp.float64)
    rev = robot.revolute_mask[:, None]
    theta = robot.dh[:, 0:1] + qT * rev
    s, c = sincos(theta)  # XLA CPU's float64 sin/cos are scalar calls; this polynomial vectorises
    return c, s, robot.dh[:, 1:2] + qT * (1.0 - rev)


def chain(robot: Robot, inputs, *, frames: bool):
    """``base @ A_1 ... A_n`` for all poses, the links a ``lax.scan`` over entry lists.

    ``inputs``: :func:`link_inputs` ``(c, s, d)``. Returns ``(R_end (3, 3, K), t_end (3, K),
    frames (n, 12, K) or None)``: each ``T_i``'s rotation rows, then its translation.
    """
    c, s, d = inputs
    K = c.shape[1]
    top = jnp.concatenate([robot.base[:3, :3].reshape(9), robot.base[:3, 3]])
    S0 = jnp.broadcast_to(top[:, None], (12, K))

    def link(S, x):
        R = [[S[3 * r + k] for k in range(3)] for r in range(3)]
        A_R, A_t = link_entries(robot.convention, *x)
        entries = [dot3(R[r], [A_R[0][k], A_R[1][k], A_R[2][k]]) for r in range(3) for k in range(3)]
        entries += [dot3(R[r], A_t) + S[9 + r] for r in range(3)]
        S = jnp.stack([jnp.broadcast_to(e, (K,)) for e in entries])
        return S, (S if frames else None)

    S, ys = jax.lax.scan(link, S0, (c, s, d, robot.dh[:, 2], robot.dh[:, 3]))
    return S[:9].reshape(3, 3, K), S[9:], ys
