"""Iterated Gauss–Newton and Levenberg–Marquardt on the exact nonlinear residual, through
optimistix (``optx.least_squares``).

Only the identifiable (base) parameters ``free`` are estimated; the others stay at zero. The
functions here are pure and vmappable: :func:`solve` handles one robot's data, the caller
vmaps over robots (see :mod:`jaxcal.calibrate`).

## Robust losses (outliers)
``loss="huber"`` or ``"cauchy"`` runs iteratively reweighted least squares (IRLS): a fixed
number of outer rounds (``lax.fori_loop``, so one compiled solve) around the optimistix solve.
Round 0 is the plain (L2) fit; each later round weights every *pose* by
``rho'(u_k) / u_k`` of its standardised residual norm ``u_k = |r_k| / s`` (``r_k`` the 3 or 6
weighted residual rows of pose k) and refits, warm-started. ``s`` is the per-row noise scale:
``loss_scale`` if given, else the robust estimate :func:`robust_scale`
``median_k |r_k| / sqrt(median chi2_dof)`` (consistent for Gaussian noise, unaffected by up to
half the poses being gross outliers), floored at ``SCALE_FLOOR``. Weights
(``c = sqrt(chi2_dof(0.95))``, 2.80 for 3 rows, 3.55 for 6):

* Huber: ``w = min(1, c / u)``;
* Cauchy: ``w = 1 / (1 + (u / c)^2)``.

A pose is an **outlier** when ``u_k > OUTLIER_K[dof]`` (``sqrt(chi2_dof(0.9999))``: 4.59 for 3
rows, 5.28 for 6).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import lineax as lx
import optimistix as optx

from ..robot import Robot
from ._model import make_residual, row_weights


LOSSES = ("l2", "huber", "cauchy")
SCALE_FLOOR = 1e-3
"""Smallest robust scale (weighted-residual units, i.e. 1e-3 sigma): noise-free fits do not
turn rounding noise into outliers."""
_CHI2_MEDIAN = {3: 2.3659738843753377, 6: 5.348120627447118}
TUNING = {3: 2.7954834829151074, 6: 3.54846265920102}   # sqrt(chi2_dof(0.95))
OUTLIER_K = {3: 4.594291399787397, 6: 5.277910688521943}  # sqrt(chi2_dof(0.9999))


def robust_scale(norms, dof: int):
    """Per-row noise scale from per-pose residual norms ``(K,)``: ``median |r_k| /
    sqrt(median chi2_dof)``, floored at :data:`SCALE_FLOOR`."""
    return jnp.maximum(jnp.median(norms) / jnp.sqrt(_CHI2_MEDIAN[dof]), SCALE_FLOOR)


def robust_weights(norms, scale, dof: int, loss: str):
    """Per-pose IRLS weights ``rho'(u)/u`` for ``u = norms / scale`` (see the module docstring)."""
    u = norms / scale
    c = TUNING[dof]
    if loss == "huber":
        return jnp.minimum(1.0, c / jnp.maximum(u, 1e-300))
    if loss == "cauchy":
        return 1.0 / (1.0 + (u / c) ** 2)
    return jnp.ones_like(u)


def make_solver(method: str, rtol: float, atol: float):
    if method == "gn":
        # QR on the base (full-rank) set; a rank-deficient free set is excluded beforehand
        return optx.GaussNewton(rtol=rtol, atol=atol, linear_solver=lx.QR())
    if method == "lm":
        return optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    raise ValueError(f"unknown least-squares method {method!r}: use 'gn' or 'lm'")


def solve(robot: Robot, q, measured, *, free: tuple[int, ...], m: int, method: str = "gn",
          position_only: bool = False, base: bool = False, tool: bool = False,
          sigma_pos: float = 1.0, sigma_rot: float = 1e-3, rtol: float = 1e-8, atol: float = 1e-10,
          max_steps: int = 50, x0=None, loss: str = "l2", loss_scale=None, rounds: int = 6):
    """Minimise ``sum_k |W pose_error(measured_k, T(x, q_k))|^2`` over ``x[free]``.

    **Arguments**: ``q`` ``(K, n)``, ``measured`` ``(K, 4, 4)``; ``free`` the indices of the
    estimated parameters in the full vector of length ``m``; ``sigma_pos`` (mm) and
    ``sigma_rot`` (rad) weight the residual rows by ``1/sigma``; ``x0`` optional start (full
    vector, default zero); ``loss`` ``"l2"`` | ``"huber"`` | ``"cauchy"`` (IRLS with ``rounds``
    outer rounds, see the module docstring), ``loss_scale`` the per-row noise scale in weighted
    units (None or NaN: robust estimate).

    **Returns** ``(x, ok, num_steps)``: the full parameter vector, whether optimistix reported
    success, and the number of steps taken.
    """
    w = row_weights(position_only, sigma_pos, sigma_rot)
    residual = make_residual(robot, base=base, tool=tool, position_only=position_only, weights=w)
    free_idx = jnp.asarray(free, dtype=jnp.int32)
    x_start = jnp.zeros(m) if x0 is None else jnp.asarray(x0)

    def full(y):
        return x_start.at[free_idx].set(y)

    def fn(y, args):
        q_, meas_, sqrt_w = args
        r = residual(full(y), q_, meas_)
        return (r.reshape(sqrt_w.shape[0], -1) * sqrt_w[:, None]).reshape(-1)

    solver = make_solver(method, rtol, atol)

    def fit(y0, pose_w):
        sol = optx.least_squares(fn, solver, y0, args=(q, measured, jnp.sqrt(pose_w)), max_steps=max_steps,
                                 throw=False)
        return sol.value, sol.result == optx.RESULTS.successful, sol.stats["num_steps"]

    K = q.shape[0]
    y, ok, steps = fit(x_start[free_idx], jnp.ones(K))
    if loss == "l2":
        return full(y), ok, steps
    if loss not in LOSSES:
        raise ValueError(f"unknown loss {loss!r}: use one of {LOSSES}")
    dof = w.shape[0]
    given = jnp.asarray(jnp.nan if loss_scale is None else loss_scale, dtype=jnp.float64)

    def outer(_, c):
        y_, ok_, steps_ = c
        norms = jnp.linalg.norm(residual(full(y_), q, measured).reshape(K, dof), axis=-1)
        scale = jnp.where(jnp.isnan(given), robust_scale(norms, dof), given)
        y2, ok2, s2 = fit(y_, robust_weights(norms, scale, dof, loss))
        return y2, ok2, steps_ + s2

    y, ok, steps = jax.lax.fori_loop(0, rounds, outer, (y, ok, steps))
    return full(y), ok, steps
