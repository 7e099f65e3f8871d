"""Candidate parameter sets (the ``params`` option): which DH errors may move and under which
ridge prior; :func:`jaxcal.calibrate_data` compares them by cross-validation."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..camera import n_params
from ..errors import DataError
from ..robot import DH_NAMES, Robot

PARAM_SETS = ("auto", "frames", "offsets", "angles", "all")
RIDGE_GRID_MM = (0.1, 0.3, 1.0, 3.0)
_KIND = {k: i for i, k in enumerate(DH_NAMES)}


@dataclasses.dataclass(frozen=True)
class Candidate:
    """A DH parameter set (indices into the 4n DH errors), an optional ridge prior and the camera
    measurement model estimated with it."""

    name: str
    dh: tuple[int, ...]
    """DH errors allowed to move (those not identifiable are dropped later)."""
    ridge_mm: float | None = None
    """Prior standard deviation ``s`` (mm for lengths, mrad for angles); None = no prior."""
    camera: str = "none"
    """Camera measurement model (:mod:`jaxcal.camera`) whose unknowns are free in this candidate."""

    @property
    def complexity(self) -> tuple[int, float]:
        return (len(self.dh) + n_params(self.camera), -(self.ridge_mm or np.inf))

    def prior_weight(self, i: int) -> float:
        """Ridge weight ``1 / s`` of DH error ``i`` (index into the 4n; lengths ``s`` mm, angles
        ``s`` mrad), 0 without a ridge; only meaningful for ``i`` in :attr:`dh`."""
        if self.ridge_mm is None:
            return 0.0
        return 1.0 / (self.ridge_mm if i % 4 in (1, 2) else self.ridge_mm * 1e-3)


def _kinds(n: int, kinds) -> tuple[int, ...]:
    return tuple(4 * j + _KIND[k] for j in range(n) for k in kinds)


def parse_params(spec: str, robot: Robot, ridge_mm: float | None = None) -> list[Candidate]:
    """Candidates for ``params``: ``auto`` (frames, offsets, angles, all with a ridge grid
    and all), one of ``frames|offsets|angles|all``, or a comma-separated list of DH kinds
    (``theta,d,a,alpha``) and/or parameter names (``theta2, a4``). ``ridge_mm`` adds a prior
    to an explicit set."""
    n = robot.n_joints
    names = robot.param_names()
    named = {
        "frames": (),
        "offsets": _kinds(n, ["theta"]),
        "angles": _kinds(n, ["theta", "alpha"]),
        "all": tuple(range(4 * n)),
    }
    spec = spec.strip()
    if spec == "auto":
        cands = [Candidate(k, v) for k, v in named.items() if k != "all"]
        cands += [Candidate(f"all, ridge {s:g}", named["all"], s) for s in RIDGE_GRID_MM]
        return cands + [Candidate("all", named["all"])]
    if spec in named:
        dh = named[spec]
    else:
        idx: set[int] = set()
        for tok in (t.strip() for t in spec.split(",")):
            if tok in _KIND:
                idx.update(_kinds(n, [tok]))
            elif tok in names:
                idx.add(names.index(tok))
            else:
                raise DataError(
                    f"params: unknown parameter or set {tok!r}; use auto, frames, offsets, angles, "
                    f"all, or a comma list of theta, d, a, alpha and names like theta2, a4 "
                    f"(joints 1..{n})",
                    option="params",
                )
        dh = tuple(sorted(idx))
    name = spec if ridge_mm is None else f"{spec}, ridge {ridge_mm:g}"
    return [Candidate(name, dh, ridge_mm)]
