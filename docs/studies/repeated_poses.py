"""How well the Franka camera data repeat themselves, against how well a calibration predicts them.

The file measures some joint configurations more than once. Their measured camera positions
agree far better than the calibrated model fits the data: what the model leaves is systematic,
not noise (``docs/franka.md``, "Why a camera model"). Groups: rows whose joint values agree to
1e-3 rad; their spread is each row's distance from the group's mean position.

    python docs/studies/repeated_poses.py > docs/studies/repeated_poses.txt
"""

import json

import numpy as np

import jaxcal
from jaxcal.measurements import franka_csv_path

TOLERANCE_RAD = 1e-3


def main():
    panda = jaxcal.preset("panda")
    meas = jaxcal.read_measurements(franka_csv_path(), panda, length_unit="m")
    q, pos = np.asarray(meas.q), np.asarray(meas.measured)[:, :3, 3]
    rows = np.asarray(meas.rows)
    done, spreads = np.zeros(len(q), bool), []
    print(f"{'rows':>20s} {'spread (mm, max distance from their mean)':>44s}")
    for k in range(len(q)):
        if done[k]:
            continue
        same = np.flatnonzero(np.max(np.abs(q - q[k]), 1) < TOLERANCE_RAD)
        done[same] = True
        if len(same) > 1:
            d = np.linalg.norm(pos[same] - pos[same].mean(0), axis=1)
            spreads.append(d.max())
            print(f"{', '.join(map(str, rows[same])):>20s} {d.max():44.3f}")
    rep = json.load(open("docs/franka/report.json"))
    print(f"\n{len(spreads)} repeated configurations: spread {min(spreads):.2f}-{max(spreads):.2f} mm")
    print(f"the default calibration (docs/franka/report.json): train RMS {rep['train_rms_mm']:.2f} mm")


if __name__ == "__main__":
    main()
