"""Monte Carlo study: many simulated robots calibrated in one compiled, vmapped solve, compared
with the simulated truth and with the Cramér–Rao bound."""

from __future__ import annotations

import statistics
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..calibration import Options, calibrate_batch, identify
from ..error_model import perturb
from ..identifiability import base_covariance, row_sigmas
from ..kinematics import fk
from ..model import Layout, Model, jacobian
from ..robot import Robot
from ..simulation import simulate
from ..solvers import design_poses
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


def crlb_batch(robot: Robot, q, ident, layout: Layout, *, sigma_pos: float, sigma_rot: float | None) -> np.ndarray:
    """Cramér–Rao covariance of the base parameters for each robot's pose set ``q (R, K, n)`` at
    the nominal model, averaged over robots: :func:`jaxcal.identifiability.crlb` for all robots
    at once (:func:`jaxcal.identifiability.base_covariance` on the stacked Jacobians)."""
    J = np.asarray(_jacobians(robot.stripped(), jnp.asarray(q), layout=layout))
    R, K = np.shape(q)[:2]
    sig = row_sigmas(
        K,
        position_only=layout.n_points > 0,
        sigma_pos_mm=sigma_pos,
        sigma_rot_rad=None if layout.n_points else sigma_rot,
    )
    Jb = J.reshape(R, -1, J.shape[-1])[..., list(ident.base)] / sig[:, None]
    return np.mean(base_covariance(Jb), axis=0)


def _true_x(robot: Robot, sim, layout: Layout) -> np.ndarray:
    """The simulated truth in the calibration's layout: a tool twist becomes the tool point's
    offset for position data."""
    x = np.asarray(sim.x_true)
    if not (layout.n_points and layout.tool):
        return x
    k = layout.n_kin + 6 * layout.base
    return x[:, : k + 3]  # the tool's translation is the point's offset (perturb's chart)


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
) -> dict:
    """Simulate ``n_robots`` robots, calibrate them all, and summarise against the truth and the
    Cramér–Rao bound.

    The simulated robots carry DH errors, and base and tool errors when those are estimated.
    ``q`` gives the calibration poses of every robot (``(K, n)``, e.g. a pose design) instead of
    drawing them. ``progress(stage: str)`` is called before each stage. Timing: the first call
    (compile + run) and ``repeats`` further runs; ``compile_seconds`` = first - median run.
    """
    from ..errors import DataError
    from ..solvers import METHODS

    for name, v in (("robots", n_robots), ("poses", n_poses), ("val_poses", n_val), ("repeats", repeats + 1)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise DataError(f"{name} must be an integer >= 1, got {v!r}", option=name)
    methods = METHODS + ("elimination", "elimination-literal")
    if method not in methods:
        raise DataError(f"method must be one of {', '.join(methods)}, got {method!r}", option="method")
    for name, v in (("noise_mm", sigma_pos), ("noise_rad", sigma_rot)):
        if not (np.isfinite(v) and v >= 0):
            raise DataError(f"{name} must be >= 0, got {v}", option=name)
    step = progress or (lambda s: None)
    noisy = sigma_pos > 0 or sigma_rot > 0
    step("simulating")
    if method.startswith("elimination"):
        # the elimination method needs its pair design; n_poses sets the pairs per step
        n_pairs = max(1, (n_poses - 2) // (2 * (robot.n_joints - 1)))
        q = design_poses(
            jax.random.fold_in(jax.random.PRNGKey(seed), 7), robot, n_pairs=n_pairs, n_abs=2, batch_shape=(n_robots,)
        )
    if q is not None:
        n_poses = int(np.shape(q)[-2])
    sim = simulate(
        robot,
        n_robots=n_robots,
        n_poses=n_poses,
        n_val=n_val,
        seed=seed,
        sigma_pos=sigma_pos,
        sigma_rot=sigma_rot,
        base=estimate_base,
        tool=estimate_tool,
        q=q,
    )
    measured = sim.measured[..., :3, 3] if position_only else sim.measured
    opts = Options(
        method=method,
        estimate_base=estimate_base,
        estimate_tool=estimate_tool,
        params="all",
        sigma_pos_mm=sigma_pos if noisy else None,
        sigma_rot_rad=sigma_rot if noisy else None,
        memory_mb=memory_mb,
    )
    ident = identify(robot, sim.q[0], opts, n_points=int(position_only))
    step("compiling (first call)")
    t0 = time.perf_counter()
    res = calibrate_batch(robot, sim.q, measured, opts, ident=ident)
    first = time.perf_counter() - t0
    runs = []
    for i in range(repeats):
        step(f"timing run {i + 1}/{repeats}")
        t0 = time.perf_counter()
        res = calibrate_batch(robot, sim.q, measured, opts, ident=ident)
        runs.append(time.perf_counter() - t0)
    run_s = statistics.median(runs) if runs else first
    step("evaluating")
    layout = res.layout
    base_idx = list(ident.base)
    x_true = _true_x(robot, sim, layout)
    target = x_true @ ident.combination_matrix.T  # what the base set estimates
    err = res.x[:, base_idx] - target  # (R, r)
    names = [ident.names[i] for i in base_idx]
    out = {
        "robot": robot.name,
        "method": method,
        "n_robots": n_robots,
        "n_poses": n_poses,
        "n_val": n_val,
        "noise": {"sigma_pos_mm": sigma_pos, "sigma_rot_rad": sigma_rot},
        "seed": seed,
        "position_only": position_only,
        "estimate_base": estimate_base,
        "estimate_tool": estimate_tool,
        "robots_per_second": n_robots / run_s,
        "run_seconds": run_s,
        "run_seconds_all": runs,
        "compile_seconds": max(first - run_s, 0.0),
        "first_call_seconds": first,
        "converged_fraction": float(res.converged.mean()),
        "max_steps_taken": int(res.num_steps.max()),
        "rank": ident.rank,
        "n_params": len(ident.names),
        "fixed": [ident.names[i] for i in ident.fixed],
        "combinations": list(ident.combinations),
        "param_rms_error": dict(zip(names, np.sqrt(np.mean(err**2, 0)).tolist())),
        "param_rms_error_max": float(np.sqrt(np.mean(err**2, 0)).max()),
        "validation_pos_rms_mm": float(
            np.sqrt(
                np.mean(
                    np.asarray(
                        _validation_rms(
                            robot.stripped(),
                            jnp.asarray(res.x),
                            jnp.asarray(sim.q_val),
                            jnp.asarray(sim.true_val),
                            layout=layout,
                        )
                    )
                    ** 2
                )
            )
        ),
        "machine": machine_info(),
    }
    if noisy:
        cov = crlb_batch(robot, sim.q, ident, layout, sigma_pos=sigma_pos, sigma_rot=sigma_rot)
        emp = np.mean(err**2, 0)
        eff = np.diag(cov) / emp
        out["crlb_efficiency"] = dict(zip(names, eff.tolist()))
        out["crlb_efficiency_mean"] = float(eff.mean())
    return out
