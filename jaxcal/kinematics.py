"""Link transforms and forward kinematics (paper eq. 1-2), batched over leading pose axes.

All functions broadcast over any leading axes and can be ``jit``-ed, ``vmap``-ed over poses
and over robots, and differentiated. The loop over the (static, small) ``n`` joints is a
``lax.scan`` over links on a structure-of-arrays chain (:mod:`jaxcal._chain`) with the
polynomial sin/cos of :mod:`jaxcal.trig`; there is no loop over poses.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._chain import chain, link_inputs
from ._config import ensure_x64
from ._joints import joint_chain, joint_fk, joint_frames_after
from .errors import DataError, RobotFileError
from .lie import compose, make_transform
from .robot import Robot
from .trig import DOMAIN


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


def check_q(robot: Robot, q) -> Float[Array, "..."]:
    """Validate joint values (real numbers, one per joint along the last axis) before they enter
    jit: :class:`jaxcal.DataError` naming the problem otherwise. Tracers pass through unchanged."""
    ensure_x64()  # float32 traced into a float64 chain fails inside jit with XLA's words
    if not hasattr(q, "dtype"):
        q = np.asarray(q)
    if q.dtype.kind not in "biuf":
        raise DataError(f"q: expected real numbers, got dtype {q.dtype}", option="q")
    n = robot.n_joints
    if q.ndim < 1 or q.shape[-1] != n:
        raise DataError(
            f"q must have shape (..., {n}) (one value per joint of {robot.name!r}), got {q.shape}", option="q"
        )
    if not isinstance(q, jax.core.Tracer):
        _check_range(robot, np.asarray(q))
    return q


def _check_range(robot: Robot, q: np.ndarray):
    """Every value finite, revolute joint angles within ``±DOMAIN`` rad (:mod:`jaxcal.trig`)."""
    rev = np.array([t == "R" for t in robot.joint_types])
    bad = ~np.isfinite(q) | (rev & ~(np.abs(q) <= DOMAIN))
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        pose, joint = idx[:-1], idx[-1]
        shown = list(idx)
        if not pose:
            where = f"q[{joint}] (joint {joint + 1})"
        else:
            where = f"q{shown} (pose {pose if len(pose) > 1 else pose[0]}, joint {joint + 1})"
        problem = "is not finite" if not np.isfinite(q[idx]) else f"= {q[idx]:.6g} rad is beyond ±{DOMAIN:g} rad"
        raise DataError(f"{where} {problem} ({int(bad.sum())} such value(s)); joint angles are in radians", option="q")


def joint_dh(robot: Robot, q: Float[Array, "*b n"]) -> Float[Array, "*b n 4"]:
    """DH values of every link at joint values ``q``: the joint variable is added to theta
    (revolute) or d (prismatic)."""
    _dh_only(robot, "joint_dh")
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
    return _fk_frames(robot.stripped(), check_q(robot, q))


@eqx.filter_jit
def _fk_frames(robot: Robot, q):
    if robot.convention == "joint":
        return joint_frames_after(robot, q.reshape(-1, robot.n_joints)).reshape(q.shape[:-1] + (robot.n_joints, 4, 4))
    _, _, ys = chain(robot, link_inputs(robot, q), frames=True)  # (n, 12, K)
    ys = jnp.transpose(ys, (2, 0, 1))  # (K, n, 12)
    T = make_transform(ys[..., :9].reshape(ys.shape[:-1] + (3, 3)), ys[..., 9:])
    return T.reshape(q.shape[:-1] + T.shape[1:])


def fk(robot: Robot, q: Float[Array, "*b n"]) -> Float[Array, "*b 4 4"]:
    """End pose ``base @ A_1 ... A_n @ tool`` (paper eq. 2 with base and tool), at the deflected
    joint values of a compliant robot (:func:`deflected`). Jit-compiled."""
    return _fk(robot.stripped(), check_q(robot, q))


GRAVITY = (0.0, 0.0, -1.0)
"""Direction of gravity in the robot's base frame (frame 0): the arm stands upright."""


def gravity_moments(robot: Robot, q: Float[Array, "*b n"]) -> Float[Array, "*b n"]:
    r"""Moment arm (mm) about each joint's axis of a unit weight at the tool origin (or at the
    robot's :attr:`~jaxcal.Robot.load` point), at the joint
    values ``q``: $\tau_i = u_i \cdot ((p - o_i) \times g)$ with the axis $u_i$ through $o_i$, the
    tool origin $p$ and :data:`GRAVITY` $g$, all in the robot's base frame. A prismatic joint's
    entry is 0. What a compliant joint's deflection is proportional to (:attr:`Robot.compliance`).
    Pure; jit it."""
    q = jnp.asarray(q)
    flat = q.reshape(-1, robot.n_joints)
    r = eqx.tree_at(lambda r: (r.base, r.compliance), robot, (jnp.eye(4), None), is_leaf=lambda x: x is None)
    load = jnp.zeros(3) if r.load is None else r.load
    weight = r.tool @ jnp.append(load, 1.0)  # in the last joint frame
    if r.convention == "joint":
        F, _, G = joint_chain(r, flat)  # (n, K, 4, 4)
        u = jnp.einsum("nkab,nb->kna", F[..., :3, :3], r.axes)
        o = jnp.swapaxes(F[..., :3, 3], 0, 1)
        p = (G @ weight)[:, :3]
    else:
        _, _, ys = chain(r, link_inputs(r, flat), frames=True)  # (n, 12, K): R row-major, then t
        ys = jnp.transpose(ys, (2, 0, 1))  # (K, n, 12)
        z, t = ys[..., 2:9:3], ys[..., 9:]  # each frame's z axis and origin
        if r.convention == "sdh":  # joint i turns about z of frame i-1 (frame 0: the base)
            K = flat.shape[0]
            z = jnp.concatenate([jnp.broadcast_to(jnp.array([0.0, 0.0, 1.0]), (K, 1, 3)), z[:, :-1]], 1)
            t = jnp.concatenate([jnp.zeros((K, 1, 3)), t[:, :-1]], 1)
        u, o = z, t
        R_n = ys[:, -1, :9].reshape(-1, 3, 3)
        p = jnp.einsum("kab,b->ka", R_n, weight[:3]) + ys[:, -1, 9:]
    tau = jnp.einsum("kna,kna->kn", u, jnp.cross(p[:, None, :] - o, jnp.asarray(GRAVITY)))
    return (tau * r.revolute_mask).reshape(q.shape)


def deflected(robot: Robot, q: Float[Array, "*b n"]) -> Float[Array, "*b n"]:
    """The joint values a compliant robot reaches at the commands ``q``: ``q + compliance *
    (gravity_moments(robot, q) - moment_ref)``; ``q`` itself for a rigid robot (``compliance``
    None). The moments are taken as given (no derivative through them): they change with the
    geometry only at second order in the deflection, and the identification Jacobian treats them
    so too."""
    if robot.compliance is None:
        return q
    return q + robot.compliance * moments_from_ref(robot, q)


def moments_from_ref(robot: Robot, q: Float[Array, "*b n"]) -> Float[Array, "*b n"]:
    """:func:`gravity_moments` less the robot's :attr:`~jaxcal.Robot.moment_ref`, held constant
    (no derivative): what each compliance multiplies. The moments are taken at the weightless
    offsets (``offset - compliance * moment_ref``), as a robot without a reference takes them, so
    that a reference changes the offsets written and nothing the model predicts."""
    if robot.moment_ref is None:
        return jax.lax.stop_gradient(gravity_moments(robot, q))
    c = jnp.zeros_like(robot.moment_ref) if robot.compliance is None else robot.compliance
    weightless = eqx.tree_at(lambda r: r.dh, robot, robot.dh.at[..., 0].add(-c * robot.moment_ref))
    return jax.lax.stop_gradient(gravity_moments(weightless, q) - robot.moment_ref)


@eqx.filter_jit
def _fk(robot: Robot, q):
    q = deflected(robot, q)
    if robot.convention == "joint":
        return joint_fk(robot, q.reshape(-1, robot.n_joints)).reshape(q.shape[:-1] + (4, 4))
    R, t, _ = chain(robot, link_inputs(robot, q), frames=False)
    T = make_transform(jnp.moveaxis(R, -1, 0), t.T)  # (K, 4, 4)
    return compose(T, robot.tool).reshape(q.shape[:-1] + (4, 4))


def _rx(alpha):
    c, s = np.cos(alpha), np.sin(alpha)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def _tx(a):
    T = np.eye(4)
    T[0, 3] = a
    return T


def _dh_only(robot: Robot, what: str):
    if robot.convention == "joint":
        raise RobotFileError(f"{what} needs a DH robot; {robot.name!r} is described by joint frames")


def _rz(theta):
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _tz(d):
    T = np.eye(4)
    T[2, 3] = d
    return T


def to_joint(robot: Robot) -> Robot:
    """The same arm in the joint-frame form (each joint a turn about, or shift along, z of its
    own origin; zero corrections and offsets), with the same end pose for every ``q``: a standard
    DH link ``Rz(theta + q) Tz(d) Tx(a) Rx(alpha)`` is ``Rz(q)`` followed by the fixed rest, which
    becomes the next joint's origin (the last one's, the tool); a modified DH link
    ``Rx(alpha) Tx(a) Rz(theta) Tz(d)`` followed by ``Rz(q)`` is the origin itself."""
    if robot.convention == "joint":
        return robot
    dh = np.asarray(robot.dh)
    fixed = [_rz(t) @ _tz(d) @ _tx(a) @ _rx(al) for t, d, a, al in dh]
    if robot.convention == "sdh":
        origins, tool = [np.eye(4)] + fixed[:-1], fixed[-1] @ np.asarray(robot.tool)
    else:
        origins = [_rx(al) @ _tx(a) @ _rz(t) @ _tz(d) for t, d, a, al in dh]
        tool = np.asarray(robot.tool)
    return robot.replace(
        dh=np.zeros((robot.n_joints, 7)),
        convention="joint",
        origins=np.stack(origins),
        axes=np.tile([0.0, 0.0, 1.0], (robot.n_joints, 1)),
        tool=tool,
    )


def to_mdh(robot: Robot) -> Robot:
    """The same arm as a modified-DH table; the last link's ``Tx(a_n) Rx(alpha_n)`` moves into
    the tool, so both models give the same end pose for every ``q``."""
    _dh_only(robot, "to_mdh")
    if robot.convention == "mdh":
        return robot
    dh = np.asarray(robot.dh)
    new = dh.copy()
    new[0, 2:] = 0.0
    new[1:, 2:] = dh[:-1, 2:]
    tail = _tx(dh[-1, 2]) @ _rx(dh[-1, 3])
    return robot.replace(dh=new, convention="mdh", tool=tail @ np.asarray(robot.tool))


def to_sdh(robot: Robot) -> Robot:
    """The same arm as a standard-DH table; the first link's ``Rx(alpha_1) Tx(a_1)`` moves into
    the base, so both models give the same end pose for every ``q``."""
    _dh_only(robot, "to_sdh")
    if robot.convention == "sdh":
        return robot
    dh = np.asarray(robot.dh)
    c = robot.compliance
    if c is not None and np.any(np.asarray(c) != 0) and dh[0, 3] != 0:
        # gravity is along -z of frame 0, which the moved Rx(alpha_1) would tilt: the compliances'
        # moments, and so the end pose, would change
        raise RobotFileError(
            f"to_sdh: {robot.name!r} has joint compliances and alpha_1 = {dh[0, 3]:.6g} rad; its standard-DH "
            "frame 0 would be tilted from the one gravity is taken in (to_joint keeps it)"
        )
    new = dh.copy()
    new[:-1, 2:] = dh[1:, 2:]
    new[-1, 2:] = 0.0
    head = _rx(dh[0, 3]) @ _tx(dh[0, 2])
    return robot.replace(dh=new, convention="sdh", base=np.asarray(robot.base) @ head)


def convert(robot: Robot, convention: str) -> Robot:
    return {"sdh": to_sdh, "mdh": to_mdh, "joint": to_joint}[convention](robot)
