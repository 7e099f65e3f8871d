"""A URDF robot through the command line on the bundled TIAGo motion-capture data: calibrate
with ``--out-model CAL.urdf``, then ``jaxcal evaluate`` the saved model, nothing re-fitted."""

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import run_cli

from jaxcal import load_model, read_measurements, save_model
from jaxcal.measurements import tiago_paths
from jaxcal.model import predict

URDF, CSV = tiago_paths()
URDF_DIR = Path(__file__).resolve().parents[1] / "data" / "urdf"


@pytest.fixture(scope="module")
def split(tmp_path_factory):
    """The first 25 postures to train on, the other 12 and three repeats to evaluate."""
    d = tmp_path_factory.mktemp("tiago")
    lines = CSV.read_text().splitlines()
    (d / "train.csv").write_text("\n".join(lines[:26]) + "\n")
    (d / "test.csv").write_text("\n".join([lines[0]] + lines[26:] + lines[1:4]) + "\n")
    return d


def test_calibrate_then_evaluate(monkeypatch, capsys, split):
    d = split
    code, out, err = run_cli(
        monkeypatch, capsys, "calibrate", URDF, d / "train.csv", "--params", "offsets", "--folds", "3",
        "--compliance", "no", "--out-model", d / "cal.urdf", "--json", d / "rep.json",
    )  # fmt: skip
    assert code in (0, None), err
    assert "sigma_pos" in out and "mm (the frames-only residual)" in " ".join(out.split())  # no weight given
    rep = json.loads((d / "rep.json").read_text())
    assert rep["points"] == 4 and "shipped_row" in rep["ignored_columns"]
    assert rep["train_rms_mm"] < 5.0  # the data set's README: a few mm
    # the saved model reproduces the fit on its own training data
    code, out, err = run_cli(monkeypatch, capsys, "evaluate", d / "cal.urdf", d / "train.csv", "--json", d / "ev.json")
    assert code in (0, None), err
    ev = json.loads((d / "ev.json").read_text())
    fitted = [p["error_mm"] for p in ev["poses"] if p["row"] not in {o["row"] for o in rep["outliers"]}]
    assert np.sqrt(np.mean(np.square(fitted))) == pytest.approx(rep["train_rms_mm"], rel=1e-6)  # outliers left out
    # held-out: per point in column order, checked against an independent computation
    code, out, err = run_cli(
        monkeypatch, capsys, "evaluate", d / "cal.urdf", d / "test.csv", "--training", d / "train.csv",
        "--json", d / "held.json",
    )  # fmt: skip
    assert code in (0, None), err
    held = json.loads((d / "held.json").read_text())
    model = load_model(d / "cal.urdf")
    meas = read_measurements(d / "test.csv", model.robot)
    e = np.linalg.norm(meas.measured - np.asarray(predict(model, meas.q)), axis=-1)
    assert [p["rms_mm"] for p in held["points"]] == pytest.approx(np.sqrt((e**2).mean(0)).tolist())
    assert [p["max_mm"] for p in held["points"]] == pytest.approx(e.max(0).tolist())
    assert held["position_rms_mm"] == pytest.approx(float(np.sqrt((e**2).mean())))
    assert held["groups"]["repeated"]["poses"] == 3  # the three training rows appended
    assert sum(g["poses"] for g in held["groups"].values()) == 15
    assert "out of training ranges" in out
    # the saved model records the joint ranges it was fitted on (outliers left out), and evaluate
    # counts, and warns about, the postures outside them
    from jaxcal.robot import read_training_ranges

    tr = read_measurements(d / "train.csv", model.robot)
    fitted_q = tr.q[~np.isin(tr.rows, [o["row"] for o in rep["outliers"]])]
    ranges = read_training_ranges(d / "cal.urdf")
    assert list(ranges) == list(model.robot.joint_names)
    assert np.allclose([ranges[n] for n in ranges], np.c_[fitted_q.min(0), fitted_q.max(0)], rtol=1e-12, atol=1e-12)
    # the report gives them in the robot file's units (a URDF's metres for the torso), and says so
    assert rep["training_ranges_units"] == ["m", "rad"]
    per_mm = np.array([[1e-3] if t == "P" else [1.0] for t in model.robot.joint_types])
    got = np.array([rep["training_ranges"][n] for n in model.robot.joint_names])
    np.testing.assert_allclose(got, np.c_[fitted_q.min(0), fitted_q.max(0)] * per_mm, rtol=1e-12, atol=1e-15)
    tol = np.array([1.0 if t == "P" else 1e-2 for t in model.robot.joint_types])
    away = ((meas.q < fitted_q.min(0) - tol) | (meas.q > fitted_q.max(0) + tol)).any(1)
    assert held["outside_training_ranges"]["poses"] == int(away.sum()) > 0.1 * len(away)
    assert "have a joint outside the ranges the model was fitted on" in " ".join(out.split())
    code, out, err = run_cli(monkeypatch, capsys, "info", d / "cal.urdf")
    assert code in (0, None) and "calibrated model of the chain base_footprint -> wrist_ft_tool_link" in out, err


def test_points_chosen_out_of_order_read_back_as_themselves(monkeypatch, capsys, split):
    """``--points 3,1``: the written URDF names each point's link by its number in the file, and
    evaluate scores each against its own marker: the training error again, not a swap."""
    d = split
    code, out, err = run_cli(
        monkeypatch, capsys, "calibrate", URDF, d / "train.csv", "--params", "frames", "--folds", "3",
        "--nested-max-poses", "0", "--points", "3,1", "--out-model", d / "p31.urdf", "--json", d / "r31.json",
    )  # fmt: skip
    assert code in (0, None), err
    code, out, err = run_cli(monkeypatch, capsys, "evaluate", d / "p31.urdf", d / "train.csv", "--json", d / "e.json")
    assert code in (0, None), err
    train, ev = json.loads((d / "r31.json").read_text()), json.loads((d / "e.json").read_text())
    assert train["point_numbers"] == [3, 1] and sorted(p["point"] for p in ev["points"]) == [1, 3]
    fitted = [o["row"] for o in train["outliers"] if o["excluded"]]
    kept = [p for p in ev["poses"] if p["row"] not in fitted]
    rms = np.sqrt(np.nanmean(np.square([p["error_mm"] for p in kept], dtype=float)))
    assert rms == pytest.approx(train["train_rms_mm"], rel=1e-6)


def test_one_point_and_wrong_point_count(monkeypatch, capsys, split):
    """A model fitted on the file's marker 2 records it: evaluate scores marker 2 by default, as
    yourdfpy's forward kinematics of the written file does, and refuses marker 1; a file that
    does not record its points' numbers is refused, not scored on a guess."""
    import yourdfpy

    d = split
    code, out, err = run_cli(
        monkeypatch, capsys, "calibrate", URDF, d / "train.csv", "--params", "frames", "--folds", "3",
        "--points", "2", "--out-model", d / "one.urdf", "--json", d / "one.json",
    )  # fmt: skip
    assert code in (0, None), err
    assert load_model(d / "one.urdf").n_points == 1 and json.loads((d / "one.json").read_text())["point_numbers"] == [2]
    code, out, err = run_cli(monkeypatch, capsys, "evaluate", d / "one.urdf", d / "test.csv", "--json", d / "e.json")
    assert code in (0, None), err
    ev = json.loads((d / "e.json").read_text())
    data = read_measurements(d / "test.csv", load_model(d / "one.urdf").robot)
    urdf = yourdfpy.URDF.load(str(d / "one.urdf"), load_meshes=False)
    names = ["torso_lift_joint"] + [f"arm_{i}_joint" for i in range(1, 8)]
    err_mm = []
    for qk, p in zip(np.asarray(data.q), np.asarray(data.measured)[:, 1]):  # the file's marker 2
        urdf.update_cfg(dict(zip(names, np.r_[qk[0] / 1000.0, qk[1:]])))  # the torso in metres
        err_mm.append(np.linalg.norm(urdf.get_transform("jaxcal_point2", "jaxcal_measurement_frame")[:3, 3] * 1e3 - p))
    assert [p["point"] for p in ev["points"]] == [2]
    assert ev["position_rms_mm"] == pytest.approx(np.sqrt(np.mean(np.square(err_mm))), rel=1e-9)
    code, out, err = run_cli(monkeypatch, capsys, "evaluate", d / "one.urdf", d / "test.csv", "--points", "1")
    assert code == 2 and "--points 1: " in err and "fitted on the data file's point(s) 2 only" in err
    # a file of poses has no points to choose: it is refused for what it measures
    header = ",".join(names) + ",x,y,z,qw,qx,qy,qz"
    rows = [",".join(repr(float(v)) for v in np.r_[qk[0] / 1000.0, qk[1:], p / 1000.0, 1.0, 0.0, 0.0, 0.0]) for qk, p in
            zip(np.asarray(data.q), np.asarray(data.measured)[:, 1])]  # fmt: skip
    (d / "poses.csv").write_text(header + "\n" + "\n".join(rows) + "\n")
    save_model(load_model(d / "one.urdf"), d / "p1.urdf", template=URDF, point_numbers=[1])  # as from x, y, z
    code, out, err = run_cli(monkeypatch, capsys, "evaluate", d / "p1.urdf", d / "poses.csv")
    assert code == 2 and "the data measure poses, the model predicts 1 point(s)" in err, err
    save_model(load_model(d / "one.urdf"), d / "bare.urdf", template=URDF)  # no record of the numbers
    code, out, err = run_cli(monkeypatch, capsys, "evaluate", d / "bare.urdf", d / "test.csv")
    assert code == 2 and "the data measure 4 point(s) per pose, the model predicts 1 point(s)" in err
    code, out, err = run_cli(
        monkeypatch, capsys, "calibrate", URDF, d / "train.csv", "--points", "5", "--out-model", d / "bad.urdf"
    )
    assert code == 2 and "--points" in err and "1..4" in err
    assert not (d / "bad.urdf").exists()


def test_output_kind_is_checked_before_the_fit(monkeypatch, capsys, split):
    d = split
    code, out, err = run_cli(monkeypatch, capsys, "calibrate", URDF, d / "train.csv", "--out-model", d / "x.toml")
    msg = "--out-model: a joint-frame robot (a URDF, or a UR factory calibration) is written as URDF (.urdf, .xml)"
    assert code == 2 and msg in err, err
    code, out, err = run_cli(monkeypatch, capsys, "calibrate", "ur5", d / "train.csv", "--out-robot", d / "x.urdf")
    text = " ".join(err.split())
    assert code == 2 and "a DH robot is written as TOML" in text and "--out-model with a .urdf path" in text


def test_compensate_brings_the_measured_point_to_the_targets(monkeypatch, capsys, split, tmp_path):
    """A model calibrated on the file's marker 2: `compensate` brings that marker (the link
    jaxcal_point2, named by its number in the data file, as yourdfpy reads the written URDF) to
    the targets, not the tool frame the points hang from; a model of four markers asks which one."""
    import yourdfpy

    d = split
    code, out, err = run_cli(
        monkeypatch, capsys, "calibrate", URDF, d / "train.csv", "--params", "frames", "--folds", "3",
        "--points", "2", "--out-model", tmp_path / "p2.urdf",
    )  # fmt: skip
    assert code in (0, None), err
    data = read_measurements(d / "test.csv", load_model(tmp_path / "p2.urdf").robot).select_points([2])
    targets = np.asarray(data.measured)[:, 0] / 1000.0  # m, as the file
    header = "torso_lift_joint," + ",".join(f"arm_{i}_joint" for i in range(1, 8)) + ",x,y,z"
    q_file = np.asarray(data.q).copy()
    q_file[:, 0] /= 1000.0  # the torso in metres
    rows = [",".join(repr(float(v)) for v in np.r_[qk, t]) for qk, t in zip(q_file, targets)]
    (tmp_path / "targets.csv").write_text(header + "\n" + "\n".join(rows) + "\n")
    code, out, err = run_cli(
        monkeypatch, capsys, "compensate", tmp_path / "p2.urdf", tmp_path / "targets.csv", "--out", tmp_path / "q.csv"
    )
    assert "compensating measured point 2 (the model's points: 2;" in out
    columns = (tmp_path / "q.csv").read_text().splitlines()[0].split(",")
    got = np.loadtxt(tmp_path / "q.csv", delimiter=",", skiprows=1)
    urdf = yourdfpy.URDF.load(str(tmp_path / "p2.urdf"), load_meshes=False)
    names = header.split(",")[:8]
    for qk, t, reached in zip(got[:, :8], targets, got[:, columns.index("reached")]):
        urdf.update_cfg(dict(zip(names, qk)))
        T = urdf.get_transform("jaxcal_point2", "jaxcal_measurement_frame")
        assert reached == 1 and np.linalg.norm(T[:3, 3] - t) * 1000 < 1e-6
    from jaxcal import Model, load_robot, save_model

    save_model(Model(load_robot(URDF), np.eye(4)[:, :3] * 50.0), tmp_path / "p4.urdf", template=URDF)
    code, out, err = run_cli(monkeypatch, capsys, "compensate", tmp_path / "p4.urdf", tmp_path / "targets.csv")
    assert code == 2 and "4 points (the data file's 1, 2, 3, 4): choose the one" in err and "--point" in err
    code, out, err = run_cli(
        monkeypatch, capsys, "compensate", tmp_path / "p2.urdf", tmp_path / "targets.csv", "--point", "1"
    )
    assert code == 2 and "--point 1: " in err and "fitted on the data file's point(s) 2 only" in err


def test_a_chain_error_names_both_link_options_as_flags(monkeypatch, capsys):
    code, _, err = run_cli(monkeypatch, capsys, "info", URDF, "--base-link", "arm_4_link", "--tip-link", "arm_2_link")
    err = " ".join(err.split())
    assert code == 2 and "'arm_2_link' (--tip-link) is not below 'arm_4_link' (--base-link)" in err, err


def test_a_joint_outside_the_chain_that_moves_is_named(tmp_path, monkeypatch, capsys):
    """The TIAGo data with the chain cut below the torso (``--base-link torso_lift_link``): the
    torso column is not the chain's, yet it moves 335 mm over the rows, which the model cannot
    follow. It is named, with how far it moves, whatever becomes of the fit; held still, it is
    only an ignored column."""
    from jaxcal.measurements import joints_left_out
    from jaxcal.robot import load_robot, read_movable_joints

    code, out, err = run_cli(
        monkeypatch, capsys, "calibrate", URDF, CSV, "--base-link", "torso_lift_link", "--params", "frames",
        "--folds", "2", "--compliance", "no", "--nested-max-poses", "0", "--json", tmp_path / "rep.json",
    )  # fmt: skip
    out, err = " ".join(out.split()), " ".join(err.split())  # as rich wrapped them
    assert "note: column 'torso_lift_joint' is a joint of the robot file above the chain calibrated" in out
    assert "(by 335.3 mm)" in out
    # 56 mm RMS: refused, the moving joint given as the likely cause
    assert code == 3 and "likely: torso_lift_joint moved but is not in the chain" in err, err
    # the same file with the torso still: nothing to say
    arm = load_robot(URDF, base_link="torso_lift_link")
    header, *rows = CSV.read_text().splitlines()
    i = header.split(",").index("torso_lift_joint")
    still = [",".join(v if k != i else "0.2" for k, v in enumerate(r.split(","))) for r in rows]
    (tmp_path / "still.csv").write_text("\n".join([header, *still]) + "\n")
    meas = read_measurements(tmp_path / "still.csv", arm)
    assert "torso_lift_joint" in meas.ignored and meas.ignored_ranges["torso_lift_joint"] == (0.2, 0.2)
    above = read_movable_joints(URDF, "torso_lift_link")
    assert above == {"torso_lift_joint": "P"} and joints_left_out(meas, arm, above) == {}
    assert list(joints_left_out(read_measurements(CSV, arm), arm, above)) == ["torso_lift_joint"]  # moving
    # joints elsewhere in the tree (below the tip, a sibling branch) move nothing of the chain
    assert read_movable_joints(URDF, None) == {} and read_movable_joints(URDF, "base_link") == {}


def test_a_compliant_models_urdf_gives_the_error_other_readers_see(tmp_path, monkeypatch, capsys):
    """A UR5 URDF whose joints bend under gravity: the model's compliances are written as elements
    only jaxcal reads, so another URDF reader (yourdfpy here) predicts with the rigid geometry. The
    command warns, and the file's header gives that geometry's error on the data, checked by
    yourdfpy from the measurement frame to the point link."""
    from helpers import load_urdf

    from jaxcal import fk, load_robot

    ur5 = load_robot(URDF_DIR / "ur5.urdf", tip_link="tool0")
    tool = np.eye(4)
    tool[:3, 3] = [0.0, 0.0, 150.0]
    true = ur5.replace(compliance=np.r_[0.0, 3e-5, 2e-5, 1e-5, 0.0, 0.0], tool=tool)
    rng = np.random.default_rng(21)
    q = rng.uniform(-2.5, 2.5, (40, 6))
    points = np.asarray(fk(true, q))[:, :3, 3] + rng.normal(0.0, 0.02, (40, 3))
    rows = "".join(",".join(repr(float(v)) for v in (*a, *b / 1e3)) + "\n" for a, b in zip(q, points))
    (tmp_path / "bent.csv").write_text(",".join(ur5.joint_names) + ",x,y,z\n" + rows)
    code, out, err = run_cli(
        monkeypatch, capsys, "calibrate", URDF_DIR / "ur5.urdf", tmp_path / "bent.csv", "--params", "all",
        "--compliance", "yes", "--folds", "3", "--nested-max-poses", "0", "--tip-link", "tool0",
        "--out-model", tmp_path / "cal.urdf",
    )  # fmt: skip
    assert code in (0, None), err
    assert "only jaxcal reads: other URDF readers (ROS, MoveIt) see the rigid geometry" in " ".join(out.split())
    text = (tmp_path / "cal.urdf").read_text()
    head = dict(
        part.split(": ", 1) for part in text.split("<!-- jaxcal: ")[1].split(" -->")[0].split("; ") if ": " in part
    )
    cal = load_urdf(tmp_path / "cal.urdf")
    seen = []
    for row in q:
        cal.update_cfg(dict(zip(ur5.joint_names, row)))
        seen.append(np.asarray(cal.get_transform("jaxcal_point1", "jaxcal_measurement_frame"))[:3, 3] * 1e3)
    rigid = float(np.sqrt(np.mean(np.sum((np.array(seen) - points) ** 2, -1))))
    assert float(head["rigid_geometry_rms_mm_on_the_data"]) == pytest.approx(rigid, rel=1e-4)
    assert rigid > 5 * float(head["rms_mm_on_the_data_with_compliance"])


def test_a_training_file_with_a_point_never_seen_is_read_for_its_joints(monkeypatch, capsys, split, tmp_path):
    """``evaluate --training`` uses the training file's joint values alone: a point empty in every
    row of it is left out there; as the data scored, the same file is refused by that point's
    columns."""
    header, *rows = (split / "train.csv").read_text().splitlines()
    cols = header.split(",")
    blank = [cols.index(c) for c in ("x3", "y3", "z3")]
    lost = tmp_path / "lost3.csv"
    kept = [",".join("" if i in blank else v for i, v in enumerate(r.split(","))) for r in rows]
    lost.write_text("\n".join([header] + kept) + "\n")
    from jaxcal import load_robot
    from jaxcal.model import Model

    model = tmp_path / "four.urdf"  # the nominal arm with four points on its tool
    save_model(Model(load_robot(URDF), np.zeros((4, 3))), model, template=URDF)
    code, out, err = run_cli(monkeypatch, capsys, "evaluate", model, split / "test.csv", "--training", lost)
    assert code in (0, None), err
    assert "out of training ranges" in out
    code, out, err = run_cli(monkeypatch, capsys, "evaluate", model, lost)
    said = " ".join(err.split())
    assert code == 2 and "point(s) 3 (x3, y3, z3) empty in every row; leave them out (--points)" in said
