"""Robots/second of vmapped Gauss–Newton (issue 3): R simulated paper arms x K poses each,
calibrated in one compiled call. Baseline in the same run: the same optimistix GN letting JAX
differentiate through forward kinematics (no analytic JVP). jaxcal GN and LM are also timed
in a fresh process with ``GLIBC_TUNABLES=glibc.malloc.hugetlb=1`` (``--envs``): XLA's buffers
for the whole batch are fresh memory on every call, faulted in 4 KiB at a time without it.
Each row counts the minor page faults of one call.

    python benchmarks/bench_gn_batch.py [--robots 1000] [--poses 100] [--repeats 5] [--envs ...]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

import jaxcal
from jaxcal.calibrate import calibrate_batch, identify
from jaxcal.error_model import perturb, pose_error
from jaxcal.simulate import simulate
from _util import HUGETLB, compile_text, machine, summary, timed


def autodiff_gn(robot, free, m, sp, sr):
    w = jnp.array([1 / sp] * 3 + [1 / sr] * 3)
    free_idx = jnp.asarray(free)

    def one(q, meas):
        def fn(y, args):
            x = jnp.zeros(m).at[free_idx].set(y)
            return (pose_error(meas, jaxcal.fk(perturb(robot, x), q)) * w).reshape(-1)

        sol = optx.least_squares(fn, optx.GaussNewton(1e-8, 1e-10, linear_solver=lx.QR()), jnp.zeros(len(free)),
                                 max_steps=50, throw=False)
        return sol.value, sol.result == optx.RESULTS.successful, sol.stats["num_steps"]

    return jax.jit(jax.vmap(one))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--robots", type=int, default=1000)
    ap.add_argument("--poses", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--envs", nargs="*", default=[HUGETLB],
                    help="environment settings, each timing jaxcal gn and lm in a fresh process")
    ap.add_argument("--_child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    robot = jaxcal.preset("paper-6r")
    sp, sr = 0.02, 2e-5
    sim = simulate(robot, n_robots=args.robots, n_poses=args.poses, seed=0, sigma_pos=sp, sigma_rot=sr)
    ident = identify(robot, sim.q[0])
    names = ("jaxcal gn (analytic JVP)", "jaxcal lm (analytic JVP)", "baseline gn (autodiff through FK)")
    if args._child:
        names = names[:2]
    else:
        print("machine:", machine())
        print(f"{args.robots} robots x {args.poses} poses, full pose, noise {sp} mm / {sr} rad")

    results = {}
    for name in names:
        if name.startswith("baseline"):
            f = autodiff_gn(robot, tuple(ident.base), 24, sp, sr)
            call = lambda: jax.block_until_ready(f(jnp.asarray(sim.q), jnp.asarray(sim.measured)))
        else:
            method = name.split()[1]
            call = lambda method=method: calibrate_batch(robot, sim.q, sim.measured, method=method, sigma_pos_mm=sp,
                                                         sigma_rot_rad=sr, ident=ident)
        first, runs = timed(call, repeats=args.repeats)
        before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        out = call()
        faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
        med = statistics.median(runs)
        conv = out.converged.mean() if hasattr(out, "converged") else float(np.mean(out[1]))
        steps = out.num_steps.max() if hasattr(out, "num_steps") else int(np.max(out[2]))
        results[name] = med
        if args._child:
            print(json.dumps({"name": name, "runs": runs, "first_s": first, "faults": faults,
                              "converged": float(conv)}))
            continue
        print(f"{name:36s} {summary(runs)}  -> {args.robots / med:8,.0f} robots/s; {compile_text(first, runs)};"
              f" converged {conv:.0%}, max steps {steps}; {faults:,} page faults/call")
    if args._child:  # only the in-process rows: a child never spawns children
        return
    for env in args.envs:  # read by glibc at process start: a fresh process each
        cmd = [sys.executable, __file__, "--_child", "--robots", str(args.robots), "--poses", str(args.poses),
               "--repeats", str(args.repeats), "--envs"]
        p = subprocess.run(cmd, env=dict(os.environ, **dict([env.split("=", 1)])), capture_output=True, text=True)
        if p.returncode != 0:
            print(f"{env}: failed ({(p.stderr.strip().splitlines() or ['?'])[-1][:160]})")
            continue
        for line in p.stdout.strip().splitlines():
            if not line.startswith("{"):
                continue
            r = json.loads(line)
            med = statistics.median(r["runs"])
            name = f"{r['name'].split(' (')[0]}, {env}"
            results[name] = med
            print(f"{name:36s} {summary(r['runs'])}  -> {args.robots / med:8,.0f} robots/s; "
                  f"{compile_text(r['first_s'], r['runs'])}; converged {r['converged']:.0%}; {r['faults']:,} page faults/call")
    base = results["baseline gn (autodiff through FK)"]
    for name, med in results.items():
        print(f"speed-up vs baseline: {name:36s} {base / med:5.2f}x")


if __name__ == "__main__":
    main()
