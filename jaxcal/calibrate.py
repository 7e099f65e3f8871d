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


def _check_inputs(robot: Robot, q, measured, batched: bool, position_only: bool = False):
    if not isinstance(robot, Robot):
        raise DataError(f"robot must be a jaxcal.Robot, got {type(robot).__name__}")
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
    Mn = np.asarray(measured)
    bad_row = np.abs(Mn[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0])).max(-1) > 1e-9
    if bad_row.any():
        idx = tuple(int(i) for i in np.argwhere(bad_row)[0])
        raise DataError(f"measured{list(idx)}: bottom row is {Mn[idx][3].tolist()}, not [0, 0, 0, 1]")
    if not position_only:
        R = Mn[..., :3, :3]
        err = np.abs(R @ np.swapaxes(R, -1, -2) - np.eye(3)).max((-1, -2))
        bad_rot = (err > 1e-6) | (np.linalg.det(R) < 0)
        if bad_rot.any():
            idx = tuple(int(i) for i in np.argwhere(bad_rot)[0])
            raise DataError(f"measured{list(idx)}: rotation is not a proper rotation matrix (|R R^T - I| = "
                            f"{err[idx]:.3g}); {int(bad_rot.sum())} such pose(s); use position_only=True if "
                            "only positions were measured")
    return q, measured


def _check_units(robot: Robot, q, measured, batched: bool):
    """Refuse a length-unit mismatch: the spread of the measured points (RMS distance to their
    centroid, independent of the unknown measurement frame) must be within 3x of the nominal
    model's at the same joint values (m read as mm gives 1000x)."""
    Q, M = (q, measured) if batched else (q[None], measured[None])
    if Q.shape[1] < 2:
        return
    P_mod = np.asarray(fk(robot, Q))[..., :3, 3]
    P_mea = np.asarray(M)[..., :3, 3]

    def spread(P):
        return np.sqrt(np.mean(np.sum((P - P.mean(-2, keepdims=True)) ** 2, -1), -1))

    s_mod, s_mea = spread(P_mod), spread(P_mea)
    for i, (a, b) in enumerate(zip(s_mod, s_mea)):
        if a > 1.0 and not (a / 3.0 <= b <= 3.0 * a):
            where = f" (data set {i})" if batched else ""
            raise DataError(f"measured{where}: positions spread {b:.4g} mm around their centroid, the nominal "
                            f"model's {a:.4g} mm at the same joint values: lengths must be in mm (were they "
                            f"given in metres?) and q in rad")


def _check_options(method, sigma_pos_mm, sigma_rot_rad, max_steps, loss, loss_scale):
    if method not in METHODS + ELIMINATION_METHODS:
        raise DataError(f"method must be one of {METHODS + ELIMINATION_METHODS}, got {method!r}")
    for name, v in (("sigma_pos_mm", sigma_pos_mm), ("sigma_rot_rad", sigma_rot_rad), ("loss_scale", loss_scale)):
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not np.isfinite(v) \
                or v < 0 or (name == "loss_scale" and v == 0):
            raise DataError(f"{name} must be a finite {'positive' if name == 'loss_scale' else 'non-negative'} "
                            f"number (or None), got {v!r}")
    if isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)) or max_steps < 1:
        raise DataError(f"max_steps must be an integer >= 1, got {max_steps!r}")
    if loss not in least_squares.LOSSES:
        raise DataError(f"loss must be one of {least_squares.LOSSES}, got {loss!r}")
    if loss != "l2" and method not in ("gn", "lm"):
        raise DataError(f"loss={loss!r} needs method 'gn' or 'lm' (iteratively reweighted), got {method!r}")


def _prepare(robot, q, measured, *, batched, method, sigma_pos_mm, sigma_rot_rad, max_steps, loss, loss_scale,
             position_only, estimate_base, estimate_tool):
    """Validate options and data (shapes, finiteness, rigid poses, units, enough poses); return
    ``(q, measured, m, rows)``: float64 arrays, the number of parameters, rows per pose."""
    _check_options(method, sigma_pos_mm, sigma_rot_rad, max_steps, loss, loss_scale)
    q, measured = _check_inputs(robot, q, measured, batched=batched, position_only=position_only)
    _check_units(robot, q, measured, batched=batched)
    m = n_params(robot, base=estimate_base, tool=estimate_tool)
    rows = 3 if position_only else 6
    k = q.shape[-2]
    if k * rows < m:
        raise DataError(f"too few poses: {k} poses x {rows} rows = {k * rows} equations for {m} parameters")
    return q, measured, m, rows


def _sigmas(position_only, sigma_pos_mm, sigma_rot_rad):
    """Row weights ``1/sigma``; None or 0 means the default (1 mm, 1 mrad)."""
    sp = 1.0 if sigma_pos_mm is None or sigma_pos_mm <= 0 else float(sigma_pos_mm)
    sr = 1e-3 if sigma_rot_rad is None or sigma_rot_rad <= 0 else float(sigma_rot_rad)
    return sp, sr


@eqx.filter_jit
def _solve_batch(robot, q, measured, sig_pos, sig_rot, *, method, free, m, position_only, base, tool,
                 rtol, atol, max_steps, loss="l2", loss_scale=None):
    def one(q_, meas_):
        if method == "linear":
            return linear.solve(robot, q_, meas_, free=free, m=m, position_only=position_only, base=base,
                                tool=tool, sigma_pos=sig_pos, sigma_rot=sig_rot)
        return least_squares.solve(robot, q_, meas_, free=free, m=m, method=method, position_only=position_only,
                                   base=base, tool=tool, sigma_pos=sig_pos, sigma_rot=sig_rot, rtol=rtol,
                                   atol=atol, max_steps=max_steps, loss=loss, loss_scale=loss_scale)

    return jax.vmap(one)(q, measured)


@eqx.filter_jit
def _pose_norms(robot, x, q, measured, sig_pos, sig_rot, *, position_only, base, tool):
    """Per-pose norms of the weighted residual rows of the model ``perturb(robot, x)``,
    batched over a leading robot axis: ``(R, K)``."""
    from .solvers._model import row_weights

    def one(x_, q_, m_):
        e = pose_error(m_, fk(perturb(robot, x_, base=base, tool=tool), q_))
        e = e[..., :3] if position_only else e
        return jnp.linalg.norm(e * row_weights(position_only, sig_pos, sig_rot), axis=-1)

    return jax.vmap(one)(x, q, measured)


def _outlier_report(norms, dof, loss, loss_scale):
    """``(scale, outlier mask, degraded)`` per data set from per-pose residual norms ``(R, K)``.

    An outlier is a pose whose norm exceeds ``OUTLIER_K[dof]`` robust scales; a plain (L2) fit
    with outliers is *degraded* (least squares spreads them over every parameter); a robust fit
    is degraded only if more than a third of the poses are outliers (then the robust scale
    itself is not trustworthy)."""
    norms = np.asarray(norms)
    if loss_scale is None:
        scale = np.maximum(np.median(norms, -1) / np.sqrt(least_squares._CHI2_MEDIAN[dof]), least_squares.SCALE_FLOOR)
    else:
        scale = np.full(norms.shape[0], float(loss_scale))
    mask = norms > least_squares.OUTLIER_K[dof] * scale[:, None]
    frac = mask.mean(-1)
    degraded = (frac > 1 / 3) if loss != "l2" else mask.any(-1)
    return scale, mask, degraded


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
    loss: str = "l2"
    outliers: tuple[int, ...] = ()  # pose indices whose standardised residual norm is > OUTLIER_K
    degraded: bool = False          # True: outliers spoil this fit (plain L2 fit with outliers) -> try loss="huber"
    robust_scale: float = float("nan")  # per-row noise scale (weighted units) used to judge outliers

    def not_identified(self) -> dict[str, str]:
        """``{parameter: why}`` for every parameter held at 0 (see :meth:`Identifiability.reasons`)."""
        return self.identifiability.reasons()

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
              max_steps: int = 50, loss: str = "l2", loss_scale: float | None = None) -> CalibrationResult:
    """Calibrate ``robot`` from joint values ``q`` ``(K, n)`` and measured poses ``measured``
    ``(K, 4, 4)`` (mm; with ``position_only=True`` only the translation column is used).

    **Arguments**: ``method`` ``"gn"`` | ``"lm"`` (optimistix Gauss–Newton /
    Levenberg–Marquardt on the exact residual) | ``"linear"`` (one-shot pseudo-inverse around
    the nominal model); ``estimate_base`` / ``estimate_tool`` add 6 twist parameters each;
    ``sigma_pos_mm``, ``sigma_rot_rad`` weight position vs rotation rows by ``1/sigma`` (defaults
    1 mm and 1 mrad); ``rtol``/``atol``/``max_steps`` go to optimistix; ``loss`` ``"l2"`` |
    ``"huber"`` | ``"cauchy"`` (robust, gn/lm only: iteratively reweighted, see
    :mod:`jaxcal.solvers.least_squares`), ``loss_scale`` the noise scale per residual row in
    weighted units (``1`` = one sigma; default: a robust estimate from the residuals).

    **Returns** a :class:`CalibrationResult`; ``converged`` is False (never silently) when the
    solver hit ``max_steps`` or failed; ``outliers`` the pose indices with gross residuals and
    ``degraded`` True when a plain fit is spoiled by them; ``not_identified()`` says which
    parameters were held at 0 and why.

    **Raises** :class:`jaxcal.DataError` for bad input (shapes, non-finite values, poses that are
    not rigid transforms, lengths apparently not in mm, too few poses, bad options) and when
    the solver produces non-finite parameters.
    """
    q, measured, m, rows = _prepare(robot, q, measured, batched=False, method=method, sigma_pos_mm=sigma_pos_mm,
                                    sigma_rot_rad=sigma_rot_rad, max_steps=max_steps, loss=loss,
                                    loss_scale=loss_scale, position_only=position_only,
                                    estimate_base=estimate_base, estimate_tool=estimate_tool)
    ident = identify(robot, q, position_only=position_only, estimate_base=estimate_base, estimate_tool=estimate_tool)
    sp, sr = _sigmas(position_only, sigma_pos_mm, sigma_rot_rad)
    if method in ELIMINATION_METHODS:
        x, ok, steps, _ = elimination.calibrate_design_batch(
            robot, q[None], measured[None], sp, sr, literal=method == "elimination-literal", max_steps=max_steps,
            tol=atol, position_only=position_only, base=estimate_base, tool=estimate_tool)
    else:
        x, ok, steps = _solve_batch(robot, q[None], measured[None], jnp.float64(sp), jnp.float64(sr), method=method,
                                    free=tuple(ident.base), m=m, position_only=position_only, base=estimate_base,
                                    tool=estimate_tool, rtol=rtol, atol=atol, max_steps=max_steps, loss=loss,
                                    loss_scale=None if loss_scale is None else jnp.float64(loss_scale))
    x = np.asarray(x[0])
    if not np.all(np.isfinite(x)):
        raise DataError("the solver produced non-finite parameters; the data are probably inconsistent "
                        "with the robot (check units and joint order)")
    cal = perturb(robot, jnp.asarray(x), base=estimate_base, tool=estimate_tool)
    norms = _pose_norms(robot, jnp.asarray(x)[None], q[None], measured[None], jnp.float64(sp), jnp.float64(sr),
                        position_only=position_only, base=estimate_base, tool=estimate_tool)
    scale, mask, degraded = _outlier_report(norms, rows, loss, loss_scale)
    se = _std_errors(robot, q, measured, x, ident, position_only=position_only, base=estimate_base,
                     tool=estimate_tool, sp=sp, sr=sr)
    return CalibrationResult(
        robot=cal, nominal=robot, method=method, x=x, std_errors=se, names=tuple(ident.names), identifiability=ident,
        converged=bool(ok[0]), num_steps=int(steps[0]),
        before=residual_stats(robot, q, measured, position_only=position_only),
        after=residual_stats(cal, q, measured, position_only=position_only),
        position_only=position_only, estimate_base=estimate_base, estimate_tool=estimate_tool, loss=loss,
        outliers=tuple(int(i) for i in np.flatnonzero(mask[0])), degraded=bool(degraded[0]),
        robust_scale=float(scale[0]))


@dataclasses.dataclass(frozen=True)
class BatchResult:
    """What :func:`calibrate_batch` returns (leading axis: robots)."""

    x: np.ndarray           # (R, m)
    converged: np.ndarray   # (R,) bool
    num_steps: np.ndarray   # (R,)
    identifiability: Identifiability
    names: tuple[str, ...]
    method: str
    loss: str = "l2"
    outlier_mask: np.ndarray | None = None  # (R, K) bool: gross residual (see CalibrationResult.outliers)
    degraded: np.ndarray | None = None      # (R,) bool
    nonfinite: np.ndarray | None = None     # (R,) bool: solver gave non-finite values; x set to 0, not converged

    def outliers(self, i: int) -> tuple[int, ...]:
        """Pose indices flagged as outliers in data set ``i``."""
        return tuple(int(k) for k in np.flatnonzero(self.outlier_mask[i]))


def calibrate_batch(robot: Robot, q, measured, *, method: str = "gn", estimate_base: bool = False,
                    estimate_tool: bool = False, position_only: bool = False, sigma_pos_mm: float | None = None,
                    sigma_rot_rad: float | None = None, rtol: float = 1e-8, atol: float = 1e-10,
                    max_steps: int = 50, ident: Identifiability | None = None, loss: str = "l2",
                    loss_scale: float | None = None) -> BatchResult:
    """:func:`calibrate` for ``R`` data sets of the same nominal robot at once: ``q`` ``(R, K,
    n)``, ``measured`` ``(R, K, 4, 4)``; one compiled, vmapped call (no Python loop over
    robots). The base set comes from the first data set unless ``ident`` is given. A data set
    whose solve gives non-finite values is reported (``nonfinite``, ``converged`` False) with
    ``x`` = 0, never NaN."""
    q, measured, m, rows = _prepare(robot, q, measured, batched=True, method=method, sigma_pos_mm=sigma_pos_mm,
                                    sigma_rot_rad=sigma_rot_rad, max_steps=max_steps, loss=loss,
                                    loss_scale=loss_scale, position_only=position_only,
                                    estimate_base=estimate_base, estimate_tool=estimate_tool)
    if ident is not None and tuple(ident.names) != tuple(param_names(robot, base=estimate_base, tool=estimate_tool)):
        raise DataError(f"ident is for parameters {ident.names[:3]}... ({len(ident.names)}), this calibration "
                        f"has {m}: pass the analysis of the same robot, base and tool options")
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
                                    tool=estimate_tool, rtol=rtol, atol=atol, max_steps=max_steps, loss=loss,
                                    loss_scale=None if loss_scale is None else jnp.float64(loss_scale))
    x, ok = np.array(x), np.array(ok)
    nonfinite = ~np.all(np.isfinite(x), axis=-1)
    x[nonfinite] = 0.0
    ok[nonfinite] = False
    norms = _pose_norms(robot, jnp.asarray(x), q, measured, jnp.float64(sp), jnp.float64(sr),
                        position_only=position_only, base=estimate_base, tool=estimate_tool)
    _, mask, degraded = _outlier_report(norms, rows, loss, loss_scale)
    return BatchResult(x=x, converged=ok, num_steps=np.asarray(steps), identifiability=ident,
                       names=tuple(ident.names), method=method, loss=loss, outlier_mask=mask, degraded=degraded,
                       nonfinite=nonfinite)
