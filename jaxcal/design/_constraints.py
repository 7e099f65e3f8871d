"""What users need around a design: a minimum spread between configurations, a box the tool must
stay in, a camera's view cone it must stay in, random feasible configurations (starts, and the
comparison with random poses)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import as_f64
from ..errors import DataError
from ._problem import DesignProblem, measures_batch, tool_positions, uniform_poses, values_of

SAMPLE_CAP = 200_000
"""Most random configurations drawn to find ones that keep the tool in the region."""


class Constraints(eqx.Module):
    """Minimum spread, box and view cone, as arrays (0 / off when not given)."""

    spread: Float[Array, ""]
    """Smallest joint-space distance between two configurations (0: none)."""
    box_lower: Float[Array, " 3"]
    box_upper: Float[Array, " 3"]
    box_on: Float[Array, ""]
    view_origin: Float[Array, " 3"]
    """The camera's position (mm, frame of the forward kinematics)."""
    view_axis: Float[Array, " 3"]
    """Its viewing direction (unit)."""
    view_half_angle: Float[Array, ""]
    """Half-angle of the cone (rad) around the axis that the points must stay in."""
    view_near: Float[Array, ""]
    view_far: Float[Array, ""]
    """Range of the distance along the axis (mm); far is finite (the largest float when not given)."""
    view_on: Float[Array, ""]

    @property
    def has_box(self) -> bool:
        return bool(np.asarray(self.box_on) > 0)

    @property
    def has_view(self) -> bool:
        return bool(np.asarray(self.view_on) > 0)

    @property
    def has_region(self) -> bool:
        return self.has_box or self.has_view


def constraints(min_spread: float = 0.0, region=None, view=None) -> Constraints:
    """Checked constraints: ``min_spread`` (joint-space Euclidean distance, rad / mm);
    ``region`` ``(lower (3,), upper (3,))``, a box (mm) in the frame of the forward kinematics
    (the robot's base transform applied) that every measured point must stay in; ``view``
    ``(origin (3,), axis (3,), half_angle)`` or ``(origin, axis, half_angle, near, far)``, a
    camera's view cone in the same frame (mm, rad) that every measured point must stay in."""
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
    origin, axis, half, near, far, view_on = _view(view)
    return Constraints(
        jnp.float64(min_spread),
        jnp.asarray(lo),
        jnp.asarray(hi),
        jnp.float64(on),
        jnp.asarray(origin),
        jnp.asarray(axis),
        jnp.float64(half),
        jnp.float64(near),
        jnp.float64(far),
        jnp.float64(view_on),
    )


def _view(view):
    """``(origin, unit axis, half_angle, near, far, on)`` of a checked view cone."""
    if view is None:
        return np.zeros(3), np.array([0.0, 0.0, 1.0]), 1.0, 0.0, 1.0, 0.0
    usage = "view must be (origin xyz, axis xyz, half_angle) or (origin, axis, half_angle, near, far): mm and rad"
    try:
        origin, axis = (np.asarray(as_f64(v, "view"), dtype=np.float64).reshape(3) for v in view[:2])
        rest = [float(v) for v in view[2:]]
    except (TypeError, ValueError):
        raise DataError(usage, option="view") from None
    if len(rest) not in (1, 3):
        raise DataError(usage, option="view")
    half, near, far = rest[0], *(rest[1:] or [0.0, np.finfo(np.float64).max])
    if not (np.all(np.isfinite(origin)) and np.all(np.isfinite(axis)) and np.isfinite(half)):
        raise DataError("view: values must be finite", option="view")
    if np.linalg.norm(axis) == 0:
        raise DataError("view: the axis must not be zero", option="view")
    if not 0 < half < np.pi / 2:
        got = f"{np.degrees(half):g} deg"
        raise DataError(f"view: the half-angle must be between 0 and 90 deg, got {got}", option="view")
    if not (np.isfinite(near) and near >= 0 and far > near):
        raise DataError(f"view: need 0 <= near < far, got near {near:g}, far {far:g} (mm)", option="view")
    return origin, axis / np.linalg.norm(axis), half, near, far, 1.0


def view_coordinates(cons: Constraints, p):
    """Distance along the view axis and angle from it (rad) of points ``p (..., 3)``."""
    xp = np if isinstance(p, np.ndarray) else jnp
    v = p - cons.view_origin
    along = v @ cons.view_axis
    radial = xp.sqrt(xp.sum((v - along[..., None] * cons.view_axis) ** 2, -1) + 1e-12)
    return along, xp.arctan2(radial, along)


@eqx.filter_jit
def positions(problem: DesignProblem, q):
    return tool_positions(problem.model, problem.layout, q)


def in_region(cons: Constraints, p, margin: float = 0.0) -> np.ndarray:
    """Whether every point ``p (..., P, 3)`` lies in the box and the view cone, each shrunk by
    ``margin`` of its size (the box's sides; the cone's half-angle and range)."""
    p = np.asarray(p)
    ok = np.ones(p.shape[:-2], bool)
    if cons.has_box:
        lo, hi = np.asarray(cons.box_lower), np.asarray(cons.box_upper)
        m = margin * (hi - lo)
        ok &= np.all((p >= lo + m) & (p <= hi - m), axis=(-2, -1))
    if cons.has_view:
        c = jax.tree_util.tree_map(np.asarray, cons)
        along, angle = view_coordinates(c, p)
        near, far = float(c.view_near), float(c.view_far)
        m = margin * (far - near) if far < np.finfo(np.float64).max else 0.0  # no far given: no range margin
        inside = (angle <= (1 - margin) * float(c.view_half_angle)) & (along >= near + m) & (along <= far - m)
        ok &= np.all(inside, axis=-1)
    return ok


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
    if cons.has_region:
        ok &= bool(np.all(in_region(cons, np.asarray(positions(problem, jnp.asarray(q))))))
    return ok


def random_feasible(problem: DesignProblem, cons: Constraints, shape: tuple[int, int], rng) -> np.ndarray:
    """``shape = (R, K)`` random configurations uniform within the joint limits and, with a
    region, keeping the tool in it (drawn without replacement while enough are found)."""
    R, K = shape
    lim = np.stack([np.asarray(problem.lower), np.asarray(problem.upper)], 1)

    def draw(n):
        return lim[:, 0] + rng.uniform(size=(n, len(lim))) * (lim[:, 1] - lim[:, 0])

    if not cons.has_region:
        return draw(R * K).reshape(R, K, -1)
    want, found, tried = R * K, [], 0
    while sum(len(f) for f in found) < want and tried < SAMPLE_CAP:
        n = min(max(4 * want, 1024), SAMPLE_CAP - tried)
        qs = draw(n)
        found.append(qs[in_region(cons, np.asarray(positions(problem, jnp.asarray(qs))), margin=0.01)])
        tried += n
    pool = np.concatenate(found)
    if len(pool) < K:
        option = "region" if cons.has_box else "view"
        shape = " and the ".join(n for n, on in (("box", cons.has_box), ("view cone", cons.has_view)) if on)
        raise DataError(
            f"{option}: only {len(pool)} of {tried} random configurations within the joint limits keep the "
            f"tool in the {shape}, fewer than the {K} poses asked for; check it (mm, robot base frame)",
            option=option,
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
    "in_region",
    "min_distance",
    "random_feasible",
    "random_values",
    "uniform_poses",
]
