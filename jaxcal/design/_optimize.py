r"""Optimal joint configurations by gradient: BFGS (:mod:`._bfgs`) on the criterion of
:mod:`._problem`, differentiated through the identification Jacobian, from several starts at
once.

The joint limits are kept by a smooth reparametrisation, ``q = c + h sin(u)`` with ``c`` the
middle and ``h`` the half range of each joint: every ``u`` is a configuration within the
limits, and the optimiser runs unconstrained. The minimum spread, the box and the view cone are
quadratic penalties on slightly tightened constraints (so that the optimum, which sits a hair beyond a
penalised bound, still satisfies the given one); a design is checked against the given
constraints afterwards.
"""

from __future__ import annotations

import functools
import time
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import LOOP_EMITTERS, jit
from ..errors import DataError
from ._bfgs import minimise
from ._constraints import (
    Constraints,
    constraints,
    feasible,
    min_distance,
    random_by_count,
    random_feasible,
    random_values,
    view_coordinates,
)
from ._problem import DesignProblem, count, loss, loss_of, measures_batch, tool_positions, values_of
from ._result import PoseDesign, frozen
from ._select import exchange

POOL_STARTS = 1000
"""Random configurations each start is selected from under a region or view."""
PENALTY = 100.0
"""Weight of the squared, normalised constraint violations against the criterion's O(1) loss."""
SPREAD_MARGIN = 1.02
"""The penalised spread is this much larger than the one asked for."""
BOX_MARGIN = 0.005
"""The penalised box is this fraction of its size smaller on every side."""
BOX_LENGTH = 0.01
"""A violation of this fraction of the box's size costs ``PENALTY``."""
VIEW_MARGIN = 0.01
"""The penalised view cone's half-angle is this fraction smaller, its range 1 mm shorter at each end."""
VIEW_ANGLE = 0.01
"""A point this many rad outside the view cone costs ``PENALTY``."""
VIEW_LENGTH = 10.0
"""A point this many mm before or beyond the view's range costs ``PENALTY``."""
BFGS_MEMORY_MB = 4096.0
"""The largest inverse Hessian the gradient design keeps (``(K n)^2`` float64 entries, a few
copies): more poses are refused up front, not met by an out-of-memory error in the compiled
program."""
BFGS_COPIES = 3


def penalty(problem: DesignProblem, cons: Constraints, q: Float[Array, "K n"]) -> Float[Array, ""]:
    """Quadratic penalty of the spread and region violations of ``q`` (0 when they hold)."""
    K = q.shape[0]
    on = cons.spread > 0
    spread = jnp.where(on, cons.spread * SPREAD_MARGIN, 1.0)
    i, j = np.triu_indices(K, 1)
    # sqrt(d^2 + tiny): smooth where two configurations coincide
    dist = jnp.sqrt(jnp.sum((q[i] - q[j]) ** 2, -1) + 1e-12)
    pen = jnp.where(on, jnp.sum(jax.nn.relu(1.0 - dist / spread) ** 2), 0.0)
    size = cons.box_upper - cons.box_lower
    lo, hi = cons.box_lower + BOX_MARGIN * size, cons.box_upper - BOX_MARGIN * size
    p = tool_positions(problem.model, problem.layout, q)
    viol = (jax.nn.relu(p - hi) + jax.nn.relu(lo - p)) / (BOX_LENGTH * size)
    along, angle = view_coordinates(cons, p)
    off = jax.nn.relu(angle - (1 - VIEW_MARGIN) * cons.view_half_angle) / VIEW_ANGLE
    off += (jax.nn.relu(cons.view_near + 1.0 - along) + jax.nn.relu(along - cons.view_far + 1.0)) / VIEW_LENGTH
    return PENALTY * (pen + cons.box_on * jnp.sum(viol**2) + cons.view_on * jnp.sum(off**2))


def within_margin(problem: DesignProblem) -> DesignProblem:
    """The problem with its limits moved inside by its :attr:`~DesignProblem.margin` (the same
    compiled programs: the limits are data)."""
    return eqx.tree_at(
        lambda p: (p.lower, p.upper), problem, (problem.lower + problem.margin, problem.upper - problem.margin)
    )


def to_q(problem: DesignProblem, u):
    c, h = (problem.upper + problem.lower) / 2, (problem.upper - problem.lower) / 2
    return c + h * jnp.sin(u)


def to_u(problem: DesignProblem, q):
    c, h = (problem.upper + problem.lower) / 2, (problem.upper - problem.lower) / 2
    return jnp.arcsin(jnp.clip((q - c) / h, -1.0 + 1e-9, 1.0 - 1e-9))


def _objective(u, args, penalised: bool = True):
    problem, cons = args
    q = to_q(problem, u)
    return loss(problem, q) + penalty(problem, cons, q) if penalised else loss(problem, q)


@jit(options=LOOP_EMITTERS)
def _optimise(
    problem: DesignProblem, cons: Constraints, q0: Float[Array, "S K n"], *, max_steps: int, tol: float, penalised: bool
):
    """BFGS from every start ``q0[s]`` in one program: final configurations, convergence flags and
    evaluations (their criteria come from the design's shared programs, not a second copy of the
    Jacobian here). Without constraints (``penalised`` False) the penalty, zero, is left out of
    the program."""
    vg = jax.value_and_grad(functools.partial(_objective, penalised=penalised))

    def one(q_):
        u, f, conv, n = minimise(vg, to_u(problem, q_), (problem, cons), max_evals=max_steps, tol=tol)
        return to_q(problem, u), conv, n

    # one start after another: batched LAPACK calls (Cholesky) inside a vmapped while_loop are
    # many times slower than the same starts in turn on the CPU backend
    return jax.lax.map(one, q0)


@eqx.filter_jit
def _losses(problem: DesignProblem, m):
    return jax.vmap(lambda m_: loss_of(problem, m_))(m)


@eqx.filter_jit
def objective_and_grad(problem: DesignProblem, q: Float[Array, "K n"]):
    """The criterion's loss (:func:`jaxcal.design.loss`) and its gradient with respect to the
    joint values."""
    return jax.value_and_grad(lambda q_: loss(problem, q_))(q)


def optimal_poses(
    problem: DesignProblem,
    n_poses: int,
    *,
    starts: int = 4,
    seed: int = 0,
    min_spread: float = 0.0,
    region=None,
    view=None,
    q0=None,
    start_pool: int | None = None,
    max_steps: int | None = None,
    tol: float = 1e-6,
    n_random: int = 200,
) -> PoseDesign:
    """``n_poses`` joint configurations that optimise the problem's criterion, by gradient.

    **Arguments**

    * ``problem``: :func:`design_problem` (robot, options, criterion, validation set).
    * ``starts``: BFGS runs from that many random configuration sets (uniform within the limits,
      the tool in the region), in one compiled call; the best feasible result wins. ``seed`` seeds them and
      the random comparison. ``q0 (S, N, n)`` or ``(N, n)`` gives the starts instead. The
      designs stay the problem's ``margin`` inside the joint limits (the random sets they are
      compared with are drawn within the limits).
    * ``min_spread``: smallest joint-space Euclidean distance between two configurations (rad;
      mm for prismatic joints). ``region``: ``(lower xyz, upper xyz)`` in mm, a box in the frame
      of the forward kinematics that every measured point must stay in. ``view``: ``(origin
      xyz, axis xyz, half_angle[, near, far])`` (mm, rad), a camera's view cone in that frame
      that every measured point must stay in.
    * ``start_pool``: each start is then the exchange selection (as :func:`select_poses`) of
      ``start_pool`` random configurations meeting the constraints, which the gradient refines.
      Default 1000 with a region or view, where random sets are poor starts and the gradient
      from them stalls in poor local optima (docs/design.md), else 0 (random sets).
    * ``max_steps``, ``tol``: BFGS's limit on evaluations (trial points; default 500 from random
      sets, 2000 from pool starts, whose refinement gains a little more with more steps) and
      its tolerance on the change of the loss, O(1), and of the reparametrised joint values.
    * ``n_random``: random pose sets of the same count to compare with.

    **Returns** a :class:`PoseDesign`; ``feasible`` is False (with a warning) when no start met
    the constraints.
    """
    n_poses = count("n_poses", n_poses, 1)
    starts, seed, n_random = count("starts", starts, 1), count("seed", seed, 0), count("n_random", n_random, 1)
    cons = constraints(min_spread, region, view)
    start_given = start_pool is not None
    if start_pool is None:
        start_pool = POOL_STARTS if cons.has_region and q0 is None else 0
    start_pool = count("start_pool", start_pool, 0)
    if start_pool and start_pool < n_poses:
        raise DataError(f"start_pool must be 0 or at least n_poses ({n_poses}), got {start_pool}", option="start_pool")
    if max_steps is None:
        max_steps = 2000 if start_pool else 500
    max_steps = count("max_steps", max_steps, 1)
    if problem.layout.rows * n_poses < problem.n_base:
        need = -(-problem.n_base // problem.layout.rows)
        raise DataError(
            f"n_poses: {n_poses} poses x {problem.layout.rows} rows cannot identify {problem.n_base} base "
            f"parameters; need at least {need}",
            option="n_poses",
        )
    size = n_poses * problem.lower.shape[0]
    if BFGS_COPIES * size**2 * 8 / 2**20 > BFGS_MEMORY_MB:
        most = int(np.sqrt(BFGS_MEMORY_MB * 2**20 / (BFGS_COPIES * 8))) // problem.lower.shape[0]
        raise DataError(
            f"n_poses: the gradient design of {n_poses} poses keeps a {size} x {size} matrix "
            f"({BFGS_COPIES * size**2 * 8 / 2**30:.3g} GB); at most {most} poses: choose more from a pool (--pool)",
            option="n_poses",
        )
    rng = np.random.default_rng([seed, 2])
    full, problem = problem, within_margin(problem)  # designed inside the margin; compared with random sets in full
    pool_asked = start_pool
    if q0 is None and start_pool:
        where = constraints(0.0, region, view)  # the exchange keeps the spread among the chosen
        try:
            pools = random_feasible(problem, where, (starts, start_pool), rng)
        except DataError:
            if start_given:
                raise
            pools = None  # a region too tight for the default pool may still hold the poses asked for
        if pools is not None:
            picked = [
                exchange(problem, cons, pools[s], n_poses, 10 * n_poses, option="min_spread")[0] for s in range(starts)
            ]
            q0 = np.stack([pools[s][i] for s, i in enumerate(picked)])
        else:
            pool_asked = 0
    if q0 is None and not pool_asked:
        q0 = random_feasible(problem, cons, (starts, n_poses), rng)
    else:
        q0 = np.asarray(q0, dtype=np.float64)
        q0 = q0[None] if q0.ndim == 2 else q0
        if q0.shape[1:] != (n_poses, problem.lower.shape[0]):
            raise DataError(f"q0 must have shape (S, {n_poses}, {problem.lower.shape[0]}), got {q0.shape}", option="q0")
    t0 = time.perf_counter()
    penalised = cons.has_region or float(cons.spread) > 0
    out = _optimise(problem, cons, jnp.asarray(q0), max_steps=max_steps, tol=tol, penalised=penalised)
    q, ok, evals = (np.asarray(a) for a in out)
    seconds = time.perf_counter() - t0
    q = np.clip(q, np.asarray(problem.lower), np.asarray(problem.upper))  # rounding of c + h sin(u)
    m = measures_batch(problem, q)
    losses = np.asarray(_losses(problem, jnp.asarray(m)))
    good = np.array([np.isfinite(losses[s]) and feasible(problem, cons, q[s]) for s in range(len(q))])
    best = int(np.lexsort((np.where(np.isfinite(losses), losses, np.inf), ~good))[0])
    if not good[best]:
        warnings.warn(
            "no start met the constraints (min_spread, region, view): the design returned violates them; "
            "loosen them or add starts",
            stacklevel=2,
        )
    values = values_of(m[best])
    return PoseDesign(
        q=frozen(q[best]),
        criterion=problem.criterion,
        values=values,
        random_values=random_values(full, cons, n_poses, n_random, rng),
        random_by_count=random_by_count(full, cons, n_poses, rng),
        method="gradient",
        base_names=problem.base_names(),
        feasible=bool(good[best]),
        min_distance=min_distance(q[best]),
        details={
            "starts": int(len(q)),
            "start_pool": start_pool,
            "start_losses": [float(v) for v in losses],
            "feasible_starts": int(good.sum()),
            "start_feasible": [bool(g) for g in good],
            "converged_starts": int(ok.sum()),
            "max_evaluations": int(evals.max()),
            "optimise_seconds": seconds,
        },
    )


__all__ = ["loss", "loss_of", "objective_and_grad", "optimal_poses", "penalty"]
