"""Pose files: one header row of joint columns (``q1..qN`` or the robot's joint names, as
measurement files, :mod:`jaxcal.measurements`), one row per configuration, in the robot file's
units unless told otherwise. A design written here is the joint part of the measurement file
``jaxcal calibrate`` reads once positions are added, and what ``jaxcal montecarlo
--poses-file`` calibrates on."""

from __future__ import annotations

import numpy as np

from .._io import write_atomic
from ..calibration import check_angles
from ..errors import DataError
from ..kinematics import check_q
from ..measurements import joint_columns, parse_rows, read_table, require_rows, unit_scale
from ..robot import ANGLE_UNITS, LENGTH_UNITS, Robot

LIMIT_ULPS = 16
"""How far (in units in the last place of the limit, or of 1) a pose file's value may lie beyond
a joint limit and still be read as at it: the rounding of a unit conversion, not an excess."""


def _scales(robot: Robot, length_unit, angle_unit) -> np.ndarray:
    lu, _ = unit_scale(length_unit, LENGTH_UNITS, "length_unit", robot.units[0])
    au, _ = unit_scale(angle_unit, ANGLE_UNITS, "angle_unit", robot.units[1])
    return np.array([lu if t == "P" else au for t in robot.joint_types])


def read_poses(path, robot: Robot, *, length_unit=None, angle_unit=None) -> np.ndarray:
    """``(K, n)`` joint values (rad, mm) of a pose file; other columns are ignored. Units default
    to the robot file's. Values beyond the joint limits the robot file gives are refused (a joint
    given none may turn beyond the range designs are drawn in; angles that look like degrees are
    refused as a calibration's are). Raises :class:`jaxcal.DataError` naming the file, row and
    column."""
    n = robot.n_joints
    src, header, records = read_table(path, f"expected a header row q1..q{n} (or the joint names)", "pose")
    cols = joint_columns(header, robot, src)
    require_rows(records, src)
    values = parse_rows(records, header, cols, src)[0]
    q = values * _scales(robot, length_unit, angle_unit)
    check_q(robot, q)
    check_angles(robot, q, np.arange(1, len(q) + 1))  # degrees, where no limits tell them
    lim = np.asarray(robot.q_limits)
    # a value at a limit in degrees or metres converts to one a few ulps beyond it (designs end
    # on the limits): within LIMIT_ULPS it is the limit; a joint given no limits has none to keep
    tol = LIMIT_ULPS * np.spacing(np.maximum(np.abs(lim), 1.0))
    given = robot.limits_given()
    bad = given & ((q < lim[:, 0] - tol[:, 0]) | (q > lim[:, 1] + tol[:, 1]))
    if bad.any():
        k, j = np.argwhere(bad)[0]
        raise DataError(
            f"{src}: row {k + 1} (line {records[k][0]}), column '{cols[j]}': {values[k, j]:.6g} is outside the "
            f"joint limits [{lim[j, 0] / _scales(robot, length_unit, angle_unit)[j]:.6g}, "
            f"{lim[j, 1] / _scales(robot, length_unit, angle_unit)[j]:.6g}] ({int(bad.any(1).sum())} such row(s))",
            option="q",
        )
    return np.where(given, np.clip(q, lim[:, 0], lim[:, 1]), q)


def write_poses(path, q, robot: Robot, *, length_unit=None, angle_unit=None) -> None:
    """Write joint values ``q (K, n)`` (rad, mm) as a pose file, atomically: columns ``q1..qN``
    (the robot's joint names if it has its own), values in the robot file's units with ``repr``
    precision (they read back bit-identically in mm and rad, and to the last bits of a unit
    conversion in m or degrees). The caller's array is not modified."""
    q = np.array(q, dtype=np.float64, copy=True)
    n = robot.n_joints
    if q.ndim != 2 or q.shape[1] != n or len(q) == 0:
        raise DataError(f"q must have shape (K, {n}) with K >= 1, got {q.shape}", option="q")
    if not np.all(np.isfinite(q)):
        k, j = np.argwhere(~np.isfinite(q))[0]
        raise DataError(f"q: row {k}, joint {j + 1}: value is not finite", option="q")
    values = q / _scales(robot, length_unit, angle_unit)
    text = ",".join(robot.joint_names) + "\n" + "".join(",".join(repr(float(v)) for v in row) + "\n" for row in values)
    write_atomic(path, text)
