"""Link transforms and forward kinematics (paper eq. 1-2), batched over leading pose axes.

All functions broadcast over any leading axes and can be ``jit``-ed, ``vmap``-ed over poses
and over robots, and differentiated. On the CPU, :func:`fk` runs the fused native kernel of
:mod:`jaxcal._native` when it is available; :func:`_fk_xla` is the pure-JAX implementation
(its reference, its fallback, and what derivatives go through). There, the loop over the
(static, small) ``n`` joints is a ``lax.scan`` over links on a structure-of-arrays chain (see
:func:`_chain` for why) with the polynomial sin/cos of :mod:`jaxcal.trig`; there is no loop
over poses.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from . import _native
from .errors import DataError
from .lie import compose, make_transform
from .robot import Robot
from .trig import DOMAIN, sincos


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


def check_q(robot: Robot, q, *, joint_axis: int = -1) -> Float[Array, "..."]:
    """Validate joint values (real numbers, one per joint along ``joint_axis``: the last axis,
    or the first for :func:`fk_pose_last`) before they enter jit: :class:`jaxcal.DataError`
    naming the problem otherwise. Tracers pass through unchanged."""
    if not hasattr(q, "dtype"):
        q = np.asarray(q)
    if q.dtype.kind not in "biuf":
        raise DataError(f"q: expected real numbers, got dtype {q.dtype}")
    n = robot.n_joints
    if q.ndim < 1 or q.shape[joint_axis] != n:
        want = f"(..., {n})" if joint_axis == -1 else f"({n}, ...)"
        raise DataError(f"q must have shape {want} (one value per joint of {robot.name!r}), got {q.shape}")
    if not isinstance(q, jax.core.Tracer):
        _check_range(robot, np.moveaxis(np.asarray(q), joint_axis, -1), joint_axis)
    return q


def _check_range(robot: Robot, q: np.ndarray, joint_axis: int = -1):
    """Every value finite, revolute joint angles within ``±DOMAIN`` rad (:mod:`jaxcal.trig`);
    ``q`` with the joint axis last, named in the message as the caller laid it out."""
    rev = np.array([t == "R" for t in robot.joint_types])
    bad = ~np.isfinite(q) | (rev & ~(np.abs(q) <= DOMAIN))
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        pose, joint = idx[:-1], idx[-1]
        shown = list(idx) if joint_axis == -1 else [joint, *pose]
        if not pose:
            where = f"q[{joint}] (joint {joint + 1})"
        else:
            where = f"q{shown} (pose {pose if len(pose) > 1 else pose[0]}, joint {joint + 1})"
        problem = "is not finite" if not np.isfinite(q[idx]) else f"= {q[idx]:.6g} rad is beyond ±{DOMAIN:g} rad"
        raise DataError(f"{where} {problem} ({int(bad.sum())} such value(s)); joint angles are in radians")


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


def _link_entries(convention: str, c, s, d, a, alpha):
    """Rotation and translation of one link as nested lists of ``(K,)`` entries, with Python
    zeros where the link has a structural zero (eq. 1 or the MDH link)."""
    ca, sa = jnp.cos(alpha), jnp.sin(alpha)
    if convention == "sdh":
        return [[c, -s * ca, s * sa], [s, c * ca, -c * sa], [0.0, sa, ca]], [a * c, a * s, d]
    return [[c, -s, 0.0], [s * ca, c * ca, -sa], [s * sa, c * sa, ca]], [a, -sa * d, ca * d]


def is_zero(x) -> bool:
    """A structural zero: the Python float 0.0 in an entry list (never an array)."""
    return isinstance(x, float) and x == 0.0


def _dot3(row, col):
    """``sum_j row[j] col[j]``, skipping structural zeros (:func:`is_zero`) of ``col``; 0.0 if
    every term is one."""
    terms = [row[j] * col[j] for j in range(3) if not is_zero(col[j])]
    return sum(terms[1:], terms[0]) if terms else 0.0


def rotate_soa(R, v):
    """``R @ v`` with the pose axis last: ``R (..., 3, 3, K)``, ``v (..., 3, K)``. Written as
    three broadcast multiply-adds, not a reduction: with a reduction, FK on 1e5 poses ran ~3x
    slower."""
    return sum(R[..., :, j, :] * v[..., j:j + 1, :] for j in range(3))


def matmul_soa(A, B):
    """``A @ B`` for ``(3, 3, K)`` blocks, pose axis last, as broadcast multiply-adds."""
    return sum(A[:, j:j + 1, :] * B[None, j, :, :] for j in range(3))


def link_inputs(robot: Robot, q):
    """cos and sin of every joint's theta and its d, pose axis last: three ``(n, K)`` arrays
    (K poses, leading axes of ``q`` flattened)."""
    return link_inputs_pose_last(robot, jnp.reshape(q, (-1, robot.n_joints)).T)


def link_inputs_pose_last(robot: Robot, qT: Float[Array, "n K"]):
    """:func:`link_inputs` for joint values already laid out ``(n, K)``."""
    qT = qT.astype(jnp.float64)
    rev = robot.revolute_mask[:, None]
    theta = robot.dh[:, 0:1] + qT * rev
    s, c = sincos(theta)  # polynomial, vectorised (jaxcal.trig): XLA's sin/cos cost more than the chain
    return c, s, robot.dh[:, 1:2] + qT * (1.0 - rev)


def _chain(robot: Robot, inputs, *, frames: bool):
    """The product ``base @ A_1 ... A_n`` for all poses, structure-of-arrays.

    The pose axis is last: each of the 12 entries of the running transform is a ``(K,)``
    vector (K poses, leading axes of ``q`` flattened), updated entry by entry with the link's
    structural zeros skipped, and the links are a ``lax.scan``, so each link's entries are
    materialised once. Written as one expression with the links unrolled, XLA CPU's loop
    fusion recomputed the whole chain, sin/cos included, inside each output entry; on 1e5
    poses the scan form is ~4x faster (``benchmarks/bench_roofline.py``). Broadcasting
    ``(3, 3, K)`` blocks instead of entries compiled faster but ran FK 2x slower.

    ``inputs``: :func:`link_inputs` ``(c, s, d)``, materialised once as the loop's inputs.
    Returns ``(R_end (3, 3, K), t_end (3, K), frames (n, 12, K))`` (rows of each ``T_i``'s
    rotation, then its translation), the last None unless ``frames``.
    """
    c, s, d = inputs
    K = c.shape[1]
    top = jnp.concatenate([robot.base[:3, :3].reshape(9), robot.base[:3, 3]])
    S0 = jnp.broadcast_to(top[:, None], (12, K))

    def link(S, x):
        R = [[S[3 * r + k] for k in range(3)] for r in range(3)]
        A_R, A_t = _link_entries(robot.convention, *x)
        entries = [_dot3(R[r], [A_R[0][k], A_R[1][k], A_R[2][k]]) for r in range(3) for k in range(3)]
        entries += [_dot3(R[r], A_t) + S[9 + r] for r in range(3)]
        S = jnp.stack([jnp.broadcast_to(e, (K,)) for e in entries])
        return S, (S if frames else None)

    S, ys = jax.lax.scan(link, S0, (c, s, d, robot.dh[:, 2], robot.dh[:, 3]))
    return S[:9].reshape(3, 3, K), S[9:], ys


@eqx.filter_jit
def _fk_frames(robot: Robot, q):
    _, _, ys = _chain(robot, link_inputs(robot, q), frames=True)  # (n, 12, K)
    ys = jnp.transpose(ys, (2, 0, 1))  # (K, n, 12)
    T = make_transform(ys[..., :9].reshape(ys.shape[:-1] + (3, 3)), ys[..., 9:])
    return T.reshape(q.shape[:-1] + T.shape[1:])


def fk(robot: Robot, q: Float[Array, "*b n"]) -> Float[Array, "*b 4 4"]:
    """End pose ``base @ A_1 ... A_n @ tool`` (paper eq. 2 with base and tool). Jit-compiled."""
    return _fk(robot, check_q(robot, q))


@eqx.filter_jit
def _fk(robot: Robot, q):
    if _native.usable(robot):  # the fused kernel (jaxcal._native); same values, ~10x faster on big batches
        q2 = jnp.reshape(q, (-1, robot.n_joints)).astype(jnp.float64)
        return _fk_native(robot, q2).reshape(q.shape[:-1] + (4, 4))
    return _fk_xla(robot, q)


def _fk_xla(robot: Robot, q):
    """Pure-JAX forward kinematics: the reference for the native kernel and its fallback."""
    R, t, _ = _chain(robot, link_inputs(robot, q), frames=False)
    T = make_transform(jnp.moveaxis(R, -1, 0), t.T)  # (K, 4, 4)
    return compose(T, robot.tool).reshape(q.shape[:-1] + (4, 4))


def fk_pose_last(robot: Robot, q: Float[Array, "n *b"]) -> Float[Array, "4 4 *b"]:
    """:func:`fk` with the pose axis last: ``q (n, *b)``, joint axis first, gives ``(4, 4, *b)``,
    ``fk_pose_last(robot, q)[..., k] == fk(robot, q[:, k])``. Jit-compiled.

    For throughput (Monte Carlo, workspace sampling, joint trajectories kept per joint): the
    native kernel reads each joint's values and writes each pose entry as contiguous runs, with
    no transposes in or out, and runs FK 1.1-1.2x faster than :func:`fk` on the same poses
    (``benchmarks/bench_roofline.py``, ``bench_kernel_phases.py``). Transposing a pose-major
    array to call this costs more than it saves."""
    return _fk_pose_last(robot, check_q(robot, q, joint_axis=0))


@eqx.filter_jit
def _fk_pose_last(robot: Robot, q):
    q2 = jnp.reshape(q, (robot.n_joints, -1)).astype(jnp.float64)
    T = _fk_pose_last_native(robot, q2) if _native.usable(robot) else _fk_pose_last_xla(robot, q2)
    return T.reshape((4, 4) + q.shape[1:])


def _fk_pose_last_xla(robot: Robot, q2):
    """Pure-JAX :func:`fk_pose_last` for ``q2 (n, K)``: the structure-of-arrays chain, then the
    tool, without leaving the pose-last layout."""
    R, t, _ = _chain(robot, link_inputs_pose_last(robot, q2), frames=False)
    R_end = matmul_soa(R, jnp.broadcast_to(robot.tool[:3, :3, None], R.shape))
    t_end = rotate_soa(R, jnp.broadcast_to(robot.tool[:3, 3:], t.shape)) + t
    bottom = jnp.broadcast_to(jnp.array([0.0, 0.0, 0.0, 1.0])[None, :, None], (1, 4, t.shape[-1]))
    return jnp.concatenate([jnp.concatenate([R_end, t_end[:, None, :]], 1), bottom], 0)


@jax.custom_jvp
def _fk_pose_last_native(robot: Robot, q2):
    return _native.fk_pose_last_call(robot, q2)


@_fk_pose_last_native.defjvp
def _fk_pose_last_native_jvp(primals, tangents):
    return jax.jvp(_fk_pose_last_xla, primals, tangents)


@jax.custom_jvp
def _fk_native(robot: Robot, q2):
    return _native.fk_call(robot, q2)


@_fk_native.defjvp
def _fk_native_jvp(primals, tangents):  # derivatives (and their primal) from the pure-JAX chain
    return jax.jvp(_fk_xla, primals, tangents)


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
