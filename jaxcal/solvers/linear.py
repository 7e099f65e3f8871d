"""One-shot linear least squares around the nominal model (the paper's "traditional" method).

``dx = argmin |W (J dx - e)|^2`` with ``J`` the identification Jacobian (eq. 10) at the nominal
parameters and ``e = pose_error(measured, T_nominal)``: a single pseudo-inverse solve, no
re-linearisation, so it carries a linearisation error of order ``|dx|^2``.
"""

from __future__ import annotations

import jax.numpy as jnp

from ..error_model import identification_jacobian, pose_error
from ..kinematics import fk
from ..robot import Robot
from ._model import row_weights


def solve(robot: Robot, q, measured, *, free: tuple[int, ...], m: int, position_only: bool = False,
          base: bool = False, tool: bool = False, sigma_pos: float = 1.0, sigma_rot: float = 1e-3):
    """**Returns** ``(x, ok, num_steps)`` like the iterative solvers (``num_steps`` = 1; ``ok`` is
    False only if the solution is not finite)."""
    J = identification_jacobian(robot, q, position_only=position_only, base=base, tool=tool)
    e = pose_error(measured, fk(robot, q))
    if position_only:
        e = e[..., :3]
    w = row_weights(position_only, sigma_pos, sigma_rot)
    free_idx = jnp.asarray(free, dtype=jnp.int32)
    A = (J * w[:, None])[..., free_idx].reshape(-1, len(free))
    b = (e * w).reshape(-1)
    y = jnp.linalg.lstsq(A, b)[0]
    x = jnp.zeros(m).at[free_idx].set(y)
    return x, jnp.all(jnp.isfinite(y)), jnp.asarray(1)
