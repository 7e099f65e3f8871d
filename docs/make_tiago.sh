#!/usr/bin/env bash
# The TIAGo motion-capture results of docs/tiago.md (repository root, venv active): each
# parameter set with point 1 alone and with all four points, K-fold held-out (nested for auto).
set -euo pipefail
U=jaxcal/data/tiago_mocap/tiago_arm.urdf
D=jaxcal/data/tiago_mocap/training.csv
for pts in 1 1,2,3,4; do
    tag=$([ "$pts" = 1 ] && echo 1pt || echo 4pt)
    for params in frames offsets all auto; do
        jaxcal calibrate $U $D --params $params --points $pts --json docs/tiago/${params}_${tag}.json > /dev/null
    done
done
COLUMNS=120 jaxcal calibrate $U $D --json docs/tiago/report.json --out-model docs/tiago/tiago-calibrated.urdf \
    | tee docs/tiago/calibrate.txt
COLUMNS=120 jaxcal evaluate docs/tiago/tiago-calibrated.urdf $D --json docs/tiago/evaluate_training.json \
    | tee docs/tiago/evaluate_training.txt
