"""Standard errors and conditioning of a fitted real-data calibration (the sandwich covariance
of :func:`jaxcal.crossval.calibrate_measurements`' final fit), and the frame summaries of its
report."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .camera import apply_camera, camera_jacobian
from .camera import param_names as camera_param_names
from .error_model import jacobian_and_fk, pose_error
from .robot import Robot


def _twist_log(T):
    from scipy.spatial.transform import Rotation

    T = np.asarray(T)
    return np.r_[T[:3, 3], Rotation.from_matrix(T[:3, :3]).as_rotvec()]


def frame_doc(T):
    from scipy.spatial.transform import Rotation

    T = np.asarray(T)
    return {"xyz_mm": [float(v) for v in T[:3, 3]],
            "rpy_deg": [float(v) for v in Rotation.from_matrix(T[:3, :3]).as_euler("xyz", degrees=True)]}


def standard_errors(setup, cal: Robot, cand, sig, B_init, X_init, delta, cam, camera: str):
    """Sandwich standard errors of the active parameters (and the unknowns ``cam`` of the camera
    model ``camera``) at the final fit:
    ``cov = s^2 (A^T A)^-1 (J^T J) (A^T A)^-1`` with ``A = [W J; P]`` (data and ridge rows),
    ``s^2`` the weighted residual variance; and the condition number of the scaled ``W J``."""
    names = setup.names
    n4 = 4 * setup.robot.n_joints
    fd = setup.n_dh_free
    active = [i for i in setup.free[:fd] if i in cand.dh] + list(setup.free[fd:])
    rows = 3 if setup.position_only else 6
    w = np.r_[np.full(3, 1 / sig[0]), np.full(3, 1 / sig[1])][:rows]
    m = len(cam)
    active += list(range(n4 + 12, n4 + 12 + m))
    J, T = jacobian_and_fk(cal, jnp.asarray(setup.q), base=True, tool=True)
    J = camera_jacobian(J, T, cam, camera)
    J = np.asarray(J)[:, :rows][..., active]
    e = np.asarray(pose_error(jnp.asarray(setup.measured), apply_camera(T, cam, camera)))[:, :rows]
    Jw = (J * w[:, None]).reshape(-1, len(active))
    r = (e * w).reshape(-1)
    p = np.array([cand.prior_weight(i) if i < n4 else 0.0 for i in active])
    N = Jw.T @ Jw + np.diag(p ** 2)
    dof = max(len(r) - len(active), 1)
    s2 = float(r @ r) / dof
    Ni = np.linalg.pinv(N)
    cov = s2 * Ni @ (Jw.T @ Jw) @ Ni
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    xb = _twist_log(np.asarray(cal.base) @ np.linalg.inv(B_init))
    xt = _twist_log(np.linalg.inv(X_init) @ np.asarray(cal.tool))
    value = np.r_[np.asarray(delta).reshape(-1), xb, xt, cam]
    names = list(names) + camera_param_names(camera)
    units = ["rad", "mm", "mm", "rad"]
    out = {}
    for j, i in enumerate(active):
        u = units[i % 4] if i < n4 else ("mm" if (i - n4) % 6 < 3 else "rad") if i < n4 + 12 else "1"
        out[names[i]] = (float(value[i]), float(se[j]), u)
    sc = np.linalg.svd(Jw / np.linalg.norm(Jw, axis=0), compute_uv=False)
    return out, float(sc[0] / sc[-1])
