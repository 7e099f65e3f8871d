"""The fitting machinery shared by every calibration workflow: the parameter layout and its
identifiable set, many fits in one compiled, vmapped solve run in memory-bounded chunks, the
frames-only first stage, and the statistics of a fit.

Every fit of a workflow (each data set of a batch, each cross-validation training set and
parameter set) runs through one compiled function, :func:`run_members`: the members differ only
in arrays (reference model, pose weights, row weights, prior weights), never in what is
compiled. A parameter set is a prior (:data:`jaxcal.solvers.PIN` holds a parameter), a training
set a pose weight of 0 or 1.
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from .._config import jit
from ..identifiability import Identifiability, analyze
from ..kinematics import fk, gravity_moments
from ..lie import so3_log
from ..model import Layout, Model, apply, errors, jacobian, observed, predict
from ..robot import JOINT_FRAME_NAMES, Robot
from ..sharding import assemble, distribute, gather, member_mesh, sharded
from ..solvers import PIN, fit, robust_scale, robust_weights
from ._initial import initial_frames

UNIT_WEIGHTS = (1.0, math.radians(1.0))
SIGMA_FLOOR = (1e-3, 1e-6)
"""Smallest estimated noise (mm, rad): with noise-free data the weighted residual is rounding
error, and larger weights would make the solver's tolerances unreachable."""
"""``(sigma_pos mm, sigma_rot rad)`` of the frames-only stage: 1 mm against 1 degree."""


@dataclasses.dataclass(frozen=True)
class Config:
    """What one compiled member solve is specialised on (hashable). Every parameter of the layout
    is a free variable of the solve; which ones move is data (the prior, :data:`PIN` holding the
    others), so nothing about the poses or the parameter set changes what is compiled."""

    layout: Layout
    method: str = "gn"
    max_steps: int = 50
    rtol: float = 1e-8
    atol: float = 1e-8
    loss: str = "l2"
    shared_data: bool = False
    """Every member fits the same ``q``/``target`` (cross-validation: members differ by mask)."""


def _member(cfg: Config, model: Model, q, target, pose_w, weights, prior, loss_scale, norms0, x0):
    lay = cfg.layout
    sol = fit(
        model,
        lay,
        tuple(range(lay.size)),
        q,
        target,
        weights=weights,
        pose_weights=pose_w,
        prior=prior,
        method=cfg.method,
        max_steps=cfg.max_steps,
        rtol=cfg.rtol,
        atol=cfg.atol,
        loss=cfg.loss,
        loss_scale=loss_scale,
        column_norms=norms0,
        x0=jnp.where(prior >= PIN, 0.0, x0),
    )
    x = jnp.where(prior >= PIN, 0.0, sol.x)  # held parameters exactly at 0
    cal = apply(model, lay, x)
    e = errors(cal, q, target)  # NaN at a lost point: its pos_err is NaN, its rows not in norms
    M = max(lay.n_points, 1)
    pos = jnp.linalg.norm(e[:, : 3 * M].reshape(-1, M, 3), axis=-1)
    rot = jnp.linalg.norm(e[:, 3:], axis=-1) if lay.n_points == 0 else jnp.zeros(q.shape[0])
    we = jnp.where(observed(target), e * weights, 0.0)
    return dict(
        x=x,
        converged=sol.converged,
        steps=sol.steps,
        pos_err=pos,
        rot_err=rot,
        norms=jnp.linalg.norm(we, axis=-1),
        pos_norms=jnp.linalg.norm(we[:, : 3 * M], axis=-1),
        rot_norms=jnp.linalg.norm(we[:, 3 * M :], axis=-1),
        model=cal,
    )


@jit(keep=True)
def _members(cfg: Config, models, q, target, pose_w, weights, prior, loss_scale, norms0, x0):
    data_axis = None if cfg.shared_data else 0
    if pose_w.shape[0] == 1:  # one member: no batching transform to trace
        one = lambda a: a[0]
        out = _member(
            cfg,
            jax.tree.map(one, models),
            q if cfg.shared_data else q[0],
            target if cfg.shared_data else target[0],
            pose_w[0],
            weights[0],
            prior[0],
            loss_scale[0],
            norms0[0],
            x0[0],
        )
        return jax.tree.map(lambda a: a[None], out)
    return jax.vmap(
        lambda m, q_, t_, pw, w, p, ls, n0, s: _member(cfg, m, q_, t_, pw, w, p, ls, n0, s),
        in_axes=(0, data_axis, data_axis, 0, 0, 0, 0, 0, 0),
    )(models, q, target, pose_w, weights, prior, loss_scale, norms0, x0)


MAX_CHUNK = 64
"""Most members per compiled call: a vmapped solve runs until its slowest member is done, so
smaller chunks waste less on easy members; and a workflow pads its small calls to one chunk."""
CACHE_BYTES = 2**22
"""The Jacobians of one compiled call's members are kept within this many bytes (about a CPU's
share of its last-level cache): each step then reads them from cache, not from memory."""
QUICK_WORK = 2**14
"""Member poses (members x padded poses, all chunks of one call) up to which the member solve is
compiled quickly (:func:`jaxcal._config.jit`): beyond, its run time outweighs the compile time
saved (a Monte Carlo study, a large batch)."""


def pose_bucket(n: int, fine: bool = False) -> int:
    """``n`` poses rounded up so that data sets of similar size share one compiled solve (the added
    poses weigh nothing): a power of two up to 1024 poses, where compiling dominates the solve,
    then (or with ``fine``, for a batch whose run time dominates) a multiple of an eighth of the
    power of two below (at most 12.5 % padding)."""
    if n <= 1024 and not fine:
        return max(16, 1 << (max(n, 1) - 1).bit_length())
    step = 1 << max(n.bit_length() - 4, 3)
    return max(16, -(-n // step) * step)


FINE_BUCKET = 2**15
"""Member poses (members x poses) from which a batch pads its poses by :func:`pose_bucket`'s
fine steps: solving it takes longer than compiling for its own pose count."""


def pad_poses(a, K: int, axis: int):
    """``a`` with its pose axis filled up to ``K`` poses by repeating the first (valid values)."""
    a = np.asarray(a)
    extra = K - a.shape[axis]
    if extra <= 0:
        return a
    first = np.take(a, [0], axis=axis)
    return np.concatenate([a, np.repeat(first, extra, axis=axis)], axis=axis)


def members_per_call(n_members: int, most: float) -> int:
    """Members per call of a vmapped program over members: the largest power of two up to
    ``most`` (and :data:`MAX_CHUNK`), or the least one that holds ``n_members`` when that is
    smaller, so that member counts of similar size share one program."""
    cap = int(max(1, min(MAX_CHUNK, most)))
    return min(1 << (cap.bit_length() - 1), 1 << max(n_members - 1, 0).bit_length())


def chunk_size(n_members: int, n_poses: int, layout: Layout, memory_mb: float) -> int:
    """Members per compiled call within ``memory_mb`` (the Jacobian and its few working copies
    dominate, ``n_poses x rows x parameters`` doubles each) and with their Jacobians within
    :data:`CACHE_BYTES`, a power of two so that batches of similar size share one compiled
    solve."""
    jac = 8.0 * n_poses * layout.rows * layout.size
    per = jac * (layout.size + 8) / layout.size * 8
    return members_per_call(n_members, min(memory_mb * 2**20 // per, CACHE_BYTES // jac))


def members_chunk(layout: Layout, n_members: int, n_poses: int, memory_mb: float, devices=None) -> int:
    """Members per device in each call of :func:`run_members` for ``n_members`` members of
    ``n_poses`` poses: a refit of some of them with this ``chunk`` runs the same program where
    its poses fall in the same bucket and its work on the same side of :data:`QUICK_WORK` (a
    batch within that work: every workflow, small batches)."""
    mesh = member_mesh(devices) if devices is not None and sharded(member_mesh(devices)) else None
    D = mesh.size if mesh is not None else 1
    Kp = pose_bucket(n_poses, fine=n_members * n_poses >= FINE_BUCKET)
    return chunk_size(-(-n_members // D), Kp, layout, memory_mb / D)


def _plan(cfg: Config, q, target, pose_w, weights, prior, loss_scale, J0, x0, chunk, memory_mb, devices):
    """How :func:`run_members` calls the solve: ``(members per call, device mesh or None, quick
    compile, (q, target, pose weights, weights, prior, loss scales, column norms, starts) with
    the poses padded)``."""
    B, K = int(pose_w.shape[0]), int(pose_w.shape[1])
    ls = np.full(B, np.nan) if loss_scale is None else np.broadcast_to(np.asarray(loss_scale, float), (B,))
    Kp = pose_bucket(K, fine=B * K >= FINE_BUCKET)
    mesh = member_mesh(devices) if devices is not None and sharded(member_mesh(devices)) else None
    D = mesh.size if mesh is not None else 1
    c = members_chunk(cfg.layout, B, K, memory_mb, devices) * D if chunk is None else chunk * D
    n0 = column_norms(J0, weights, pose_w, prior)
    x0 = np.zeros(np.shape(prior)) if x0 is None else np.asarray(x0)
    axis = 0 if cfg.shared_data else 1
    q, target = pad_poses(q, Kp, axis), pad_poses(target, Kp, axis)
    pose_w = np.concatenate([np.asarray(pose_w, float), np.zeros((B, Kp - K))], 1)
    quick = -(-B // c) * c * Kp <= QUICK_WORK
    return c, mesh, quick, (q, target, pose_w, weights, prior, ls, n0, x0)


def prepare_members(
    cfg: Config,
    models: Model,
    q,
    target,
    pose_w,
    *,
    chunk: int | None = None,
    memory_mb: float = 1024.0,
    devices=None,
) -> bool:
    """Start compiling, in the background, the solve that :func:`run_members` runs for these
    members (``models`` and ``pose_w`` with their member axis, ``q``/``target`` as there; only
    their shapes and the models' structure matter), so that it compiles while the caller finds
    the start and the identifiable set. False where nothing was started (the program is there
    already, the cache is off, or the members are spread over devices)."""
    B, K = np.shape(pose_w)
    lay = cfg.layout
    weights, prior, J0 = np.ones((B, lay.rows)), np.ones((B, lay.size)), np.zeros((K, lay.rows, lay.size))
    c, mesh, quick, padded = _plan(cfg, q, target, pose_w, weights, prior, None, J0, None, chunk, memory_mb, devices)
    if mesh is not None:
        return False
    args = _chunk_args(cfg, models, *padded, np.minimum(np.arange(c), B - 1))
    return _members.prepare(cfg, *args, quick=quick)


def _chunk_args(cfg: Config, models, q, target, pose_w, weights, prior, ls, n0, x0, idx):
    m_, pw, w, p, l_, n_, s_, *data = take(
        [models, pose_w, weights, prior, ls, n0, x0] + ([] if cfg.shared_data else [q, target]), idx
    )
    q_, t_ = (q, target) if cfg.shared_data else data
    return (m_, np.asarray(q_), np.asarray(t_), pw, w, p, l_, n_, s_)


def _shares(args, mesh, cfg: Config):
    """``(device, its members' arguments)`` for each device of ``mesh``, in order: the member
    arrays cut into equal consecutive parts, the data whole to each where members share it."""
    devices = list(mesh.devices.flat)
    n = len(args[3]) // len(devices)
    for i, dev in enumerate(devices):
        part = lambda a: jax.tree.map(lambda x: x[i * n : (i + 1) * n], a)  # noqa: E731
        m_, q_, t_, *rest = args
        q_, t_ = (q_, t_) if cfg.shared_data else (part(q_), part(t_))
        yield dev, (part(m_), q_, t_, *part(rest))


def run_members(
    cfg: Config,
    models: Model,
    q,
    target,
    pose_w,
    weights,
    prior,
    loss_scale=None,
    *,
    J0,
    x0=None,
    chunk: int | None = None,
    memory_mb: float = 1024.0,
    progress=None,
    label: str = "fitting",
    devices=None,
    fallback: bool = False,
) -> dict:
    """Fit every member (leading axis of ``models``, ``pose_w``, ``weights``, ``prior``; and of
    ``q``/``target`` unless ``cfg.shared_data``) in chunks of one compiled, vmapped solve.

    ``prior`` ``(B, m)`` covers every parameter of the layout (:data:`PIN`: held). ``J0`` is a
    Jacobian ``(K, rows, m)`` of the data at the reference (:func:`analyse`): the start's column
    scaling comes from it, each member's own weights applied. ``x0`` ``(B, m)``: starting points
    relative to each member's reference (default 0).

    Chunks have a fixed size (``chunk``, default :func:`chunk_size`; the last is padded by
    repeating its last member), so one compile serves every chunk, and memory is bounded by
    ``memory_mb`` whatever the member count. ``devices`` (from
    :func:`jaxcal.sharding.select_devices`; default: the default device) share each chunk's
    members, ``chunk`` members per device.
    ``progress(done, total, label)`` is called after each chunk. ``fallback``: the members that
    Gauss–Newton did not converge (or left non-finite) are fitted again by Levenberg–Marquardt,
    whose damping holds a step on a nearly degenerate model where a full Gauss–Newton step
    diverges; ``retried`` says which. Returns NumPy arrays with the member axis first.
    """
    B, K = int(pose_w.shape[0]), int(pose_w.shape[1])
    plan = (cfg, q, target, pose_w, weights, prior, loss_scale, J0, x0, chunk, memory_mb, devices)
    c, mesh, quick, padded = _plan(*plan)
    outs = []
    for start in range(0, B, c):
        args = _chunk_args(cfg, models, *padded, np.minimum(np.arange(start, start + c), B - 1))
        if mesh is None:
            outs.append(jax.tree.map(np.asarray, _members(cfg, *args, quick=quick)))
        elif all(d.platform == "cpu" for d in mesh.devices.flat):
            # each CPU device solves its own members, one device after another (each result waited
            # for): a solve sharded over the member axis tests for its slowest member with a
            # collective every step, and solves run at once on several CPU devices of a process,
            # both of which deadlock in XLA's CPU runtime; jitted here, since the kept (exported)
            # programs deadlock on a second device too. Several processes: each its own devices'
            # shares, then gathered
            solve = _members.quick if quick and jax.default_backend() == "cpu" else _members.full
            mine = [(d, s) for d, s in _shares(args, mesh, cfg) if d.process_index == jax.process_index()]
            calls = [jax.block_until_ready(solve(cfg, *jax.device_put(s, dev))) for dev, s in mine]
            if jax.process_count() == 1:
                outs.append(jax.tree.map(lambda *a: np.concatenate([np.asarray(x) for x in a]), *calls))
            else:
                outs.append(gather(assemble(calls, mesh)))
        else:  # every member array split over the devices; data shared by all members on each
            m_, q_, t_, *rest = args
            q_, t_ = distribute((q_, t_), mesh, split=not cfg.shared_data)
            outs.append(gather(_members(cfg, distribute(m_, mesh), q_, t_, *distribute(rest, mesh), quick=quick)))
        if progress is not None:
            progress(min(start + c, B), B, label)
    out = jax.tree.map(lambda *a: np.concatenate(a)[:B], *outs)
    for k in ("pos_err", "rot_err", "norms", "pos_norms", "rot_norms"):  # the padding poses out again
        out[k] = out[k][:, :K]
    out["retried"] = np.zeros(B, bool)
    bad = ~np.asarray(out["converged"], bool) | ~np.all(np.isfinite(out["x"]), -1)
    if fallback and cfg.method == "gn" and bad.any():
        idx = np.flatnonzero(bad)
        ls = None if loss_scale is None else np.broadcast_to(np.asarray(loss_scale, float), (B,))[idx]
        data = (q, target) if cfg.shared_data else take([q, target], idx)
        # in the call's chunk: one program for any number retried (within a pose bucket and mode)
        again = run_members(
            dataclasses.replace(cfg, method="lm"), take(models, idx), *data, take(pose_w, idx), take(weights, idx),
            take(prior, idx), ls, J0=J0, x0=None if x0 is None else take(x0, idx), memory_mb=memory_mb,
            label=label + " (Levenberg-Marquardt)", devices=devices, chunk=c // (1 if mesh is None else mesh.size),
        )  # fmt: skip
        again["retried"] = np.ones(len(idx), bool)

        def merged(a, b):
            a = np.array(a)
            a[idx] = b
            return a

        out = jax.tree.map(merged, out, again)
    return out


def _chain(robot: Robot, q):
    """The chain's poses with an identity base, its tool included: what the closed-form frames
    (:mod:`._initial`) work from."""
    return fk(eqx.tree_at(lambda r: r.base, robot, jnp.eye(4)), q)


_chain_poses = jit(_chain, keep=True)


def start_models(robot: Robot, layout: Layout, q, target, masks, *, shared: bool) -> Model:
    """A reference model per member (leading axis of ``masks (B, K)``): the robot with the
    closed-form guess of its frames (:mod:`._initial`) from the member's poses, when estimated."""
    masks = np.asarray(masks, float)
    S, K = masks.shape
    robot = carrying(robot, layout)
    if shared:  # the analysis program of the nominal model has them (one program fewer to compile)
        F = _analysed(jax.tree.map(np.asarray, nominal_model(robot, layout)), layout, q)[2]
    else:  # every member's poses in one padded row: batches of similar size share one program
        flat = np.asarray(q).reshape(S * K, -1)
        F = np.asarray(_chain_poses(robot, pad_poses(flat, pose_bucket(S * K), 0)))[: S * K].reshape(S, K, 4, 4)
    B, X, pts = initial_frames(
        F,
        robot.base,
        target,
        masks,
        n_points=layout.n_points,
        estimate_base=layout.base,
        estimate_tool=layout.tool,
    )
    models = broadcast_model(nominal_model(robot, layout), S)
    return eqx.tree_at(lambda m: (m.robot.base, m.robot.tool, m.points), models, (B, np.asarray(robot.tool) @ X, pts))


def nominal_model(robot: Robot, layout: Layout) -> Model:
    """The nominal model of a layout: the robot (its structure alone: compiled functions are
    shared by robots of one structure), its measured points at the tool origin."""
    pts = np.zeros((layout.n_points, 3)) if layout.n_points else None
    return Model(carrying(robot.stripped(), layout), pts, camera=layout.camera)


GENERIC_POINT_MM = 100.0
"""Distance of :func:`generic_model`'s measured points from the tool origin."""


def generic_model(robot: Robot, layout: Layout, distance_mm: float = GENERIC_POINT_MM) -> Model:
    """:func:`nominal_model` with its measured points at seeded generic offsets ``distance_mm``
    from the tool origin: a point on the last joint's axis (or several at one place) hides
    parameters that real markers reveal, so what a pose set must identify is judged at generic
    points. Points that are not estimated (a known tool) stay at the tool origin. Nearly
    parallel DH axes are parallel in it (:func:`parallel_snapped`), as the set is chosen."""
    model = parallel_snapped(nominal_model(robot, layout))
    if not layout.n_points or not layout.tool:
        return model
    pts = np.random.default_rng(0).normal(size=(layout.n_points, 3))
    pts *= distance_mm / np.linalg.norm(pts, axis=-1, keepdims=True)
    return eqx.tree_at(lambda m: m.points, model, pts)


def joint_tolerance(robot: Robot) -> np.ndarray:
    """``(n,)`` a joint that moves less than this over the data never moves (rad; mm for a
    prismatic joint)."""
    return np.where(np.array([t == "R" for t in robot.joint_types]), 1e-6, 1e-3)


STILL_GRIDS = 10
"""A joint whose values span at most this many posture grids (:func:`same_pose`: 1e-3 rad, 1 mm)
over the data is held still, its spread an encoder's read-back of a joint not moved: the
identifiable set is taken as if it never moved (:func:`identified`). Its jitter separates
parameters only by amounts the noise swamps, and a fit that used it would write them anywhere
along what the still joint leaves undetermined."""


def still_span(robot: Robot) -> np.ndarray:
    """``(n,)`` at most this spread over the data (rad; mm for a prismatic joint) is no motion."""
    return STILL_GRIDS * same_pose(robot)


def identification_poses(robot: Robot, q) -> np.ndarray:
    """``q (..., K, n)`` with each joint that spreads at most :func:`still_span` over the poses set to
    its median: the poses the identifiable set is decided on (``q`` itself where every joint moves)."""
    q = np.asarray(q)
    still = np.ptp(q, axis=-2) <= still_span(robot)
    if not still.any():
        return q
    return np.where(still[..., None, :], np.median(q, axis=-2, keepdims=True), q)


PARALLEL_RAD = 0.01
"""Consecutive DH axes within this angle of parallel (``alpha`` near 0 or pi) are taken as
parallel when the parameters to estimate are chosen (:func:`identified`). Where they are not
exactly parallel, the common normal's place along them (``d``) moves ``1 / sin(alpha)`` times as
far as the arm does: a calibrated table of a parallel-axis arm (``alpha`` a few mrad) would
otherwise free the ``d`` the nominal holds, and a recalibration from it run ``d`` by metres."""


def parallel_snapped(model: Model) -> Model:
    """``model`` with its DH ``alpha`` within :data:`PARALLEL_RAD` of 0 or pi set to it exactly
    (``model`` itself when none is, or for joint frames)."""
    robot = model.robot
    if robot.convention == "joint":
        return model
    dh = np.array(robot.dh)
    alpha = dh[..., 3]  # (n,), or (B, n) for a batch of models
    exact = np.round(alpha / np.pi) * np.pi
    near = (np.abs(alpha - exact) < PARALLEL_RAD) & (alpha != exact)
    if not near.any():
        return model
    dh[..., 3] = np.where(near, exact, alpha)
    return eqx.tree_at(lambda m: m.robot.dh, model, jnp.asarray(dh))


def identified(model: Model, layout: Layout, q, robot: Robot, J=None, poses=None) -> Identifiability:
    """:func:`base_set` of ``model`` over the poses ``q`` (``poses``: the ones measured, a mask), a
    joint that barely moves taken as still (:func:`identification_poses`) and nearly parallel DH
    axes as parallel (:func:`parallel_snapped`); ``J``, the Jacobian at ``q`` where the caller has
    it, serves when every joint moves and no axis is snapped."""
    q = np.asarray(q)
    q_id = identification_poses(robot, q)
    snapped = parallel_snapped(model)
    if J is None or q_id is not q or snapped is not model:
        J = analyse(snapped, layout, q_id)[0]
    J = np.asarray(J)
    return base_set(J if poses is None else J[np.asarray(poses, bool)], layout, robot)


def same_pose(robot: Robot) -> np.ndarray:
    """``(n,)`` the grid (rad; mm for a prismatic joint) on which joint vectors that round alike are
    one posture: 1e-4 rad moves a 1 m arm 0.1 mm, far below any two postures a calibration means
    to tell apart, and far above an encoder's read-back noise."""
    return np.where(np.array([t == "R" for t in robot.joint_types]), 1e-4, 0.1)


def posture_ids(q, grid) -> np.ndarray:
    """``(K,)`` one label per posture: poses whose joint values all lie within one ``grid`` step
    (:func:`same_pose`) of each other's, directly or through others, share one (a repeated
    measurement of a posture)."""
    u = np.asarray(q, float) / grid
    K = len(u)
    label = np.arange(K)

    def root(i):
        while label[i] != i:
            label[i] = label[label[i]]
            i = label[i]
        return i

    for i in range(K - 1):  # rows at a time: memory K x n, not K x K x n
        for j in np.flatnonzero(np.all(np.abs(u[i + 1 :] - u[i]) <= 1.0, axis=-1)) + i + 1:
            a, b = root(i), root(int(j))
            label[max(a, b)] = min(a, b)
    return np.array([root(i) for i in range(K)])


def distinct_poses(q, grid) -> np.ndarray:
    """Number of distinct postures among the poses ``q (..., K, n)``: rows that round alike on
    ``grid`` (:func:`same_pose`) repeat one posture, and add no equation a fit can use."""
    keys = np.round(np.asarray(q, float) / grid)
    h = np.sort(keys @ np.random.default_rng(0).uniform(0.5, 1.5, keys.shape[-1]), axis=-1)
    return 1 + np.count_nonzero(np.diff(h, axis=-1), axis=-1)


def carrying(robot: Robot, layout: Layout) -> Robot:
    """``robot`` with zero compliances where the layout estimates them and it has none: every
    model of a workflow then has one structure, and one compiled solve serves them all."""
    if layout.n_comp and robot.compliance is None:
        return eqx.tree_at(lambda r: r.compliance, robot, np.zeros(robot.n_joints), is_leaf=lambda v: v is None)
    return robot


moments = jit(gravity_moments)
""":func:`jaxcal.kinematics.gravity_moments` as one compiled program (op by op, each operation
would be a program of its own to compile in each process)."""


def centred(model: Model, layout: Layout, q, used, x, cov, active) -> tuple[Model, np.ndarray, np.ndarray, list]:
    """A fitted model with its compliances' reference moments (:attr:`jaxcal.Robot.moment_ref`)
    at their mean over the poses fitted (``used (K,)`` of ``q (K, n)``: the moments of every pose
    in one program the data's checks compiled already): the same predictions (the moments are taken
    at the weightless offsets, which do not move), and a rigid geometry, what readers other than
    jaxcal load, at the arm's mean load over these data. Fits and their priors work in the form
    they were given (weightless for a rigid start), so this follows them; the estimates ``x`` and
    their covariance ``cov`` (``active``: the estimated indices) follow by the linear map
    ``offset_j + c_j (m_new - m_old)_j``. Returns the model, ``x``, ``cov`` and the indices of the
    offsets moved."""
    r = model.robot
    c = None if r.compliance is None else np.asarray(r.compliance)
    if not layout.n_comp or c is None or not np.any(c):
        return model, x, cov, []
    old = np.zeros(r.n_joints) if r.moment_ref is None else np.asarray(r.moment_ref)
    dh = np.array(r.dh)
    weightless = r.replace(
        dh=dh - np.c_[c * old, np.zeros((r.n_joints, dh.shape[1] - 1))], compliance=None, moment_ref=None
    )
    new = np.asarray(moments(weightless.stripped(), np.asarray(q)))[np.asarray(used, bool)].mean(0)
    dh[:, 0] += c * (new - old)
    moved = [j for j in range(r.n_joints) if c[j] != 0]
    A = np.eye(len(x))
    x = np.array(x, dtype=float)
    for j in moved:
        i, k = j * r.n_kinds, layout.compliances[j]
        x[i] += c[j] * (new[j] - old[j])
        A[i, k] = new[j] - old[j] if k in active else 0.0
    out = Model(r.replace(dh=dh, moment_ref=new), model.points, model.camera_params, camera=model.camera)
    return out, x, A @ cov @ A.T, [j * r.n_kinds for j in moved]


def broadcast_model(model: Model, n: int) -> Model:
    """``n`` copies of ``model`` along a new leading axis (members sharing one reference)."""
    return jax.tree.map(lambda a: np.broadcast_to(np.asarray(a), (n,) + np.shape(a)), model)


def wrapped(model: Model, nominal: Robot) -> Model:
    """``model`` with every DH angle (theta and alpha), or every revolute joint's offset, within
    half a turn of the nominal one: the same kinematics, and offsets in (-pi, pi] a controller
    can take."""
    dh = np.array(model.robot.dh, copy=True)
    nom = np.asarray(nominal.dh)
    rev = np.array([t == "R" for t in nominal.joint_types])
    for k in (0,) if nominal.convention == "joint" else (0, 3):
        d = dh[..., k] - nom[..., k]
        turned = nom[..., k] + (np.pi - np.mod(np.pi - d, 2 * np.pi))
        dh[..., k] = np.where(rev, turned, dh[..., k]) if nominal.convention == "joint" else turned
    r = eqx.tree_at(lambda r: r.dh, model.robot, dh)
    return Model(r, model.points, model.camera_params, camera=model.camera)


def described(model: Model, robot: Robot) -> Model:
    """``model`` with ``robot``'s name, joint names and file units (compiled functions work on
    the structure alone, :meth:`jaxcal.Robot.stripped`)."""
    r = model.robot.with_meta(robot.name, robot.joint_names, robot.units, robot.limits_set)
    return Model(r, model.points, model.camera_params, camera=model.camera)


def member(models: Model, i: int) -> Model:
    """Member ``i`` of a batch of models."""
    return jax.tree.map(lambda a: np.asarray(a)[i], models)


def column_norms(J0, weights, pose_w, prior) -> np.ndarray:
    """``(B, m)`` norms of each member's weighted Jacobian columns (and prior rows) at the start,
    from one Jacobian ``J0 (K, rows, m)``."""
    S = np.asarray(J0) ** 2  # (K, rows, m)
    w2 = np.asarray(weights) ** 2  # (B, rows)
    return np.sqrt(np.einsum("bk,br,krj->bj", np.asarray(pose_w), w2, S) + np.asarray(prior) ** 2)


@jit(keep=True)
def _levers(models: Model, layout: Layout, q, real):
    def one(m, q_, real_):  # selection.lever's RMS point displacement per unit, of the position rows
        J = jacobian(m, layout, q_)
        P = J[:, : 3 * max(layout.n_points, 1)].reshape(J.shape[0], max(layout.n_points, 1), 3, -1)
        P = jnp.where(jnp.isfinite(P) & real_[:, None, None, None], P, 0.0)  # padded and unmeasured poses out
        return jnp.sqrt(jnp.sum(jnp.sum(P**2, 2), axis=(0, 1)) / (jnp.sum(real_) * P.shape[1]))

    return jax.vmap(one)(models, q, real)


def _measured(masks: Float[np.ndarray, "R K"], Kb: int):
    """``(R, Kb)`` the poses a member measured, False for those padded up to ``Kb``."""
    masks = np.asarray(masks) > 0
    return jnp.asarray(np.concatenate([masks, np.zeros((len(masks), Kb - masks.shape[1]), bool)], 1))


def levers(models: Model, layout: Layout, q: Float[np.ndarray, "R K n"], memory_mb: float, masks=None) -> np.ndarray:
    """``(R, m)`` each member's lever (:func:`._selection.lever`) at its model ``models`` (leading
    axis) and poses ``q``, over the poses of ``masks (R, K)`` (default all): a physically scaled
    prior is each data set's own, as :func:`jaxcal.calibrate` gives it alone. One compiled program
    for every batch of a pose bucket: chunks of a power of two members, poses padded as the
    solves pad them."""
    R, K = np.shape(q)[:2]
    Kb = pose_bucket(K)
    c = members_per_call(R, memory_mb * 2**20 // (2 * Kb * layout.rows * layout.size * 8))
    qp = pad_poses(np.asarray(q), Kb, 1)
    real = _measured(np.ones((R, K)) if masks is None else masks, Kb)
    out = []
    for start in range(0, R, c):
        idx = np.minimum(np.arange(start, start + c), R - 1)  # the last chunk padded: one compile
        out.append(np.asarray(_levers(take(models, idx), layout, qp[idx], real[idx]))[: R - start])
    return np.concatenate(out)


def sigmas_from(pos_err, rot_err, masks, n_points: int):
    """RMS per coordinate (mm) and per axis (rad) of each member's errors over its mask (lost
    points, NaN, left out), floored at :data:`SIGMA_FLOOR`;
    ``(B, 2)``. Position-only data get a rotation sigma of 1 (unused)."""
    masks = np.asarray(masks, float)
    n = masks.sum(-1)
    seen = masks[:, :, None] * np.isfinite(pos_err)
    sp = np.sqrt(np.nansum(masks[:, :, None] * pos_err**2, (1, 2)) / (3 * seen.sum((1, 2))))
    sr = np.sqrt(np.sum(masks * rot_err**2, 1) / (3 * n)) if n_points == 0 else np.ones_like(sp)
    return np.stack([np.maximum(sp, SIGMA_FLOOR[0]), np.maximum(sr, SIGMA_FLOOR[1])], -1)


def robust_sigmas(pos_err, rot_err, masks, n_points: int):
    """As :func:`sigmas_from`, from medians (:func:`jaxcal.solvers.robust_scale` of the error norms
    of the points seen and of the rotations, over each member's mask): the noise of a fit that a
    few outliers would set by their squares."""
    masks = np.asarray(masks, bool)
    pos = np.asarray(pos_err, float)
    seen = (masks[:, :, None] & np.isfinite(pos)).reshape(len(pos), -1)

    def scale(norms, weights, floor):  # in units of the floor: robust_scale's own floor lies below it
        return np.maximum(np.asarray(robust_scale(norms / floor, 3, weights.astype(float))) * floor, floor)

    sp = scale(np.where(seen, pos.reshape(len(pos), -1), 0.0), seen, SIGMA_FLOOR[0])
    sr = scale(np.asarray(rot_err, float), masks, SIGMA_FLOOR[1]) if n_points == 0 else np.ones_like(sp)
    return np.stack([sp, sr], -1)


def weights_of(layout: Layout, sigmas) -> np.ndarray:
    """Row weights ``(B, rows)`` from ``(B, 2)`` sigmas."""
    sigmas = np.atleast_2d(sigmas)
    if layout.n_points == 0:
        return np.c_[np.repeat(1 / sigmas[:, :1], 3, 1), np.repeat(1 / sigmas[:, 1:], 3, 1)]
    return np.repeat(1 / sigmas[:, :1], layout.rows, 1)


@jit(keep=True)
def _nominal(model: Model, layout: Layout, q):
    pred = predict(model, q)
    pos = pred[..., :3, 3] if layout.n_points == 0 else pred[..., 0, :]
    return jacobian(model, layout, q), pos, _chain(model.robot, q)


def prepare_analysis(model: Model, layout: Layout, q) -> bool:
    """Start compiling :func:`analyse`'s program for a model of this structure and poses of this
    shape in the background (:func:`prepare_members`)."""
    return _nominal.prepare(model, layout, pad_poses(q, pose_bucket(np.shape(q)[0]), 0))


def analyse(model: Model, layout: Layout, q) -> tuple[np.ndarray, np.ndarray]:
    """``(J (K, rows, m), tool positions (K, 3))`` of the model at the poses ``q``: the Jacobian
    of the identifiability analysis and the column scaling, the positions of the unit check."""
    return _analysed(model, layout, q)[:2]


def _analysed(model: Model, layout: Layout, q) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`analyse`'s ``(J, positions)`` and the chain's poses ``(K, 4, 4)`` with an identity
    base (:func:`_chain`)."""
    K = np.shape(q)[0]
    return tuple(np.asarray(a)[:K] for a in _nominal(model, layout, pad_poses(q, pose_bucket(K), 0)))


def base_set(J, layout: Layout, robot: Robot | None = None, *, rtol: float = 1e-8) -> Identifiability:
    """Identifiability of every parameter of ``layout`` from the Jacobian ``J`` (:func:`analyse`),
    the frames offered first (they keep what they can absorb), then the DH errors or joint frames
    (in :func:`kin_order` of ``robot``) and the joint compliances, then the camera. A URDF joint
    origin's shifts and turns are then exchanged for better separated ones (``swappable`` of
    :func:`analyze`): their order is a heuristic, a DH table's held parameters the textbook ones.
    The joint offsets stay as the order keeps them: a joint's zero is the error a user looks for,
    and the offsets candidate estimates the offsets in the set."""
    frames, cams = list(layout.frames), list(layout.cameras)
    order = kin_order(robot, layout)
    names = layout.names()
    joint = robot is not None and robot.convention == "joint"
    swappable = [i for i in order if not names[i].startswith("offset")] if joint else None
    J = np.asarray(J).reshape(-1, layout.size)
    kin = order + list(layout.compliances)
    return analyze(J, names, rtol=rtol, priority=frames + kin + cams, swappable=swappable)


def scaled_condition(J, base) -> float:
    """The condition number of the columns ``base`` of ``J (rows, m)``, each scaled to unit norm:
    how separable those parameters are on these poses, whatever their units."""
    cols = np.asarray(J)[:, list(base)]
    s = np.linalg.svd(cols / np.maximum(np.linalg.norm(cols, axis=0), 1e-300), compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")


def reidentified(
    ident: Identifiability, model: Model, layout: Layout, q, robot: Robot, max_condition: float
) -> tuple[Identifiability, str] | None:
    """The base set identified at ``model`` (a fit) and a note saying so, when ``ident``'s (decided
    at the nominal) is not separable there: column-scaled condition above ``max_condition``. A fit
    far from its nominal can run to where the nominal's set turns dependent (an origin offset
    cancelled makes a shift one with two joint offsets); it stops there at a point of the
    parameterisation, not of the arm. ``None`` otherwise."""
    J = analyse(model, layout, q)[0].reshape(-1, layout.size)
    cond = scaled_condition(J, ident.base)
    if cond <= max_condition:
        return None
    again = identified(model, layout, q, robot, J=J)
    if set(again.base) == set(ident.base):
        return None
    names = layout.names()
    freed = [names[i] for i in again.base if i not in ident.base]
    held = [names[i] for i in ident.base if i not in again.base]
    return again, (
        f"the parameters estimated were chosen again at the fit: those identifiable at the nominal model "
        f"were not separable where the fit ran (condition {cond:.1e}), so {', '.join(freed)} "
        f"{'is' if len(freed) == 1 else 'are'} estimated and {', '.join(held)} held instead"
    )


@jit(keep=True)
def _normals(models: Model, layout: Layout, q, real):
    def one(m, q_, real_):
        J = jnp.where(real_[:, None, None], jacobian(m, layout, q_), 0.0)  # padded and unmeasured poses out
        J = J.reshape(-1, layout.size)
        return J.T @ J

    return jax.vmap(one)(models, q, real)


def scaled_normals(
    models: Model, layout: Layout, q: Float[np.ndarray, "R K n"], base, memory_mb: float, masks=None
) -> Float[np.ndarray, "R b b"]:  # fmt: skip
    """``(R, b, b)`` each member's normal matrix of the columns ``base`` at ``models`` (leading axis)
    on its poses ``q`` of ``masks (R, K)`` (default all), each column scaled to unit norm. One
    compiled program over chunks within ``memory_mb`` (the normal matrix of every parameter; the
    set's columns taken and scaled here)."""
    R, K = np.shape(q)[:2]
    Kb = pose_bucket(K)
    c = members_per_call(R, memory_mb * 2**20 // (4 * Kb * layout.rows * layout.size * 8))  # a Jacobian, copies
    qp, cols, out = pad_poses(np.asarray(q), Kb, 1), list(base), []
    real = _measured(np.ones((R, K)) if masks is None else masks, Kb)
    for start in range(0, R, c):
        idx = np.minimum(np.arange(start, start + c), R - 1)  # the last chunk padded: one compile
        N = np.asarray(_normals(take(models, idx), layout, qp[idx], real[idx]))[: R - start][:, cols][:, :, cols]
        d = np.maximum(np.sqrt(np.abs(np.diagonal(N, axis1=1, axis2=2))), 1e-300)
        out.append(N / d[:, :, None] / d[:, None, :])
    return np.concatenate(out)


def _eigenvalues(N) -> tuple[np.ndarray, np.ndarray]:
    bad = ~np.all(np.isfinite(N), axis=(1, 2))
    return bad, np.linalg.eigvalsh(np.where(bad[:, None, None], np.eye(N.shape[-1]), N))


def inseparable(N: Float[np.ndarray, "R b b"], max_condition: float) -> np.ndarray:
    """``(R,)`` which of :func:`scaled_normals`' matrices ``N`` have a condition above
    ``max_condition`` (or are not finite): their parameters are not separable."""
    bad, ev = _eigenvalues(N)
    return bad | ~(ev[:, 0] > 0) | (ev[:, -1] > max_condition**2 * ev[:, 0])


def separable_counts(N: Float[np.ndarray, "R b b"], max_condition: float) -> np.ndarray:
    """``(R,)`` how many directions each of :func:`scaled_normals`' matrices ``N`` separates: its
    eigenvalues within ``max_condition`` squared of its largest (0 where it is not finite)."""
    bad, ev = _eigenvalues(N)
    return np.where(bad, 0, np.sum(ev * max_condition**2 > ev[:, -1:], axis=-1))


def singular_at_fit(
    models: Model, layout: Layout, q: Float[np.ndarray, "R K n"], base, max_condition: float, memory_mb: float,
    masks=None,
) -> np.ndarray:  # fmt: skip
    """``(R,)`` which members' set ``base`` is not separable at their fit ``models`` (leading
    axis) on their poses ``q`` of ``masks (R, K)`` (default all), as :func:`reidentified` judges
    one fit: the column-scaled condition above ``max_condition`` (:func:`inseparable`)."""
    return inseparable(scaled_normals(models, layout, q, base, memory_mb, masks), max_condition)


def kin_order(robot: Robot | None, layout: Layout) -> list[int]:
    """The kinematic parameters in the order the base set takes them. For a joint frame, the
    origin's turns least aligned with the joint's axis ``a`` come first (and a prismatic joint's
    shifts likewise): to first order the offset is the turn ``sum_k a_k r_k`` (the shift
    ``sum_k a_k t_k``), so the one most aligned with the axis is the offset's twin and is the one
    left out, whatever the axis' direction, and what is kept stays well conditioned (a z axis
    leaves ``rz`` out, an x axis ``rx``)."""
    if robot is None or robot.convention != "joint":
        return list(range(layout.n_kin))
    out, axes, p = [], np.abs(np.asarray(robot.axes)), len(JOINT_FRAME_NAMES)
    for j, kind in enumerate(robot.joint_types):
        b = p * j
        shifts = sorted(range(3), key=lambda k: axes[j, k]) if kind == "P" else range(3)
        turns = sorted(range(3), key=lambda k: axes[j, k])
        out += [b] + [b + 1 + k for k in shifts] + [b + 4 + k for k in turns]
    return out


def generic_rank(model: Model, layout: Layout, n_poses: int, columns) -> int:
    """Rank of ``columns`` of the Jacobian on a generic pose set (seeded, uniform within the joint
    limits, at least 60 poses): what a pose set must identify to count as enough data. Evaluated
    in blocks of ``n_poses`` poses, so the data's compiled Jacobian serves."""
    return generic_ranks(model, layout, n_poses, [columns])[0]


def generic_ranks(model: Model, layout: Layout, n_poses: int, column_sets) -> list[int]:
    """:func:`generic_rank` of each of ``column_sets``, on one Jacobian."""
    lim = np.asarray(model.robot.q_limits)
    rng = np.random.default_rng(0)
    n_poses = n_poses if n_poses > 0 else 60
    blocks = []
    for _ in range(-(-60 // n_poses)):
        qg = lim[:, 0] + rng.uniform(size=(n_poses, len(lim))) * (lim[:, 1] - lim[:, 0])
        blocks.append(analyse(model, layout, qg)[0].reshape(-1, layout.size))
    J = np.concatenate(blocks)
    return [analyze(J[:, list(cols)], [str(c) for c in cols]).rank for cols in column_sets]


def relative_x(reference, layout: Layout, model: Model) -> np.ndarray:
    """``x`` of ``model`` relative to ``reference`` (a :class:`Model`, or a robot with no points;
    either may carry a leading batch axis) in the layout of ``layout``: DH deltas, the frames'
    translations and rotation vectors (the chart of :func:`jaxcal.error_model.perturb`), the
    points' offsets and the camera unknowns' changes, so that ``apply(reference, layout, x)`` is
    ``model``."""
    if isinstance(reference, Robot):
        reference = Model(reference, np.zeros((layout.n_points, 3)) if layout.n_points else None, camera=layout.camera)
    r0, r1 = reference.robot, model.robot
    lead = np.broadcast_shapes(np.shape(r1.dh)[:-2], np.shape(r0.dh)[:-2])
    out = [(np.asarray(r1.dh) - np.asarray(r0.dh)).reshape(lead + (-1,))]
    if layout.base:  # the chart of jaxcal.error_model.perturb: translation, then turn about the origin
        B0, B1 = np.asarray(r0.base), np.asarray(r1.base)
        out.append(
            np.concatenate(
                [B1[..., :3, 3] - B0[..., :3, 3], so3_log(B1[..., :3, :3] @ np.swapaxes(B0[..., :3, :3], -1, -2))], -1
            )
        )
    if layout.tool:
        if layout.n_points == 0:
            X0, X1 = np.asarray(r0.tool), np.asarray(r1.tool)
            R0t = np.swapaxes(X0[..., :3, :3], -1, -2)
            out.append(
                np.concatenate(
                    [
                        np.einsum("...ij,...j->...i", R0t, X1[..., :3, 3] - X0[..., :3, 3]),
                        so3_log(R0t @ X1[..., :3, :3]),
                    ],
                    -1,
                )
            )
        else:
            out.append((np.asarray(model.points) - np.asarray(reference.points)).reshape(lead + (-1,)))
    if layout.n_comp:
        c0, c1 = (
            np.zeros(lead + (layout.n_comp,)) if c is None else np.asarray(c) for c in (r0.compliance, r1.compliance)
        )
        out.append(c1 - c0)
    cam = np.asarray(model.camera_params) - np.asarray(reference.camera_params)
    out.append(cam.reshape(cam.shape[:-1] + (-1,))[..., : layout.n_camera])
    return np.concatenate([np.broadcast_to(o, lead + o.shape[-1:]) for o in out], -1)


def take(tree, idx):
    """The members ``idx`` of a batch (a model, or a list of arrays), as NumPy arrays: no eager
    JAX operation, so nothing is compiled for it."""
    return jax.tree.map(lambda a: np.asarray(a)[idx], tree)


def condition_number(normal, active) -> float:
    """Condition number of the column-scaled weighted Jacobian of the ``active`` free parameters,
    from its normal matrix."""
    N = np.asarray(normal)[np.ix_(active, active)]
    d = np.sqrt(np.clip(np.diag(N), 1e-300, None))
    ev = np.linalg.eigvalsh(N / np.outer(d, d))
    return float(np.sqrt(ev[-1] / ev[0])) if ev[0] > 0 else float("inf")


def fit_statistics(J, weights, pose_w, norms, *, loss: str, loss_scale, rows: int, seen=None) -> dict:
    """What the standard errors and outlier report of one fit need, from its per-pose weighted
    residual norms and the Jacobian ``J (K, rows, m)`` at its solution (not at its start: a
    parameter the data do not determine can look determined at the nominal robot):
    the robust ``scale``, the weighted normal matrix ``normal``, ``rss`` and ``n_rows``. ``seen``
    ``(K, rows)``: the observed rows (:func:`jaxcal.model.observed`; default all)."""
    norms, pose_w = np.asarray(norms), np.asarray(pose_w)
    seen = np.ones(np.shape(J)[:2], bool) if seen is None else np.asarray(seen)
    scale = float(loss_scale) if loss_scale is not None else float(robust_scale(norms, rows, pose_w))
    w = pose_w * (robust_weights(norms, scale, rows, loss) if loss != "l2" else 1.0)
    Jw = np.asarray(J) * (np.asarray(weights)[None, :] * seen)[:, :, None]
    return {
        "scale": scale,
        "normal": np.einsum("k,kri,krj->ij", w, Jw, Jw),
        "rss": float(np.sum(w * norms**2)),
        "n_rows": int(np.sum(seen[pose_w > 0])),
        "pose_weights": w,
    }


def leverage(J, weights, st: dict, prior, seen=None) -> np.ndarray:
    """Each row's leverage ``(K, rows)``, the hat matrix's diagonal ``w_k (W J)_r N^-1 (W J)_r^T``
    of the fit :func:`fit_statistics` describes (``N`` as in :func:`covariance`, the prior rows in
    it). Their sum is the effective number of parameters, fewer than the free ones under a prior:
    a residual's variance is ``s^2 (1 - h_r)``, which is what a noise read from residuals lacks."""
    prior = np.asarray(prior)
    keep = prior < PIN
    seen = np.ones(np.shape(J)[:2], bool) if seen is None else np.asarray(seen)
    Jw = (np.asarray(J) * (np.asarray(weights)[None, :] * seen)[:, :, None])[:, :, keep]
    N = st["normal"][np.ix_(keep, keep)] + np.diag(prior[keep] ** 2)
    h = np.einsum("kri,ij,krj->kr", Jw, np.linalg.pinv(N), Jw)
    return np.asarray(st["pose_weights"])[:, None] * h


def covariance(normal, rss, n_rows, prior) -> tuple[np.ndarray, float]:
    """Sandwich covariance of the free parameters, ``s^2 N^-1 (J^T J) N^-1`` with ``N = J^T J +
    diag(p^2)`` (data and prior rows) and ``s^2`` the weighted residual variance over the rows
    less the effective parameter count ``tr(N^-1 J^T J)`` (the leverages' sum, :func:`leverage`:
    a parameter the prior holds absorbs less of the noise); and ``s^2``."""
    p = np.where(np.asarray(prior) >= PIN, 0.0, np.asarray(prior))
    held = np.asarray(prior) >= PIN
    N = normal + np.diag(p**2)
    keep = ~held
    cov = np.zeros_like(N)
    if keep.any():
        Ni = np.linalg.pinv(N[np.ix_(keep, keep)])
        JJ = normal[np.ix_(keep, keep)]
        dof = max(float(n_rows) - float(np.trace(Ni @ JJ)), 1.0)
        s2 = float(rss) / dof
        cov[np.ix_(keep, keep)] = s2 * Ni @ JJ @ Ni
        return cov, s2
    return cov, float("nan")


def nan_rms(a, axis) -> np.ndarray:
    """RMS of the finite values of ``a`` over ``axis`` (a lost point is NaN); NaN where there is
    none (a member with no pose kept), without numpy's empty-slice warning."""
    a = np.asarray(a, float)
    ok = np.isfinite(a)
    n = ok.sum(axis)
    s = np.where(ok, a, 0.0) ** 2
    return np.sqrt(np.divide(s.sum(axis), n, out=np.full(np.shape(n), np.nan), where=n > 0))


def residual_stats(pos_err, rot_err, mask=None, *, n_points: int) -> dict:
    """Position RMS / max / median (mm, per pose: the norm over its points' errors) and rotation
    RMS (deg) over the poses of ``mask``."""
    pos_err = np.asarray(pos_err)
    sel = np.ones(pos_err.shape[0], bool) if mask is None else np.asarray(mask, bool)
    d = pos_err[sel]
    per_point = nan_rms(d, 0) if d.size else np.full(max(n_points, 1), np.nan)
    f = d[np.isfinite(d)]  # lost points (NaN) left out
    out = {
        "pos_rms_mm": float(np.sqrt(np.mean(f**2))) if f.size else float("nan"),
        "pos_max_mm": float(f.max()) if f.size else float("nan"),
        "pos_median_mm": float(np.median(f)) if f.size else float("nan"),
    }
    if n_points > 1:
        out["points_rms_mm"] = [float(v) for v in per_point]
    if n_points == 0:
        out["rot_rms_deg"] = float(np.degrees(np.sqrt(np.mean(np.asarray(rot_err)[sel] ** 2))))
    return out


@jit
def _tool_positions(robot: Robot, q):
    return fk(robot, q)[..., :3, 3]


def nominal_positions(robot: Robot, q):
    """Tool positions of the nominal robot at ``q`` (any leading axes), for the unit check: the
    poses flattened and padded as the solves pad theirs, so data sets of similar size share one
    program."""
    q = np.asarray(q)
    flat = q.reshape(-1, q.shape[-1])
    n = len(flat)
    pos = _tool_positions(robot.stripped(), pad_poses(flat, pose_bucket(n), 0))  # one program per structure
    return np.asarray(pos)[:n].reshape(q.shape[:-1] + (3,))
