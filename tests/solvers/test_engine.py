"""The engine's Gauss–Newton (optimistix's Newton root finder on the whitened normal equations)
agrees with a plain Gauss–Newton loop written here in NumPy, step for step."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.testing import assert_allclose

import jaxcal
from jaxcal.solvers import fit, gauss_newton, outlier_threshold
from jaxcal.solvers._engine import chi2_isf, chi2_sf, tuning

COLUMN_SCALE = 1e3  # columns of the test problem near the engine's scaled size


def _problem(seed):
    """A small nonlinear least-squares problem with a non-zero residual at its minimum."""
    rng = np.random.default_rng(seed)
    M = rng.normal(size=(60, 4)) * COLUMN_SCALE / np.sqrt(60)
    b = rng.normal(size=60) * 0.1

    def r(z, xp):
        return xp.sin(M @ z / COLUMN_SCALE) * COLUMN_SCALE / 30 - b + 0.02 * (M @ z) ** 2 / COLUMN_SCALE**2

    def jac(z):
        c = np.cos(M @ z / COLUMN_SCALE) / 30
        return (c + 0.04 * (M @ z) / COLUMN_SCALE**2)[:, None] * M

    return r, jac


def _reference(r, jac, z, rtol=1e-8, atol=1e-8, max_steps=50):
    """Gauss–Newton in NumPy: solve J^T J dz = J^T r, move to z - dz, stop after a step within the
    tolerances. Returns the iterates."""
    out = [z]
    for _ in range(max_steps):
        J = jac(z)
        dz = np.linalg.solve(J.T @ J, J.T @ r(z, np))
        z = z - dz
        out.append(z)
        if np.max(np.abs(dz) / (atol + rtol * np.abs(z))) < 1:
            break
    return out


def test_gauss_newton_matches_the_reference_loop():
    r, jac = _problem(0)

    def normal(z, _):
        J = jax.jacfwd(lambda z_: r(z_, jnp))(z)
        return J.T @ J, J.T @ r(z, jnp)

    z0 = np.full(4, 0.3)
    ref = _reference(r, jac, z0)
    assert len(ref) >= 4  # three steps or more
    for steps in (1, len(ref) - 1):  # the same iterate after one step, and at the end
        z, ok, n = gauss_newton(normal, jnp.asarray(z0), None, max_steps=steps)
        assert_allclose(np.asarray(z), ref[steps], rtol=1e-9, atol=1e-12)
        assert int(n) == steps and bool(ok) == (steps == len(ref) - 1)
    grad = jac(ref[-1]).T @ r(ref[-1], np)
    assert np.max(np.abs(grad)) < 1e-6  # the end point is a minimum


def test_gauss_newton_reports_a_singular_system():
    def normal(z, _):  # the second parameter never enters the residual
        J = jnp.array([[1.0, 0.0], [2.0, 0.0]]) * COLUMN_SCALE
        return J.T @ J, J.T @ (J @ z - 1.0)

    z, ok, _ = gauss_newton(normal, jnp.zeros(2), None)
    assert not bool(ok)


def test_fit_gn_equals_the_reference_on_a_calibration():
    """``fit`` (GN) on a simulated UR5 ends where the NumPy loop on the same weighted residual ends."""
    robot = jaxcal.preset("ur5")
    sim = jaxcal.simulate(robot, n_poses=30, seed=3, sigma_pos=0.02)
    model = jaxcal.model.Model(robot)
    layout = jaxcal.model.Layout.of(robot)
    ident = jaxcal.calibration.identify(robot, sim.q[0], estimate_base=False, estimate_tool=False)
    free = tuple(int(i) for i in ident.base)
    weights = np.r_[np.full(3, 1 / 0.02), np.full(3, 1 / 1e-4)]
    q, T = jnp.asarray(sim.q[0]), jnp.asarray(sim.measured[0])
    sol = eqx.filter_jit(fit)(model, layout, free, q, T, weights=jnp.asarray(weights), method="gn")
    assert bool(sol.converged)

    def residual(y):
        x = jnp.zeros(layout.size).at[jnp.asarray(free)].set(y)
        return (jaxcal.model.errors(jaxcal.model.apply(model, layout, x), q, T) * weights).reshape(-1)

    # compiled once each, not one program per operation and step
    residual_jit, jac_jit = jax.jit(residual), jax.jit(jax.jacfwd(residual))

    def r(y, xp):
        e = residual_jit(jnp.asarray(y))
        return np.asarray(e) if xp is np else e

    def jac(y):
        return np.asarray(jac_jit(jnp.asarray(y)))

    ref = _reference(r, jac, np.zeros(len(free)))
    assert_allclose(np.asarray(sol.x)[list(free)], ref[-1], atol=1e-9)


def test_chi_square_quantiles_are_scipys():
    """The closed-form chi-square tail (the robust tuning, the outlier thresholds) against
    scipy.stats, for the row counts of positions, poses and several points."""
    from scipy.stats import chi2, norm

    for dof in range(1, 41):
        for x in (0.01, 0.5, 3.0, 20.0, 80.0):
            assert_allclose(chi2_sf(x, dof), chi2.sf(x, dof), rtol=1e-12, atol=1e-300)
        for p in (0.5, 0.05, 1e-4, norm.sf(5.0), 1e-12):
            assert_allclose(chi2_isf(p, dof), chi2.isf(p, dof), rtol=1e-12)
        assert_allclose(outlier_threshold(dof, 4.0), np.sqrt(chi2.isf(norm.sf(4.0), dof)), rtol=1e-12)
    assert_allclose(tuning(np.array([3, 6, 12])), np.sqrt(chi2.ppf(0.95, [3, 6, 12])), rtol=1e-12)
