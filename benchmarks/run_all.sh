#!/usr/bin/env bash
# Runs every benchmark and keeps its output in docs/bench/ (the numbers in benchmarks/README.md).
# From the repository root, venv active; pybotics in its own venv at .venv-pybotics (see
# bench_vs_pybotics.py). About 15 minutes on a 2-core CPU; run it on an otherwise idle machine.
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
# the kernel through JAX: d5c4b6b (OpenMP, Taylor sincos), 56880a1 (sincos table, register transposes and stores,
# its own threads), 71795e0 (the Jacobian in 2 chunks per thread)
run kernel_ab bench_kernel_ab.py --rounds 7 --repeats 61 d5c4b6b 56880a1 71795e0
# the same with glibc keeping freed memory: no process in the state whose output buffers are fresh memory each call
run kernel_ab_keep_heap bench_kernel_ab.py --rounds 11 --repeats 61 d5c4b6b 56880a1 71795e0 --keep-heap
# the kernel alone (no JAX): its phases, and the one of d5c4b6b; both again built without AVX-512
run kernel_phases bench_kernel_phases.py --repeats 300
run kernel_phases_d5c4b6b bench_kernel_phases.py --repeats 300 --source d5c4b6b
JAXCAL_NATIVE_FLAGS=-mno-avx512f run kernel_phases_avx2 bench_kernel_phases.py --repeats 100
JAXCAL_NATIVE_FLAGS=-mno-avx512f run kernel_phases_avx2_d5c4b6b bench_kernel_phases.py --repeats 100 --source d5c4b6b
