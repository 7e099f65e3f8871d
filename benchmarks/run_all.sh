#!/usr/bin/env bash
# Runs every benchmark and keeps its output in docs/bench/ (the numbers in benchmarks/README.md).
# From the repository root, venv active; pybotics in its own venv at .venv-pybotics (see
# bench_vs_pybotics.py). About 30 minutes on a 2-core CPU; run it on an otherwise idle machine.
set -euo pipefail
cd "$(dirname "$0")"
out=../docs/bench
mkdir -p "$out"
# ONLY="kinematics roofline" runs a subset
run() { local name=$1; shift; [[ -z "${ONLY:-}" || " $ONLY " == *" $name "* ]] || return 0; echo "== $name: python $*"; python "$@" 2>&1 | grep -v '^WARNING' | tee "$out/$name.txt"; }
run kinematics bench_kinematics.py
run gn_batch bench_gn_batch.py --repeats 3
run vs_pybotics bench_vs_pybotics.py --pybotics-python ../.venv-pybotics/bin/python --json "$out/vs_pybotics.json"
run roofline bench_roofline.py --repeats 15 --json "$out/roofline.json"
run elimination_vs_gn bench_elimination_vs_gn.py --robots 100
run scaling bench_scaling.py --out "$out"
# the kernel before / after the register-resident chain of c2113e9 (both as shipped, 512-bit vectors)
run kernel_ab bench_kernel_ab.py --rounds 5 --repeats 61 1de7fc5 c2113e9
