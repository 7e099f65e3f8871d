"""Robots per second of batched Gauss–Newton and Levenberg–Marquardt: R simulated arms x K poses
each, calibrated by :func:`jaxcal.calibrate_batch`. Baseline in the same run: the same
Gauss–Newton through optimistix letting JAX differentiate through forward kinematics (no
analytic JVP), vmapped over the robots in one compiled call.

    python benchmarks/bench_gn_batch.py [--robots 1000] [--poses 100] [--repeats 3] [--lm-robots 200]

Full-pose data of the paper's arm with 0.02 mm / 2e-5 rad noise, base and tool known. Both sides
fit the identifiable set of the first robot's poses with weights ``1 / sigma``, Gauss–Newton on
the normal equations (Cholesky) over columns scaled to equal norm at the start, tolerances
1e-8: the same solve, apart from where its Jacobian comes from. ``calibrate_batch`` includes
its input checks and runs in chunks of robots; the baseline is the bare vmapped solve.
Levenberg–Marquardt takes several times GN's steps, so it runs on the first ``--lm-robots`` data
sets of the same batch (robots/s is per its own count).
"""

from __future__ import annotations

import argparse
import statistics

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
from _util import compile_text, print_machine, summary, timed

import jaxcal
from jaxcal.calibration import identify
from jaxcal.error_model import identification_jacobian, perturb, pose_error

SP, SR = 0.02, 2e-5
SCALED_NORM = 1e3
"""Norm of every scaled column at the start, as in :func:`jaxcal.solvers.fit` (its tolerances
then mean the same on both sides)."""


def autodiff_gn(robot, free, q0):
    """Vmapped optimistix GN on the weighted pose residual, its Jacobian by autodiff through FK."""
    m = 4 * robot.n_joints
    w = jnp.array([1 / SP] * 3 + [1 / SR] * 3)
    free_idx = jnp.asarray(free)
    # column scaling from the nominal Jacobian on the first robot's poses, as calibrate_batch does
    J0 = np.asarray(identification_jacobian(robot, q0))[..., list(free)] * np.asarray(w)[:, None]
    scale = jnp.asarray(SCALED_NORM / np.sqrt(np.sum(J0**2, axis=(0, 1))))
    solver = optx.GaussNewton(rtol=1e-8, atol=1e-8, linear_solver=lx.Normal(lx.Cholesky()))

    def one(q, meas):
        def fn(z, _):
            x = jnp.zeros(m).at[free_idx].set(scale * z)
            return (pose_error(meas, jaxcal.fk(perturb(robot, x), q)) * w).reshape(-1)

        sol = optx.least_squares(fn, solver, jnp.zeros(len(free)), max_steps=50, throw=False)
        x = jnp.zeros(m).at[free_idx].set(scale * sol.value)
        return x, sol.result == optx.RESULTS.successful, sol.stats["num_steps"]

    return jax.jit(jax.vmap(one))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--robots", type=int, default=1000)
    ap.add_argument("--poses", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--lm-robots", type=int, default=200, help="data sets of the LM row (the first ones)")
    args = ap.parse_args()
    robot = jaxcal.preset("paper-6r")
    sim = jaxcal.simulate(robot, n_robots=args.robots, n_poses=args.poses, n_val=1, seed=0, sigma_pos=SP, sigma_rot=SR)
    ident = identify(robot, sim.q[0], estimate_base=False, estimate_tool=False)
    print_machine()
    print(
        f"paper-6r, {args.robots} robots x {args.poses} poses, full pose, noise {SP} mm / {SR} rad, "
        f"{len(ident.base)} parameters; {args.repeats} warm calls each"
    )

    def jaxcal_call(method, R):
        return lambda: jaxcal.calibrate_batch(
            robot,
            sim.q[:R],
            sim.measured[:R],
            method=method,
            sigma_pos_mm=SP,
            sigma_rot_rad=SR,
            estimate_base=False,
            estimate_tool=False,
            ident=ident,
        )

    base_fn = autodiff_gn(robot, ident.base, sim.q[0])
    q, meas = jnp.asarray(sim.q), jnp.asarray(sim.measured)
    R_lm = min(args.lm_robots, args.robots)
    rows = {
        "jaxcal gn (calibrate_batch)": (jaxcal_call("gn", args.robots), args.robots),
        f"jaxcal lm (calibrate_batch, {R_lm} robots)": (jaxcal_call("lm", R_lm), R_lm),
        "baseline gn (autodiff through FK)": (lambda: base_fn(q, meas), args.robots),
    }
    speed, xs = {}, {}
    for name, (call, R) in rows.items():
        out, first, runs = timed(call, repeats=args.repeats, result=True)
        x, ok, steps = (out.x, out.converged, out.num_steps) if hasattr(out, "x") else out
        speed[name], xs[name] = R / statistics.median(runs), np.asarray(x)
        print(
            f"{name:40s} {summary(runs)} -> {speed[name]:8,.0f} robots/s; "
            f"{compile_text(first, runs)}; converged {np.mean(ok):.0%}, max steps {int(np.max(steps))}",
            flush=True,
        )
    base = "baseline gn (autodiff through FK)"
    gap = np.max(np.abs(xs["jaxcal gn (calibrate_batch)"] - xs[base]))
    print(f"largest difference of the GN estimates, jaxcal vs baseline: {gap:.1e} (mm / rad)")
    for name in rows:
        print(f"robots/s vs baseline: {name:42s} {speed[name] / speed[base]:5.2f}x")


if __name__ == "__main__":
    main()
