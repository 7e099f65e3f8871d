"""Initial guess of the unknown base and tool frames (hand-eye style), before any fitting.

Measured poses obey ``T_meas_k = B · F_k · X`` with ``F_k = fk(robot with identity base, q_k)``
(the nominal chain including the robot's nominal tool, e.g. the Franka flange) and two unknown
rigid transforms: ``B`` (measurement frame -> robot base) and ``X`` (nominal tool -> measured
point/frame, e.g. flange -> camera). Closed-form steps, NumPy, deterministic:

1. rotation (and a first translation) of ``B`` by a rigid registration of the nominal tool
   positions ``p(F_k)`` onto the measured positions (:func:`jaxcal.measurements.register_points`);
2. full poses only: ``R_B`` from relative motions (Park & Martin): the rotation vector of
   ``R_meas_i R_meas_j^T`` is ``R_B`` times that of ``R_Fi R_Fj^T``, aligned over consecutive
   pairs (Kabsch); then ``R_X`` as the chordal mean of ``R_Fk^T R_B^T R_meas_k`` projected onto
   SO(3);
3. translations: ``p_meas_k = R_B R_Fk p_X + R_B p_Fk + p_B`` is linear in ``(p_X, p_B)``:
   one linear least-squares solve. Position-only data re-register ``B`` onto the tool points
   ``p_Fk + R_Fk p_X`` and repeat step 3 a few times (``R_X`` stays the identity: a tool
   rotation does not move a measured point).

The result is only a starting point: the frames-only Gauss–Newton fit refines it.
"""

from __future__ import annotations

import numpy as np

from .errors import DataError
from .kinematics import fk
from .measurements import register_points


def _project_so3(M: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def nominal_chain(robot, q) -> np.ndarray:
    """``F_k``: poses of the nominal chain with an identity base, the robot's own tool."""
    return np.asarray(fk(robot.replace(base=np.eye(4)), np.asarray(q, dtype=np.float64)))


def initial_frames(robot, q, measured, *, position_only: bool, estimate_base: bool = True,
                   estimate_tool: bool = True, iterations: int = 50) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form guess ``(B, X)`` with ``measured_k ~ B F_k X`` (see the module docstring).

    **Arguments**: ``q`` ``(K, n)``; ``measured`` ``(K, 4, 4)`` (mm); frames not estimated are
    kept: ``B = robot.base``, ``X = I``.

    **Returns** ``(B, X)``, 4x4 each; the initial robot is
    ``robot.replace(base=B, tool=robot.tool @ X)``.
    """
    F = nominal_chain(robot, q)
    M = np.asarray(measured, dtype=np.float64)
    K = len(F)
    if K < 3:
        raise DataError(f"need at least 3 poses to initialise the base/tool frames, got {K}")
    B = np.asarray(robot.base, dtype=np.float64).copy()
    X = np.eye(4)
    pF, pM = F[:, :3, 3], M[:, :3, 3]
    if estimate_base:
        B = register_points(pF, pM)
    RF, RM = F[:, :3, :3], M[:, :3, :3]
    if not position_only and estimate_tool:
        if estimate_base:
            from scipy.spatial.transform import Rotation

            a = Rotation.from_matrix(RM[1:] @ np.swapaxes(RM[:-1], 1, 2)).as_rotvec()
            b = Rotation.from_matrix(RF[1:] @ np.swapaxes(RF[:-1], 1, 2)).as_rotvec()
            if np.linalg.matrix_rank(b, tol=1e-6) >= 2:
                B[:3, :3] = Rotation.align_vectors(a, b)[0].as_matrix()
        X[:3, :3] = _project_so3(np.einsum("kji,lj,klm->im", RF, B[:3, :3], RM) / K)
    elif not position_only and estimate_base:
        B[:3, :3] = _project_so3(np.einsum("kij,kmj->im", RM, RF) / K)
    for _ in range(1 if not position_only or not estimate_base else iterations):
        RB = B[:3, :3]
        b = (pM - pF @ RB.T).reshape(-1)
        cols = []
        if estimate_tool:
            cols.append(np.einsum("ij,kjl->kil", RB, RF))               # (K, 3, 3) -> p_X
        if estimate_base:
            cols.append(np.broadcast_to(np.eye(3), (K, 3, 3)))          # p_B
        if not cols:
            break
        A = np.concatenate(cols, axis=2).reshape(3 * K, -1)
        if not estimate_base:
            b = b - np.tile(B[:3, 3], K)
        sol = np.linalg.lstsq(A, b, rcond=None)[0]
        if estimate_tool:
            X[:3, 3] = sol[:3]
            sol = sol[3:]
        if estimate_base:
            B[:3, 3] = sol[:3]
            if position_only:  # re-register the base onto the current tool points
                B = register_points(pF + np.einsum("kij,j->ki", RF, X[:3, 3]), pM)
    return B, X
