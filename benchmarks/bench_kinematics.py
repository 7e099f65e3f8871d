"""Poses per second of forward kinematics and the identification Jacobian: jaxcal (jitted, batched
over poses) against a plain NumPy loop over poses, timed in the same run.

    python benchmarks/bench_kinematics.py [--poses 1000 100000] [--numpy-poses 2000] [--repeats 21]

jaxcal is timed inside ``jax.jit`` (as the solvers call it) at each batch size; the NumPy loop
(one pose at a time, 4x4 products) at ``--numpy-poses``, its rate does not depend on the batch.
Both are checked to agree before anything is timed.
"""

from __future__ import annotations

import argparse
import statistics

import jax
import jax.numpy as jnp
import numpy as np
from _util import compile_text, print_machine, summary, timed

import jaxcal
from jaxcal.error_model import identification_jacobian


def np_link(th, d, a, al):
    ct, st, ca, sa = np.cos(th), np.sin(th), np.cos(al), np.sin(al)
    return np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0, sa, ca, d], [0, 0, 0, 1.0]])


def np_fk_loop(dh, Q):
    out = np.empty((len(Q), 4, 4))
    for k, q in enumerate(Q):
        T = np.eye(4)
        for (th, d, a, al), qi in zip(dh, q):
            T = T @ np_link(th + qi, d, a, al)
        out[k] = T
    return out


def np_jac_loop(dh, Q):
    """Identification Jacobian (position then rotation rows, SDH columns theta, d, a, alpha per
    joint), one pose at a time."""
    n = len(dh)
    out = np.empty((len(Q), 6, 4 * n))
    for k, q in enumerate(Q):
        frames, T = [], np.eye(4)
        for (th, d, a, al), qi in zip(dh, q):
            T = T @ np_link(th + qi, d, a, al)
            frames.append(T)
        p_end = T[:3, 3]
        for i, ((_, _, a, al), F) in enumerate(zip(dh, frames)):
            R, p = F[:3, :3], F[:3, 3]
            ca, sa = np.cos(al), np.sin(al)
            local = [
                (np.array([0, a * ca, -a * sa]), np.array([0, sa, ca])),
                (np.array([0, sa, ca]), np.zeros(3)),
                (np.array([1.0, 0, 0]), np.zeros(3)),
                (np.zeros(3), np.array([1.0, 0, 0])),
            ]
            for j, (v, w) in enumerate(local):
                ws = R @ w
                out[k, :3, 4 * i + j] = R @ v + np.cross(ws, p_end - p)
                out[k, 3:, 4 * i + j] = ws
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--poses", type=int, nargs="+", default=[1000, 100_000], help="batch sizes of the jaxcal calls")
    ap.add_argument("--numpy-poses", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=21)
    args = ap.parse_args()
    robot = jaxcal.preset("paper-6r")
    dh = np.asarray(robot.dh)
    rng = np.random.default_rng(0)
    Q = rng.uniform(-np.pi, np.pi, (max(args.poses + [args.numpy_poses]), 6))

    ops = {
        "FK": (jax.jit(jaxcal.fk), np_fk_loop),
        "identification Jacobian": (jax.jit(identification_jacobian), np_jac_loop),
    }
    for name, (jfn, nfn) in ops.items():  # the baseline must agree with jaxcal before anything is timed
        if not np.allclose(nfn(dh, Q[:50]), np.asarray(jfn(robot, jnp.asarray(Q[:50]))), atol=1e-9):
            raise SystemExit(f"{name}: the NumPy loop and jaxcal disagree")

    print_machine()
    print(
        f"paper-6r (SDH, 6R); jaxcal: jax.jit of the public function, {args.repeats} warm calls per size; "
        f"NumPy: a loop over {args.numpy_poses} poses, 3 calls"
    )
    for name, (jfn, nfn) in ops.items():
        _, nruns = timed(nfn, dh, Q[: args.numpy_poses], repeats=3)
        np_pps = args.numpy_poses / statistics.median(nruns)
        print(f"\n{name}\n  numpy loop   {args.numpy_poses:>7d} poses: {summary(nruns)}  -> {np_pps:14,.0f} poses/s")
        for K in args.poses:
            q = jnp.asarray(Q[:K])
            first, runs = timed(jfn, robot, q, repeats=args.repeats)
            pps = K / statistics.median(runs)
            print(
                f"  jaxcal jit   {K:>7d} poses: {summary(runs)}  -> {pps:14,.0f} poses/s  "
                f"{pps / np_pps:8,.0f}x numpy; {compile_text(first, runs)}"
            )


if __name__ == "__main__":
    main()
