"""The error model (eq. 8-10) and the identification Jacobian against autodiff of the exact,
nonlinear pose error."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import random_dh, random_transform
from numpy.testing import assert_allclose

from jaxcal import Robot, fk
from jaxcal import error_model as E
from jaxcal.lie import hat, vee
from jaxcal.robot import preset


def _robots(rng):
    out = [preset("paper-6r"), preset("puma560"), preset("ur5"), preset("panda")]
    for conv in ("sdh", "mdh"):
        out.append(
            Robot(
                random_dh(rng),
                convention=conv,
                base=random_transform(rng),
                tool=random_transform(rng, 80.0),
                joint_types=("R", "P", "R", "R", "P", "R"),
            )
        )
    return out


def _true_error(robot, q, base, tool):
    T0 = fk(robot, q)
    return lambda x: E.pose_error(fk(E.perturb(robot, x, base=base, tool=tool), q), T0)


def test_identification_jacobian_matches_jacfwd(rng):
    """All columns (DH, base and tool) against autodiff of the exact nonlinear pose error, on
    one arm per structure: SDH and MDH presets, random SDH/MDH arms with prismatic joints."""
    robots = _robots(rng)
    for robot in [robots[0], robots[3]] + robots[4:]:
        Q = jnp.asarray(rng.uniform(-2, 2, (8, robot.n_joints)))
        m = E.n_params(robot, base=True, tool=True)
        J = E.identification_jacobian(robot, Q, base=True, tool=True)
        assert J.shape == (8, 6, m)
        ad = jax.jit(jax.vmap(lambda q: jax.jacfwd(_true_error(robot, q, True, True))(jnp.zeros(m))))(Q)
        scale = max(1.0, float(jnp.abs(ad).max()))
        assert_allclose(np.asarray(J), np.asarray(ad), atol=1e-12 * scale, rtol=0)


@pytest.mark.parametrize("base,tool", [(False, False), (True, False), (False, True)])
def test_jacobian_column_layout_without_frames(rng, base, tool):
    """Without base/tool columns the Jacobian is the full one (checked against autodiff above)
    with those columns dropped; position_only keeps the 3 position rows."""
    for robot in _robots(rng)[3:]:
        Q = jnp.asarray(rng.uniform(-2, 2, (8, robot.n_joints)))
        n4 = 4 * robot.n_joints
        full = np.asarray(E.identification_jacobian(robot, Q, base=True, tool=True))
        keep = (
            list(range(n4)) + (list(range(n4, n4 + 6)) if base else []) + (list(range(n4 + 6, n4 + 12)) if tool else [])
        )
        J = E.identification_jacobian(robot, Q, base=base, tool=tool)
        assert_allclose(np.asarray(J), full[..., keep], atol=1e-12, rtol=0)
        Jp = E.identification_jacobian(robot, Q, base=base, tool=tool, position_only=True)
        assert_allclose(np.asarray(Jp), full[..., :3, keep], atol=1e-12, rtol=0)


@pytest.mark.parametrize("base,tool,position_only", [(True, True, False), (False, False, True), (False, True, False)])
def test_jacobian_and_fk_is_the_two_calls_from_one_chain(rng, base, tool, position_only):
    """The fused call the solvers use returns the autodiff-checked Jacobian and the FK end pose."""
    for robot in _robots(rng)[3:]:
        Q = jnp.asarray(rng.uniform(-2, 2, (2, 4, robot.n_joints)))
        J, T = E.jacobian_and_fk(robot, Q, base=base, tool=tool, position_only=position_only)
        want = E.identification_jacobian(robot, Q, base=base, tool=tool, position_only=position_only)
        assert J.shape == want.shape and T.shape == (2, 4, 4, 4)
        assert_allclose(np.asarray(J), np.asarray(want), atol=1e-12, rtol=0)
        assert_allclose(np.asarray(T), np.asarray(fk(robot, Q)), atol=1e-9, rtol=0)


def test_jacobians_keep_leading_axes_and_vmap_over_robots(rng):
    robots = [
        Robot(random_dh(rng), convention="mdh", base=random_transform(rng), tool=random_transform(rng, 80.0))
        for _ in range(3)
    ]
    Q = jnp.asarray(rng.uniform(-2, 2, (2, 4, 6)))
    for fn in (E.identification_jacobian, E.twist_jacobian):
        J = fn(robots[0], Q, base=True, tool=True)
        assert J.shape == (2, 4, 6, 36)
        flat = fn(robots[0], Q.reshape(-1, 6), base=True, tool=True)
        assert_allclose(np.asarray(J).reshape(-1, 6, 36), np.asarray(flat), atol=1e-12)
        stacked = jax.tree.map(lambda *x: jnp.stack(x), *robots)
        batched = jax.vmap(lambda r: fn(r, Q[0], base=True, tool=True))(stacked)
        for r, got in zip(robots, batched):
            assert_allclose(np.asarray(got), np.asarray(fn(r, Q[0], base=True, tool=True)), atol=1e-9)


def test_twist_jacobian_frames_map_to_the_autodiff_checked_pose_rows(rng):
    """Twist columns (base and tool included) through dp = v + w x p_end are the identification
    Jacobian's pose rows (checked against jax.jacfwd elsewhere)."""
    for robot in _robots(rng):
        robot = robot.replace(base=random_transform(rng), tool=random_transform(rng, 80.0))
        Q = jnp.asarray(rng.uniform(-2, 2, (7, robot.n_joints)))
        tw = E.twist_jacobian(robot, Q, base=True, tool=True)
        want = E.identification_jacobian(robot, Q, base=True, tool=True)
        got = E.twist_to_pose_rows(tw, fk(robot, Q)[:, :3, 3])
        assert_allclose(np.asarray(got), np.asarray(want), atol=1e-9 * float(np.abs(want).max()))


def test_eq10_literal_sum_equals_adjoint_form(rng):
    for robot in _robots(rng):
        Q = jnp.asarray(rng.uniform(-2, 2, (10, robot.n_joints)))
        delta = jnp.asarray(rng.normal(size=(robot.n_joints, 4)))
        # one program per robot, not one per operation
        M, H = jax.jit(lambda Q, d: (E.error_twist_matrix(robot, Q, d), hat(E.twist_jacobian(robot, Q) @ d.ravel())))(
            Q, delta
        )
        assert_allclose(np.asarray(M), np.asarray(H), atol=1e-9)


def test_eq10_is_dT_Tinv_to_first_order(rng):
    """(T(p + eps*delta) - T(p)) T^{-1} / eps -> sum_i T_i Omega_i T_i^{-1} as eps -> 0."""
    robot = preset("paper-6r")
    q = jnp.asarray(rng.uniform(-2, 2, 6))
    delta = jnp.asarray(rng.normal(size=(6, 4)))
    M = np.asarray(E.error_twist_matrix(robot, q, delta))
    T = np.asarray(fk(robot, q))
    errs = []
    for eps in (1e-3, 5e-4):
        Tp = np.asarray(fk(robot.with_dh_delta(eps * delta), q))
        errs.append(np.abs((Tp - T) @ np.linalg.inv(T) / eps - M).max())
    assert errs[0] / errs[1] == pytest.approx(2.0, rel=0.05)  # O(eps) remainder
    assert errs[1] < 1e-2 * np.abs(M).max()


@pytest.mark.parametrize("name", ["paper-6r", "panda"])
def test_first_order_model_error_is_quadratic(name, rng):
    """|e_true(s d) - J s d| = O(s^2): halving s divides the remainder by 4."""
    robot = preset(name)
    Q = jnp.asarray(rng.uniform(-2, 2, (20, robot.n_joints)))
    m = E.n_params(robot, base=True, tool=True)
    d = jnp.asarray(rng.normal(size=m)) * jnp.where(jnp.arange(m) % 4 % 2 == 0, 1e-2, 1.0)
    J = E.identification_jacobian(robot, Q, base=True, tool=True)
    remainder = jax.jit(
        lambda s: jnp.abs(jax.vmap(lambda q: _true_error(robot, q, True, True)(s * d))(Q) - J @ (s * d)).max()
    )
    rem = [float(remainder(s)) for s in (1e-2, 5e-3, 2.5e-3)]
    r1, r2 = rem[0] / rem[1], rem[1] / rem[2]
    assert 3.6 < r1 < 4.4 and 3.6 < r2 < 4.4, (rem, r1, r2)


def test_vee_hat_roundtrip(rng):
    xi = jnp.asarray(rng.normal(size=(5, 6)))
    assert_allclose(np.asarray(vee(hat(xi))), np.asarray(xi))


def test_param_names_and_layout():
    r = preset("paper-6r")
    names = E.param_names(r, base=True, tool=True)
    assert len(names) == E.n_params(r, base=True, tool=True) == 36
    assert names[:5] == ["theta1", "d1", "a1", "alpha1", "theta2"]
    assert names[24] == "base_x" and names[-1] == "tool_rz"


def test_base_and_tool_errors_are_applied_as_documented(rng):
    """docs/conventions.md: the base ``[exp(w) R_B | t_B + v]``, the tool ``[R_X exp(w) | t_X +
    R_X v]``, written here with scipy's rotation vectors, not jaxcal's Lie helpers."""
    from scipy.spatial.transform import Rotation

    robot = Robot(random_dh(rng), base=random_transform(rng, 1000.0), tool=random_transform(rng, 80.0))
    x = np.zeros(robot.n_joints * 4 + 12)
    x[-12:] = rng.normal(0.0, [2.0, 2.0, 2.0, 0.01, 0.01, 0.01] * 2)
    out = E.perturb(robot, x, base=True, tool=True)
    B, X = np.asarray(robot.base), np.asarray(robot.tool)
    vb, wb, vt, wt = x[-12:-9], x[-9:-6], x[-6:-3], x[-3:]
    want_B, want_X = np.eye(4), np.eye(4)
    want_B[:3, :3], want_B[:3, 3] = Rotation.from_rotvec(wb).as_matrix() @ B[:3, :3], B[:3, 3] + vb
    want_X[:3, :3], want_X[:3, 3] = X[:3, :3] @ Rotation.from_rotvec(wt).as_matrix(), X[:3, 3] + X[:3, :3] @ vt
    assert_allclose(np.asarray(out.base), want_B, atol=1e-9)
    assert_allclose(np.asarray(out.tool), want_X, atol=1e-9)
