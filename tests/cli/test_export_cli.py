"""`jaxcal calibrate --out-ur-kinematics --out-dh --report` on simulated UR5 tracker data: the
UR kinematics file's forward kinematics, computed from the YAML alone, reproduces the calibrated
model to 1e-6 mm; every output is written only on success; robots the outputs cannot describe
are refused before any fitting."""

import csv
import json

import numpy as np
import pytest
import yaml
from helpers import UR5_TRACKER, measurement_csv, pairwise_distances, run_cli, ur5_factory_doc, ur5_tracker, ur_yaml_fk

import jaxcal
import jaxcal.calibration

OUTPUTS = {"--out-ur-kinematics": "cal.yaml", "--out-dh": "dh.csv", "--report": "report.html"}


@pytest.fixture(scope="module")
def tracker_csv(tmp_path_factory):
    _, sim, _, _ = ur5_tracker()
    path = tmp_path_factory.mktemp("d") / "tracker.csv"
    path.write_text(measurement_csv(sim.q[0], sim.measured[0], position_only=True))
    return path


def _calibrate(monkeypatch, capsys, tmp_path, data, robot="ur5", *extra):
    opts = ["--folds", UR5_TRACKER["folds"], "--params", UR5_TRACKER["params"]]
    opts += ["--sigma-pos-mm", UR5_TRACKER["sigma_pos"], "--out-robot", tmp_path / "cal.toml"]
    outs = [v for k, f in OUTPUTS.items() for v in (k, tmp_path / f)]
    return run_cli(monkeypatch, capsys, "calibrate", robot, data, *opts, *outs, *extra)


def test_ur_kinematics_reproduce_the_calibrated_model(tmp_path, monkeypatch, capsys, tracker_csv):
    code, out, err = _calibrate(monkeypatch, capsys, tmp_path, tracker_csv)
    assert code in (0, None), err
    cal = jaxcal.load_robot(tmp_path / "cal.toml")
    doc = yaml.safe_load((tmp_path / "cal.yaml").read_text())
    q = np.random.default_rng(5).uniform(-np.pi, np.pi, (300, 6))
    chain = ur_yaml_fk(doc, q)
    chain[:, :3, 3] *= 1000.0  # m -> mm
    # the last link's a6, alpha6 are held (the tool absorbs them): UR's flange is DH frame 6
    assert np.all(np.asarray(cal.dh)[5, 2:] == 0.0)
    flange = np.asarray(jaxcal.fk(cal.replace(tool=np.eye(4)), q))
    worst = np.abs(pairwise_distances(chain[:, :3, 3]) - pairwise_distances(flange[:, :3, 3])).max()
    assert worst < 1e-6, worst  # mm
    # with the calibrated base in front and the tool (the reflector) behind: the measured points
    ends = np.asarray(cal.base) @ chain @ np.asarray(cal.tool)
    np.testing.assert_allclose(ends[:, :3, 3], np.asarray(jaxcal.fk(cal, q))[:, :3, 3], atol=1e-6)
    out = " ".join(out.split())  # as rich wrapped it
    assert f"sigma_pos {UR5_TRACKER['sigma_pos']:.3g} mm (--sigma-pos-mm)" in out  # the weight given, named
    assert "not in it" in out and "base (measurement frame -> base)" in out and "tool (tool0 -> TCP)" in out
    # the base as printed, rotation included, is the calibrated one (roll, pitch, yaw about fixed x, y, z)
    from scipy.spatial.transform import Rotation

    said = out.split("base (measurement frame -> base): xyz ")[1].split(" rad")[0]
    xyz, rpy = (np.array(part.split(", "), float) for part in said.split(" mm, rpy "))
    np.testing.assert_allclose(xyz, np.asarray(cal.base)[:3, 3], atol=1e-4)
    R = Rotation.from_euler("xyz", rpy).as_matrix()
    np.testing.assert_allclose(R, np.asarray(cal.base)[:3, :3], atol=2e-6)
    assert np.abs(rpy).max() > 1e-4  # a turned base: the rotation matters
    text = (tmp_path / "cal.yaml").read_text()
    assert "# not in this file" in text and "heldout_rms_mm" in text
    # the DH table holds the calibrated table of the robot file
    rows = list(csv.DictReader((tmp_path / "dh.csv").open()))
    np.testing.assert_array_equal([float(r["calibrated"]) for r in rows], np.asarray(cal.dh).ravel())
    assert {r["convention"] for r in rows} == {"sdh"}
    # given where a robot file goes, it is named for what it is (it was "not valid TOML")
    with pytest.raises(jaxcal.RobotFileError, match="a calibrate --out-dh table lists the DH parameters"):
        jaxcal.load_robot(tmp_path / "dh.csv")
    html = (tmp_path / "report.html").read_text()
    assert html.startswith("<!DOCTYPE html>") and html.count("data:image/png;base64,") == 3
    # evaluated alone, the UR file has neither frame: the command says so
    code, out, err = run_cli(monkeypatch, capsys, "evaluate", tmp_path / "cal.yaml", tracker_csv, "--length-unit", "mm")
    assert code in (0, None) and "is a UR kinematics file, which holds no base or tool frame" in " ".join(out.split())


def test_nothing_written_unless_the_fit_converged(tmp_path, monkeypatch, capsys, tracker_csv):
    """A final fit that did not converge writes none of the outputs (and keeps an old one)."""
    real = jaxcal.calibration.calibrate_data

    def not_converged(*a, **kw):
        res = real(*a, **kw)
        res.report["converged"] = False
        return res

    monkeypatch.setattr(jaxcal.calibration, "calibrate_data", not_converged)
    (tmp_path / "dh.csv").write_text("the user's table\n")
    code, out, err = _calibrate(monkeypatch, capsys, tmp_path, tracker_csv)
    assert code == 1 and "did not converge" in out + err
    assert not (tmp_path / "cal.yaml").exists() and not (tmp_path / "report.html").exists()
    assert (tmp_path / "dh.csv").read_text() == "the user's table\n"


def test_a_fit_stopped_short_is_not_judged_as_a_calibration(tmp_path, monkeypatch, capsys, tracker_csv):
    """One solver step (--max-steps 1) leaves the parameters where they started: the command says
    the fit did not converge (exit 1), not that the data do not determine the parameters it never
    moved (exit 3, with a likely input mistake)."""
    code, out, err = _calibrate(monkeypatch, capsys, tmp_path, tracker_csv, "ur5", "--max-steps", "1")
    assert code == 1 and "error: the final fit did not converge in 1 step(s) (--max-steps 1)" in " ".join(err.split())
    assert "not a calibration" not in err and not (tmp_path / "cal.toml").exists()


def _no_fit(*a, **kw):
    raise AssertionError("calibrate_data was called: the refusal came after the fit")


@pytest.mark.parametrize(
    "robot, flag, msg",
    [
        ("panda", "--out-ur-kinematics", "needs a six-joint revolute arm as a DH table (UR's, or any such) or as UR's"),
        ("tiago", "--out-ur-kinematics", "it has 8 joints, not 6"),
        ("tiago", "--out-dh", "is described by joint frames (a URDF), not a DH table"),
    ],
)
def test_robots_refused_before_fitting(tmp_path, monkeypatch, capsys, tracker_csv, robot, flag, msg):
    from pathlib import Path

    monkeypatch.setattr(jaxcal.calibration, "calibrate_data", _no_fit)
    path = Path(jaxcal.__file__).parent / "data" / "tiago_mocap" / "tiago_arm.urdf" if robot == "tiago" else robot
    code, out, err = run_cli(monkeypatch, capsys, "calibrate", path, tracker_csv, flag, tmp_path / "x.out")
    err = " ".join(err.split())
    assert code == 2 and err.startswith(f"error: {flag}") and msg in err, err
    assert not (tmp_path / "x.out").exists()


@pytest.mark.parametrize("flag", list(OUTPUTS))
def test_unwritable_output_refused_before_fitting(tmp_path, monkeypatch, capsys, tracker_csv, flag):
    monkeypatch.setattr(jaxcal.calibration, "calibrate_data", _no_fit)
    (tmp_path / "afile").write_text("x")
    code, out, err = run_cli(monkeypatch, capsys, "calibrate", "ur5", tracker_csv, flag, tmp_path / "afile" / "x")
    err = " ".join(err.split())
    assert code == 2 and flag in err and "is a file, not a folder" in err, err


def test_an_output_that_fails_late_leaves_none_written(tmp_path, monkeypatch, capsys, tracker_csv):
    """A folder where a plot goes: the command stops with an error naming it, and none of the
    other outputs (robot, UR file, DH table, report) is written."""
    (tmp_path / "plots" / "parameters.png").mkdir(parents=True)
    code, out, err = _calibrate(monkeypatch, capsys, tmp_path, tracker_csv, "ur5", "--plots", tmp_path / "plots")
    err = " ".join(err.split())
    assert code == 2 and "parameters.png: is a directory" in err and "Traceback" not in err, err
    assert "written to" not in out  # nothing said to be written that was not
    for f in ("cal.toml", *OUTPUTS.values()):
        assert not (tmp_path / f).exists(), f
    assert not (tmp_path / "plots" / "pose_errors.png").exists()


@pytest.mark.parametrize(
    "flag, name, msg",
    [
        ("--out-robot", "cal.yaml", "a robot file is TOML (.toml) or URDF (.urdf)"),
        ("--out-model", "cal.yml", "a robot file is TOML (.toml) or URDF (.urdf)"),
        ("--out-ur-kinematics", "cal.toml", "a UR kinematics file is YAML"),
    ],
)
def test_an_output_named_as_another_format_refused_before_fitting(
    tmp_path, monkeypatch, capsys, tracker_csv, flag, name, msg
):
    """jaxcal reads a robot file by its name's ending: a TOML named .yaml would be read back as
    UR's format, and a UR file named .toml as TOML."""
    monkeypatch.setattr(jaxcal.calibration, "calibrate_data", _no_fit)
    code, out, err = run_cli(monkeypatch, capsys, "calibrate", "ur5", tracker_csv, flag, tmp_path / name)
    err = " ".join(err.split())
    assert code == 2 and err.startswith(f"error: {flag}") and msg in err, err
    assert not (tmp_path / name).exists()


def test_a_compliant_models_ur_file_gives_its_rigid_geometrys_error(tmp_path, monkeypatch, capsys):
    """A UR5 with compliant joints: the UR kinematics file holds the rigid geometry alone, so its
    header gives that geometry's error on the data (checked by composing the file's chain with
    NumPy), not the held-out error of the model with compliances, which it is named as."""
    rng = np.random.default_rng(21)
    ur5 = jaxcal.preset("ur5")
    tool = np.eye(4)
    tool[:3, 3] = [0.0, 0.0, 150.0]
    true = ur5.replace(compliance=np.r_[0.0, 3e-5, 2e-5, 1e-5, 0.0, 0.0], tool=tool)
    q = rng.uniform(-np.pi, np.pi, (40, 6))
    points = np.asarray(jaxcal.fk(true, q))[:, :3, 3] + rng.normal(0.0, 0.02, (40, 3))
    data = tmp_path / "bent.csv"
    rows = "".join(",".join(repr(float(v)) for v in (*a, *b)) + "\n" for a, b in zip(q, points))
    data.write_text("q1,q2,q3,q4,q5,q6,x,y,z\n" + rows)
    code, out, err = run_cli(
        monkeypatch, capsys, "calibrate", "ur5", data, "--params", "all", "--compliance", "yes", "--folds", "3",
        "--nested-max-poses", "0", "--out-robot", tmp_path / "cal.toml", "--out-ur-kinematics", tmp_path / "cal.yaml",
        "--json", tmp_path / "rep.json",
    )  # fmt: skip
    assert code in (0, None), err
    text = (tmp_path / "cal.yaml").read_text()
    head = dict(line[2:].split(": ", 1) for line in text.splitlines() if line.startswith("# ") and ": " in line)
    assert "heldout_rms_mm" not in head and "not in this file" in head["compliance"]
    cal = jaxcal.load_robot(tmp_path / "cal.toml")
    chain = ur_yaml_fk(yaml.safe_load(text), q)
    chain[:, :3, 3] *= 1000.0  # m -> mm
    ends = np.asarray(cal.base) @ chain @ np.asarray(cal.tool)
    rigid = float(np.sqrt(np.mean(np.sum((ends[:, :3, 3] - points) ** 2, -1))))
    assert float(head["rigid_geometry_rms_mm_on_the_data"]) == pytest.approx(rigid, rel=1e-4)
    assert rigid > 5 * float(head["heldout_rms_mm_with_compliance"])  # what the file alone does not reach
    # and the report says it, for a script that reads --json rather than the file's header
    rep = json.loads((tmp_path / "rep.json").read_text())
    assert rep["rigid_geometry_rms_mm_on_the_data"] == pytest.approx(rigid, rel=1e-4)
    assert any("a reader of the rigid geometry" in n for n in rep["notes"])


def test_a_factory_calibrated_ur_file_calibrated_again_is_written_back(tmp_path, monkeypatch, capsys):
    """A UR5 factory calibration file (joint frames) and tracker data of an arm that has since
    moved off it: the UR file the command writes, composed with NumPy and the tool it prints,
    predicts the arm's points at new joint values within the training ranges to noise level,
    where the factory file errs by millimetres. The URDF it writes starts at base_link_inertia
    and is written back too; a URDF's chain not said to start there is refused
    (``test_robots_refused_before_fitting``)."""
    rng = np.random.default_rng(8)
    factory = ur5_factory_doc(rng)
    factory["kinematics"]["wrist_1"]["yaw"] -= 2 * np.pi  # as real files have: the written one follows it
    (tmp_path / "factory.yaml").write_text(yaml.safe_dump(factory))
    truth = {"kinematics": {k: v for k, v in factory["kinematics"].items()}}
    moved = ur5_factory_doc(rng)["kinematics"]  # the arm's drift since: a second set of errors
    nominal = ur5_factory_doc(rng, 0.0, 0.0)["kinematics"]
    for k in moved:
        if isinstance(moved[k], dict):
            truth["kinematics"][k] = {c: factory["kinematics"][k][c] + moved[k][c] - nominal[k][c] for c in moved[k]}
    lo, hi = np.array([-3.0, -2.6, -2.6, -3.0, -3.0, -3.0]), np.array([3.0, -0.5, 2.6, 3.0, 3.0, 3.0])
    q = rng.uniform(lo, hi, (60, 6))
    B = np.eye(4)
    B[:3, 3] = [1500.0, -300.0, 200.0]
    tcp = np.array([10.0, 20.0, 80.0, 1.0])
    chain = ur_yaml_fk(truth, q)
    chain[:, :3, 3] *= 1000.0
    points = np.einsum("kij,j->ki", B @ chain, tcp)[:, :3]
    poses = np.tile(np.eye(4), (len(q), 1, 1))
    poses[:, :3, 3] = points
    (tmp_path / "data.csv").write_text(measurement_csv(q, poses, position_only=True, rng=rng, sigma_mm=0.02))
    code, out, err = run_cli(
        monkeypatch, capsys, "calibrate", tmp_path / "factory.yaml", tmp_path / "data.csv", "--length-unit", "mm",
        "--folds", "3", "--params", "all", "--out-ur-kinematics", tmp_path / "cal.yaml",
        "--out-model", tmp_path / "m.urdf",
    )  # fmt: skip
    assert code in (0, None), err
    # its URDF names the chain's first frame as UR does, so that it too is written back as a UR file
    assert '<parent link="base_link_inertia"/>' in (tmp_path / "m.urdf").read_text()
    code, _, err = run_cli(
        monkeypatch, capsys, "calibrate", tmp_path / "m.urdf", tmp_path / "data.csv", "--length-unit", "mm",
        "--folds", "3", "--params", "frames", "--out-ur-kinematics", tmp_path / "again.yaml",
    )  # fmt: skip
    assert code in (0, None), err
    said = " ".join(out.split()).split("tool (tool0 -> TCP): xyz ")[1].split(" mm")[0]
    tool = np.r_[np.array(said.split(", "), float), 1.0]
    new = rng.uniform(lo, hi, (200, 6))
    truth_chain, cal_chain, factory_chain = (
        ur_yaml_fk(d, new) for d in (truth, yaml.safe_load((tmp_path / "cal.yaml").read_text()), factory)
    )

    def distances(chain, p):  # of the tool point, mm (the chains are in metres)
        return pairwise_distances(np.einsum("kij,j->ki", chain, p * [1e-3, 1e-3, 1e-3, 1.0])[:, :3] * 1000.0)

    want = distances(truth_chain, tcp)
    assert np.abs(distances(cal_chain, tool) - want).max() < 0.15
    assert np.abs(distances(factory_chain, tcp) - want).max() > 2.0  # what the fit had to find
    cal = yaml.safe_load((tmp_path / "cal.yaml").read_text())["kinematics"]
    assert abs(cal["wrist_1"]["yaw"] - factory["kinematics"]["wrist_1"]["yaw"]) < 0.1
