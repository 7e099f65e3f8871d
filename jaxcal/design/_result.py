"""A pose design and its comparison with random poses of the same count."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ._problem import CRITERIA, value

STARTS_AGREE = 1e-3
"""Optimiser starts none of which met its tolerance, but whose criterion (each feasible start's;
per parameter for D) ends within this relative spread, have found one flat optimum: said as a
note, not a warning."""

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
    random_by_count: dict = dataclasses.field(default_factory=dict)
    """Median criteria of random pose sets of other counts (``"counts"`` and one list per
    criterion), drawn under the same conditions: how many random poses match the design."""

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
        """How many random poses, drawn under the design's conditions, would match the design
        on ``criterion`` (default its own): the median random set's value interpolated against
        the pose count (log-log; :func:`matching_count`) over :attr:`random_by_count`, with the
        comparison's own median at the design's count. NaN without those sets."""
        c = criterion or self.criterion
        key, N = _key(c), self.q.shape[0]
        counts = list(self.random_by_count.get("counts", []))
        if not counts:
            return float("nan")
        med = list(self.random_by_count[key])
        if N in counts:
            med[counts.index(N)] = float(np.median(self.random_values[key]))
        sign = 1.0 if c == "d" else -1.0  # larger is better in what is interpolated
        y = [sign * (m if c == "d" else np.log(m)) for m in med]
        v = value(c, self.values)
        return matching_count(counts, y, sign * (v if c == "d" else np.log(v)))

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
        largest = max(self.random_by_count.get("counts", [N]))
        for c in CRITERIA:
            med = float(np.median(self.random_values[_key(c)]))
            n = self.equivalent_random_poses(c)
            # beyond the largest count drawn the figure is extrapolated: only its bound is shown
            match = f"> {largest}" if n > largest else f"{n:.1f}" if np.isfinite(n) else "-"
            lines.append(
                f"{LABELS[c]:<44} {value(c, self.values):>12.5g} {med:>14.5g} "
                f"{self.random_fraction_better(c):>13.1%} {match:>22}"
            )
        lines.append(
            f"(random: {R} sets of {N} of the pool's poses in the region and view: random configurations within "
            f"the joint limits rarely reach it)"
            if self.details.get("random_from") == "pool"
            else f"(random: {R} sets of {N} poses within the joint limits, region and view if given)"
        )
        if self.details.get("converged_starts") == 0:  # a solver that stopped short says so
            lines.append(self._stopped_short())
        return "\n".join(lines)

    def _stopped_short(self) -> str:
        """What a design none of whose optimiser starts met its tolerance says: a warning, or a
        note where the feasible starts' criteria ended together (:data:`STARTS_AGREE`)."""
        d = self.details
        said = (
            f"none of the {d['starts']} optimiser starts converged (the most evaluations one used: "
            f"{d['max_evaluations']})"
        )
        ok = [v for v, f in zip(d.get("start_losses", []), d.get("start_feasible", [])) if f and np.isfinite(v)]
        if len(ok) < 2:
            return f"warning: {said}: the poses are the best point reached, not an optimum"
        # the losses (:func:`._problem.loss_of`): -log det / b (D: its per-parameter ratio, the
        # D-efficiency), log of the A trace, log of the squared validation RMS
        what, spread = {
            "d": ("D-efficiency (det ** (1 / parameters))", math.expm1(max(ok) - min(ok))),
            "a": ("A criterion", math.expm1(max(ok) - min(ok))),
            "validation": ("expected validation RMS", math.expm1((max(ok) - min(ok)) / 2)),
        }[self.criterion]
        if spread <= STARTS_AGREE:
            return (
                f"note: {said}, but the {len(ok)} starts ended within {spread:.2%} of one another in the {what}: a "
                f"flat optimum, which more evaluations would barely improve"
            )
        return (
            f"warning: {said}, and the {len(ok)} starts ended {spread:.1%} apart in the {what}: the poses are the "
            f"best point reached, not an optimum (more --starts may find a better one)"
        )

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
            "random_median_by_count": self.random_by_count,
            "feasible": self.feasible,
            "min_distance": self.min_distance,
            "base_names": list(self.base_names),
            "details": self.details,
            "q": self.q.tolist(),
        }


def matching_count(counts, y, target: float) -> float:
    """The count at which ``y``, a figure growing with the pose count (such as minus the log of
    an RMS), reaches ``target``: interpolated linearly in ``log count`` between the first two
    counts that bracket it, extrapolated from the end segments beyond them. Counts with a
    non-finite figure (sets too small to identify the parameters) are left out; NaN when fewer
    than two remain. ``y`` is taken as its running maximum (more poses never lose information;
    a dip is sampling noise), so a target beyond a flat tail is never reached: inf."""
    k, y = np.log(np.asarray(counts, dtype=np.float64)), np.asarray(y, dtype=np.float64)
    keep = np.isfinite(y)
    k, y = k[keep], np.maximum.accumulate(y[keep]) if keep.any() else y[keep]
    if len(k) < 2 or not np.isfinite(target):
        return float("nan")
    above = np.flatnonzero(y[1:] >= target)
    i = int(above[0]) if len(above) else len(k) - 2
    if y[i + 1] == y[i]:  # flat: reached at the segment's start, or (past the end) never
        return float(np.exp(k[i])) if y[i] >= target else float("inf")
    return float(np.exp(k[i] + (target - y[i]) / (y[i + 1] - y[i]) * (k[i + 1] - k[i])))


def _key(c: str) -> str:
    return {"d": "log_det", "a": "a_trace", "validation": "validation_rms_mm"}[c]


def frozen(a) -> np.ndarray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.flags.writeable = False
    return a
