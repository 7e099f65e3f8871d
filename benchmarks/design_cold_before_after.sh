#!/usr/bin/env bash
# Cold `jaxcal design panda --poses 30` (no compilation cache: XDG_CACHE_HOME and
# JAX_COMPILATION_CACHE_DIR point at a fresh empty folder each run) of an earlier revision and of
# the working tree, alternately, so their times compare on the same machine state; with the
# criterion value each found (it should not change).
# Usage (repository root, venv active): bash benchmarks/design_cold_before_after.sh REV [ROUNDS]
# REV's own modules come from `git archive` into a temporary folder; environment passes through
# (e.g. OPENBLAS_NUM_THREADS=1).
set -euo pipefail
rev=${1:?usage: design_cold_before_after.sh REV [ROUNDS]}
rounds=${2:-3}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir "$tmp/before"
git archive "$rev" | tar -x -C "$tmp/before"
run() {  # label, tree
  local cache="$tmp/cache-$1"
  rm -rf "$cache" && mkdir "$cache"
  # from the tree's own folder: `python -c` puts the working directory ahead of PYTHONPATH
  (cd "$2" && XDG_CACHE_HOME=$cache JAX_COMPILATION_CACHE_DIR=$cache/jax PYTHONPATH=$2 /usr/bin/time -f "%e %U %S" \
    -o "$tmp/time" python -c "from jaxcal.cli import main; main()" design panda --poses 30 --out "$tmp/p.csv" \
    --json "$tmp/d.json" > /dev/null 2>&1)
  read -r wall user sys < "$tmp/time"
  value=$(python -c "import json; print(f\"{json.load(open('$tmp/d.json'))['values']['validation_rms_mm']:.12g}\")")
  echo "$1: wall $wall s (user $user, sys $sys), load $(cut -d' ' -f1 /proc/loadavg), criterion $value mm"
}
for i in $(seq "$rounds"); do
  run "before-$rev" "$tmp/before"
  run "after" "$PWD"
done
