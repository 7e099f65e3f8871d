"""Poses/second of forward kinematics and the identification Jacobian: jitted + batched JAX
against a plain NumPy loop over poses, in the same run.

    python benchmarks/bench_kinematics.py [--poses 100000]
"""

from __future__ import annotations

import argparse
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxcal
from jaxcal import error_model as E
from _util import machine, summary, timed


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
    """Geometric identification Jacobian (position + rotation rows), one pose at a time."""
    n = len(dh)
    out = np.empty((len(Q), 6, 4 * n))
    for k, q in enumerate(Q):
        frames, T = [], np.eye(4)
        for (th, d, a, al), qi in zip(dh, q):
            T = T @ np_link(th + qi, d, a, al)
            frames.append(T)
        p_end = T[:3, 3]
        for i, ((th, d, a, al), F) in enumerate(zip(dh, frames)):
            R, p = F[:3, :3], F[:3, 3]
            ca, sa = np.cos(al), np.sin(al)
            local = [(np.array([0, a * ca, -a * sa]), np.array([0, sa, ca])),
                     (np.array([0, sa, ca]), np.zeros(3)), (np.array([1.0, 0, 0]), np.zeros(3)),
                     (np.zeros(3), np.array([1.0, 0, 0]))]
            for j, (v, w) in enumerate(local):
                ws = R @ w
                out[k, :3, 4 * i + j] = R @ v + np.cross(ws, p_end - p)
                out[k, 3:, 4 * i + j] = ws
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--poses", type=int, default=100_000)
    ap.add_argument("--numpy-poses", type=int, default=2_000)
    ap.add_argument("--repeats", type=int, default=51, help="jitted calls timed (7 until 2026-11-24: medians "
                    "moved 2x between runs on a shared VM)")
    args = ap.parse_args()
    robot = jaxcal.preset("paper-6r")
    rng = np.random.default_rng(0)
    Q = jnp.asarray(rng.uniform(-np.pi, np.pi, (args.poses, 6)))
    Qn = np.asarray(Q[: args.numpy_poses])
    dh = np.asarray(robot.dh)

    fk_jit = jax.jit(jaxcal.fk)
    jac_jit = jax.jit(E.identification_jacobian)
    # the NumPy reference must agree with jaxcal before we time anything
    assert np.allclose(np_fk_loop(dh, Qn[:50]), np.asarray(fk_jit(robot, Q[:50])), atol=1e-9)
    assert np.allclose(np_jac_loop(dh, Qn[:50]), np.asarray(jac_jit(robot, Q[:50])), atol=1e-9)

    print("machine:", machine())
    rows = []
    for name, jfn, nfn in (("FK", fk_jit, np_fk_loop), ("identification Jacobian", jac_jit, np_jac_loop)):
        first, runs = timed(jfn, robot, Q, repeats=args.repeats)
        nruns = []
        for _ in range(3):
            t0 = time.perf_counter()
            nfn(dh, Qn)
            nruns.append(time.perf_counter() - t0)
        jax_pps = args.poses / statistics.median(runs)
        np_pps = args.numpy_poses / statistics.median(nruns)
        print(f"{name:24s} jax jit  {args.poses} poses: {summary(runs)}  compile+first {first:.3f} s")
        print(f"{name:24s} numpy loop {args.numpy_poses} poses: {summary(nruns)}")
        print(f"{name:24s} poses/s: jax {jax_pps:,.0f}  numpy {np_pps:,.0f}  ratio {jax_pps / np_pps:,.0f}x")
        rows.append((name, jax_pps, np_pps))


if __name__ == "__main__":
    main()
