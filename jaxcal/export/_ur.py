r"""A six-joint DH robot as a Universal Robots kinematics file (``ur_description``'s
``default_kinematics.yaml`` format; read by ``ur_robot_driver`` as ``kinematics_params_file``).

## The mapping
In UR's description each revolute joint ``i`` sits at an ``<origin xyz rpy>`` in its parent link
and turns about its own z; the chain runs ``base_link_inertia`` (= ``base``, the controller's
Base frame) -> ``shoulder_link`` -> ... -> ``wrist_3_link`` (= ``tool0``, the tool flange). A
standard-DH chain regroups into exactly that form, since ``Rz(theta + q) Tz(d) = Tz(d) Rz(theta)
Rz(q)``::

    A_1 ... A_6 = [Tz(d_1) Rz(theta_1)] Rz(q_1) [Tx(a_1) Rx(alpha_1) Tz(d_2) Rz(theta_2)] Rz(q_2) ...
                  [Tx(a_5) Rx(alpha_5) Tz(d_6) Rz(theta_6)] Rz(q_6) [Tx(a_6) Rx(alpha_6)]

so joint ``i``'s origin is ``Tx(a_{i-1}) Rx(alpha_{i-1}) Tz(d_i) Rz(theta_i)`` (``a_0 = alpha_0 =
0``): the modified-DH row ``i`` of the same arm (:func:`jaxcal.to_mdh`), written as xyz (metres)
and roll-pitch-yaw. UR's nominal UR5 file is this with UR's DH table: shoulder ``z = d_1``,
upper_arm ``roll = alpha_1``, forearm ``x = a_2``, ...

## What is not in the file
* the **base frame** (measurement frame -> ``base``): where the robot stands in the tracker's
  (or the cell's) frame; ``base_link`` is ``base`` turned by pi about z, so the cell -> ``base_link``
  transform is ``base @ Rz(pi)``;
* the **tool** (``tool0`` -> the measured point or tool frame, i.e. the TCP), with the last DH
  link's ``Tx(a_6) Rx(alpha_6)`` (zero for UR's table; the tool carries it otherwise).

Both are written as comments at the top of the file and returned by :func:`ur_kinematics`.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from .._io import write_atomic
from ..errors import RobotFileError
from ..kinematics import mdh_link, to_mdh
from ..lie import matrix_to_rpy
from ..robot import UR_KEYS, UR_ORIGINS, Robot


def check_ur(robot: Robot, option: str | None = None) -> None:
    """Raise :class:`jaxcal.RobotFileError` unless ``robot`` is a DH robot with six revolute
    joints, the arms a UR kinematics file describes."""
    why = ""
    if robot.convention == "joint":
        why = (
            "it is described by joint frames (a URDF, or a UR kinematics file whose origins are not in DH form, "
            "as factory calibrations are), not a DH table"
        )
    elif robot.n_joints != 6:
        why = f"it has {robot.n_joints} joints, not 6"
    elif "P" in robot.joint_types:
        why = f"joint {robot.joint_types.index('P') + 1} is prismatic"
    if why:
        raise RobotFileError(
            f"{option or 'a UR kinematics file'} needs a six-joint revolute DH table (UR's, or any such); "
            f"{robot.name!r} is not: {why}",
            option=option,
        )


def _xyz_rpy(T) -> list[float]:
    """A transform (mm) as ``x, y, z`` (m) and roll, pitch, yaw (rad)."""
    T = np.asarray(T)
    v = [float(x) / 1000.0 for x in T[:3, 3]] + [float(x) for x in np.asarray(matrix_to_rpy(T[:3, :3]))]
    return [x + 0.0 for x in v]  # no -0.0


def _said(T) -> str:
    v = _xyz_rpy(T)
    return f"xyz [{', '.join(f'{x!r}' for x in v[:3])}] m, rpy [{', '.join(f'{x!r}' for x in v[3:])}] rad"


def ur_kinematics(robot: Robot) -> tuple[dict, np.ndarray, np.ndarray]:
    """``(document, base, tool)``: the UR kinematics document of ``robot`` (metres, radians; the
    module docstring's mapping) and the two transforms (mm) it does not hold: the measurement
    frame -> ``base`` and ``tool0`` -> the tool point or frame (the TCP)."""
    check_ur(robot)
    mdh = to_mdh(robot)
    entries = {}
    for key, row in zip(UR_ORIGINS, np.asarray(mdh.dh)):
        # the MDH link Rx(alpha) Tx(a) Rz(theta) Tz(d) is the origin Tx(a) Rx(alpha) Tz(d) Rz(theta)
        entries[key] = dict(zip(UR_KEYS, _xyz_rpy(np.asarray(mdh_link(*row)))))
    digest = hashlib.sha256(repr(sorted((k, tuple(v.values())) for k, v in entries.items())).encode()).digest()
    doc = {"kinematics": {**entries, "hash": f"calib_{int.from_bytes(digest[:8], 'big')}"}}
    return doc, np.asarray(mdh.base), np.asarray(mdh.tool)


def ur_kinematics_text(robot: Robot, *, comment: dict | None = None) -> tuple[str, np.ndarray, np.ndarray]:
    """``(text, base, tool)``: :func:`ur_kinematics` as YAML, headed by comments that say what it
    is and give the base and tool it does not hold (``comment``: more ``key: value`` lines)."""
    import yaml  # imported when needed: only the UR files use it

    doc, base, tool = ur_kinematics(robot)
    head = [
        f"UR kinematics of {robot.name}, written by jaxcal for ur_description / ur_robot_driver "
        "(kinematics_params_file)",
        "each entry: a joint's <origin> in its parent link (metres; roll-pitch-yaw about fixed x, y, z, radians)",
        "not in this file (see docs/using-the-result.md):",
        f"  base (measurement frame -> base, the controller's Base): {_said(base)}",
        f"  tool (tool0 -> the calibrated tool point / frame, the TCP): {_said(tool)}",
        *(f"{k}: {v}" for k, v in (comment or {}).items()),
    ]
    body = yaml.safe_dump(doc, sort_keys=False, default_flow_style=False)
    return "".join(f"# {line}\n" for line in head) + body, base, tool


def save_ur_kinematics(robot: Robot, path, *, comment: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Write ``robot`` (a six-joint revolute DH robot in UR's convention, lengths mm) as a UR
    kinematics file, atomically; **returns** ``(base, tool)``, the transforms (mm) the file does
    not hold (module docstring). Read it back with :func:`jaxcal.load_robot`.

    **Raises** :class:`jaxcal.RobotFileError` for any other robot, or a path not ending in
    ``.yaml``/``.yml`` (how :func:`jaxcal.load_robot` knows the file)."""
    if not isinstance(robot, Robot):
        raise RobotFileError(
            f"{path}: save_ur_kinematics takes a jaxcal.Robot (a result's .robot), not a {type(robot).__name__}"
        )
    if Path(path).suffix.lower() not in (".yaml", ".yml"):
        raise RobotFileError(f"{path}: a UR kinematics file is YAML and its name ends in .yaml (or .yml)")
    text, base, tool = ur_kinematics_text(robot, comment=comment)
    write_atomic(path, text)
    return base, tool
