"""Realistic mistakes in a data file never become a calibration: `jaxcal calibrate` refuses
them with the likely cause, writes nothing and exits non-zero. The data come from a forward
kinematics written apart from jaxcal (`helpers.dh_fk`)."""

import numpy as np
import pytest
from helpers import dh_fk, measurement_csv, run_cli  # noqa: E402
from scipy.spatial.transform import Rotation

from jaxcal import preset

K = 30


@pytest.fixture(scope="module")
def truth():
    """A UR5 with small DH errors, a base frame (mounting) and a tool, and K poses."""
    rng = np.random.default_rng(24)
    ur5 = preset("ur5")
    dh = (
        np.asarray(ur5.dh)
        + np.c_[rng.normal(0, 2e-3, 6), rng.normal(0, 0.5, 6), rng.normal(0, 0.5, 6), rng.normal(0, 2e-3, 6)]
    )
    base = np.eye(4)
    base[:3, :3] = Rotation.from_euler("xyz", [0.02, -0.03, 1.1]).as_matrix()
    base[:3, 3] = [900.0, -350.0, 120.0]
    tool = np.eye(4)
    tool[:3, 3] = [15.0, -10.0, 120.0]
    q = rng.uniform(-np.pi, np.pi, (K, 6))
    poses = dh_fk(dh, q, base=base, tool=tool)
    return dict(q=q, poses=poses, rng=rng)


def _csv(truth, q=None, poses=None, **kw):
    q = truth["q"] if q is None else q
    poses = truth["poses"] if poses is None else poses
    return measurement_csv(q, poses, rng=np.random.default_rng(7), sigma_mm=0.05, sigma_rad=5e-4, **kw)


def _relabel(text, mapping):
    """The header with column names replaced (the data stay where they are)."""
    head, rest = text.split("\n", 1)
    cols = head.split(",")
    return ",".join(mapping.get(c, c) for c in cols) + "\n" + rest


def _quaternion_xyzw(text):
    """The quaternion written x, y, z, w under a w, x, y, z header."""
    head, *rows = text.strip().split("\n")
    out = [head]
    for r in rows:
        f = r.split(",")
        f[-4:] = f[-3:] + f[-4:-3]
        out.append(",".join(f))
    return "\n".join(out) + "\n"


def _mirrored_y(poses):
    """Positions from a measurement frame whose y axis points the other way (left-handed)."""
    out = np.array(poses, copy=True)
    out[:, 1, 3] *= -1
    return out


MISTAKES = {
    "x and y swapped": (lambda t: _relabel(_csv(t), {"x": "y", "y": "x"}), "swapped x, y"),
    "joints 2 and 3 swapped": (
        lambda t: _relabel(_csv(t), {"q2": "q3", "q3": "q2"}),
        "joints 2 and 3 swapped ('q2', 'q3')",
    ),
    "joint names reversed": (
        lambda t: _relabel(_csv(t), {f"q{i}": f"q{7 - i}" for i in range(1, 7)}),
        "joints reversed",
    ),
    "quaternion x, y, z, w": (lambda t: _quaternion_xyzw(_csv(t)), "quaternion written x, y, z, w"),
    "y axis mirrored": (lambda t: _csv(t, poses=_mirrored_y(t["poses"])), "mirrored y"),
}


def _run(tmp_path, monkeypatch, capsys, text, *extra):
    data = tmp_path / "data.csv"
    data.write_text(text)
    out_robot, report = tmp_path / "out.toml", tmp_path / "report.json"
    code, out, err = run_cli(
        monkeypatch,
        capsys,
        "calibrate",
        "ur5",
        data,
        "--folds",
        "3",
        "--params",
        "all",
        "--compliance",  # the data carry none; the refusals are the point
        "no",
        "--out-robot",
        out_robot,
        "--json",
        report,
        *extra,
    )
    return code, out, " ".join(err.split()), out_robot, report


def test_correct_file_calibrates(tmp_path, monkeypatch, capsys, truth):
    code, out, err, out_robot, report = _run(tmp_path, monkeypatch, capsys, _csv(truth))
    assert code == 0, err
    assert out_robot.exists() and report.exists()


@pytest.mark.parametrize("case", list(MISTAKES))
def test_mistake_refused_with_its_cause(tmp_path, monkeypatch, capsys, truth, case):
    make, cause = MISTAKES[case]
    code, out, err, out_robot, report = _run(tmp_path, monkeypatch, capsys, make(truth))
    assert code == 3, err
    assert "not a calibration" in err and f"Likely cause: {cause}" in err, err
    assert "nothing was written" in err
    assert not out_robot.exists() and not report.exists()
    assert "Traceback" not in err


def test_degrees_in_a_radians_file_refused(tmp_path, monkeypatch, capsys, truth):
    text = measurement_csv(np.degrees(truth["q"]), truth["poses"])
    code, out, err, out_robot, report = _run(tmp_path, monkeypatch, capsys, text)
    assert code == 2 and "--angle-unit deg" in err, err
    assert not out_robot.exists() and not report.exists()


def test_radians_read_as_degrees_named(tmp_path, monkeypatch, capsys, truth):
    """A file in radians read with --angle-unit deg: every joint barely moves, the positions spread
    unlike the model's, and the message names the unit."""
    code, out, err, out_robot, report = _run(tmp_path, monkeypatch, capsys, _csv(truth), "--angle-unit", "deg")
    assert code == 2 and "radians read as degrees" in err and "--angle-unit rad" in err, err
    assert not out_robot.exists() and not report.exists()


def test_metres_with_a_mm_robot_refused(tmp_path, monkeypatch, capsys, truth):
    poses = truth["poses"].copy()
    poses[:, :3, 3] /= 1000.0
    code, out, err, out_robot, report = _run(tmp_path, monkeypatch, capsys, measurement_csv(truth["q"], poses))
    assert code == 2 and "--length-unit m" in err, err
    assert not out_robot.exists() and not report.exists()


def test_failed_run_keeps_the_previous_model(tmp_path, monkeypatch, capsys, truth):
    """A run that does not converge leaves an existing output file as it was."""
    out_robot = tmp_path / "out.toml"
    out_robot.write_text("# the user's good model\n")
    code, out, err, _, report = _run(tmp_path, monkeypatch, capsys, _csv(truth), "--max-steps", "1")
    assert code == 1, err
    assert out_robot.read_text() == "# the user's good model\n" and not report.exists()
    assert "did not converge" in out + err


def test_output_path_under_a_file_refused_before_the_fit(tmp_path, monkeypatch, capsys, truth):
    (tmp_path / "afile").write_text("x")
    data = tmp_path / "data.csv"
    data.write_text(_csv(truth))
    code, out, err = run_cli(
        monkeypatch, capsys, "calibrate", "ur5", data, "--out-robot", tmp_path / "afile" / "r.toml"
    )
    err = " ".join(err.split())
    assert code == 2 and "--out-robot" in err and "is a file, not a folder" in err, err
    assert "Traceback" not in err and "calibrating" not in out
