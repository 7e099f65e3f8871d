"""How much the Franka held-out figures move with the fold assignment: the nested 5-fold
cross-validation of ``jaxcal calibrate`` repeated with fold seeds 0..4, for each camera model.
Usage (repository root, venv active): python docs/franka_fold_seeds.py docs/franka/fold_seeds.json"""

import json
import statistics
import sys

import jaxcal
from jaxcal.measurements import franka_csv_path

robot = jaxcal.preset("panda")
meas = jaxcal.read_measurements(franka_csv_path(), robot, length_unit="m")
out = {}
for camera in ("none", "depth", "linear", "quadratic", "auto"):
    rows = []
    for seed in range(5):
        rep = jaxcal.calibrate_data(robot, meas, camera=camera, seed=seed).report
        rows.append(
            {
                "seed": seed,
                "heldout_rms_mm": rep["heldout_rms_mm"],
                "heldout_rot_rms_deg": rep["heldout_rot_rms_deg"],
                "nested_choices": rep["nested_choices"],
                "choice": rep["choice"],
            }
        )
        print(camera, rows[-1], flush=True)
    v = [r["heldout_rms_mm"] for r in rows]
    out[camera] = {"seeds": rows, "median_mm": statistics.median(v), "min_mm": min(v), "max_mm": max(v)}
json.dump(out, open(sys.argv[1], "w"), indent=2)
