"""The real Franka Panda camera data set, end to end through `jaxcal calibrate` (5-fold CV)."""

import json

import numpy as np
from helpers import run_cli

from jaxcal import fk, preset
from jaxcal.measurements import franka_csv_path, read_measurements
from jaxcal.robot import load_robot


def test_franka_calibrate_cli(tmp_path, monkeypatch, capsys):
    code, out, err = run_cli(
        monkeypatch,
        capsys,
        "calibrate",
        "panda",
        franka_csv_path(),
        "--length-unit",
        "m",
        "--folds",
        "5",
        "--json",
        tmp_path / "r.json",
        "--out-robot",
        tmp_path / "cal.toml",
        "--plots",
        tmp_path / "plots",
    )
    assert code in (0, None), err
    rep = json.loads((tmp_path / "r.json").read_text())
    for key in (
        "train_rms_mm",
        "heldout_rms_mm",
        "heldout_max_mm",
        "heldout_rot_rms_deg",
        "frames_only_heldout_rms_mm",
        "frames_only_heldout_max_mm",
        "frames_only_heldout_rot_rms_deg",
        "parameters",
        "unidentifiable",
        "condition_number",
        "converged",
        "steps",
        "choice",
    ):
        assert key in rep
    assert rep["poses"] == 114 and rep["folds"] == 5 and rep["converged"]
    # the data's README: frames only ~3.3 mm RMS on the training poses, ~3.5 mm held out
    assert 3.0 < rep["frames_only_train_rms_mm"] < 3.6
    assert 3.0 < rep["frames_only_heldout_rms_mm"] < 4.0
    # calibration must help on poses it never saw; measured 1.44 mm (the 1.2 mm goal is NOT reached)
    assert rep["heldout_rms_mm"] < 0.5 * rep["frames_only_heldout_rms_mm"]
    assert rep["heldout_rms_mm"] < 1.6
    assert rep["heldout_rot_rms_deg"] < rep["frames_only_heldout_rot_rms_deg"]
    assert rep["heldout_rms_mm"] >= rep["train_rms_mm"]  # held out is never better than training
    # the last two rows, one configuration measured twice ~4 mm off (docs/franka.md), are outliers
    flagged = [o["row"] for o in rep["outliers"]]
    assert {113, 114} <= set(flagged) and len(flagged) <= 0.2 * 114 and "outlier pose(s)" in out
    # independent check of the written model: its residual on the poses fitted (all but the
    # outliers) is the reported training RMS
    cal = load_robot(tmp_path / "cal.toml")
    m = read_measurements(franka_csv_path(), preset("panda"), length_unit="m")
    d = np.linalg.norm(np.asarray(fk(cal, m.q))[:, :3, 3] - m.poses[:, :3, 3], axis=1)
    d = d[~np.isin(m.rows, flagged)]
    assert abs(np.sqrt(np.mean(d**2)) - rep["train_rms_mm"]) < 1e-6
    # the camera sits ~(94, -11, 43) mm from the flange: tool = flange (d = 107 mm) @ camera
    assert np.allclose(rep["tool"]["xyz_mm"], [94, -11, 107 + 43], atol=15)
    for name in ("pose_errors.png", "parameters.png"):
        assert (tmp_path / "plots" / name).stat().st_size > 10_000
    assert "held-out" in out and rep["choice"] in out


def test_franka_calibrate_with_quadratic_camera_model(tmp_path, monkeypatch, capsys):
    """`--camera-model quadratic`: the camera's 17 measurement unknowns are estimated with the
    robot. Measured 1.12 mm held out at the default fold seed (1.44 without a camera model, 1.35
    with the depth scale only, 1.20 with the linear map; docs/franka/fold_seeds.json). The set
    is given (`--params all`, what nested selection picks in every fold of this file), so its
    plain K-fold held-out error is unbiased and the run skips the selection's nested folds."""
    code, out, err = run_cli(
        monkeypatch,
        capsys,
        "calibrate",
        "panda",
        franka_csv_path(),
        "--length-unit",
        "m",
        "--camera-model",
        "quadratic",
        "--params",
        "all",
        "--json",
        tmp_path / "r.json",
        "--out-robot",
        tmp_path / "cal.toml",
    )
    assert code in (0, None), err
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["camera_model"] == "quadratic" and rep["converged"]
    cam = rep["camera_parameters"]
    assert len(cam) == 17 and all(np.isfinite(v["std_error"]) and v["std_error"] > 0 for v in cam.values())
    assert not any(k.startswith("camera") for k in rep["parameters"])
    assert rep["heldout_rms_mm"] < 1.2  # the goal; the plain model is at 1.44
    assert rep["heldout_rms_mm"] >= rep["train_rms_mm"]
    # the robot file holds the robot alone: the command says what it predicts without the camera
    # model, and the file records it; evaluate of that file on the fitted rows gives the same
    import tomllib

    assert "warning: the camera model (quadratic) corrects the camera's measurements" in " ".join(out.split())
    cal = tomllib.loads((tmp_path / "cal.toml").read_text())["calibration"]
    assert cal["camera_model"] == "quadratic" and cal["robot_alone_train_rms_mm"] > 2 * rep["train_rms_mm"]
    fitted = franka_csv_path().read_text().splitlines()
    out_rows = {o["row"] for o in rep["outliers"] if o["excluded"]}
    (tmp_path / "fitted.csv").write_text(
        "\n".join([fitted[0]] + [r for k, r in enumerate(fitted[1:], 1) if k not in out_rows]) + "\n"
    )
    code, _, ev_err = run_cli(
        monkeypatch, capsys, "evaluate", tmp_path / "cal.toml", tmp_path / "fitted.csv", "--length-unit", "m",
        "--json", tmp_path / "e.json",
    )  # fmt: skip
    assert code in (0, None), ev_err
    alone = json.loads((tmp_path / "e.json").read_text())["position_rms_mm"]
    np.testing.assert_allclose(alone, cal["robot_alone_train_rms_mm"], rtol=1e-9)
    # independent check: the written robot (which carries no camera model) through the documented
    # camera formula t' = (I + A) t + z Q (u^2, v^2, uv), t = -R^T p, reproduces the training RMS
    c = [v["value"] for v in cam.values()]
    A = np.array([[c[1], c[2], c[3]], [c[4], -c[1], c[5]], [c[6], c[7], c[0]]])
    Q = np.array(c[8:]).reshape(3, 3)
    cal = load_robot(tmp_path / "cal.toml")
    m = read_measurements(franka_csv_path(), preset("panda"), length_unit="m")
    T = np.asarray(fk(cal, m.q))
    t = -np.einsum("kji,kj->ki", T[:, :3, :3], T[:, :3, 3])
    u, v = t[:, 0] / t[:, 2], t[:, 1] / t[:, 2]
    t_rep = t @ (np.eye(3) + A).T + t[:, 2:] * (np.stack([u * u, v * v, u * v], 1) @ Q.T)
    p_reported = -np.einsum("kij,kj->ki", T[:, :3, :3], t_rep)
    d = np.linalg.norm(p_reported - m.poses[:, :3, 3], axis=1)[~np.isin(m.rows, [o["row"] for o in rep["outliers"]])]
    assert abs(np.sqrt(np.mean(d**2)) - rep["train_rms_mm"]) < 1e-6
    assert "camera model quadratic" in out
