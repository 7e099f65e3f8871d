"""`jaxcal calibrate` on large measurement files: wall time and peak memory of the whole command
(`/usr/bin/time -v`), for each size asked. The data: the Panda preset with small DH errors, a
base frame and a tool, full poses with 0.05 mm / 5e-4 rad noise, written by a NumPy forward
kinematics apart from jaxcal's.

    python benchmarks/bench_large_file.py [--poses 20000 100000] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile

import numpy as np
from _util import print_machine
from scipy.spatial.transform import Rotation

import jaxcal


def mdh_fk(dh, q, base, tool):
    """End poses of a modified-DH arm, one NumPy product per link."""
    T = np.broadcast_to(base, (len(q), 4, 4)).copy()
    for i, (theta, d, a, alpha) in enumerate(dh):
        ca, sa = np.cos(alpha), np.sin(alpha)
        c, s = np.cos(theta + q[:, i]), np.sin(theta + q[:, i])
        A = np.zeros((len(q), 4, 4))
        A[:, 0, 0], A[:, 0, 1], A[:, 0, 3] = c, -s, a
        A[:, 1, 0], A[:, 1, 1], A[:, 1, 2], A[:, 1, 3] = s * ca, c * ca, -sa, -sa * d
        A[:, 2, 0], A[:, 2, 1], A[:, 2, 2], A[:, 2, 3] = s * sa, c * sa, ca, ca * d
        A[:, 3, 3] = 1.0
        T = T @ A
    return T @ tool


def write_csv(path, n, seed=0):
    rng = np.random.default_rng(seed)
    r = jaxcal.preset("panda")
    dh = (
        np.asarray(r.dh)
        + np.c_[rng.normal(0, 2e-3, 7), rng.normal(0, 0.5, 7), rng.normal(0, 0.5, 7), rng.normal(0, 2e-3, 7)]
    )
    base = np.eye(4)
    base[:3, :3] = Rotation.from_euler("xyz", [0.01, -0.02, 0.7]).as_matrix()
    base[:3, 3] = [600.0, -300.0, 50.0]
    tool = np.array(r.tool)
    tool[:3, 3] += [20.0, -10.0, 60.0]
    lim = np.asarray(r.q_limits)
    q = lim[:, 0] + rng.uniform(size=(n, 7)) * (lim[:, 1] - lim[:, 0])
    T = mdh_fk(dh, q, base, tool)
    p = T[:, :3, 3] + rng.normal(0, 0.05, (n, 3))
    rot = Rotation.from_rotvec(rng.normal(0, 5e-4, (n, 3))) * Rotation.from_matrix(T[:, :3, :3])
    quat = rot.as_quat(scalar_first=True)
    table = np.c_[q, p, quat]
    header = ",".join([f"q{i + 1}" for i in range(7)] + ["x", "y", "z", "qw", "qx", "qy", "qz"])
    np.savetxt(path, table, delimiter=",", header=header, comments="", fmt="%.17g")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--poses", type=int, nargs="+", default=[20000, 100000])
    ap.add_argument("--out", default=None, help="keep the CSVs here (default: a temporary folder)")
    args = ap.parse_args()
    print_machine()
    folder = args.out or tempfile.mkdtemp()
    os.makedirs(folder, exist_ok=True)
    jaxcal_cmd = [sys.executable, "-c", "import jaxcal_launch; jaxcal_launch.main()"]
    for n in args.poses:
        path = os.path.join(folder, f"panda_{n}.csv")
        write_csv(path, n)
        cmd = ["/usr/bin/time", "-v", *jaxcal_cmd, "calibrate", "panda", path, "--json", path + ".json"]
        p = subprocess.run(cmd, capture_output=True, text=True)
        wall = re.search(r"Elapsed \(wall clock\) time.*: (\S+)", p.stderr).group(1)
        rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", p.stderr).group(1))
        held = json.loads(open(path + ".json").read())["heldout_rms_mm"] if p.returncode == 0 else float("nan")
        print(f"{n:7d} poses: exit {p.returncode}, wall {wall}, max RSS {rss / 1024:.0f} MB, held-out {held:.4f} mm")
        if p.returncode != 0:
            print(p.stderr[-2000:])


if __name__ == "__main__":
    main()
