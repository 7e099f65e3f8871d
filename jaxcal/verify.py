"""`jaxcal verify`: every analytic matrix of the paper (eq. 3-10), and the joint-frame model's
identification Jacobian, against ``jax.jacfwd``.

A self-check a user can run on their own machine; the test suite checks the same things with
tighter sweeps.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from . import derivatives as D
from . import error_model as E
from . import kinematics as K
from .errors import DataError
from .lie import hat
from .robot import PRESETS, preset


def _ad_partials(conv, P):
    f = lambda p: jnp.moveaxis(jax.jacfwd(lambda x: K.LINKS[conv](*x))(p), -1, 0)
    return np.asarray(jax.vmap(f)(jnp.asarray(P)))


def check_all(n_points: int = 2000, seed: int = 0) -> list[tuple[str, float, float]]:
    """Rows ``(what, max abs error, tolerance)`` for every analytic matrix."""
    if n_points < 40:
        raise DataError(
            f"points must be >= 40 (the fixed special-angle points come first), got {n_points}", option="points"
        )
    if seed < 0:
        raise DataError(f"seed must be >= 0, got {seed}", option="seed")
    rng = np.random.default_rng(seed)
    P = np.c_[
        rng.uniform(-7, 7, n_points),
        rng.uniform(-1e3, 1e3, n_points),
        rng.uniform(-1e3, 1e3, n_points),
        rng.uniform(-7, 7, n_points),
    ]
    P[:40, 3] = np.tile([0.0, np.pi / 2, -np.pi / 2, np.pi], 10)
    rows = []
    for conv in ("sdh", "mdh"):
        ad = _ad_partials(conv, P)
        A = np.asarray(K.LINKS[conv](*P.T))
        rows.append(
            (
                f"{conv.upper()} dA/dp (eq. {4 if conv == 'sdh' else 6})",
                float(np.abs(np.asarray(D.PARTIALS[conv](*P.T)) - ad).max()),
                1e-11,
            )
        )
        om = np.linalg.solve(A[:, None], ad)
        rows.append(
            (
                f"{conv.upper()} Omega = A^-1 dA/dp (eq. {5 if conv == 'sdh' else 7})",
                float(np.abs(np.asarray(D.OMEGAS[conv](*P.T)) - om).max()),
                1e-8,
            )
        )
    for name in PRESETS:
        robot = preset(name)
        Q = jnp.asarray(rng.uniform(-2, 2, (20, robot.n_joints)))
        for r, what in ((robot, "eq. 10, adjoint form"), (K.to_joint(robot), "joint frames")):
            m = E.n_params(r, base=True, tool=True)
            J = E.identification_jacobian(r, Q, base=True, tool=True)

            def true_err(x, q, r=r):
                return E.pose_error(K.fk(E.perturb(r, x, base=True, tool=True), q), K.fk(r, q))

            ad = jax.vmap(lambda q, m=m, true_err=true_err: jax.jacfwd(true_err)(jnp.zeros(m), q))(Q)
            rows.append((f"identification Jacobian, {name} ({what})", float(jnp.abs(J - ad).max()), 1e-9))
        d = jnp.asarray(rng.normal(size=(robot.n_joints, 4)))
        lit = E.error_twist_matrix(robot, Q, d)
        adj = E.twist_jacobian(robot, Q) @ d.ravel()
        rows.append((f"eq. 10 literal 4x4 sum vs adjoint form, {name}", float(jnp.abs(lit - hat(adj)).max()), 1e-9))
    return rows
