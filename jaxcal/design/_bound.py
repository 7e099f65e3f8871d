r"""How good any ``N`` poses can be: approximate (continuous) design theory over a set of
candidate configurations.

``N`` poses of the candidates give the information ``M = N sum_j w_j A_j + P0`` for the
weights ``w_j = (times candidate j is chosen) / N`` (``A_j = L_j^T L_j`` the information of one
pose, :func:`jaxcal.design.information`; ``P0`` the prior). Letting the weights take any values
``w >= 0, sum w = 1`` relaxes the problem to a convex one (the criterion ``tr(M^{-1} S)`` is
convex in ``w``, ``log det M`` concave), so its optimum bounds every ``N``-pose design of the
candidates, and a dual bound follows from the gradient at any ``w``: for the linear criteria
(``validation``, ``a``) ``phi(w*) >= phi(w) - N (max_j d_j - sum_j w_j d_j)`` with
``d_j = tr(M^{-1} A_j M^{-1} S)``; for ``d``, ``log det M(w*) <= log det M(w) + N (max_j d_j -
sum_j w_j d_j)`` with ``d_j = tr(M^{-1} A_j)`` (the equivalence theorem's gap). The weights are
found by the multiplicative algorithm (``w_j`` times ``d_j^{1/2}`` for the linear criteria,
``d_j`` for ``d``, renormalised) until the bound is within ``tol`` of the value.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._config import as_f64
from ..errors import DataError
from ._problem import DesignProblem, count, pose_blocks, value, values_of


@eqx.filter_jit
def _relaxed(problem: DesignProblem, A, n: float, tol: float, max_iter: int):
    """Weights of the relaxed design, its criterion terms (:func:`measures`), the dual gap in the
    minimised criterion's units (``log`` for the linear ones, ``log det`` for D) and iterations."""
    d_opt = problem.weights[0] > 0
    F = jnp.where(problem.weights[1] > 0, jnp.eye(A.shape[-1]), problem.val_factor)
    P0 = jnp.diag(problem.prior)

    def state(w):
        M = n * jnp.einsum("p,pbc->bc", w, A) + P0
        C = jnp.linalg.cholesky(M)
        Ci = jax.scipy.linalg.solve_triangular(C, jnp.eye(M.shape[0]), lower=True)
        Mi = Ci.T @ Ci
        G = jnp.where(d_opt, Mi, Mi @ F.T @ F @ Mi)
        d = jnp.einsum("pbc,bc->p", A, G)  # tr(A_j G)
        logdet = 2.0 * jnp.sum(jnp.log(jnp.diagonal(C)))
        m = jnp.stack([logdet, jnp.sum(Ci**2), jnp.sum((Ci @ problem.val_factor.T) ** 2)])
        phi = jnp.where(d_opt, logdet, jnp.sum(G * M))  # tr(M^-1 F^T F)
        gap = n * (jnp.max(d) - jnp.dot(w, d))
        rel = jnp.where(d_opt, gap, -jnp.log1p(-jnp.minimum(gap / phi, 1.0 - 1e-16)))  # log phi - log bound
        return m, d, rel

    def body(s):
        w, _, d, _, k = s
        w = w * jnp.where(d_opt, d, jnp.sqrt(d))
        w = w / jnp.sum(w)
        m, d, rel = state(w)
        return w, m, d, rel, k + 1

    def cond(s):
        return (s[3] > tol) & (s[4] < max_iter)

    w0 = jnp.full(A.shape[0], 1.0 / A.shape[0])
    m0, d0, rel0 = state(w0)
    w, m, _, rel, k = jax.lax.while_loop(cond, body, (w0, m0, d0, rel0, 0))
    return w, m, rel, k


def design_bound(problem: DesignProblem, candidates, n_poses: int, *, tol: float = 1e-3, max_iter: int = 20000) -> dict:
    """The best value of the problem's criterion that any ``n_poses`` configurations of
    ``candidates (P, n)`` can reach, by approximate design theory (module docstring).

    **Returns** ``bound`` (the criterion in its reported units, :func:`jaxcal.design.evaluate`:
    no ``n_poses`` of the candidates do better), ``relaxed`` (the relaxed optimum's three
    criteria, within ``tol`` of the bound in log units), ``support`` (candidates with a weight
    of at least a tenth of a pose), ``weights (P,)`` and ``iterations``. With many candidates
    spread over where the poses may go (e.g. :func:`jaxcal.design.random_poses`), the bound
    holds, to the candidates' coverage, for any design there, the gradient's included.
    """
    n_poses = count("n_poses", n_poses, 1)
    q = np.asarray(as_f64(candidates, "candidates"))
    if q.ndim != 2 or q.shape[1] != problem.lower.shape[0] or len(q) < 1 or not np.all(np.isfinite(q)):
        raise DataError(
            f"candidates must be finite with shape (P, {problem.lower.shape[0]}), got {q.shape}", option="candidates"
        )
    P = len(q)
    L = pose_blocks(problem, q)
    A = jnp.asarray(np.einsum("prb,prc->pbc", L, L))
    w, m, rel, k = _relaxed(problem, A, float(n_poses), tol, max_iter)
    relaxed = values_of(m)
    crit = problem.criterion
    v, gap = value(crit, relaxed), float(rel)
    bound = v + gap if crit == "d" else v * np.exp(-gap / 2) if crit == "validation" else v * np.exp(-gap)
    w = np.asarray(w)
    return {
        "criterion": crit,
        "bound": float(bound),
        "relaxed": relaxed,
        "support": int(np.sum(w * n_poses >= 0.1)),
        "weights": w,
        "iterations": int(k),
        "candidates": P,
    }
