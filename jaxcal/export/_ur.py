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

## Joint frames
A robot read from a UR kinematics file whose origins are off the DH form (UR's factory
calibrations) is a joint-frame robot whose chain is UR's own, ``base_link_inertia`` to
``wrist_3_link``: each entry is then the joint's corrected origin with its offset turned in
(``O_i E_i Rz(offset_i)``), read off the chain at zero joint values. A URDF's chain often starts
at its ``base_link``, a turn of pi about z from ``base_link_inertia``, so joint frames are written
only where the caller says the chain is UR's (``ur_chain``; the command says so for a UR file and
for a URDF chain from ``base_link_inertia``), and a first origin turned by about pi is refused.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from .._io import write_atomic
from ..errors import RobotFileError
from ..kinematics import fk_frames, mdh_link, to_mdh
from ..lie import matrix_to_rpy
from ..robot import UR_KEYS, UR_ORIGINS, Robot, read_ur_kinematics


def check_ur(robot: Robot, option: str | None = None, *, ur_chain: bool = False) -> None:
    """Raise :class:`jaxcal.RobotFileError` unless ``robot`` is an arm a UR kinematics file
    describes: six revolute joints, as a DH table or (``ur_chain``: its chain is UR's own, as
    :func:`jaxcal.robot.read_ur_kinematics` reads one) joint frames turning about their z."""
    why = ""
    if robot.n_joints != 6:
        why = f"it has {robot.n_joints} joints, not 6"
    elif "P" in robot.joint_types:
        why = f"joint {robot.joint_types.index('P') + 1} is prismatic"
    elif robot.convention == "joint" and not ur_chain:
        why = (
            "it is described by joint frames whose first is not known to be UR's base: a URDF's chain often starts "
            "at base_link, a turn of pi about z from UR's base_link_inertia (the command writes a chain read from a "
            "UR kinematics file, factory calibrations included, or from a URDF's base_link_inertia (--base-link); "
            "save_ur_kinematics with ur_chain=True)"
        )
    elif robot.convention == "joint":
        off = np.flatnonzero(np.abs(np.asarray(robot.axes) - [0.0, 0.0, 1.0]).max(axis=1) > 1e-12)
        yaw = float(np.arctan2(*_entries(robot)[0, 1::-1, 0])) if not off.size else 0.0
        if off.size:
            why = f"joint {off[0] + 1} turns about {np.asarray(robot.axes)[off[0]].tolist()} of its origin, not z"
        elif abs(yaw) > np.pi / 2:  # UR's base and base_link are pi apart; a factory calibration moves mrad
            why = (
                f"its first joint's origin is turned by {yaw:.3f} rad about z: the chain starts at base_link, not at "
                "UR's base (base_link_inertia); read the chain from base_link_inertia"
            )
    if why:
        raise RobotFileError(
            f"{option or 'a UR kinematics file'} needs a six-joint revolute arm as a DH table (UR's, or any such) "
            f"or as UR's own joint frames; {robot.name!r} is not: {why}",
            option=option,
        )


def _xyz_rpy(T, like=None) -> list[float]:
    """A transform (mm) as ``x, y, z`` (m) and roll, pitch, yaw (rad); with ``like`` (a roll,
    pitch, yaw), the same rotation written as near it as it goes: of the two triples of a
    rotation, each angle moved by whole turns, the nearer."""
    T = np.asarray(T)
    rpy = np.asarray(matrix_to_rpy(T[:3, :3]), float)
    if like is not None:
        like = np.asarray(like, float)
        twins = [rpy, rpy + [np.pi, 0.0, np.pi] - [0.0, 2 * rpy[1] - np.pi, 0.0]]  # (r + pi, pi - p, y + pi)
        turned = [c + 2 * np.pi * np.round((like - c) / (2 * np.pi)) for c in twins]
        rpy = min(turned, key=lambda c: float(np.abs(c - like).sum()))
    v = [float(x) / 1000.0 for x in T[:3, 3]] + [float(x) for x in rpy]
    return [x + 0.0 for x in v]  # no -0.0


def _angles_of(path) -> dict:
    """Each entry's roll, pitch, yaw in a UR kinematics file (checked as :func:`jaxcal.load_robot`
    reads it)."""
    import yaml

    read_ur_kinematics(path)  # a file that does not read is refused with its reason
    kin = yaml.safe_load(Path(path).read_text(encoding="utf-8"))["kinematics"]
    return {key: [float(kin[key][k]) for k in UR_KEYS[3:]] for key in UR_ORIGINS}


def _said(T) -> str:
    v = _xyz_rpy(T)
    return f"xyz [{', '.join(f'{x!r}' for x in v[:3])}] m, rpy [{', '.join(f'{x!r}' for x in v[3:])}] rad"


def _entries(robot: Robot) -> np.ndarray:
    """``(6, 4, 4)`` each joint's origin in its parent link, the joint's turn left out (mm)."""
    if robot.convention == "joint":  # the chain at zero joint values: O_i E_i Rz(offset_i), base left out
        T = np.asarray(fk_frames(robot.replace(base=np.eye(4)), np.zeros(6)))
        return np.concatenate([T[:1], np.linalg.inv(T[:-1]) @ T[1:]])
    # the MDH link Rx(alpha) Tx(a) Rz(theta) Tz(d) is the origin Tx(a) Rx(alpha) Tz(d) Rz(theta)
    return np.stack([np.asarray(mdh_link(*row)) for row in np.asarray(to_mdh(robot).dh)])


def ur_kinematics(robot: Robot, *, ur_chain: bool = False, like=None) -> tuple[dict, np.ndarray, np.ndarray]:
    """``(document, base, tool)``: the UR kinematics document of ``robot`` (metres, radians; the
    module docstring's mapping) and the two transforms (mm) it does not hold: the measurement
    frame -> ``base`` and ``tool0`` -> the tool point or frame (the TCP). ``ur_chain``: a
    joint-frame robot's chain is UR's own (module docstring, "Joint frames"). ``like``: a UR
    kinematics file (the one calibrated) whose angles the written ones follow, the same
    rotations written as near its numbers as they go, so that a diff shows what changed."""
    check_ur(robot, ur_chain=ur_chain)
    near = _angles_of(like) if like is not None else {}
    entries = {key: dict(zip(UR_KEYS, _xyz_rpy(T, near.get(key)))) for key, T in zip(UR_ORIGINS, _entries(robot))}
    digest = hashlib.sha256(repr(sorted((k, tuple(v.values())) for k, v in entries.items())).encode()).digest()
    doc = {"kinematics": {**entries, "hash": f"calib_{int.from_bytes(digest[:8], 'big')}"}}
    outer = robot if robot.convention == "joint" else to_mdh(robot)
    return doc, np.asarray(outer.base), np.asarray(outer.tool)


def ur_kinematics_text(
    robot: Robot, *, comment: dict | None = None, ur_chain: bool = False, like=None
) -> tuple[str, np.ndarray, np.ndarray]:
    """``(text, base, tool)``: :func:`ur_kinematics` as YAML, headed by comments that say what it
    is and give the base and tool it does not hold (``comment``: more ``key: value`` lines)."""
    import yaml  # imported when needed: only the UR files use it

    doc, base, tool = ur_kinematics(robot, ur_chain=ur_chain, like=like)
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


def save_ur_kinematics(
    robot: Robot, path, *, comment: dict | None = None, ur_chain: bool = False, like=None
) -> tuple[np.ndarray, np.ndarray]:
    """Write ``robot`` (a six-joint revolute DH robot, lengths mm; or, with ``ur_chain``, one read
    from a UR kinematics file as joint frames and calibrated) as a UR kinematics file,
    atomically; **returns** ``(base, tool)``, the transforms (mm) the file does not hold (module
    docstring). Read it back with :func:`jaxcal.load_robot`. ``like``: :func:`ur_kinematics`'s.

    **Raises** :class:`jaxcal.RobotFileError` for any other robot, or a path not ending in
    ``.yaml``/``.yml`` (how :func:`jaxcal.load_robot` knows the file)."""
    if not isinstance(robot, Robot):
        raise RobotFileError(
            f"{path}: save_ur_kinematics takes a jaxcal.Robot (a result's .robot), not a {type(robot).__name__}"
        )
    if Path(path).suffix.lower() not in (".yaml", ".yml"):
        raise RobotFileError(f"{path}: a UR kinematics file is YAML and its name ends in .yaml (or .yml)")
    text, base, tool = ur_kinematics_text(robot, comment=comment, ur_chain=ur_chain, like=like)
    write_atomic(path, text)
    return base, tool
