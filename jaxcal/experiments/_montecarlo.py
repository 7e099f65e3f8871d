"""Monte Carlo study: many simulated robots calibrated by compiled, vmapped solves, in chunks of
bounded memory shared over devices, compared with the simulated truth and with the Cramér–Rao
bound; resumable when its chunks are kept in a folder (:mod:`._study`)."""

from __future__ import annotations

import dataclasses
import statistics
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._config import as_f64
from ..calibration import Options, calibrate_batch, identify, still_joint_notes
from ..error_model import perturb
from ..errors import DataError
from ..identifiability import base_covariance, row_sigmas
from ..kinematics import check_q, fk
from ..model import Layout, Model, jacobian
from ..robot import Robot
from ..sharding import describe, select_devices
from ..simulation import error_scales, inject_outliers, measure, outlier_count, sample_poses
from ..solvers import design_poses
from ._study import StudyFolder, fingerprint
from ._timing import machine_info


@eqx.filter_jit
def _validation_rms(robot, x, q_val, true_val, *, layout: Layout):
    """Position RMS (mm) of each calibrated model ``x (R, m)`` vs its true robot on the
    inspection poses (the tool origin)."""
    k = layout.n_kin + 6 * layout.base
    pose_tool = layout.tool and layout.n_points == 0

    def one(x_, q_, true_):
        cal = perturb(robot, x_[: k + 6 * pose_tool], base=layout.base, tool=pose_tool)
        T = fk(cal, q_)
        p = T[..., :3, 3]
        if layout.n_points and layout.tool:
            p = p + jnp.einsum("kij,j->ki", T[..., :3, :3], x_[k : k + 3])
        return jnp.sqrt(jnp.mean(jnp.sum((p - true_[..., :3, 3]) ** 2, -1)))

    return jax.vmap(one)(x, q_val, true_val)


@eqx.filter_jit
def _jacobians(robot, q, *, layout: Layout):
    model = Model(robot, jnp.zeros((layout.n_points, 3)) if layout.n_points else None, camera=layout.camera)
    return jax.vmap(lambda q_: jacobian(model, layout, q_))(q)


def _points(layout: Layout, R: int, x_true=None):
    """``(R, M, 3)`` the measured points the bound is evaluated at: each true robot's tool point
    where the layout estimates it (at the tool origin, rotations about the last axis would not
    move it), else the tool origin; None for poses."""
    if not layout.n_points:
        return None
    pts = np.zeros((R, layout.n_points, 3))
    if layout.tool and x_true is not None:
        k = layout.n_kin + 6 * layout.base
        pts[:, 0] = np.asarray(x_true)[:, k : k + 3]
    return pts


@eqx.filter_jit
def _information(robot, q, w, points, *, layout: Layout, base: tuple[int, ...]):
    """``(R, r, r)`` Fisher information ``Jb^T Jb`` of the base columns, each robot's rows
    weighted by its ``w (R, rows)`` (0 for a pose its fit left out): each robot's Jacobian reduced
    where it is made (its measured ``points`` (R, M, 3), or None)."""

    def one(q_, w_, p_):
        model = Model(robot, p_, camera=layout.camera)
        Jb = jacobian(model, layout, q_).reshape(-1, layout.size)[:, list(base)] * w_[:, None]
        return Jb.T @ Jb

    return jax.vmap(one)(q, w, points)


def crlb_variances(
    robot: Robot, q, ident, layout: Layout, *, sigma_pos: float, sigma_rot: float | None, x_true=None, kept=None
) -> np.ndarray:
    """``(R, r)`` Cramér–Rao variances of the base parameters for each robot's pose set ``q (R,
    K, n)`` at the nominal model (its measured point where ``x_true`` puts it, :func:`_points`):
    the diagonal of :func:`jaxcal.identifiability.crlb`, from each robot's column-scaled
    information matrix, :data:`CRLB_SLICE` robots at a time (a slice's Jacobians are the largest
    arrays of a study). ``kept (R, K)``: the poses each fit used (default all): the bound of the
    data a fit that leaves out outliers is made from."""
    return _variances(_base_information(robot, q, ident, layout, sigma_pos, sigma_rot, x_true, kept))


def _singular(N) -> np.ndarray:
    """``(R,)`` which information matrices are singular once their columns are scaled."""
    d = np.sqrt(np.abs(np.diagonal(N, axis1=-2, axis2=-1)))
    s = np.where(d > 0, d, 1.0)  # a zero column is singular by itself
    finite = np.all(np.isfinite(N), axis=(-2, -1))
    cond = np.linalg.cond(np.where(finite[:, None, None], N, 0.0) / (s[:, :, None] * s[:, None, :]))
    return ~finite | ~np.isfinite(cond) | (cond > 1e12) | np.any(d == 0, axis=-1)


def _variances(N) -> np.ndarray:
    d = np.sqrt(np.diagonal(N, axis1=-2, axis2=-1))  # column scales: inv of a matrix with unit diagonal
    return np.diagonal(np.linalg.inv(N / (d[:, :, None] * d[:, None, :])), axis1=-2, axis2=-1) / d**2


def _base_information(
    robot: Robot, q, ident, layout: Layout, sigma_pos, sigma_rot, x_true=None, kept=None
) -> np.ndarray:
    """``(R, r, r)`` information of the base parameters of each robot's poses ``q (R, K, n)``,
    of those ``kept (R, K)`` where given."""
    q = np.asarray(q)
    R, K = q.shape[:2]
    pts = _points(layout, R, x_true)
    sig = row_sigmas(
        K,
        position_only=layout.n_points > 0,
        sigma_pos_mm=sigma_pos,
        sigma_rot_rad=None if layout.n_points else sigma_rot,
    )
    kept = np.ones((R, K), bool) if kept is None else np.asarray(kept, bool)
    w = np.repeat(kept, len(sig) // K, axis=1) / sig  # (R, rows), rows pose by pose
    step = min(R, CRLB_SLICE)
    pad = lambda a: None if a is None else np.concatenate([a, np.repeat(a[-1:], -R % step, 0)])  # noqa: E731
    padded, pts, w = pad(q), pad(pts), pad(w)  # whole slices: one compile
    base = tuple(ident.base)
    piece = lambda a, s: None if a is None else a[s : s + step]  # noqa: E731
    fn = lambda s: _information(  # noqa: E731
        robot.stripped(), piece(padded, s), piece(w, s), piece(pts, s), layout=layout, base=base
    )
    return np.concatenate([np.asarray(fn(s)) for s in range(0, len(padded), step)])[:R]


@eqx.filter_jit
def _position_moments(robot, q_val, points, *, layout: Layout, base: tuple[int, ...]):
    """``(R, r, r)`` mean over each robot's inspection poses ``q_val (R, V, n)`` of ``G^T G``,
    ``G`` the base columns of the measured point's position rows (``points``, :func:`_points`):
    ``tr(C S)`` is the expected squared position error there for an estimate with covariance ``C``."""

    def one(qv, p_):
        G = jacobian(Model(robot, p_, camera=layout.camera), layout, qv)[:, :3][..., list(base)]
        return jnp.einsum("vrb,vrc->bc", G, G) / qv.shape[0]

    return jax.vmap(one)(q_val, points)


def _validation_crlb(N, S) -> np.ndarray:
    """``(R,)`` ``tr(N^-1 S)`` per robot, columns scaled to a unit diagonal of ``N`` first."""
    d = np.sqrt(np.diagonal(N, axis1=-2, axis2=-1))
    D = d[:, :, None] * d[:, None, :]
    return np.trace(np.linalg.solve(N / D, np.broadcast_to(S, N.shape) / D), axis1=-2, axis2=-1)


CRLB_SLICE = 256
"""Robots per Cramér–Rao evaluation of :func:`crlb_variances`."""


def _crlb_each(robot, q, ident, layout, sigma_pos, sigma_rot) -> np.ndarray:
    J = np.asarray(_jacobians(robot.stripped(), jnp.asarray(q), layout=layout))
    R, K = np.shape(q)[:2]
    sig = row_sigmas(
        K,
        position_only=layout.n_points > 0,
        sigma_pos_mm=sigma_pos,
        sigma_rot_rad=None if layout.n_points else sigma_rot,
    )
    Jb = J.reshape(R, -1, J.shape[-1])[..., list(ident.base)] / sig[:, None]
    return base_covariance(Jb)


def crlb_batch(robot: Robot, q, ident, layout: Layout, *, sigma_pos: float, sigma_rot: float | None) -> np.ndarray:
    """Cramér–Rao covariance of the base parameters for each robot's pose set ``q (R, K, n)`` at
    the nominal model, averaged over robots: :func:`jaxcal.identifiability.crlb` for all robots
    at once (:func:`jaxcal.identifiability.base_covariance` on the stacked Jacobians)."""
    return np.mean(_crlb_each(robot, q, ident, layout, sigma_pos, sigma_rot), axis=0)


def _true_x(x_true, layout: Layout) -> np.ndarray:
    """The simulated truth in the calibration's layout: a tool twist becomes the tool point's
    offset for position data."""
    x = np.asarray(x_true)
    if not (layout.n_points and layout.tool):
        return x
    k = layout.n_kin + 6 * layout.base
    return x[:, : k + 3]  # the tool's translation is the point's offset (perturb's chart)


@eqx.filter_jit
def _draw(
    robot: Robot,
    key,
    idx,
    scales,
    q_given,
    q_each,
    q_val,
    sigmas,
    *,
    n_poses: int,
    n_val: int,
    base,
    tool,
    design,
    outliers,
):
    """Robots ``idx`` of a study: true errors, poses, noisy measurements, inspection poses and
    their true poses, outlier flags, and the calibration poses' true poses. Robot ``i``'s draw
    depends on ``(key, i)`` alone, so a study's results do not depend on how it is chunked, on the
    devices, or on being resumed. ``q_each (R, K, n)``:
    each robot's poses (drawn under the study's conditions); ``q_val (V, n)``: the inspection
    poses of every robot."""

    def one(i, q_e):
        kx, kq, kv, kn = jax.random.split(jax.random.fold_in(key, i), 4)
        x = jax.random.normal(kx, scales.shape, dtype=jnp.float64) * scales
        if design is not None:
            q = design_poses(kq, robot, n_pairs=design[0], n_abs=design[1])
        elif q_e is not None:
            q = q_e
        else:
            q = sample_poses(kq, robot, (n_poses,)) if q_given is None else q_given
        meas = measure(robot, x, q, kn, sigma_pos=sigmas[0], sigma_rot=sigmas[1], base=base, tool=tool)
        bad = jnp.zeros(q.shape[0], bool)
        if outliers is not None:  # gross errors, on a key of their own (the clean draws unchanged)
            meas, bad = inject_outliers(jax.random.fold_in(kn, 1), meas, *outliers)
        qv = sample_poses(kv, robot, (n_val,)) if q_val is None else q_val
        true = perturb(robot, x, base=base, tool=tool)
        return x, q, meas, qv, fk(true, qv), bad, fk(true, q)

    return jax.vmap(one)(idx, q_each)


def default_chunk(n_robots: int, n_poses: int, n_val: int, n_joints: int, memory_mb: float, n_devices: int) -> int:
    """Robots per study chunk within ``memory_mb``: the chunk's draws (poses, measurements,
    inspection poses) and their few working copies; all robots when they fit, else a power of
    two, at least one per device and at most :data:`MAX_CHUNK_ROBOTS`."""
    per_robot = 8 * (n_poses + n_val) * (16 + n_joints) * 6
    cap = max(int(memory_mb * 2**20 // per_robot), n_devices, 1)
    cap = min(2 ** int(np.log2(cap)), MAX_CHUNK_ROBOTS)
    return int(n_robots if n_robots <= cap else cap)


MAX_CHUNK_ROBOTS = 8192
"""Most robots per study chunk: a chunk is also the unit of work lost to an interruption."""


def run_montecarlo(
    robot: Robot,
    *,
    n_robots: int = 1000,
    n_poses: int = 100,
    n_val: int = 50,
    sigma_pos: float = 0.02,
    sigma_rot: float = 2e-5,
    method: str = "gn",
    seed: int = 0,
    position_only: bool = False,
    estimate_base: bool = False,
    estimate_tool: bool = False,
    q=None,
    repeats: int = 3,
    memory_mb: float = 1024.0,
    progress=None,
    devices: str | int | None = "all",
    out=None,
    chunk_robots: int | None = None,
    max_chunks: int | None = None,
    region=None,
    view=None,
    min_spread: float = 0.0,
    q_val=None,
    outliers: float = 0.0,
    outlier_mm=(3.0, 6.0),
    keep_outliers: bool = False,
) -> dict:
    """Simulate ``n_robots`` robots, calibrate them all, and summarise against the truth and the
    Cramér–Rao bound.

    The robots are drawn, calibrated and summarised in chunks of ``chunk_robots`` (default: as
    many as fit in ``memory_mb``, :func:`default_chunk`), so memory does not grow with
    ``n_robots``; each chunk is shared over ``devices`` (:func:`jaxcal.calibrate_batch`). With
    ``out`` (a folder), each chunk's results are written as it completes and a rerun continues
    where the last stopped (:class:`._study.StudyFolder`); ``max_chunks`` stops after that many
    chunks of this call (a job with a time limit). The simulated robots carry DH errors, and base
    and tool errors when those are estimated. ``q`` gives the calibration poses of every robot
    (``(K, n)``, e.g. a pose design) instead of drawing them. ``progress(done, total, stage)`` is
    called as robots complete.

    Timing: the first chunk of this call includes compiling; the later chunks are warm runs. A
    call that computes a single chunk reruns it ``repeats`` times to time it warm (the chunk,
    never the whole study). ``compile_seconds`` = the first chunk's time minus its warm estimate.

    Conditions, as for :func:`jaxcal.design.optimal_poses`: ``region`` (a box), ``view`` (a
    camera's view cone) and ``min_spread`` constrain each robot's random poses, drawn by the
    design's sampler (:class:`jaxcal.design.PoseSampler`); ``q_val (V, n)`` are the inspection
    poses of every robot (where the calibrated arm will work) instead of ``n_val`` random ones.
    The summary's ``conditions`` says which were used, and ``crlb_validation_pos_rms_mm`` is
    the inspection RMS the Cramér–Rao bound predicts (first order, at the nominal robot).

    Outliers: ``outliers`` the share of each robot's poses given a gross position error of
    ``outlier_mm = (A, B)`` mm (:func:`jaxcal.simulation.inject_outliers`); the calibration finds
    and leaves them out unless ``keep_outliers``; the summary counts the poses flagged, injected
    or not (``outliers_found``, ``outliers_missed``, ``false_alarms``).
    """
    from ..solvers import METHODS

    for name, v in (("robots", n_robots), ("poses", n_poses), ("val_poses", n_val), ("repeats", repeats + 1)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise DataError(f"{name} must be an integer >= 1, got {v!r}", option=name)
    for name, v in (("chunk_robots", chunk_robots), ("max_chunks", max_chunks)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1):
            raise DataError(f"{name} must be an integer >= 1, got {v!r}", option=name)
    methods = METHODS + ("elimination", "elimination-literal")
    if method not in methods:
        raise DataError(f"method must be one of {', '.join(methods)}, got {method!r}", option="method")
    for name, v in (("noise_mm", sigma_pos), ("noise_rad", sigma_rot)):
        if not (np.isfinite(v) and v >= 0):
            raise DataError(f"{name} must be >= 0, got {v}", option=name)
    if not (np.isfinite(memory_mb) and memory_mb > 0):
        raise DataError(f"memory_mb must be > 0, got {memory_mb}", option="memory_mb")
    devs = select_devices(devices)
    step = progress or (lambda done, total, stage: None)
    noisy = sigma_pos > 0 or (sigma_rot > 0 and not position_only)  # position-only: no rotation measured
    if noisy and not position_only and min(sigma_pos, sigma_rot) == 0:
        zero, other = ("noise_mm", "rotation") if sigma_pos == 0 else ("noise_rad", "position")
        raise DataError(
            f"{zero} is 0 but the {other} noise is not: with one noise-free component the fit's weights and the "
            f"Cramer-Rao bound are degenerate; give both > 0, or both 0 for a noise-free study",
            option=zero,
        )
    design = None
    if method.startswith("elimination"):  # its pair design; n_poses sets the pairs per step
        if q is not None:
            raise DataError(
                f"method {method} calibrates on its own pair design: given calibration poses need a least-squares "
                f"method ({', '.join(METHODS)})",
                option="method",
            )
        asked = n_poses
        design = (max(1, (n_poses - 2) // (2 * (robot.n_joints - 1))), 2)
        n_poses = 2 * (robot.n_joints - 1) * design[0] + design[1]
    elif q is not None:
        q = np.asarray(as_f64(q, "q"))
        if q.ndim != 2 or q.shape[1] != robot.n_joints or not np.all(np.isfinite(q)):
            raise DataError(f"q must be finite with shape (K, {robot.n_joints}), got {q.shape}", option="q")
        n_poses = q.shape[0]
    sampler, q_val, conditions = _conditions(robot, q, q_val, region, view, min_spread, position_only, n_poses, seed)
    if sampler is not None and design is not None:
        raise DataError(
            "region, view and min_spread need random poses, not the elimination's pair design", option="method"
        )
    if design is not None:
        conditions["calibration_poses"] = (
            f"the elimination's pair design, random per robot: {design[0]} pair(s) per step and {design[1]} "
            f"undifferenced = {n_poses} poses" + (f" (of the {asked} asked)" if asked != n_poses else "")
        )
    n_val = n_val if q_val is None else len(q_val)
    definition = {
        "robot": robot.name,
        "robot_fingerprint": fingerprint(robot.stripped()),
        "method": method,
        "n_robots": n_robots,
        "n_poses": n_poses,
        "n_val": n_val,
        "noise": {"sigma_pos_mm": sigma_pos, "sigma_rot_rad": sigma_rot},
        "seed": seed,
        "position_only": position_only,
        "estimate_base": estimate_base,
        "estimate_tool": estimate_tool,
        "poses_fingerprint": None if q is None else fingerprint(q),
        **({"conditions": conditions} if conditions["constrained"] or q_val is not None else {}),
        "chunk_robots": chunk_robots or default_chunk(n_robots, n_poses, n_val, robot.n_joints, memory_mb, len(devs)),
    }
    gross = _gross(outliers, outlier_mm, n_poses)  # (count, A, B) or None; in the definition only when used
    if gross is not None:
        definition["outliers"] = {"fraction": outliers, "outlier_mm": list(gross[1:])}
    if keep_outliers:
        definition["keep_outliers"] = True
    folder = StudyFolder(out, definition) if out is not None else None
    c = folder.chunk_robots if folder is not None else definition["chunk_robots"]
    n_chunks = -(-n_robots // c)
    done = folder.done(n_chunks) if folder is not None else np.zeros(n_chunks, bool)
    opts = Options(
        method=method,
        estimate_base=estimate_base,
        estimate_tool=estimate_tool,
        params="all",
        sigma_pos_mm=sigma_pos if noisy else None,
        sigma_rot_rad=sigma_rot if noisy and not position_only else None,
        memory_mb=memory_mb,
        keep_outliers=keep_outliers,
    )
    stripped = robot.stripped()
    scales = error_scales(robot, base=estimate_base, tool=estimate_tool)

    def draw(i):  # chunk i, the last padded to a whole chunk by repeating its last robot: one compile
        idx = np.minimum(np.arange(i * c, (i + 1) * c), n_robots - 1)
        kw = dict(n_poses=n_poses, n_val=n_val, base=estimate_base, tool=estimate_tool, design=design, outliers=gross)
        sigmas = np.array([sigma_pos, sigma_rot])
        q_each = None if sampler is None else sampler.sets(idx)
        return [
            np.asarray(a)
            for a in _draw(stripped, jax.random.PRNGKey(seed), idx, scales, q, q_each, q_val, sigmas, **kw)
        ]

    ident = identify(robot, draw(0)[1][0], opts, n_points=int(position_only))  # on robot 0's poses
    base_idx = list(ident.base)
    acc = _Sums.empty(len(base_idx))
    for i in np.flatnonzero(done):
        acc.add(folder.load(int(i), n_robots))
    step(acc.n, n_robots, "robots")
    first, warm, computed = None, [], 0
    t_start = time.perf_counter()
    for i in np.flatnonzero(~done):
        if max_chunks is not None and computed >= max_chunks:
            break
        x_true, q_i, meas, q_val_i, true_val, bad, true_q = draw(int(i))
        measured = _measured(meas, position_only)
        t0 = time.perf_counter()
        res = calibrate_batch(robot, q_i, measured, opts, ident=ident, devices=devs)
        dt = time.perf_counter() - t0
        if first is None:
            first = (len(q_i), dt, (q_i, measured))
        else:  # warm chunks time themselves: the first chunk's data are not needed again
            warm.append((len(q_i), dt))
            first = first[:2] + (None,)
        nonlinear = estimate_base or estimate_tool or position_only or robot.convention == "joint"
        exact = _truth_exactly(robot, q_i, true_q, position_only, opts, ident, devs) if nonlinear else None
        rec = _record(
            robot, res, x_true, q_i, q_val_i, true_val, ident, sigma_pos, sigma_rot, noisy, q_val is not None,
            keep_outliers,
        )  # fmt: skip
        if exact is not None:  # the base-set errors against the truths' own coordinates
            fine = np.isfinite(exact[:, base_idx])
            rec["err"] = np.where(fine, res.x[:, base_idx] - exact[:, base_idx], rec["err"])
        rec |= _flag_counts(res, bad)
        n_i = min(c, n_robots - i * c)  # without the padding
        rec = {k: v[:n_i] for k, v in rec.items()}
        rec["robots"] = np.array([i * c, i * c + n_i])
        if folder is not None:
            folder.save(int(i), rec)
        acc.add(rec)
        computed += 1
        step(acc.n, n_robots, "robots")
    wall = time.perf_counter() - t_start
    if first is not None and not warm:  # one chunk: time it again, warm (that chunk alone)
        for r in range(repeats):
            step(r, repeats, "timing")
            t0 = time.perf_counter()
            calibrate_batch(robot, *first[2], opts, ident=ident, devices=devs)
            warm.append((first[0], time.perf_counter() - t0))
    described = ("robot", "method", "n_robots", "n_poses", "n_val", "noise", "seed")
    described += ("position_only", "estimate_base", "estimate_tool")
    described += tuple(k for k in ("outliers", "keep_outliers") if k in definition)
    out_d = {k: definition[k] for k in described} | {
        "conditions": conditions,
        "elimination_pairs_per_step": None if design is None else design[0],
        "devices": describe(devs),
        "chunk_robots": c,
        "chunks": n_chunks,
        "chunks_done": int(done.sum()) + computed,
        "chunks_computed": computed,
        "complete": acc.n == n_robots,
        **_timing(first, warm, wall),
        "rank": ident.rank,
        "n_params": len(ident.names),
        "fixed": [ident.names[k] for k in ident.fixed],
        "combinations": list(ident.combinations),
        **acc.summary([ident.names[k] for k in base_idx], noisy),
        "machine": machine_info(),
    }
    if q is not None:  # given poses that leave a joint still: every fit holds what only it separates
        out_d["still_joints"] = list(still_joint_notes(robot, q))
    if folder is not None and out_d["complete"]:
        folder.write_summary(out_d)
    return out_d


def _conditions(robot, q, q_val, region, view, min_spread, position_only, n_poses, seed):
    """The study's conditions: a sampler of each robot's poses (None: uniform within the
    limits, or given), the checked inspection poses, and their description for the summary."""
    from ..design import constraints, feasible, workspace

    cons = constraints(min_spread, region, view)
    constrained = cons.has_region or float(cons.spread) > 0
    sampler = None
    if q is None:
        sampler = study_sampler(robot, n_poses, seed=seed, position_only=position_only, constraints=cons)
    if q_val is not None:
        q_val = np.asarray(check_q(robot, as_f64(q_val, "q_val")))
        if q_val.ndim != 2 or len(q_val) < 1:
            raise DataError(
                f"q_val must have shape (V, {robot.n_joints}) with V >= 1, got {q_val.shape}", option="q_val"
            )
    view_doc = None
    if cons.has_view:
        far = float(cons.view_far)
        view_doc = {
            "origin_mm": np.asarray(cons.view_origin).tolist(),
            "axis": np.asarray(cons.view_axis).tolist(),
            "half_angle_deg": float(np.degrees(cons.view_half_angle)),
            "near_mm": float(cons.view_near),
            "far_mm": far if far < np.finfo(np.float64).max else None,
        }
    doc = {
        "constrained": constrained,
        "calibration_poses": "given" if q is not None else "random, constrained" if constrained else "random",
        "region": [np.asarray(cons.box_lower).tolist(), np.asarray(cons.box_upper).tolist()] if cons.has_box else None,
        "view": view_doc,
        "min_spread": float(cons.spread),
        "acceptance": None if sampler is None else sampler.acceptance,
        "validation_poses": "random per robot" if q_val is None else "given",
        "validation_fingerprint": None if q_val is None else fingerprint(q_val),
    }
    if q is not None and constrained:
        doc["given_poses_meet_conditions"] = feasible(workspace(robot, int(position_only)), cons, q)
    return sampler, q_val, doc


def study_sampler(
    robot: Robot,
    n_poses: int,
    *,
    seed: int = 0,
    position_only: bool = False,
    region=None,
    view=None,
    min_spread: float = 0.0,
    constraints=None,
):
    """The sampler of the robots' poses in a study with these conditions
    (:class:`jaxcal.design.PoseSampler`; robot ``i`` calibrates on ``.sets([i])[0]``), or None
    when they are not constrained (uniform within the joint limits). ``constraints``: already
    checked ones (:func:`jaxcal.design.constraints`) instead of the three options."""
    from ..design import PoseSampler, workspace
    from ..design import constraints as make_constraints

    cons = make_constraints(min_spread, region, view) if constraints is None else constraints
    if not cons.has_region and float(cons.spread) == 0:
        return None
    key = jax.random.fold_in(jax.random.PRNGKey(seed), SAMPLER_STREAM)  # apart from the robots' own draws
    return PoseSampler(workspace(robot, int(position_only)), cons, n_poses, key)


SAMPLER_STREAM = 0x5A3


def _gross(fraction, outlier_mm, n_poses: int):
    """``(poses per robot, A, B)`` of the outlier injection, None without; checked."""
    from ..errors import DataError

    if isinstance(fraction, bool) or not isinstance(fraction, (int, float, np.number)) or not 0 <= fraction <= 1:
        raise DataError(f"outliers must be a share of the poses in [0, 1], got {fraction!r}", option="outliers")
    lo_hi = np.asarray(outlier_mm, float) if np.shape(outlier_mm) == (2,) else np.full(2, np.nan)
    if not 0 <= lo_hi[0] <= lo_hi[1] < np.inf:
        raise DataError(f"outlier_mm must be A,B with 0 <= A <= B (mm), got {outlier_mm!r}", option="outlier_mm")
    n = outlier_count(fraction, n_poses)
    return (n, float(lo_hi[0]), float(lo_hi[1])) if n else None


def _flag_counts(res, bad) -> dict:
    """Per robot: injected outliers flagged, injected ones missed, clean poses flagged."""
    flag = np.zeros_like(bad) if res.outlier_mask is None else res.outlier_mask
    return {"flags": np.stack([(flag & bad).sum(1), (~flag & bad).sum(1), (flag & ~bad).sum(1)], 1)}


def _measured(meas, position_only: bool):
    return meas[..., :3, 3] if position_only else meas


def _truth_exactly(robot, q, true_poses, position_only: bool, opts, ident, devs):
    """``(R, m)`` each simulated truth's own coordinates in the base set: a Gauss-Newton fit of its
    true poses at its calibration poses, whatever the study's method (a one-step method's truth
    would share its bias); NaN where it did not converge (the truth is then mapped linearly). With
    the base or the tool estimated, the frames absorb DH errors nonlinearly, and a linear map of
    the truth misses by more than the noise moves a well-determined frame parameter; so do the
    combinations of points alone (``theta5 - c a5``: the flange's turn is not measured) and those
    of joint frames (``offset1 + rz1 - ry2``: turns of successive frames compose, not add)."""
    exact = dataclasses.replace(opts, method="gn", keep_outliers=True, sigma_pos_mm=None, sigma_rot_rad=None)
    res = calibrate_batch(robot, q, _measured(true_poses, position_only), exact, ident=ident, devices=devs)
    return np.where(res.converged[:, None], res.x, np.nan)


def _record(
    robot, res, x_true, q, q_val, true_val, ident, sigma_pos, sigma_rot, noisy, shared_val=False, keep_outliers=False
) -> dict:
    """One chunk's results: per robot the estimates, truths, base-set errors (against the truth
    mapped linearly), convergence and inspection RMS; the chunk's sum of Cramér–Rao covariances."""
    layout = res.layout
    x_t = _true_x(x_true, layout)
    err = res.x[:, list(ident.base)] - x_t @ ident.combination_matrix.T  # what the base set estimates
    val = _validation_rms(
        robot.stripped(), jnp.asarray(res.x), jnp.asarray(q_val), jnp.asarray(true_val), layout=layout
    )
    rec = {
        "x": res.x,
        "x_true": x_t,
        "err": err,
        "converged": res.converged,
        "steps": res.num_steps,
        "val_rms": np.asarray(val),
    }
    if noisy:  # each robot's bound on the base set's variances, and on its inspection error
        # of the poses its fit used: a pose left out as an outlier informs nothing
        kept = None if res.outlier_mask is None or keep_outliers else ~np.asarray(res.outlier_mask)
        N = _base_information(robot, q, ident, layout, sigma_pos, sigma_rot, x_t, kept)
        if kept is not None and (lost := _singular(N)).any():  # so many left out that nothing bounds it:
            # the bound of all its poses (finite) for such a robot; its fit on the rest was singular too
            N[lost] = _base_information(robot, np.asarray(q)[lost], ident, layout, sigma_pos, sigma_rot, x_t[lost])
        rec["crlb_var"] = _variances(N)
        pts = _points(layout, len(x_t), x_t)
        one = shared_val and not (layout.n_points and layout.tool)  # the same inspection for every robot
        qv, pts = (q_val[:1], None if pts is None else pts[:1]) if one else (q_val, pts)
        S = _position_moments(robot.stripped(), jnp.asarray(qv), pts, layout=layout, base=tuple(ident.base))
        rec["crlb_val2"] = _validation_crlb(N, np.asarray(S))
    return rec


MIN_EFFICIENCY_ROBOTS = 3
"""Fewest robots whose squared errors give a CRLB efficiency: the ratio of the bound to a mean of
``n`` squared errors is biased up by about ``n / (n - 2)``, without bound below three."""
FEW_EFFICIENCY_ROBOTS = 30
"""Below this many robots the summary notes that the efficiency is biased up and uncertain
(``crlb_efficiency_note``, which the CLI prints as a warning)."""


DOMINATED_SE = 0.5
"""A parameter's efficiency whose relative standard error is beyond this rests on a few robots
whose bounds dominate the sum (poses that barely separate it for them): the summary names it
(``crlb_efficiency_note``), where ``sqrt(2 / n)`` is under 0.26 at 30 robots."""


class _Sums:
    """Running sums over chunks, from which the summary follows (memory independent of the
    robot count)."""

    def __init__(self, r: int):
        self.n, self.conv, self.max_steps = 0, 0, 0
        self.err2, self.val2, self.crlb, self.crlb2 = np.zeros(r), 0.0, np.zeros(r), np.zeros(r)
        self.crlb_val2 = 0.0
        self.flags = np.zeros(3, int)  # outliers found, missed, false alarms

    @classmethod
    def empty(cls, r: int) -> _Sums:
        return cls(r)

    def add(self, rec: dict) -> None:
        self.n += len(rec["err"])
        self.conv += int(np.sum(rec["converged"]))
        self.max_steps = max(self.max_steps, int(np.max(rec["steps"])))
        self.err2 = self.err2 + np.sum(rec["err"] ** 2, 0)
        self.val2 += float(np.sum(rec["val_rms"] ** 2))
        if "crlb_var" in rec:
            self.crlb = self.crlb + np.sum(rec["crlb_var"], 0)
            self.crlb2 = self.crlb2 + np.sum(rec["crlb_var"] ** 2, 0)
        if "crlb_val2" in rec:
            self.crlb_val2 += float(np.sum(rec["crlb_val2"]))
        if "flags" in rec:
            self.flags = self.flags + np.sum(rec["flags"], 0)

    def summary(self, names, noisy: bool) -> dict:
        n = max(self.n, 1)
        rms = np.sqrt(self.err2 / n)
        out = {
            "robots_done": self.n,
            "converged_fraction": self.conv / n,
            "max_steps_taken": self.max_steps,
            "param_rms_error": dict(zip(names, rms.tolist())),
            "param_rms_error_max": float(rms.max()),
            "validation_pos_rms_mm": float(np.sqrt(self.val2 / n)),
            **dict(zip(("outliers_found", "outliers_missed", "false_alarms"), map(int, self.flags))),
        }
        if noisy and self.n >= MIN_EFFICIENCY_ROBOTS:
            eff = (self.crlb / n) / (self.err2 / n)
            out["crlb_efficiency"] = dict(zip(names, eff.tolist()))
            out["crlb_efficiency_mean"] = float(eff.mean())
            worst = int(np.argmin(eff))
            out["crlb_efficiency_worst"] = {"parameter": names[worst], "efficiency": float(eff[worst])}
            # each figure is a bound over a sum of squared errors of variances c_i (the bound met):
            # relative spread sqrt(2 sum c_i^2) / sum c_i, sqrt(2 / n) when the robots' bounds are
            # equal, larger where a few robots' bounds dominate; biased up by about n / (n - 2)
            rel = np.sqrt(2.0 * self.crlb2) / np.where(self.crlb > 0, self.crlb, np.nan)
            out["crlb_efficiency_rel_se_each"] = dict(zip(names, rel.tolist()))
            out["crlb_efficiency_rel_se"] = float(np.nanmax(rel))
        if noisy:
            out["crlb_validation_pos_rms_mm"] = float(np.sqrt(self.crlb_val2 / n))
        shaky = [k for k, v in out.get("crlb_efficiency_rel_se_each", {}).items() if v > DOMINATED_SE]
        if noisy and self.n >= FEW_EFFICIENCY_ROBOTS and shaky:
            out["crlb_efficiency_note"] = (
                f"the CRLB efficiency of {', '.join(shaky)} rests on a few robots whose bounds dominate the sum "
                f"(relative standard error up to {out['crlb_efficiency_rel_se']:.2g}): their poses barely separate "
                "these parameters (a measured point near a joint's axis?), and each such figure is one or two "
                "squared errors; the other parameters' figures hold"
            )
        if noisy and self.n < FEW_EFFICIENCY_ROBOTS:
            out["crlb_efficiency_note"] = (
                f"{self.n} robot(s): the CRLB efficiency "
                + (
                    f"needs at least {MIN_EFFICIENCY_ROBOTS}"
                    if self.n < MIN_EFFICIENCY_ROBOTS
                    else "is biased up (about n / (n - 2)) and uncertain"
                )
                + f"; use {FEW_EFFICIENCY_ROBOTS} robots or more (--robots)"
            )
        return out


def _timing(first, warm, wall: float) -> dict:
    """Speed of this call's chunks: warm robots per second, compile time apart."""
    if first is None:  # nothing left to compute
        return {
            "robots_per_second": None,
            "run_seconds": None,
            "run_seconds_all": [],
            "compile_seconds": None,
            "first_call_seconds": None,
            "wall_seconds": wall,
        }
    runs = [t for _, t in warm]
    rate = sum(n for n, _ in warm) / sum(runs) if warm else None  # no warm run: not measured
    return {
        "robots_per_second": rate,
        "run_seconds": statistics.median(runs) if runs else None,
        "run_seconds_all": runs,
        "compile_seconds": None if rate is None else max(first[1] - first[0] / rate, 0.0),
        "first_call_seconds": first[1],
        "wall_seconds": wall,
    }
