"""Joint compliance (jaxcal.Robot.compliance): gravity moments against the virtual-work formula,
the deflected forward kinematics, the identification Jacobian against autodiff, and the robot
files carrying it."""

import equinox as eqx
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


def _moments_by_autodiff(robot, q):
    """``-dz/dq`` of the tool height (base frame) of a rigid copy, pose by pose, by autodiff of its
    FK: the moments of a unit weight (compiled as one program, not one per operation)."""
    rigid = robot.replace(base=np.eye(4), compliance=None)
    return eqx.filter_jit(lambda r, q: -jax.vmap(jax.grad(lambda qi: jaxcal.fk(r, qi)[2, 3]))(q))(rigid, q)


@pytest.mark.parametrize("conv", sorted(ROBOTS))
def test_gravity_moments_are_the_virtual_work_of_a_unit_weight(conv, rng):
    """A unit weight at the tool exerts ``-dz/dq_i`` about joint i (z up): the moment arm the
    compliance multiplies, checked by autodiff of the forward kinematics."""
    robot = ROBOTS[conv]().replace(base=jaxcal.preset("ur5").base)
    q = rng.uniform(-1.2, 1.2, (9, robot.n_joints))
    want = np.asarray(_moments_by_autodiff(robot, jnp.asarray(q)))
    assert_allclose(np.asarray(eqx.filter_jit(gravity_moments)(robot, q)), want, atol=1e-8)
    assert np.abs(want).max() > 100.0  # a test that can fail: moments of hundreds of mm


def test_a_prismatic_joint_has_no_moment_and_no_compliance(rng):
    robot = jaxcal.Robot(np.array([[0, 100.0, 0, 0], [0, 0, 300.0, 0]]), joint_types=["P", "R"])
    assert np.all(np.asarray(eqx.filter_jit(gravity_moments)(robot, rng.uniform(-1, 1, (5, 2))))[:, 0] == 0)
    with pytest.raises(jaxcal.RobotFileError, match="joint 1: a prismatic joint has no compliance"):
        robot.replace(compliance=[1e-5, 0.0])


@pytest.mark.parametrize("conv", sorted(ROBOTS))
def test_fk_of_a_compliant_robot_is_the_rigid_fk_at_the_deflected_joints(conv, rng):
    robot = ROBOTS[conv]()
    c = rng.uniform(1e-5, 3e-5, robot.n_joints)
    q = rng.uniform(-1.2, 1.2, (6, robot.n_joints))
    tau = np.asarray(_moments_by_autodiff(robot, jnp.asarray(q)))
    rigid = np.asarray(jaxcal.fk(robot, q + c * tau))
    got = np.asarray(jaxcal.fk(robot.replace(compliance=c), q))
    assert_allclose(got, rigid, atol=1e-9)
    assert np.abs(got - np.asarray(jaxcal.fk(robot, q)))[..., :3, 3].max() > 1.0  # the deflection shows
    # with reference moments m the offsets hold at m: the same arm written with offsets + c m
    m = rng.uniform(-300.0, 300.0, robot.n_joints)
    dh = np.array(robot.dh)
    dh[:, 0] += c * m
    assert_allclose(np.asarray(jaxcal.fk(robot.replace(dh=dh, compliance=c, moment_ref=m), q)), rigid, atol=1e-9)


@pytest.mark.parametrize("conv", sorted(ROBOTS))
@pytest.mark.parametrize("n_points", [0, 2])
def test_jacobian_of_the_compliances_matches_autodiff(conv, n_points, rng):
    """The analytic identification Jacobian with compliances (the joint offset's column times the
    moment) against ``jax.jacfwd`` of the residual, away from zero; the moments are taken as given
    in both (:func:`jaxcal.kinematics.deflected`)."""
    robot = ROBOTS[conv]()
    robot = robot.replace(compliance=np.where(np.array(robot.joint_types) == "R", 1e-5, 0.0))
    if n_points:  # and reference moments (jaxcal.Robot.moment_ref), which the columns subtract
        robot = robot.replace(moment_ref=rng.uniform(-300.0, 300.0, robot.n_joints))
    lay = Layout.of(robot, base=True, tool=True, n_points=n_points, compliance=True)
    model = Model(robot, rng.normal(0, 50, (n_points, 3)) if n_points else None)
    q = jnp.asarray(rng.uniform(-1, 1, (5, robot.n_joints)))
    x = rng.normal(0, 1e-3, lay.size)
    x[list(lay.compliances)] = rng.normal(0, 1e-5, lay.n_comp)

    @jax.jit  # one program, not one per operation
    def both(x):
        target = predict(apply(model, lay, 0.5 * x), q)
        want = jax.jacfwd(lambda v: errors(apply(model, lay, v), q, target))(x)
        return residual_and_jacobian(model, lay, x, q, target)[1], want

    J, want = both(jnp.asarray(x))
    w = np.abs(np.asarray(want))
    tol = 1e-10 * w.max(axis=(0, 1)) + 1e-13 * w.max()  # per column; a numerically zero one at rounding
    assert np.all(np.abs(np.asarray(J) - np.asarray(want)) <= tol)
    assert lay.names()[lay.compliances[0]] == "compliance1"


def test_robot_files_carry_the_compliance(tmp_path, rng):
    """A TOML (in metres and degrees) and a URDF written with compliances read back with the same
    forward kinematics; yourdfpy still reads the URDF."""
    import yourdfpy

    ur5 = jaxcal.preset("ur5").replace(
        units=("m", "deg"), compliance=rng.uniform(0, 3e-5, 6), moment_ref=rng.uniform(-300, 300, 6)
    )
    jaxcal.save_robot(ur5, tmp_path / "ur5.toml")
    back = jaxcal.load_robot(tmp_path / "ur5.toml")
    assert_allclose(np.asarray(back.compliance), np.asarray(ur5.compliance), rtol=1e-14)
    assert_allclose(np.asarray(back.moment_ref), np.asarray(ur5.moment_ref), rtol=1e-14)
    q = rng.uniform(-1, 1, (5, 6))
    assert_allclose(np.asarray(jaxcal.fk(back, q)), np.asarray(jaxcal.fk(ur5, q)), atol=1e-9)

    urdf = "jaxcal/data/tiago_mocap/tiago_arm.urdf"
    tiago = jaxcal.load_robot(urdf)
    tiago = tiago.replace(
        compliance=np.where(np.array(tiago.joint_types) == "R", 2e-5, 0.0), moment_ref=rng.uniform(-300, 300, 8)
    )
    jaxcal.save_model(Model(tiago), tmp_path / "t.urdf", template=urdf)
    again = jaxcal.load_model(tmp_path / "t.urdf").robot
    assert_allclose(np.asarray(again.moment_ref), np.asarray(tiago.moment_ref), rtol=1e-12)
    qt = np.c_[rng.uniform(0.05, 0.3, 5), rng.uniform(-1, 1, (5, 7))]
    assert_allclose(np.asarray(jaxcal.fk(again, qt)), np.asarray(jaxcal.fk(tiago, qt)), atol=1e-9)
    assert len(yourdfpy.URDF.load(str(tmp_path / "t.urdf"), load_meshes=False).robot.joints) > 8
    # the file says at its top that only jaxcal reads the compliances, whoever wrote it
    head = (tmp_path / "t.urdf").read_text().split("<robot")[0]
    assert "only jaxcal reads; other URDF readers apply the rigid geometry only" in head


def test_info_shows_what_a_file_holds_beyond_its_table(tmp_path, monkeypatch, capsys):
    """``jaxcal info`` of a compliant model file lists the compliances, where their weight is,
    and the measured points by their numbers: a reloaded file's rigid table alone hid them."""
    from helpers import run_cli

    ur5 = jaxcal.preset("ur5").replace(
        compliance=[0.0, 1.5e-6, 2e-6, 0.0, 0.0, 0.0], load=np.array([10.0, 0, 0]), moment_ref=[0, -250.0, 120, 7, 0, 0]
    )
    points = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    jaxcal.save_robot(ur5, tmp_path / "c.toml", points=points, point_numbers=[3, 1])
    code, out, err = run_cli(monkeypatch, capsys, "info", str(tmp_path / "c.toml"))
    text = " ".join(out.split())
    assert code in (0, None), err
    assert "joint compliances (rad per mm of moment arm): q2 1.5e-06, q3 2e-06; weight at xyz 10 0 0 mm" in text
    assert "joint offsets hold at the moment arms (mm): q2 -250, q3 120" in text
    assert "point 3 on the tool: xyz 1 2 3 mm" in text and "point 1 on the tool: xyz 4 5 6 mm" in text


def _tiago_truth(rng, perturb: bool):
    """A TIAGo arm (joint origins perturbed or not), an unknown measurement frame, three points on
    the hand, compliant joints; its measurements from the virtual work of the rigid arm, not from
    jaxcal's compliance code."""
    from helpers import random_transform

    nominal = jaxcal.load_robot("jaxcal/data/tiago_mocap/tiago_arm.urdf")
    n = nominal.n_joints
    err = np.c_[rng.normal(0, 2e-3, (n, 1)), rng.normal(0, 0.5, (n, 3)), rng.normal(0, 1e-3, (n, 3))]
    true = nominal.replace(dh=np.asarray(nominal.dh) + perturb * err, base=random_transform(rng, 500.0))
    c = np.where(np.array(nominal.joint_types) == "R", rng.uniform(0.5e-5, 2e-5, n), 0.0)
    pts = rng.normal(0, 60.0, (3, 3))

    def measure(q):
        tau = np.asarray(_moments_by_autodiff(true, jnp.asarray(q)))
        T = np.asarray(jaxcal.fk(true, q + c * tau))
        return np.einsum("kij,mj->kmi", T[:, :3, :3], pts) + T[:, None, :3, 3]

    lim = np.asarray(nominal.q_limits) * 0.8
    return nominal, c, measure, rng.uniform(lim[:, 0], lim[:, 1], (60, n)), rng.uniform(lim[:, 0], lim[:, 1], (20, n))


def test_calibrate_recovers_compliance(rng):
    """Nominal geometry, compliant joints: ``compliance="yes"`` gives the compliances back and
    predicts new postures to 1e-6 mm (noise-free); a rigid fit misses by millimetres."""
    nominal, c, measure, q, q_new = _tiago_truth(rng, perturb=False)
    res = jaxcal.calibrate(nominal, q, measure(q), compliance="yes")
    assert res.converged
    free = [res.names[i] for i in res.free if res.names[i].startswith("compliance")]
    assert len(free) >= 5  # the arm joints whose moments vary
    for name in free:
        assert abs(res.delta(name) - c[int(name.removeprefix("compliance")) - 1]) < 1e-11
    assert np.abs(np.asarray(predict(res.model, q_new)) - measure(q_new)).max() < 1e-6
    assert jaxcal.calibrate(nominal, q, measure(q), compliance="no").after["pos_rms_mm"] > 1.0


def test_compliance_with_geometry_errors_is_close(rng):
    """With perturbed joint origins too, the rigid errors the base frame absorbs tilt the model's
    gravity a little (gravity is -z of the model's base frame): the compliances come back within
    a few percent and new postures within 0.01 mm, where the rigid fit misses by millimetres."""
    nominal, c, measure, q, q_new = _tiago_truth(rng, perturb=True)
    res = jaxcal.calibrate(nominal, q, measure(q), compliance="yes")
    assert res.converged
    for name in (res.names[i] for i in res.free if res.names[i].startswith("compliance")):
        j = int(name.removeprefix("compliance")) - 1
        assert abs(res.delta(name) - c[j]) < 0.05 * c[j]
    assert np.abs(np.asarray(predict(res.model, q_new)) - measure(q_new)).max() < 0.01
    assert jaxcal.calibrate(nominal, q, measure(q), compliance="no").after["pos_rms_mm"] > 1.0


def test_a_point_folded_into_the_tool_keeps_the_compliances_weight(tmp_path, rng):
    """A one-point model's robot (the point folded into its tool, what --out-robot writes) keeps
    the unit weight where the model had it, the old tool origin: its moments are those of that
    weight by autodiff, its forward kinematics the model's prediction of the point, and a TOML in
    metres and degrees reads back the same. Without the load point the two part by millimetres."""
    from jaxcal.model import measured_robot, predict

    tool = np.eye(4)
    tool[:3, :3] = jaxcal.lie.rpy_to_matrix(np.array([0.3, -0.2, 0.5]))
    ur5 = jaxcal.preset("ur5").replace(compliance=np.r_[0.0, rng.uniform(1e-5, 3e-5, 3), 0.0, 0.0], tool=tool)
    model = Model(ur5, np.array([[80.0, -60.0, 200.0]]))
    folded = measured_robot(model)
    q = rng.uniform(-1.5, 1.5, (12, 6))
    assert_allclose(
        np.asarray(eqx.filter_jit(gravity_moments)(folded, q)), np.asarray(_moments_by_autodiff(ur5, jnp.asarray(q))),
        atol=1e-8,
    )  # fmt: skip
    want = np.asarray(predict(model, q))[:, 0]
    assert_allclose(np.asarray(jaxcal.fk(folded, q))[:, :3, 3], want, atol=1e-9)
    jaxcal.save_robot(folded.replace(units=("m", "deg")), tmp_path / "f.toml")
    back = jaxcal.load_robot(tmp_path / "f.toml")
    assert_allclose(np.asarray(jaxcal.fk(back, q))[:, :3, 3], want, atol=1e-9)
    moved = np.asarray(jaxcal.fk(folded.replace(load=None), q))[:, :3, 3]
    assert np.linalg.norm(moved - want, axis=-1).max() > 0.5  # the weight's place matters here
    # a rigid choice (every compliance 0) has no weight to keep: no load, and its file has none
    rigid = measured_robot(Model(ur5.replace(compliance=np.zeros(6)), model.points))
    assert rigid.load is None


def test_conversions_keep_a_compliant_arms_pose_or_refuse(rng):
    """Gravity is along -z of frame 0: ``to_mdh`` and ``to_joint`` keep that frame and so the
    deflected end pose; ``to_sdh`` of an MDH arm whose first twist is not 0 would tilt it and is
    refused, while with a zero first twist it converts exactly."""
    r = jaxcal.preset("panda")  # MDH, alpha_1 = 0
    r = r.replace(compliance=np.full(7, 3e-6), moment_ref=rng.uniform(-300, 300, 7))
    q = rng.uniform(-1.5, 1.5, (20, 7))
    want = np.asarray(jaxcal.fk(r, q))
    for other in (jaxcal.to_sdh(r), to_joint(r), jaxcal.to_mdh(jaxcal.to_sdh(r))):
        assert_allclose(np.asarray(jaxcal.fk(other, q)), want, atol=1e-9)
    dh = np.asarray(r.dh).copy()
    dh[0, 3] = 0.4
    tilted = r.replace(dh=dh)
    with pytest.raises(jaxcal.RobotFileError, match="to_sdh: .* has joint compliances and alpha_1 = 0.4"):
        jaxcal.to_sdh(tilted)
    rigid = np.asarray(jaxcal.fk(tilted.replace(compliance=np.zeros(7)), q))
    assert_allclose(np.asarray(jaxcal.fk(jaxcal.to_sdh(tilted.replace(compliance=np.zeros(7))), q)), rigid, atol=1e-9)


def test_references_are_the_mean_over_the_poses_each_fit_used():
    """The bent UR5 (NumPy FK, :func:`helpers.bent_ur5`). ``calibrate`` writes the reference
    moments as the mean moment over the poses it fitted: not over outliers it left out, and, for a
    model calibrated again on poses elsewhere, the new data's mean, not the file's. The batch's
    ``x`` stays relative to the nominal robot: applied to it, the data are predicted."""
    from helpers import bent_ur5

    ur5 = jaxcal.preset("ur5")
    _, _, c, tau, q, p = bent_ur5(40, 0.02)
    p = p.copy()
    p[:6] += [30.0, -40.0, 25.0]  # gross outliers at six poses of large moments
    first = jaxcal.calibrate(ur5, q, p, compliance="yes")
    assert set(first.outliers) == set(range(6))
    m = tau(q[6:]).mean(0)
    r1 = first.model.robot
    assert_allclose(np.asarray(r1.moment_ref)[1:4], m[1:4], atol=1.0)  # mm, of hundreds
    assert abs(np.asarray(r1.moment_ref)[1] - tau(q).mean(0)[1]) > 0.05 * abs(m[1])  # the outliers' mean differs

    elsewhere = np.random.default_rng(5).uniform([-1, -2.5, 0.5, -1, -1, -1], [1, -1.5, 1.5, 1, 1, 1], (40, 6))
    _, _, _, _, q2, p2 = bent_ur5(sigma=0.02, q=elsewhere)
    again = jaxcal.calibrate(r1, q2, p2, compliance="yes")
    m2 = tau(q2).mean(0)
    assert_allclose(np.asarray(again.model.robot.moment_ref)[1:4], m2[1:4], atol=1.0)
    assert np.abs(m2 - m)[1:4].max() > 50.0  # the test can fail: the file's moments are not these
    assert np.sqrt(np.mean(np.sum((np.asarray(predict(again.model, q2))[:, 0] - p2) ** 2, -1))) < 3 * 0.02 * np.sqrt(3)

    # the offsets a set without them holds still move with their compliances: the table says so
    lengths = jaxcal.calibrate(ur5, q2, p2, compliance="yes", params="a,d,alpha")
    row = next(line for line in lengths.table().splitlines() if line.split()[0] == "theta2")
    assert lengths.delta("theta2") != 0 and row.endswith("(held; moved by its compliance)")

    batch = jaxcal.calibrate_batch(ur5, q2[None], p2[None], compliance="yes")
    model = Model(ur5.replace(compliance=np.zeros(6)), np.zeros((1, 3)))
    fitted = apply(model, batch.layout, jnp.asarray(batch.x[0]))
    err = np.asarray(predict(fitted, q2))[:, 0] - p2
    assert np.sqrt(np.mean(np.sum(err**2, -1))) < 3 * 0.02 * np.sqrt(3)
