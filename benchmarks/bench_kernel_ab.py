"""A/B of native-kernel versions: ``chain.cc`` from git revisions (or files) timed side by side.

Each version is built (cached like the shipped kernel, keyed by its source) and timed in its own
fresh process, the processes interleaved over ``--rounds`` so that a slow stretch of a shared
machine hits every version alike. Paper arm, FK and the identification Jacobian at 10^4 and 10^5
poses per call; medians and min over ``--repeats`` calls per process, the median over rounds,
and the ratio against the first version (the baseline).

    python benchmarks/bench_kernel_ab.py 4be92ef HEAD        # git revisions
    python benchmarks/bench_kernel_ab.py old.cc jaxcal/_native/chain.cc
    python benchmarks/bench_kernel_ab.py HEAD@-mprefer-vector-width=256 HEAD   # compiler flags

A version may end in ``@FLAG,FLAG``: flags appended to the shipped ones (``jaxcal._native._FLAGS``
of this checkout, whatever the revision), so a later flag overrides an earlier one.

Each round also counts its minor page faults per call: through JAX, a process's output buffers
are either reused or fresh memory on every call (glibc returned them to Linux), and which one
depends on the heap's history, not on the kernel (the 10^4-pose Jacobian took 0.19-0.23 ms in
rounds with 28-135 faults per call and 0.39-0.90 ms in rounds with 161-424, for d5c4b6b's,
56880a1's and 71795e0's kernels alike; docs/bench/kernel_ab.txt, 2026-11-24). ``--keep-heap`` runs every child with ``_util.KEEP_HEAP`` (glibc keeps freed
memory) to compare kernels without that state; ``--env NAME=VALUE`` sets any other variable:

    python benchmarks/bench_kernel_ab.py d5c4b6b HEAD --keep-heap
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

from _util import KEEP_HEAP, kernel_source, machine

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

CHILD = r"""
import json, resource, statistics, sys
from pathlib import Path
import numpy as np
import jax
import jaxcal
from jaxcal import _native
sys.path.insert(0, sys.argv[3])
from _util import timed
_native.SOURCE = Path(sys.argv[1])  # before the first use: the kernel is built from this source
_native._FLAGS = _native._FLAGS + [f for f in sys.argv[4].split(",") if f]
ok, why = _native.status()
if not ok:
    raise SystemExit(why)
robot = jaxcal.preset("paper-6r")
out = {}
for K in (10_000, 100_000):
    Q = jax.numpy.asarray(np.random.default_rng(0).uniform(-np.pi, np.pi, (K, 6)))
    for op, f in (("FK", jax.jit(lambda q: jaxcal.fk(robot, q))),
                  ("Jacobian", jax.jit(lambda q: jaxcal.error_model.identification_jacobian(robot, q)))):
        f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        _, runs = timed(f, Q, repeats=int(sys.argv[2]))
        faults = (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0) / (len(runs) + 1)
        out[f"{op}, {K:,} poses/call"] = [statistics.median(runs), min(runs), faults]
print(json.dumps(out))
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("versions", nargs="+",
                    help="git revisions or chain.cc files, each optionally @FLAG,FLAG; the first is the baseline")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=21)
    ap.add_argument("--env", action="append", default=[], metavar="NAME=VALUE",
                    help="set in every child process (e.g. _util.KEEP_HEAP: glibc keeping freed memory)")
    ap.add_argument("--keep-heap", action="store_true", help="--env " + KEEP_HEAP)
    args = ap.parse_args()
    if args.keep_heap:
        args.env.append(KEEP_HEAP)
    env = dict(os.environ, **dict(e.split("=", 1) for e in args.env))
    print("machine:", machine())
    with tempfile.TemporaryDirectory() as tmp:
        srcs = [(kernel_source(spec, tmp, ROOT), flags) for spec, _, flags in (v.partition("@") for v in args.versions)]
        got = {v: [] for v in args.versions}
        for _ in range(args.rounds):
            for v, (src, flags) in zip(args.versions, srcs):
                p = subprocess.run([sys.executable, "-c", CHILD, src, str(args.repeats), HERE, flags],
                                   capture_output=True, text=True, env=env)
                if p.returncode:
                    raise SystemExit(f"{v}: {p.stderr.strip()[-2000:]}")
                got[v].append(json.loads(p.stdout.strip().splitlines()[-1]))
    base = args.versions[0]
    print(f"{args.rounds} rounds of fresh processes, {args.repeats} calls each{''.join(' ' + e for e in args.env)}; "
          f"ms per call: median of the rounds' medians [each round's median (its minor page faults per call)] "
          f"(min of all calls); ratio = baseline / version. A round whose output buffers are fresh memory on "
          f"every call (glibc returned them; faults in the hundreds) is the allocator's state, not the kernel's")
    for key in got[base][0]:
        ref = statistics.median(r[key][0] for r in got[base])
        for v in args.versions:
            meds = [r[key][0] for r in got[v]]
            med = statistics.median(meds)
            rounds = ', '.join(f'{r[key][0] * 1e3:.3f} ({r[key][2]:.0f})' for r in got[v])
            print(f"{key:28s} {v:>36s}  {med * 1e3:8.3f} ms [{rounds}]"
                  f" (min {min(r[key][1] for r in got[v]) * 1e3:.3f})  x{ref / med:5.2f}")


if __name__ == "__main__":
    main()
