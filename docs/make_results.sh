#!/usr/bin/env bash
# Regenerates the results the docs' tables quote, then the tables (repository root, venv active).
# The studies in docs/studies/ each write their own .txt (the command is in each one's docstring).
set -euo pipefail
jaxcal reproduce --out docs/reproduce/noise-free
jaxcal reproduce --noise-mm 0.02 --noise-rad 2e-5 --out docs/reproduce/noisy
jaxcal montecarlo paper-6r --robots 1000 --poses 100 --noise-mm 0.02 --noise-rad 2e-5 --json docs/montecarlo/gn_1000.json
jaxcal calibrate panda jaxcal/data/franka_panda_camera/measurements.csv --length-unit m \
    --json docs/franka/report.json --out-robot docs/franka/panda-calibrated.toml --plots docs/franka
jaxcal calibrate panda jaxcal/data/franka_panda_camera/measurements.csv --length-unit m --camera-model depth \
    --json docs/franka/report_depth_scale.json
jaxcal calibrate panda jaxcal/data/franka_panda_camera/measurements.csv --length-unit m --camera-model linear \
    --json docs/franka/report_camera_linear.json
COLUMNS=120 jaxcal calibrate panda jaxcal/data/franka_panda_camera/measurements.csv --length-unit m \
    --camera-model quadratic --json docs/franka/report_camera_quadratic.json \
    --out-robot docs/franka/panda-calibrated-camera-quadratic.toml | tee docs/franka/calibrate_camera_quadratic.txt
jaxcal calibrate panda jaxcal/data/franka_panda_camera/measurements.csv --length-unit m --camera-model auto \
    --json docs/franka/report_camera_auto.json
python docs/franka_fold_seeds.py docs/franka/fold_seeds.json
bash docs/make_tiago.sh
python docs/tables.py --write
