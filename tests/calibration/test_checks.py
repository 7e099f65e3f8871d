"""Checks of the data against the robot file before and beside a fit (:mod:`jaxcal.calibration._checks`)."""

import numpy as np

import jaxcal
from jaxcal.calibration._checks import limit_notes


def test_rows_beyond_a_joints_limits_are_named_in_the_files_units():
    """A degree robot file whose joint 2 stops at 40 deg, data rows 5 and 9 at 55 deg: one note,
    naming the joint, both rows and the limits and readings in degrees; a joint whose limits were
    typed in radians in the degree file has most rows beyond them, and the note asks about the
    unit. Joints without limits of their own are not judged."""
    ur5 = jaxcal.preset("ur5")
    lim = np.tile([-np.pi, np.pi], (6, 1))
    lim[1] = np.radians([-120.0, 40.0])
    lim[3] = np.radians([-2.0, 2.0])  # "2 deg": radians typed into a degree file
    robot = ur5.replace(q_limits=lim, units=("m", "deg"))
    q = np.random.default_rng(1).uniform(-0.6, 0.6, (12, 6))
    q[[4, 8], 1] = np.radians(55.0)
    notes = limit_notes(robot, q, rows=np.arange(2, 14))  # the file's rows: a header, then 2..13
    assert len(notes) == 2, notes
    assert notes[0].startswith("joint 2 (q2): row(s) 6, 10 lie beyond its limits in the robot file ([-120, 40] deg")
    assert "readings 55 to 55)" in notes[0] and "another unit" not in notes[0]
    assert notes[1].startswith("joint 4 (q4): row(s)")
    assert "are the limits in another unit than the file's deg?" in notes[1]
    assert limit_notes(ur5, q) == ()  # the preset's own limits hold every row
