"""Checks of the data against the robot file before and beside a fit (:mod:`jaxcal.calibration._checks`)."""

import numpy as np

import jaxcal
from jaxcal.calibration._checks import limit_notes


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
