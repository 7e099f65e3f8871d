"""Closed-form starting values of the unknown base and tool frames (hand-eye style), for every
data set of a batch and every cross-validation training set at once.

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

In NumPy, batched over leading axes (data sets, training sets): a handful of small SVDs and
solves per member, where a compiled program would cost more to trace and compile than it saves.
"""

from __future__ import annotations

import numpy as np

from ..lie import so3_log


def _proper(U, Vt):
    """``U diag(1, 1, det(U Vt)) Vt``: the nearest rotation of an SVD."""
    d = np.sign(np.linalg.det(U @ Vt))
    return (U * np.stack([np.ones_like(d), np.ones_like(d), d], -1)[..., None, :]) @ Vt


def _project_so3(M):
    U, _, Vt = np.linalg.svd(M)
    return _proper(U, Vt)


def _kabsch(A, B, w):
    """Weighted rotation ``R`` with ``R a ~ b`` (vectors ``(..., N, 3)``, centred by the caller) and
    the singular values of the cross-covariance (to tell a degenerate alignment)."""
    U, s, Vt = np.linalg.svd(np.swapaxes(w[..., None] * B, -1, -2) @ A)
    return _proper(U, Vt), s


def _register(P_from, P_to, w):
    """Weighted rigid transform ``(R, t)`` with ``R p_from + t ~ p_to``."""
    wn = w / np.sum(w, -1, keepdims=True)
    ca, cb = (wn[..., None, :] @ P_from)[..., 0, :], (wn[..., None, :] @ P_to)[..., 0, :]
    R, _ = _kabsch(P_from - ca[..., None, :], P_to - cb[..., None, :], w)
    return R, cb - (R @ ca[..., None])[..., 0]


def _solve_normal(N, rhs, tool: int):
    """The normal equations ``N x = rhs`` with a trace-relative ridge of 1e-9 on the first
    ``tool`` unknowns (the tool's), so that a direction the poses do not determine stays at the
    nominal tool (0) instead of making the solve fail: shared with the base's translation (a
    SCARA's parallel axes take a shift along them in either), it goes wholly to the base, the
    measurement frame that is unknown anyway, and not in part to the tool a controller uses. (The
    ridge stands well above the rounding of a base metres away; what the poses do determine it
    moves by a part in a billion.)"""
    n = N.shape[-1]
    ridge = 1e-9 * np.trace(N, axis1=-2, axis2=-1) / n
    held = (np.arange(n) < tool).astype(float)
    return np.linalg.solve(N + ridge[..., None, None] * np.diag(held), rhs[..., None])[..., 0]


def _lstsq(A, b, tool: int):
    """Least squares through :func:`_solve_normal`."""
    return _solve_normal(np.swapaxes(A, -1, -2) @ A, (b[..., None, :] @ A)[..., 0, :], tool)


def _transform(R, p):
    T = np.zeros(R.shape[:-2] + (4, 4))
    T[..., :3, :3], T[..., :3, 3], T[..., 3, 3] = R, p, 1.0
    return T


def initial_frames(
    F,
    base,
    target,
    weights,
    *,
    n_points: int = 0,
    estimate_base: bool = True,
    estimate_tool: bool = True,
    iterations: int = 50,
):
    """Starting ``(B, X, points)`` (module docstring), for every member of leading axes ``...``.

    **Arguments**: ``F`` ``(..., K, 4, 4)`` the nominal chain's poses with an identity base (its
    own tool included); ``base`` ``(4, 4)`` the nominal base; ``target`` measured poses
    ``(..., K, 4, 4)`` (``n_points = 0``) or points ``(..., K, M, 3)`` (NaN where a point was
    lost: left out); ``weights`` ``(..., K)`` select the poses used. Frames not estimated are
    kept: ``B = base``, ``X = I``, points 0.

    **Returns** ``B (..., 4, 4)``, ``X (..., 4, 4)`` (the reference tool is ``tool @ X``) and
    points ``(..., M, 3)`` in that tool frame (``(..., 0, 3)`` for poses).
    """
    F, base, target = np.asarray(F, float), np.asarray(base, float), np.asarray(target, float)
    w = np.asarray(weights, float)
    lead, K = w.shape[:-1], w.shape[-1]
    F = np.broadcast_to(F, lead + (K, 4, 4))
    RF, pF = F[..., :3, :3], F[..., :3, 3]
    R_B = np.broadcast_to(base[:3, :3], lead + (3, 3))
    p_B = np.broadcast_to(base[:3, 3], lead + (3,))
    X = np.broadcast_to(np.eye(4), lead + (4, 4)).copy()
    if n_points == 0:
        target = np.broadcast_to(target, lead + (K, 4, 4))
        RM, pM = target[..., :3, :3], target[..., :3, 3]
        if estimate_base:
            R_B, p_B = _register(pF, pM, w)
        if estimate_tool:
            if estimate_base:
                a = so3_log(RM[..., 1:, :, :] @ np.swapaxes(RM[..., :-1, :, :], -1, -2))
                b = so3_log(RF[..., 1:, :, :] @ np.swapaxes(RF[..., :-1, :, :], -1, -2))
                R_rel, s = _kabsch(b, a, w[..., 1:] * w[..., :-1])
                spans = s[..., 1] > 1e-6 * s[..., 0]  # the motions span two axes or more
                R_B = np.where(spans[..., None, None], R_rel, R_B)
            X[..., :3, :3] = _project_so3(np.einsum("...k,...kji,...lj,...klm->...im", w, RF, R_B, RM))
        elif estimate_base:
            R_B = _project_so3(np.einsum("...k,...kij,...kmj->...im", w, RM, RF))
        cols = []
        if estimate_tool:
            cols.append(np.einsum("...ij,...kjl->...kil", R_B, RF))  # p_X
        if estimate_base:
            cols.append(np.broadcast_to(np.eye(3), lead + (K, 3, 3)))  # p_B
        if cols:
            sw = np.sqrt(w)[..., None]
            A = (np.concatenate(cols, -1) * sw[..., None]).reshape(lead + (3 * K, -1))
            rhs = pM - np.einsum("...kj,...ij->...ki", pF, R_B) - (0.0 if estimate_base else p_B[..., None, :])
            sol = _lstsq(A, (rhs * sw).reshape(lead + (3 * K,)), 3 if estimate_tool else 3 * estimate_base)
            if estimate_tool:
                X[..., :3, 3] = sol[..., :3]
            if estimate_base:
                p_B = sol[..., -3:]
        return _transform(R_B, p_B), X, np.zeros(lead + (0, 3))

    M = n_points
    PM = np.broadcast_to(target, lead + (K, M, 3))
    seen = np.all(np.isfinite(PM), -1)  # (..., K, M): a lost point (NaN) weighs nothing
    PM = np.where(seen[..., None], PM, 0.0)
    wkm = w[..., None] * seen
    ww = wkm.reshape(lead + (K * M,))
    pts = np.zeros(lead + (M, 3))

    def model_points(pts):
        P = np.swapaxes(RF @ np.swapaxes(pts, -1, -2)[..., None, :, :], -1, -2) + pF[..., None, :]
        return P.reshape(lead + (K * M, 3))

    for _ in range(iterations if (estimate_base and estimate_tool) else 1):
        if estimate_base:
            R_B, p_B = _register(model_points(pts), PM.reshape(lead + (K * M, 3)), ww)
        if estimate_tool:
            # p_kj = G_k m_j + R_B p_Fk + p_B with G_k = R_B R_Fk a rotation: linear in (m_1..m_M,
            # p_B), normal equations built block by block (G_k^T G_k = I)
            G = R_B[..., None, :, :] @ RF  # (..., K, 3, 3)
            rhs = (
                PM - (pF @ np.swapaxes(R_B, -1, -2))[..., None, :] - (0.0 if estimate_base else p_B[..., None, None, :])
            )  # (..., K, M, 3)
            Gt_rhs = (np.swapaxes(G, -1, -2)[..., :, None, :, :] @ rhs[..., None])[..., 0]  # (..., K, M, 3): G_k^T r_kj
            n = 3 * M + (3 if estimate_base else 0)
            N = np.zeros(lead + (n, n))
            g = np.zeros(lead + (n,))
            count = wkm.sum(-2)  # (..., M)
            sums = np.swapaxes(wkm, -1, -2) @ G.reshape(lead + (K, 9))  # (..., M, 9): sum_k w G_k
            for j in range(M):
                N[..., 3 * j : 3 * j + 3, 3 * j : 3 * j + 3] = count[..., j, None, None] * np.eye(3)
                g[..., 3 * j : 3 * j + 3] = (wkm[..., j, None] * Gt_rhs[..., j, :]).sum(-2)
                if estimate_base:
                    C = sums[..., j, :].reshape(lead + (3, 3))
                    N[..., 3 * j : 3 * j + 3, 3 * M :] = np.swapaxes(C, -1, -2)
                    N[..., 3 * M :, 3 * j : 3 * j + 3] = C
            if estimate_base:
                N[..., 3 * M :, 3 * M :] = count.sum(-1)[..., None, None] * np.eye(3)
                g[..., 3 * M :] = (wkm[..., None] * rhs).sum((-3, -2))
            sol = _solve_normal(N, g, 3 * M)
            pts = sol[..., : 3 * M].reshape(lead + (M, 3))
            if estimate_base:
                p_B = sol[..., 3 * M :]
    return _transform(R_B, p_B), X, pts
