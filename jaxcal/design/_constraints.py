"""What users need around a design: a minimum spread between configurations, a box the tool must
stay in, random feasible configurations (starts, and the comparison with random poses)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import as_f64
from ..errors import DataError
from ._problem import DesignProblem, measures_batch, tool_positions, uniform_poses, values_of

SAMPLE_CAP = 200_000
"""Most random configurations drawn to find ones that keep the tool in the region."""


class Constraints(eqx.Module):
    """Minimum spread and region, as arrays (0 / off when not given)."""

    spread: Float[Array, ""]
    """Smallest joint-space distance between two configurations (0: none)."""
    box_lower: Float[Array, " 3"]
    box_upper: Float[Array, " 3"]
    box_on: Float[Array, ""]

    @property
    def has_box(self) -> bool:
        return bool(np.asarray(self.box_on) > 0)


def constraints(min_spread: float = 0.0, region=None) -> Constraints:
    """Checked constraints: ``min_spread`` (joint-space Euclidean distance, rad / mm) and
    ``region`` ``(lower (3,), upper (3,))``, a box (mm) in the frame of the forward kinematics
    (the robot's base transform applied) that every measured point must stay in."""
    if isinstance(min_spread, bool) or not isinstance(min_spread, (int, float, np.integer, np.floating)):
        raise DataError(f"min_spread must be a number >= 0, got {min_spread!r}", option="min_spread")
    if not (np.isfinite(min_spread) and min_spread >= 0):
        raise DataError(f"min_spread must be a finite number >= 0, got {min_spread!r}", option="min_spread")
    lo, hi, on = np.zeros(3), np.ones(3), 0.0
    if region is not None:
        try:
            lo, hi = (np.asarray(as_f64(b, "region"), dtype=np.float64).reshape(3) for b in region)
        except (TypeError, ValueError):
            raise DataError(
                "region must be a pair (lower xyz, upper xyz) of 3 numbers each (mm)", option="region"
            ) from None
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise DataError("region: bounds must be finite", option="region")
        bad = np.flatnonzero(lo >= hi)
        if bad.size:
            axis = "xyz"[bad[0]]
            raise DataError(
                f"region: lower {axis} {lo[bad[0]]:g} is not below upper {axis} {hi[bad[0]]:g}", option="region"
            )
        on = 1.0
    return Constraints(jnp.float64(min_spread), jnp.asarray(lo), jnp.asarray(hi), jnp.float64(on))


@eqx.filter_jit
def positions(problem: DesignProblem, q):
    return tool_positions(problem.model, problem.layout, q)


def in_box(cons: Constraints, p, margin: float = 0.0) -> np.ndarray:
    """Whether every point ``p (..., P, 3)`` lies in the box shrunk by ``margin`` of its size."""
    lo, hi = np.asarray(cons.box_lower), np.asarray(cons.box_upper)
    m = margin * (hi - lo)
    return np.all((p >= lo + m) & (p <= hi - m), axis=(-2, -1))


def min_distance(q) -> float:
    """Smallest Euclidean distance between two rows of ``q (K, n)`` (inf for one row)."""
    q = np.asarray(q)
    if len(q) < 2:
        return float("inf")
    d = np.sqrt(np.sum((q[:, None] - q[None]) ** 2, -1))
    return float(d[np.triu_indices(len(q), 1)].min())


def feasible(problem: DesignProblem, cons: Constraints, q) -> bool:
    """Limits, spread and region hold for the configurations ``q (K, n)``."""
    q = np.asarray(q)
    ok = bool(np.all(q >= np.asarray(problem.lower)) and np.all(q <= np.asarray(problem.upper)))
    ok &= min_distance(q) >= float(cons.spread) * (1 - 1e-9)
    if cons.has_box:
        ok &= bool(np.all(in_box(cons, np.asarray(positions(problem, jnp.asarray(q))))))
    return ok


def random_feasible(problem: DesignProblem, cons: Constraints, shape: tuple[int, int], rng) -> np.ndarray:
    """``shape = (R, K)`` random configurations uniform within the joint limits and, with a
    region, keeping the tool in it (drawn without replacement while enough are found)."""
    R, K = shape
    lim = np.stack([np.asarray(problem.lower), np.asarray(problem.upper)], 1)

    def draw(n):
        return lim[:, 0] + rng.uniform(size=(n, len(lim))) * (lim[:, 1] - lim[:, 0])

    if not cons.has_box:
        return draw(R * K).reshape(R, K, -1)
    want, found, tried = R * K, [], 0
    while sum(len(f) for f in found) < want and tried < SAMPLE_CAP:
        n = min(max(4 * want, 1024), SAMPLE_CAP - tried)
        qs = draw(n)
        found.append(qs[in_box(cons, np.asarray(positions(problem, jnp.asarray(qs))), margin=0.01)])
        tried += n
    pool = np.concatenate(found)
    if len(pool) < K:
        raise DataError(
            f"region: only {len(pool)} of {tried} random configurations within the joint limits keep the "
            f"tool in the box, fewer than the {K} poses asked for; check the box (mm, robot base frame)",
            option="region",
        )
    idx = rng.choice(len(pool), size=want, replace=len(pool) < want)
    return pool[idx].reshape(R, K, -1)


def random_values(problem: DesignProblem, cons: Constraints, n_poses: int, n_random: int, rng) -> dict:
    """All three criteria of ``n_random`` random feasible pose sets of ``n_poses``, ``(R,)`` each."""
    q = random_feasible(problem, cons, (n_random, n_poses), rng)
    m = np.asarray(measures_batch(problem, jnp.asarray(q)))
    out = {k: np.array([values_of(r)[k] for r in m]) for k in ("log_det", "a_trace", "validation_rms_mm")}
    for v in out.values():
        v.flags.writeable = False
    return out


__all__ = [
    "Constraints",
    "constraints",
    "feasible",
    "min_distance",
    "random_feasible",
    "random_values",
    "uniform_poses",
]
