r"""Universal Robots' kinematics files (``ur_description``'s ``config/<type>/default_kinematics.yaml``,
the ``kinematics_params_file`` of ``ur_robot_driver``) -> :class:`jaxcal.Robot`.

The file gives, for each of the six revolute joints ``shoulder_pan_joint .. wrist_3_joint``, the
``<origin xyz rpy>`` of the joint in its parent link (metres; roll-pitch-yaw about fixed axes,
radians); each joint turns about its own z. The chain starts at ``base_link_inertia``, which
coincides with ``base`` (the controller's Base frame), and ends at ``wrist_3_link``, which
coincides with ``tool0`` (the tool flange)::

    kinematics:
      shoulder:  {x: ..., y: ..., z: ..., roll: ..., pitch: ..., yaw: ...}
      upper_arm: ...
      forearm:   ...
      wrist_1:   ...
      wrist_2:   ...
      wrist_3:   ...
      hash: calib_<digits>

An origin of the form ``Tx(a) Rx(alpha) Tz(d) Rz(theta)`` (UR's nominal files, and what
:func:`jaxcal.save_ur_kinematics` writes) is a modified-DH row ``(theta, d, a, alpha)``: such a
file reads as an ``mdh`` robot. Any other file (UR's factory calibrations move the origins off
that form) reads as joint frames (``convention="joint"``). Base and tool are the identity: the
robot's base is UR's ``base``, its tool ``tool0``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import RobotFileError
from ..lie import rpy_to_matrix
from ._robot import Robot

UR_ORIGINS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
"""The entries of a kinematics file, one per joint, base to tip."""
UR_JOINT_NAMES = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
UR_KEYS = ("x", "y", "z", "roll", "pitch", "yaw")
UR_BASE = "base_link_inertia"
"""The link a kinematics file's chain starts at (UR's ``base``); ``base_link`` is a turn of pi about z from it."""
DH_FORM_TOL = 1e-9
"""Largest departure (m, rad) of an origin from ``Tx(a) Rx(alpha) Tz(d) Rz(theta)`` read as a DH row."""


def dh_row_of(T) -> tuple[np.ndarray, float, float]:
    """The modified-DH row ``(theta, d, a, alpha)`` of an origin ``T = Tx(a) Rx(alpha) Tz(d)
    Rz(theta)`` (lengths in ``T``'s unit, rad), and how far ``T`` is from that form: the rotation's
    and the translation's misfit."""
    R, p = T[:3, :3], T[:3, 3]
    # Rx(alpha) Rz(theta) = [[ct, -st, 0], [ca st, ca ct, -sa], [sa st, sa ct, ca]], p = (a, -sa d, ca d)
    theta, alpha = np.arctan2(-R[0, 1], R[0, 0]), np.arctan2(-R[1, 2], R[2, 2])
    ca, sa = np.cos(alpha), np.sin(alpha)
    d = -sa * p[1] + ca * p[2]
    row = np.array([theta, d, p[0], alpha]) + 0.0  # no -0.0
    return row, float(abs(R[0, 2])), float(abs(ca * p[1] + sa * p[2]))


def _entry(doc, key, path):
    v = doc.get(key)
    if not isinstance(v, dict):
        raise RobotFileError(f"{path}: kinematics.{key} must be a mapping with keys {', '.join(UR_KEYS)}")
    out = []
    for k in UR_KEYS:
        if k not in v:
            raise RobotFileError(f"{path}: kinematics.{key}.{k} is missing")
        x = v[k]
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not np.isfinite(x):
            raise RobotFileError(f"{path}: kinematics.{key}.{k} must be a finite number, got {x!r}")
        out.append(float(x))
    return out


def read_ur_kinematics(path) -> Robot:
    """A UR kinematics file as a robot in metres (module docstring): modified DH where every
    origin has the DH form, joint frames otherwise. The joint limits are +-2 pi."""
    import yaml  # imported when needed: only this reader uses it

    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise RobotFileError(f"robot file not found: {path}") from None
    except yaml.YAMLError as e:
        raise RobotFileError(f"{path}: not valid YAML: {e}") from None
    kin = doc.get("kinematics") if isinstance(doc, dict) else None
    if not isinstance(kin, dict):
        raise RobotFileError(
            f"{path}: a UR kinematics file needs a top-level 'kinematics' mapping (a .yaml robot file is read as "
            "UR's ROS 2 kinematics file; a DH table goes in a .toml robot file)"
        )
    origins = np.tile(np.eye(4), (6, 1, 1))
    for i, key in enumerate(UR_ORIGINS):
        v = _entry(kin, key, path)
        origins[i, :3, :3] = np.asarray(rpy_to_matrix(np.array(v[3:])))
        origins[i, :3, 3] = np.array(v[:3]) * 1000.0  # m -> mm
    rows = [dh_row_of(T) for T in origins]
    kw = dict(
        q_limits=np.tile([-2 * np.pi, 2 * np.pi], (6, 1)),
        name=path.stem,
        joint_names=UR_JOINT_NAMES,
        units=("m", "rad"),
    )
    if all(rot <= DH_FORM_TOL and pos <= 1000.0 * DH_FORM_TOL for _, rot, pos in rows):
        return Robot(np.stack([r for r, _, _ in rows]), convention="mdh", **kw)
    return Robot(None, convention="joint", origins=origins, axes=np.tile([0.0, 0.0, 1.0], (6, 1)), **kw)
