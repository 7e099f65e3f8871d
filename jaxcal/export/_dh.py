"""The calibrated kinematic table beside the nominal one: per parameter the nominal and calibrated
values, their difference and its standard error, in the robot file's units (``--out-dh``)."""

from __future__ import annotations

import csv
import io

import numpy as np

from .._io import write_atomic
from ..errors import RobotFileError
from ..robot import ANGLE_UNITS, LENGTH_UNITS

COLUMNS = ("parameter", "joint", "unit", "nominal", "calibrated", "delta", "std_error", "status", "convention")


def dh_rows(result) -> list[dict]:
    """One row per kinematic parameter of a :class:`jaxcal.DataCalibration` (DH, or a URDF
    robot's joint-frame corrections, whose nominal values are 0), keyed by :data:`COLUMNS`;
    ``std_error`` is ``None`` and ``status`` says why for a parameter held at its nominal value;
    then the joint compliances the model estimated (angle unit per length unit) and the moment
    arms their offsets hold at (:attr:`jaxcal.Robot.moment_ref`, length unit); ``convention``
    the table's (``sdh``, ``mdh``: Craig's, whose ``alpha_i``, ``a_i`` precede joint i)."""
    nominal, rep = result.nominal, result.report
    lu, au = nominal.units
    per_joint = nominal.n_kinds
    nom = np.asarray(nominal.dh).ravel()
    cal = np.asarray(result.model.robot.dh).ravel()
    held = rep.get("not_estimated", {})
    rows = []
    for i, (name, unit) in enumerate(zip(nominal.param_names(), nominal.param_units())):
        file_unit, scale = (lu, LENGTH_UNITS[lu]) if unit == "mm" else (au, ANGLE_UNITS[au])
        if name in result.deltas and name not in held:
            status, se = "estimated", result.deltas[name][1] / scale
        elif name in result.deltas:  # an offset its compliance moved to the mean load: its reason says so
            status, se = f"not estimated: {held[name]}", result.deltas[name][1] / scale
        else:
            status = f"not estimated: {held[name]}" if name in held else f"not in the chosen set ({rep['choice']})"
            se = None
        rows.append(
            {
                "parameter": name,
                "joint": i // per_joint + 1,
                "unit": file_unit,
                "nominal": float(nom[i] / scale),
                "calibrated": float(cal[i] / scale),
                "delta": float((cal[i] - nom[i]) / scale),
                "std_error": se,
                "status": status,
                "convention": nominal.convention,
            }
        )
    comp = result.model.robot.compliance
    comp0 = np.zeros(nominal.n_joints) if nominal.compliance is None else np.asarray(nominal.compliance)
    for j in range(nominal.n_joints) if comp is not None else ():  # joint compliances, when the model has them
        name, scale = f"compliance{j + 1}", ANGLE_UNITS[au] / LENGTH_UNITS[lu]
        if name not in result.deltas:
            continue
        rows.append(
            {
                "parameter": name,
                "joint": j + 1,
                "unit": f"{au}/{lu}",
                "nominal": float(comp0[j] / scale),
                "calibrated": float(np.asarray(comp)[j] / scale),
                "delta": float((np.asarray(comp)[j] - comp0[j]) / scale),
                "std_error": result.deltas[name][1] / scale,
                "status": "estimated",
                "convention": nominal.convention,
            }
        )
    ref = result.model.robot.moment_ref
    if comp is not None and ref is not None:  # where the offsets hold: not estimated, the data's mean
        ref0 = np.zeros(nominal.n_joints) if nominal.moment_ref is None else np.asarray(nominal.moment_ref)
        for j in range(nominal.n_joints):
            if f"compliance{j + 1}" not in result.deltas:
                continue
            rows.append(
                {
                    "parameter": f"reference_moment{j + 1}",
                    "joint": j + 1,
                    "unit": lu,
                    "nominal": float(ref0[j] / LENGTH_UNITS[lu]),
                    "calibrated": float(np.asarray(ref)[j] / LENGTH_UNITS[lu]),
                    "delta": float((np.asarray(ref)[j] - ref0[j]) / LENGTH_UNITS[lu]),
                    "std_error": None,
                    "status": "the mean gravity moment arm over the data, at which the joint's offset holds",
                    "convention": nominal.convention,
                }
            )
    return rows


def dh_table(result) -> str:
    """:func:`dh_rows` as CSV text (full float precision; an empty ``std_error`` for a held
    parameter)."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(COLUMNS)
    for r in dh_rows(result):
        w.writerow(["" if r[c] is None else repr(r[c]) if isinstance(r[c], float) else r[c] for c in COLUMNS])
    return out.getvalue()


def check_dh(robot, option: str | None = None) -> None:
    """Raise :class:`jaxcal.RobotFileError` unless ``robot`` has a DH table."""
    if robot.convention == "joint":
        raise RobotFileError(
            f"{option or 'a DH table'}: {robot.name!r} is described by joint frames (a URDF), not a DH table; "
            "its corrections are in the JSON report's parameters",
            option=option,
        )


def save_dh_table(result, path) -> None:
    """Write :func:`dh_table` of a DH robot's calibration atomically."""
    if not all(hasattr(result, k) for k in ("nominal", "report", "deltas")):
        raise RobotFileError(
            f"{path}: save_dh_table takes the result of jaxcal.calibrate_data (the nominal table, the estimates "
            f"and their standard errors), not a {type(result).__name__}"
        )
    check_dh(result.nominal)
    write_atomic(path, dh_table(result))
