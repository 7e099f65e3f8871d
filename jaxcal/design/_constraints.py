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
from ..model import Layout, Model
from ..robot import Robot
from ._problem import (
    DesignProblem,
    measures_batch,
    measures_of_information,
    pose_blocks,
    reference,
    tool_positions,
    uniform_poses,
    values_of,
)


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
    v = p - cons.view_origin
    along = v @ cons.view_axis
    radial = jnp.sqrt(jnp.sum((v - along[..., None] * cons.view_axis) ** 2, -1) + 1e-12)
    return along, jnp.arctan2(radial, along)


class Workspace(eqx.Module):
    """What the constraints are checked on: a nominal model, whose measured points (the tool
    origin for poses) must stay in the region, and the joint limits. A :class:`DesignProblem`
    has the same fields and serves as well."""

    model: Model
    lower: Float[Array, " n"]
    upper: Float[Array, " n"]
    layout: Layout = eqx.field(static=True)


def workspace(robot: Robot, n_points: int = 0, points=None) -> Workspace:
    """The workspace of ``robot`` measured at ``n_points`` points (``points (M, 3)`` on the tool,
    mm; default: at the tool origin), or at the tool's pose (0)."""
    layout = Layout.of(robot, n_points=n_points)
    model = Model(robot.stripped(), None if n_points == 0 else np.zeros((n_points, 3)) if points is None else points)
    lim = np.asarray(robot.q_limits, dtype=np.float64)
    return Workspace(model, jnp.asarray(lim[:, 0]), jnp.asarray(lim[:, 1]), layout)


def positions(space: Workspace | DesignProblem, q) -> np.ndarray:
    """Positions ``(K, P, 3)`` of the measured points at the poses ``q (K, n)`` (the design's one
    compiled Jacobian program, :func:`reference`)."""
    return reference(space.model, space.layout, q)[1]


@eqx.filter_jit
def _inside(cons: Constraints, p, margin):
    """:func:`in_region`, traceable."""
    m = margin * (cons.box_upper - cons.box_lower)
    box = jnp.all((p >= cons.box_lower + m) & (p <= cons.box_upper - m), axis=(-2, -1))
    along, angle = view_coordinates(cons, p)
    far_given = cons.view_far < np.finfo(np.float64).max
    m = jnp.where(far_given, margin * (cons.view_far - cons.view_near), 0.0)  # no far given: no range margin
    cone = (angle <= (1 - margin) * cons.view_half_angle) & (along >= cons.view_near + m) & (along <= cons.view_far - m)
    return (box | (cons.box_on == 0)) & (jnp.all(cone, axis=-1) | (cons.view_on == 0))


def in_region(cons: Constraints, p, margin: float = 0.0) -> np.ndarray:
    """Whether every point ``p (..., P, 3)`` lies in the box and the view cone, each shrunk by
    ``margin`` of its size (the box's sides; the cone's half-angle and range)."""
    return np.asarray(_inside(cons, jnp.asarray(p, jnp.float64), jnp.float64(margin)))


def min_distance(q) -> float:
    """Smallest Euclidean distance between two rows of ``q (K, n)`` (inf for one row)."""
    q = np.asarray(q)
    if len(q) < 2:
        return float("inf")
    d = np.sqrt(np.sum((q[:, None] - q[None]) ** 2, -1))
    return float(d[np.triu_indices(len(q), 1)].min())


def feasible(space: Workspace | DesignProblem, cons: Constraints, q) -> bool:
    """Limits, spread and region hold for the configurations ``q (K, n)``."""
    q = np.asarray(q)
    ok = bool(np.all(q >= np.asarray(space.lower)) and np.all(q <= np.asarray(space.upper)))
    ok &= min_distance(q) >= float(cons.spread) * (1 - 1e-9)
    if cons.has_region:
        ok &= bool(np.all(in_region(cons, positions(space, q))))
    return ok


SAMPLE_CAP = 200_000
"""Most random configurations drawn for one pose set (and to estimate how many keep the tool in
the region)."""
SAMPLE_MARGIN = 0.01
"""Random configurations keep the measured points this fraction of the region's size inside it."""
RETRIES = 8
"""A set still short after this many times the candidates expected to fill it fails."""
_PILOT = 4096
_BLOCK = 2**17
"""Candidates per compiled call of the sampler (sets x candidates per set)."""


@eqx.filter_jit
def _accepted(space, cons: Constraints, key, *, n: int):
    """How many of ``n`` configurations uniform within the limits keep the points in the region."""
    q = space.lower + jax.random.uniform(key, (n, space.lower.shape[0])) * (space.upper - space.lower)
    return jnp.sum(_inside(cons, tool_positions(space.model, space.layout, q), SAMPLE_MARGIN))


@eqx.filter_jit
def _draw_sets(space, cons: Constraints, key, idx, *, n_poses: int, n_candidates: int, spread: bool):
    """Set ``i`` of ``idx``: the first ``n_poses`` of ``n_candidates`` configurations uniform
    within the limits (from ``fold_in(key, i)``) that keep the points in the region and, with
    ``spread``, lie at least the minimum spread from every one taken before. Returns the sets
    ``(R, n_poses, n)`` (inf where too few were found) and how many were found ``(R,)``."""
    n = space.lower.shape[0]

    def one(i):
        u = jax.random.uniform(jax.random.fold_in(key, i), (n_candidates, n))
        cand = space.lower + u * (space.upper - space.lower)
        ok = _inside(cons, tool_positions(space.model, space.layout, cand), SAMPLE_MARGIN)
        if not spread:
            order = jnp.argsort(~ok, stable=True)[:n_poses]  # the accepted ones, in drawing order
            found = jnp.minimum(jnp.sum(ok), n_poses)
            return jnp.where((jnp.arange(n_poses) < found)[:, None], cand[order], jnp.inf), found

        def take(state, c):  # sequential: a candidate too close to one taken is skipped
            chosen, count = state
            far = jnp.all(jnp.sum((chosen - c[0]) ** 2, -1) >= cons.spread**2)
            new = c[1] & far & (count < n_poses)
            chosen = chosen.at[jnp.minimum(count, n_poses - 1)].set(
                jnp.where(new, c[0], chosen[jnp.minimum(count, n_poses - 1)])
            )
            return (chosen, count + new), None

        (chosen, found), _ = jax.lax.scan(take, (jnp.full((n_poses, n), jnp.inf), 0), (cand, ok))
        return chosen, found

    return jax.vmap(one)(idx)


class PoseSampler:
    """Random pose sets under the design's conditions: configurations uniform within the joint
    limits, conditioned on the measured points staying in the region and the view (a margin of
    :data:`SAMPLE_MARGIN` inside) and, with a minimum spread, on every two of a set lying that far
    apart (taken in drawing order). Set ``i`` depends on the key and ``i`` alone, so a Monte Carlo
    study's robots do not depend on its chunking.

    ``space``: :func:`workspace` (or a design problem); ``cons``: :func:`constraints`; ``key`` a
    JAX key. Raises :class:`jaxcal.DataError` (naming ``region`` or ``view``) when too few random
    configurations satisfy the region.
    """

    def __init__(self, space, cons: Constraints, n_poses: int, key):
        self.space, self.cons, self.n_poses = space, cons, int(n_poses)
        k_pilot, self.key = jax.random.split(key)
        found, tried = 0, 0
        if cons.has_region:  # the acceptance rate sizes the candidates per set
            while tried < SAMPLE_CAP and found < 64:
                found += int(_accepted(space, cons, jax.random.fold_in(k_pilot, tried), n=_PILOT))
                tried += _PILOT
        self.acceptance = found / tried if cons.has_region else 1.0
        if cons.has_region and (found == 0 or self.n_poses / self.acceptance > SAMPLE_CAP):
            option = "region" if cons.has_box else "view"
            shape = " and the ".join(n for n, on in (("box", cons.has_box), ("view cone", cons.has_view)) if on)
            raise DataError(
                f"{option}: only {found} of {tried} random configurations within the joint limits keep the "
                f"tool in the {shape}, too few to draw {self.n_poses} poses there; give candidate poses inside it "
                f"(--pool; select_poses), or check it (mm, in the frame the robot's base is given in)",
                option=option,
            )
        need = (self.n_poses + 4 * np.sqrt(self.n_poses) + 8) / self.acceptance
        self.n_candidates = int(2 ** np.ceil(np.log2(max(need * (1.5 if float(cons.spread) > 0 else 1.0), 64))))

    def sets(self, idx) -> np.ndarray:
        """The pose sets ``idx`` as ``(len(idx), n_poses, n)`` joint values (rad, mm)."""
        idx = np.asarray(idx, dtype=np.int64).reshape(-1)
        out = np.full((len(idx), self.n_poses, self.space.lower.shape[0]), np.inf)
        todo, m, attempt = np.arange(len(idx)), self.n_candidates, 0
        while todo.size:
            if m > RETRIES * self.n_candidates:  # the spread, not chance: more candidates will not do
                raise DataError(
                    f"min_spread: fewer than {self.n_poses} random configurations {float(self.cons.spread):g} apart "
                    f"among {m // 2} (in the region where given); lower min_spread or the pose count",
                    option="min_spread",
                )
            block = min(max(1, _BLOCK // m), 2 ** int(np.ceil(np.log2(len(todo)))))  # few shapes, little waste
            key = jax.random.fold_in(self.key, attempt)
            padded = np.concatenate([todo, np.repeat(todo[-1:], -len(todo) % block)])
            for s in range(0, len(padded), block):
                rows = padded[s : s + block]
                q, found = _draw_sets(
                    self.space,
                    self.cons,
                    key,
                    jnp.asarray(idx[rows]),
                    n_poses=self.n_poses,
                    n_candidates=m,
                    spread=float(self.cons.spread) > 0,
                )
                ok = np.asarray(found) == self.n_poses
                out[rows[ok]] = np.asarray(q)[ok]
            todo = todo[~np.all(np.isfinite(out[todo]), axis=(1, 2))]
            m, attempt = 2 * m, attempt + 1
        return out


def random_poses(
    robot: Robot,
    n_poses: int,
    *,
    n_sets: int | None = None,
    n_points: int = 0,
    points=None,
    min_spread: float = 0.0,
    region=None,
    view=None,
    seed: int = 0,
) -> np.ndarray:
    """Random configurations of ``robot`` under a design's conditions (:class:`PoseSampler`):
    ``(n_poses, n)``, or ``(n_sets, n_poses, n)`` sets drawn apart. ``n_points``/``points``: what
    must stay in the ``region``/``view`` (0: the tool origin); the rest as for
    :func:`jaxcal.design.optimal_poses`. E.g. validation poses where a camera sees the tool."""
    for name, v, lo in (("n_poses", n_poses, 1), ("n_sets", 1 if n_sets is None else n_sets, 1), ("seed", seed, 0)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise DataError(f"{name} must be an integer >= {lo}, got {v!r}", option=name)
    space = workspace(robot, n_points, points)
    sampler = PoseSampler(space, constraints(min_spread, region, view), n_poses, jax.random.PRNGKey(seed))
    q = sampler.sets(np.arange(1 if n_sets is None else n_sets))
    return q[0] if n_sets is None else q


def random_feasible(space, cons: Constraints, shape: tuple[int, int], rng) -> np.ndarray:
    """``shape = (R, K)`` random configurations within the joint limits: uniform without
    constraints, else from a :class:`PoseSampler` seeded by ``rng``."""
    R, K = shape
    lim = np.stack([np.asarray(space.lower), np.asarray(space.upper)], 1)
    if not cons.has_region and float(cons.spread) == 0:
        return (lim[:, 0] + rng.uniform(size=(R * K, len(lim))) * (lim[:, 1] - lim[:, 0])).reshape(R, K, -1)
    key = jax.random.PRNGKey(int(rng.integers(2**31)))
    return PoseSampler(space, cons, K, key).sets(np.arange(R))


def random_values(problem: DesignProblem, cons: Constraints, n_poses: int, n_random: int, rng) -> dict:
    """All three criteria of ``n_random`` random feasible pose sets of ``n_poses``, ``(R,)`` each."""
    return criteria_of_sets(problem, random_feasible(problem, cons, (n_random, n_poses), rng))


MATCH_COUNTS = 2.0 ** (np.arange(-2, 7) / 2)
"""Pose counts, as multiples of a design's, of the random sets that say how many random poses
match it (:meth:`PoseDesign.equivalent_random_poses`): from half to eight times."""
MATCH_SETS = 50
"""Random sets at those counts (nested: each count's set holds the smaller ones')."""
MATCH_POOL = 4
"""The random configurations they are taken from, as a multiple of the largest count."""


def match_counts(problem: DesignProblem, n_poses: int) -> np.ndarray:
    """The counts of :data:`MATCH_COUNTS` for a design of ``n_poses``, without those too few to
    identify the base parameters."""
    ks = np.unique(np.round(n_poses * MATCH_COUNTS).astype(int))
    return ks[ks * problem.layout.rows >= problem.n_base]


def criteria_by_count(problem: DesignProblem, rows, counts, rng) -> dict:
    """The median of each criterion over :data:`MATCH_SETS` random sets of the configurations
    ``rows (P, n)`` at each count of ``counts`` (increasing, at most ``P``), each set the first
    ``k`` of a random order of the rows: ``{"counts": (C,), name: (C,)}``. A set's information is
    the sum of its poses', so one Jacobian per row serves every set and count."""
    counts = [int(k) for k in counts]
    L = pose_blocks(problem, np.asarray(rows))
    A = np.einsum("prb,prc->pbc", L, L)
    order = np.stack([rng.permutation(len(A))[: counts[-1]] for _ in range(MATCH_SETS)])
    M = np.broadcast_to(np.diag(np.asarray(problem.prior)), (MATCH_SETS,) + A.shape[1:]).copy()
    medians, done = [], 0
    for k in counts:
        M += A[order[:, done:k]].sum(axis=1)
        done = k
        m = [values_of(r) for r in measures_of_information(problem, M)]
        medians.append({name: float(np.median([v[name] for v in m])) for name in m[0]})
    return {"counts": counts} | {name: [r[name] for r in medians] for name in medians[0]}


def random_by_count(problem: DesignProblem, cons: Constraints, n_poses: int, rng) -> dict:
    """:func:`criteria_by_count` at the :func:`match_counts` of ``n_poses``, over random
    configurations drawn as the comparison's sets of ``n_poses`` are (:func:`random_feasible`;
    a minimum spread holds within each drawn set, not among the rows taken from several)."""
    counts = match_counts(problem, n_poses)
    n_sets = -(-MATCH_POOL * int(counts[-1]) // n_poses)
    rows = random_feasible(problem, cons, (n_sets, n_poses), rng).reshape(n_sets * n_poses, -1)
    return criteria_by_count(problem, rows, counts, rng)


def criteria_of_sets(problem: DesignProblem, q) -> dict:
    """All three criteria of the pose sets ``q (R, K, n)``, ``(R,)`` each (read-only)."""
    m = measures_batch(problem, q)
    out = {k: np.array([values_of(r)[k] for r in m]) for k in ("log_det", "a_trace", "validation_rms_mm")}
    for v in out.values():
        v.flags.writeable = False
    return out


__all__ = [
    "Constraints",
    "PoseSampler",
    "Workspace",
    "workspace",
    "constraints",
    "criteria_by_count",
    "criteria_of_sets",
    "feasible",
    "in_region",
    "min_distance",
    "match_counts",
    "random_by_count",
    "random_feasible",
    "random_poses",
    "random_values",
    "uniform_poses",
]
