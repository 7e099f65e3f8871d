"""Robots per second of batched Gauss–Newton on a few cores, lever by lever, in one run: an
earlier revision (its own modules, from a git worktree) and this tree on one CPU device, on two
(``--xla_force_host_platform_device_count``), and with XLA's CPU threading off.

    python benchmarks/bench_scale_out.py [--before REV] [--robots 1000] [--poses 100] [--repeats 3] [--rounds 2]

Every configuration runs in a fresh process (XLA flags and the device count are fixed when JAX
starts): ``calibrate_batch`` GN over ``--robots`` simulated paper-6r arms x ``--poses`` full poses,
0.02 mm / 2e-5 rad noise, base and tool known, as ``bench_gn_batch.py``. The configurations run
in turn, ``--rounds`` times over, so that a busy spell of the machine shows as a spread between
rounds rather than as a lever. Each line: the median of ``--repeats`` warm calls, the compile
time apart, and the largest difference of the estimates from this tree's one-device run.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from _util import describe

ROOT = Path(__file__).resolve().parent.parent
CHILD = r"""
import json, statistics, sys, time
import numpy as np
import jax, jaxcal
from jaxcal.calibration import identify
R, K, repeats, devices, save = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5]
robot = jaxcal.preset("paper-6r")
sim = jaxcal.simulate(robot, n_robots=R, n_poses=K, n_val=1, seed=0, sigma_pos=0.02, sigma_rot=2e-5)
ident = identify(robot, sim.q[0], estimate_base=False, estimate_tool=False)
kw = dict(method="gn", sigma_pos_mm=0.02, sigma_rot_rad=2e-5, estimate_base=False, estimate_tool=False, ident=ident)
if devices != "-":  # revisions before the devices option
    kw["devices"] = devices
call = lambda: jaxcal.calibrate_batch(robot, sim.q, sim.measured, **kw)
t0 = time.perf_counter(); res = call(); first = time.perf_counter() - t0
runs = []
for _ in range(repeats):
    t0 = time.perf_counter(); call(); runs.append(time.perf_counter() - t0)
np.save(save, res.x)
print(json.dumps({"jaxcal": jaxcal.__file__, "first": first, "runs": runs,
                  "devices": jax.device_count(), "converged": float(res.converged.mean()),
                  "max_steps": int(res.num_steps.max())}))
"""
SINGLE_THREAD = "--xla_cpu_multi_thread_eigen=false"


def configurations(before: str | None, tree: Path | None):
    """``(label, PYTHONPATH, XLA_FLAGS, devices argument)``."""
    out = []
    if before:
        out.append((f"before ({before}), 1 device", tree, "", "-"))
    out += [
        ("this tree, 1 device", ROOT, "", "all"),
        ("this tree, 2 CPU devices", ROOT, "--xla_force_host_platform_device_count=2", "all"),
        ("this tree, 1 device, XLA threading off", ROOT, SINGLE_THREAD, "all"),
        (
            "this tree, 2 CPU devices, XLA threading off",
            ROOT,
            f"--xla_force_host_platform_device_count=2 {SINGLE_THREAD}",
            "all",
        ),
    ]
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--before", help="an earlier revision to measure first (git worktree)")
    ap.add_argument("--robots", type=int, default=1000)
    ap.add_argument("--poses", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args()
    print("machine:", describe(), flush=True)
    print(f"loadavg at start: {os.getloadavg()[0]:.2f}", flush=True)
    print(
        f"paper-6r, calibrate_batch GN, {args.robots} robots x {args.poses} poses, full pose; "
        f"{args.repeats} warm calls each"
    )
    tmp = Path(tempfile.mkdtemp())
    tree = None
    if args.before:
        tree = tmp / "before"
        subprocess.run(["git", "worktree", "add", "-q", "--detach", str(tree), args.before], cwd=ROOT, check=True)
    try:
        confs = configurations(args.before, tree)
        rates = {c[0]: [] for c in confs}
        for rnd in range(args.rounds):
            for i, (label, path, flags, devices) in enumerate(confs):
                save = tmp / f"x{i}.npy"
                env = dict(os.environ, PYTHONPATH=str(path), XLA_FLAGS=flags)
                cmd = [
                    sys.executable,
                    "-c",
                    CHILD,
                    str(args.robots),
                    str(args.poses),
                    str(args.repeats),
                    devices,
                    str(save),
                ]
                p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=1800, cwd=tmp)
                if p.returncode:
                    print(f"{label}: failed\n{p.stderr[-2000:]}")
                    continue
                d = json.loads(p.stdout.strip().splitlines()[-1])
                med = statistics.median(d["runs"])
                rates[label].append(args.robots / med)
                ref = tmp / f"x{[c[0] for c in confs].index('this tree, 1 device')}.npy"
                gap = float(np.abs(np.load(save) - np.load(ref)).max()) if ref.exists() else float("nan")
                print(
                    f"round {rnd + 1}  {label:46s} {args.robots / med:7,.0f} robots/s  (median {med:.3f} s, "
                    f"min {min(d['runs']):.3f}, max {max(d['runs']):.3f}; compile {max(d['first'] - med, 0):.2f} s; "
                    f"{d['devices']} device(s); converged {d['converged']:.0%}, max {d['max_steps']} steps; "
                    f"differs from this tree's 1 device by {gap:.1e}; load {os.getloadavg()[0]:.2f}; "
                    f"{Path(d['jaxcal']).parent.parent.name})",
                    flush=True,
                )
        base = next(iter(rates))
        print(f"\nbest round of each, robots/s and ratio to '{base}':")
        for label, r in rates.items():
            if r:
                print(f"  {label:46s} {max(r):7,.0f}  {max(r) / max(rates[base]):5.2f}x")
    finally:
        if tree is not None:
            subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, check=False)


if __name__ == "__main__":
    main()
