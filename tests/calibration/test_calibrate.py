"""Single fits and batches (`calibrate`, `calibrate_batch`) against the simulated truth."""

import re

import equinox as eqx
import numpy as np
import pytest
from helpers import solve_keys
from numpy.testing import assert_allclose

import jaxcal
from jaxcal.calibration import calibrate, calibrate_batch, identify
from jaxcal.simulation import error_scales, sample_poses, simulate


def _truth_in_base_set(robot, *, base=False, tool=False, position_only=False, n_poses=40, seed=0):
    """Simulation whose true errors are zero on the parameters the solver must hold fixed
    (a truth with errors there is not exactly representable: see docs)."""
    import jax

    q = np.asarray(sample_poses(jax.random.PRNGKey(seed + 100), robot, (n_poses,)))
    ident = identify(robot, q, n_points=int(position_only), estimate_base=base, estimate_tool=tool)
    scales = error_scales(robot, base=base, tool=tool)
    scales[list(ident.fixed)] = 0.0
    sim = simulate(robot, n_robots=3, q=q, seed=seed, scales=scales, base=base, tool=tool)
    return sim, ident


CASES = [
    ("paper-6r", "gn", False, False, False),
    ("puma560", "gn", False, False, False),
    ("ur5", "gn", False, False, False),
    ("paper-6r", "gn", True, True, False),
    ("ur5", "gn", True, True, False),
    ("paper-6r", "gn", False, False, True),
    ("paper-6r", "lm", False, False, False),
    ("puma560", "lm", True, True, False),
]


@pytest.mark.parametrize("name,method,base,tool,position_only", CASES)
def test_noise_free_recovery(name, method, base, tool, position_only):
    robot = jaxcal.preset(name)
    sim, ident = _truth_in_base_set(
        robot, base=base, tool=tool, position_only=position_only, n_poses=60 if position_only else 40
    )
    res = calibrate_batch(
        robot,
        sim.q,
        sim.measured,
        method=method,
        estimate_base=base,
        estimate_tool=tool,
        position_only=position_only,
        ident=ident,
    )
    assert res.converged.all(), res.num_steps
    assert_allclose(res.x, sim.x_true, atol=1e-9, rtol=0)
    assert np.all(res.x[:, list(ident.fixed)] == 0.0)


def test_identifiable_combination_recovered_when_truth_has_fixed_error():
    """Truth with an error on d3 (not identifiable apart from d2 on the paper arm): the
    estimate of d2 is d2 + d3 up to the second-order model error (axes 2, 3 are no longer
    exactly parallel in the true robot)."""
    robot = jaxcal.preset("paper-6r")
    sim = simulate(robot, n_robots=3, n_poses=40, seed=5)
    res = calibrate_batch(robot, sim.q, sim.measured, method="gn", estimate_base=False, estimate_tool=False)
    C = res.identifiability.combination_matrix
    est = res.x[:, list(res.identifiability.base)]
    expect = sim.x_true @ C.T
    i_d2 = res.identifiability.base.index(res.names.index("d2"))
    assert_allclose(est[:, i_d2], sim.x_true[:, 5] + sim.x_true[:, 9], atol=1e-4)
    # second order: errors ~ 0.005 rad x 0.05 mm scale, far below the first-order size
    assert np.abs(est - expect).max() < 1e-3 * np.abs(expect).max()


def test_linear_one_shot_error_is_a_linearisation_error():
    """The one-shot linear solve is exact to first order: its error shrinks ~4x when the
    injected errors halve."""
    robot = jaxcal.preset("paper-6r")
    errs = []
    for s in (1.0, 0.5, 0.25):
        sim, ident = _truth_in_base_set(robot, n_poses=40, seed=2)
        x_true = sim.x_true * s
        sim2 = simulate(robot, n_robots=3, q=sim.q[0], x_true=x_true, seed=2)
        res = calibrate_batch(
            robot, sim2.q, sim2.measured, method="linear", ident=ident, estimate_base=False, estimate_tool=False
        )
        errs.append(np.abs(res.x - x_true).max())
    r1, r2 = errs[0] / errs[1], errs[1] / errs[2]
    assert 3.5 < r1 < 4.5 and 3.5 < r2 < 4.5, errs
    assert errs[0] > 1e-6  # and it is not exact: GN's job


def test_calibrate_single_result_object():
    robot = jaxcal.preset("puma560")
    sim, ident = _truth_in_base_set(robot, base=True, n_poses=30, seed=3)
    res = calibrate(robot, sim.q[0], sim.measured[0], estimate_base=True, estimate_tool=False)
    assert res.converged and res.num_steps >= 1
    assert_allclose(res.x, sim.x_true[0], atol=1e-9)
    assert res.after["pos_rms_mm"] < 1e-8 < res.before["pos_rms_mm"]
    # the calibrated robot reproduces the true robot's poses on new joint values
    import jax.numpy as jnp

    from jaxcal.error_model import perturb

    true_robot = eqx.filter_jit(perturb)(robot, jnp.asarray(sim.x_true[0]), base=True)
    assert_allclose(
        np.asarray(jaxcal.fk(res.robot, jnp.asarray(sim.q_val[0]))),
        np.asarray(jaxcal.fk(true_robot, jnp.asarray(sim.q_val[0]))),
        atol=1e-8,
    )
    assert "held at 0" in res.table() and res.delta("theta2") == res.x[4]


def test_not_converged_is_reported():
    robot = jaxcal.preset("paper-6r")
    sim = simulate(robot, n_robots=2, n_poses=30, seed=4, scales=error_scales(robot) * 20)
    res = calibrate_batch(
        robot, sim.q, sim.measured, method="gn", max_steps=1, estimate_base=False, estimate_tool=False
    )
    assert not res.converged.any()
    assert np.all(res.num_steps == 1)


def test_a_fit_not_to_use_is_returned_with_a_warning():
    """``calibrate`` and ``calibrate_data`` return an unconverged or implausible fit (``strict``
    off) marked, and warn (:class:`jaxcal.CalibrationWarning`): a script that saves the result
    without looking is told. A good fit gives no warning."""
    import warnings

    robot = jaxcal.preset("paper-6r")
    sim = simulate(robot, n_poses=30, seed=4, scales=error_scales(robot) * 20)
    q, T = np.asarray(sim.q[0]), np.asarray(sim.measured[0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert calibrate(robot, q, T).converged
    with pytest.warns(jaxcal.CalibrationWarning, match="did not converge"):
        assert not calibrate(robot, q, T, method="gn", max_steps=1).converged
    swapped = T.copy()
    swapped[:, :3, 3] = T[:, :3, 3][:, [1, 0, 2]]
    with pytest.warns(jaxcal.CalibrationWarning, match="is not plausible.*swapped x, y"):
        data = jaxcal.Measurements(q, swapped)
        assert not jaxcal.calibrate_data(robot, data, params="frames", folds=3, compliance="no").report["plausible"]


def test_rank_deficient_design_reports_not_garbage():
    """All poses with joints 4..6 at zero and few poses: the report names what is missing, the
    estimates are finite, fixed parameters are exactly zero."""
    robot = jaxcal.preset("paper-6r")
    rng = np.random.default_rng(0)
    q = np.zeros((12, 6))
    q[:, :3] = rng.uniform(-1, 1, (12, 3))
    sim = simulate(robot, n_robots=1, q=q, seed=0)
    res = calibrate(robot, q, sim.measured[0], estimate_base=False, estimate_tool=False)
    rep = res.identifiability.report()
    assert res.identifiability.rank < 23 and "fixed" in rep
    assert np.all(np.isfinite(res.x)) and np.all(res.x[list(res.identifiability.fixed)] == 0)


def test_inputs_are_checked_and_not_mutated():
    robot = jaxcal.preset("paper-6r")
    sim = simulate(robot, n_robots=1, n_poses=20, seed=0)
    q, meas = sim.q[0].copy(), sim.measured[0].copy()
    q0, m0 = q.copy(), meas.copy()
    calibrate(robot, q, meas, method="linear", estimate_base=False, estimate_tool=False)
    assert np.array_equal(q, q0) and np.array_equal(meas, m0)
    with pytest.raises(jaxcal.DataError, match="6 joints"):
        calibrate(robot, q[:, :5], meas)
    with pytest.raises(jaxcal.DataError, match="too few poses"):
        calibrate(robot, q[:3], meas[:3])
    bad = meas.copy()
    bad[7, 0, 3] = np.nan
    where = r"measured: non-finite value \(nan\) at pose index 7, matrix element \[0\]\[3\]"
    with pytest.raises(jaxcal.DataError, match=where):
        calibrate(robot, q, bad)


def test_base_keeps_its_gauge_and_offsets_stay_small():
    """A mounted UR5 (base yawed 1.1 rad, raised 120 mm) with small DH errors, including theta1, d1
    and whole turns added to theta3 and theta4 (the same kinematics): the base frame absorbs
    theta1 and d1 (held at 0 and named), every offset change is reported within half a turn and
    small, the lengths change by millimetres, and the model reproduces the arm on new poses.
    Data from an independent forward kinematics."""
    from helpers import dh_fk
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(31)
    ur5 = jaxcal.preset("ur5")
    err = np.c_[rng.normal(0, 2e-3, 6), rng.normal(0, 0.5, 6), rng.normal(0, 0.5, 6), rng.normal(0, 2e-3, 6)]
    dh_true = np.asarray(ur5.dh) + err
    dh_true[2, 0] += 4 * np.pi
    dh_true[3, 0] -= 4 * np.pi
    base = np.eye(4)
    base[:3, :3] = Rotation.from_euler("z", 1.1).as_matrix()
    base[:3, 3] = [400.0, -200.0, 120.0]
    q, q_new = rng.uniform(-np.pi, np.pi, (40, 6)), rng.uniform(-np.pi, np.pi, (20, 6))
    res = calibrate(ur5, q, dh_fk(dh_true, q, base=base))
    assert res.converged and res.plausible
    held = res.not_identified()
    for name in ("theta1", "d1"):
        assert res.delta(name) == 0.0 and "base" in held[name]
    for name in ("d3", "d4"):  # parallel axes 2-4: absorbed into d2, and said so (not "by the base")
        assert "d2" in held[name] and "base" not in held[name], held[name]
    d_theta = res.x[0:24:4]
    assert np.all(np.abs(d_theta) <= np.pi) and np.abs(d_theta).max() < 0.05
    assert np.abs(res.x[[1, 2, 5, 6, 9, 10, 13, 14, 17, 18, 21, 22]]).max() < 5.0
    saved_theta = np.asarray(res.robot.dh)[:, 0]
    assert np.all(np.abs(saved_theta - np.asarray(ur5.dh)[:, 0]) < 0.05)
    assert_allclose(np.asarray(jaxcal.fk(res.robot, q_new)), dh_fk(dh_true, q_new, base=base), atol=1e-6)


@pytest.mark.parametrize(
    "batch,kw",
    [(False, dict()), (False, dict(estimate_base=True, estimate_tool=True, position_only=True)), (True, dict())],
)
def test_the_solve_compiled_in_the_background_is_the_one_calibrate_runs(monkeypatch, batch, kw):
    """calibrate starts compiling its solve and its analysis before it has a start
    (jaxcal._config.jit.prepare), from stand-in arguments: their keys must be the real calls', or
    the compile is wasted."""
    keys, analysis = (solve_keys(monkeypatch, name) for name in ("_members", "_nominal"))
    ur5 = jaxcal.preset("ur5")
    sim = simulate(ur5, n_robots=3 if batch else 1, n_poses=30, seed=3, sigma_pos=0.01, sigma_rot=1e-5)
    res = calibrate_batch(ur5, sim.q, sim.measured, **kw) if batch else calibrate(ur5, sim.q[0], sim.measured[0], **kw)
    assert np.all(res.converged)
    # the fits themselves (the plausibility check that may follow is a batch of its own)
    assert len(keys["prepared"]) == 1 and keys["called"][:2] == keys["prepared"] * 2
    # the analysis too (a single data set's start takes its chain poses from it)
    assert len(analysis["prepared"]) == 1 and analysis["prepared"][0] in analysis["called"]


def test_a_scaled_prior_is_each_members_own():
    """With ``ridge_mm`` each member's prior is scaled by the lever of its own poses, as
    calibrate scales it for that data set alone: a member's answer does not depend on the
    others in its batch."""
    ur5 = jaxcal.preset("ur5")
    sim = simulate(ur5, n_robots=3, n_poses=30, seed=7, sigma_pos=0.02, sigma_rot=2e-5, base=True, tool=True)
    kw = dict(params="all", ridge_mm=1.0)
    res = calibrate_batch(ur5, sim.q, sim.measured, **kw)
    for r in range(3):
        alone = calibrate(ur5, sim.q[r], sim.measured[r], **kw)
        assert_allclose(res.x[r], alone.x, atol=1e-9)


def test_pose_weights_are_the_noises_not_the_nominal_models_errors():
    """Full poses, noise 0.02 mm and 2e-5 rad, no noise given: the weights are taken from the
    calibrated fit's residual (the frames-only one is the arm's errors, millimetres and
    milliradians, in another ratio). The reported standard errors then match the Monte Carlo
    spread of the estimates over noise draws (same truth, same poses), and the estimates are as
    precise as with the true noise given."""
    ur5 = jaxcal.preset("ur5")
    one = simulate(ur5, n_robots=1, n_poses=40, seed=11, base=True, tool=True)
    R = 48
    sim = simulate(
        ur5, n_robots=R, n_poses=40, seed=5, x_true=one.x_true[0], q=one.q[0], sigma_pos=0.02, sigma_rot=2e-5,
        base=True, tool=True,
    )  # fmt: skip
    res = calibrate(ur5, sim.q[0], sim.measured[0])
    assert res.sigma_rot_rad == pytest.approx(2e-5, rel=0.25) and res.sigma_pos_mm == pytest.approx(0.02, rel=0.25)
    batch = calibrate_batch(ur5, sim.q, sim.measured)
    assert_allclose(batch.x[0], res.x, atol=1e-9)  # the batch weighs each member as calibrate does
    given = calibrate_batch(ur5, sim.q, sim.measured, sigma_pos_mm=0.02, sigma_rot_rad=2e-5)
    free = np.flatnonzero(batch.estimated[0])
    spread = batch.x.std(0, ddof=1)[free]
    ratio = spread / res.std_errors[free]
    # 48 draws: a spread's own noise is about 10 %
    assert np.all((ratio > 0.6) & (ratio < 1.5)) and 0.85 < np.median(ratio) < 1.2, ratio
    assert_allclose(spread, given.x.std(0, ddof=1)[free], rtol=0.05)


def test_a_batch_says_which_fits_are_not_calibrations():
    """A member whose arm is far beyond the plausibility limits (errors 150 times the usual
    scale) is not a calibration, said in calibrate's words; the others stay plausible."""
    from jaxcal.simulation import error_scales

    ur5 = jaxcal.preset("ur5")
    s = error_scales(ur5, base=True, tool=True)
    xt = np.random.default_rng(0).normal(size=(3, len(s))) * s
    xt[2] *= 150
    sim = simulate(ur5, n_robots=3, n_poses=40, seed=7, x_true=xt, sigma_pos=0.02, sigma_rot=2e-5, base=True, tool=True)
    res = calibrate_batch(ur5, sim.q, sim.measured)
    assert list(res.plausible) == [True, True, False] and res.implausible[:2] == ("", "")
    # in calibrate's words: the parameter, its change and the option that limits it
    assert "changes by" in res.implausible[2] and "(max_angle_change_deg)" in res.implausible[2], res.implausible


def test_one_wild_row_is_an_outlier_not_a_unit_mistake():
    """A position of 99999 mm in one pose of one member (a tracker's sentinel): calibrate and
    the batch name it as an outlier; the length-unit check, robust to a few wild rows, does not
    refuse the data set, nor the batch the others."""
    ur5 = jaxcal.preset("ur5")
    sim = simulate(ur5, n_robots=3, n_poses=40, seed=3, sigma_pos=0.02, base=True, tool=True)
    P = np.array(sim.measured[:, :, :3, 3])
    P[2, 5] = 99999.0
    alone = calibrate(ur5, sim.q[2], P[2])
    assert alone.outliers == (5,) and alone.plausible
    res = calibrate_batch(ur5, sim.q, P)
    assert [res.outliers(r) for r in range(3)] == [(), (), (5,)] and res.converged.all()
    assert_allclose(res.x[2], alone.x, atol=1e-9)
    # more outliers than max_outlier_fraction: that member is not a calibration, as calibrate says;
    # strict refuses the batch naming it
    many = r"1 of 40 poses \(\d %\) are outliers, more than max_outlier_fraction 2 %"  # calibrate's words
    res = calibrate_batch(ur5, sim.q, P, max_outlier_fraction=0.02)
    assert res.implausible[:2] == ("", "") and re.search(many, res.implausible[2]), res.implausible
    with pytest.raises(jaxcal.ImplausibleFitError, match=r"1 of 3 data sets are not plausible .*data set 2: 1 of 40"):
        calibrate_batch(ur5, sim.q, P, max_outlier_fraction=0.02, strict=True)


def test_pose_weights_taken_again_leave_outliers_to_the_detection():
    """Full poses with one gross (3 mm) and five moderate position outliers: the weights taken
    again from the fit are medians, which the outliers do not set, so calibrate and the batch
    find the same outliers and the same model, and the gross one among them."""
    ur5 = jaxcal.preset("ur5")
    sim = simulate(ur5, n_robots=2, n_poses=40, seed=3, sigma_pos=0.02, sigma_rot=2e-5, base=True, tool=True)
    rng = np.random.default_rng(0)
    meas = np.array(sim.measured)
    bad = rng.choice(40, 6, replace=False)
    meas[0, bad[0], :3, 3] += rng.normal(size=3) * 3.0
    for k in bad[1:]:
        meas[0, k, :3, 3] += rng.normal(size=3) * rng.uniform(0.05, 0.12)
    alone = calibrate(ur5, sim.q[0], meas[0])
    res = calibrate_batch(ur5, sim.q, meas)
    assert res.outliers(0) == alone.outliers and bad[0] in alone.outliers and set(alone.outliers) <= set(bad)
    assert_allclose(res.x[0], alone.x, atol=1e-9)
    assert alone.sigma_pos_mm == pytest.approx(0.02, rel=0.3)  # the noise, not the outliers'


def test_a_calibrated_table_of_a_parallel_axis_arm_calibrates_again():
    """A UR5's calibrated DH table has its parallel axes 2-4 a few mrad off parallel (alpha2,
    alpha3): calibrating again from it (next year's recalibration) freed the d the nominal holds,
    whose common normal then ran by metres (d4 changed by 2107 mm: implausible, every seed). The
    axes are taken as parallel when the set is chosen. Data from a NumPy FK of a perturbed arm."""
    from helpers import dh_fk

    ur5 = jaxcal.preset("ur5")
    rng = np.random.default_rng(5)
    dh = np.asarray(ur5.dh) + rng.normal(size=(6, 4)) * [0.002, 0.3, 0.3, 0.002]
    tool = np.eye(4)
    tool[:3, 3] = [10.0, -20.0, 60.0]
    lim = np.asarray(ur5.q_limits)
    q1, q2, qv = (rng.uniform(lim[:, 0], lim[:, 1], size=(k, 6)) for k in (60, 60, 100))
    points = lambda q: dh_fk(dh, q, tool=tool)[:, :3, 3]  # noqa: E731
    first = calibrate(ur5, q1, points(q1) + rng.normal(0, 0.02, (60, 3)))
    assert first.plausible and 1e-4 < np.abs(np.asarray(first.robot.dh)[1:3, 3]).max() < 0.01
    again = calibrate(first.robot, q2, points(q2) + rng.normal(0, 0.02, (60, 3)))
    assert again.converged and again.plausible, again.implausible
    assert {"d3", "d4"} <= set(again.not_identified())
    assert np.abs(np.asarray(again.robot.dh) - np.asarray(first.robot.dh))[:, 1:3].max() < 2.0  # mm
    T = np.asarray(jaxcal.fk(again.robot, qv))
    pred = T[:, :3, :3] @ np.asarray(again.model.points[0]) + T[:, :3, 3]  # the measured point
    assert np.sqrt(np.mean(np.sum((pred - points(qv)) ** 2, -1))) < 0.05


def test_the_parameters_a_pose_set_must_identify_take_nearly_parallel_axes_as_parallel():
    """What counts as enough data (the generic rank) is judged on the set a calibration chooses:
    a UR5 table with alpha2, alpha3 3 mrad off parallel counted two d's that are never estimated
    (27 against the nominal's 25), refusing pose counts the fit needs no more than the nominal's."""
    from jaxcal.calibration._core import generic_model, generic_rank
    from jaxcal.model import Layout

    ur5 = jaxcal.preset("ur5")
    dh = np.asarray(ur5.dh).copy()
    dh[1:3, 3] = -0.003
    off = ur5.replace(dh=dh)
    lay = Layout.of(ur5, base=True, tool=True, n_points=1)
    cols = range(lay.size)
    assert generic_rank(generic_model(off, lay), lay, 60, cols) == generic_rank(generic_model(ur5, lay), lay, 60, cols)
