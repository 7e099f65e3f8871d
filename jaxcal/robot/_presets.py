"""Published DH tables (mm, rad).

* ``paper_6r``: the paper's Table 1 arm (SDH; offset -pi/2 on joint 2). The paper gives no
  joint limits; we use +-170 degrees on every joint (documented assumption).
* ``puma560``: PUMA 560, standard DH as in Corke's Robotics Toolbox (``mdl_puma560``), limits
  from the same source.
* ``ur5``, ``ur10e``: Universal Robots UR5 and UR10e, standard DH from the manufacturer's
  published tables, in UR's joint convention (the controller's joint angles, its Base frame as
  frame 0, the tool flange as frame 6): what :func:`jaxcal.save_ur_kinematics` writes for
  ``ur_description``. Limits +-pi, a sampling range (the arms turn +-2 pi).
* ``panda``: Franka Emika Panda, modified DH (Craig) from Franka's documentation, flange
  offset d = 107 mm as the tool transform.
"""

from __future__ import annotations

import numpy as np

from ._robot import Robot

PI = np.pi
_deg = np.deg2rad


def paper_6r() -> Robot:
    dh = np.array(
        [
            # theta offset, d, a, alpha
            [0.0, 0.0, 160.0, -PI / 2],
            [-PI / 2, 0.0, 580.0, 0.0],
            [0.0, 0.0, 200.0, -PI / 2],
            [0.0, 640.0, 0.0, PI / 2],
            [0.0, 228.0, 0.0, -PI / 2],
            [0.0, 0.0, 0.0, 0.0],
        ]
    )
    return Robot(dh, convention="sdh", q_limits=np.tile(_deg([-170.0, 170.0]), (6, 1)), name="paper-6r")


def puma560() -> Robot:
    dh = np.array(
        [
            [0.0, 0.0, 0.0, PI / 2],
            [0.0, 0.0, 431.8, 0.0],
            [0.0, 150.05, 20.3, -PI / 2],
            [0.0, 431.8, 0.0, PI / 2],
            [0.0, 0.0, 0.0, -PI / 2],
            [0.0, 0.0, 0.0, 0.0],
        ]
    )
    lim = _deg(np.array([[-160, 160], [-225, 45], [-45, 225], [-110, 170], [-100, 100], [-266, 266]], float))
    return Robot(dh, convention="sdh", q_limits=lim, name="puma560")


def ur5() -> Robot:
    dh = np.array(
        [
            [0.0, 89.159, 0.0, PI / 2],
            [0.0, 0.0, -425.0, 0.0],
            [0.0, 0.0, -392.25, 0.0],
            [0.0, 109.15, 0.0, PI / 2],
            [0.0, 94.65, 0.0, -PI / 2],
            [0.0, 82.3, 0.0, 0.0],
        ]
    )
    return Robot(dh, convention="sdh", q_limits=np.tile([-PI, PI], (6, 1)), name="ur5")


def ur10e() -> Robot:
    dh = np.array(
        [
            [0.0, 180.7, 0.0, PI / 2],
            [0.0, 0.0, -612.7, 0.0],
            [0.0, 0.0, -571.55, 0.0],
            [0.0, 174.15, 0.0, PI / 2],
            [0.0, 119.85, 0.0, -PI / 2],
            [0.0, 116.55, 0.0, 0.0],
        ]
    )
    return Robot(dh, convention="sdh", q_limits=np.tile([-PI, PI], (6, 1)), name="ur10e")


def panda() -> Robot:
    dh = np.array(
        [
            [0.0, 333.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, -PI / 2],
            [0.0, 316.0, 0.0, PI / 2],
            [0.0, 0.0, 82.5, PI / 2],
            [0.0, 384.0, -82.5, -PI / 2],
            [0.0, 0.0, 0.0, PI / 2],
            [0.0, 0.0, 88.0, PI / 2],
        ]
    )
    tool = np.eye(4)
    tool[2, 3] = 107.0
    lim = np.array(
        [
            [-2.8973, 2.8973],
            [-1.7628, 1.7628],
            [-2.8973, 2.8973],
            [-3.0718, -0.0698],
            [-2.8973, 2.8973],
            [-0.0175, 3.7525],
            [-2.8973, 2.8973],
        ]
    )
    return Robot(dh, convention="mdh", tool=tool, q_limits=lim, name="panda")


PRESETS = {"paper-6r": paper_6r, "puma560": puma560, "ur5": ur5, "ur10e": ur10e, "panda": panda}


def preset(name: str) -> Robot:
    try:
        return PRESETS[name]()
    except KeyError:
        raise KeyError(f"unknown preset {name!r}; known: {', '.join(PRESETS)}") from None
