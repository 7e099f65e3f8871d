"""The polynomial sin/cos of the kinematics hot path (jaxcal.trig) against NumPy's libm, and
the joint-angle domain it is used on (kinematics.check_q)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpy.testing import assert_allclose

from jaxcal import DataError, Robot, fk
from jaxcal.robot import preset
from jaxcal.trig import DOMAIN, sincos

_sincos = jax.jit(sincos)


@pytest.mark.parametrize("scale", [1e-3, 1.0, 10.0, 1e3, DOMAIN])
def test_matches_numpy(scale):
    x = np.random.default_rng(7).uniform(-scale, scale, 200_000)
    s, c = map(np.asarray, _sincos(jnp.asarray(x)))
    assert np.abs(s - np.sin(x)).max() <= 2.3e-16
    assert np.abs(c - np.cos(x)).max() <= 2.3e-16


@pytest.mark.skipif(np.finfo(np.longdouble).nmant < 63, reason="needs x87 extended precision")
def test_polynomials_truncation_error():
    """The minimax coefficients themselves (typed in from fdlibm): evaluated in extended precision
    on |r| <= pi/4 against extended-precision sin/cos, the polynomials are off by less than
    3e-18 (an error in any coefficient's digits shows here, far above rounding)."""
    from jaxcal.trig import _C, _S

    r = np.linspace(-np.pi / 4, np.pi / 4, 20001).astype(np.longdouble)
    z = r * r

    def horner(cs):
        acc = np.longdouble(cs[-1])
        for c in cs[-2::-1]:
            acc = acc * z + np.longdouble(c)
        return acc

    assert np.abs(r + r * z * horner(_S) - np.sin(r)).max() < 3e-18
    assert np.abs(1 - z / 2 + z * z * horner(_C) - np.cos(r)).max() < 3e-18


def test_quadrant_boundaries_and_special_values():
    k = np.arange(-4000, 4001)
    eps = np.array([-1e-9, -2.2e-16, 0.0, 2.2e-16, 1e-9])
    x = np.concatenate([(k[:, None] * np.pi / 4 + eps).ravel(), [0.0, -0.0, 1e-300, -1e-300, 5e-324]])
    s, c = map(np.asarray, _sincos(jnp.asarray(x)))
    assert_allclose(s, np.sin(x), rtol=0, atol=2.3e-16)
    assert_allclose(c, np.cos(x), rtol=0, atol=2.3e-16)
    assert np.all(s[-3:-1] == x[-3:-1]) and np.all(c[-5:] == 1.0)  # sin x = x, cos x = 1 for tiny x


def test_derivative_is_exact():
    x = jnp.asarray(np.random.default_rng(8).uniform(-20, 20, 1000))
    dx = jnp.asarray(np.random.default_rng(9).normal(size=1000))
    _, (ds, dc) = jax.jvp(sincos, (x,), (dx,))
    assert_allclose(ds, np.cos(x) * dx, rtol=0, atol=5e-16 * 4)
    assert_allclose(dc, -np.sin(x) * dx, rtol=0, atol=5e-16 * 4)
    g = jax.vmap(jax.grad(lambda t: sincos(t)[0] * sincos(t)[1]))(x)  # d(sin cos) = cos 2x
    assert_allclose(g, np.cos(2 * np.asarray(x)), rtol=0, atol=1e-15)


def test_fk_refuses_angles_beyond_the_domain_and_non_finite_values():
    robot = preset("paper-6r")
    q = np.zeros((5, 6))
    q[3, 1] = 2 * DOMAIN
    with pytest.raises(DataError, match=r"q\[3, 1\] \(pose 3, joint 2\).*beyond"):
        fk(robot, q)
    q[3, 1], q[2, 4] = 0.0, np.nan
    with pytest.raises(DataError, match=r"q\[2, 4\] \(pose 2, joint 5\) is not finite"):
        fk(robot, q)
    fk(robot, np.full((1, 6), 0.99 * DOMAIN))  # the edge is allowed


def test_prismatic_values_are_lengths_not_angles():
    dh = np.array([[0.0, 0.0, 100.0, np.pi / 2], [0.0, 0.0, 50.0, 0.0]])
    robot = Robot(dh, joint_types=("R", "P"))
    q = np.array([[0.3, 2 * DOMAIN]])  # 200 m of travel: not refused
    T = np.asarray(fk(robot, q))[0]
    p_joint2 = np.array([100.0 * np.cos(0.3), 100.0 * np.sin(0.3), 0.0])  # after link 1
    assert_allclose(np.linalg.norm(T[:3, 3] - p_joint2), np.hypot(50.0, 2 * DOMAIN), rtol=1e-12)
