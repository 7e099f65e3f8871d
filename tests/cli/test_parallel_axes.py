"""Arms whose axes are all parallel (a SCARA, a planar arm) through `jaxcal calibrate`: what the
data cannot identify is held at 0 and named, and the held-out error is at the noise level. Data
from an independent forward kinematics (`helpers.dh_fk`), position-only with 0.05 mm noise."""

import json
import tomllib

import numpy as np
import pytest
from helpers import dh_fk, measurement_csv, run_cli

SIGMA = 0.05
ARMS = {
    # theta, d, a, alpha (mm, rad); SCARA: RRPR with vertical axes, joint 3 a prismatic quill
    "scara": (
        "RRPR",
        [[0.0, 400.0, 350.0, 0.0], [0.0, 0.0, 300.0, np.pi], [0.0, 100.0, 0.0, 0.0], [0.0, 80.0, 0.0, 0.0]],
        [[-2.5, 2.5], [-2.5, 2.5], [0.0, 200.0], [-3.0, 3.0]],
    ),
    "planar": (
        "RRR",
        [[0.0, 0.0, 300.0, 0.0], [0.0, 0.0, 250.0, 0.0], [0.0, 0.0, 100.0, 0.0]],
        [[-2.8, 2.8], [-2.8, 2.8], [-2.8, 2.8]],
    ),
}


def _toml(types, dh, limits):
    out = ['name = "arm"', 'convention = "sdh"', 'length_unit = "mm"', 'angle_unit = "rad"']
    for t, row, lim in zip(types, dh, limits):
        out += [
            "[[joints]]",
            f"theta = {row[0]!r}",
            f"d = {row[1]!r}",
            f"a = {row[2]!r}",
            f"alpha = {row[3]!r}",
            f'type = "{t}"',
            f"limits = [{lim[0]!r}, {lim[1]!r}]",
        ]
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("arm", list(ARMS))
def test_parallel_axis_arm_calibrates_at_noise_level(tmp_path, monkeypatch, capsys, arm):
    types, dh, limits = ARMS[arm]
    rng = np.random.default_rng(7)
    n = len(types)
    robot_file = tmp_path / "arm.toml"
    robot_file.write_text(_toml(types, dh, limits))
    err = np.c_[rng.normal(0, 2e-3, n), rng.normal(0, 0.3, n), rng.normal(0, 0.3, n), np.zeros(n)]
    lim = np.asarray(limits)
    q = lim[:, 0] + rng.uniform(size=(80, n)) * (lim[:, 1] - lim[:, 0])
    tool = np.eye(4)
    tool[:3, 3] = [20.0, -10.0, 30.0]
    base = np.eye(4)
    base[:3, 3] = [500.0, 200.0, -50.0]
    poses = dh_fk(np.asarray(dh) + err, q, joint_types=types, base=base, tool=tool)
    data = tmp_path / "data.csv"
    data.write_text(measurement_csv(q, poses, position_only=True, rng=rng, sigma_mm=SIGMA))
    code, out, err_text = run_cli(
        monkeypatch,
        capsys,
        "calibrate",
        robot_file,
        data,
        "--json",
        tmp_path / "r.json",
        "--out-robot",
        tmp_path / "cal.toml",
    )
    assert code == 0, err_text + out
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["heldout_rms_mm"] < 3 * SIGMA * np.sqrt(3), rep["heldout_rms_mm"]
    assert rep["unidentifiable"], "the parallel axes leave parameters the data cannot identify"
    doc = tomllib.loads((tmp_path / "cal.toml").read_text())  # the file says how its values are fixed
    assert doc["calibration"]["convention"] == "sdh" and "half a turn" in doc["calibration"]["gauge"]
