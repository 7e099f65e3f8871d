"""Joint compliance (jaxcal.Robot.compliance): gravity moments against the virtual-work formula,
the deflected forward kinematics, the identification Jacobian against autodiff, and the robot
files carrying it."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpy.testing import assert_allclose

import jaxcal
from jaxcal.kinematics import gravity_moments, to_joint
from jaxcal.model import Layout, Model, apply, errors, predict, residual_and_jacobian

ROBOTS = {"sdh": lambda: jaxcal.preset("ur5"), "mdh": lambda: jaxcal.preset("panda")}
ROBOTS["joint"] = lambda: to_joint(jaxcal.preset("panda"))


def _rigid_z(robot, q):
    """Tool height in the robot's base frame of a rigid copy (an FK of its own)."""
    return jaxcal.fk(robot.replace(base=np.eye(4), compliance=None), q)[..., 2, 3]


@pytest.mark.parametrize("conv", sorted(ROBOTS))
def test_gravity_moments_are_the_virtual_work_of_a_unit_weight(conv, rng):
    """A unit weight at the tool exerts ``-dz/dq_i`` about joint i (z up): the moment arm the
    compliance multiplies, checked by autodiff of the forward kinematics."""
    robot = ROBOTS[conv]().replace(base=jaxcal.preset("ur5").base)
    q = rng.uniform(-1.2, 1.2, (9, robot.n_joints))
    want = -np.asarray(jax.vmap(jax.grad(lambda qi: _rigid_z(robot, qi)))(jnp.asarray(q)))
    assert_allclose(np.asarray(gravity_moments(robot, q)), want, atol=1e-8)
    assert np.abs(want).max() > 100.0  # a test that can fail: moments of hundreds of mm


def test_a_prismatic_joint_has_no_moment_and_no_compliance(rng):
    robot = jaxcal.Robot(np.array([[0, 100.0, 0, 0], [0, 0, 300.0, 0]]), joint_types=["P", "R"])
    assert np.all(np.asarray(gravity_moments(robot, rng.uniform(-1, 1, (5, 2))))[:, 0] == 0)
    with pytest.raises(jaxcal.RobotFileError, match="joint 1: a prismatic joint has no compliance"):
        robot.replace(compliance=[1e-5, 0.0])


@pytest.mark.parametrize("conv", sorted(ROBOTS))
def test_fk_of_a_compliant_robot_is_the_rigid_fk_at_the_deflected_joints(conv, rng):
    robot = ROBOTS[conv]()
    c = rng.uniform(1e-5, 3e-5, robot.n_joints)
    q = rng.uniform(-1.2, 1.2, (6, robot.n_joints))
    tau = -np.asarray(jax.vmap(jax.grad(lambda qi: _rigid_z(robot, qi)))(jnp.asarray(q)))
    rigid = np.asarray(jaxcal.fk(robot, q + c * tau))
    got = np.asarray(jaxcal.fk(robot.replace(compliance=c), q))
    assert_allclose(got, rigid, atol=1e-9)
    assert np.abs(got - np.asarray(jaxcal.fk(robot, q)))[..., :3, 3].max() > 1.0  # the deflection shows


@pytest.mark.parametrize("conv", sorted(ROBOTS))
@pytest.mark.parametrize("n_points", [0, 2])
def test_jacobian_of_the_compliances_matches_autodiff(conv, n_points, rng):
    """The analytic identification Jacobian with compliances (the joint offset's column times the
    moment) against ``jax.jacfwd`` of the residual, away from zero; the moments are taken as given
    in both (:func:`jaxcal.kinematics.deflected`)."""
    robot = ROBOTS[conv]()
    robot = robot.replace(compliance=np.where(np.array(robot.joint_types) == "R", 1e-5, 0.0))
    lay = Layout.of(robot, base=True, tool=True, n_points=n_points, compliance=True)
    model = Model(robot, rng.normal(0, 50, (n_points, 3)) if n_points else None)
    q = jnp.asarray(rng.uniform(-1, 1, (5, robot.n_joints)))
    x = rng.normal(0, 1e-3, lay.size)
    x[list(lay.compliances)] = rng.normal(0, 1e-5, lay.n_comp)
    target = predict(apply(model, lay, jnp.asarray(0.5 * x)), q)
    _, J = residual_and_jacobian(model, lay, jnp.asarray(x), q, target)
    want = jax.jacfwd(lambda v: errors(apply(model, lay, v), q, target))(jnp.asarray(x))
    w = np.abs(np.asarray(want))
    tol = 1e-10 * w.max(axis=(0, 1)) + 1e-13 * w.max()  # per column; a numerically zero one at rounding
    assert np.all(np.abs(np.asarray(J) - np.asarray(want)) <= tol)
    assert lay.names()[lay.compliances[0]] == "compliance1"


def test_robot_files_carry_the_compliance(tmp_path, rng):
    """A TOML (in metres and degrees) and a URDF written with compliances read back with the same
    forward kinematics; yourdfpy still reads the URDF."""
    import yourdfpy

    ur5 = jaxcal.preset("ur5").replace(units=("m", "deg"), compliance=rng.uniform(0, 3e-5, 6))
    jaxcal.save_robot(ur5, tmp_path / "ur5.toml")
    back = jaxcal.load_robot(tmp_path / "ur5.toml")
    assert_allclose(np.asarray(back.compliance), np.asarray(ur5.compliance), rtol=1e-14)
    q = rng.uniform(-1, 1, (5, 6))
    assert_allclose(np.asarray(jaxcal.fk(back, q)), np.asarray(jaxcal.fk(ur5, q)), atol=1e-9)

    urdf = "jaxcal/data/tiago_mocap/tiago_arm.urdf"
    tiago = jaxcal.load_robot(urdf)
    tiago = tiago.replace(compliance=np.where(np.array(tiago.joint_types) == "R", 2e-5, 0.0))
    jaxcal.save_model(Model(tiago), tmp_path / "t.urdf", template=urdf)
    again = jaxcal.load_model(tmp_path / "t.urdf").robot
    qt = np.c_[rng.uniform(0.05, 0.3, 5), rng.uniform(-1, 1, (5, 7))]
    assert_allclose(np.asarray(jaxcal.fk(again, qt)), np.asarray(jaxcal.fk(tiago, qt)), atol=1e-9)
    assert len(yourdfpy.URDF.load(str(tmp_path / "t.urdf"), load_meshes=False).robot.joints) > 8
