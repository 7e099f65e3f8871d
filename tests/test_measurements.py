"""Measurement CSV files: round trip, units, the real Franka data, clear errors, registration."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial.transform import Rotation

from jaxcal import DataError, Robot, fk, preset
from jaxcal.measurements import (
    Measurements,
    franka_csv_path,
    orientation_like,
    read_measurements,
    write_measurements,
)

HEADER7 = "q1,q2,q3,q4,q5,q6,q7,x,y,z"
GOOD_ROW = "0.1,0.2,0.3,-1.5,0.5,1.5,0.7"
QUAT_ROW = ",1,0,0,0"


@pytest.fixture(scope="module")
def panda():
    return preset("panda")


def _random_q(rng, robot, k):
    lim = np.asarray(robot.q_limits)
    return rng.uniform(lim[:, 0], lim[:, 1], size=(k, robot.n_joints))


def _csv(tmp_path, text, name="m.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _spread_rows(k=3, quat=False):
    """k good data rows with positions spread over ~hundreds of mm."""
    return "".join(f"{GOOD_ROW},{100.0 * i},{50.0 * i},{300 + 10.0 * i}{QUAT_ROW if quat else ''}\n" for i in range(k))


# -- round trips ------------------------------------------------------------------------------


@pytest.mark.parametrize("position_only", [False, True])
def test_round_trip(tmp_path, rng, panda, position_only):
    q = _random_q(rng, panda, 20)
    poses = np.asarray(fk(panda, q))
    path = tmp_path / "rt.csv"
    write_measurements(path, q, poses, position_only=position_only)
    m = read_measurements(path, panda)
    assert m.position_only is position_only
    assert_array_equal(m.q, q)  # repr floats: bit-identical
    assert_array_equal(m.poses[:, :3, 3], poses[:, :3, 3])
    assert_array_equal(m.rows, np.arange(1, 21))
    assert m.source == "rt.csv"
    if position_only:
        assert_array_equal(m.poses[:, :3, :3], np.broadcast_to(np.eye(3), (20, 3, 3)))
        assert path.read_text().splitlines()[0] == HEADER7
    else:
        assert_allclose(m.poses, poses, atol=1e-12)
        assert path.read_text().splitlines()[0] == HEADER7 + ",qw,qx,qy,qz"


def test_written_for_a_robot_in_metres_and_degrees_reads_back_for_it(tmp_path, rng):
    """With ``robot``, the file is in its units and joint names, which read_measurements assumes
    for it: a URDF robot (metres) and a TOML one in m and deg with a prismatic joint read back
    what was written, not 1000 times it; without, a metres robot refuses the mm file by its
    prismatic joint (a positions check cannot see it: the points scale with the joint)."""
    from jaxcal import load_robot
    from jaxcal.measurements import tiago_paths

    tiago = load_robot(tiago_paths()[0])
    dh = Robot(np.array([[0.0, 300.0, 200.0, 0.0], [0.3, 0.0, 250.0, 0.5], [0.0, 0.0, 0.0, 0.0]]),
               joint_types="RRP", q_limits=[[-2.0, 2.0], [-2.0, 2.0], [0.0, 300.0]], units=("m", "deg"))  # fmt: skip
    for robot in (tiago, dh):
        assert robot.units[0] == "m" and "P" in robot.joint_types
        q = _random_q(rng, robot, 20)
        points = np.asarray(fk(robot, q))[:, None, :3, 3] + rng.normal(size=(20, 2, 3))
        path = tmp_path / f"{robot.name}.csv"
        write_measurements(path, q, points, robot=robot)
        m = read_measurements(path, robot)
        assert path.read_text().startswith(",".join(robot.joint_names) + ",x1,y1,z1")
        assert_allclose(m.q, q, rtol=1e-14, atol=1e-12)
        assert_allclose(m.measured, points, rtol=1e-14, atol=1e-12)
        write_measurements(path, q, points, joint_names=robot.joint_names)  # mm and rad
        from jaxcal.calibration import check_angles

        q_mm = read_measurements(path, robot).q
        with pytest.raises(DataError, match="^q: prismatic joint .* beyond 100 times its limits") as e:
            check_angles(robot, q_mm)
        assert e.value.option == "length_unit"
        # from a file: named by the first of its rows beyond, in the robot's unit, not as the array q
        j = robot.joint_types.index("P")
        over = np.flatnonzero(np.abs(q_mm[:, j]) > 100 * np.abs(np.asarray(robot.q_limits)[j]).max())[0]
        first = f"first at row {over + 2}: {q_mm[over, j] / 1000:.6g} m"
        with pytest.raises(DataError, match=f"^prismatic joint .*; {first}\\)"):
            check_angles(robot, q_mm, np.arange(2, 22))
        # a batch of data sets (calibrate_batch) with one such set: named the same way
        with pytest.raises(DataError, match=f"prismatic joint {robot.joint_names[-1]!r}|prismatic joint 'torso"):
            check_angles(robot, np.stack([q, q_mm]))


def test_write_does_not_mutate_inputs(tmp_path, rng, panda):
    q = _random_q(rng, panda, 5)
    poses = np.asarray(fk(panda, q)).copy()
    poses[:, :3, :3] = -poses[:, :3, :3] @ np.diag([1.0, 1.0, -1.0])  # still a rotation
    q0, p0 = q.copy(), poses.copy()
    write_measurements(tmp_path / "w.csv", q, poses)
    assert_array_equal(q, q0)
    assert_array_equal(poses, p0)
    assert q.flags.writeable and poses.flags.writeable


def test_write_quaternion_scalar_first_nonnegative(tmp_path):
    R = Rotation.from_rotvec([0.0, 0.0, 3.0]).as_matrix()  # 172 deg about z: qw small, positive
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, [1.0, 2.0, 3.0]
    write_measurements(tmp_path / "one.csv", np.zeros((1, 2)), T[None])
    qw, qx, qy, qz = map(float, (tmp_path / "one.csv").read_text().splitlines()[1].split(",")[-4:])
    assert qw > 0 and qx == 0 and qy == 0
    assert_allclose([qw, qz], [math.cos(1.5), math.sin(1.5)], atol=1e-15)


def test_write_refuses_bad_shapes_and_rotations(tmp_path):
    with pytest.raises(DataError, match=r"q must be \(K, n\).*got q \(3,\), measured \(3, 4, 4\)"):
        write_measurements(tmp_path / "x.csv", np.zeros(3), np.tile(np.eye(4), (3, 1, 1)))
    bad = np.tile(np.eye(4), (2, 1, 1))
    bad[1, 0, 0] = 2.0
    with pytest.raises(DataError, match=r"measured\[1\] rotation is not a proper rotation"):
        write_measurements(tmp_path / "x.csv", np.zeros((2, 3)), bad)
    write_measurements(tmp_path / "x.csv", np.zeros((2, 3)), bad, position_only=True)  # ignored


# -- units ------------------------------------------------------------------------------------


def test_units_m_and_deg(tmp_path, panda):
    deg = [10.0, 20.0, 30.0, -90.0, 45.0, 90.0, 180.0]
    rows = "".join(",".join(map(str, deg)) + f",{0.1 * i},{0.2 * i},{0.5 + 0.1 * i}\n" for i in range(3))
    m = read_measurements(_csv(tmp_path, HEADER7 + "\n" + rows), panda, length_unit="m", angle_unit="deg")
    assert_allclose(m.q[0], np.deg2rad(deg), rtol=1e-15)
    assert_allclose(m.poses[2, :3, 3], [200.0, 400.0, 700.0], rtol=1e-15)


def test_prismatic_joint_takes_length_unit(tmp_path):
    robot = Robot(np.array([[0.0, 0.0, 300.0, 0.0], [0.0, 0.0, 0.0, 0.0]]), joint_types=["R", "P"])
    rows = "".join(f"90,{0.05 * i},{0.1 * i},{0.2 * i},0.3\n" for i in range(3))
    m = read_measurements(_csv(tmp_path, "q1,q2,x,y,z\n" + rows), robot, length_unit="m", angle_unit="deg")
    assert_allclose(m.q[:, 0], math.pi / 2, rtol=1e-15)
    assert_allclose(m.q[:, 1], [0.0, 50.0, 100.0], rtol=1e-15)


def test_bad_unit_name(tmp_path, panda):
    p = _csv(tmp_path, HEADER7 + "\n" + _spread_rows())
    with pytest.raises(DataError, match=r"length_unit must be one of 'mm', 'm', got 'cm'"):
        read_measurements(p, panda, length_unit="cm")
    with pytest.raises(DataError, match=r"angle_unit must be one of 'rad', 'deg', got 'grad'"):
        read_measurements(p, panda, angle_unit="grad")


def test_units_follow_the_robot_file(tmp_path):
    """A robot file in metres and degrees: its data file is read in metres and degrees unless
    told otherwise."""
    from jaxcal import load_robot

    (tmp_path / "r.toml").write_text(
        'length_unit = "m"\nangle_unit = "deg"\n[[joints]]\ntheta = 0.0\nd = 0.1\n'
        "a = 0.3\nalpha = 90.0\n[[joints]]\ntheta = 0.0\nd = 0.0\na = 0.2\nalpha = 0.0\n"
    )
    robot = load_robot(tmp_path / "r.toml")
    assert robot.units == ("m", "deg")
    p = _csv(tmp_path, "q1,q2,x,y,z\n90,45,0.1,0.2,0.3\n")
    m = read_measurements(p, robot)
    assert m.units == ("m", "deg")
    assert_allclose(m.q[0], [math.pi / 2, math.pi / 4], rtol=1e-15)
    assert_allclose(m.measured[0, 0], [100.0, 200.0, 300.0], rtol=1e-15)
    m = read_measurements(p, robot, length_unit="mm", angle_unit="rad")
    assert_allclose(m.q[0], [90.0, 45.0])
    assert_allclose(m.measured[0, 0], [0.1, 0.2, 0.3])


def test_joint_columns_by_name_and_other_columns_listed(tmp_path, panda):
    named = panda.replace(joint_names=[f"joint{j}" for j in range(1, 8)])
    text = (
        "stamp,joint7,joint6,joint5,joint4,joint3,joint2,joint1,x,y,z,note\n1.5,0.7,0.6,0.5,-1,0.3,0.2,0.1,1,2,3,ok\n"
    )
    m = read_measurements(_csv(tmp_path, text), named)
    assert_allclose(m.q[0], [0.1, 0.2, 0.3, -1, 0.5, 0.6, 0.7])
    assert m.ignored == ("stamp", "note")
    # Excel's trailing separators (empty column names, twice): no data, not a duplicated column
    m = read_measurements(
        _csv(tmp_path, text.replace("note\n", "note;;\n").replace("ok\n", "ok;;\n").replace(",", ";")), named
    )
    assert_allclose(m.q[0], [0.1, 0.2, 0.3, -1, 0.5, 0.6, 0.7])
    assert m.ignored == ("stamp", "note")
    # a column without a name that holds data is listed by its position
    m = read_measurements(_csv(tmp_path, text.replace("note\n", "note,\n").replace("ok\n", "ok,42\n")), named)
    assert m.ignored == ("stamp", "note", "column 13 (no name)")
    # orientations in forms jaxcal does not read are named (calibrate then warns: positions alone)
    names = ["stamp", "r11", "R23", "roll", "Yaw", "rx", "rot_w", "A", "B", "C", "W", "P", "R", "note", "A1", "x2"]
    assert orientation_like(names) == ["r11", "R23", "roll", "Yaw", "rx", "rot_w", "A", "B", "C", "W", "P", "R"]
    # a quaternion under names jaxcal does not read (its own are qw, qx, qy, qz, exactly)
    quats = ["QW", "QX", "q_w", "q_z", "ow", "oz", "orientation.w", "pose.orientation.x", "q1", "q12", "z"]
    assert orientation_like(quats) == quats[:-3]


def test_joint_names_that_look_numbered_are_names(tmp_path, panda):
    """A URDF whose joints are named q0..q6, or q2, q1, ...: the columns are the joints' names, in
    the robot's order, not the numbering."""
    for names in ([f"q{j}" for j in range(7)], ["q2", "q1", "q3", "q4", "q5", "q6", "q7"]):
        robot = panda.replace(joint_names=names)
        text = ",".join(reversed(names)) + ",x,y,z\n" + "0.7,0.6,0.5,-1,0.3,0.2,0.1,1,2,3\n"
        m = read_measurements(_csv(tmp_path, text), robot)
        assert_allclose(m.q[0], [0.1, 0.2, 0.3, -1, 0.5, 0.6, 0.7])


def test_several_points_per_pose(tmp_path, panda):
    text = "q1,q2,q3,q4,q5,q6,q7,x1,y1,z1,x2,y2,z2\n" + GOOD_ROW + ",1,2,3,4,5,6\n"
    m = read_measurements(_csv(tmp_path, text), panda)
    assert m.n_points == 2 and m.measured.shape == (1, 2, 3)
    assert_allclose(m.measured[0], [[1, 2, 3], [4, 5, 6]])
    with pytest.raises(DataError, match=r"point 2: missing column\(s\) 'z2'"):
        read_measurements(_csv(tmp_path, text.replace(",z2", ""), "b.csv"), panda)


HEADER_3PT = HEADER7.replace(",x,y,z", "") + "".join(f",x{m},y{m},z{m}" for m in (1, 2, 3))


def _three_points(*cells):
    """Rows of a three-point file: each a 9-tuple of point cells (strings), joints GOOD_ROW."""
    return HEADER_3PT + "\n" + "".join(GOOD_ROW + "," + ",".join(c) + "\n" for c in cells)


def test_lost_points_are_nan_and_a_row_without_any_is_dropped(tmp_path, panda):
    full = [str(100.0 + 10 * j) for j in range(9)]
    rows = [
        full,
        full[:3] + ["", "", ""] + full[6:],  # point 2 occluded
        ["nan", "NaN", "nan"] + full[3:],  # point 1: nan is empty too
        [""] * 9,  # nothing seen: dropped
        full,
    ]
    m = read_measurements(_csv(tmp_path, _three_points(*rows)), panda)
    assert_array_equal(m.rows, [1, 2, 3, 5]) and m.dropped_rows == (4,)
    assert m.lost_points == [(2, 2), (3, 1)]
    assert np.isnan(m.measured[1, 1]).all() and np.isfinite(m.measured[1, [0, 2]]).all()
    assert_allclose(m.measured[0], np.reshape([float(v) for v in full], (3, 3)))
    # selecting points drops the rows none of whose selected points was seen
    one = m.select_points([1])
    assert_array_equal(one.rows, [1, 2, 5]) and one.dropped_rows == (3, 4) and one.lost_points == []
    assert m.select_points([2, 3]).lost_points == [(2, 2)]
    # a point empty in every row is named with its columns; chosen out, the file reads
    unseen = _csv(tmp_path, _three_points(["", "", ""] + full[3:], ["", "", ""] + full[3:]), "b.csv")
    with pytest.raises(DataError, match=r"b\.csv: point\(s\) 1 \(x1, y1, z1\) empty in every row"):
        read_measurements(unseen, panda)
    assert read_measurements(unseen, panda, points=[2, 3]).point_numbers == (2, 3)
    assert read_measurements(unseen, panda, drop_unseen=True).point_numbers == (2, 3)  # for its joints alone
    lost_first = m.subset(np.array([False, False, True, False]))  # row 3: point 1 not seen
    with pytest.raises(DataError, match=r"point\(s\) \[1\] \(points\) were not seen in any row"):
        lost_first.select_points([1])


LOST_BAD = {
    "part of a point": (
        ["1", "", "3"] + ["4"] * 6,
        r"row 1 \(line 2\), column 'y1': empty value, but 'x1', 'z1' of the same point are not",
    ),
    "empty and not a number": (["", "abc", ""] + ["4"] * 6, r"row 1 \(line 2\), column 'y1': not a number: 'abc'"),
    "infinite": (["inf", "", ""] + ["4"] * 6, r"row 1 \(line 2\), column 'x1': value 'inf' is not finite"),
    "nothing at all": ([""] * 9, r"no row has a measured point"),
}


@pytest.mark.parametrize("case", list(LOST_BAD))
def test_lost_points_bad_cells_named(tmp_path, panda, case):
    cells, pattern = LOST_BAD[case]
    with pytest.raises(DataError, match=pattern):
        read_measurements(_csv(tmp_path, _three_points(cells), "e.csv"), panda)


def test_a_pose_file_keeps_refusing_empty_cells(tmp_path, panda):
    text = HEADER7 + ",qw,qx,qy,qz\n" + GOOD_ROW + ",,,,1,0,0,0\n"
    with pytest.raises(DataError, match=r"row 1 \(line 2\), column 'x': empty value"):
        read_measurements(_csv(tmp_path, text, "e.csv"), panda)


def test_a_pose_not_measured_is_dropped_and_a_partial_one_refused(tmp_path, panda):
    """A camera that did not find its target leaves the row's seven cells empty (or nan): the row
    is dropped and named, as a row of points none of which was seen; the others read unchanged.
    Some of the seven empty is a damaged row, refused naming the cell."""
    rows = [GOOD_ROW + ",0.1,0.2,0.3,1,0,0,0", GOOD_ROW + ",,,,,,,", GOOD_ROW + ",0.4,0.5,0.6,0,1,0,0"]
    rows.append(GOOD_ROW + ",nan,NaN,nan,nan,nan,nan,nan")
    rows.append(GOOD_ROW + ",0.7,0.8,0.9,0,0,0,1")
    m = read_measurements(_csv(tmp_path, HEADER7 + ",qw,qx,qy,qz\n" + "\n".join(rows) + "\n"), panda, length_unit="m")
    assert_array_equal(m.rows, [1, 3, 5]) and m.dropped_rows == (2, 4) and m.n_points == 0
    assert_allclose(m.poses[:, :3, 3], [[100, 200, 300], [400, 500, 600], [700, 800, 900]], rtol=1e-15)
    assert_allclose(m.poses[1, :3, :3], np.diag([1.0, -1.0, -1.0]), atol=1e-15)  # qx = 1: half a turn about x
    text = HEADER7 + ",qw,qx,qy,qz\n" + GOOD_ROW + ",1,2,3,,,,\n"
    partial = r"row 1 \(line 2\), column 'qw': empty value, but 'x', 'y', 'z' of the same pose"
    with pytest.raises(DataError, match=partial):
        read_measurements(_csv(tmp_path, text, "p.csv"), panda)


def test_a_file_that_leaves_a_marker_out_keeps_the_others_numbers(tmp_path, panda):
    """Markers 1 and 3 written, marker 2's columns left out (a file cut down to the markers a
    session used): read as points 1 and 3, each chosen by its number (it was refused as "point 2:
    missing column(s)"); a point with only some of its columns is still refused."""
    head = "q1,q2,q3,q4,q5,q6,q7,x1,y1,z1,x3,y3,z3\n"
    rows = [GOOD_ROW + ",1,2,3,30,20,10", GOOD_ROW + ",4,5,6,60,50,40", GOOD_ROW + ",7,8,9,90,80,70"]
    m = read_measurements(_csv(tmp_path, head + "\n".join(rows) + "\n"), panda)
    assert m.numbers == (1, 3) and m.n_points == 2
    assert_array_equal(m.measured[:, 1], [[30, 20, 10], [60, 50, 40], [90, 80, 70]])
    three = m.select_points([3])
    assert three.numbers == (3,)
    assert_array_equal(three.measured[:, 0], m.measured[:, 1])
    with pytest.raises(DataError, match=r"must be distinct point numbers in 1, 3"):
        m.select_points([2])
    chosen = read_measurements(_csv(tmp_path, head + "\n".join(rows) + "\n", "c.csv"), panda, points=[3, 1])
    assert chosen.numbers == (3, 1)
    assert_array_equal(chosen.measured, m.measured[:, ::-1])
    with pytest.raises(DataError, match=r"point 3: missing column\(s\) 'z3'"):
        read_measurements(_csv(tmp_path, head.replace(",z3", "") + GOOD_ROW + ",1,2,3,4,5\n", "d.csv"), panda)


# -- the real Franka data ---------------------------------------------------------------------


def test_franka_file(panda):
    path = franka_csv_path()
    assert path.is_file() and (path.parent / "LICENSE").is_file()
    m = read_measurements(path, panda, length_unit="m")
    assert m.q.shape == (114, 7) and m.poses.shape == (114, 4, 4) and not m.position_only
    assert_allclose(m.poses[0, :3, 3], [-222.0360636, 233.2162467, 269.4955311], rtol=1e-15)
    assert_allclose(m.q[0, 0], 0.194000037, rtol=1e-15)
    R = m.poses[:, :3, :3]
    assert_allclose(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    raw = np.loadtxt(path, delimiter=",", skiprows=1)[:, 10:]
    assert_allclose(np.linalg.norm(raw, axis=1), 1.0, atol=1e-6)  # unit already in the file
    assert_array_equal(m.rows, np.arange(1, 115))


# -- Measurements -----------------------------------------------------------------------------


def test_subset_keeps_rows_and_is_read_only(tmp_path, panda):
    m = read_measurements(_csv(tmp_path, HEADER7 + "\n" + _spread_rows(6)), panda)
    s = m.subset([4, 1])
    assert_array_equal(s.rows, [5, 2])
    assert_array_equal(s.poses, m.poses[[4, 1]])
    assert s.source == m.source and len(s) == 2
    assert_array_equal(m.subset(np.arange(6) % 2 == 0).rows, [1, 3, 5])
    assert_array_equal(m.subset(slice(3, None)).rows, [4, 5, 6])
    assert_array_equal(m.subset(2).rows, [3])
    with pytest.raises(ValueError):
        s.q[0, 0] = 1.0


# -- bad input: one test per case, each checking what the message names ------------------------

BAD = {
    "empty": ("", r"e\.csv: file is empty; expected a header row q1\.\.q7,x,y,z"),
    "blank lines only": ("\n\n", r"e\.csv: file is empty"),
    "header only": (HEADER7 + "\n", r"e\.csv: header only, no data rows"),
    "missing x": ("q1,q2,q3,q4,q5,q6,q7,y,z\n", r"e\.csv: missing column\(s\) 'x'; expected x, y, z"),
    "missing q3": ("q1,q2,q4,q5,q6,q7,x,y,z\n", r"e\.csv: missing column\(s\) 'q3'"),
    "duplicated column": ("q1,q2,q3,q4,q5,q6,q7,x,y,z,y\n", r"duplicated column name 'y' \(columns 9 and 11\)"),
    "6 joints": ("q1,q2,q3,q4,q5,q6,x,y,z\n", r"e\.csv: robot has 7 joints, file has q1\.\.q6"),
    "8 joints": (HEADER7.replace("q7", "q7,q8") + "\n", r"robot has 7 joints, file has q1\.\.q8"),
    "numbered from 0": (
        "q0,q1,q2,q3,q4,q5,q6,x,y,z\n",
        r"joint columns q0\.\.q6: jaxcal numbers joints from 1; name them q1\.\.q7",
    ),
    "q9 gap": (HEADER7 + ",q9\n", r"column\(s\) 'q9' but the robot has 7 joints \(q1\.\.q7\)"),
    "partial quaternion": (
        HEADER7 + ",qw,qx\n",
        r"only some quaternion columns present \(qw, qx; missing qy, qz\); give all",
    ),
    "non-numeric": (
        HEADER7 + "\n" + GOOD_ROW + ",1,2,3\n" + GOOD_ROW + ",1,abc,3\n",
        r"e\.csv: row 2 \(line 3\), column 'y': not a number: 'abc'",
    ),
    "empty field": (HEADER7 + "\n" + GOOD_ROW + ",1,2,\n", r"row 1 \(line 2\), column 'z': empty value"),
    "nan": (
        HEADER7 + "\n" + GOOD_ROW.replace("0.3", "nan") + ",1,2,3\n",
        r"row 1 \(line 2\), column 'q3': value 'nan' is not finite",
    ),
    "inf": (
        HEADER7 + "\n\n" + GOOD_ROW + ",1,2,3\n" + GOOD_ROW + ",1,-inf,3\n",
        r"row 2 \(line 4\), column 'y': value '-inf' is not finite",
    ),
    "too few fields": (
        HEADER7 + "\n" + GOOD_ROW + ",1,2,3\n" + GOOD_ROW + ",1,2\n",
        r"row 2 \(line 3\): 9 fields, but the header has 10 columns",
    ),
    "too many fields": (HEADER7 + "\n" + GOOD_ROW + ",1,2,3,4\n", r"row 1 \(line 2\): 11 fields"),
    "header not matched": (
        "Q1,Q2,Q3,Q4,Q5,Q6,Q7,X,Y,Z\n" + GOOD_ROW + ",1,2,3\n",
        r"no joint columns; expected q1\.\.q7 .*; the header was read as 'Q1', 'Q2', .*names are matched exactly",
    ),
    "a row commented out": (
        HEADER7 + "\n" + GOOD_ROW + ",1,2,3\n# " + GOOD_ROW + ",1,2,3\n",
        r"e\.csv: row 2 \(line 3\) starts with '#': comment lines go before the header; delete the row, or its '#'",
    ),
    "a comment below the header": (
        HEADER7 + "\n" + GOOD_ROW + ',1,2,3\n# note,"bad batch\n' + GOOD_ROW + ",1,2,3\n",
        r"row 2 \(line 3\) starts with '#'",
    ),
    "a row commented out beside an id column": (
        "id," + HEADER7 + "\nP1," + GOOD_ROW + ",1,2,3\n# P2," + GOOD_ROW + ",1,2,3\nP3," + GOOD_ROW + ",1,2,3\n",
        r"row 2 \(line 3\) starts with '#'.*\(1 such row\(s\)\)",
    ),
    "decimal comma": (
        HEADER7.replace(",", ";") + "\n" + GOOD_ROW.replace(",", ";").replace(".", ",") + ";1;2;3\n",
        r"row 1 \(line 2\), column 'q1': not a number: '0,1' \(a decimal comma\? write decimals with a point\)",
    ),
    "non-unit quaternion": (
        HEADER7 + ",qw,qx,qy,qz\n" + GOOD_ROW + ",1,2,3,1,0,0,0\n" + GOOD_ROW + ",1,2,3,0.5,0.5,0.5,0.4\n",
        r"row 2 \(line 3\): quaternion \(qw, qx, qy, qz\) has norm 0\.953939, not 1 "
        r"\(tolerance 0\.001\); 1 such row",
    ),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input(tmp_path, panda, case):
    text, pattern = BAD[case]
    with pytest.raises(DataError, match=pattern):
        read_measurements(_csv(tmp_path, text, "e.csv"), panda)


def test_missing_file(tmp_path, panda):
    with pytest.raises(DataError, match=r"measurement file not found: .*nope\.csv"):
        read_measurements(tmp_path / "nope.csv", panda)


@pytest.mark.parametrize("encoding", ["utf-16", "cp1252"])
def test_a_file_saved_as_unicode_text_or_windows_text_reads_as_utf8(tmp_path, panda, encoding):
    """Excel's "Unicode text" (UTF-16 with its byte-order mark) and its Windows "CSV"
    (Windows-1252, here a degree sign in a column the calibration ignores) read as the UTF-8 file."""
    text = HEADER7 + ",angle \u00b0\n" + "".join(r + ",0\n" for r in _spread_rows(4).splitlines())
    want = read_measurements(_csv(tmp_path, text, "plain.csv"), panda)
    p = tmp_path / "other.csv"
    p.write_bytes(text.encode(encoding))
    got = read_measurements(p, panda)
    assert_array_equal(got.q, want.q)
    assert_array_equal(got.measured, want.measured)


def test_a_byte_neither_encoding_reads_is_named_by_its_line(tmp_path, panda):
    """0xe9 reads in Windows-1252 (an e acute), 0x81 in neither: the error names 0x81's line."""
    p = tmp_path / "bytes.csv"
    p.write_bytes((HEADER7 + ",note\n" + GOOD_ROW + ",1,2,3,caf\xe9\n").encode("cp1252") + b"x\x81\n")
    with pytest.raises(DataError, match=r"bytes\.csv: line 3: byte 0x81 is neither UTF-8 nor Windows-1252"):
        read_measurements(p, panda)


def test_not_text(tmp_path, panda):
    p = tmp_path / "bin.csv"
    p.write_bytes(b"\xff\xfe\x00\x81garbage")
    with pytest.raises(DataError, match=r"bin\.csv: cannot read as a CSV text file"):
        read_measurements(p, panda)


def test_near_unit_quaternion_normalised_and_columns_any_order(tmp_path, panda):
    text = (
        "qx,qy,qz,qw,z,y,x,q7,q6,q5,q4,q3,q2,q1\n"
        "0,0,0.0005,1.0004,300,0,0,0.7,0.6,0.5,-1,0.3,0.2,0.1\n"  # norm 1.0004: within tolerance
        "0,0,0,1,300,0,100,0.7,0.6,0.5,-1,0.3,0.2,0.1\n"
        "0,0,0,1,300,100,0,0.7,0.6,0.5,-1,0.3,0.2,0.1\n"
    )
    m = read_measurements(_csv(tmp_path, "\ufeff" + text), panda)  # a UTF-8 BOM is accepted
    assert_allclose(m.q[0], [0.1, 0.2, 0.3, -1, 0.5, 0.6, 0.7])
    assert_allclose(m.poses[0, :3, 3], [0, 0, 300])
    R = m.poses[0, :3, :3]
    assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
    assert_allclose(Rotation.from_matrix(R).as_rotvec(), [0, 0, 2 * math.atan2(0.0005, 1.0004)], atol=1e-15)


def test_measurements_shape_check():
    with pytest.raises(DataError, match="inconsistent shapes"):
        Measurements(q=np.zeros((3, 2)), measured=np.zeros((2, 4, 4)), source="s", rows=np.arange(3))


@pytest.mark.parametrize("numbers", [(2, 2, 5), (7, 8), (0, 1, 2), (1.5, 2, 3)])
def test_point_numbers_name_each_point_once(numbers):
    """The points' numbers in the file name their parameters: a repeated number would merge two
    points' parameters in the report, a missing one fail deep in the fit."""
    with pytest.raises(DataError, match="point_numbers .* each of the 3 measured points"):
        Measurements(q=np.zeros((4, 6)), measured=np.zeros((4, 3, 3)), point_numbers=numbers)


def test_a_non_finite_coordinate_is_named_by_its_points_file_number():
    """Points chosen as 3, 1: an infinite coordinate of the first is the file's point 3."""
    from jaxcal import calibrate_data

    p = np.ones((6, 2, 3))
    p[4, 0, 1] = np.inf
    with pytest.raises(DataError, match="row 5, point 3, y"):
        calibrate_data(preset("ur5"), Measurements(q=np.zeros((6, 6)), measured=p, point_numbers=(3, 1)))


@pytest.mark.parametrize(
    "dialect",
    [
        "semicolons",
        "tabs",
        "excel sep line",
        "comment lines first",
        "crlf",
        "sep line then comments",
        "lines of empty fields",
        "trailing separators on rows",
        "trailing separators on the header",
        "semicolons and a comma in a name",
        "an id column of #1, #2, ...",
        "a tab named by a sep line",
    ],
)
def test_spreadsheet_exports_read_as_the_plain_file(tmp_path, panda, dialect):
    """The same table as a European spreadsheet (semicolons), a tab-separated export, a file whose
    first line is Excel's ``sep=;`` (before or after comments), one with ``#`` comment lines first,
    Windows line ends, lines of empty cells, or trailing separators on the rows
    or on the header alone: the same measurements, and line numbers that still point into the file."""
    plain = HEADER7 + "\n" + _spread_rows(4)
    lines = plain.splitlines()
    text = {
        "semicolons": plain.replace(",", ";"),
        "tabs": plain.replace(",", "\t"),
        "excel sep line": "sep=;\n" + plain.replace(",", ";"),
        "comment lines first": "# exported by a tracker\n# units: mm, rad\n" + plain,
        "crlf": plain.replace("\n", "\r\n"),
        "sep line then comments": "sep=;\n# exported by a tracker\n" + plain.replace(",", ";"),
        "lines of empty fields": "\n".join(lines[:2] + [",,,,,,,,,", ",,"] + lines[2:]) + "\n",
        "trailing separators on rows": "\n".join(lines[:1] + [r + ",," for r in lines[1:]]) + "\n",
        "trailing separators on the header": "\n".join([lines[0] + ",,,"] + lines[1:]) + "\n",
        "a tab named by a sep line": "sep=\t\n" + plain.replace(",", "\t"),
        "an id column of #1, #2, ...": "\n".join(["id," + lines[0]] + [f"#{i},{r}" for i, r in enumerate(lines[1:])])
        + "\n",
        "semicolons and a comma in a name": "\n".join(
            [lines[0].replace(",", ";") + ";note, operator"] + [r.replace(",", ";") + ";ok" for r in lines[1:]]
        )
        + "\n",
    }[dialect]
    want = read_measurements(_csv(tmp_path, plain, "plain.csv"), panda)
    got = read_measurements(_csv(tmp_path, text), panda)
    assert_array_equal(got.q, want.q)
    assert_array_equal(got.measured, want.measured)
    bad = text.splitlines()
    bad[-1] = bad[-1].replace("330.0", "abc")
    skipped = len(text.splitlines()) - len(plain.splitlines())
    with pytest.raises(DataError, match=rf"row 4 \(line {5 + skipped}\), column 'z': not a number: 'abc'"):
        read_measurements(_csv(tmp_path, "\n".join(bad) + "\n", "bad.csv"), panda)


def test_a_joint_named_like_a_position_column(tmp_path):
    """A lift named ``z``: numbered joint columns read it (its name is the position's), and a
    header that names it twice says why and what to write instead."""
    dh = np.array([[0.0, 400.0, 350.0, 0.0], [0.0, 0.0, 300.0, math.pi], [0.0, 50.0, 0.0, 0.0]])
    r = Robot(dh, joint_types="RRP", joint_names=("j1", "j2", "z"), q_limits=[[-2, 2], [-2, 2], [0, 200]])
    q = np.random.default_rng(0).uniform([-2, -2, 20], [2, 2, 180], (6, 3))
    p = np.asarray(fk(r, q))[:, :3, 3]
    rows = "".join(",".join(repr(float(v)) for v in np.r_[a, b]) + "\n" for a, b in zip(q, p))
    (tmp_path / "num.csv").write_text("q1,q2,q3,x,y,z\n" + rows)
    assert_allclose(np.asarray(read_measurements(tmp_path / "num.csv", r).q), q, rtol=0, atol=1e-12)
    (tmp_path / "named.csv").write_text("j1,j2,z,x,y,z\n" + rows)
    with pytest.raises(
        DataError, match="duplicated column name 'z'.*if a joint is named like a measurement column.*q1..qN"
    ):
        read_measurements(tmp_path / "named.csv", r)


def test_a_number_with_underscores_is_not_a_number(tmp_path):
    """Python's float reads 1_000 as 1000; a data file's 1_000 is a typo or a foreign format and
    is refused naming its row and column."""
    robot = Robot(np.zeros((2, 4)))
    with pytest.raises(DataError, match=r"row 2 \(line 3\), column 'y': not a number: '1_000'"):
        read_measurements(_csv(tmp_path, "q1,q2,x,y,z\n0.1,0.2,1,2,3\n0.2,0.3,1,1_000,3\n"), robot)


def test_a_joint_turning_several_times_is_read_and_a_degree_row_still_named(tmp_path):
    """A URDF continuous joint (no limits of its own) may read 3..8 rad: those rows beyond a
    turn are not another unit. A row in degrees among radians is still refused by row."""
    from jaxcal import load_robot
    from jaxcal.measurements import read_measurements

    urdf = tmp_path / "r.urdf"
    urdf.write_text(
        '<robot name="r"><link name="a"/><link name="b"/><link name="c"/>'
        '<joint name="spin" type="continuous"><parent link="a"/><child link="b"/>'
        '<origin xyz="0 0 0.1"/><axis xyz="0 0 1"/></joint>'
        '<joint name="tilt" type="revolute"><parent link="b"/><child link="c"/><origin xyz="0.2 0 0"/>'
        '<axis xyz="1 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>'
    )
    robot = load_robot(urdf)
    spin = np.linspace(3.0, 8.0, 12)
    tilt = np.linspace(-0.5, 0.5, 12)
    # the tip c: 0.2 m along x turned by spin about z, 0.1 m up (tilt about x moves nothing on x)
    xyz = np.c_[0.2 * np.cos(spin), 0.2 * np.sin(spin), np.full(12, 0.1)]

    def csv(q1):
        path = tmp_path / "d.csv"
        path.write_text(
            "spin,tilt,x,y,z\n"
            + "".join(f"{a:.17g},{b:.17g},{x:.17g},{y:.17g},{z:.17g}\n" for a, b, (x, y, z) in zip(q1, tilt, xyz))
        )
        return path

    m = read_measurements(csv(spin), robot)
    assert_allclose(np.asarray(m.q)[:, 0], spin)
    degrees = spin.copy()
    degrees[4] = np.degrees(spin[4])  # row 5 written in degrees
    with pytest.raises(DataError, match=r"mixed angle units\? row 5, column 'spin'"):
        read_measurements(csv(degrees), robot)
