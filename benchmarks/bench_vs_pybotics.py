"""jaxcal against pybotics (issue 7.1): the same simulated robot, poses, measurements and
parameter set; time to a converged calibration and the accuracy reached, both tools.

The problem: the Franka Panda (MDH, 7 joints, flange d = 107 mm as the tool), position-only
measurements (what pybotics fits) with ``--noise-mm`` Gaussian noise per coordinate, true
errors drawn on the position-identifiable DH parameters (jaxcal's base set; the rest is held at
nominal in both tools, so both fit the same parameter set). Accuracy: position RMS of the
calibrated model against the noise-free truth on ``--val`` inspection poses, and the RMS of the
parameter errors.

pybotics pins numpy<2 and runs in its own venv; its fit (``OptimizationHandler`` +
``scipy.optimize.least_squares`` on ``optimize_accuracy``, finite differences, as its docs
show) runs in ``pybotics_worker.py`` and the two talk through files:

    python3 -m venv .venv-pybotics && .venv-pybotics/bin/pip install pybotics
    python benchmarks/bench_vs_pybotics.py [--pybotics-python .venv-pybotics/bin/python]
        [--poses 100] [--val 100] [--noise-mm 0.02] [--repeats 7] [--json OUT.json]

Also timed in the same run: scipy ``least_squares`` with 2-point finite differences on
jaxcal's jitted residual (the stand-in the issue names if pybotics cannot be installed; without
``--pybotics-python`` only this stand-in is compared, and the output says so). "Cold" is a
fresh Python process: ``import jaxcal`` plus the first ``calibrate`` call (compilation).

"Whole processes" (``--processes N``, after the pybotics timings): in turn, ``N`` times each, a
fresh jaxcal process with an empty compilation cache (its own ``XDG_CACHE_HOME``), one with the
cache an earlier process filled, and pybotics' whole process (``pybotics_worker.py --repeats 1``:
interpreter, imports, one fit); wall times from outside, medians and the ratios to pybotics.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
# jaxcal row [theta, d, a, alpha] -> pybotics row [alpha, a, theta, d]
TO_PYB = {0: 2, 1: 3, 2: 1, 3: 0}


def cold_start(problem: str) -> None:
    """Child-process mode: time ``import jaxcal`` and the first calibrate call."""
    t0 = time.perf_counter()
    import numpy as np

    import jaxcal

    t1 = time.perf_counter()
    p = np.load(problem)
    res = jaxcal.calibrate(
        jaxcal.preset("panda"),
        p["q"],
        p["measured"],
        position_only=True,
        method="gn",
        sigma_pos_mm=float(p["noise_mm"]),
        estimate_base=False,
        estimate_tool=False,
    )
    t2 = time.perf_counter()
    print(json.dumps({"import_s": t1 - t0, "first_call_s": t2 - t1, "converged": res.converged}))


def whole_processes(prob_jaxcal: str, pyb_cmd: list[str] | None, n: int, tmp: str) -> dict:
    """Wall seconds of whole processes, run in turn (module docstring): ``jaxcal cold``, ``jaxcal
    warm cache`` and, with ``pyb_cmd``, ``pybotics``. A JAX cache the caller's environment sets is
    removed from the children's, so that cold means cold."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_") and k != "JAXCAL_CACHE"}

    def wall(cmd, **kw):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True, **kw)
        return time.perf_counter() - t0

    jaxcal_cmd = [sys.executable, __file__, "--_cold", prob_jaxcal]
    warm_home = os.path.join(tmp, "warm")
    wall(jaxcal_cmd, env=dict(env, XDG_CACHE_HOME=warm_home))  # fills the warm cache
    out = {"jaxcal cold": [], "jaxcal warm cache": []} | ({"pybotics": []} if pyb_cmd else {})
    for i in range(n):
        out["jaxcal cold"].append(wall(jaxcal_cmd, env=dict(env, XDG_CACHE_HOME=os.path.join(tmp, f"cold{i}"))))
        out["jaxcal warm cache"].append(wall(jaxcal_cmd, env=dict(env, XDG_CACHE_HOME=warm_home)))
        if pyb_cmd:
            out["pybotics"].append(wall(pyb_cmd))
    return out


def make_problem(n_poses, n_val, noise, seed):
    import jax
    import numpy as np

    import jaxcal
    from jaxcal.calibration import identify
    from jaxcal.simulation import error_scales, sample_poses, simulate

    robot = jaxcal.preset("panda")
    kq, kv, kx = jax.random.split(jax.random.PRNGKey(seed), 3)
    q = np.asarray(sample_poses(kq, robot, (n_poses,)))
    q_val = np.asarray(sample_poses(kv, robot, (n_val,)))
    free = np.asarray(identify(robot, q, n_points=1, estimate_base=False, estimate_tool=False).base)
    x_true = np.zeros(4 * robot.n_joints)
    x_true[free] = (error_scales(robot) * np.asarray(jax.random.normal(kx, x_true.shape)))[free]
    sim = simulate(robot, n_poses=n_poses, n_val=n_val, seed=seed, sigma_pos=noise, x_true=x_true, q=q, q_val=q_val)
    return robot, free, sim


def pyb_index(j: int) -> int:
    i, k = divmod(int(j), 4)
    return 4 * i + TO_PYB[k]


def run_pybotics(python, robot, free, sim, noise, repeats, tmp):
    import numpy as np

    dh = np.asarray(robot.dh)
    mdh = dh[:, [3, 2, 0, 1]]
    mask = np.zeros(dh.size, bool)
    mask[[pyb_index(j) for j in free]] = True
    prob = os.path.join(tmp, "pyb_problem.npz")
    np.savez(
        prob,
        mdh=mdh,
        tool=np.asarray(robot.tool),
        base=np.asarray(robot.base),
        q=sim.q[0],
        positions=sim.measured[0, :, :3, 3],
        mask=mask,
        q_val=sim.q_val[0],
        q_check=sim.q_val[0, :20],
    )
    out = os.path.join(tmp, "pyb_result.json")
    subprocess.run([python, os.path.join(HERE, "pybotics_worker.py"), prob, out, "--repeats", str(repeats)], check=True)
    with open(out) as f:
        r = json.load(f)
    # pybotics' fitted parameter errors back in jaxcal's layout
    d = np.asarray(r["mdh_fitted"]) - mdh
    r["x_fit"] = np.stack([d[:, 2], d[:, 3], d[:, 1], d[:, 0]], axis=1).reshape(-1)
    r["command"] = [python, os.path.join(HERE, "pybotics_worker.py"), prob, out, "--repeats", "1"]
    return r


def scipy_fd_standin(robot, free, sim, noise, repeats):
    """scipy least_squares, 2-point finite differences, on jaxcal's jitted position residual."""
    import jax
    import jax.numpy as jnp
    import numpy as np
    import scipy.optimize

    import jaxcal
    from jaxcal.error_model import perturb

    q, meas = jnp.asarray(sim.q[0]), jnp.asarray(sim.measured[0, :, :3, 3])
    free_idx = jnp.asarray(free)

    @jax.jit
    def resid(y):
        x = jnp.zeros(4 * robot.n_joints).at[free_idx].set(y)
        return ((jaxcal.fk(perturb(robot, x), q)[:, :3, 3] - meas) / noise).reshape(-1)

    fun = lambda y: np.asarray(resid(jnp.asarray(y)))
    fun(np.zeros(len(free)))  # compile outside the timing
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        r = scipy.optimize.least_squares(fun, np.zeros(len(free)))
        times.append(time.perf_counter() - t0)
    x = np.zeros(4 * robot.n_joints)
    x[free] = r.x
    return {
        "times_s": times,
        "median_s": statistics.median(times),
        "nfev": int(r.nfev),
        "success": bool(r.success),
        "x_fit": x,
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--pybotics-python", default=os.path.join(os.path.dirname(HERE), ".venv-pybotics/bin/python"))
    ap.add_argument("--poses", type=int, default=100)
    ap.add_argument("--val", type=int, default=100)
    ap.add_argument("--noise-mm", type=float, default=0.02)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--pybotics-repeats", type=int, default=3)
    ap.add_argument("--processes", type=int, default=5, help="whole-process runs of each tool (0: none)")
    ap.add_argument("--json")
    ap.add_argument("--_cold", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args._cold:
        return cold_start(args._cold)

    import numpy as np
    from _util import machine, print_machine, summary, timed

    import jaxcal
    from jaxcal.error_model import perturb

    robot, free, sim = make_problem(args.poses, args.val, args.noise_mm, args.seed)
    x_true = sim.x_true[0]
    truth_val = sim.true_val[0, :, :3, 3]

    def accuracy(x):
        val = np.asarray(jaxcal.fk(perturb(robot, np.asarray(x)), sim.q_val[0]))[:, :3, 3]
        return (
            float(np.sqrt(np.mean(np.sum((val - truth_val) ** 2, -1)))),
            float(np.sqrt(np.mean((np.asarray(x)[free] - x_true[free]) ** 2))),
        )

    print_machine()
    print(
        f"panda (MDH, 7R), {args.poses} poses, position-only, noise {args.noise_mm} mm, "
        f"{len(free)} parameters (jaxcal's identifiable set, same mask in every tool)"
    )
    rows = {}

    # jaxcal: warm runs of the public calibrate(), and a cold process
    call = lambda: jaxcal.calibrate(
        robot,
        sim.q[0],
        sim.measured[0],
        position_only=True,
        method="gn",
        sigma_pos_mm=args.noise_mm,
        estimate_base=False,
        estimate_tool=False,
    )
    first, runs = timed(call, repeats=args.repeats)
    res = call()
    rows["jaxcal gn (calibrate)"] = {
        "median_s": statistics.median(runs),
        "times_s": runs,
        "x_fit": res.x,
        "success": res.converged,
        "steps": res.num_steps,
    }
    print(
        f"jaxcal gn warm        {summary(runs)}  first call in this process {first:.2f} s; "
        f"converged {res.converged} in {res.num_steps} steps"
    )

    with tempfile.TemporaryDirectory() as tmp:
        prob = os.path.join(tmp, "jaxcal_problem.npz")
        np.savez(prob, q=sim.q[0], measured=sim.measured[0], noise_mm=args.noise_mm)
        t0 = time.perf_counter()
        out = subprocess.run([sys.executable, __file__, "--_cold", prob], check=True, capture_output=True, text=True)
        cold_wall = time.perf_counter() - t0
        cold = json.loads(out.stdout.strip().splitlines()[-1])
        cold["process_wall_s"] = cold_wall
        print(
            f"jaxcal gn cold        import {cold['import_s']:.2f} s + first calibrate {cold['first_call_s']:.2f} s "
            f"(whole process {cold_wall:.2f} s)"
        )

        sc = scipy_fd_standin(robot, free, sim, args.noise_mm, args.pybotics_repeats)
        rows["scipy least_squares FD on jaxcal residual"] = sc
        print(f"scipy FD stand-in     {summary(sc['times_s'])}  nfev {sc['nfev']}")

        have_pyb = os.path.exists(args.pybotics_python)
        if have_pyb:
            pyb = run_pybotics(args.pybotics_python, robot, free, sim, args.noise_mm, args.pybotics_repeats, tmp)
            fk_nom = np.asarray(jaxcal.fk(robot, sim.q_val[0, :20]))[:, :3, 3]
            fk_gap = float(np.max(np.abs(np.asarray(pyb["fk_nominal_check"]) - fk_nom)))
            if fk_gap > 1e-6:
                raise SystemExit(f"pybotics and jaxcal FK disagree by {fk_gap} mm: not the same robot")
            rows["pybotics (least_squares FD)"] = pyb
            print(
                f"pybotics              {summary(pyb['times_s'])}  nfev {pyb['nfev']}  {pyb['message']} "
                f"(FK agrees with jaxcal to {fk_gap:.1e} mm; versions {pyb['versions']})"
            )
        else:
            print(
                f"pybotics not found at {args.pybotics_python}: only the scipy finite-difference stand-in is "
                "compared (see the module docstring to install pybotics in its own venv)"
            )
        processes = {}
        if args.processes > 0:
            processes = whole_processes(prob, pyb["command"] if have_pyb else None, args.processes, tmp)
            ref = statistics.median(processes["pybotics"]) if have_pyb else None
            print(f"\nwhole processes, {args.processes} each, run in turn (wall s)")
            for name, t in processes.items():
                ratio = f"  {statistics.median(t) / ref:5.2f}x pybotics" if ref else ""
                print(f"  {name:18s} median {statistics.median(t):6.2f}  (min {min(t):.2f}, max {max(t):.2f}){ratio}")

    base = rows["jaxcal gn (calibrate)"]["median_s"]
    print(f"\n{'tool':44s} {'median s':>10s} {'ratio':>9s} {'val RMS mm':>11s} {'param RMS':>10s} converged")
    summary_rows = []
    for name, r in rows.items():
        val_rms, par_rms = accuracy(r["x_fit"])
        ratio = r["median_s"] / base
        print(f"{name:44s} {r['median_s']:10.4f} {ratio:8.1f}x {val_rms:11.5f} {par_rms:10.2e} {r['success']}")
        summary_rows.append(
            {
                "tool": name,
                "median_s": r["median_s"],
                "min_s": min(r["times_s"]),
                "max_s": max(r["times_s"]),
                "slowdown_vs_jaxcal": ratio,
                "val_rms_mm": val_rms,
                "param_rms": par_rms,
                "converged": bool(r["success"]),
            }
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(
                {
                    "machine": machine(),
                    "poses": args.poses,
                    "noise_mm": args.noise_mm,
                    "n_params": len(free),
                    "cold": cold,
                    "whole_processes_s": processes,
                    "rows": summary_rows,
                },
                f,
                indent=1,
            )


if __name__ == "__main__":
    main()
