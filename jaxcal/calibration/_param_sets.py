"""Candidate parameter sets (the ``params`` option): which DH errors may move and under which
ridge prior; :func:`jaxcal.calibrate_data` compares them by cross-validation."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..camera import n_params
from ..errors import DataError
from ..robot import DH_NAMES, JOINT_FRAME_NAMES, Robot

PARAM_SETS = ("auto", "frames", "offsets", "angles", "all")
RIDGE_GRID_MM = (0.1, 0.3, 1.0, 3.0)
_ANGLES = {"sdh": ("theta", "alpha"), "mdh": ("theta", "alpha"), "joint": ("offset", "rx", "ry", "rz")}


@dataclasses.dataclass(frozen=True)
class Candidate:
    """A kinematic parameter set (indices into the robot's parameter errors), an optional ridge
    prior and the camera measurement model estimated with it."""

    name: str
    dh: tuple[int, ...]
    """DH errors allowed to move (those not identifiable are dropped later)."""
    ridge_mm: float | None = None
    """Prior standard deviation ``s`` (mm for lengths, mrad for angles); None = no prior."""
    camera: str = "none"
    """Camera measurement model (:mod:`jaxcal.camera`) whose unknowns are free in this candidate."""
    units: tuple[str, ...] = ()
    """``mm`` or ``rad`` per kinematic parameter (:meth:`jaxcal.Robot.param_units`)."""
    compliance: bool = False
    """The joint compliances (:attr:`jaxcal.Robot.compliance`) are estimated with the set."""

    @property
    def complexity(self) -> tuple[int, float]:
        return (len(self.dh) + n_params(self.camera), -(self.ridge_mm or np.inf))

    def prior_weight(self, i: int) -> float:
        """Ridge weight ``1 / s`` of kinematic error ``i`` (lengths ``s`` mm, angles ``s`` mrad),
        0 without a ridge; only meaningful for ``i`` in :attr:`dh`."""
        if self.ridge_mm is None:
            return 0.0
        length = self.units[i] == "mm" if self.units else i % 4 in (1, 2)
        return 1.0 / (self.ridge_mm if length else self.ridge_mm * 1e-3)


def _kinds(robot: Robot, kinds) -> tuple[int, ...]:
    names = JOINT_FRAME_NAMES if robot.convention == "joint" else DH_NAMES
    p = len(names)
    return tuple(p * j + names.index(k) for j in range(robot.n_joints) for k in kinds)


def parse_params(spec: str, robot: Robot, ridge_mm: float | None = None) -> list[Candidate]:
    """Candidates for ``params``: ``auto`` (frames, offsets, angles, all with a ridge grid
    and all), one of ``frames|offsets|angles|all``, or a comma-separated list of kinds
    (DH: ``theta,d,a,alpha``; joint frames: ``offset,x,y,z,rx,ry,rz``) and/or parameter names
    (``theta2, a4``; ``offset2, rx3``). ``angles`` are the DH angles, or a joint frame's offset
    and rotation. ``ridge_mm`` adds a prior to an explicit set."""
    n = robot.n_joints
    names = robot.param_names()
    kinds = JOINT_FRAME_NAMES if robot.convention == "joint" else DH_NAMES
    units = tuple(robot.param_units())
    named = {
        "frames": (),
        "offsets": _kinds(robot, [kinds[0]]),
        "angles": _kinds(robot, _ANGLES[robot.convention]),
        "all": tuple(range(len(names))),
    }
    spec = spec.strip()
    if spec == "auto":
        cands = [Candidate(k, v, units=units) for k, v in named.items() if k != "all"]
        cands += [Candidate(f"all, ridge {s:g}", named["all"], s, units=units) for s in RIDGE_GRID_MM]
        return cands + [Candidate("all", named["all"], units=units)]
    if spec in named:
        dh = named[spec]
    else:
        idx: set[int] = set()
        for tok in (t.strip() for t in spec.split(",")):
            if tok in kinds:
                idx.update(_kinds(robot, [tok]))
            elif tok in names:
                idx.add(names.index(tok))
            else:
                raise DataError(
                    f"params: unknown parameter or set {tok!r}; use auto, frames, offsets, angles, "
                    f"all, or a comma list of {', '.join(kinds)} and names like {names[0]}, {names[-1]} "
                    f"(joints 1..{n})",
                    option="params",
                )
        dh = tuple(sorted(idx))
    name = spec if ridge_mm is None else f"{spec}, ridge {ridge_mm:g}"
    return [Candidate(name, dh, ridge_mm, units=units)]
