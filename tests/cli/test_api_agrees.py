"""The command line and the Python API are one engine: `jaxcal calibrate` and
`jaxcal.calibrate_data` give the same model and report on the same data and options, and
`jaxcal.calibrate` on all poses with the chosen set agrees with the workflow's final fit."""

import json

import numpy as np
from helpers import random_transform, run_cli

import jaxcal
from jaxcal.measurements import write_measurements
from jaxcal.simulation import simulate


def test_cli_and_api_agree(tmp_path, monkeypatch, capsys, rng):
    r = jaxcal.preset("ur5")
    truth = r.replace(base=random_transform(rng, 400.0), tool=random_transform(rng, 80.0))
    sim = simulate(truth, n_poses=40, seed=7, sigma_pos=0.03, sigma_rot=1e-4)
    path = tmp_path / "data.csv"
    write_measurements(path, sim.q[0], sim.measured[0])
    opts = ["--params", "all", "--folds", "3", "--loss", "huber", "--compliance", "no"]
    code, _, err = run_cli(
        monkeypatch,
        capsys,
        "calibrate",
        "ur5",
        path,
        *opts,
        "--json",
        tmp_path / "r.json",
        "--out-robot",
        tmp_path / "cal.toml",
    )
    assert code in (0, None), err
    cli = json.loads((tmp_path / "r.json").read_text())
    api = jaxcal.calibrate_data(
        r, jaxcal.read_measurements(path, r), params="all", folds=3, loss="huber", compliance="no"
    )
    for key in ("heldout_rms_mm", "train_rms_mm", "frames_only_heldout_rms_mm", "sigma_pos_mm"):
        assert abs(cli[key] - api.report[key]) <= 1e-9, key
    for name, p in api.report["parameters"].items():
        assert abs(cli["parameters"][name]["value"] - p["value"]) <= 1e-9, name
    written = jaxcal.load_robot(tmp_path / "cal.toml")
    q = sim.q_val[0]
    np.testing.assert_allclose(np.asarray(jaxcal.fk(written, q)), np.asarray(jaxcal.fk(api.robot, q)), atol=1e-9)
    # the workflow's final fit is calibrate() with the same options and noise weights on all poses
    # (calibrate alone takes its pose weights again from its fit; the workflow's are its selection's)
    sig = dict(sigma_pos_mm=api.report["sigma_pos_mm"], sigma_rot_rad=np.radians(api.report["sigma_rot_deg"]))
    one = jaxcal.calibrate(r, sim.q[0], sim.measured[0], params="all", loss="huber", compliance="no", **sig)
    np.testing.assert_allclose(np.asarray(jaxcal.fk(one.robot, q)), np.asarray(jaxcal.fk(api.robot, q)), atol=1e-9)
