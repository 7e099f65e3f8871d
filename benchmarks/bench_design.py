"""Optimal pose design validated by Monte Carlo: on each arm, N poses designed by gradient
(criterion: the expected validation position error from the Cramér–Rao bound) and N poses
selected from a pool of random candidates, against random N, 2N, 3N, 4N poses; every pose set is
calibrated on the same simulated robots (``jaxcal.experiments.run_montecarlo``), and the
validation RMS (tool position, 50 random validation poses per robot) compared. Then the time to
design 30 poses for the 7-joint Panda, compile apart from run.

    python benchmarks/bench_design.py [--robots 500] [--poses 25] [--pool 1000] [--starts 4]

Two calibration settings per arm: full pose with the base and tool known (the ``jaxcal
montecarlo`` default), and position only with the base and tool estimated (a laser tracker).
Noise 0.02 mm per coordinate, 2e-5 rad per axis. The random pose sets are drawn per robot,
uniform within the joint limits, as the validation poses are. "random poses to match" is where
the random pose sets' validation RMS, interpolated linearly in log RMS against log K, equals
the design's. "ideal random poses" is the design's CRLB validation error expressed as a count of
random poses without the finite-sample penalty (the information of 2,000 random poses scaled to
the count): how much a design can gain over random poses at all.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from _util import print_machine

import jaxcal
from jaxcal import design
from jaxcal.experiments import run_montecarlo

SETTINGS = {
    "full pose, frames known": dict(position_only=False, estimate_base=False, estimate_tool=False),
    "position only, base and tool estimated": dict(position_only=True, estimate_base=True, estimate_tool=True),
}
SEED = 7


def problem_of(robot, setting: dict):
    return design.design_problem(
        robot,
        n_points=int(setting["position_only"]),
        estimate_base=setting["estimate_base"],
        estimate_tool=setting["estimate_tool"],
        sigma_pos_mm=0.02,
        sigma_rot_rad=2e-5,
        seed=SEED,
    )


def mc(robot, setting, args, **kw) -> float:
    out = run_montecarlo(robot, n_robots=args.robots, n_val=50, seed=SEED, repeats=0, **setting, **kw)
    assert out["converged_fraction"] > 0.99, out["converged_fraction"]
    return out["validation_pos_rms_mm"]


def matching(ks, rms, target) -> str:
    """Random poses whose interpolated validation RMS equals ``target`` (log-log)."""
    if target >= rms[0]:
        return f"<= {ks[0]}"
    k = design.matching_count(ks, -np.log(rms), -np.log(target))
    return f"{k:.0f}" if target >= rms[-1] else f"> {ks[-1]} (extrapolated {k:.0f})"


def validate(args) -> None:
    N = args.poses
    ks = [N, 2 * N, 3 * N, 4 * N]
    rng = np.random.default_rng(SEED)
    for name in ("paper-6r", "ur5", "panda"):
        robot = jaxcal.preset(name)
        lim = np.asarray(robot.q_limits)
        pool = lim[:, 0] + rng.uniform(size=(args.pool, len(lim))) * (lim[:, 1] - lim[:, 0])
        wide = lim[:, 0] + rng.uniform(size=(2000, len(lim))) * (lim[:, 1] - lim[:, 0])
        for label, setting in SETTINGS.items():
            problem = problem_of(robot, setting)
            t0 = time.perf_counter()
            grad = design.optimal_poses(problem, N, starts=args.starts, seed=SEED)
            t_grad = time.perf_counter() - t0
            t0 = time.perf_counter()
            sel = design.select_poses(problem, pool, N, seed=SEED)
            t_sel = time.perf_counter() - t0
            ideal = design.evaluate(problem, wide)["validation_rms_mm"] ** 2 * len(wide)
            rand = np.array([mc(robot, setting, args, n_poses=k) for k in ks])
            rows = [("gradient design", grad, t_grad), (f"pool selection (of {args.pool})", sel, t_sel)]
            verdict = "NO"
            print(f"\n{name}, {label}: {grad.q.shape[1]} joints, {len(grad.base_names)} base parameters", flush=True)
            print(f"  {'pose set':<30} {'poses':>5} {'MC validation RMS mm':>21} {'CRLB mm':>9} "
                  f"{'random poses to match':>28} {'ideal random poses':>19} {'design s':>9}")  # fmt: skip
            for k, r in zip(ks, rand):
                print(f"  {'random':<30} {k:>5} {r:>21.5f}")
            for what, d, sec in rows:
                got = mc(robot, setting, args, q=d.q)
                if d is grad:
                    verdict = "yes" if got <= rand[2] else "NO"
                crlb = d.values["validation_rms_mm"]
                print(
                    f"  {what:<30} {N:>5} {got:>21.5f} {crlb:>9.5f} {matching(ks, rand, got):>28} "
                    f"{ideal / crlb**2:>19.1f} {sec:>9.1f}",
                    flush=True,
                )
            print(f"  designed {N} no worse than random {3 * N} (MC): {verdict}")


def timing(args) -> None:
    robot = jaxcal.preset("panda")
    problem = design.design_problem(robot)  # calibrate's defaults: full pose, base and tool estimated
    out = []
    for seed in (0, 1):
        load = os.getloadavg()[0]
        t0 = time.perf_counter()
        d = design.optimal_poses(problem, 30, starts=args.starts, seed=seed)
        out.append((time.perf_counter() - t0, load, d))
    (first, l1, _), (run, l2, d) = out
    print(
        f"\ndesign 30 poses, panda (7 joints, {len(d.base_names)} base parameters, base and tool estimated), "
        f"{args.starts} starts, {d.details['max_evaluations']} BFGS evaluations:\n"
        f"  first call {first:.1f} s (load {l1:.1f}), second call (run only) {run:.1f} s (load {l2:.1f}), "
        f"compile about {first - run:.1f} s; under 30 s: {'yes' if first < 30 else 'NO'}"
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", type=int, default=500)
    p.add_argument("--poses", type=int, default=25)
    p.add_argument("--pool", type=int, default=1000)
    p.add_argument("--starts", type=int, default=4)
    p.add_argument("--skip-validation", action="store_true")
    args = p.parse_args()
    print_machine()
    print(f"load average at start {os.getloadavg()[0]:.1f}")
    timing(args)
    if not args.skip_validation:
        validate(args)


if __name__ == "__main__":
    main()
