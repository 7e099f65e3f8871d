"""Robot files (TOML) -> :class:`jaxcal.Robot` and back, with unit conversion at the edge.

File shape (see README)::

    name = "paper-6r"
    convention = "sdh"          # "sdh" or "mdh"
    length_unit = "mm"          # "mm" or "m"
    angle_unit = "rad"          # "rad" or "deg"
    load = [0.0, 0.0, 0.0]      # optional: where the compliances' weight sits in the tool frame
                                # (length unit; jaxcal.Robot.load; default the tool origin)
    [[joints]]                  # one table per joint, base to tip
    theta = 0.0                 # joint offset added to q
    d = 0.0
    a = 160.0
    alpha = -1.5707963267948966
    type = "R"                  # optional: "R" (default) or "P"
    limits = [-3.14, 3.14]      # optional: joint limits (angle unit, or length unit if "P")
    compliance = 0.0            # optional: turn per length of gravity moment arm (angle unit
                                # per length unit; jaxcal.Robot.compliance)
    reference_moment = 0.0      # optional: the moment arm (length unit) at which theta holds
                                # (jaxcal.Robot.moment_ref; default 0)
    [tool]                      # optional, flange -> tool point/frame
    xyz = [0.0, 0.0, 0.0]
    rpy = [0.0, 0.0, 0.0]       # roll-pitch-yaw, fixed axes x-y-z
    [base]                      # optional, measurement frame -> robot base; same keys
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import tomli_w

from .._io import write_atomic
from ..errors import RobotFileError
from ..lie import matrix_to_rpy, rpy_to_matrix
from ._robot import ANGLE_UNITS as ANGLE
from ._robot import DEFAULT_LIMITS, Robot
from ._robot import LENGTH_UNITS as LENGTH

TOP_KEYS = {
    "name", "convention", "length_unit", "angle_unit", "joints", "tool", "base", "calibration", "points", "load",
    "point_numbers",
}  # fmt: skip
JOINT_KEYS = {"name", "theta", "d", "a", "alpha", "type", "limits", "compliance", "reference_moment"}
FRAME_KEYS = {"xyz", "rpy"}


def _num(v, where):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise RobotFileError(f"{where}: expected a number, got {v!r}")
    if not math.isfinite(v):
        raise RobotFileError(f"{where}: not finite ({v!r})")
    return float(v)


def _frame(tab, what, lu, au):
    if not isinstance(tab, dict):
        raise RobotFileError(f"[{what}] must be a table with keys xyz and rpy")
    unknown = set(tab) - FRAME_KEYS
    if unknown:
        raise RobotFileError(f"[{what}]: unknown key(s) {sorted(unknown)}; allowed: xyz, rpy")
    out = []
    for key, scale in (("xyz", lu), ("rpy", au)):
        v = tab.get(key, [0.0, 0.0, 0.0])
        if not isinstance(v, list) or len(v) != 3:
            raise RobotFileError(f"[{what}].{key} must be a list of 3 numbers, got {v!r}")
        out.append(np.array([_num(x, f"[{what}].{key}[{i}]") * scale for i, x in enumerate(v)]))
    T = np.eye(4)
    T[:3, :3] = np.asarray(rpy_to_matrix(out[1]))
    T[:3, 3] = out[0]
    return T


def robot_from_dict(doc: dict, *, source: str = "robot file") -> Robot:
    """Build a robot from a parsed TOML document (units converted to mm and rad)."""
    unknown = set(doc) - TOP_KEYS
    if unknown:
        raise RobotFileError(f"{source}: unknown top-level key(s) {sorted(unknown)}; allowed: {sorted(TOP_KEYS)}")
    conv = doc.get("convention", "sdh")
    if conv not in ("sdh", "mdh"):
        raise RobotFileError(f"{source}: convention must be 'sdh' or 'mdh', got {conv!r}")
    lu_name, au_name = doc.get("length_unit", "mm"), doc.get("angle_unit", "rad")
    if lu_name not in LENGTH:
        raise RobotFileError(f"{source}: length_unit must be 'mm' or 'm', got {lu_name!r}")
    if au_name not in ANGLE:
        raise RobotFileError(f"{source}: angle_unit must be 'rad' or 'deg', got {au_name!r}")
    lu, au = LENGTH[lu_name], ANGLE[au_name]
    joints = doc.get("joints")
    if not isinstance(joints, list) or not joints:
        raise RobotFileError(f"{source}: needs at least one [[joints]] table")
    dh, types, limits, names, compliance, given, ref = [], [], [], [], [], [], []
    for i, j in enumerate(joints, start=1):
        if not isinstance(j, dict):
            raise RobotFileError(f"{source}: joint {i} is not a table")
        bad = set(j) - JOINT_KEYS
        if bad:
            raise RobotFileError(f"{source}: joint {i}: unknown key(s) {sorted(bad)}; allowed: {sorted(JOINT_KEYS)}")
        missing = [k for k in ("theta", "d", "a", "alpha") if k not in j]
        if missing:
            raise RobotFileError(f"{source}: joint {i}: missing {', '.join(missing)}")
        jname = j.get("name", f"q{i}")
        if not isinstance(jname, str) or not jname:
            raise RobotFileError(f"{source}: joint {i}: name must be a non-empty string, got {jname!r}")
        names.append(jname)
        jt = j.get("type", "R")
        if jt not in ("R", "P"):
            raise RobotFileError(f"{source}: joint {i}: type must be 'R' or 'P', got {jt!r}")
        dh.append(
            [
                _num(j["theta"], f"joint {i} theta") * au,
                _num(j["d"], f"joint {i} d") * lu,
                _num(j["a"], f"joint {i} a") * lu,
                _num(j["alpha"], f"joint {i} alpha") * au,
            ]
        )
        turn = 2 * np.pi * 1.01  # a twist or an offset beyond a whole turn is an angle in another unit
        for key, v in (("theta", dh[-1][0]), ("alpha", dh[-1][3])):
            if au_name == "rad" and abs(v) > turn:
                raise RobotFileError(
                    f"{source}: joint {i} ({jname}) {key} = {v:g} rad, beyond a whole turn: are the file's "
                    f'angles degrees? Then write angle_unit = "deg"'
                )
        types.append(jt)
        compliance.append(_num(j["compliance"], f"joint {i} compliance") * au / lu if "compliance" in j else None)
        ref.append(_num(j["reference_moment"], f"joint {i} reference_moment") * lu if "reference_moment" in j else None)
        lim = j.get("limits", None)
        scale = au if jt == "R" else lu
        given.append(lim is not None)
        if lim is None:
            limits.append(DEFAULT_LIMITS[jt])
        else:
            if not isinstance(lim, list) or len(lim) != 2:
                raise RobotFileError(f"{source}: joint {i}: limits must be [lower, upper]")
            limits.append([_num(x, f"joint {i} limits") * scale for x in lim])
    base = _frame(doc["base"], "base", lu, au) if "base" in doc else None
    tool = _frame(doc["tool"], "tool", lu, au) if "tool" in doc else None
    load = doc.get("load")
    if load is not None:
        if not isinstance(load, list) or len(load) != 3:
            raise RobotFileError(f"{source}: load must be [x, y, z] (the compliances' weight in the tool frame)")
        load = [_num(v, f"load[{i}]") * lu for i, v in enumerate(load)]
    name = doc.get("name", "robot")
    if not isinstance(name, str):
        raise RobotFileError(f"{source}: name must be a string")
    return Robot(
        np.array(dh),
        convention=conv,
        joint_types=types,
        base=base,
        tool=tool,
        q_limits=np.array(limits),
        limits_set=given,
        name=name,
        joint_names=names,
        units=(lu_name, au_name),
        compliance=None if all(c is None for c in compliance) else [c or 0.0 for c in compliance],
        moment_ref=None if all(m is None for m in ref) else [m or 0.0 for m in ref],
        load=load,
    )


def read_toml(path) -> tuple[Robot, np.ndarray | None]:
    """``(robot, points)`` of a robot TOML file (see the module docstring for its shape): the
    measured points (mm, tool frame) a calibration wrote as ``points = [[x, y, z], ...]`` in the
    file's length unit, or ``None``."""
    path = Path(path)
    try:
        with path.open("rb") as f:
            doc = tomllib.load(f)
    except FileNotFoundError:
        raise RobotFileError(f"robot file not found: {path}") from None
    except tomllib.TOMLDecodeError as e:
        if path.read_text(errors="replace").lstrip().startswith("{"):  # a JSON file, as calibrate --json writes
            raise RobotFileError(
                f"{path}: a JSON file, not a robot file (TOML, URDF or UR yaml): a calibrate --json report holds the "
                "figures, not a model to load; give the file written by --out-robot or --out-model"
            ) from None
        if path.suffix.lower() == ".csv":  # a data file, or the DH table calibrate --out-dh writes
            raise RobotFileError(
                f"{path}: a CSV file, not a robot file (TOML, URDF or UR yaml): a calibrate --out-dh table lists the "
                "DH parameters to read, without the base and tool frames, joint types and limits a model holds; "
                "give the file written by --out-robot or --out-model"
            ) from None
        raise RobotFileError(f"{path}: not valid TOML: {e}") from None
    robot = robot_from_dict(doc, source=str(path))
    pts = doc.get("points", [])
    if not isinstance(pts, list) or not all(isinstance(p, list) and len(p) == 3 for p in pts):
        raise RobotFileError(f"{path}: points must be a list of [x, y, z]")
    _numbers(doc, len(pts), path)
    if "points" not in doc:
        return robot, None
    lu = LENGTH[robot.units[0]]
    return robot, np.array([[_num(v, f"points[{i}]") * lu for v in p] for i, p in enumerate(pts)])


def _numbers(doc: dict, n_points: int, path) -> tuple[int, ...] | None:
    """``point_numbers``, checked: the data file's number of each of the ``points``."""
    if "point_numbers" not in doc:
        return None
    v = doc["point_numbers"]
    if (
        not isinstance(v, list)
        or not n_points
        or len(v) != n_points
        or not all(isinstance(j, int) and not isinstance(j, bool) and j >= 1 for j in v)
        or len(set(v)) != len(v)
    ):
        raise RobotFileError(
            f"{path}: point_numbers must list the data file's number (1, 2, ...) of each of the {n_points} "
            f"points, each once; got {v!r}"
        )
    return tuple(v)


def point_numbers_toml(path) -> tuple[int, ...] | None:
    """The data file's number of each measured point a calibrated robot file holds
    (``point_numbers``), or ``None``."""
    with Path(path).open("rb") as f:
        doc = tomllib.load(f)
    pts = doc.get("points", [])
    return _numbers(doc, len(pts) if isinstance(pts, list) else 0, path)


def robot_to_dict(robot: Robot, *, comment: dict | None = None, points=None, point_numbers=None) -> dict:
    """A TOML-ready document in the robot's own units (``robot.units``, full float precision);
    ``comment`` adds a ``[calibration]`` table that says how the values were obtained,
    ``points`` the measured points on the tool (mm in, the file's unit out), ``point_numbers``
    their numbers in the data file they were fitted to (so that a subset is scored as itself)."""
    if robot.convention == "joint":
        raise RobotFileError("a joint-frame robot is written as URDF (a path ending in .urdf)")
    lu_name, au_name = robot.units
    lu, au = LENGTH[lu_name], ANGLE[au_name]
    dh = np.array(robot.dh)
    # a twist or offset beyond a whole turn is written within one (the same frames): the reader
    # takes one beyond a turn in radians for degrees
    turns = np.abs(dh[:, [0, 3]]) > 2 * np.pi
    dh[:, [0, 3]] = np.where(turns, dh[:, [0, 3]] - 2 * np.pi * np.round(dh[:, [0, 3]] / (2 * np.pi)), dh[:, [0, 3]])
    dh = dh / np.array([au, lu, lu, au])
    lim = np.asarray(robot.q_limits) / robot.joint_scale()[:, None]
    given = robot.limits_given()
    doc = {
        "name": robot.name,
        "convention": robot.convention,
        "length_unit": lu_name,
        "angle_unit": au_name,
        "joints": [
            {
                "name": robot.joint_names[i],
                "theta": float(r[0]),
                "d": float(r[1]),
                "a": float(r[2]),
                "alpha": float(r[3]),
                "type": t,
            }
            # limits the robot was given; without, the file gives none either (read back as none)
            | ({"limits": [float(lim[i, 0]), float(lim[i, 1])]} if given[i] else {})
            for i, (r, t) in enumerate(zip(dh, robot.joint_types))
        ],
    }
    if robot.compliance is not None:
        for j, c in zip(doc["joints"], np.asarray(robot.compliance)):
            j["compliance"] = float(c) * lu / au
        if robot.moment_ref is not None:
            for j, m in zip(doc["joints"], np.asarray(robot.moment_ref)):
                j["reference_moment"] = float(m) / lu
        if robot.load is not None and np.any(np.asarray(robot.compliance) != 0):
            doc["load"] = [float(v) / lu for v in np.asarray(robot.load)]
    for key in ("tool", "base"):
        T = np.asarray(getattr(robot, key))
        if not np.allclose(T, np.eye(4), atol=0, rtol=0):
            doc[key] = {
                "xyz": [float(v) / lu for v in T[:3, 3]],
                "rpy": [float(v) / au for v in np.asarray(matrix_to_rpy(T[:3, :3]))],
            }
    if points is not None and len(points):
        doc["points"] = [[float(v) / lu for v in p] for p in np.asarray(points)]
        if point_numbers is not None:
            doc["point_numbers"] = [int(j) for j in point_numbers]
    if comment:
        doc["calibration"] = dict(comment)
    return doc


def training_ranges_toml(path) -> dict | None:
    """The ``[calibration] training_ranges`` of a calibrated robot file (joint name -> ``(lowest,
    highest)``, mm and rad), or ``None``."""
    with Path(path).open("rb") as f:
        doc = tomllib.load(f)
    ranges = doc.get("calibration", {}).get("training_ranges")
    if not isinstance(ranges, dict):
        return None
    robot = robot_from_dict(doc, source=str(path))
    lu, au = LENGTH[robot.units[0]], ANGLE[robot.units[1]]
    kind = dict(zip(robot.joint_names, robot.joint_types))
    out = {}
    for name, v in ranges.items():
        if name not in kind or not isinstance(v, list) or len(v) != 2:
            raise RobotFileError(f"{path}: [calibration] training_ranges.{name} must be [lowest, highest] of a joint")
        s = au if kind[name] == "R" else lu
        out[name] = (_num(v[0], f"training_ranges.{name}") * s, _num(v[1], f"training_ranges.{name}") * s)
    return out


def save_toml(robot: Robot, path, *, comment: dict | None = None, points=None, point_numbers=None) -> None:
    """Write a robot TOML file in the robot's own units, atomically (a reader never sees half a
    file, and an existing file is replaced only once the new one is complete)."""
    doc = robot_to_dict(robot, comment=comment, points=points, point_numbers=point_numbers)
    write_atomic(path, tomli_w.dumps(doc))
