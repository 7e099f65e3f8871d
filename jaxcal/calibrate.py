"""Public calibration API: :func:`calibrate` (one data set) and :func:`calibrate_batch` (a
batch of robots in one compiled, vmapped call).

Pipeline: nominal identification Jacobian over the pose set -> identifiable (base) parameter
set (:mod:`jaxcal.identifiability`) -> solver on the base set only (the other parameters stay
at zero and are reported as fixed) -> calibrated robot + residual statistics.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._config import as_f64
from .error_model import identification_jacobian, n_params, param_names, perturb, pose_error
from .errors import DataError
from .identifiability import Identifiability, analyze
from .kinematics import fk
from .robot import Robot
from .solvers import elimination, least_squares, linear

METHODS = ("gn", "lm", "linear")
ELIMINATION_METHODS = ("elimination", "elimination-literal")  # need a jaxcal.design pose design


def _check_inputs(robot: Robot, q, measured, batched: bool):
    q = as_f64(q, "q")
    measured = as_f64(measured, "measured")
    lead = 2 if batched else 1
    shape_q = "(R, K, n)" if batched else "(K, n)"
    if q.ndim != lead + 1 or q.shape[-1] != robot.n_joints:
        raise DataError(f"q must have shape {shape_q} with n = {robot.n_joints} joints, got {q.shape}")
    if measured.shape != q.shape[:-1] + (4, 4):
        raise DataError(f"measured must have shape {q.shape[:-1] + (4, 4)} (one 4x4 pose per row of q), got {measured.shape}")
    for name, arr in (("q", q), ("measured", measured)):
        bad = ~np.isfinite(np.asarray(arr))
        if bad.any():
            idx = np.argwhere(bad)[0]
            raise DataError(f"{name}: non-finite value at index {tuple(int(i) for i in idx)}")
    return q, measured


def _sigmas(position_only, sigma_pos_mm, sigma_rot_rad):
    sp = 1.0 if sigma_pos_mm is None or sigma_pos_mm <= 0 else float(sigma_pos_mm)
    sr = 1e-3 if sigma_rot_rad is None or sigma_rot_rad <= 0 else float(sigma_rot_rad)
    return sp, sr


@eqx.filter_jit
def _solve_batch(robot, q, measured, sig_pos, sig_rot, *, method, free, m, position_only, base, tool,
                 rtol, atol, max_steps):
    def one(q_, meas_):
        if method == "linear":
            return linear.solve(robot, q_, meas_, free=free, m=m, position_only=position_only, base=base,
                                tool=tool, sigma_pos=sig_pos, sigma_rot=sig_rot)
        return least_squares.solve(robot, q_, meas_, free=free, m=m, method=method, position_only=position_only,
                                   base=base, tool=tool, sigma_pos=sig_pos, sigma_rot=sig_rot, rtol=rtol,
                                   atol=atol, max_steps=max_steps)

    return jax.vmap(one)(q, measured)


def residual_stats(robot: Robot, q, measured, *, position_only: bool) -> dict:
    """Position RMS / max (mm) and, for full poses, rotation RMS (deg) of ``measured`` vs the
    model ``robot``."""
    e = np.asarray(pose_error(jnp.asarray(measured), fk(robot, jnp.asarray(q))))
    dp = np.linalg.norm(e[..., :3], axis=-1)
    out = {"pos_rms_mm": float(np.sqrt(np.mean(dp ** 2))), "pos_max_mm": float(dp.max())}
    if not position_only:
        out["rot_rms_deg"] = float(np.degrees(np.sqrt(np.mean(np.sum(e[..., 3:] ** 2, -1)))))
    return out


@dataclasses.dataclass(frozen=True)
class CalibrationResult:
    """What :func:`calibrate` returns."""

    robot: Robot                     # the calibrated model
    nominal: Robot
    method: str
    x: np.ndarray                    # (m,) parameter errors, layout of error_model.param_names
    std_errors: np.ndarray           # (m,) 1-sigma standard errors (0 for fixed parameters)
    names: tuple[str, ...]
    identifiability: Identifiability
    converged: bool
    num_steps: int
    before: dict                     # residual statistics of the nominal model
    after: dict                      # residual statistics of the calibrated model
    position_only: bool
    estimate_base: bool
    estimate_tool: bool

    def delta(self, name: str) -> float:
        return float(self.x[self.names.index(name)])

    def table(self) -> str:
        fixed = set(self.identifiability.fixed)
        lines = [f"{'parameter':>10s} {'delta':>14s} {'std err':>11s}"]
        for i, (n, v, s) in enumerate(zip(self.names, self.x, self.std_errors)):
            lines.append(f"{n:>10s} {v:14.8g} {s:11.3g}" + ("  (fixed: not identifiable)" if i in fixed else ""))
        return "\n".join(lines)


def _std_errors(robot, q, measured, x, ident, *, position_only, base, tool, sp, sr):
    m = len(x)
    cal = perturb(robot, jnp.asarray(x), base=base, tool=tool)
    J = np.asarray(identification_jacobian(cal, jnp.asarray(q), position_only=position_only, base=base, tool=tool))
    e = np.asarray(pose_error(jnp.asarray(measured), fk(cal, jnp.asarray(q))))
    e = e[..., :3] if position_only else e
    w = np.array([1 / sp] * 3 + [1 / sr] * 3)[: e.shape[-1]]
    A = (J * w[:, None]).reshape(-1, m)[:, list(ident.base)]
    r = (e * w).reshape(-1)
    dof = max(A.shape[0] - A.shape[1], 1)
    s2 = float(r @ r) / dof
    cov = s2 * np.linalg.pinv(A.T @ A)
    out = np.zeros(m)
    out[list(ident.base)] = np.sqrt(np.clip(np.diag(cov), 0, None))
    return out


def identify(robot: Robot, q, *, position_only=False, estimate_base=False, estimate_tool=False,
             rtol: float = 1e-8) -> Identifiability:
    """Identifiability analysis of the nominal model over the pose set ``q`` ``(K, n)``."""
    J = np.asarray(identification_jacobian(robot, jnp.asarray(q), position_only=position_only,
                                           base=estimate_base, tool=estimate_tool))
    return analyze(J, param_names(robot, base=estimate_base, tool=estimate_tool), rtol=rtol)


def calibrate(robot: Robot, q, measured, *, method: str = "gn", estimate_base: bool = False,
              estimate_tool: bool = False, position_only: bool = False, sigma_pos_mm: float | None = None,
              sigma_rot_rad: float | None = None, rtol: float = 1e-8, atol: float = 1e-10,
              max_steps: int = 50) -> CalibrationResult:
    """Calibrate ``robot`` from joint values ``q`` ``(K, n)`` and measured poses ``measured``
    ``(K, 4, 4)`` (mm; with ``position_only=True`` only the translation column is used).

    **Arguments**: ``method`` ``"gn"`` | ``"lm"`` (optimistix Gauss–Newton /
    Levenberg–Marquardt on the exact residual) | ``"linear"`` (one-shot pseudo-inverse around
    the nominal model); ``estimate_base`` / ``estimate_tool`` add 6 twist parameters each;
    ``sigma_pos_mm``, ``sigma_rot_rad`` weight position vs rotation rows by ``1/sigma`` (defaults
    1 mm and 1 mrad); ``rtol``/``atol``/``max_steps`` go to optimistix.

    **Returns** a :class:`CalibrationResult`; ``converged`` is False (never silently) when the
    solver hit ``max_steps`` or failed.
    """
    if method not in METHODS + ELIMINATION_METHODS:
        raise ValueError(f"method must be one of {METHODS + ELIMINATION_METHODS}, got {method!r}")
    q, measured = _check_inputs(robot, q, measured, batched=False)
    m = n_params(robot, base=estimate_base, tool=estimate_tool)
    rows = 3 if position_only else 6
    if q.shape[0] * rows < m:
        raise DataError(f"too few poses: {q.shape[0]} poses x {rows} rows = {q.shape[0] * rows} equations "
                        f"for {m} parameters")
    ident = identify(robot, q, position_only=position_only, estimate_base=estimate_base, estimate_tool=estimate_tool)
    sp, sr = _sigmas(position_only, sigma_pos_mm, sigma_rot_rad)
    if method in ELIMINATION_METHODS:
        x, ok, steps, _ = elimination.calibrate_design_batch(
            robot, q[None], measured[None], sp, sr, literal=method == "elimination-literal", max_steps=max_steps,
            tol=atol, position_only=position_only, base=estimate_base, tool=estimate_tool)
    else:
        x, ok, steps = _solve_batch(robot, q[None], measured[None], jnp.float64(sp), jnp.float64(sr), method=method,
                                    free=tuple(ident.base), m=m, position_only=position_only, base=estimate_base,
                                    tool=estimate_tool, rtol=rtol, atol=atol, max_steps=max_steps)
    x = np.asarray(x[0])
    if not np.all(np.isfinite(x)):
        raise DataError("the solver produced non-finite parameters; the data are probably inconsistent "
                        "with the robot (check units and joint order)")
    cal = perturb(robot, jnp.asarray(x), base=estimate_base, tool=estimate_tool)
    se = _std_errors(robot, q, measured, x, ident, position_only=position_only, base=estimate_base,
                     tool=estimate_tool, sp=sp, sr=sr)
    return CalibrationResult(
        robot=cal, nominal=robot, method=method, x=x, std_errors=se, names=tuple(ident.names), identifiability=ident,
        converged=bool(ok[0]), num_steps=int(steps[0]),
        before=residual_stats(robot, q, measured, position_only=position_only),
        after=residual_stats(cal, q, measured, position_only=position_only),
        position_only=position_only, estimate_base=estimate_base, estimate_tool=estimate_tool)


@dataclasses.dataclass(frozen=True)
class BatchResult:
    """What :func:`calibrate_batch` returns (leading axis: robots)."""

    x: np.ndarray           # (R, m)
    converged: np.ndarray   # (R,) bool
    num_steps: np.ndarray   # (R,)
    identifiability: Identifiability
    names: tuple[str, ...]
    method: str


def calibrate_batch(robot: Robot, q, measured, *, method: str = "gn", estimate_base: bool = False,
                    estimate_tool: bool = False, position_only: bool = False, sigma_pos_mm: float | None = None,
                    sigma_rot_rad: float | None = None, rtol: float = 1e-8, atol: float = 1e-10,
                    max_steps: int = 50, ident: Identifiability | None = None) -> BatchResult:
    """:func:`calibrate` for ``R`` data sets of the same nominal robot at once: ``q`` ``(R, K,
    n)``, ``measured`` ``(R, K, 4, 4)``; one compiled, vmapped call (no Python loop over
    robots). The base set comes from the first data set unless ``ident`` is given."""
    if method not in METHODS + ELIMINATION_METHODS:
        raise ValueError(f"method must be one of {METHODS + ELIMINATION_METHODS}, got {method!r}")
    q, measured = _check_inputs(robot, q, measured, batched=True)
    m = n_params(robot, base=estimate_base, tool=estimate_tool)
    if ident is None:
        ident = identify(robot, q[0], position_only=position_only, estimate_base=estimate_base,
                         estimate_tool=estimate_tool)
    sp, sr = _sigmas(position_only, sigma_pos_mm, sigma_rot_rad)
    if method in ELIMINATION_METHODS:
        x, ok, steps, _ = elimination.calibrate_design_batch(
            robot, q, measured, sp, sr, literal=method == "elimination-literal", max_steps=max_steps, tol=atol,
            position_only=position_only, base=estimate_base, tool=estimate_tool)
    else:
        x, ok, steps = _solve_batch(robot, q, measured, jnp.float64(sp), jnp.float64(sr), method=method,
                                    free=tuple(ident.base), m=m, position_only=position_only, base=estimate_base,
                                    tool=estimate_tool, rtol=rtol, atol=atol, max_steps=max_steps)
    return BatchResult(x=np.asarray(x), converged=np.asarray(ok), num_steps=np.asarray(steps),
                       identifiability=ident, names=tuple(ident.names), method=method)
