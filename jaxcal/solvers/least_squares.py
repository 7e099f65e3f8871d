"""Iterated Gauss–Newton and Levenberg–Marquardt on the exact nonlinear residual, through
optimistix (``optx.least_squares``).

Only the identifiable (base) parameters ``free`` are estimated; the others stay at zero. The
functions here are pure and vmappable: :func:`solve` handles one robot's data, the caller
vmaps over robots (see :mod:`jaxcal.calibrate`).
"""

from __future__ import annotations

import jax.numpy as jnp
import lineax as lx
import optimistix as optx

from ..robot import Robot
from ._model import make_residual, row_weights


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
          max_steps: int = 50, x0=None):
    """Minimise ``sum_k |W pose_error(measured_k, T(x, q_k))|^2`` over ``x[free]``.

    **Arguments**: ``q`` ``(K, n)``, ``measured`` ``(K, 4, 4)``; ``free`` the indices of the
    estimated parameters in the full vector of length ``m``; ``sigma_pos`` (mm) and
    ``sigma_rot`` (rad) weight the residual rows by ``1/sigma``; ``x0`` optional start (full
    vector, default zero).

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
        q_, meas_ = args
        return residual(full(y), q_, meas_)

    sol = optx.least_squares(fn, make_solver(method, rtol, atol), x_start[free_idx], args=(q, measured),
                             max_steps=max_steps, throw=False)
    ok = sol.result == optx.RESULTS.successful
    return full(sol.value), ok, sol.stats["num_steps"]
