"""On-manifold Gauss–Newton / Levenberg–Marquardt with the analytic identification Jacobian,
vmapped over many members (training sets x parameter sets) that share one robot.

Used by :mod:`jaxcal.crossval`, where one compiled call fits every cross-validation member:
optimistix (:mod:`jaxcal.solvers.least_squares`, the library's reference GN/LM) compiled for ~15 s
on that batched problem, this loop in ~2 s. Base and tool are updated on the manifold
(``exp(dxi_b) B``, ``X exp(dxi_t)``), so the identification Jacobian at the current robot is the
exact derivative; ridge priors enter as extra rows of the normal equations.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from ..error_model import identification_jacobian, pose_error
from ..kinematics import fk
from ..lie import se3_exp
from ..robot import Robot


class Problem(eqx.Module):
    """Static description shared by every member of a batched fit."""

    template: Robot
    """The nominal robot; its base and tool are replaced by each member's current frames."""
    free: tuple[int, ...] = eqx.field(static=True)
    n_dh_free: int = eqx.field(static=True)
    rows: int = eqx.field(static=True)


def member_robot(prob: Problem, delta, B, X) -> Robot:
    r = prob.template
    return eqx.tree_at(lambda r: (r.dh, r.base, r.tool), r, (r.dh + delta, B, X))


def fit_one(prob: Problem, delta0, B0, X0, q, meas, mask, w, prior, *, method: str, max_steps: int):
    """On-manifold Gauss–Newton / Levenberg–Marquardt for one member.

    State: DH errors ``delta`` (additive), base ``B`` and tool ``X`` (updated as
    ``exp(dxi_b) B`` and ``X exp(dxi_t)``), so the analytic identification Jacobian at the
    current robot is the exact derivative of the model (no autodiff through the kinematics,
    which keeps compilation short). Each step solves the column-scaled normal equations of
    the stacked rows ``[W J; P]`` (data and prior); ``lm`` adds ``mu I`` with the usual
    accept/reject schedule, ``gn`` always accepts, ``linear`` takes one step.
    """
    free = jnp.asarray(prob.free, jnp.int32)
    fd, n4, rows = prob.n_dh_free, 4 * prob.template.n_joints, prob.rows
    sw = jnp.sqrt(mask)[:, None] * w[:rows]
    frame_sel = [i - n4 for i in prob.free[fd:]]

    def cost_and_system(state, need_system=True):
        delta, B, X = state
        rob = member_robot(prob, delta, B, X)
        e = pose_error(meas, fk(rob, q))[..., :rows] * sw                   # (K, rows)
        pr = prior * delta.reshape(-1)[free[:fd]]
        cost = jnp.sum(e ** 2) + jnp.sum(pr ** 2)
        if not need_system:
            return cost
        J = identification_jacobian(rob, q, base=True, tool=True)[..., :rows, :][..., free] * sw[..., None]
        J = J.reshape(-1, len(prob.free))
        N = J.T @ J + jnp.diag(jnp.concatenate([prior ** 2, jnp.zeros(len(frame_sel))]))
        g = J.T @ e.reshape(-1) - jnp.concatenate([prior * pr, jnp.zeros(len(frame_sel))])
        return cost, N, g

    def apply(state, s):
        delta, B, X = state
        x = jnp.zeros(n4 + 12).at[free].set(s)
        return (delta + x[:n4].reshape(delta.shape), se3_exp(x[n4:n4 + 6]) @ B, X @ se3_exp(x[n4 + 6:]))

    def step(state, mu):
        cost, N, g = cost_and_system(state)
        d = 1.0 / jnp.sqrt(jnp.maximum(jnp.diag(N), 1e-300))
        z = jnp.linalg.solve(d[:, None] * N * d[None, :] + mu * jnp.eye(len(d)), d * g)
        return cost, d * z, jnp.max(jnp.abs(z))

    state0 = (delta0, B0, X0)
    if method == "linear":
        _, s, _ = step(state0, 0.0)
        state = apply(state0, s)
        return state, jnp.all(jnp.isfinite(s)), jnp.asarray(1)

    lm = method == "lm"

    def body(c):
        state, mu, i, _, _ = c
        cost, s, zmax = step(state, mu)
        new = apply(state, s)
        if lm:
            new_cost = cost_and_system(new, need_system=False)
            accept = new_cost < cost
            state = jax.tree.map(lambda a, b: jnp.where(accept, a, b), new, state)
            mu = jnp.where(accept, mu / 3.0, mu * 4.0)
            done = (accept & ((zmax < 1e-7) | (cost - new_cost <= 1e-12 * cost))) | (mu > 1e12)
            conv = accept & ((zmax < 1e-7) | (cost - new_cost <= 1e-12 * cost))
        else:
            state = new
            conv = zmax < 1e-7
            done = conv
        return state, mu, i + 1, done, conv

    def cond(c):
        return (c[2] < max_steps) & ~c[3]

    init = (state0, jnp.asarray(1e-3 if lm else 0.0), jnp.asarray(0), jnp.asarray(False), jnp.asarray(False))
    state, _, steps, _, conv = jax.lax.while_loop(cond, body, init)
    ok = conv & jnp.all(jnp.isfinite(state[0]))
    return state, ok, steps


def fit_batch(prob, delta0, B0, X0, q, meas, mask, w, prior, *, method, max_steps):
    """vmapped over members: ``delta0 (M, n, 4)``, ``B0, X0 (M, 4, 4)``, ``mask (M, K)``,
    ``w (M, 6)``, ``prior (M, f_dh)``. Returns ``((delta, B, X), ok, steps, poses (M, K, 4, 4))``."""

    def one(delta0, B0, X0, mask, w, prior):
        state, ok, steps = fit_one(prob, delta0, B0, X0, q, meas, mask, w, prior, method=method,
                                    max_steps=max_steps)
        return state, ok, steps, fk(member_robot(prob, *state), q)

    return jax.vmap(one)(delta0, B0, X0, mask, w, prior)
