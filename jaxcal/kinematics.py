"""Link transforms and forward kinematics (paper eq. 1-2), batched over leading pose axes.

All functions are pure ``jax.numpy`` and broadcast over any leading axes, so they can be
``jit``-ed and ``vmap``-ed over poses and over robots. The loop over joints is a Python loop
over a static, small ``n`` (unrolled by XLA); there is no loop over poses.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .errors import DataError
from .lie import compose
from .robot import Robot


def _rows(*rows):
    return jnp.stack([jnp.stack(r, -1) for r in rows], -2)


def sdh_link(theta, d, a, alpha) -> Float[Array, "*b 4 4"]:
    """Standard DH link, paper eq. (1): ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``."""
    theta, d, a, alpha = jnp.broadcast_arrays(*(jnp.asarray(x, jnp.float64) for x in (theta, d, a, alpha)))
    ct, st, ca, sa = jnp.cos(theta), jnp.sin(theta), jnp.cos(alpha), jnp.sin(alpha)
    z, o = jnp.zeros_like(theta), jnp.ones_like(theta)
    return _rows(
        (ct, -st * ca, st * sa, a * ct),
        (st, ct * ca, -ct * sa, a * st),
        (z, sa, ca, d),
        (z, z, z, o),
    )


def mdh_link(theta, d, a, alpha) -> Float[Array, "*b 4 4"]:
    """Modified (Craig) DH link: ``Rx(alpha) Tx(a) Rz(theta) Tz(d)``.

    ``alpha`` and ``a`` are Craig's ``alpha_{i-1}``, ``a_{i-1}``, stored in joint i's row.
    """
    theta, d, a, alpha = jnp.broadcast_arrays(*(jnp.asarray(x, jnp.float64) for x in (theta, d, a, alpha)))
    ct, st, ca, sa = jnp.cos(theta), jnp.sin(theta), jnp.cos(alpha), jnp.sin(alpha)
    z, o = jnp.zeros_like(theta), jnp.ones_like(theta)
    return _rows(
        (ct, -st, z, a),
        (st * ca, ct * ca, -sa, -sa * d),
        (st * sa, ct * sa, ca, ca * d),
        (z, z, z, o),
    )


LINKS = {"sdh": sdh_link, "mdh": mdh_link}


def check_q(robot: Robot, q) -> Float[Array, "*b n"]:
    """Validate joint values (real numbers, last axis one per joint) before they enter jit:
    :class:`jaxcal.DataError` naming the problem otherwise. Tracers pass through unchanged."""
    if not hasattr(q, "dtype"):
        q = np.asarray(q)
    if q.dtype.kind not in "biuf":
        raise DataError(f"q: expected real numbers, got dtype {q.dtype}")
    if q.ndim < 1 or q.shape[-1] != robot.n_joints:
        raise DataError(f"q must have shape (..., {robot.n_joints}) (one value per joint of {robot.name!r}), "
                        f"got {q.shape}")
    return q


def joint_dh(robot: Robot, q: Float[Array, "*b n"]) -> Float[Array, "*b n 4"]:
    """DH values of every link at joint values ``q``: the joint variable is added to theta
    (revolute) or d (prismatic)."""
    q = jnp.asarray(check_q(robot, q))
    rev = robot.revolute_mask
    add = jnp.stack([q * rev, q * (1.0 - rev), jnp.zeros_like(q), jnp.zeros_like(q)], -1)
    return robot.dh + add


def link_transforms(robot: Robot, q: Float[Array, "*b n"]) -> Float[Array, "*b n 4 4"]:
    """``A_1..A_n`` at joint values ``q``."""
    p = joint_dh(robot, q)
    return LINKS[robot.convention](p[..., 0], p[..., 1], p[..., 2], p[..., 3])


def fk_frames(robot: Robot, q: Float[Array, "*b n"]) -> Float[Array, "*b n 4 4"]:
    """Frames ``T_i = base @ A_1 ... A_i`` for i = 1..n (the paper's T_i, with the base).

    The tool transform is not included; see :func:`fk`. Jit-compiled (per robot structure and
    ``q`` shape).
    """
    return _fk_frames(robot, check_q(robot, q))


@eqx.filter_jit
def _fk_frames(robot: Robot, q):
    A = link_transforms(robot, q)
    T = jnp.broadcast_to(robot.base, A.shape[:-3] + (4, 4))
    frames = []
    for i in range(robot.n_joints):
        T = compose(T, A[..., i, :, :])
        frames.append(T)
    return jnp.stack(frames, -3)


def fk(robot: Robot, q: Float[Array, "*b n"]) -> Float[Array, "*b 4 4"]:
    """End pose ``base @ A_1 ... A_n @ tool`` (paper eq. 2 with base and tool). Jit-compiled."""
    return _fk(robot, check_q(robot, q))


@eqx.filter_jit
def _fk(robot: Robot, q):
    return compose(_fk_frames(robot, q)[..., -1, :, :], robot.tool)


def _rx(alpha):
    c, s = np.cos(alpha), np.sin(alpha)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def _tx(a):
    T = np.eye(4)
    T[0, 3] = a
    return T


def to_mdh(robot: Robot) -> Robot:
    """The same arm as a modified-DH table; the last link's ``Tx(a_n) Rx(alpha_n)`` moves into
    the tool, so both models give the same end pose for every ``q``."""
    if robot.convention == "mdh":
        return robot
    dh = np.asarray(robot.dh)
    new = dh.copy()
    new[0, 2:] = 0.0
    new[1:, 2:] = dh[:-1, 2:]
    tail = _tx(dh[-1, 2]) @ _rx(dh[-1, 3])
    return Robot(new, convention="mdh", joint_types=robot.joint_types, base=robot.base,
                 tool=tail @ np.asarray(robot.tool), q_limits=robot.q_limits, name=robot.name)


def to_sdh(robot: Robot) -> Robot:
    """The same arm as a standard-DH table; the first link's ``Rx(alpha_1) Tx(a_1)`` moves into
    the base, so both models give the same end pose for every ``q``."""
    if robot.convention == "sdh":
        return robot
    dh = np.asarray(robot.dh)
    new = dh.copy()
    new[:-1, 2:] = dh[1:, 2:]
    new[-1, 2:] = 0.0
    head = _rx(dh[0, 3]) @ _tx(dh[0, 2])
    return Robot(new, convention="sdh", joint_types=robot.joint_types,
                 base=np.asarray(robot.base) @ head, tool=robot.tool, q_limits=robot.q_limits,
                 name=robot.name)


def convert(robot: Robot, convention: str) -> Robot:
    return {"sdh": to_sdh, "mdh": to_mdh}[convention](robot)
