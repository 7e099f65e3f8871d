"""Monte Carlo study: many simulated robots calibrated in one compiled, vmapped call, compared
with the simulated truth and with the Cramér–Rao bound."""

from __future__ import annotations

import statistics
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..calibrate import calibrate_batch, identify
from ..error_model import identification_jacobian, perturb
from ..identifiability import base_covariance, row_sigmas
from ..kinematics import fk
from ..robot import Robot
from ..simulate import simulate
from .machine import machine_info


@eqx.filter_jit
def _validation_rms(robot, x, q_val, true_val, *, base, tool):
    """Position RMS (mm) of each calibrated model ``x (R, m)`` vs its true robot on the
    inspection poses; compiled once per robot structure and batch shape."""

    def one(x_, q_, true_):
        T = fk(perturb(robot, x_, base=base, tool=tool), q_)
        return jnp.sqrt(jnp.mean(jnp.sum((T[..., :3, 3] - true_[..., :3, 3]) ** 2, -1)))

    return jax.vmap(one)(x, q_val, true_val)


def _crlb_batch(robot, q, ident, *, position_only, base, tool, sigma_pos, sigma_rot):
    """Cramér–Rao covariance of the base parameters for each robot's pose set (at the
    nominal model), averaged over robots: :func:`jaxcal.identifiability.crlb` for all robots at
    once (:func:`jaxcal.identifiability.base_covariance` on the stacked Jacobians)."""
    J = np.asarray(jax.vmap(lambda q_: identification_jacobian(robot, q_, position_only=position_only,
                                                               base=base, tool=tool))(jnp.asarray(q)))
    sig = row_sigmas(q.shape[1], position_only=position_only, sigma_pos_mm=sigma_pos,
                     sigma_rot_rad=None if position_only else sigma_rot).reshape(-1)
    Jb = J.reshape(J.shape[0], -1, J.shape[-1])[..., list(ident.base)] / sig[:, None]
    return np.mean(base_covariance(Jb), axis=0)


def run_montecarlo(robot: Robot, *, n_robots: int = 1000, n_poses: int = 100, n_val: int = 50,
                   sigma_pos: float = 0.02, sigma_rot: float = 2e-5, method: str = "gn", seed: int = 0,
                   position_only: bool = False, estimate_base: bool = False, estimate_tool: bool = False,
                   repeats: int = 3, progress=None) -> dict:
    """Simulate ``n_robots`` robots, calibrate them all in one call, and summarise.

    ``progress(stage: str)`` is called before each stage (for a display). Timing: the first
    call (compile + run) and ``repeats`` further runs; ``compile_seconds`` = first - median run.
    """
    step = progress or (lambda s: None)
    noisy = sigma_pos > 0 or sigma_rot > 0
    step("simulating")
    q = None
    if method.startswith("elimination"):
        # the elimination method needs its pair design; n_poses sets the pairs per step
        from ..design import design_poses

        n_pairs = max(1, (n_poses - 2) // (2 * (robot.n_joints - 1)))
        q = design_poses(jax.random.fold_in(jax.random.PRNGKey(seed), 7), robot, n_pairs=n_pairs, n_abs=2,
                         batch_shape=(n_robots,))
        n_poses = int(q.shape[-2])
    sim = simulate(robot, n_robots=n_robots, n_poses=n_poses, n_val=n_val, seed=seed, sigma_pos=sigma_pos,
                   sigma_rot=sigma_rot, base=estimate_base, tool=estimate_tool, q=q)
    ident = identify(robot, sim.q[0], position_only=position_only, estimate_base=estimate_base,
                     estimate_tool=estimate_tool)
    kw = dict(method=method, estimate_base=estimate_base, estimate_tool=estimate_tool, position_only=position_only,
              sigma_pos_mm=sigma_pos if noisy else None, sigma_rot_rad=sigma_rot if noisy else None, ident=ident)
    step("compiling (first call)")
    t0 = time.perf_counter()
    res = calibrate_batch(robot, sim.q, sim.measured, **kw)
    first = time.perf_counter() - t0
    runs = []
    for i in range(repeats):
        step(f"timing run {i + 1}/{repeats}")
        t0 = time.perf_counter()
        res = calibrate_batch(robot, sim.q, sim.measured, **kw)
        runs.append(time.perf_counter() - t0)
    run_s = statistics.median(runs)
    step("evaluating")
    base_idx = list(ident.base)
    target = sim.x_true @ ident.combination_matrix.T           # what the base set estimates
    err = res.x[:, base_idx] - target                           # (R, r)
    names = [ident.names[i] for i in base_idx]
    out = {
        "robot": robot.name, "method": method, "n_robots": n_robots, "n_poses": n_poses, "n_val": n_val,
        "noise": {"sigma_pos_mm": sigma_pos, "sigma_rot_rad": sigma_rot}, "seed": seed,
        "position_only": position_only, "estimate_base": estimate_base, "estimate_tool": estimate_tool,
        "robots_per_second": n_robots / run_s, "run_seconds": run_s, "run_seconds_all": runs,
        "compile_seconds": max(first - run_s, 0.0), "first_call_seconds": first,
        "converged_fraction": float(res.converged.mean()), "max_steps_taken": int(res.num_steps.max()),
        "rank": ident.rank, "n_params": len(ident.names), "fixed": [ident.names[i] for i in ident.fixed],
        "combinations": list(ident.combinations),
        "param_rms_error": dict(zip(names, np.sqrt(np.mean(err ** 2, 0)).tolist())),
        "param_rms_error_max": float(np.sqrt(np.mean(err ** 2, 0)).max()),
        "validation_pos_rms_mm": float(np.sqrt(np.mean(np.asarray(_validation_rms(
            robot, res.x, sim.q_val, sim.true_val, base=estimate_base, tool=estimate_tool)) ** 2))),
        "machine": machine_info(),
    }
    if noisy:
        cov = _crlb_batch(robot, sim.q, ident, position_only=position_only, base=estimate_base,
                          tool=estimate_tool, sigma_pos=sigma_pos, sigma_rot=sigma_rot)
        emp = np.mean(err ** 2, 0)
        eff = np.diag(cov) / emp
        out["crlb_efficiency"] = dict(zip(names, eff.tolist()))
        out["crlb_efficiency_mean"] = float(eff.mean())
    return out
