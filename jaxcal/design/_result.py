"""A pose design and its comparison with random poses of the same count."""

from __future__ import annotations

import dataclasses

import numpy as np

from ._problem import CRITERIA, value

LABELS = {
    "d": "log det information (D, larger is better)",
    "a": "trace of scaled covariance (A)",
    "validation": "expected validation RMS, mm (CRLB)",
}


@dataclasses.dataclass(frozen=True, eq=False)
class PoseDesign:
    """Result of :func:`optimal_poses` or :func:`select_poses` (arrays read-only)."""

    q: np.ndarray
    """``(N, n)`` joint configurations (rad; mm for prismatic joints)."""
    criterion: str
    values: dict
    """All three criteria of the design (:func:`evaluate`)."""
    random_values: dict
    """The same criteria of ``n_random`` random pose sets of the same count, ``(R,)`` each."""
    method: str
    """``"gradient"`` or ``"pool"``."""
    base_names: tuple[str, ...]
    """The base parameters the design is for."""
    feasible: bool
    """The limits hold, and the spread and region constraints where given."""
    min_distance: float
    """Smallest joint-space distance between two chosen configurations."""
    details: dict = dataclasses.field(default_factory=dict)
    """Method-specific figures: starts, steps, convergence, exchanges, pool indices."""

    @property
    def value(self) -> float:
        """The design's value of its criterion."""
        return value(self.criterion, self.values)

    def random_fraction_better(self, criterion: str | None = None) -> float:
        """Fraction of the random pose sets that beat the design on ``criterion`` (default its
        own)."""
        c = criterion or self.criterion
        r = np.asarray(self.random_values[_key(c)])
        v = value(c, self.values)
        return float(np.mean(r > v) if c == "d" else np.mean(r < v))

    def equivalent_random_poses(self, criterion: str | None = None) -> float:
        """How many random poses would match the design on ``criterion``, estimated from the
        median random set of the same count, with the information growing in proportion to the
        number of poses (the variances as ``1/K``, ``log det`` as ``b log K``)."""
        c = criterion or self.criterion
        N = self.q.shape[0]
        med = float(np.median(self.random_values[_key(c)]))
        v = value(c, self.values)
        if c == "d":
            return float(N * np.exp((v - med) / len(self.base_names)))
        if c == "validation":
            return float(N * (med / v) ** 2)
        return float(N * med / v)

    def report(self) -> str:
        """A table of the design's criteria against the random pose sets."""
        N = self.q.shape[0]
        R = len(next(iter(self.random_values.values())))
        lines = [
            f"{self.method} design of {N} poses, criterion {self.criterion!r}, "
            f"{len(self.base_names)} base parameters; {'feasible' if self.feasible else 'NOT FEASIBLE'}, "
            f"smallest joint-space distance {self.min_distance:.4g}",
            f"{'criterion':<44} {'design':>12} {'random median':>14} {'random better':>14} "
            f"{'random poses to match':>22}",
        ]
        for c in CRITERIA:
            med = float(np.median(self.random_values[_key(c)]))
            lines.append(
                f"{LABELS[c]:<44} {value(c, self.values):>12.5g} {med:>14.5g} "
                f"{self.random_fraction_better(c):>13.1%} {self.equivalent_random_poses(c):>22.1f}"
            )
        lines.append(
            f"(random: {R} sets of {N} of the pool's poses in the region and view: random configurations within "
            f"the joint limits rarely reach it)"
            if self.details.get("random_from") == "pool"
            else f"(random: {R} sets of {N} poses within the joint limits, region and view if given)"
        )
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-ready summary (without the random samples)."""
        return {
            "method": self.method,
            "criterion": self.criterion,
            "n_poses": int(self.q.shape[0]),
            "values": dict(self.values),
            "random_median": {k: float(np.median(v)) for k, v in self.random_values.items()},
            "random_fraction_better": {c: self.random_fraction_better(c) for c in CRITERIA},
            "equivalent_random_poses": {c: self.equivalent_random_poses(c) for c in CRITERIA},
            "feasible": self.feasible,
            "min_distance": self.min_distance,
            "base_names": list(self.base_names),
            "details": self.details,
            "q": self.q.tolist(),
        }


def _key(c: str) -> str:
    return {"d": "log_det", "a": "a_trace", "validation": "validation_rms_mm"}[c]


def frozen(a) -> np.ndarray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.flags.writeable = False
    return a
