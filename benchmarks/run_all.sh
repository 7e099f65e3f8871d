#!/usr/bin/env bash
# Runs every benchmark and keeps its output in docs/bench/<name>.txt (the numbers quoted in
# benchmarks/README.md). From the repository root with the venv active; pybotics in its own venv
# at .venv-pybotics (see bench_vs_pybotics.py). Timings are only as clean as the machine is idle.
# ONLY="kinematics scaling" bash benchmarks/run_all.sh runs a subset.
set -euo pipefail
cd "$(dirname "$0")"
out=../docs/bench
mkdir -p "$out"
run() {
  local name=$1; shift
  [[ -z "${ONLY:-}" || " $ONLY " == *" $name "* ]] || return 0
  echo "== $name: python $*"
  local t0=$SECONDS
  python "$@" 2>&1 | grep --line-buffered -v '^WARNING' | tee "$out/$name.txt"
  echo "== $name: $((SECONDS - t0)) s"
}
run kinematics bench_kinematics.py
run gn_batch bench_gn_batch.py --repeats 3
run vs_pybotics bench_vs_pybotics.py --pybotics-python ../.venv-pybotics/bin/python --json "$out/vs_pybotics.json"
run elimination_vs_gn bench_elimination_vs_gn.py --robots 100
run scaling bench_scaling.py --out "$out"
run large_file bench_large_file.py --poses 20000 100000
run design bench_design.py
run scale_out bench_scale_out.py --before f007281 --rounds 2
