r"""The best ``N`` poses of a candidate pool (poses a user knows are reachable and collision-free):
a greedy start, then Fedorov exchanges on the same criteria as the gradient design.

Each pool pose ``j`` contributes ``A_j = L_j^T L_j`` to the information (``L_j``: its weighted,
scaled base-set rows, :func:`jaxcal.design.information`). The greedy start adds, one at a time,
the pose that raises ``log det`` most (of the information plus a small ridge, so that the first
picks are defined). An exchange then replaces a chosen pose ``i`` by a pool pose ``j`` when the
criterion improves, the best pair of all first, until none improves. Every pair is scored
without refactoring: with ``M_i = M - A_i`` and ``K = I + L_j M_i^{-1} L_j^T`` (rows x rows),

* ``log det(M_i + A_j) = log det M_i + log det K``;
* ``tr(F (M_i + A_j)^{-1} F^T) = tr(F M_i^{-1} F^T) - tr(K^{-1} Z^T Z)``, ``Z = F M_i^{-1} L_j^T``
  (Sherman–Morrison–Woodbury), with ``F = I`` (A) or the validation factor.

When ``M_i`` is singular or nearly so (the fewest poses that identify the parameters, less
one: :data:`SINGULAR`), each swapped set is factorised anew instead.
"""

from __future__ import annotations

import time
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .._config import as_f64
from ..errors import DataError
from ._constraints import (
    constraints,
    criteria_by_count,
    criteria_of_sets,
    feasible,
    in_region,
    match_counts,
    min_distance,
    positions,
    random_by_count,
    random_values,
)
from ._problem import DesignProblem, count, information, measures_batch, pose_blocks, values_of
from ._result import PoseDesign, frozen

RIDGE = 1e-6
"""Ridge of the greedy start, relative to the mean information of one pool pose."""
SINGULAR = 1e-8
"""A chosen set less one pose whose squared Cholesky pivots span more than ``1 / SINGULAR`` is
singular for the Woodbury scores, which go through its inverse: they would be finite but wrong
(a rank one short factorises on a rounding-level pivot)."""
IMPROVEMENT = 1e-10
"""Smallest improvement of the loss an exchange must bring."""


def _loss_terms(problem: DesignProblem, logdet, tr_a, tr_v):
    b = problem.n_base
    terms = jnp.stack([-logdet / b, jnp.log(tr_a), jnp.log(tr_v)], -1)
    return jnp.sum(jnp.where(problem.weights > 0, terms, 0.0), -1)


def _swap_losses(problem: DesignProblem, Mi_base, L: Float[Array, "P r b"], C=None):
    """Loss of ``Mi_base + A_j`` for every pool pose ``j`` (Woodbury, module docstring); ``C``
    the Cholesky factor of ``Mi_base`` when the caller has it."""
    C = jnp.linalg.cholesky(Mi_base) if C is None else C
    Ci = jax.scipy.linalg.solve_triangular(C, jnp.eye(C.shape[0]), lower=True)
    Minv = Ci.T @ Ci
    F = problem.val_factor
    logdet = 2.0 * jnp.sum(jnp.log(jnp.diagonal(C)))
    tr_a, tr_v = jnp.sum(Ci**2), jnp.sum((Ci @ F.T) ** 2)
    ML = jnp.einsum("bc,prc->pbr", Minv, L)  # M_i^-1 L_j^T
    K = jnp.eye(L.shape[1]) + jnp.einsum("prb,pbs->prs", L, ML)
    Kc = jnp.linalg.cholesky(K)
    ld = logdet + 2.0 * jnp.sum(jnp.log(jnp.diagonal(Kc, axis1=-2, axis2=-1)), -1)

    def reduce(Z):  # tr(K^-1 Z^T Z) = |Kc^-1 Z^T|_F^2
        W = jax.scipy.linalg.solve_triangular(Kc, jnp.swapaxes(Z, -1, -2), lower=True)
        return jnp.sum(W**2, axis=(-2, -1))

    ta = tr_a - reduce(ML)
    tv = tr_v - reduce(jnp.einsum("cb,pbr->pcr", F, ML))
    out = _loss_terms(problem, ld, ta, tv)
    return jnp.where(jnp.isfinite(out), out, jnp.inf)


def _direct_losses(problem: DesignProblem, Mi_base, A: Float[Array, "P b b"]):
    """Loss of ``Mi_base + A_j`` for every pool pose ``j``, each factorised anew: for a set
    with one pose too few to identify the parameters, where ``Mi_base`` is singular and the
    Woodbury form (:func:`_swap_losses`) is undefined although the swapped sets are not."""

    def one(Aj):
        C = jnp.linalg.cholesky(Mi_base + Aj)
        Ci = jax.scipy.linalg.solve_triangular(C, jnp.eye(C.shape[0]), lower=True)
        ld = 2.0 * jnp.sum(jnp.log(jnp.diagonal(C)))
        return _loss_terms(problem, ld, jnp.sum(Ci**2), jnp.sum((Ci @ problem.val_factor.T) ** 2))

    out = jax.vmap(one)(A)
    return jnp.where(jnp.isfinite(out), out, jnp.inf)


def _close(pool: Float[Array, "P n"], chosen: Float[Array, "N n"], spread) -> Bool[Array, "P N"]:
    """Which pool poses lie closer than ``spread`` (joint space) to each of ``chosen``: formed per
    step, never as a ``(P, P)`` matrix, which a pool of tens of thousands would not fit."""
    return jnp.sum((pool[:, None] - chosen[None]) ** 2, -1) < spread**2


@eqx.filter_jit
def _greedy(problem: DesignProblem, L, allowed: Bool[Array, " P"], pool: Float[Array, "P n"], spread, n: int):
    """``n`` pool indices by greedy ``log det`` (with a ridge): each step the allowed pose, not
    closer than ``spread`` to a chosen one, that raises it most. -1 where none was left."""
    A = jnp.einsum("prb,prc->pbc", L, L)
    ridge = RIDGE * jnp.trace(jnp.mean(A, 0)) / A.shape[-1]
    d_problem = eqx.tree_at(lambda p: p.weights, problem, jnp.array([1.0, 0.0, 0.0]))

    def step(k, state):
        chosen, M, ok = state
        s = _swap_losses(d_problem, M + ridge * jnp.eye(M.shape[0]), L)
        s = jnp.where(ok, s, jnp.inf)
        j = jnp.argmin(s)
        found = jnp.isfinite(s[j])
        chosen = chosen.at[k].set(jnp.where(found, j, -1))
        M = M + jnp.where(found, A[j], 0.0)
        ok = ok & ~_close(pool, pool[j][None], spread)[:, 0] & (jnp.arange(len(ok)) != j)
        return chosen, M, ok

    init = (jnp.full(n, -1), jnp.diag(problem.prior), allowed)
    return jax.lax.fori_loop(0, n, step, init)[0]


@eqx.filter_jit
def _exchange(problem: DesignProblem, L, chosen: Int[Array, " N"], allowed, pool, spread, max_swaps: int):
    """Fedorov exchange from ``chosen`` until no swap improves the loss (or ``max_swaps``)."""
    A = jnp.einsum("prb,prc->pbc", L, L)
    P = L.shape[0]

    def info(ch):
        return jnp.diag(problem.prior) + jnp.sum(A[ch], 0)

    def best_swap(ch):
        M = info(ch)
        in_set = jnp.zeros(P, bool).at[ch].set(True)
        close = _close(pool, pool[ch], spread)  # (P, N): each pool pose too close to a chosen one
        n_close = jnp.sum(close, 1)

        def slot(i):
            Mi = M - A[ch[i]]
            C = jnp.linalg.cholesky(Mi)
            s = _swap_losses(problem, Mi, L, C)
            d = jnp.diagonal(C)
            regular = jnp.all(jnp.isfinite(d)) & (jnp.min(d) ** 2 > SINGULAR * jnp.max(d) ** 2)
            s = jax.lax.cond(regular & jnp.any(jnp.isfinite(s)), lambda: s, lambda: _direct_losses(problem, Mi, A))
            ok = allowed & ~in_set & (n_close - close[:, i] == 0)
            return jnp.where(ok, s, jnp.inf)

        S = jax.lax.map(slot, jnp.arange(ch.shape[0]))  # (N, P)
        k = jnp.argmin(S)
        return S.reshape(-1)[k], k // P, k % P

    def current(ch):
        M = info(ch)
        return _direct_losses(problem, M - A[ch[0]], A[ch[0]][None])[0]

    def cond(state):
        ch, loss, swaps, done = state
        return ~done & (swaps < max_swaps)

    def body(state):
        ch, loss, swaps, _ = state
        new, i, j = best_swap(ch)
        better = new < loss - IMPROVEMENT * jnp.abs(loss)
        ch = jnp.where(better, ch.at[i].set(j), ch)
        return ch, jnp.where(better, new, loss), swaps + better, ~better

    out = jax.lax.while_loop(cond, body, (chosen, current(chosen), 0, False))
    return out[0], out[2]


def exchange(problem: DesignProblem, cons, pool: np.ndarray, n_poses: int, max_swaps: int, *, option: str = "pool"):
    """Pool rows of the best ``n_poses`` by greedy start and Fedorov exchange, among the pool
    poses in the region and view and never two closer than the spread: ``(indices, swaps, the
    pool poses in the region and view (P,))``. Raises :class:`jaxcal.DataError` when too few are usable (said of
    ``option``: the pool given, or the constraints a pool drawn for them could not meet)."""
    allowed = np.ones(len(pool), bool)
    if cons.has_region:
        allowed = in_region(cons, positions(problem, pool))
    L = jnp.asarray(pose_blocks(problem, pool))
    pool_, spread = jnp.asarray(pool), jnp.asarray(float(cons.spread))
    start = np.asarray(_greedy(problem, L, jnp.asarray(allowed), pool_, spread, n_poses))
    if np.any(start < 0):
        what = f"{len(pool)} random configurations in the region and view"
        what = f"the pool's {len(pool)} poses" if option == "pool" else what
        raise DataError(
            f"{option}: only {int(np.sum(start >= 0))} of {what} satisfy the region, the view and the minimum "
            f"spread together, fewer than the {n_poses} asked for",
            option=option,
        )
    chosen, swaps = _exchange(problem, L, jnp.asarray(start), jnp.asarray(allowed), pool_, spread, max_swaps)
    return np.asarray(chosen), int(swaps), allowed


def select_poses(
    problem: DesignProblem,
    pool,
    n_poses: int,
    *,
    min_spread: float = 0.0,
    region=None,
    view=None,
    max_swaps: int | None = None,
    seed: int = 0,
    n_random: int = 200,
) -> PoseDesign:
    """The best ``n_poses`` configurations of ``pool (P, n)`` for the problem's criterion.

    **Arguments**: ``pool`` joint values (rad, mm) within the robot's limits; ``min_spread``,
    ``region`` and ``view`` as for :func:`optimal_poses` (pool poses that leave them are never
    chosen);
    ``max_swaps`` the most exchanges (default ``10 n_poses``); ``seed`` and ``n_random`` the
    comparison with random pose sets (drawn uniformly within the limits, as for the gradient
    design, not from the pool).

    **Returns** a :class:`PoseDesign` whose ``details["indices"]`` are the chosen pool rows.

    **Raises** :class:`jaxcal.DataError` for a pool with bad values or values beyond the joint
    limits the robot gives (naming the row and joint; a joint given none, such as a UR preset's,
    turns as far as its values say), or too few usable candidates.
    """
    n_poses = count("n_poses", n_poses, 1)
    max_swaps = 10 * n_poses if max_swaps is None else count("max_swaps", max_swaps, 0)
    seed, n_random = count("seed", seed, 0), count("n_random", n_random, 1)
    pool = np.asarray(as_f64(pool, "pool"))
    n = problem.lower.shape[0]
    if pool.ndim != 2 or pool.shape[1] != n:
        raise DataError(f"pool must have shape (P, {n}), got {pool.shape}", option="pool")
    lo, hi = np.asarray(problem.lower), np.asarray(problem.upper)
    bounded = np.array(problem.bounded)  # a joint given no limits may turn further
    bad = ~np.isfinite(pool) | (bounded & ((pool < lo) | (pool > hi)))
    if bad.any():
        k, j = np.argwhere(bad)[0]
        raise DataError(
            f"pool: row {k}, joint {j + 1}: {pool[k, j]:.6g} is outside the joint limits [{lo[j]:.6g}, {hi[j]:.6g}]",
            option="pool",
        )
    if len(pool) < n_poses:
        raise DataError(f"pool has {len(pool)} poses, fewer than the {n_poses} asked for", option="pool")
    if problem.layout.rows * n_poses < problem.n_base:
        raise DataError(f"n_poses: {n_poses} poses cannot identify {problem.n_base} base parameters", option="n_poses")
    cons = constraints(min_spread, region, view)
    t0 = time.perf_counter()
    chosen, swaps, allowed = exchange(problem, cons, pool, n_poses, max_swaps)
    seconds = time.perf_counter() - t0
    q = pool[chosen]
    distinct = len(np.unique(q, axis=0))
    if distinct < n_poses:  # the pool's repeated rows: a repeat measures a posture again, no more
        warnings.warn(
            f"the pool has {len(np.unique(pool, axis=0))} distinct rows of {len(pool)}: the design repeats "
            f"{n_poses - distinct} of its {n_poses} poses (measuring a posture again averages its noise, and "
            "tells nothing of the arm elsewhere)",
            stacklevel=2,
        )
    values = values_of(measures_batch(problem, q[None])[0])
    if not np.isfinite(values["log_det"]):
        raise DataError(_unidentified(problem, pool[allowed], n_poses, len(pool)), option="pool")
    rng = np.random.default_rng([seed, 3])
    try:
        rand, drawn_from = random_values(problem, cons, n_poses, n_random, rng), "joint limits"
        by_count = random_by_count(problem, cons, n_poses, rng)
    except DataError:  # a region random configurations rarely reach, which the pool's rows do
        rand, by_count = _pool_random_values(problem, cons, pool, n_poses, n_random, rng)
        drawn_from = "pool"
    return PoseDesign(
        q=frozen(q),
        criterion=problem.criterion,
        values=values,
        random_values=rand,
        random_by_count=by_count,
        method="pool",
        base_names=problem.base_names(),
        feasible=feasible(problem, cons, q),
        min_distance=min_distance(q),
        details={
            "indices": [int(i) for i in chosen],
            "pool_size": int(len(pool)),
            "usable": int(allowed.sum()),
            "swaps": int(swaps),
            "select_seconds": seconds,
            "random_from": drawn_from,
        },
    )


def _unidentified(problem: DesignProblem, pool, n_poses: int, n_pool: int) -> str:
    """Why no ``n_poses`` of the pool's poses in the region and view (``pool``, of ``n_pool``)
    identify the base parameters: the joints that never move among them, how many distinct poses
    they are, and the parameters their information leaves free."""
    lam, U = np.linalg.eigh(np.asarray(information(problem, jnp.asarray(pool))))
    null = U[:, lam <= 1e-9 * max(lam.max(), 1e-300)]
    names = problem.base_names()
    free = [names[i] for i in np.flatnonzero(np.abs(null).max(1, initial=0.0) > 0.3)]
    still = [j + 1 for j in np.flatnonzero(np.ptp(pool, 0) <= 1e-9)]
    joints = f"joint{'s' if len(still) > 1 else ''} {', '.join(map(str, still))}"
    why = [f"{joints} never move{'s' if len(still) == 1 else ''}"]
    why = (why if still else []) + [f"{len(np.unique(pool, axis=0))} distinct poses of {len(pool)} rows"]
    if len(pool) < n_pool:
        why.insert(0, f"{len(pool)} of its {n_pool} rows in the region and view")
    if free:
        why.append(f"its poses leave {', '.join(free)} free")
    return (
        f"pool: no {n_poses} of its poses identify the {len(names)} base parameters ({'; '.join(why)}); "
        "nothing was designed: a pool that moves every joint over its range, or --params for what it moves"
    )


def _pool_random_values(problem: DesignProblem, cons, pool, n_poses: int, n_random: int, rng) -> tuple[dict, dict]:
    """The criteria of ``n_random`` random sets of ``n_poses`` of the pool's rows in the region and
    view, and their medians at other counts (:func:`criteria_by_count`, as many rows as there
    are): the comparison when random configurations within the joint limits cannot be drawn
    there."""
    ok = np.flatnonzero(in_region(cons, positions(problem, pool)) if cons.has_region else np.ones(len(pool), bool))
    sets = np.stack([rng.choice(ok, n_poses, replace=False) for _ in range(n_random)])
    counts = match_counts(problem, n_poses)
    return criteria_of_sets(problem, pool[sets]), criteria_by_count(problem, pool[ok], counts[counts <= len(ok)], rng)
