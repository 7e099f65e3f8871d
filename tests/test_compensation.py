"""Compensation by inverse kinematics of the calibrated model, checked against simulated truth."""

import equinox as eqx
import numpy as np
import pytest
from helpers import dh_fk, random_transform
from numpy.testing import assert_allclose

from jaxcal import DataError, Measurements, calibrate_data, fk, load_robot, preset
from jaxcal.compensation import compensate, compensate_targets, read_targets
from jaxcal.error_model import perturb
from jaxcal.simulation import simulate


@pytest.mark.parametrize("name", ["paper-6r", "panda"])
def test_ik_reaches_reachable_targets(rng, name):
    """Targets made by the model itself from known joints: IK from a perturbed start reaches them."""
    r = preset(name)
    q_true = np.asarray(simulate(r, n_poses=20, seed=3).q[0])
    targets = np.asarray(fk(r, q_true))
    res = compensate(r, targets, q_true + rng.normal(scale=0.02, size=q_true.shape))
    assert res.converged.all()
    assert res.pos_residual_mm.max() < 1e-6 and res.rot_residual_deg.max() < 1e-7
    if r.n_joints == 6:  # non-redundant: the joints themselves come back
        assert_allclose(res.q, q_true, atol=1e-8)


def test_compensation_reduces_true_error_to_calibration_accuracy():
    """Calibrate a simulated arm (DH, base and tool errors, noise); send the compensated commands to the
    TRUE robot: its position error drops to within 1.5x the calibrated model's held-out RMS."""
    r = preset("paper-6r")
    sim = simulate(r, n_poses=60, n_val=50, seed=11, sigma_pos=0.05, sigma_rot=2e-4, base=True, tool=True)
    res = calibrate_data(r, Measurements(sim.q[0], sim.measured[0]), params="all", folds=3, compliance="no")
    true_robot = eqx.filter_jit(perturb)(r, sim.x_true[0], base=True, tool=True)  # one program, not one per operation
    q_cmd = np.asarray(sim.q_val[0])
    targets = np.asarray(fk(r, q_cmd))  # where the nominal model says the commands go
    before = np.linalg.norm(np.asarray(fk(true_robot, q_cmd))[:, :3, 3] - targets[:, :3, 3], axis=1)
    comp = compensate(res.robot, targets, q_cmd)
    # a few random targets sit near a singularity / the calibrated workspace boundary: reported, not hidden
    ok = comp.converged
    assert ok.mean() >= 0.9 and comp.pos_residual_mm[ok].max() < 1e-6
    after = np.linalg.norm(np.asarray(fk(true_robot, comp.q))[:, :3, 3] - targets[:, :3, 3], axis=1)[ok]
    rms_before, rms_after = np.sqrt(np.mean(before[ok] ** 2)), np.sqrt(np.mean(after**2))
    assert rms_before > 2.0  # mm: the uncompensated arm is well off
    assert rms_after <= 1.5 * res.report["heldout_rms_mm"]
    assert rms_after < rms_before / 20


def test_targets_file(tmp_path):
    r = preset("paper-6r")
    q = np.asarray(simulate(r, n_poses=4, seed=1).q[0])
    p = tmp_path / "t.csv"
    p.write_text("q1,q2,q3,q4,q5,q6\n" + "".join(",".join(repr(float(v)) for v in row) + "\n" for row in q))
    t = read_targets(p, r)
    assert t.poses is None and t.q.shape == (4, 6)
    with pytest.raises(DataError, match="nominal robot is needed"):
        compensate_targets(r, t)
    poses, res = compensate_targets(r, t, nominal=r)
    assert_allclose(res.q, q, atol=1e-10)  # the nominal model reaches its own targets unchanged


@pytest.mark.parametrize(
    "text, msg",
    [
        ("x,y\n1,2\n", "missing column\\(s\\) 'z'"),
        ("q1,q2\n0,0\n", "robot has 6 joints, file has q1..q2"),
        ("x,y,z,qw\n1,2,3,1\n", "only some quaternion columns present"),
        ("x,y,z\n1,abc,3\n", "row 1 \\(line 2\\), column 'y': not a number: 'abc'"),
        ("x,y,z\n1,2,inf\n", "row 1 \\(line 2\\), column 'z': value 'inf' is not finite"),
        ("x,y,z,qw,qx,qy,qz\n1,2,3,1,1,0,0\n", "row 1 \\(line 2\\): quaternion .* has norm 1.41421"),
        ("x,y,z\n", "header only"),
    ],
)
def test_targets_bad_input(tmp_path, text, msg):
    p = tmp_path / "t.csv"
    p.write_text(text)
    with pytest.raises(DataError, match=msg):
        read_targets(p, preset("paper-6r"))


def _arm_with_errors(rng, name, base=None):
    """A preset with small DH errors (and optionally a measurement frame): the 'calibrated' model."""
    r = preset(name)
    dh = (
        np.asarray(r.dh)
        + np.c_[
            rng.normal(0, 2e-3, r.n_joints),
            rng.normal(0, 0.5, r.n_joints),
            rng.normal(0, 0.5, r.n_joints),
            rng.normal(0, 2e-3, r.n_joints),
        ]
    )
    return r, r.replace(dh=dh, base=np.eye(4) if base is None else base)


def test_position_targets_stay_on_the_branch_and_within_limits(rng):
    """Position-only targets from nominal commands: the commands stay within a small correction of
    the nominal ones (no whole-turn jumps) and inside the joint limits; checked with an independent
    forward kinematics."""
    nominal, cal = _arm_with_errors(rng, "panda")
    lim = np.asarray(nominal.q_limits)
    q_nom = lim[:, 0] + (0.2 + 0.6 * rng.uniform(size=(40, 7))) * (lim[:, 1] - lim[:, 0])
    targets = dh_fk(np.asarray(nominal.dh), q_nom, convention="mdh", tool=np.asarray(nominal.tool))
    res = compensate(cal, targets, q_nom, position_only=True)
    assert res.ok.all()
    assert np.abs(res.q - q_nom).max() < 0.2
    assert np.all((res.q >= lim[:, 0]) & (res.q <= lim[:, 1]))
    reached = dh_fk(np.asarray(cal.dh), res.q, convention="mdh", tool=np.asarray(cal.tool))
    assert np.abs(reached[:, :3, 3] - targets[:, :3, 3]).max() < 1e-5


def test_out_of_limit_and_unreachable_targets_are_flagged(rng):
    r = preset("paper-6r")
    narrow = r.replace(q_limits=np.asarray(r.q_limits) * 0.1)
    q = np.asarray(r.q_limits).mean(1) + 0.5  # outside the narrow limits
    T = np.array(fk(r, np.tile(q, (2, 1))))
    T[1, :3, 3] += 1e5  # far beyond the reach
    res = compensate(narrow, T, np.tile(q, (2, 1)))
    assert not res.within_limits[0] and not res.ok[0]
    assert not res.converged[1] and not res.ok[1]
    # a joint whose limits lie a whole turn from the start: the same pose a turn on is inside them
    lim = np.array(r.q_limits)
    lim[0] = 0.5, 6.0
    wide = r.replace(q_limits=lim)
    q_true = np.tile(np.asarray(r.q_limits).mean(1), (2, 1))
    q_true[:, 0] = [5.0, 3.0]
    start = q_true + 0.01
    start[0, 0] -= 2 * np.pi  # -1.27: on the branch of the start, the solution is beyond the lower limit
    res = compensate(wide, np.asarray(fk(r, q_true)), start)
    assert res.ok.all()
    assert_allclose(res.q, q_true, atol=1e-8)
    # a command within the limits whose target lies just beyond them on its branch: not sent a
    # whole turn round (the wrist would spin through a turn), flagged beyond the limits
    lim[0] = -1.0, 6.0  # the target's -1.003 + 2 pi lies inside them
    q_true[0, 0] = -1.003
    start = q_true + 0.006
    res = compensate(r.replace(q_limits=lim), np.asarray(fk(r, q_true)), start)
    assert res.converged.all() and list(res.within_limits) == [False, True] and list(res.ok) == [False, True]
    assert_allclose(res.q[0], q_true[0], atol=1e-8)  # on the branch, not -1.003 + 2 pi


def test_a_joint_given_no_limits_has_none_to_be_outside_of():
    """The UR presets give no limits (their +-pi is a sampling range; the arms turn +-2 pi): a
    command of 4.5 rad is within the limits, and stays where it is (not turned into +-pi). A
    joint given limits is still judged by them."""
    ur5 = preset("ur5")
    assert not ur5.limits_given().any()
    q = np.array([[4.5, -1.0, 1.2, -0.5, 1.0, 0.3], [-5.0, -1.2, 1.0, 0.4, -1.0, 2.0]])
    targets = dh_fk(np.asarray(ur5.dh), q)
    res = compensate(ur5, targets, q + 0.01)
    assert res.ok.all() and res.within_limits.all()
    assert_allclose(res.q, q, atol=1e-8)
    lim = np.asarray(ur5.q_limits).copy()
    lim[0] = -1.0, 1.0  # given: neither 4.5 nor -5.0 rad lies within them, a turn on or not
    res = compensate(ur5.replace(q_limits=lim), targets, q + 0.01)
    assert not res.within_limits.any() and not res.ok.any()


def test_nominal_commands_are_moved_into_the_calibrated_frame(rng, tmp_path):
    """Targets given as nominal commands, a calibrated model whose base is a tracker frame far from
    the robot: the targets are built in the model's frame, every command is reached with a small
    correction, and the calibrated arm then puts its tool where the nominal arm would (robot frame)."""
    B = random_transform(rng, 1500.0)
    nominal, cal = _arm_with_errors(rng, "paper-6r", base=B)
    lim = np.asarray(nominal.q_limits)
    q = lim[:, 0] + (0.2 + 0.6 * rng.uniform(size=(30, 6))) * (lim[:, 1] - lim[:, 0])
    p = tmp_path / "targets.csv"
    p.write_text("q1,q2,q3,q4,q5,q6\n" + "".join(",".join(repr(float(v)) for v in row) + "\n" for row in q))
    t = read_targets(p, nominal)
    _, res = compensate_targets(cal, t, nominal=nominal)
    assert res.ok.all()
    assert np.abs(res.q - q).max() < 0.3  # a correction, not a whole turn
    want = dh_fk(np.asarray(nominal.dh), q, tool=np.asarray(nominal.tool))
    got = np.linalg.inv(B) @ dh_fk(np.asarray(cal.dh), res.q, base=B, tool=np.asarray(cal.tool))
    assert np.abs(got[:, :3, 3] - want[:, :3, 3]).max() < 1e-5


def test_a_compliant_arm_and_a_long_prismatic_move_are_reached(rng, tmp_path):
    """A compliant arm reaches its deflected joint values: the targets it makes itself from known
    commands give those commands back. A prismatic joint moved by 80 mm is reached too (the pull
    toward the start would otherwise leave ~damping x 80 mm)."""
    r = preset("paper-6r")
    r = eqx.tree_at(lambda x: x.compliance, r, np.full(6, 2e-6), is_leaf=lambda v: v is None)
    q_true = np.asarray(simulate(r, n_poses=12, seed=4).q[0])
    res = compensate(r, np.asarray(fk(r, q_true)), q_true + rng.normal(scale=0.005, size=q_true.shape))
    assert res.converged.all() and res.pos_residual_mm.max() < 1e-6
    assert_allclose(res.q, q_true, atol=1e-8)  # the nearest root: the commands themselves

    (tmp_path / "rrpr.toml").write_text(
        'name = "rrpr"\nconvention = "sdh"\n'
        + "".join(
            f'[[joints]]\ntheta = 0.0\nd = {d}\na = {a}\nalpha = {al}\ntype = "{t}"\nlimits = [{lo}, {hi}]\n'
            for d, a, al, t, lo, hi in (
                (400.0, 350.0, 0.0, "R", -2.6, 2.6),
                (0.0, 300.0, np.pi, "R", -2.4, 2.4),
                (50.0, 0.0, 0.0, "P", 0.0, 200.0),
                (0.0, 0.0, 0.0, "R", -6.0, 6.0),
            )
        )
    )
    s = load_robot(tmp_path / "rrpr.toml")
    q_true = np.array([[0.3, -0.8, 150.0, 1.0], [-1.2, 1.5, 120.0, -0.5]])
    start = q_true + np.array([0.01, -0.01, -80.0, 0.02])
    res = compensate(s, np.asarray(fk(s, q_true)), start, position_only=True)
    assert res.converged.all() and res.pos_residual_mm.max() < 1e-6
    assert_allclose(res.q[:, 2], q_true[:, 2], atol=1e-6)


def test_targets_in_another_unit_are_refused_naming_the_option(tmp_path):
    """Commands with target positions, written in metres for a robot in mm, or the commands in
    degrees: refused as calibrate and evaluate refuse them, naming the option that reads them."""
    r = preset("paper-6r")
    q = np.asarray(simulate(r, n_poses=8, seed=2).q[0])
    pos = np.asarray(fk(r, q))[:, :3, 3]

    def targets(qs, ps):
        p = tmp_path / "t.csv"
        rows = ["q1,q2,q3,q4,q5,q6,x,y,z"] + [",".join(repr(float(v)) for v in np.r_[a, b]) for a, b in zip(qs, ps)]
        p.write_text("\n".join(rows) + "\n")
        return read_targets(p, r)

    poses, res = compensate_targets(r, targets(q, pos))
    assert res.converged.all()
    with pytest.raises(DataError, match="metres read as millimetres") as e:
        compensate_targets(r, targets(q, pos / 1000.0))
    assert e.value.option == "length_unit"
    with pytest.raises(DataError, match="look like degrees") as e:
        compensate_targets(r, targets(np.degrees(q), pos))
    assert e.value.option == "angle_unit"
    # positions alone, in metres, by a tracker 5 m from the base: beyond any reach, refused
    far = r.replace(base=np.asarray(r.base) + np.pad(np.array([[5000.0], [0.0], [0.0]]), ((0, 1), (3, 0))))
    p = tmp_path / "xyz.csv"
    p.write_text("x,y,z\n" + "".join(",".join(repr(float(v)) for v in b / 1000.0) + "\n" for b in pos + [5000.0, 0, 0]))
    with pytest.raises(DataError, match="times its reach") as e:
        compensate_targets(far, read_targets(p, far))
    assert e.value.option == "length_unit"


def test_a_command_that_left_its_starting_branch_is_not_sent():
    """A target that the start command is far from (its elbow 80 degrees off): the solve reaches
    it only by turning a joint well past MAX_MOVE_DEG, which is another command than the one meant;
    it is flagged (on_branch False) and not among the rows to send. A small correction is."""
    r = preset("ur5")
    q0 = np.array([[0.3, -1.2, 1.4, -1.5, -1.4, 0.2]] * 2)
    q_true = q0.copy()
    q_true[0, 2] += np.radians(80.0)
    q_true[1, 2] += np.radians(2.0)
    res = compensate(r, np.asarray(fk(r, q_true)), q0)
    assert res.converged.all() and res.within_limits.all()
    assert list(res.on_branch) == [False, True] and list(res.ok) == [False, True]


def test_a_nominal_robot_with_target_positions_given_is_refused(tmp_path):
    """The file gives x, y, z: a nominal robot would not be used to make targets, so it is refused,
    not silently ignored."""
    r = preset("paper-6r")
    p = tmp_path / "t.csv"
    p.write_text("q1,q2,q3,q4,q5,q6,x,y,z\n0,0.1,0.2,0.3,0.4,0.5,500,100,300\n")
    with pytest.raises(DataError, match="nominal: the targets file gives the target positions"):
        compensate_targets(r, read_targets(p, r), nominal=r)


def test_targets_without_commands_have_no_branch_to_leave(tmp_path):
    """Positions only: the solve starts from the middle of the limits, which is no command of the
    user's, so a reached target is sent however far its joints are from that start."""
    r = preset("ur5")
    q = np.array([[0.3, -1.2, 1.4, -1.5, -1.4, 0.2], [-1.0, -2.0, 2.0, -0.5, 1.0, 2.5]])
    p = np.asarray(fk(r, q))[:, :3, 3]
    f = tmp_path / "t.csv"
    f.write_text("x,y,z\n" + "".join(",".join(repr(float(v)) for v in pk) + "\n" for pk in p))
    _, res = compensate_targets(r, read_targets(f, r))
    assert res.converged.all() and res.on_branch.all() and res.ok.all()


def test_commands_for_a_pose_model_whose_tool_is_another_frame_warn():
    """Joint commands alone for a model calibrated from poses: its tool a calibration's correction
    away from the nominal one says nothing; 121 mm and 20 degrees away (the measured body, not the
    taught tool) is named, with both distances, computed here with scipy."""
    from scipy.spatial.transform import Rotation

    from jaxcal.compensation import tool_note

    ur5 = preset("ur5")
    near, far = np.array(ur5.tool), np.array(ur5.tool)
    near[:3, 3] += [1.0, -2.0, 0.5]
    far[:3, :3] = far[:3, :3] @ Rotation.from_euler("x", 20.0, degrees=True).as_matrix()
    far[:3, 3] += [0.0, 0.0, 121.0]
    assert tool_note(0, ur5.replace(tool=near), ur5, "cal.toml", commands_only=True) == ""
    note = tool_note(0, ur5.replace(tool=far), ur5, "cal.toml", commands_only=True)
    assert "cal.toml's tool is 121 mm and 20 deg from the nominal robot's" in note
    assert tool_note(0, ur5.replace(tool=far), ur5, "cal.toml", commands_only=False) == ""  # pose targets


def test_a_lift_under_an_arm_is_used_where_the_target_needs_it(tmp_path):
    """A prismatic lift under a UR5-like arm (7 joints, pose targets): solved in mm and rad as
    they are, the least step moved the revolute joints (a radian moves the tool hundreds of mm)
    and left the lift still, and one target drove the elbow 12 degrees into a point 0.3 mm off.
    Scaled by the arm's lever, every target is reached with small moves of all joints."""
    rows = [
        ("P", 0.0, 100.0, 0.0, 0.0, 0.0, 500.0),
        ("R", 0.0, 89.159, 0.0, np.pi / 2, -2.9, 2.9),
        ("R", -np.pi / 2, 0.0, 425.0, 0.0, -2.9, 2.9),
        ("R", 0.0, 0.0, 392.25, 0.0, -2.9, 2.9),
        ("R", np.pi / 2, 109.15, 0.0, np.pi / 2, -2.9, 2.9),
        ("R", 0.0, 94.65, 0.0, -np.pi / 2, -2.9, 2.9),
        ("R", 0.0, 82.3, 0.0, 0.0, -6.0, 6.0),
    ]
    (tmp_path / "lift.toml").write_text(
        'name = "lift"\nconvention = "sdh"\n'
        + "".join(
            f'[[joints]]\ntype = "{t}"\ntheta = {th}\nd = {d}\na = {a}\nalpha = {al}\nlimits = [{lo}, {hi}]\n'
            for t, th, d, a, al, lo, hi in rows
        )
    )
    nominal = load_robot(tmp_path / "lift.toml")
    rng = np.random.default_rng(6)
    dh = np.array([r[1:5] for r in rows]) + rng.normal(scale=[0.002, 0.5, 0.5, 0.002], size=(7, 4))
    q = np.c_[rng.uniform(100, 400, 20), rng.uniform(-2, 2, (20, 6))]
    types = [r[0] for r in rows]
    targets = dh_fk(np.array([r[1:5] for r in rows]), q, joint_types=types)  # where the nominal puts the tool
    res = compensate(nominal.replace(dh=dh), targets, q)
    assert res.converged.all()
    reached = dh_fk(dh, res.q, joint_types=types)  # the calibrated arm at the commands, in NumPy
    assert np.linalg.norm(reached[:, :3, 3] - targets[:, :3, 3], axis=1).max() < 1e-6
    moved = res.q - q
    assert np.abs(moved[:, 0]).max() < 10.0 and np.degrees(np.abs(moved[:, 1:]).max()) < 5.0


def test_a_target_reached_near_a_singularity_counts_as_reached():
    """UR5 (NumPy FK truth) at postures with the wrist near its singularity (q5 ~ 0), from starts
    0.3 rad off: where the returned command puts the tool within a micron of the target (NumPy FK
    of the command), the target is reached; it was flagged not reached where the solver crept on
    at nanometres, or stopped at its step limit with no residual left."""
    r = preset("ur5")
    rng = np.random.default_rng(3)
    dh = np.asarray(r.dh) + np.stack([rng.normal(0, s, 6) for s in (0.003, 0.5, 0.5, 0.003)], 1)
    q = rng.uniform(-2.5, 2.5, (200, 6))
    q[:, 4] = rng.normal(0, 0.01, 200)
    targets = dh_fk(dh, q)
    for position_only in (False, True):
        res = compensate(r.replace(dh=dh), targets, q + rng.normal(0, 0.3, q.shape), position_only=position_only)
        T = dh_fk(dh, res.q)
        miss = np.linalg.norm(T[:, :3, 3] - targets[:, :3, 3], axis=1)
        turn = np.arccos(np.clip((np.einsum("kij,kij->k", T[:, :3, :3], targets[:, :3, :3]) - 1) / 2, -1, 1))
        close = (miss < 1e-3) & ((turn < 1e-6) | position_only)
        assert close.sum() > 150  # most are reached; some starts lead elsewhere
        assert_allclose(res.pos_residual_mm, miss, atol=1e-6)
        assert (res.converged == close).all(), np.flatnonzero(res.converged != close)
