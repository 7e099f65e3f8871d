"""Cost curves (issue 7.2): time vs number of poses (one robot) and vs number of robots in one
vmapped batch (100 poses each), for FK, the identification Jacobian, one-shot least squares,
Gauss–Newton and robust elimination, on the paper's arm (full-pose data, 0.02 mm / 2e-5 rad
noise). Writes a log-log plot and the numbers, and prints the fitted exponent ``b`` of
``time ~ size^b`` over the largest three sizes (where fixed per-call overhead no longer
dominates) and over the whole range.

    python benchmarks/bench_scaling.py [--max-poses 100000] [--max-robots 10000]
        [--out docs/bench]   # writes scaling.json, scaling.png

The solvers are timed through the public :func:`jaxcal.calibrate_batch` (input checks, the
solve, residual/outlier report; the identifiability analysis is computed once beforehand
and passed in). Elimination runs on its own pair designs (``10 P`` poses for ``P`` pairs per
step), sized to the same pose counts. Each point: first call (compile + run), then the median
of warm repeats (3 to 21: as many as fit in 0.25 s, 3 at least, 1 when a warm call takes over 2 s;
until 2026-11-24 always 3, and FK's exponents moved 0.5-0.85 between runs); compile = first call minus
the warm median.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxcal
from jaxcal import design
from jaxcal import simulate as S
from jaxcal.calibrate import calibrate_batch, identify
from jaxcal.error_model import identification_jacobian, perturb
from _util import block, machine

SP, SR = 0.02, 2e-5
OPS = ("FK", "Jacobian", "one-shot LS", "GN", "elimination")


def time_point(fn):
    t0 = time.perf_counter()
    block(fn())
    first = time.perf_counter() - t0
    runs = []
    while len(runs) < 21:  # 3 warm runs at least, more while they add up to under 0.25 s
        t0 = time.perf_counter()
        block(fn())
        runs.append(time.perf_counter() - t0)
        if runs[0] > 2.0 or (len(runs) >= 3 and sum(runs) > 0.25):  # one warm run is enough above 2 s
            break
    med = statistics.median(runs)
    return {"median_s": med, "min_s": min(runs), "max_s": max(runs), "compile_s": max(first - med, 0.0),
            "repeats": len(runs)}


def workloads(robot, R, K, seed):
    """Callables for every op on R robots x K poses (R = 1: a single data set)."""
    m = 4 * robot.n_joints
    pairs = max(K // (2 * (robot.n_joints - 1)), 1)
    q_el = np.asarray(design.design_poses(jax.random.PRNGKey(seed), robot, n_pairs=pairs, n_abs=0))
    q_uni = np.asarray(S.sample_poses(jax.random.PRNGKey(seed + 1), robot, (K,)))
    sim = S.simulate(robot, n_robots=R, q=q_uni, seed=seed, sigma_pos=SP, sigma_rot=SR, n_val=1)
    sim_el = S.simulate(robot, n_robots=R, q=q_el, x_true=sim.x_true, seed=seed + 2, sigma_pos=SP, sigma_rot=SR,
                        n_val=1)
    ident = identify(robot, q_uni)
    X = jnp.asarray(sim.x_true)
    Q = jnp.broadcast_to(jnp.asarray(q_uni), (R, K, robot.n_joints))
    fk_b = jax.jit(jax.vmap(lambda x, q: jaxcal.fk(perturb(robot, x), q)))
    jac_b = jax.jit(jax.vmap(lambda x, q: identification_jacobian(perturb(robot, x), q)))
    cal = lambda method, s: (lambda: calibrate_batch(robot, s.q, s.measured, method=method, sigma_pos_mm=SP,
                                                     sigma_rot_rad=SR, ident=None if method == "elimination"
                                                     else ident).x)
    assert X.shape == (R, m)
    return {"FK": lambda: fk_b(X, Q), "Jacobian": lambda: jac_b(X, Q), "one-shot LS": cal("linear", sim),
            "GN": cal("gn", sim), "elimination": cal("elimination", sim_el)}, q_el.shape[0]


def exponent(sizes, times, last=3):
    x, y = np.log(np.asarray(sizes, float)), np.log(np.asarray(times, float))
    return float(np.polyfit(x[-last:], y[-last:], 1)[0]), float(np.polyfit(x, y, 1)[0])


def sweep(robot, label, sizes, make, seed):
    res = {op: [] for op in OPS}
    for s in sizes:
        fns, k_el = make(s)
        for op in OPS:
            r = time_point(fns[op])
            r["size"] = s
            if op == "elimination":
                r["design_poses"] = k_el
            res[op].append(r)
            print(f"{label} {s:>7d} {op:12s} median {r['median_s'] * 1e3:11.3f} ms (min {r['min_s'] * 1e3:.3f}, "
                  f"max {r['max_s'] * 1e3:.3f}, n={r['repeats']})  compile {r['compile_s']:6.2f} s", flush=True)
    return res


def plot(results, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, (key, xlabel) in zip(axes, (("poses", "poses (one robot)"), ("robots", "robots in one batch (100 poses each)"))):
        for op in OPS:
            pts = results[key]["points"][op]
            sizes = [p["size"] for p in pts]
            ax.loglog(sizes, [p["median_s"] for p in pts], "o-", label=f"{op} (b = {results[key]['exponent'][op]['last3']:.2f})")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("warm median time (s)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"jaxcal cost curves, paper arm, {results['machine']['cores']}-core {results['machine']['platform']}"
                 f" (jax {results['machine']['jax']}); b: exponent over the largest 3 sizes")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--max-poses", type=int, default=100_000)
    ap.add_argument("--max-robots", type=int, default=10_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="docs/bench")
    args = ap.parse_args()
    robot = jaxcal.preset("paper-6r")
    print("machine:", machine())
    decades = lambda top: [10 ** e for e in range(1, 7) if 10 ** e <= top]
    pose_sizes = decades(args.max_poses)
    robot_sizes = [1] + decades(args.max_robots)
    results = {"machine": machine(), "arm": "paper-6r", "noise": [SP, SR]}
    results["poses"] = {"points": sweep(robot, "poses ", pose_sizes, lambda K: workloads(robot, 1, K, args.seed),
                                        args.seed)}
    results["robots"] = {"points": sweep(robot, "robots", robot_sizes, lambda R: workloads(robot, R, 100, args.seed),
                                         args.seed)}
    print("\nexponent b of time ~ size^b (largest 3 sizes | whole range)")
    for key in ("poses", "robots"):
        results[key]["exponent"] = {}
        for op in OPS:
            pts = results[key]["points"][op]
            e3, eall = exponent([p["size"] for p in pts], [p["median_s"] for p in pts])
            results[key]["exponent"][op] = {"last3": e3, "all": eall}
            print(f"  vs {key:6s} {op:12s} b = {e3:5.2f} | {eall:5.2f}")
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "scaling.json"), "w") as f:
        json.dump(results, f, indent=1)
    plot(results, os.path.join(args.out, "scaling.png"))
    print(f"wrote {args.out}/scaling.json, {args.out}/scaling.png")


if __name__ == "__main__":
    main()
