#!/usr/bin/env bash
# A jaxcal command in a fresh process with no compilation cache (XDG_CACHE_HOME, under which
# jaxcal keeps its compiled and traced programs, points at a fresh empty folder each run; JAX's
# own cache folder is unset: a user's own JAX cache turns jaxcal's kept programs off), an earlier
# revision and the working tree alternately, so their times compare on the same machine state; then the working
# tree again with the cache its cold run filled. Each line ends with the value at KEY (a dotted
# path into the command's --json output), which should not change.
# Usage (repository root, venv active):
#   bash benchmarks/cold_before_after.sh REV ROUNDS KEY JAXCAL_ARGS...
#   bash benchmarks/cold_before_after.sh 765cf8d 4 values.validation_rms_mm design panda --poses 30 --out /tmp/p.csv
#   bash benchmarks/cold_before_after.sh 765cf8d 3 heldout_rms_mm calibrate \
#       jaxcal/data/tiago_mocap/tiago_arm.urdf jaxcal/data/tiago_mocap/training.csv
# REV's own modules come from `git archive` into a temporary folder; data paths are taken from the
# repository root; environment passes through (e.g. OPENBLAS_NUM_THREADS=1).
set -euo pipefail
rev=${1:?usage: cold_before_after.sh REV ROUNDS KEY JAXCAL_ARGS...}
rounds=${2:?ROUNDS}
key=${3:?KEY}
shift 3
root=$PWD
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir "$tmp/before"
git archive "$rev" | tar -x -C "$tmp/before"
# data paths relative to the repository root, so that both trees read the same files
args=()
for a in "$@"; do
  if [ -e "$root/$a" ]; then args+=("$root/$a"); else args+=("$a"); fi
done
run() {  # label, tree, cache folder
  local cache="$3"
  # from the tree's own folder: `python -c` puts the working directory ahead of PYTHONPATH
  (cd "$2" && env -u JAX_COMPILATION_CACHE_DIR XDG_CACHE_HOME=$cache PYTHONPATH=$2 /usr/bin/time -f "%e %U %S" \
    -o "$tmp/time" python -c "from jaxcal.cli import main; main()" "${args[@]}" --json "$tmp/out.json" > /dev/null 2>&1)
  read -r wall user sys < "$tmp/time"
  value=$(python -c "
import json
v = json.load(open('$tmp/out.json'))
for k in '$key'.split('.'):
    v = v[k]
print(f'{v:.12g}')")
  echo "$1: wall $wall s (user $user, sys $sys), load $(cut -d' ' -f1 /proc/loadavg), $key $value"
}
for i in $(seq "$rounds"); do
  rm -rf "$tmp/cache-before" "$tmp/cache-after"
  run "before-$rev" "$tmp/before" "$tmp/cache-before"
  run "after" "$root" "$tmp/cache-after"
  run "after, warm cache" "$root" "$tmp/cache-after"
done
