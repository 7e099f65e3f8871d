"""Runs a pybotics calibration on a problem written by ``bench_vs_pybotics.py`` (issue 7).

Runs in pybotics' own virtual environment (pybotics pins numpy<2 and cannot share a venv with
jax); it imports neither jax nor jaxcal. The fit is the one pybotics documents: an
``OptimizationHandler`` with a kinematic-chain mask (and a tool mask when the problem has one)
and ``scipy.optimize.least_squares`` on ``pybotics.optimization.optimize_accuracy`` (per-pose
position-error norms, 2-point finite differences, default ``trf`` method and tolerances).

    .venv-pybotics/bin/python benchmarks/pybotics_worker.py PROBLEM.npz RESULT.json [--repeats 3]
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import platform
import statistics
import time

import numpy as np
import scipy
import scipy.optimize
from pybotics.optimization import OptimizationHandler, compute_absolute_errors, optimize_accuracy
from pybotics.robot import Robot
from pybotics.tool import Tool


def build_robot(p) -> Robot:
    robot = Robot.from_parameters(np.array(p["mdh"], dtype=float))  # rows [alpha, a, theta, d]
    robot.tool = Tool(matrix=np.array(p["tool"], dtype=float))
    robot.world_frame = np.array(p["base"], dtype=float)
    return robot


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("problem")
    ap.add_argument("result")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    p = np.load(args.problem)
    q, pos, mask = p["q"], p["positions"], p["mask"].astype(bool)
    tool_mask = p["tool_mask"].astype(bool) if "tool_mask" in p else np.zeros(6, bool)

    # the FK of the nominal model must match jaxcal's before anything is timed
    nominal = build_robot(p)
    fk_nominal = np.array([nominal.fk(qk)[:3, 3] for qk in p["q_check"]])

    times, res = [], None
    for _ in range(args.repeats):
        handler = OptimizationHandler(robot=build_robot(p), kinematic_chain_mask=list(mask), tool_mask=list(tool_mask))
        t0 = time.perf_counter()
        res = scipy.optimize.least_squares(
            fun=optimize_accuracy, x0=handler.generate_optimization_vector(), args=(handler, q, pos)
        )
        times.append(time.perf_counter() - t0)
    handler.apply_optimization_vector(res.x)
    fitted = handler.robot
    val = np.array([fitted.fk(qk)[:3, 3] for qk in p["q_val"]])
    train_err = compute_absolute_errors(qs=q, positions=pos, robot=fitted)
    out = {
        "times_s": times,
        "median_s": statistics.median(times),
        "nfev": int(res.nfev),
        "status": int(res.status),
        "success": bool(res.success),
        "message": str(res.message),
        "x": res.x.tolist(),
        "mdh_fitted": fitted.kinematic_chain.matrix.tolist(),
        "tool_fitted": np.asarray(fitted.tool.matrix).tolist(),
        "val_positions": val.tolist(),
        "train_rms_mm": float(np.sqrt(np.mean(train_err**2))),
        "fk_nominal_check": fk_nominal.tolist(),
        "versions": {
            "pybotics": importlib.metadata.version("pybotics"),
            "numpy": np.__version__,
            "scipy": scipy.__version__,
            "python": platform.python_version(),
        },
    }
    with open(args.result, "w") as f:
        json.dump(out, f)


if __name__ == "__main__":
    main()
