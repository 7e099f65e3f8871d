"""Pose design where the arm works: a camera's view cone and a box, judged by Monte Carlo at
validation poses inside them (docs/design.md, "Constrained workspaces").

    nice -n 10 python benchmarks/bench_design_regions.py [--robots 500] [--out docs/bench/design_regions]

On UR5 and Panda, for a view cone that admits 10-30 % of random configurations and for a box
that is a quarter of the reachable workspace (the quadrant x, y >= 0), in two calibration
settings (full pose with the base and tool known; position only with both estimated): 25 poses
designed by gradient (``jaxcal.design.optimal_poses`` with its defaults: 4 starts, each the
exchange selection of 1,000 random configurations in the region, refined by BFGS) and 25
selected from a pool of 1,000 random configurations in the region, against 25/50/75/100 random
poses drawn in the region per robot (the design's sampler); every pose set calibrated on the
same simulated robots (``run_montecarlo``, GN, noise 0.02 mm and 2e-5 rad) and inspected at
the same 200 random validation poses in the region. Beside each Monte Carlo figure the CRLB
prediction (``crlb_validation_pos_rms_mm``); "bound" is the best any 25 poses can do there
(``jaxcal.design.design_bound`` over 10,000 random configurations in the region); "random
poses to match" interpolates the random pose sets' figures (log RMS against log count).

Then, for the view cone, why the gain is what it is: the design's CRLB from random starts (the
default without a region), more starts, more steps, a minimum spread, the D criterion, against
the bound (here over twice the candidates) and the D-optimal relaxed design.

Writes ``OUT.txt`` (the tables) and ``OUT.json`` (every figure).
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
from _util import print_machine

import jaxcal
from jaxcal import design
from jaxcal.experiments import run_montecarlo, study_sampler

N = 25
KS = (25, 50, 75, 100)
SEED = 7
VIEW = ([1500.0, 0.0, 600.0], [-1100.0, 0.0, -200.0], float(np.radians(10.0)))
"""A camera 1.5 m in front of the arm, 0.6 m up, looking at (400, 0, 400) mm; half-angle 10 deg."""
BOXES = {
    "ur5": ([0.0, 0.0, -1100.0], [1100.0, 1100.0, 1100.0]),
    "panda": ([0.0, 0.0, -400.0], [1200.0, 1200.0, 1300.0]),
}
"""The quadrant x, y >= 0 of each arm's reach: a quarter of its workspace."""
SETTINGS = {
    "full pose, frames known": dict(position_only=False, estimate_base=False, estimate_tool=False),
    "position only, frames estimated": dict(position_only=True, estimate_base=True, estimate_tool=True),
}


def conditions(name: str) -> dict:
    return {"view cone": dict(view=VIEW), "box": dict(region=BOXES[name])}


def problem_of(robot, setting: dict, q_val):
    return design.design_problem(
        robot,
        n_points=int(setting["position_only"]),
        estimate_base=setting["estimate_base"],
        estimate_tool=setting["estimate_tool"],
        sigma_pos_mm=0.02,
        sigma_rot_rad=2e-5,
        q_val=q_val,
    )


def matching(ks, rms, target) -> float:
    """Random poses whose interpolated RMS equals ``target`` (log-log; extrapolated beyond)."""
    return design.matching_count(ks, -np.log(rms), -np.log(target))


def study(args, robot, cond: str, where: dict, label: str, setting: dict, out: dict) -> None:
    kw = dict(n_points=int(setting["position_only"]), **where)
    q_val = design.random_poses(robot, 200, seed=SEED, **kw)
    problem = problem_of(robot, setting, q_val)
    acc = study_sampler(robot, N, seed=SEED, position_only=setting["position_only"], **where).acceptance
    t0 = time.perf_counter()
    grad = design.optimal_poses(problem, N, seed=SEED, **where)
    t_grad = time.perf_counter() - t0
    pool = design.random_poses(robot, args.pool, seed=SEED + 1, **kw)
    t0 = time.perf_counter()
    sel = design.select_poses(problem, pool, N, seed=SEED, **where)
    t_sel = time.perf_counter() - t0
    bound = design.design_bound(problem, design.random_poses(robot, args.candidates, seed=SEED + 2, **kw), N)
    ideal = design.evaluate(problem, design.random_poses(robot, 4000, seed=SEED + 3, **kw))["validation_rms_mm"]

    def mc(**extra):
        r = run_montecarlo(robot, n_robots=args.robots, seed=SEED, repeats=0, q_val=q_val, **setting, **where, **extra)
        assert r["converged_fraction"] > 0.99, r["converged_fraction"]
        return r["validation_pos_rms_mm"], r["crlb_validation_pos_rms_mm"]

    rand = np.array([mc(n_poses=k) for k in KS])  # (4, 2): MC, CRLB
    rows = {"gradient design": (grad, t_grad), f"pool selection (of {args.pool})": (sel, t_sel)}
    res = {k: mc(q=d.q) for k, (d, _) in rows.items()}
    rec = {
        "acceptance": acc,
        "base_parameters": len(grad.base_names),
        "random": {str(k): list(r) for k, r in zip(KS, rand)},
        "bound": bound["bound"],
        "bound_support": bound["support"],
    }
    print(
        f"\n{robot.name}, {cond} ({acc:.0%} of random configurations admitted), {label}: "
        f"{grad.q.shape[1]} joints, {len(grad.base_names)} base parameters",
        flush=True,
    )
    print(f"  {'pose set':<30} {'poses':>5} {'MC validation RMS mm':>21} {'CRLB mm':>9} {'random poses to match':>22} "
          f"{'design s':>9}")  # fmt: skip
    for k, (m, c) in zip(KS, rand):
        print(f"  {'random, in the region':<30} {k:>5} {m:>21.5f} {c:>9.5f}")
    for what, (d, sec) in rows.items():
        m, c = res[what]
        match = matching(KS, rand[:, 0], m)
        rec[what] = {"mc": m, "crlb": c, "random_poses_to_match": match, "seconds": sec, "feasible": d.feasible}
        print(f"  {what:<30} {N:>5} {m:>21.5f} {c:>9.5f} {match:>22.1f} {sec:>9.1f}", flush=True)
    b = bound["bound"]
    b_match = matching(KS, rand[:, 1], b)  # a CRLB against the random sets' CRLB
    g_crlb = res["gradient design"][1]
    print(f"  {'bound (any 25 poses)':<30} {N:>5} {'':>21} {b:>9.5f} {b_match:>22.1f}")
    print(f"  ideal random poses (random poses' information without the small-sample loss): "
          f"{4000 * ideal**2 / g_crlb**2:.1f} for the design's CRLB")  # fmt: skip
    beat = res["gradient design"][0] <= rand[1, 0]
    print(
        f"  designed {N} no worse than random 50 (MC): {'yes' if beat else 'NO'}; design's CRLB "
        f"{100 * (g_crlb / b - 1):.1f} % above the bound, which random {b_match:.0f} poses match"
    )
    rec.update(bound_random_poses_to_match=b_match, ideal_random_poses=4000 * ideal**2 / g_crlb**2)
    rec.update(designed_beats_random_50=bool(beat), design_above_bound=g_crlb / b - 1)
    out[f"{robot.name} | {cond} | {label}"] = rec


def why(args, robot, label: str, setting: dict, out: dict) -> None:
    """The view cone: the design's CRLB by method, against the bound and random information."""
    kw = dict(n_points=int(setting["position_only"]), view=VIEW)
    q_val = design.random_poses(robot, 200, seed=SEED, **kw)
    problem = problem_of(robot, setting, q_val)
    cands = design.random_poses(robot, 2 * args.candidates, seed=SEED + 2, **kw)  # twice the study's
    bound = design.design_bound(problem, cands, N)
    d_bound = design.design_bound(design.with_criterion(problem, "d"), cands, N)
    variants = {
        "4 random starts, 500 steps (no pool)": dict(start_pool=0),
        "16 random starts, 500 steps": dict(start_pool=0, starts=16),
        "4 random starts, 2000 steps": dict(start_pool=0, max_steps=2000),
        "4 pool starts (default)": {},
        "4 pool starts, min spread 0.3 rad": dict(min_spread=0.3),
        "4 pool starts, criterion d": dict(criterion="d"),
    }
    print(f"\nwhy: {robot.name}, view cone, {label}: CRLB validation RMS of 25 poses (mm)", flush=True)
    print(f"  bound (criterion validation) over {len(cands)} candidates {bound['bound']:.5f}; the D-optimal "
          f"relaxed design's {d_bound['relaxed']['validation_rms_mm']:.5f}")  # fmt: skip
    rec = {"bound": bound["bound"], "d_relaxed_validation": d_bound["relaxed"]["validation_rms_mm"]}
    for what, v in variants.items():
        v = dict(v)
        pb = design.with_criterion(problem, v.pop("criterion", "validation"))
        t0 = time.perf_counter()
        d = design.optimal_poses(pb, N, seed=SEED, view=VIEW, n_random=50, **v)
        sec = time.perf_counter() - t0
        val = d.values["validation_rms_mm"]
        print(f"  {what:<40} {val:.5f} ({100 * (val / bound['bound'] - 1):+5.1f} % vs bound) "
              f"feasible {d.feasible}, {sec:.0f} s", flush=True)  # fmt: skip
        rec[what] = {"crlb": val, "seconds": sec, "feasible": d.feasible}
    out[f"why | {robot.name} | {label}"] = rec


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", type=int, default=500)
    p.add_argument("--pool", type=int, default=1000)
    p.add_argument("--candidates", type=int, default=10000)
    p.add_argument("--arms", default="ur5,panda")
    p.add_argument("--out", default=None, help="write OUT.json (every figure)")
    args = p.parse_args()
    print_machine()
    print(f"load average at start {os.getloadavg()[0]:.1f}")
    out: dict = {}
    t0 = time.perf_counter()
    for name in args.arms.split(","):
        robot = jaxcal.preset(name)
        for label, setting in SETTINGS.items():
            for cond, where in conditions(name).items():
                study(args, robot, cond, where, label, setting, out)
            why(args, robot, label, setting, out)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s, load average at end {os.getloadavg()[0]:.1f}")
    if args.out:
        with open(args.out + ".json", "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
