"""jaxcal against pybotics (issue 7.1): the same simulated robot, poses, measurements and
parameter set; time to a converged calibration and the accuracy reached, both tools.

Two problems (``--robot``), position-only measurements (what pybotics fits) with ``--noise-mm``
Gaussian noise per coordinate, true errors drawn on the position-identifiable parameters
(jaxcal's base set; the rest is held at nominal in both tools, so both fit the same set):

- ``panda``: the Franka Panda preset (MDH, 7 joints, flange d = 107 mm as the tool), tool known;
- ``ur10``: pybotics' own UR10 model (``pybotics.predefined_models.ur10``, MDH, 6 joints) read by
  jaxcal from a robot file, a 100 mm probe as the tool whose position is estimated too (pybotics'
  ``tool_mask`` x, y, z; jaxcal's ``estimate_tool``), true probe errors of 1 mm per axis.

Accuracy: position RMS of the calibrated model against the noise-free truth on ``--val``
inspection poses, and the RMS of the parameter errors.

pybotics pins numpy<2 and runs in its own venv; its fit (``OptimizationHandler`` +
``scipy.optimize.least_squares`` on ``optimize_accuracy``, finite differences, as its docs
show) runs in ``pybotics_worker.py`` and the two talk through files:

    python3 -m venv .venv-pybotics && .venv-pybotics/bin/pip install pybotics
    python benchmarks/bench_vs_pybotics.py [--pybotics-python .venv-pybotics/bin/python]
        [--robot panda|ur10] [--poses 100] [--val 100] [--noise-mm 0.02] [--repeats 7] [--json OUT.json]

Also timed in the same run: scipy ``least_squares`` with 2-point finite differences on
jaxcal's jitted residual (the stand-in the issue names if pybotics cannot be installed; without
``--pybotics-python`` only this stand-in is compared, and the output says so). "Cold" is a
fresh Python process: ``import jaxcal``, loading the robot (its file for ``ur10``) and the first
``calibrate`` call (compilation).

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


# pybotics.predefined_models.ur10(), rows [alpha, a, theta, d] (mm, rad)
UR10_MDH = [
    [0.0, 0.0, 0.0, 118.0],
    [1.5707963267948966, 0.0, 3.141592653589793, 0.0],
    [0.0, 612.7, 0.0, 0.0],
    [0.0, 571.6, 0.0, 163.9],
    [-1.5707963267948966, 0.0, 0.0, 115.7],
    [1.5707963267948966, 0.0, 3.141592653589793, 92.2],
]
PROBE_MM = 100.0


def ur10_file(path: str) -> str:
    """pybotics' UR10 as a jaxcal robot file (MDH, mm), a 100 mm probe along the flange's z."""
    lines = ['name = "ur10-pybotics"', 'convention = "mdh"', 'length_unit = "mm"', 'angle_unit = "rad"']
    for alpha, a, theta, d in UR10_MDH:
        lines += ["[[joints]]", f"theta = {theta!r}", f"d = {d!r}", f"a = {a!r}", f"alpha = {alpha!r}"]
    lines += ["[tool]", f"xyz = [0.0, 0.0, {PROBE_MM!r}]", "rpy = [0.0, 0.0, 0.0]"]
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
    return path


def fit_jaxcal(robot, q, measured, noise_mm, estimate_tool, params):
    """jaxcal's fit of the DH errors named in ``params`` (the set the other tools fit: left to
    itself, calibrate judges identifiability at its starting model and can keep a near-dependent
    pair that the nominal robot's analysis drops)."""
    import jaxcal

    return jaxcal.calibrate(
        robot,
        q,
        measured,
        params=params,
        method="gn",
        sigma_pos_mm=noise_mm,
        estimate_base=False,
        estimate_tool=estimate_tool,
    )


def cold_start(problem: str) -> None:
    """Child-process mode: time ``import jaxcal``, loading the robot and the first calibrate call."""
    t0 = time.perf_counter()
    import numpy as np

    import jaxcal

    t1 = time.perf_counter()
    p = np.load(problem)
    robot = jaxcal.load_robot(str(p["robot_file"])) if str(p["robot_file"]) else jaxcal.preset("panda")
    t2 = time.perf_counter()
    res = fit_jaxcal(robot, p["q"], p["measured"], float(p["noise_mm"]), bool(p["estimate_tool"]), str(p["params"]))
    t3 = time.perf_counter()
    print(json.dumps({"import_s": t1 - t0, "load_s": t2 - t1, "first_call_s": t3 - t2, "converged": res.converged}))


def whole_processes(prob_jaxcal: str, pyb_cmd: list[str] | None, n: int, tmp: str) -> dict:
    """Wall seconds of whole processes, run in turn (module docstring): ``jaxcal cold``, ``jaxcal
    warm cache`` and, with ``pyb_cmd``, ``pybotics``. A JAX cache the caller's environment sets is
    removed from the children's, so that cold means cold; so is ``PYTHONDONTWRITEBYTECODE``, so
    that jaxcal's modules load from bytecode as an installed package's do."""
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith("JAX_") and k not in ("JAXCAL_CACHE", "PYTHONDONTWRITEBYTECODE")
    }

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


def make_problem(name, n_poses, n_val, noise, seed, tmp):
    """The robot, its file (``""``: the preset), whether the tool is estimated, the parameters
    all tools fit (indices into jaxcal's layout: DH errors, then the tool point), the truth and
    the noisy positions. The truth is the robot with the errors applied exactly
    (:func:`jaxcal.error_model.perturb`, the probe moved in the flange frame)."""
    import jax
    import numpy as np

    import jaxcal
    from jaxcal.calibration import identify
    from jaxcal.simulation import error_scales, sample_poses

    robot_file = ur10_file(os.path.join(tmp, "ur10.toml")) if name == "ur10" else ""
    robot = jaxcal.load_robot(robot_file) if robot_file else jaxcal.preset("panda")
    tool = name == "ur10"
    kq, kv, kx, kt, kn = jax.random.split(jax.random.PRNGKey(seed), 5)
    q = np.asarray(sample_poses(kq, robot, (n_poses,)))
    q_val = np.asarray(sample_poses(kv, robot, (n_val,)))
    free = np.asarray(identify(robot, q, n_points=1, estimate_base=False, estimate_tool=tool).base)
    n4 = 4 * robot.n_joints
    x_true = np.zeros(n4 + (3 if tool else 0))
    draw = np.concatenate([error_scales(robot), np.ones(3)])[: len(x_true)] * np.asarray(
        jax.random.normal(kx, x_true.shape)
    )
    x_true[free] = draw[free]
    measured = positions(robot, x_true, q) + noise * np.asarray(jax.random.normal(kn, (n_poses, 3)))
    return dict(
        robot=robot,
        robot_file=robot_file,
        estimate_tool=tool,
        params=",".join(robot.param_names()[i] for i in free if i < n4),
        free=free,
        x_true=x_true,
        q=q,
        measured=measured,
        q_val=q_val,
        truth_val=positions(robot, x_true, q_val),
    )


def positions(robot, x, q):
    """Tool-point positions of ``robot`` with errors ``x``: DH errors, then (if given) the tool
    point's offset in the tool frame."""
    import numpy as np

    import jaxcal
    from jaxcal.error_model import perturb

    n4 = 4 * robot.n_joints
    T = np.asarray(jaxcal.fk(perturb(robot, np.asarray(x[:n4])), q))
    offset = np.zeros(3) if len(x) == n4 else np.asarray(x[n4 : n4 + 3])
    return T[:, :3, 3] + np.einsum("kij,j->ki", T[:, :3, :3], offset)


def pyb_index(j: int) -> int:
    i, k = divmod(int(j), 4)
    return 4 * i + TO_PYB[k]


def run_pybotics(python, prob, repeats, tmp):
    import numpy as np

    robot, free = prob["robot"], prob["free"]
    n4 = 4 * robot.n_joints
    dh = np.asarray(robot.dh)
    mdh = dh[:, [3, 2, 0, 1]]
    mask = np.zeros(dh.size, bool)
    mask[[pyb_index(j) for j in free if j < n4]] = True
    tool_mask = np.zeros(6, bool)
    tool_mask[[j - n4 for j in free if j >= n4]] = True  # x, y, z of pybotics' tool position
    path = os.path.join(tmp, "pyb_problem.npz")
    np.savez(
        path,
        mdh=mdh,
        tool=np.asarray(robot.tool),
        base=np.asarray(robot.base),
        q=prob["q"],
        positions=prob["measured"],
        mask=mask,
        tool_mask=tool_mask,
        q_val=prob["q_val"],
        q_check=prob["q_val"][:20],
    )
    out = os.path.join(tmp, "pyb_result.json")
    subprocess.run([python, os.path.join(HERE, "pybotics_worker.py"), path, out, "--repeats", str(repeats)], check=True)
    with open(out) as f:
        r = json.load(f)
    # pybotics' fitted parameter errors back in jaxcal's layout; its tool position is the
    # nominal probe's (a pure translation) plus the offset jaxcal calls the tool point
    d = np.asarray(r["mdh_fitted"]) - mdh
    x = np.stack([d[:, 2], d[:, 3], d[:, 1], d[:, 0]], axis=1).reshape(-1)
    if prob["estimate_tool"]:
        x = np.concatenate([x, np.asarray(r["tool_fitted"])[:3, 3] - np.asarray(robot.tool)[:3, 3]])
    r["x_fit"] = x
    r["command"] = [python, os.path.join(HERE, "pybotics_worker.py"), path, out, "--repeats", "1"]
    return r


def scipy_fd_standin(prob, noise, repeats):
    """scipy least_squares, 2-point finite differences, on jaxcal's jitted position residual."""
    import jax
    import jax.numpy as jnp
    import numpy as np
    import scipy.optimize

    import jaxcal
    from jaxcal.error_model import perturb

    robot, free = prob["robot"], prob["free"]
    n4, m = 4 * robot.n_joints, len(prob["x_true"])
    q, meas = jnp.asarray(prob["q"]), jnp.asarray(prob["measured"])
    free_idx = jnp.asarray(free)

    @jax.jit
    def resid(y):
        x = jnp.zeros(m).at[free_idx].set(y)
        T = jaxcal.fk(perturb(robot, x[:n4]), q)
        p = T[:, :3, 3] + (jnp.einsum("kij,j->ki", T[:, :3, :3], x[n4:]) if m > n4 else 0.0)
        return ((p - meas) / noise).reshape(-1)

    fun = lambda y: np.asarray(resid(jnp.asarray(y)))
    fun(np.zeros(len(free)))  # compile outside the timing
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        r = scipy.optimize.least_squares(fun, np.zeros(len(free)))
        times.append(time.perf_counter() - t0)
    x = np.zeros(m)
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
    ap.add_argument("--robot", choices=("panda", "ur10"), default="panda")
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

    with tempfile.TemporaryDirectory() as tmp:
        prob = make_problem(args.robot, args.poses, args.val, args.noise_mm, args.seed, tmp)
        robot, free, x_true = prob["robot"], prob["free"], prob["x_true"]

        def accuracy(x):
            val = positions(robot, np.asarray(x)[: len(x_true)], prob["q_val"])
            return (
                float(np.sqrt(np.mean(np.sum((val - prob["truth_val"]) ** 2, -1)))),
                float(np.sqrt(np.mean((np.asarray(x)[free] - x_true[free]) ** 2))),
            )

        print_machine()
        what = "tool known" if not prob["estimate_tool"] else f"robot file, {PROBE_MM:g} mm probe estimated"
        print(
            f"{robot.name} ({robot.convention.upper()}, {robot.n_joints}R, {what}), {args.poses} poses, "
            f"position-only, noise {args.noise_mm} mm, {len(free)} parameters (jaxcal's identifiable set, "
            "same mask in every tool)"
        )
        rows = {}

        # jaxcal: warm runs of the public calibrate(), and a cold process
        data = (prob["q"], prob["measured"], args.noise_mm, prob["estimate_tool"], prob["params"])
        call = lambda: fit_jaxcal(robot, *data)
        first, runs = timed(call, repeats=args.repeats)
        res = call()
        if not np.array_equal(np.asarray(res.free), free):
            raise SystemExit(f"jaxcal estimated {res.free}, not the shared set {free}")
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

        path = os.path.join(tmp, "jaxcal_problem.npz")
        np.savez(
            path,
            q=prob["q"],
            measured=prob["measured"],
            noise_mm=args.noise_mm,
            robot_file=prob["robot_file"],
            estimate_tool=prob["estimate_tool"],
            params=prob["params"],
        )
        env = {
            k: v
            for k, v in os.environ.items()
            if not k.startswith("JAX_") and k not in ("JAXCAL_CACHE", "PYTHONDONTWRITEBYTECODE")
        }
        env["XDG_CACHE_HOME"] = os.path.join(tmp, "cold-single")  # an empty compilation cache
        t0 = time.perf_counter()
        out = subprocess.run(
            [sys.executable, __file__, "--_cold", path], check=True, capture_output=True, text=True, env=env
        )
        cold_wall = time.perf_counter() - t0
        cold = json.loads(out.stdout.strip().splitlines()[-1])
        cold["process_wall_s"] = cold_wall
        print(
            f"jaxcal gn cold        import {cold['import_s']:.2f} s + load {cold['load_s']:.3f} s + first calibrate "
            f"{cold['first_call_s']:.2f} s (whole process {cold_wall:.2f} s)"
        )

        sc = scipy_fd_standin(prob, args.noise_mm, args.pybotics_repeats)
        rows["scipy least_squares FD on jaxcal residual"] = sc
        print(f"scipy FD stand-in     {summary(sc['times_s'])}  nfev {sc['nfev']}")

        have_pyb = os.path.exists(args.pybotics_python)
        if have_pyb:
            pyb = run_pybotics(args.pybotics_python, prob, args.pybotics_repeats, tmp)
            fk_nom = positions(robot, np.zeros(len(x_true)), prob["q_val"][:20])
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
            processes = whole_processes(path, pyb["command"] if have_pyb else None, args.processes, tmp)
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
                    "robot": args.robot,
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
