"""Robot files by their suffix: TOML (DH tables), URDF (joint frames) or a UR kinematics file
(``.yaml``, :mod:`._ur`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._io import check_writable
from ..errors import RobotFileError
from ._robot import Robot
from ._toml import point_numbers_toml, read_toml, save_toml, training_ranges_toml
from ._ur import read_ur_kinematics
from ._urdf import calibrated_chain as _urdf_chain
from ._urdf import movable_joints_urdf, point_numbers_urdf, read_urdf, save_urdf, training_ranges_urdf


def _is_urdf(path) -> bool:
    return Path(path).suffix.lower() in (".urdf", ".xml")


def _is_yaml(path) -> bool:
    return Path(path).suffix.lower() in (".yaml", ".yml")


def read_robot_file(path, *, base_link: str | None = None, tip_link: str | None = None):
    """``(robot, points)``: a robot file and the measured points (mm, tool frame) a calibration
    wrote into it (``None`` if none). ``base_link`` and ``tip_link`` choose a URDF's chain."""
    if _is_urdf(path):
        return read_urdf(path, base_link=base_link, tip_link=tip_link)
    if base_link is not None or tip_link is not None:
        raise RobotFileError(f"{path}: base_link and tip_link choose the chain of a URDF file")
    if _is_yaml(path):
        return read_ur_kinematics(path), None
    return read_toml(path)


def calibrated_chain(path) -> tuple[str, str | None] | None:
    """``(base link, tip link)`` of the chain a calibrated URDF was written for (its
    ``jaxcal_measurement_frame`` and ``jaxcal_tool`` links); ``None`` for any other file."""
    return _urdf_chain(path) if _is_urdf(path) and Path(path).exists() else None


def read_movable_joints(path, above: str | None) -> dict[str, str]:
    """The movable joints of a URDF above the link ``above`` (a chain's base link), which move
    the whole chain (name -> ``"R"`` or ``"P"``); empty for other files, whose joints are all
    the chain's, or for the root."""
    return movable_joints_urdf(path, above) if _is_urdf(path) and Path(path).exists() else {}


def read_training_ranges(path) -> dict | None:
    """The joint ranges a calibrated model was fitted on, as its file records them (joint name ->
    ``(lowest, highest)``, mm and rad), or ``None`` (a nominal file, a UR kinematics file)."""
    if _is_yaml(path):
        return None
    return training_ranges_urdf(path) if _is_urdf(path) else training_ranges_toml(path)


def read_point_numbers(path) -> tuple[int, ...] | None:
    """The data file's number of each measured point a calibrated model holds, as its file
    records them (``(1, 3)`` for a fit with ``--points 1,3``), or ``None`` (no points, a nominal
    file, a UR kinematics file)."""
    if _is_yaml(path):
        return None
    return point_numbers_urdf(path) if _is_urdf(path) else point_numbers_toml(path)


def load_robot(path, *, base_link: str | None = None, tip_link: str | None = None) -> Robot:
    """Read a robot file: TOML (a DH table, :mod:`jaxcal.robot._toml`), URDF (the chain from
    ``base_link`` to ``tip_link``, :mod:`jaxcal.robot._urdf`) or a UR kinematics file (``.yaml``,
    :mod:`jaxcal.robot._ur`)."""
    return read_robot_file(path, base_link=base_link, tip_link=tip_link)[0]


def save_robot(
    robot: Robot,
    path,
    *,
    comment: dict | None = None,
    points=None,
    template=None,
    base_link: str | None = None,
    tip_link: str | None = None,
    training_ranges: dict | None = None,
    point_numbers=None,
) -> None:
    """Write a robot file atomically: URDF for a path ending in ``.urdf`` (a joint-frame robot;
    ``template`` the nominal URDF whose chain it keeps), TOML otherwise (a DH robot). ``points``
    (mm, tool frame) are written with it, and ``training_ranges`` (joint name -> ``(lowest,
    highest)``, mm and rad: :func:`read_training_ranges`), and ``point_numbers``, the data
    file's number of each point (:func:`read_point_numbers`)."""
    if not isinstance(robot, Robot):
        raise RobotFileError(
            f"{path}: save_robot takes a jaxcal.Robot (a result's .robot), not a {type(robot).__name__}"
        )
    if _is_yaml(path):  # load_robot reads .yaml as UR's kinematics file, which this is not
        raise RobotFileError(
            f"{path}: a robot file is written as TOML (.toml) or URDF (.urdf); a UR kinematics file (.yaml) "
            "is written by jaxcal.save_ur_kinematics (--out-ur-kinematics)"
        )
    check_writable(path, "path")
    points = None if points is None or not len(np.asarray(points)) else np.asarray(points)
    if point_numbers is not None:  # as the readers check them: one distinct number >= 1 per point
        nums = list(point_numbers)
        if (
            points is None
            or len(nums) != len(points)
            or len(set(nums)) != len(nums)
            or not all(isinstance(j, (int, np.integer)) and not isinstance(j, bool) and j >= 1 for j in nums)
        ):
            raise RobotFileError(
                f"{path}: point_numbers {nums} must give one distinct number >= 1 to each of the "
                f"{0 if points is None else len(points)} points"
            )
    if _is_urdf(path):
        if robot.convention != "joint":
            raise RobotFileError(
                f"{path}: a DH robot is written as TOML; jaxcal.to_joint converts it to joint frames for URDF"
            )
        save_urdf(
            robot, path, points=points, template=template, base_link=base_link, tip_link=tip_link, comment=comment,
            training_ranges=training_ranges, point_numbers=point_numbers,
        )  # fmt: skip
    else:
        if training_ranges:
            scale = dict(zip(robot.joint_names, robot.joint_scale()))
            file = {n: [v / scale[n] for v in r] for n, r in training_ranges.items()}
            comment = dict(comment or {}) | {"training_ranges": file}
        save_toml(robot, path, comment=comment, points=points, point_numbers=point_numbers)
