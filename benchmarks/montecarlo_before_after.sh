#!/usr/bin/env bash
# End-to-end GN Monte Carlo (1,000 UR5 robots x 100 full poses) of an earlier revision and of the
# working tree, one after the other in one run, so their robots/s compare on the same machine state.
# Usage (repository root, venv active): bash benchmarks/montecarlo_before_after.sh REV [montecarlo args]
# REV's own modules are imported from a git worktree; extra environment (e.g. JAXCAL_NATIVE=0 for
# revisions that had a native kernel) passes through.
set -euo pipefail
rev=${1:?usage: montecarlo_before_after.sh REV [args]}; shift
args=${*:-"--robots 1000 --poses 100 --repeats 5"}
tree=$(mktemp -d)/before
git worktree add -q --detach "$tree" "$rev"
trap 'git worktree remove --force "$tree"' EXIT
run() {  # label, PYTHONPATH
  echo "== $1"
  # from the tree's own folder: `python -c` puts the working directory ahead of PYTHONPATH
  (cd "$2" && PYTHONPATH=$2 python -c "from jaxcal.cli import main; main()" montecarlo ur5 $args --json "$tree/$1.json" \
    > /dev/null 2>&1)
  python -c "import json; d = json.load(open('$tree/$1.json')); print(f\"{d['robots_per_second']:.0f} robots/s, compile {d['compile_seconds']:.2f} s, CRLB efficiency {d['crlb_efficiency_mean']:.3f}\")"
}
run "before-$rev" "$tree"
run "after" "$PWD"
