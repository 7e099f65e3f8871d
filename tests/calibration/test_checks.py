"""Checks of the data against the robot file before and beside a fit (:mod:`jaxcal.calibration._checks`)."""

import numpy as np
import pytest
from helpers import dh_fk

import jaxcal
from jaxcal.calibration._checks import check_angles, check_rigid_points, joint_ranges, limit_notes
from jaxcal.calibration._evaluate import beyond


def test_rows_beyond_a_joints_limits_are_named_in_the_files_units():
    """A degree robot file whose joint 2 stops at 40 deg, data rows 6 and 10 at 55 deg: one note,
    naming the joint, both rows and the limits and readings in degrees; a joint whose limits were
    typed in radians in the degree file has most rows beyond them, and the note asks about the
    unit. A reading at a limit, written to six decimals, is the limit; a joint without limits of
    its own (the defaults) is not judged, however far its readings go."""
    ur5 = jaxcal.preset("ur5")
    lim = np.tile([-np.pi, np.pi], (6, 1))
    lim[1] = np.radians([-120.0, 40.0])
    lim[3] = np.radians([-2.0, 2.0])  # "2 deg": radians typed into a degree file
    lim[4] = np.radians([-170.0, 170.0])
    robot = ur5.replace(q_limits=lim, units=("m", "deg"))
    q = np.random.default_rng(1).uniform(-0.6, 0.6, (12, 6))
    q[[4, 8], 1] = np.radians(55.0)
    q[3, 4] = np.radians(round(170.0 + 4e-7, 6))  # 170.000000 in the file
    q[[2, 7], 5] = 4.0  # joint 6 keeps the default limits (+-pi): not judged
    notes = limit_notes(robot, q, rows=np.arange(2, 14))  # the file's rows: a header, then 2..13
    assert len(notes) == 2, notes
    assert notes[0].startswith("joint 2 (q2): row(s) 6, 10 lie beyond its limits in the robot file ([-120, 40] deg")
    assert "readings 55 to 55)" in notes[0] and "another unit" not in notes[0]
    assert notes[1].startswith("joint 4 (q4): row(s)")
    assert "are the limits in another unit than the file's deg?" in notes[1]
    # without the file's rows, the poses' indices
    assert limit_notes(robot, q[:6])[0].startswith("joint 2 (q2): pose(s) 4 lie beyond")
    q[3, 4] = np.radians(170.001)  # a thousandth of a degree beyond: outside
    assert any(n.startswith("joint 5 (q5): row(s) 5 lie beyond") for n in limit_notes(robot, q, rows=np.arange(2, 14)))


def test_a_continuous_joint_read_over_a_whole_turn_has_the_arc_it_visited_as_its_range():
    """Readings of joint 1 (limits a whole turn apart) in [0, 2 pi) that visit 5.5 rad to 0.8 rad
    across 0: its range is that arc, -0.783 to 0.8 rad, not 0.0 to 6.28; a posture at 3.1 rad is
    outside it, one at 6.0 (a turn from -0.283) inside. A joint limited to less than a turn keeps
    its readings' span, however they are spread, and a prismatic joint too."""
    lim = [[0.0, 2 * np.pi], [-3.0, 3.0], [0.0, 300.0]]
    robot = jaxcal.Robot(np.zeros((3, 4)), joint_types="RRP", q_limits=lim)
    rng = np.random.default_rng(0)
    q = np.stack([np.r_[rng.uniform(5.5, 2 * np.pi, 20), rng.uniform(0.0, 0.8, 20)], rng.uniform(-3.0, 3.0, 40),
                  rng.uniform(0.0, 300.0, 40)], 1)  # fmt: skip
    q[0, 0], q[20, 0] = 5.5, 0.8
    lo, hi = joint_ranges(robot, q)
    np.testing.assert_allclose([lo[0], hi[0]], [5.5 - 2 * np.pi, 0.8])
    np.testing.assert_allclose(
        [lo[1], hi[1], lo[2], hi[2]], [q[:, 1].min(), q[:, 1].max(), q[:, 2].min(), q[:, 2].max()]
    )
    ranges = dict(zip(robot.joint_names, zip(lo, hi)))
    probe = np.array([[3.1, 0.0, 100.0], [0.3, 0.0, 100.0], [6.0, 0.0, 100.0]])
    assert (beyond(robot, probe, ranges) > 0).any(-1).tolist() == [True, False, False]


@pytest.mark.parametrize("columns", [[5], [1, 5], list(range(6))])
def test_joint_columns_in_degrees_are_named_where_the_others_are_radians(columns):
    """UR5 readings within +-1.2 rad, the given columns written in degrees: refused, with the
    option for a whole file in degrees; where the other columns span less than half a turn
    (radians), the message names the columns in degrees and says to convert them."""
    ur5 = jaxcal.preset("ur5")
    q = np.random.default_rng(3).uniform(-1.2, 1.2, (20, 6))
    q[:, columns] = np.degrees(q[:, columns])
    with pytest.raises(jaxcal.DataError, match="look like degrees") as e:
        check_angles(ur5, q, rows=np.arange(1, 21))
    msg = str(e.value)
    assert 'angle_unit="deg"' in msg
    named = ", ".join(repr(ur5.joint_names[j]) for j in columns)
    if len(columns) < 6:
        assert f"only joint(s) {named} look so" in msg and "convert them" in msg
    else:
        assert "only joint(s)" not in msg


def test_one_column_in_degrees_beside_joints_moving_most_of_a_turn_is_named_with_both_readings():
    """UR5 readings over +-2.5 rad (more than half a turn), joint 4 written in degrees: the other
    columns never leave a turn, as radians do, so joint 4 is named with the advice to convert it;
    the whole-file option (which would have read the radians as degrees) is given as the other
    reading, not alone."""
    ur5 = jaxcal.preset("ur5")
    q = np.random.default_rng(4).uniform(-2.5, 2.5, (30, 6))
    q[:, 3] = np.degrees(q[:, 3])
    with pytest.raises(jaxcal.DataError, match="look like degrees") as e:
        check_angles(ur5, q, rows=np.arange(1, 31))
    msg = str(e.value)
    assert f"joint(s) {ur5.joint_names[3]!r} are beyond a turn in most poses, the other revolute joints never" in msg
    assert "convert them" in msg and 'angle_unit="deg"' in msg


@pytest.mark.parametrize("held", ["still at 3 deg", "within +-3 deg"])
def test_no_column_hint_where_another_joint_is_held_still(held):
    """A file all in degrees whose joint 6 is held at 3 deg, or moves within +-3 deg: converting
    "only" joints 1-5 would leave joint 6 wrong, so no column is named; the whole-file option is."""
    ur5 = jaxcal.preset("ur5")
    rng = np.random.default_rng(3)
    q = np.degrees(rng.uniform(-2.5, 2.5, (20, 6)))
    q[:, 5] = 3.0 if held == "still at 3 deg" else rng.uniform(-3.0, 3.0, 20)
    with pytest.raises(jaxcal.DataError, match="look like degrees") as e:
        check_angles(ur5, q, rows=np.arange(1, 21))
    assert "only joint(s)" not in str(e.value) and 'angle_unit="deg"' in str(e.value)


def _markers(K, seed, sigma, *, lost=0.0, link4=6, axis_mm=60.0):
    """A UR5 (NumPy FK) carrying four markers on its tool seen from its base frame, ``sigma``
    (mm, per marker) noise, a share ``lost`` of the cells lost; marker 4 on link ``link4`` (5:
    before joint 6, ``axis_mm`` from its axis)."""
    rng = np.random.default_rng(seed)
    dh = np.asarray(jaxcal.preset("ur5").dh)
    q = rng.uniform(-2.5, 2.5, (K, 6))
    tool = np.array([[60.0, 0.0, 40.0], [-50.0, 40.0, 60.0], [0.0, -70.0, 90.0], [30.0, 50.0, 120.0]])
    T = dh_fk(dh, q)
    P = np.einsum("kij,mj->kmi", T[:, :3, :3], tool) + T[:, None, :3, 3]
    if link4 == 5:
        L = dh_fk(dh[:5], q[:, :5])
        P[:, 3] = np.einsum("kij,j->ki", L[:, :3, :3], [axis_mm, 0.0, 150.0]) + L[:, :3, 3]
    P += rng.normal(size=P.shape) * np.asarray(sigma, float).reshape(-1, 1)
    P[rng.random((K, 4)) < lost] = np.nan
    return q, P


def test_points_that_keep_their_distances_are_not_refused():
    """Clean data the check must pass: most cells lost (pairs seen together in too few rows are
    no evidence); three markers re-emitted exactly by a rigid-body fit beside a raw one with
    0.3 mm noise, seen in all rows or in a few; one marker twenty times noisier than the others,
    in 20 rows."""
    q, P = _markers(30, 17, 0.5, lost=0.6)
    check_rigid_points(P, q, np.ones(6, bool))
    q, P = _markers(40, 3, [0.0, 0.0, 0.0, 0.3])
    check_rigid_points(P, q, np.ones(6, bool))
    P[np.random.default_rng(0).random(40) < 0.7, 3] = np.nan  # and seen in too few rows to judge
    check_rigid_points(P, q, np.ones(6, bool))
    q, P = _markers(15, 3, 0.5)  # no pair in enough rows
    check_rigid_points(P, q, np.ones(6, bool))
    for seed in range(10):
        q, P = _markers(20, seed, [0.05, 0.05, 0.05, 1.0])
        check_rigid_points(P, q, np.ones(6, bool))


@pytest.mark.parametrize("K", [20, 40])
def test_a_marker_on_the_wrong_link_near_the_last_axis_is_refused(K):
    """Marker 4 on link 5, 20 mm from joint 6's axis, 0.5 mm noise: its distances to the others
    spread by less than twenty times theirs, but follow joint 6's angle; refused, naming it and
    the points to keep (with few rows, by the last joints' angles)."""
    q, P = _markers(K, 1, 0.5, link4=5, axis_mm=20.0)
    with pytest.raises(jaxcal.DataError, match=r"point 4 does not keep its distances to points 1, 2, 3") as e:
        check_rigid_points(P, q, np.ones(6, bool))
    assert "follow the joint angles by" in str(e.value) and "(--points 1,2,3)" in str(e.value)
