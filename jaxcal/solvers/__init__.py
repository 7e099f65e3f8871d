"""Calibration solvers. Each ``solve(robot, q, measured, *, free, m, ...)`` is pure and
vmappable and returns ``(x, ok, num_steps)``."""

from . import least_squares, linear

__all__ = ["least_squares", "linear"]
