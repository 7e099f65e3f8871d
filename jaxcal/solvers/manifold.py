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

from ..camera import apply_camera, camera_jacobian, n_params
from ..error_model import jacobian_and_fk, pose_error
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
    camera: str = eqx.field(static=True, default="none")
    """Camera measurement model (:mod:`jaxcal.camera`) whose unknowns are estimated with the
    robot; their prior weights are the last ``n_params(camera)`` entries of ``prior``."""


def member_robot(prob: Problem, delta, B, X) -> Robot:
    r = prob.template
    return eqx.tree_at(lambda r: (r.dh, r.base, r.tool), r, (r.dh + delta, B, X))


def fit_one(prob: Problem, delta0, B0, X0, q, meas, mask, w, prior, c0, *, method: str, max_steps: int):
    """On-manifold Gauss–Newton / Levenberg–Marquardt for one member.

    State: DH errors ``delta`` (additive), base ``B`` and tool ``X`` (updated as
    ``exp(dxi_b) B`` and ``X exp(dxi_t)``), so the analytic identification Jacobian at the
    current robot is the exact derivative of the model (no autodiff through the kinematics,
    which keeps compilation short). Each step solves the column-scaled normal equations of
    the stacked rows ``[W J; P]`` (data and prior); ``lm`` adds ``mu I`` with the usual
    accept/reject schedule, ``gn`` always accepts, ``linear`` takes one step. The state also
    holds the camera model's unknowns ``c`` (start ``c0 (m,)``, prior weights ``prior[-m:]``; none
    for ``prob.camera == "none"``): the model pose goes through :func:`jaxcal.camera.apply_camera`
    and the Jacobian gets its exact derivative and columns (:func:`jaxcal.camera.camera_jacobian`).
    """
    free = jnp.asarray(prob.free, jnp.int32)
    fd, n4, rows = prob.n_dh_free, 4 * prob.template.n_joints, prob.rows
    sw = jnp.sqrt(mask)[:, None] * w[:rows]
    frame_sel = [i - n4 for i in prob.free[fd:]]
    cam, m = prob.camera, n_params(prob.camera)
    # prior rows: DH errors, (frames: none), camera unknowns
    prior_all = jnp.concatenate([prior[:fd], jnp.zeros(len(frame_sel)), prior[fd:fd + m]])
    cols = jnp.concatenate([free, n4 + 12 + jnp.arange(m, dtype=jnp.int32)])

    def cost_and_system(state, need_system=True):
        delta, B, X, sc = state
        rob = member_robot(prob, delta, B, X)
        if need_system:  # the Jacobian and the pose from one pass over the chain
            J, T = jacobian_and_fk(rob, q, base=True, tool=True)
        else:
            T = fk(rob, q)
        e = pose_error(meas, apply_camera(T, sc, cam))[..., :rows] * sw   # (K, rows)
        pr = prior_all * jnp.concatenate([delta.reshape(-1)[free[:fd]], jnp.zeros(len(frame_sel)), sc])
        cost = jnp.sum(e ** 2) + jnp.sum(pr ** 2)
        if not need_system:
            return cost
        J = camera_jacobian(J, T, sc, cam)
        J = J[..., :rows, :][..., cols] * sw[..., None]
        J = J.reshape(-1, len(cols))
        N = J.T @ J + jnp.diag(prior_all ** 2)
        g = J.T @ e.reshape(-1) - prior_all * pr
        return cost, N, g

    def apply(state, s):
        delta, B, X, sc = state
        x = jnp.zeros(n4 + 12 + m).at[cols].set(s)
        return (delta + x[:n4].reshape(delta.shape), se3_exp(x[n4:n4 + 6]) @ B, X @ se3_exp(x[n4 + 6:n4 + 12]),
                sc + x[n4 + 12:])

    def step(state, mu):
        cost, N, g = cost_and_system(state)
        d = 1.0 / jnp.sqrt(jnp.maximum(jnp.diag(N), 1e-300))
        z = jnp.linalg.solve(d[:, None] * N * d[None, :] + mu * jnp.eye(len(d)), d * g)
        return cost, d * z, jnp.max(jnp.abs(z))

    state0 = (delta0, B0, X0, jnp.asarray(c0, delta0.dtype).reshape(m))
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
    ok = conv & jnp.all(jnp.isfinite(state[0])) & jnp.all(jnp.isfinite(state[3]))
    return state, ok, steps


def fit_batch(prob, delta0, B0, X0, q, meas, mask, w, prior, c0=None, *, method, max_steps):
    """vmapped over members: ``delta0 (M, n, 4)``, ``B0, X0 (M, 4, 4)``, ``mask (M, K)``,
    ``w (M, 6)``, ``prior (M, f_dh + m)`` (``m`` camera unknowns), ``c0 (M, m)`` (camera start,
    default 0). Returns ``((delta, B, X, c), ok, steps, poses (M, K, 4, 4))``; ``poses`` are the
    predicted measurements (through the camera model)."""
    if c0 is None:
        c0 = jnp.zeros((delta0.shape[0], n_params(prob.camera)), delta0.dtype)

    def one(delta0, B0, X0, mask, w, prior, c0):
        state, ok, steps = fit_one(prob, delta0, B0, X0, q, meas, mask, w, prior, c0, method=method,
                                    max_steps=max_steps)
        T = fk(member_robot(prob, *state[:3]), q)
        return state, ok, steps, apply_camera(T, state[3], prob.camera)

    return jax.vmap(one)(delta0, B0, X0, mask, w, prior, c0)
