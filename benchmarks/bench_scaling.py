"""Cost curves: time vs the number of poses (one robot) and vs the number of robots in one batch
(100 poses each), for FK, the identification Jacobian, one-shot least squares, Gauss–Newton and
robust elimination on the paper's arm (full-pose data, 0.02 mm / 2e-5 rad noise). Prints the
exponent ``b`` of ``time ~ size^b`` over the largest three sizes (past the fixed per-call cost)
and over the whole range; writes the points to ``scaling.json`` and a log-log plot to
``scaling.png`` in ``--out`` (``run_all.sh`` keeps the printed table as ``scaling.txt`` there).

    python benchmarks/bench_scaling.py [--max-poses 10000] [--max-robots 1000] [--out docs/bench]

FK and the Jacobian are vmapped over perturbed robots (one robot for the poses sweep), as a
batched solve calls them. The solvers run through :func:`jaxcal.calibrate_batch` (input checks,
the solve, the outlier report; the identifiability analysis is done once beforehand and passed
in). Elimination runs on its own pair design, sized to about the same pose count. Each point:
the first call (compile + run) apart, then the median of warm calls (as many as fit in 0.25 s,
3 to 21; one when a call takes over 2 s).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics

import jax
import jax.numpy as jnp
import numpy as np
from _util import compile_s, machine, print_machine, timed

import jaxcal
from jaxcal.calibration import identify
from jaxcal.error_model import identification_jacobian, perturb
from jaxcal.simulation import sample_poses
from jaxcal.solvers import design_poses

SP, SR = 0.02, 2e-5
OPS = ("FK", "Jacobian", "one-shot LS", "GN", "elimination")


def workloads(robot, R, K, seed):
    """A callable per op on R robots x K poses, and the elimination design's pose count."""
    n = robot.n_joints
    pairs = max(K // (2 * (n - 1)), 1)
    q_el = np.asarray(design_poses(jax.random.PRNGKey(seed), robot, n_pairs=pairs, n_abs=0))
    q_uni = np.asarray(sample_poses(jax.random.PRNGKey(seed + 1), robot, (K,)))
    sim = jaxcal.simulate(robot, n_robots=R, q=q_uni, n_val=1, seed=seed, sigma_pos=SP, sigma_rot=SR)
    sim_el = jaxcal.simulate(
        robot, n_robots=R, q=q_el, x_true=sim.x_true, n_val=1, seed=seed + 2, sigma_pos=SP, sigma_rot=SR
    )
    ident = identify(robot, q_uni, estimate_base=False, estimate_tool=False)
    X = jnp.asarray(sim.x_true)
    Q = jnp.broadcast_to(jnp.asarray(q_uni), (R, K, n))
    fk_b = jax.jit(jax.vmap(lambda x, q: jaxcal.fk(perturb(robot, x), q)))
    jac_b = jax.jit(jax.vmap(lambda x, q: identification_jacobian(perturb(robot, x), q)))

    def cal(method, s):
        # elimination builds its own plan from the design; the least-squares methods take the analysis
        kw = {} if method == "elimination" else {"ident": ident}
        return lambda: (
            jaxcal.calibrate_batch(
                robot,
                s.q,
                s.measured,
                method=method,
                sigma_pos_mm=SP,
                sigma_rot_rad=SR,
                estimate_base=False,
                estimate_tool=False,
                **kw,
            ).x
        )

    return {
        "FK": lambda: fk_b(X, Q),
        "Jacobian": lambda: jac_b(X, Q),
        "one-shot LS": cal("linear", sim),
        "GN": cal("gn", sim),
        "elimination": cal("elimination", sim_el),
    }, q_el.shape[0]


def exponent(sizes, times, last=3):
    x, y = np.log(np.asarray(sizes, float)), np.log(np.asarray(times, float))
    return float(np.polyfit(x[-last:], y[-last:], 1)[0]), float(np.polyfit(x, y, 1)[0])


def sweep(label, sizes, make):
    res = {op: [] for op in OPS}
    for s in sizes:
        fns, k_el = make(s)
        for op in OPS:
            first, runs = timed(fns[op], repeats=21, budget_s=0.25)
            med = statistics.median(runs)
            r = {
                "size": s,
                "median_s": med,
                "min_s": min(runs),
                "max_s": max(runs),
                "repeats": len(runs),
                "compile_s": compile_s(first, runs),
            }
            if op == "elimination":
                r["design_poses"] = k_el
            res[op].append(r)
            print(
                f"{label} {s:>7d} {op:12s} median {med * 1e3:11.3f} ms (min {r['min_s'] * 1e3:.3f}, "
                f"max {r['max_s'] * 1e3:.3f}, n={r['repeats']})  compile {r['compile_s']:6.2f} s",
                flush=True,
            )
    return res


def plot(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, (key, xlabel) in zip(
        axes, (("poses", "poses (one robot)"), ("robots", "robots in one batch (100 poses each)"))
    ):
        for op in OPS:
            pts = results[key]["points"][op]
            ax.loglog(
                [p["size"] for p in pts],
                [p["median_s"] for p in pts],
                "o-",
                label=f"{op} (b = {results[key]['exponent'][op]['last3']:.2f})",
            )
        ax.set_xlabel(xlabel)
        ax.set_ylabel("warm median time (s)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    m = results["machine"]
    fig.suptitle(
        f"jaxcal cost curves, paper arm, {m['cores']}-core {m['platform']} (jax {m['jax']}); "
        f"b: exponent over the largest 3 sizes"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--max-poses", type=int, default=10_000)
    ap.add_argument("--max-robots", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="docs/bench")
    args = ap.parse_args()
    robot = jaxcal.preset("paper-6r")
    print_machine()
    decades = lambda top: [10**e for e in range(1, 7) if 10**e <= top]
    results = {"machine": machine(), "arm": "paper-6r", "noise": [SP, SR]}
    results["poses"] = {"points": sweep("poses ", decades(args.max_poses), lambda K: workloads(robot, 1, K, args.seed))}
    results["robots"] = {
        "points": sweep("robots", [1] + decades(args.max_robots), lambda R: workloads(robot, R, 100, args.seed))
    }
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
