"""Bad input never passes silently (issue 8): every public entry point (Python API and CLI)
raises a typed jaxcal error whose message names the offending row / column / parameter; the
CLI prints it as one line without a traceback and exits non-zero.

Each case is one row of a table (name -> call, expected error type, message pattern), so the
list doubles as the record of what was tried."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import jaxcal
from jaxcal import DataError, RobotFileError
from jaxcal.calibration import calibrate, calibrate_batch, identify
from jaxcal.compensation import compensate
from jaxcal.error_model import identification_jacobian, perturb
from jaxcal.experiments import run_montecarlo
from jaxcal.measurements import read_measurements, write_measurements
from jaxcal.robot import load_robot
from jaxcal.simulation import simulate

ROBOT = jaxcal.preset("paper-6r")
SIM = simulate(ROBOT, n_robots=2, n_poses=20, seed=0, sigma_pos=0.01, sigma_rot=1e-5)
Q, M = SIM.q[0], SIM.measured[0]


def _with(a, idx, value):
    b = np.array(a, copy=True)
    b[idx] = value
    return b


def _scaled_pos(m, s):
    b = np.array(m, copy=True)
    b[..., :3, 3] *= s
    return b


# -- Python API ------------------------------------------------------------------------------
PY = {
    # Robot(...)
    "Robot dh wrong shape": (lambda: jaxcal.Robot(np.zeros((6, 3))), RobotFileError, r"shape \(n_joints, 4\)"),
    "Robot dh 3-D": (lambda: jaxcal.Robot(np.zeros((1, 6, 4))), RobotFileError, r"got \(1, 6, 4\)"),
    "Robot no joints": (lambda: jaxcal.Robot(np.zeros((0, 4))), RobotFileError, "at least one joint"),
    "Robot dh nan": (
        lambda: jaxcal.Robot(_with(np.zeros((3, 4)), (2, 1), np.nan)),
        RobotFileError,
        "joint 3: d is not finite",
    ),
    "calibrate q ragged": (
        lambda: calibrate(jaxcal.preset("ur5"), [[0.0] * 6, [1.0, 2.0]], np.zeros((2, 3))),
        DataError,
        r"q: not a rectangular array of numbers",
    ),
    "calibrate q booleans": (
        lambda: calibrate(jaxcal.preset("ur5"), np.zeros((30, 6), bool), np.zeros((30, 3))),
        DataError,
        "q: expected real numbers, got booleans",
    ),
    "calibrate_batch point never seen in any data set": (
        lambda: calibrate_batch(
            jaxcal.preset("ur5"), np.zeros((3, 30, 6)), _with(np.zeros((3, 30, 2, 3)), (..., 1, slice(None)), np.nan)
        ),
        DataError,
        r"point\(s\) 2 not seen at any pose of any data set ",
    ),
    "calibrate q a list of booleans": (
        lambda: calibrate(jaxcal.preset("ur5"), [[True] * 6] * 30, np.zeros((30, 3))),
        DataError,
        "q: expected real numbers, got booleans",
    ),
    "Robot dh strings": (lambda: jaxcal.Robot(np.array([["a"] * 4])), DataError, "dh: expected real numbers"),
    "Robot dh complex": (lambda: jaxcal.Robot(np.zeros((2, 4), complex)), DataError, "complex"),
    "Robot convention": (lambda: jaxcal.Robot(np.zeros((2, 4)), convention="dh"), RobotFileError, "convention"),
    "Robot joint types count": (
        lambda: jaxcal.Robot(np.zeros((2, 4)), joint_types=("R", "R", "P")),
        RobotFileError,
        "3 joint types for 2 joints",
    ),
    "Robot joint type X": (
        lambda: jaxcal.Robot(np.zeros((2, 4)), joint_types=("R", "X")),
        RobotFileError,
        "joint 2: type",
    ),
    "Robot base 3x3": (lambda: jaxcal.Robot(np.zeros((2, 4)), base=np.eye(3)), RobotFileError, "base must be a 4x4"),
    "Robot tool not rigid": (
        lambda: jaxcal.Robot(np.zeros((2, 4)), tool=2 * np.eye(4)),
        RobotFileError,
        "tool is not a rigid",
    ),
    "Robot tool nan": (
        lambda: jaxcal.Robot(np.zeros((2, 4)), tool=np.full((4, 4), np.nan)),
        RobotFileError,
        "tool transform has non-finite",
    ),
    "Robot limits shape": (
        lambda: jaxcal.Robot(np.zeros((2, 4)), q_limits=np.zeros((3, 2))),
        RobotFileError,
        r"q_limits must have shape \(2, 2\)",
    ),
    "Robot limits inverted": (
        lambda: jaxcal.Robot(np.zeros((2, 4)), q_limits=[[0, 1], [1, 0]]),
        RobotFileError,
        "joint 2: lower limit",
    ),
    # fk / identification Jacobian / perturb
    "fk q one value": (
        lambda: jaxcal.fk(ROBOT, np.zeros(1)),
        DataError,
        r"q must have shape \(\.\.\., 6\).*got \(1,\)",
    ),
    "fk q 5 joints": (lambda: jaxcal.fk(ROBOT, np.zeros((4, 5))), DataError, r"got \(4, 5\)"),
    "fk q scalar": (lambda: jaxcal.fk(ROBOT, 0.0), DataError, r"got \(\)"),
    "fk q strings": (lambda: jaxcal.fk(ROBOT, np.array(["a"] * 6)), DataError, "expected real numbers"),
    "jacobian q 7 joints": (lambda: identification_jacobian(ROBOT, np.zeros((3, 7))), DataError, r"got \(3, 7\)"),
    "perturb x too long": (lambda: perturb(ROBOT, np.zeros(30)), DataError, r"x must have shape \(24,\)"),
    "perturb x base missing": (
        lambda: perturb(ROBOT, np.zeros(24), base=True),
        DataError,
        r"\(30,\) = 6 joints x 4 DH errors \+ 6 base",
    ),
    # calibrate
    "calibrate q 5 joints": (lambda: calibrate(ROBOT, Q[:, :5], M), DataError, "n = 6 joints"),
    "calibrate measured count": (
        lambda: calibrate(ROBOT, Q, M[:-1]),
        DataError,
        r"measured must have shape \(20, 4, 4\)",
    ),
    "calibrate q nan": (
        lambda: calibrate(ROBOT, _with(Q, (4, 2), np.nan), M),
        DataError,
        r"q: non-finite value \(nan\) at pose index 4, joint 'q3'",
    ),
    "calibrate measured inf": (
        lambda: calibrate(ROBOT, Q, _with(M, (7, 1, 3), np.inf)),
        DataError,
        r"measured: non-finite value \(inf\) at pose index 7, matrix element \[1\]\[3\]",
    ),
    "calibrate q complex": (lambda: calibrate(ROBOT, Q.astype(complex), M), DataError, "complex"),
    "calibrate q 1-D": (lambda: calibrate(ROBOT, Q[0], M[0]), DataError, r"q must have shape \(K, n\)"),
    "calibrate no poses": (lambda: calibrate(ROBOT, Q[:0], M[:0]), DataError, "too few poses: 0 poses"),
    "calibrate too few poses": (lambda: calibrate(ROBOT, Q[:3], M[:3]), DataError, "3 poses x 6 rows = 18"),
    "calibrate rotation not rigid": (
        lambda: calibrate(ROBOT, Q, _with(M, (3, 0, 0), 2.0)),
        DataError,
        r"measured\[3\]: rotation is not a proper rotation",
    ),
    "calibrate reflection": (
        lambda: calibrate(ROBOT, Q, M @ np.diag([1.0, 1.0, -1.0, 1.0])),
        DataError,
        r"measured\[0\]: rotation is not a proper rotation matrix \(its determinant is -1, a reflection",
    ),
    "calibrate bottom row": (
        lambda: calibrate(ROBOT, Q, _with(M, (5, 3, 0), 1.0)),
        DataError,
        r"measured\[5\]: bottom row",
    ),
    "calibrate metres as mm": (
        lambda: calibrate(ROBOT, Q, _scaled_pos(M, 1e-3)),
        DataError,
        r"positions spread .* metres read as millimetres.*length_unit=\"m\"",
    ),
    "calibrate method": (lambda: calibrate(ROBOT, Q, M, method="newton"), DataError, "method must be one of"),
    "calibrate sigma nan": (lambda: calibrate(ROBOT, Q, M, sigma_pos_mm=float("nan")), DataError, "sigma_pos_mm"),
    "calibrate sigma negative": (lambda: calibrate(ROBOT, Q, M, sigma_rot_rad=-1e-3), DataError, "sigma_rot_rad"),
    "calibrate rotation noise of positions": (
        lambda: calibrate(ROBOT, Q, M[:, :3, 3], sigma_rot_rad=1e-4),
        DataError,
        "sigma_rot_rad 0.0001: the noise of measured rotations; the data are positions",
    ),
    "calibrate max_steps 0": (lambda: calibrate(ROBOT, Q, M, max_steps=0), DataError, "max_steps"),
    "calibrate loss unknown": (lambda: calibrate(ROBOT, Q, M, loss="tukey"), DataError, "loss must be one of"),
    "calibrate loss with linear": (
        lambda: calibrate(ROBOT, Q, M, method="linear", loss="huber"),
        DataError,
        "needs method 'gn' or 'lm'",
    ),
    "calibrate loss_scale 0": (lambda: calibrate(ROBOT, Q, M, loss="huber", loss_scale=0.0), DataError, "loss_scale"),
    "calibrate loss_scale with l2": (lambda: calibrate(ROBOT, Q, M, loss_scale=1.0), DataError, "loss 'l2' has none"),
    "calibrate robot not Robot": (lambda: calibrate("paper-6r", Q, M), DataError, "robot must be a jaxcal.Robot"),
    # calibrate_batch
    "batch unbatched q": (lambda: calibrate_batch(ROBOT, Q, M), DataError, r"\(R, K, n\)"),
    "batch q nan": (
        lambda: calibrate_batch(ROBOT, _with(SIM.q, (1, 3, 0), np.nan), SIM.measured),
        DataError,
        r"q: non-finite value \(nan\) at data set 1, pose index 3, joint 'q1'",
    ),
    "batch too few poses": (
        lambda: calibrate_batch(ROBOT, SIM.q[:, :2], SIM.measured[:, :2]),
        DataError,
        "too few poses: 2 poses",
    ),
    "batch no data sets": (
        lambda: calibrate_batch(ROBOT, SIM.q[:0], SIM.measured[:0]),
        DataError,
        "no data sets: q and measured have R = 0",
    ),
    "batch metres in one data set": (
        lambda: calibrate_batch(ROBOT, SIM.q, np.stack([SIM.measured[0], _scaled_pos(SIM.measured[1], 1e-3)])),
        DataError,
        r"measured \(data set 1\)",
    ),
    "batch ident of other options": (
        lambda: calibrate_batch(
            ROBOT,
            SIM.q,
            SIM.measured,
            estimate_base=True,
            ident=identify(ROBOT, Q, estimate_base=False, estimate_tool=False),
        ),
        DataError,
        "ident is for",
    ),
    # simulate
    "simulate n_poses 0": (lambda: simulate(ROBOT, n_poses=0), DataError, "n_poses must be an integer >= 1"),
    "simulate n_robots 0": (lambda: simulate(ROBOT, n_robots=0), DataError, "n_robots"),
    "simulate outliers round to none": (
        lambda: simulate(ROBOT, n_poses=30, outliers=0.01),
        DataError,
        "a share of 0.01 of 30 poses rounds to no pose",
    ),
    "montecarlo one noise-free component": (
        lambda: run_montecarlo(ROBOT, n_robots=2, n_poses=20, sigma_pos=0.0, sigma_rot=1e-5),
        DataError,
        "noise_mm is 0 but the rotation noise is not",
    ),
    "simulate sigma nan": (lambda: simulate(ROBOT, sigma_pos=float("nan")), DataError, "sigma_pos"),
    "simulate sigma negative": (lambda: simulate(ROBOT, sigma_rot=-1.0), DataError, "sigma_rot"),
    "simulate x_true shape": (lambda: simulate(ROBOT, x_true=np.zeros(5)), DataError, r"x_true .* got \(5,\)"),
    "simulate q nan": (
        lambda: simulate(ROBOT, q=np.full((5, 6), np.nan)),
        DataError,
        r"q: non-finite value at index \(0, 0\)",
    ),
    "simulate q 5 joints": (lambda: simulate(ROBOT, q=np.zeros((5, 5))), DataError, r"q must have shape \(K, 6\)"),
    "simulate scales shape": (lambda: simulate(ROBOT, scales=np.ones(3)), DataError, "scales must be 24"),
    # compensate
    "compensate targets nan": (
        lambda: compensate(ROBOT, _with(M[:2], (1, 0, 3), np.nan), Q[:2]),
        DataError,
        r"targets: non-finite value at index \(1, 0, 3\)",
    ),
    "compensate q_start nan": (
        lambda: compensate(ROBOT, M[:2], _with(Q[:2], (0, 4), np.inf)),
        DataError,
        r"q_start: non-finite value at index \(0, 4\)",
    ),
    "compensate q_start 5 joints": (lambda: compensate(ROBOT, M[:2], Q[:2, :5]), DataError, r"\(K, 6\)"),
    "compensate targets not rigid": (
        lambda: compensate(ROBOT, _with(M[:2], (1, 0, 0), 3.0), Q[:2]),
        DataError,
        r"targets\[1\]: rotation",
    ),
    "compensate damping negative": (lambda: compensate(ROBOT, M[:2], Q[:2], damping=-1.0), DataError, "damping"),
    "calibrate a point never seen": (
        lambda: calibrate(ROBOT, Q, np.stack([M[:, :3, 3], np.full((len(Q), 3), np.nan)], 1)),
        DataError,
        r"point\(s\) 2 not seen at any pose \(all NaN, empty in the file\); leave them out",
    ),
    "calibrate_data one posture": (
        lambda: jaxcal.calibrate_data(ROBOT, jaxcal.Measurements(np.tile(Q[:1], (20, 1)), np.tile(M[:1], (20, 1, 1)))),
        DataError,
        r"no joint moves over the 20 poses: every row is the same posture \(rows 1\.\.20\)",
    ),
    "calibrate robot file in another unit": (  # not only the data's unit: the robot's, as written, is no arm
        lambda: calibrate(ROBOT.replace(dh=np.asarray(ROBOT.dh) * [1, 1000, 1000, 1]), Q, M),
        DataError,
        r"read the data with length_unit=\"m\"; or the robot file's lengths are not in mm: as written, the arm "
        r"reaches",
    ),
    "calibrate_data fewer poses than folds": (  # fewer folds would fit the frames (params auto tries those)
        lambda: jaxcal.calibrate_data(ROBOT, jaxcal.Measurements(Q[:4], M[:4])),
        DataError,
        r"folds \(5\) more than the distinct postures \(4; rows repeating a posture are one\): use fewer folds",
    ),
    "calibrate_data fewer poses than the parameters": (  # the poses' count first: fewer folds would not help
        lambda: jaxcal.calibrate_data(ROBOT, jaxcal.Measurements(Q[:4], M[:4]), params="all"),
        DataError,
        r"too few poses: 4 poses x 6 rows = 24 equations for \d+ parameters",
    ),
    "calibrate_data arrays as a tuple": (
        lambda: jaxcal.calibrate_data(ROBOT, (Q, M)),
        DataError,
        r"data must be a jaxcal.Measurements .* got tuple",
    ),
}


@pytest.mark.parametrize("case", list(PY))
def test_python_api(case):
    call, err, pattern = PY[case]
    with pytest.raises(err, match=pattern):
        call()


# -- robot files (TOML) ----------------------------------------------------------------------
GOOD_TOML = """name = "two"
convention = "sdh"
length_unit = "mm"
angle_unit = "rad"
[[joints]]
theta = 0.0
d = 100.0
a = 200.0
alpha = 1.5707963267948966
[[joints]]
theta = 0.1
d = 0.0
a = 300.0
alpha = 0.0
limits = [-2.0, 2.0]
[tool]
xyz = [0.0, 0.0, 50.0]
rpy = [0.0, 0.0, 0.0]
"""

TOML = {
    "unknown top-level key": ("colour = 'red'\n" + GOOD_TOML, "unknown top-level key(s) ['colour']"),
    "unknown joint key": (
        GOOD_TOML.replace("a = 300.0", "a = 300.0\noffset = 1"),
        "joint 2: unknown key(s) ['offset']",
    ),
    "unknown tool key": (
        GOOD_TOML.replace("rpy = [0.0, 0.0, 0.0]", "rpy = [0.0, 0.0, 0.0]\nscale = 1"),
        "[tool]: unknown key(s) ['scale']",
    ),
    "missing field": (GOOD_TOML.replace("d = 100.0\n", ""), "joint 1: missing d"),
    "missing all joints": ('name = "x"\n', "needs at least one [[joints]]"),
    "wrong type string": (GOOD_TOML.replace("a = 300.0", "a = '300'"), "joint 2 a: expected a number"),
    "wrong type bool": (GOOD_TOML.replace("d = 100.0", "d = true"), "joint 1 d: expected a number"),
    "wrong type joints": (GOOD_TOML.split("[[joints]]")[0] + "joints = 'RR'\n", "needs at least one [[joints]]"),
    "non-finite": (GOOD_TOML.replace("a = 200.0", "a = inf"), "joint 1 a: not finite"),
    "degrees under rad": (
        GOOD_TOML.replace("alpha = 1.5707963267948966", "alpha = 90.0"),
        "alpha = 90 rad, beyond a whole turn: are the file's angles degrees?",
    ),
    "bad joint type": (GOOD_TOML.replace("alpha = 0.0", "alpha = 0.0\ntype = 'S'"), "joint 2: type must be 'R' or 'P'"),
    "limits wrong length": (
        GOOD_TOML.replace("limits = [-2.0, 2.0]", "limits = [-2.0, 0.0, 2.0]"),
        "joint 2: limits must be [lower, upper]",
    ),
    "limits inverted": (
        GOOD_TOML.replace("limits = [-2.0, 2.0]", "limits = [2.0, -2.0]"),
        "joint 2: lower limit is not below",
    ),
    "tool xyz wrong length": (GOOD_TOML.replace("xyz = [0.0, 0.0, 50.0]", "xyz = [0.0, 50.0]"), "[tool].xyz"),
    "bad length unit": (GOOD_TOML.replace('length_unit = "mm"', 'length_unit = "inch"'), "length_unit"),
    "bad convention": (GOOD_TOML.replace('convention = "sdh"', 'convention = "dh"'), "convention"),
    "name not a string": (GOOD_TOML.replace('name = "two"', "name = 2"), "name must be a string"),
    "not TOML": (GOOD_TOML.replace("[[joints]]", "[[joints]\n", 1), "not valid TOML"),
    "empty file": ("", "needs at least one [[joints]]"),
}


def test_good_toml_loads(tmp_path):
    p = tmp_path / "good.toml"
    p.write_text(GOOD_TOML)
    r = load_robot(p)
    assert r.n_joints == 2 and r.joint_types == ("R", "R")


@pytest.mark.parametrize("case", list(TOML))
def test_robot_file(tmp_path, case):
    text, msg = TOML[case]
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(RobotFileError) as e:
        load_robot(p)
    assert msg in str(e.value)


def test_robot_file_joint_count_vs_data(tmp_path):
    """A 2-joint robot file with 6-joint measurement data: the inconsistent joint count is named."""
    p = tmp_path / "two.toml"
    p.write_text(GOOD_TOML)
    d = tmp_path / "six.csv"
    write_measurements(d, Q, M)
    with pytest.raises(DataError, match=r"robot has 2 joints, file has q1\.\.q6"):
        read_measurements(d, load_robot(p))
    with pytest.raises(DataError, match="n = 2 joints"):
        calibrate(load_robot(p), Q, M)


# -- measurement files -------------------------------------------------------------------------
def _csv_lines():
    """A good measurement file for ROBOT (mm, rad) as lines of text."""
    buf = []
    header = ",".join([f"q{j}" for j in range(1, 7)] + ["x", "y", "z"])
    buf.append(header)
    for qk, mk in zip(Q, M):
        buf.append(",".join(repr(float(v)) for v in list(qk) + list(mk[:3, 3])))
    return buf


LINES = _csv_lines()


def _mixed_m(lines):
    out = list(lines)
    vals = out[3].split(",")
    out[3] = ",".join(vals[:6] + [repr(float(v) / 1000) for v in vals[6:]])  # data row 3 in metres
    return out


def _sentinel(lines, rows=(3,), value="1e10"):
    """Three points per row (the second and third 50 mm off the first); the third point of the
    data ``rows`` written as a lost-marker stand-in, ``value`` in each coordinate."""
    out = [lines[0].replace("x,y,z", "x1,y1,z1,x2,y2,z2,x3,y3,z3")]
    for i, line in enumerate(lines[1:], start=1):
        v = line.split(",")
        second = [repr(float(c) + 50.0) for c in v[6:]]
        third = [value] * 3 if i in rows else [repr(float(c) - 50.0) for c in v[6:]]
        out.append(",".join(v + second + third))
    return out


def _wrapped(lines):
    out = list(lines)
    vals = out[5].split(",")
    vals[1] = repr(0.5 + 2 * np.pi)  # row 5: q2 a turn beyond 0.5 rad
    out[5] = ",".join(vals)
    return out


def _mixed_deg(lines):
    out = list(lines)
    vals = out[5].split(",")
    out[5] = ",".join([repr(float(v) * 180 / np.pi) if i == 1 else v for i, v in enumerate(vals)])  # row 5: q2 deg
    vals = out[5].split(",")
    vals[1] = "100.0"  # well beyond 2*pi
    out[5] = ",".join(vals)
    return out


CSV = {
    "empty": ([], "file is empty"),
    "blank lines only": (["", ""], "file is empty"),
    "header only": (LINES[:1], "header only, no data rows"),
    "duplicated column": (
        [LINES[0] + ",x"] + [r + ",1.0" for r in LINES[1:]],
        "duplicated column name 'x' (columns 7 and 10)",
    ),
    "missing column": (
        [LINES[0].replace(",z", "")] + [r.rsplit(",", 1)[0] for r in LINES[1:]],
        "missing column(s) 'z'",
    ),
    "x, y, z and numbered points": (
        [LINES[0] + ",x1,y1,z1"] + [r + ",1.0,2.0,3.0" for r in LINES[1:]],
        "both x, y, z and numbered point columns ('x1', 'y1', 'z1'); use one scheme",
    ),
    "7 joint columns": (
        [LINES[0].replace("q6", "q6,q7")] + [r.replace(",", ",0.0,", 1) for r in LINES[1:]],
        "robot has 6 joints, file has q1..q7",
    ),
    "not a number": (
        LINES[:4] + [LINES[4].replace(LINES[4].split(",")[7], "abc")] + LINES[5:],
        "row 4 (line 5), column 'y': not a number: 'abc'",
    ),
    "nan value": (
        LINES[:2] + [LINES[2].replace(LINES[2].split(",")[0], "nan", 1)] + LINES[3:],
        "row 2 (line 3), column 'q1': value 'nan' is not finite",
    ),
    "ragged row": (LINES[:3] + [LINES[3].rsplit(",", 1)[0]] + LINES[4:], "row 3 (line 4): 8 fields"),
    "mixed units m among mm": (_mixed_m(LINES), "mixed length units? row 3"),
    "a lost marker written as 1e10": (_sentinel(LINES), "row 3, point 3: position norm 1.732e+10 mm while"),
    # in most rows: the rows' other points, not the median row, say what their unit is
    "a marker lost in most rows written as 1e10": (
        _sentinel(LINES, rows=range(2, len(LINES))),
        "row 2, point 3: position norm 1.732e+10 mm while the row's other points",
    ),
    "a marker lost in most rows written as zeros": (
        _sentinel(LINES, rows=range(2, len(LINES)), value="0"),
        "point 3 is at exactly 0, 0, 0 in",
    ),
    "mixed units deg among rad": (_mixed_deg(LINES), "mixed angle units? row 5, column 'q2'"),
    "a joint reading off by a turn": (
        _wrapped(LINES),
        "mixed angle units, or a reading off by a whole turn (an encoder's wrap: 0.5 rad is within the limits)? "
        "row 5, column 'q2'",
    ),
}


@pytest.mark.parametrize("case", list(CSV))
def test_measurement_file(tmp_path, case):
    lines, msg = CSV[case]
    p = tmp_path / "m.csv"
    p.write_text("\n".join(lines) + ("\n" if lines else ""))
    with pytest.raises(DataError) as e:
        read_measurements(p, ROBOT)
    assert msg in str(e.value)


def test_a_sentinel_in_a_point_left_out_does_not_refuse_the_file(tmp_path):
    """The lost marker's sentinel is in point 3: reading point 1 alone reads every row, the
    file's own values; reading points 1 and 3 refuses it, naming point 3 (the file's number, not
    its place in the selection); point 3 alone cannot tell a sentinel from a unit, and says both."""
    p = tmp_path / "m.csv"
    p.write_text("\n".join(_sentinel(LINES)) + "\n")
    meas = read_measurements(p, ROBOT, points=[1])
    np.testing.assert_array_equal(meas.measured[:, 0], M[:, :3, 3])
    assert meas.point_numbers == (1,)
    with pytest.raises(DataError, match="row 3, point 3: position norm .* a lost marker written as a sentinel"):
        read_measurements(p, ROBOT, points=[1, 3])
    with pytest.raises(DataError, match="units, or a lost marker written as a sentinel value\\? row 3: position norm"):
        read_measurements(p, ROBOT, points=[3])


def test_good_file_reads(tmp_path):
    p = tmp_path / "m.csv"
    p.write_text("\n".join(LINES) + "\n")
    meas = read_measurements(p, ROBOT)
    np.testing.assert_array_equal(meas.q, Q)


# -- command line ------------------------------------------------------------------------------
from helpers import run_cli  # noqa: E402


def _files(tmp_path):
    good_csv = tmp_path / "good.csv"
    good_csv.write_text("\n".join(LINES) + "\n")
    bad_toml = tmp_path / "bad.toml"
    bad_toml.write_text(TOML["missing field"][0])
    header_only = tmp_path / "header.csv"
    header_only.write_text(LINES[0] + "\n")
    mixed = tmp_path / "mixed.csv"
    mixed.write_text("\n".join(_mixed_m(LINES)) + "\n")
    degrees = tmp_path / "degrees.csv"  # every joint column in degrees; data row 1 has no position (dropped)
    rows = [line.split(",") for line in LINES[1:]]
    rows[0][6:] = ["", "", ""]
    degrees.write_text(
        "\n".join([LINES[0]] + [",".join([repr(float(np.degrees(float(v)))) for v in r[:6]] + r[6:]) for r in rows])
        + "\n"
    )
    return dict(good=good_csv, bad_toml=bad_toml, header=header_only, mixed=mixed, degrees=degrees)


CLI = {
    "info bad robot file": (lambda f: ["info", f["bad_toml"]], "joint 1: missing d"),
    "info missing robot file": (lambda f: ["info", "no-such-robot"], "robot file not found: no-such-robot"),
    "verify --points 0": (lambda f: ["verify", "--points", "0"], "--points must be >= 40"),
    "montecarlo --method bogus": (
        lambda f: ["montecarlo", "paper-6r", "--robots", "2", "--poses", "10", "--method", "bogus"],
        "--method must be one of",
    ),
    "montecarlo --robots 0": (lambda f: ["montecarlo", "paper-6r", "--robots", "0"], "--robots must be"),
    "montecarlo --val-poses 0": (lambda f: ["montecarlo", "paper-6r", "--val-poses", "0"], "--val-poses"),
    "montecarlo --noise-mm -1": (lambda f: ["montecarlo", "paper-6r", "--noise-mm", "-1"], "--noise-mm must be"),
    "montecarlo bad robot": (lambda f: ["montecarlo", f["bad_toml"]], "joint 1: missing d"),
    "montecarlo --devices 2": (
        lambda f: ["montecarlo", "paper-6r", "--devices", "2"],
        "--devices: 2 requested, but 1 cpu device is available",
    ),
    "montecarlo --devices two": (lambda f: ["montecarlo", "paper-6r", "--devices", "two"], "--devices must be"),
    "montecarlo --out file": (lambda f: ["montecarlo", "paper-6r", "--out", f["good"]], "is a file, not a folder"),
    "reproduce --noise-mm -1": (
        lambda f: ["reproduce", "--noise-mm", "-1", "--out", f["good"].parent / "o"],
        "--noise-mm must be >= 0",
    ),
    "reproduce --pairs 0": (lambda f: ["reproduce", "--pairs", "0", "--out", f["good"].parent / "o"], "--pairs"),
    "reproduce --seed -3": (
        lambda f: ["reproduce", "--seed", "-3", "--out", f["good"].parent / "o"],
        "--seed must be an integer >= 0, got -3",
    ),
    "montecarlo elimination of positions": (
        lambda f: ["montecarlo", "paper-6r", "--robots", "2", "--method", "elimination", "--position-only"],
        "needs full-pose measurements, not positions alone (--position-only)",
    ),
    "montecarlo elimination estimating the base": (
        lambda f: ["montecarlo", "paper-6r", "--robots", "2", "--method", "elimination", "--estimate-base"],
        "needs a known base frame, not one estimated (--estimate-base)",
    ),
    "calibrate header-only file": (lambda f: ["calibrate", "paper-6r", f["header"]], "header only, no data rows"),
    "calibrate mixed units": (lambda f: ["calibrate", "paper-6r", f["mixed"]], "mixed length units?"),
    "calibrate joints in degrees": (
        lambda f: ["calibrate", "paper-6r", f["degrees"]],
        "(row 2, joint 'q",  # the file's row (the first is dropped) and column, not an array index
    ),
    "calibrate missing data": (
        lambda f: ["calibrate", "paper-6r", f["good"].parent / "none.csv"],
        "measurement file not found",
    ),
    "calibrate --method bogus": (lambda f: ["calibrate", "paper-6r", f["good"], "--method", "bogus"], "--method"),
    "calibrate --folds 1": (lambda f: ["calibrate", "paper-6r", f["good"], "--folds", "1"], "--folds"),
    "calibrate --length-unit inch": (
        lambda f: ["calibrate", "paper-6r", f["good"], "--length-unit", "inch"],
        "--length-unit must be one of",
    ),
    "compensate header-only targets": (lambda f: ["compensate", "paper-6r", f["header"]], "header only"),
    "compensate bad robot": (lambda f: ["compensate", f["bad_toml"], f["good"]], "joint 1: missing d"),
}


@pytest.mark.parametrize("case", list(CLI))
def test_cli_one_line_exit_2(tmp_path, monkeypatch, capsys, case):
    args, msg = CLI[case]
    code, out, err = run_cli(monkeypatch, capsys, *args(_files(tmp_path)))
    assert code == 2, (code, out, err)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert msg in lines[0], err
    assert "Traceback" not in err + out
    assert not (tmp_path / "o").exists()  # a refused reproduce leaves no folder


def test_calibrate_leaves_out_a_point_with_a_sentinel_before_reading_it(tmp_path, monkeypatch, capsys):
    data = tmp_path / "two.csv"
    data.write_text("\n".join(_sentinel(LINES)) + "\n")
    code, out, err = run_cli(monkeypatch, capsys, "calibrate", "paper-6r", data, "--points", "1", "--folds", "2")
    assert code in (0, None), err
    code, out, err = run_cli(monkeypatch, capsys, "calibrate", "paper-6r", data, "--points", "3")
    assert code == 2 and "row 3" in err


def test_cli_entry_point_subprocess(tmp_path):
    """The installed `jaxcal` script itself: one line on stderr, exit code 2, no traceback."""
    exe = Path(sys.executable).with_name("jaxcal")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-c", "from jaxcal.cli import main; main()"]
    f = _files(tmp_path)
    p = subprocess.run(cmd + ["calibrate", "paper-6r", str(f["header"])], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    assert p.stderr.strip().count("\n") == 0 and "header only, no data rows" in p.stderr
    assert "Traceback" not in p.stderr + p.stdout
