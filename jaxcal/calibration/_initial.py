"""Closed-form starting values of the unknown base and tool frames (hand-eye style), in pure JAX
so that every data set of a batch and every cross-validation training set gets its own in one
vmapped call.

Measured poses obey ``T_meas_k = B F_k X`` with ``F_k = fk(robot with identity base, q_k)`` (the
nominal chain with the robot's own tool, e.g. a flange) and two unknown rigid transforms ``B``
(measurement frame -> robot base) and ``X`` (nominal tool -> measured frame); measured points obey
``p_kj = B F_k m_j`` with unknown points ``m_j`` in the tool frame. Steps, each a weighted
closed form (``weights`` select a training set):

1. rotation of ``B`` by a rigid registration (Kabsch) of the model's tool points onto the
   measured ones;
2. full poses: ``R_B`` from relative motions (Park & Martin): the rotation vector of
   ``R_meas_k R_meas_{k+1}^T`` is ``R_B`` times that of ``R_Fk R_F{k+1}^T``, aligned by Kabsch
   over consecutive pairs when they span more than one axis; then ``R_X`` as the chordal mean of
   ``R_Fk^T R_B^T R_meas_k`` projected onto SO(3);
3. translations: ``p_meas = R_B (R_F p_X + p_F) + p_B`` is linear in ``(p_X, p_B)`` (or in the
   points ``m_j`` and ``p_B``): one weighted least-squares solve. Points re-register ``B`` onto
   the current model points and repeat.

The result is only a starting point; the frames-only fit refines it.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from ..kinematics import fk
from ..lie import so3_log
from ..robot import Robot


def _proper(U, Vt):
    """``U diag(1, 1, det(U Vt)) Vt``: the nearest rotation of an SVD."""
    d = jnp.sign(jnp.linalg.det(U @ Vt))
    return (U * jnp.stack([jnp.ones_like(d), jnp.ones_like(d), d])) @ Vt


def _project_so3(M):
    U, _, Vt = jnp.linalg.svd(M)
    return _proper(U, Vt)


def _kabsch(A, B, w):
    """Weighted rotation ``R`` with ``R a ~ b`` (vectors ``(N, 3)``, centred by the caller) and the
    singular values of the cross-covariance (to tell a degenerate alignment)."""
    U, s, Vt = jnp.linalg.svd(jnp.einsum("n,ni,nj->ij", w, B, A))
    return _proper(U, Vt), s


def _register(P_from, P_to, w):
    """Weighted rigid transform ``(R, t)`` with ``R p_from + t ~ p_to``."""
    wn = w / jnp.sum(w)
    ca, cb = wn @ P_from, wn @ P_to
    R, _ = _kabsch(P_from - ca, P_to - cb, w)
    return R, cb - R @ ca


def _lstsq(A, b):
    """Least squares by the normal equations with a trace-relative ridge of 1e-12, so that a
    direction the poses do not determine stays at 0 instead of making the solve fail."""
    N = A.T @ A
    return jnp.linalg.solve(N + 1e-12 * jnp.trace(N) / N.shape[0] * jnp.eye(N.shape[0]), A.T @ b)


def initial_frames(
    robot: Robot,
    q,
    target,
    weights=None,
    *,
    n_points: int = 0,
    estimate_base: bool = True,
    estimate_tool: bool = True,
    iterations: int = 50,
):
    """Starting ``(B, X, points)`` (module docstring). Pure and vmappable.

    **Arguments**: ``q`` ``(K, n)``; ``target`` measured poses ``(K, 4, 4)`` (``n_points = 0``) or
    points ``(K, M, 3)`` (NaN where a point was lost: left out); ``weights`` ``(K,)`` select the
    poses used (default all). Frames not
    estimated are kept: ``B = robot.base``, ``X = I``, points 0.

    **Returns** ``B (4, 4)``, ``X (4, 4)`` (the reference tool is ``robot.tool @ X``) and points
    ``(M, 3)`` in that tool frame (``(0, 3)`` for poses).
    """
    F = fk(eqx.tree_at(lambda r: r.base, robot, jnp.eye(4)), q)
    K = q.shape[0]
    w = jnp.ones(K) if weights is None else jnp.asarray(weights, jnp.float64)
    RF, pF = F[:, :3, :3], F[:, :3, 3]
    R_B, p_B = robot.base[:3, :3], robot.base[:3, 3]
    X = jnp.eye(4)
    if n_points == 0:
        RM, pM = target[:, :3, :3], target[:, :3, 3]
        if estimate_base:
            R_B, p_B = _register(pF, pM, w)
        if estimate_tool:
            if estimate_base:
                a = so3_log(RM[1:] @ jnp.swapaxes(RM[:-1], 1, 2))
                b = so3_log(RF[1:] @ jnp.swapaxes(RF[:-1], 1, 2))
                R_rel, s = _kabsch(b, a, w[1:] * w[:-1])
                R_B = jnp.where(s[1] > 1e-6 * s[0], R_rel, R_B)  # the motions span two axes or more
            R_X = _project_so3(jnp.einsum("k,kji,lj,klm->im", w, RF, R_B, RM))
            X = X.at[:3, :3].set(R_X)
        elif estimate_base:
            R_B = _project_so3(jnp.einsum("k,kij,kmj->im", w, RM, RF))
        cols = []
        if estimate_tool:
            cols.append(jnp.einsum("ij,kjl->kil", R_B, RF))  # p_X
        if estimate_base:
            cols.append(jnp.broadcast_to(jnp.eye(3), (K, 3, 3)))  # p_B
        if cols:
            sw = jnp.sqrt(w)[:, None]
            A = (jnp.concatenate(cols, 2) * sw[..., None]).reshape(3 * K, -1)
            rhs = pM - pF @ R_B.T - (0.0 if estimate_base else p_B)
            sol = _lstsq(A, (rhs * sw).reshape(-1))
            if estimate_tool:
                X = X.at[:3, 3].set(sol[:3])
            if estimate_base:
                p_B = sol[-3:]
        return _transform(R_B, p_B), X, jnp.zeros((0, 3))

    M = n_points
    PM = target.reshape(K, M, 3)
    seen = jnp.all(jnp.isfinite(PM), -1)  # (K, M): a lost point (NaN) weighs nothing
    PM = jnp.where(seen[..., None], PM, 0.0)
    wkm = w[:, None] * seen
    ww = wkm.reshape(K * M)
    pts = jnp.zeros((M, 3))

    def model_points(pts):
        return (jnp.einsum("kij,mj->kmi", RF, pts) + pF[:, None]).reshape(K * M, 3)

    def step(_, c):
        R_B, p_B, pts = c
        if estimate_base:
            R_B, p_B = _register(model_points(pts), PM.reshape(K * M, 3), ww)
        if estimate_tool:
            # p_kj = R_B (R_Fk m_j + p_Fk) + p_B: linear in (m_1..m_M, p_B)
            blocks = jnp.einsum("ij,kjl->kil", R_B, RF)  # (K, 3, 3)
            Am = jnp.eye(M)[None, :, None, :, None] * blocks[:, None, :, None, :]  # (K, M, 3, M, 3)
            A = [Am.reshape(K, M, 3, 3 * M)]
            if estimate_base:
                A.append(jnp.broadcast_to(jnp.eye(3), (K, M, 3, 3)))
            A = jnp.concatenate(A, -1)
            rhs = PM - pF[:, None] @ R_B.T - (0.0 if estimate_base else p_B)
            sw = jnp.sqrt(wkm)[:, :, None]
            sol = _lstsq((A * sw[..., None]).reshape(3 * K * M, -1), (rhs * sw).reshape(-1))
            pts = sol[: 3 * M].reshape(M, 3)
            if estimate_base:
                p_B = sol[3 * M :]
        return R_B, p_B, pts

    n_iter = iterations if (estimate_base and estimate_tool) else 1
    R_B, p_B, pts = jax.lax.fori_loop(0, n_iter, step, (R_B, p_B, pts))
    return _transform(R_B, p_B), X, pts


def _transform(R, p):
    return jnp.eye(4).at[:3, :3].set(R).at[:3, 3].set(p)
