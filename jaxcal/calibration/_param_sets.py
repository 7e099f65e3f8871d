"""Candidate parameter sets (the ``params`` option): which DH errors may move and under which
prior; :func:`jaxcal.calibrate_data` chooses among them (:mod:`._selection`)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..camera import n_params
from ..errors import DataError
from ..robot import DH_NAMES, JOINT_FRAME_NAMES, Robot

PARAM_SETS = ("auto", "frames", "offsets", "angles", "all")
PRIOR_GRID_MM = (0.3, 1.0, 3.0)
"""The prior standard deviations (mm of point motion, :mod:`._selection`) ``auto`` tries, and none."""
_ANGLES = {"sdh": ("theta", "alpha"), "mdh": ("theta", "alpha"), "joint": ("offset", "rx", "ry", "rz")}


@dataclasses.dataclass(frozen=True)
class Candidate:
    """A kinematic parameter set (indices into the robot's parameter errors), an optional ridge
    prior and the camera measurement model estimated with it."""

    name: str
    dh: tuple[int, ...]
    """DH errors allowed to move (those not identifiable are dropped later)."""
    ridge_mm: float | None = None
    """Prior standard deviation ``s``: how far (mm) each parameter is expected to move the measured
    points (:func:`prior_weight`); None = no prior."""
    camera: str = "none"
    """Camera measurement model (:mod:`jaxcal.camera`) whose unknowns are free in this candidate."""
    units: tuple[str, ...] = ()
    """``mm`` or ``rad`` per kinematic parameter (:meth:`jaxcal.Robot.param_units`)."""
    compliance: bool = False
    """The joint compliances (:attr:`jaxcal.Robot.compliance`) are estimated with the set."""

    @property
    def complexity(self) -> tuple[int, float]:
        """Fewer free parameters, then a stronger prior, is simpler."""
        return (len(self.dh) + n_params(self.camera) + 1000 * self.compliance, self.ridge_mm or np.inf)

    def prior_weight(self, lever_mm: float) -> float:
        """Prior weight ``L / s`` of a parameter whose lever (RMS displacement of the measured points
        per unit of it) is ``lever_mm``: physically scaled, 1 mm and the angle that moves the
        points 1 mm weigh the same; 0 without a prior."""
        return 0.0 if self.ridge_mm is None else float(lever_mm) / self.ridge_mm


def _kinds(robot: Robot, kinds) -> tuple[int, ...]:
    names = JOINT_FRAME_NAMES if robot.convention == "joint" else DH_NAMES
    p = len(names)
    return tuple(p * j + names.index(k) for j in range(robot.n_joints) for k in kinds)


def parse_params(
    spec: str, robot: Robot, ridge_mm: float | None = None, *, compliance: bool = False
) -> list[Candidate]:
    """Candidates for ``params``: ``auto`` (frames, offsets, and all under each prior of
    :data:`PRIOR_GRID_MM` and none; each of the last also with the joint compliances when
    ``compliance``), one of ``frames|offsets|angles|all``, or a comma-separated list of kinds
    (DH: ``theta,d,a,alpha``; joint frames: ``offset,x,y,z,rx,ry,rz``) and/or parameter names
    (``theta2, a4``; ``offset2, rx3``). ``angles`` are the DH angles, or a joint frame's offset
    and rotation. ``ridge_mm`` adds a prior to an explicit set, ``compliance`` the compliances."""
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
        cands = [Candidate(k, named[k], units=units) for k in ("frames", "offsets")]
        for comp in (False, True) if compliance else (False,):
            base = "all + compliance" if comp else "all"
            cands += [
                Candidate(
                    base if s is None else f"{base}, prior {s:g} mm", named["all"], s, units=units, compliance=comp
                )
                for s in PRIOR_GRID_MM + (None,)
            ]
        return cands
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
    name = spec + (" + compliance" if compliance else "") + ("" if ridge_mm is None else f", prior {ridge_mm:g} mm")
    return [Candidate(name, dh, ridge_mm, units=units, compliance=compliance)]
