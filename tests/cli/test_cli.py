"""The command line (through the real entry point `jaxcal.cli.main`): bad input gives one clear
line and exit code 2; a unit mismatch is refused with its evidence; compensation output."""

import json
import re

import numpy as np
import pytest
from helpers import run_cli  # noqa: E402

from jaxcal import fk, preset
from jaxcal.error_model import perturb
from jaxcal.measurements import write_measurements
from jaxcal.robot import load_robot, save_robot
from jaxcal.simulation import simulate


@pytest.fixture(scope="module")
def panda_data(tmp_path_factory):
    """A good simulated Panda data set (mm, rad) with its header and rows as text."""
    r = preset("panda")
    sim = simulate(r, n_poses=12, seed=4, sigma_pos=0.1, sigma_rot=1e-3)
    p = tmp_path_factory.mktemp("d") / "good.csv"
    write_measurements(p, sim.q[0], sim.measured[0])
    return p.read_text().splitlines()


def _write(tmp_path, lines, name="bad.csv"):
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def _replace_field(line, col, value):
    f = line.split(",")
    f[col] = value
    return ",".join(f)


BAD = {
    "missing column": (
        lambda h, rows: [h.replace(",z,", ",")] + [",".join(r.split(",")[:9] + r.split(",")[10:]) for r in rows],
        "missing column(s) 'z'",
    ),
    "joint count": (
        lambda h, rows: [h.replace("q7,", "")] + [",".join(r.split(",")[:6] + r.split(",")[7:]) for r in rows],
        "robot has 7 joints, file has q1..q6",
    ),
    "non-numeric": (
        lambda h, rows: [h] + rows[:2] + [_replace_field(rows[2], 8, "12,5x")] + rows[3:],
        "row 3 (line 4): 15 fields",
    ),
    "non-numeric value": (
        lambda h, rows: [h] + rows[:2] + [_replace_field(rows[2], 8, "abc")] + rows[3:],
        "row 3 (line 4), column 'y': not a number: 'abc'",
    ),
    "non-finite": (
        lambda h, rows: [h] + [_replace_field(rows[0], 1, "nan")] + rows[1:],
        "row 1 (line 2), column 'q2': value 'nan' is not finite",
    ),
    "non-unit quaternion": (
        lambda h, rows: [h] + rows[:4] + [_replace_field(rows[4], 10, "3.0")] + rows[5:],
        "row 5 (line 6): quaternion (qw, qx, qy, qz) has norm",
    ),
    "too few poses": (  # (five poses fit the frames alone: params auto tries what they can fit)
        lambda h, rows: [h] + rows[:2],
        "--folds (3) more than the distinct postures (2; rows repeating a posture are one): use fewer folds, or "
        "measure more postures; 3-fold cross-validation of 12 parameters needs at least 3",
    ),
    "empty": (lambda h, rows: [""], "file is empty"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_calibrate_bad_input(tmp_path, monkeypatch, capsys, panda_data, case):
    make, msg = BAD[case]
    p = _write(tmp_path, make(panda_data[0], panda_data[1:]))
    code, out, err = run_cli(monkeypatch, capsys, "calibrate", "panda", p, "--folds", "3")
    assert code == 2
    assert msg in " ".join(err.split()), err
    assert "Traceback" not in err and err.strip().startswith("error:")


@pytest.mark.parametrize(
    "args, msg",
    [
        (["--method", "newton"], "--method must be one of gn, lm, linear"),
        (["--params", "theta,beta"], "unknown parameter or set 'beta'"),
        (["--folds", "40"], "--folds (40) more than the distinct postures (12"),
        (["--length-unit", "inch"], "--length-unit must be one of 'mm', 'm', got 'inch'"),
        (["--ridge", "-1", "--params", "all"], "--ridge-mm must be a finite positive number"),
    ],
)
def test_calibrate_bad_options(tmp_path, monkeypatch, capsys, panda_data, args, msg):
    p = _write(tmp_path, panda_data, "good.csv")
    code, _, err = run_cli(monkeypatch, capsys, "calibrate", "panda", p, *args)
    assert code == 2 and msg in " ".join(err.split()), err


def test_calibrate_missing_files(tmp_path, monkeypatch, capsys, panda_data):
    code, _, err = run_cli(monkeypatch, capsys, "calibrate", "panda", tmp_path / "nope.csv")
    assert code == 2 and "measurement file not found" in err
    code, _, err = run_cli(monkeypatch, capsys, "calibrate", tmp_path / "nope.toml", tmp_path / "nope.csv")
    assert code == 2 and "robot file not found" in err


def test_calibrate_refuses_metres_read_as_mm(tmp_path, monkeypatch, capsys, panda_data):
    """Positions written in metres but read as mm: an error with the evidence and the option that
    fixes it, exit 2, and no model written."""
    h, rows = panda_data[0], panda_data[1:]
    scaled = [
        ",".join(f if not 7 <= i <= 9 else repr(float(f) / 1000) for i, f in enumerate(r.split(","))) for r in rows
    ]
    p = _write(tmp_path, [h] + scaled)
    code, _, err = run_cli(
        monkeypatch,
        capsys,
        "calibrate",
        "panda",
        p,
        "--folds",
        "3",
        "--params",
        "frames",
        "--out-robot",
        tmp_path / "cal.toml",
    )
    msg = " ".join(err.split())
    assert code == 2 and "metres read as millimetres" in msg and "--length-unit" in msg, err
    assert not (tmp_path / "cal.toml").exists()


def test_compensate_cli(tmp_path, monkeypatch, capsys):
    r = preset("paper-6r")
    sim = simulate(r, n_poses=6, seed=2)
    cal = perturb(r, sim.x_true[0])
    save_robot(cal, tmp_path / "cal.toml")
    q = np.asarray(sim.q[0])
    t = tmp_path / "targets.csv"
    t.write_text("q1,q2,q3,q4,q5,q6\n" + "".join(",".join(repr(float(v)) for v in row) + "\n" for row in q))
    code, out, err = run_cli(monkeypatch, capsys, "compensate", tmp_path / "cal.toml", t)
    assert code == 2 and "the nominal robot is needed" in " ".join(err.split())
    code, out, err = run_cli(
        monkeypatch,
        capsys,
        "compensate",
        tmp_path / "cal.toml",
        t,
        "--nominal",
        "paper-6r",
        "--out",
        tmp_path / "out.csv",
    )
    assert code == 0, err
    assert "reached: 6/6" in out
    lines = (tmp_path / "out.csv").read_text().splitlines()
    assert lines[0].startswith("q1,q2,q3,q4,q5,q6,pos_residual_mm")
    qc = np.array([[float(v) for v in ln.split(",")[:6]] for ln in lines[1:]])
    # independent check: the calibrated robot at the written commands lands on the nominal targets
    got = np.asarray(fk(load_robot(tmp_path / "cal.toml"), qc))
    want = np.asarray(fk(r, q))
    assert np.abs(got[:, :3, 3] - want[:, :3, 3]).max() < 1e-5


def test_compensate_hints_at_metres_for_targets_all_at_the_frames_origin(tmp_path, monkeypatch, capsys):
    """UR5 tool positions written in metres, without commands: every target within a mm of the
    measurement frame's origin, none reached; the warning asks whether they are metres. The same
    file in mm is reached, with no such hint."""
    r = preset("ur5")
    pos = np.asarray(fk(r, np.asarray(simulate(r, n_poses=5, seed=3).q[0])))[:, :3, 3]
    t = tmp_path / "t.csv"
    for scale, reached in ((1e-3, False), (1.0, True)):
        t.write_text("x,y,z\n" + "".join(",".join(repr(float(v)) for v in p * scale) + "\n" for p in pos))
        code, out, err = run_cli(monkeypatch, capsys, "compensate", "ur5", t)
        said = " ".join((out + err).split())
        assert (code in (0, None)) == reached, (code, said)
        assert ("written in metres (--length-unit m)?" in said) == (not reached), said


def test_compensate_asks_for_the_frame_of_targets_far_from_their_commands(tmp_path, monkeypatch, capsys):
    """UR5 tool positions with their commands, written in another session's tracker frame (3.9 m
    off): none reached, and the warning asks for the targets' frame (each row was blamed on a
    branch or a singularity alone). The same targets in the robot's frame: reached, no hint."""
    r = preset("ur5")
    q = np.asarray(simulate(r, n_poses=5, seed=3).q[0])
    pos = np.asarray(fk(r, q))[:, :3, 3]
    t = tmp_path / "t.csv"
    for shift, reached in (([3000.0, -2500.0, 0.0], False), ([0.0, 0.0, 0.0], True)):
        rows = np.hstack([q + 1e-3, pos + shift])
        t.write_text("q1,q2,q3,q4,q5,q6,x,y,z\n" + "".join(",".join(map(repr, map(float, v))) + "\n" for v in rows))
        code, out, err = run_cli(monkeypatch, capsys, "compensate", "ur5", t)
        said = " ".join((out + err).split())
        assert (code in (0, None)) == reached, (code, said)
        assert ("are they in the calibrated model's frame" in said) == (not reached), said


def test_compensate_names_a_quaternion_written_in_another_order(tmp_path, monkeypatch, capsys):
    """UR5 poses with their commands, the quaternions written by scipy (scalar last) under the
    scalar-first names, or of the inverse rotation: rows are missed, and the warning names that
    mistake. The same file written right is reached without the hint."""
    from scipy.spatial.transform import Rotation

    r = preset("ur5")
    q = np.asarray(simulate(r, n_poses=6, seed=4).q[0])
    T = np.asarray(fk(r, q))
    xyzw = Rotation.from_matrix(T[:, :3, :3]).as_quat()
    t = tmp_path / "t.csv"
    written = {
        "": xyzw[:, [3, 0, 1, 2]],
        "quaternion written x, y, z, w": xyzw,
        "quaternion of the inverse rotation": xyzw[:, [3, 0, 1, 2]] * [1, -1, -1, -1],
    }
    for mistake, quat in written.items():
        rows = np.hstack([q + 1e-3, T[:, :3, 3], quat])
        t.write_text(
            "q1,q2,q3,q4,q5,q6,x,y,z,qw,qx,qy,qz\n" + "".join(",".join(map(repr, map(float, v))) + "\n" for v in rows)
        )
        code, out, err = run_cli(monkeypatch, capsys, "compensate", "ur5", t)
        said = " ".join((out + err).split())
        assert (code in (0, None)) == (not mistake), (code, said)
        assert ("check the quaternion columns" in said) == bool(mistake), said
        if mistake:
            assert f"without a {mistake}" in said, said


def test_the_largest_joint_correction_does_not_count_a_whole_turn(tmp_path, monkeypatch, capsys):
    """A command read a whole turn below joint 1's limits [0.5, 6] (5.0 written as 5.0 - 2 pi),
    its pose the target: the command sent is 5.0, on the target, and the correction said is the
    solve's own few hundredths of a degree, not 360."""
    from scipy.spatial.transform import Rotation

    r = preset("paper-6r")
    lim = np.array(r.q_limits)
    lim[0] = 0.5, 6.0
    robot = r.replace(q_limits=lim)
    save_robot(robot, tmp_path / "r.toml")
    q = np.asarray(r.q_limits).mean(1)
    q[0] = 5.0
    T = np.asarray(fk(r, q[None]))[0]
    wx, wy, wz, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    start = q + 1e-4
    start[0] -= 2 * np.pi
    t = tmp_path / "t.csv"
    row = [*start, *T[:3, 3], w, wx, wy, wz]
    t.write_text("q1,q2,q3,q4,q5,q6,x,y,z,qw,qx,qy,qz\n" + ",".join(repr(float(v)) for v in row) + "\n")
    code, out, err = run_cli(monkeypatch, capsys, "compensate", tmp_path / "r.toml", t, "--out", tmp_path / "o.csv")
    assert code in (0, None), out + err
    sent = [float(v) for v in (tmp_path / "o.csv").read_text().splitlines()[1].split(",")[:6]]
    assert abs(sent[0] - 5.0) < 1e-6
    said = float(out.split("largest joint correction: ")[1].split(" deg")[0])
    assert said < 0.1, said


@pytest.mark.parametrize("columns", ["q", "j"])
def test_compensate_writes_the_commands_under_the_targets_joint_columns(tmp_path, monkeypatch, capsys, columns):
    """A robot whose joints are named ``j1..j6`` reads targets headed ``q1..q6`` or ``j1..j6``; the
    commands written are headed as the targets were, so the file reads back where they did."""
    import dataclasses

    r = preset("paper-6r")
    r = dataclasses.replace(r, joint_names=tuple(f"j{i}" for i in range(1, 7)))
    save_robot(r, tmp_path / "cal.toml")
    q = np.random.default_rng(4).uniform(-1.0, 1.0, (3, 6))
    p = np.array(fk(r, q))[:, :3, 3]
    names = [f"{columns}{i}" for i in range(1, 7)]
    t = tmp_path / "targets.csv"
    t.write_text(
        ",".join(names + ["x", "y", "z"])
        + "\n"
        + "".join(",".join(repr(float(v)) for v in [*qk, *pk]) + "\n" for qk, pk in zip(q, p))
    )
    code, out, err = run_cli(monkeypatch, capsys, "compensate", tmp_path / "cal.toml", t, "--out", tmp_path / "o.csv")
    assert code in (0, None), out + err
    header = (tmp_path / "o.csv").read_text().splitlines()[0].split(",")
    assert header[:6] == names


def test_compensate_cli_marks_rows_it_cannot_send(tmp_path, monkeypatch, capsys):
    """Position targets, one far beyond the reach: exit 1, the row is named, and the output file
    marks it (reached = 0) while the others are sent."""
    r = preset("paper-6r")
    save_robot(r, tmp_path / "cal.toml")
    q = np.random.default_rng(3).uniform(-1.0, 1.0, (4, 6))
    p = np.array(fk(r, q))[:, :3, 3]
    p[2] += 1e5
    t = tmp_path / "targets.csv"
    t.write_text(
        "q1,q2,q3,q4,q5,q6,x,y,z\n"
        + "".join(",".join(repr(float(v)) for v in [*qk, *pk]) + "\n" for qk, pk in zip(q, p))
    )
    code, out, err = run_cli(monkeypatch, capsys, "compensate", tmp_path / "cal.toml", t, "--out", tmp_path / "o.csv")
    assert code == 1, err
    assert "row 3: not reached" in out
    rows = [ln.split(",") for ln in (tmp_path / "o.csv").read_text().splitlines()]
    assert rows[0][-3:] == ["reached", "within_limits", "on_branch"]
    assert [ln[-3] for ln in rows[1:]] == ["1", "1", "0", "1"]
    # position targets: no rotation was asked for, so none is reported (not a residual of 0)
    assert "rot_residual_deg" not in rows[0] and "rotation residual" not in out and rows[0][6] == "pos_residual_mm"
    assert all(len(ln) == len(rows[0]) for ln in rows)
    # without joint columns the solves start at the middle of the limits: the warning says to give them
    assert "without joint columns" not in out
    t.write_text("x,y,z\n" + "".join(",".join(repr(float(v)) for v in pk) + "\n" for pk in p))
    code, out, err = run_cli(monkeypatch, capsys, "compensate", tmp_path / "cal.toml", t)
    assert code == 1 and "without joint columns every solve starts at the middle of the joint limits" in " ".join(
        out.split()
    )


def test_out_robot_of_several_points_keeps_them(tmp_path, monkeypatch, capsys):
    """Three markers per pose on a DH robot: `--out-robot` writes the robot with its points, and
    `jaxcal evaluate` of that file alone reproduces the calibration's training error."""
    r = preset("ur5")
    sim = simulate(r, n_poses=30, seed=5, sigma_pos=0.0, base=True, tool=True)
    T = np.asarray(sim.measured[0])
    pts = np.array([[40.0, 0.0, 30.0], [-30.0, 50.0, 20.0], [0.0, -45.0, 60.0]])
    P = np.einsum("kij,mj->kmi", T[:, :3, :3], pts) + T[:, None, :3, 3]
    P += np.random.default_rng(5).normal(scale=0.02, size=P.shape)
    head = ",".join([f"q{i}" for i in range(1, 7)] + [f"{a}{m}" for m in (1, 2, 3) for a in "xyz"])
    rows = [",".join(repr(float(v)) for v in np.r_[q, p.ravel()]) for q, p in zip(np.asarray(sim.q[0]), P)]
    data = _write(tmp_path, [head, *rows], "three.csv")
    code, out, err = run_cli(
        monkeypatch, capsys, "calibrate", "ur5", data, "--nested-max-poses", "0", "--compliance", "no",
        "--out-robot", tmp_path / "cal.toml", "--out-model", tmp_path / "cal.urdf",
        "--json", tmp_path / "rep.json",
    )  # fmt: skip
    assert code in (0, None), err
    assert "with the 3 measured points" in " ".join(out.split())
    assert "a URDF is in metres: evaluate or compensate it on data in mm with --length-unit mm" in " ".join(out.split())
    code, _, err = run_cli(monkeypatch, capsys, "evaluate", tmp_path / "cal.urdf", data, "--length-unit", "mm")
    assert code in (0, None), err  # as it says
    # the DH model as a URDF in joint frames: yourdfpy places its points where jaxcal's TOML does
    import yourdfpy

    from jaxcal.model import load_model, predict

    u = yourdfpy.URDF.load(str(tmp_path / "cal.urdf"), load_meshes=False)
    want = np.asarray(predict(load_model(tmp_path / "cal.toml"), np.asarray(sim.q[0])[:5]))
    for k, qk in enumerate(np.asarray(sim.q[0])[:5]):
        u.update_cfg(dict(zip([f"q{i}" for i in range(1, 7)], qk)))
        for j in range(3):
            got = u.get_transform(f"jaxcal_point{j + 1}", "jaxcal_measurement_frame")[:3, 3] * 1000.0
            assert np.abs(got - want[k, j]).max() < 1e-6
    code, out, err = run_cli(
        monkeypatch, capsys, "evaluate", tmp_path / "cal.toml", data, "--json", tmp_path / "ev.json"
    )
    assert code in (0, None), err
    train = json.loads((tmp_path / "rep.json").read_text())["train_rms_mm"]
    assert json.loads((tmp_path / "ev.json").read_text())["position_rms_mm"] == pytest.approx(train, rel=1e-6)
    # fitted on markers 3 and 1 only (in that order): the file records them, and evaluate scores
    # those two by default, each against its own point
    code, out, err = run_cli(
        monkeypatch, capsys, "calibrate", "ur5", data, "--nested-max-poses", "0", "--compliance", "no",
        "--points", "3,1",
        "--out-robot", tmp_path / "c31.toml", "--json", tmp_path / "r31.json",
    )  # fmt: skip
    assert code in (0, None), err
    assert "point_numbers = [ 3, 1, ]" in " ".join((tmp_path / "c31.toml").read_text().split())
    # each point's parameters and printed position carry its number in the file, not its place
    r31 = json.loads((tmp_path / "r31.json").read_text())
    assert [k for k in r31["parameters"] if k.startswith("point")] == [f"point{j}_{c}" for j in (3, 1) for c in "xyz"]
    printed = [ln.split(":")[0].strip() for ln in out.splitlines() if "on the tool:" in ln]
    assert printed == ["point 3 on the tool", "point 1 on the tool"]
    # the pair fitted is markers 1 and 3 (their distance on the tool), in that order of the file
    p3, p1 = np.asarray(r31["points_mm"])
    assert np.linalg.norm(p3 - p1) == pytest.approx(np.linalg.norm(pts[2] - pts[0]), abs=0.1)
    code, out, err = run_cli(
        monkeypatch, capsys, "evaluate", tmp_path / "c31.toml", data, "--json", tmp_path / "e.json"
    )
    assert code in (0, None), err
    ev, train = json.loads((tmp_path / "e.json").read_text()), json.loads((tmp_path / "r31.json").read_text())
    assert [p["point"] for p in ev["points"]] == [3, 1] == train["point_numbers"]
    assert ev["position_rms_mm"] == pytest.approx(train["train_rms_mm"], rel=1e-6)
    # the preset itself, as calibrate takes it: its errors may be the arm's own, never calibrated
    code, out, err = run_cli(monkeypatch, capsys, "evaluate", "ur5", data, "--points", "1")
    assert code in (0, None), err
    assert "if this model was never calibrated" in " ".join((out + err).split())


def test_a_pose_the_camera_did_not_measure_is_dropped_and_named(tmp_path, monkeypatch, capsys):
    """Franka camera rows whose seven measurement cells are empty (or nan) are dropped: evaluate
    names them and scores the other rows alone."""
    from jaxcal.measurements import franka_csv_path

    lines = franka_csv_path().read_text().splitlines()[:13]
    for k, fill in ((3, ""), (8, "nan")):
        lines[k] = ",".join(lines[k].split(",")[:7] + [fill] * 7)
    data = tmp_path / "seen.csv"
    data.write_text("\n".join(lines) + "\n")
    code, out, err = run_cli(
        monkeypatch, capsys, "evaluate", "panda", data, "--length-unit", "m", "--json", tmp_path / "e.json"
    )
    assert code in (0, None), err
    assert "row(s) 3, 8 dropped: no pose measured there" in " ".join((out + err).split())
    ev = json.loads((tmp_path / "e.json").read_text())
    assert ev["dropped_rows"] == [3, 8] and [p["row"] for p in ev["poses"]] == [1, 2, 4, 5, 6, 7, 9, 10, 11, 12]


def test_an_output_that_is_an_input_or_another_output_is_refused(tmp_path, monkeypatch, capsys):
    """`--json DATA.csv` would replace the measurements by their report, and two outputs on one
    path would keep only the last: each is refused before any work, naming both, and the data
    file is left as it was (also through another spelling of its path)."""
    from jaxcal.measurements import tiago_paths

    urdf, csv = tiago_paths()
    data = tmp_path / "t.csv"
    data.write_bytes(csv.read_bytes())
    calib = ("calibrate", urdf, data, "--params", "frames")
    code, out, err = run_cli(monkeypatch, capsys, *calib, "--json", tmp_path / "sub" / ".." / "t.csv")
    assert code == 2 and "--json" in err and "is the data file; it would be overwritten" in err, err
    code, out, err = run_cli(monkeypatch, capsys, *calib, "--json", tmp_path / "a.out", "--report", tmp_path / "a.out")
    assert code == 2 and "--report" in err and "is also --json; each output needs its own file" in err, err
    code, out, err = run_cli(monkeypatch, capsys, *calib, "--out-model", urdf)
    assert code == 2 and "is the robot file" in err, err
    code, out, err = run_cli(monkeypatch, capsys, "evaluate", urdf, data, "--json", data)
    assert code == 2 and "is the data file" in err, err
    assert data.read_bytes() == csv.read_bytes() and not (tmp_path / "a.out").exists()


def test_info_shows_the_frames_and_limits_of_a_dh_robot(tmp_path, monkeypatch, capsys):
    """A calibrated DH file's base and tool frames are part of its model: `info` prints them (rpy
    as scipy's fixed-axis x-y-z angles of the same matrix) beside each joint's limits."""
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", [0.1, 0.2, 0.3]).as_matrix()
    T[:3, 3] = [10.0, -20.0, 30.0]
    r = preset("ur5").replace(base=T, q_limits=np.tile([-1.25, 2.75], (6, 1)))
    save_robot(r, tmp_path / "r.toml")
    code, out, err = run_cli(monkeypatch, capsys, "info", tmp_path / "r.toml")
    assert code in (0, None), err
    assert "base: xyz 10 -20 30 mm, rpy 0.1 0.2 0.3 rad" in out and "tool: xyz 0 0 0 mm" in out
    assert out.count("-1.25") == 6  # each joint's lower limit (the column may wrap)


def test_info_says_a_joint_given_no_limits_has_none(monkeypatch, capsys):
    """The UR presets give no limits: `info` says so, and shows the range poses are sampled in
    (the Panda preset's are its own)."""
    code, out, err = run_cli(monkeypatch, capsys, "info", "ur5")
    assert code in (0, None), err
    assert out.count("none") == out.count("sampled") == 6 and out.count("3.142") == 12  # the column may wrap
    code, out, err = run_cli(monkeypatch, capsys, "info", "panda")
    assert "none" not in out and out.count("2.897") == 8


@pytest.mark.parametrize("command", ["calibrate", "design", "montecarlo", "info", "evaluate", "compensate"])
def test_the_help_names_every_preset(monkeypatch, capsys, command):
    """The robot argument's help lists the presets a command accepts, each of them, and the list
    written out for the help is the presets'."""
    from jaxcal.cli._app import PRESET_NAMES
    from jaxcal.robot import PRESETS

    assert PRESET_NAMES == tuple(PRESETS)
    code, out, _ = run_cli(monkeypatch, capsys, command, "--help")
    assert code in (0, None)
    text = re.sub(r"[\s│]", "", out)  # rich wraps and boxes the help
    for name in PRESETS:
        assert name in text, name


def test_the_command_list_gives_each_command_a_short_summary(monkeypatch, capsys):
    """``jaxcal --help`` lists each command with a line or two, not its whole description broken
    where the docstring's lines end."""
    code, out, _ = run_cli(monkeypatch, capsys, "--help")
    assert code in (0, None)
    box = out[out.index("Commands") :]
    rows = [ln for ln in box.splitlines()[1:] if ln.startswith("│")]
    names = [ln.split()[1] for ln in rows if ln[2] != " "]
    assert {"calibrate", "compensate", "design", "evaluate"} <= set(names)
    assert len(rows) <= 2 * len(names), box


def test_a_library_warning_is_said_as_one_line_of_the_command(monkeypatch, capsys):
    """A warning from inside the library reaches the terminal as the command's own
    ``warning: ...`` line, not Python's ``file:line: UserWarning`` form."""
    import warnings

    from jaxcal.cli import _info

    loaded = _info.load_robot_arg

    def load(*a, **k):
        warnings.warn("greedy base set topped up [by QR]", UserWarning, stacklevel=1)
        return loaded(*a, **k)

    monkeypatch.setattr(_info, "load_robot_arg", load)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        code, _, err = run_cli(monkeypatch, capsys, "info", "ur5")
    assert code in (0, None)
    assert err == "warning: greedy base set topped up [by QR]\n"
    assert warnings.showwarning is not None and "jaxcal" not in getattr(warnings.showwarning, "__module__", "")


@pytest.mark.parametrize(
    "command", [("info",), ("design", "--poses", "8", "--out", "never.csv"), ("evaluate", "data.csv")]
)
def test_chain_links_given_with_a_preset_are_refused(monkeypatch, capsys, tmp_path, command):
    """--base-link / --tip-link choose a URDF's chain: with a preset they would be ignored."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "data.csv").write_text("q1,q2,q3,q4,q5,q6,x,y,z\n" + "0.1,0.2,0.3,0.4,0.5,0.6,100,200,300\n" * 3)
    code, _, err = run_cli(monkeypatch, capsys, command[0], "paper-6r", *command[1:], "--tip-link", "nothing")
    assert code == 2 and "a preset; base_link and tip_link choose the chain of a URDF file" in " ".join(err.split())
    assert not (tmp_path / "never.csv").exists()
