"""The real-data workflow (`calibrate_data`) on simulated data: folds, the base/tool initial
guess, the cross-validated choice of parameter set, camera models, recovery of the true robot."""

import dataclasses
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import dh_fk, random_transform, solve_keys
from numpy.testing import assert_allclose, assert_array_equal

from jaxcal import DataError, Measurements, Options, fk, preset
from jaxcal.calibration import calibrate_data, fold_ids
from jaxcal.calibration._initial import initial_frames
from jaxcal.error_model import perturb
from jaxcal.simulation import simulate


def calibrate_measurements(robot, q, measured, *, position_only=False, **kw):
    """The workflow on arrays (positions when ``position_only``)."""
    meas = np.asarray(measured)
    return calibrate_data(robot, Measurements(q, meas[:, None, :3, 3] if position_only else meas), **kw)


def test_folds_deterministic_balanced_and_cover_every_pose():
    f = fold_ids(23, 5, seed=3)
    assert_array_equal(f, fold_ids(23, 5, seed=3))
    assert not np.array_equal(f, fold_ids(23, 5, seed=4))
    assert sorted(np.bincount(f)) == [4, 4, 5, 5, 5]
    for bad in (1, 24):
        with pytest.raises(DataError, match="folds must be between 2 and the number of poses"):
            fold_ids(23, bad, seed=0)
    # without repeats, the same folds as before grouping existed: a seeded permutation cut in turn
    want = np.empty(23, np.int64)
    want[np.random.default_rng(3).permutation(23)] = np.arange(23) % 5
    assert_array_equal(f, want)


def test_repeats_of_a_posture_are_held_out_together():
    """A posture measured again (joint readings within 1e-4 rad) is one posture: its repeats share
    a K-fold fold and a range-end fold, so a held-out pose's twin never trains the model that
    predicts it; the folds stay balanced."""
    from jaxcal.calibration._core import posture_ids, same_pose
    from jaxcal.calibration._selection import range_end_held

    rng = np.random.default_rng(8)
    ur5 = preset("ur5")
    q = rng.uniform(-np.pi, np.pi, (20, 6))
    q = np.concatenate([q, q[:12] + rng.normal(0, 2e-5, (12, 6)), q[:4] + 5e-5])  # twins and triplets
    groups = posture_ids(q, same_pose(ur5))
    assert len(set(groups.tolist())) == 20 and all(groups[20 + i] == groups[i] for i in range(12))
    f = fold_ids(len(q), 5, seed=1, groups=groups)
    for g in set(groups.tolist()):
        assert len(set(f[groups == g].tolist())) == 1
    assert np.bincount(f).max() - np.bincount(f).min() <= 3
    for m in range_end_held(q, np.ones(len(q), bool), groups=groups):
        assert all(m[groups == g].all() or not m[groups == g].any() for g in set(groups.tolist()))
    # fewer postures than folds: the inner folds are as many as the postures (none empty); the
    # outer ones are refused by calibrate_data, once the pose count's own check has spoken
    from jaxcal.calibration._selection import kfold_held

    few = np.repeat(np.arange(3), 4)
    assert len(kfold_held(np.ones(12, bool), 5, 0, few)) == 3
    twelve = np.repeat(q[:4], 3, axis=0) + rng.normal(0, 1e-6, (12, 6))
    full = np.asarray(fk(ur5, twelve))  # four postures of full poses: enough equations for the frames
    with pytest.raises(DataError, match=r"folds \(5\) more than the distinct postures \(4"):
        calibrate_data(ur5, Measurements(twelve, full), params="frames", compliance="no", folds=5)


def test_a_held_out_figure_is_not_lowered_by_listing_each_pose_twice():
    """A file of 24 poses of a point on the tool, and the same file with every row listed twice:
    the same information, so about the same held-out RMS (the folds differ), not the lower one a
    pose's copy left in the training set gives. Both fits are plausible."""
    import warnings

    rng = np.random.default_rng(16)
    ur5 = preset("ur5")
    dh = np.asarray(ur5.dh) + rng.normal(0.0, [1e-3, 0.3, 0.3, 1e-3], (6, 4))
    q = rng.uniform(-np.pi, np.pi, (24, 6))
    T = dh_fk(dh, q)
    tip = np.einsum("kij,j->ki", T[:, :3, :3], [20.0, -30.0, 80.0]) + T[:, :3, 3]
    kw = dict(params="all", folds=4, nested_max_poses=0, compliance="no")
    measured = tip + rng.normal(0, 0.05, tip.shape)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an implausible fit would warn
        once = calibrate_data(ur5, Measurements(q, measured[:, None]), **kw).report["heldout_rms_mm"]
        twice = calibrate_data(ur5, Measurements(np.tile(q, (2, 1)), np.tile(measured, (2, 1))[:, None]), **kw)
    assert 0.9 < twice.report["heldout_rms_mm"] / once < 1.3


@pytest.mark.parametrize("position_only", [False, True])
def test_initial_frames_exact_on_nominal_robot(rng, position_only):
    """Noise-free data of the nominal DH with unknown base and tool: the closed-form guess is exact."""
    r = preset("panda")
    B, X = random_transform(rng, 500.0), random_transform(rng, 100.0)
    lim = np.asarray(r.q_limits)
    q = lim[:, 0] + rng.uniform(size=(30, r.n_joints)) * (lim[:, 1] - lim[:, 0])
    meas = np.asarray(fk(r.replace(base=B, tool=np.asarray(r.tool) @ X), q))
    F = np.asarray(fk(r.replace(base=np.eye(4)), q))
    w = np.ones(len(q))
    if position_only:
        Bh, _, pts = initial_frames(F, np.asarray(r.base), meas[:, None, :3, 3], w, n_points=1)
        assert_allclose(pts[0], X[:3, 3], atol=1e-8)  # the tool rotation does not move the point
    else:
        Bh, Xh, _ = initial_frames(F, np.asarray(r.base), meas, w)
        assert_allclose(Xh, X, atol=1e-8)
    assert_allclose(Bh, B, atol=1e-8)
    # every member of a batch gets its own frames: all poses, the first 20 (consecutive poses give
    # the relative motions), all again
    sets = np.stack([w, (np.arange(len(q)) < 20).astype(float), w])
    target = meas[:, None, :3, 3] if position_only else meas
    Bs, Xs, _ = initial_frames(F, np.asarray(r.base), target, sets, n_points=int(position_only))
    assert Bs.shape == (3, 4, 4) and Xs.shape == (3, 4, 4)
    assert_allclose(Bs, np.broadcast_to(B, (3, 4, 4)), atol=1e-8)


def _sim(robot, x_dh, B, X, *, n=60, sp=0.05, sr=2e-4, seed=0):
    m = 4 * robot.n_joints
    sim = simulate(
        robot.replace(base=B, tool=np.asarray(robot.tool) @ X),
        n_poses=n,
        n_val=40,
        seed=seed,
        x_true=np.r_[x_dh, np.zeros(12)][: m + 12],
        sigma_pos=sp,
        sigma_rot=sr,
        base=True,
        tool=True,
    )
    return sim


def test_recovers_true_robot_and_honest_heldout(rng, monkeypatch):
    """DH errors + unknown frames: the calibrated model matches the true robot on poses it never saw,
    to about the noise level; frames only does not. Every fit runs the solve compiled in the
    background from the start."""
    keys = solve_keys(monkeypatch)
    r = preset("panda")
    x_dh = np.asarray(simulate(r, seed=5).x_true[0])[: 4 * r.n_joints] * 4  # ~0.02 rad, ~0.2 mm
    B, X = random_transform(rng, 500.0), random_transform(rng, 100.0)
    sim = _sim(r, x_dh, B, X)
    res = calibrate_measurements(r, sim.q[0], sim.measured[0], params="all", folds=3)
    assert set(keys["prepared"]) == set(keys["called"]) and len(keys["called"]) > 3
    true_val, q_val = sim.true_val[0], sim.q_val[0]
    err = np.linalg.norm(np.asarray(fk(res.robot, q_val))[:, :3, 3] - true_val[:, :3, 3], axis=1)
    fo = res.per_pose["frames_only"]
    err_fo = np.linalg.norm(np.asarray(fk(fo, q_val))[:, :3, 3] - true_val[:, :3, 3], axis=1)
    rep = res.report
    assert rep["converged"] and rep["cv_fits_converged"] == rep["cv_fits"]
    assert np.sqrt(np.mean(err**2)) < 0.1  # true model error, mm (noise 0.05 mm per axis)
    assert np.sqrt(np.mean(err_fo**2)) > 1.0
    # held-out error = model error + noise; noise alone is sqrt(3) * 0.05 = 0.087 mm RMS
    assert 0.07 < rep["heldout_rms_mm"] < 0.15
    assert rep["frames_only_heldout_rms_mm"] > 5 * rep["heldout_rms_mm"]
    assert rep["heldout_rms_mm"] > rep["train_rms_mm"] * 0.9
    assert set(rep["unidentifiable"]) == {"theta1", "d1", "a1", "alpha1", "theta7", "d7"}
    # standard errors are honest: most identified DH errors within 3 sigma of the truth
    # (a base-set estimate carries absorbed fixed errors, so compare only joints 2..6)
    names = r.param_names()
    z = [
        abs(p["value"] - x_dh[names.index(k)]) / p["std_error"]
        for k, p in rep["parameters"].items()
        if k in names and k[-1] in "23456"
    ]
    assert np.mean(np.array(z) < 3) > 0.9


def test_cv_prefers_simple_model_when_dh_is_exact(rng):
    """True DH = nominal: the cross-validated choice must not be the full set."""
    r = preset("panda")
    B, X = random_transform(rng, 500.0), random_transform(rng, 100.0)
    sim = _sim(r, np.zeros(28), B, X, n=40, sp=0.5, sr=2e-3, seed=2)
    res = calibrate_measurements(r, sim.q[0], sim.measured[0], params="auto", folds=4)
    assert res.report["choice"] != "all"
    assert len(res.report["selection"]["kept"]) <= 3  # what is kept is noise: at most a few
    assert res.report["heldout_rms_mm"] < 1.1 * res.report["frames_only_heldout_rms_mm"]


def test_camera_models_recovered_from_simulated_camera(rng):
    """A camera reporting the target through a linear distortion (I + A) t in its axes (depth 1 %
    long, a principal-point shear, a lateral scale): the linear model recovers A and predicts
    held-out poses far better than the plain model; the depth model recovers a pure depth scale."""
    from jaxcal.camera import apply_camera

    r = preset("panda")
    x_dh = np.asarray(simulate(r, seed=5).x_true[0])[: 4 * r.n_joints] * 2
    B, X = random_transform(rng, 500.0), random_transform(rng, 100.0)
    sim = _sim(r, x_dh, B, X, n=60, sp=0.05, sr=2e-4, seed=3)
    c = np.array([0.01, 0.004, -0.003, 0.002, 0.002, -0.003, 0.001, 0.002])  # depth, anisotropy, off-diagonal
    meas = np.asarray(apply_camera(np.asarray(sim.measured[0]), c, "linear"))
    kw = dict(params="all", folds=3)
    lin = calibrate_measurements(r, sim.q[0], meas, camera="linear", **kw).report
    without = calibrate_measurements(r, sim.q[0], meas, **kw).report
    got = np.array([v["value"] for v in lin["camera_parameters"].values()])
    assert_allclose(got, c, atol=5e-4)
    se = np.array([v["std_error"] for v in lin["camera_parameters"].values()])
    assert np.all(se > 0) and np.all(np.abs(got - c) < 5 * se + 1e-5)
    assert lin["heldout_rms_mm"] < 0.2 * without["heldout_rms_mm"]
    assert without["camera_model"] == "none" and without["camera_parameters"] is None
    meas_d = np.asarray(apply_camera(np.asarray(sim.measured[0]), np.array([0.01]), "depth"))
    dep = calibrate_measurements(r, sim.q[0], meas_d, camera="depth", **kw).report
    assert abs(dep["camera_parameters"]["camera_depth_scale"]["value"] - 0.01) < 1e-3
    with pytest.raises(DataError, match="camera model 'depth' needs full poses"):
        calibrate_measurements(r, sim.q[0], meas, position_only=True, camera="depth")
    with pytest.raises(DataError, match="camera must be one of none, depth, linear, quadratic, auto"):
        calibrate_measurements(r, sim.q[0], meas, camera="fisheye")


def test_quadratic_camera_model_recovered_on_franka_geometry(rng):
    """The Franka data's joint angles and camera geometry (target in front of the camera, 0.13-0.63 m
    away), DH errors, 0.05 mm noise, and a camera whose reports carry a linear map and the
    image-field term: the quadratic model recovers all 17 unknowns and predicts held-out poses
    at the noise level; the linear model cannot."""
    from jaxcal.camera import apply_camera
    from jaxcal.lie import make_transform, rpy_to_matrix
    from jaxcal.measurements import franka_csv_path, read_measurements

    r = preset("panda")
    q = read_measurements(franka_csv_path(), r, length_unit="m").q
    B = np.asarray(make_transform(rpy_to_matrix(np.radians([-0.1, 0.61, -0.02])), np.array([-656.0, 589.0, 7.2])))
    X = np.asarray(make_transform(rpy_to_matrix(np.radians([0.5, -0.9, 88.2])), np.array([91.2, -11.6, 142.7])))
    x_dh = np.asarray(simulate(r, seed=5).x_true[0])[: 4 * r.n_joints] * 2
    true = perturb(r.replace(base=B, tool=X), jnp.asarray(x_dh))
    T = np.array(fk(true, q))
    z = -np.einsum("ki,ki->k", T[:, :3, 2], T[:, :3, 3])
    assert z.min() > 100.0  # the geometry the model needs
    T[:, :3, 3] += rng.normal(0, 0.05, (len(q), 3))
    c = np.r_[0.005, 0.002, 0.004, -0.002, -0.01, 0.001, 0.003, 0.003, rng.normal(0, 0.01, 9)]
    meas = np.asarray(apply_camera(T, c, "quadratic"))
    kw = dict(params="all", folds=3)
    quad = calibrate_measurements(r, q, meas, camera="quadratic", **kw).report
    auto = calibrate_measurements(r, q, meas, camera="auto", **kw).report
    lin = {row["name"]: row for row in auto["cv"]}["all, camera linear"]
    # auto: the camera model is chosen by cross-validation (the nested figures include the choice)
    assert auto["camera_model"] == "quadratic" and auto["camera_model_option"] == "auto"
    assert auto["choice"] == "all, camera quadratic"
    assert {c.split(" (")[0] for c in auto["nested_choices"]} == {"all, camera quadratic"}
    assert [c["name"] for c in auto["cv"]] == [f"all, camera {m}" for m in ("none", "depth", "linear", "quadratic")]
    assert_allclose(auto["heldout_rms_mm"], quad["heldout_rms_mm"], rtol=1e-6)
    assert list(auto["camera_parameters"]) == list(quad["camera_parameters"])
    plain = calibrate_measurements(r, q, T, camera="auto", **kw).report  # a camera without distortion
    assert plain["camera_model"] == "none" and plain["camera_parameters"] is None
    got = np.array([v["value"] for v in quad["camera_parameters"].values()])
    se = np.array([v["std_error"] for v in quad["camera_parameters"].values()])
    assert list(quad["camera_parameters"])[8:] == [f"camera_Q_{a}_{f}" for a in "xyz" for f in ("uu", "vv", "uv")]
    assert np.all(se > 0) and np.all(np.abs(got - c) < 5 * se + 1e-6)
    assert_allclose(got, c, atol=2e-3)
    assert quad["heldout_rms_mm"] < 0.15  # noise alone: sqrt(3) * 0.05 = 0.087 mm
    assert lin["heldout_rms_mm"] > 2 * quad["heldout_rms_mm"]
    behind = meas.copy()
    behind[7, :3, 3] *= -1  # pose 7: target behind the camera
    with pytest.raises(
        DataError, match=r"model quadratic needs the target in front of the camera.*pose 7 \(data row 8\) has z = -"
    ):
        calibrate_measurements(r, q, behind, camera="quadratic", **kw)


def test_auto_chooses_on_the_problem_linearised_where_the_fit_is(rng):
    """DH errors of about a degree: the problem linearised at the frames-only fit misjudges the
    candidates (its residual there is mostly second order), so the selection is made again at the
    fit. The chosen model then matches the true robot on poses it never saw to the noise level,
    and the held-out figure says so."""
    r = preset("panda")
    x_dh = np.asarray(simulate(r, seed=5).x_true[0])[: 4 * r.n_joints] * 4
    B, X = random_transform(rng, 500.0), random_transform(rng, 100.0)
    sim = _sim(r, x_dh, B, X, sp=0.02, sr=2e-5)
    res = calibrate_measurements(r, sim.q[0], sim.measured[0], folds=3)
    err = np.linalg.norm(np.asarray(fk(res.robot, sim.q_val[0]))[:, :3, 3] - sim.true_val[0][:, :3, 3], axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.03  # noise 0.02 mm per axis; 0.23 mm when chosen at the frames-only fit
    assert res.report["heldout_rms_mm"] < 0.06


def test_rotation_rows_weighted_at_the_noises_ratio():
    """Full poses, noise 0.02 mm and 2e-5 rad, the arm's errors millimetres and milliradians: the
    frames-only residual's ratio of radians to millimetres is the errors', about 50 times the
    noise's. The workflow weighs the rotation rows at the noise's ratio, so its standard errors
    are those of calibrate, whose weights come from its own fit (checked against the Monte Carlo
    spread in test_calibrate.py)."""
    from jaxcal import calibrate

    ur5 = preset("ur5")
    one = simulate(ur5, n_robots=1, n_poses=40, seed=11, base=True, tool=True)
    sim = simulate(
        ur5, n_robots=1, n_poses=40, seed=5, x_true=one.x_true[0], q=one.q[0], sigma_pos=0.02, sigma_rot=2e-5,
        base=True, tool=True,
    )  # fmt: skip
    rep = calibrate_measurements(ur5, sim.q[0], sim.measured[0], params="all", folds=3).report
    ratio = np.radians(rep["sigma_rot_deg"]) / rep["sigma_pos_mm"]
    assert ratio == pytest.approx(2e-5 / 0.02, rel=0.3)
    alone = calibrate(ur5, sim.q[0], sim.measured[0], params="all")
    se = {alone.names[i]: alone.std_errors[i] for i in alone.free}
    both = [(rep["parameters"][n]["std_error"], se[n]) for n in se if n in rep["parameters"]]
    assert len(both) > 15
    assert_allclose(*np.array(both).T, rtol=0.2)


def test_millimetres_read_as_metres_are_refused_before_the_fit():
    """TIAGo points in mm read for its URDF (metres): a start fitted to the data agrees with any
    spread by a tool 1000x the arm, so it does not vouch for the unit; the refusal comes before
    any fit, naming the option."""
    from jaxcal import load_robot, read_measurements
    from jaxcal.measurements import tiago_paths

    urdf, csv = tiago_paths()
    robot = load_robot(urdf)
    m = read_measurements(csv, robot)
    mm = Measurements(m.q, np.asarray(m.measured) * 1000.0)
    with pytest.raises(DataError, match="millimetres read as metres") as e:
        calibrate_data(robot, mm, progress=lambda *a: pytest.fail("fitted before refusing"))
    assert e.value.option == "length_unit"


def test_a_marker_far_out_on_a_flange_that_barely_moves_is_not_taken_for_another_unit():
    """A pan-tilt head (axes 5 mm apart) carrying a marker 400 mm out, in mm: the start fitted to
    the data spreads some 45x the nominal flange, as a tool far out does; only another unit's
    factor between the data and the nominal (100x and more) makes that no evidence."""
    dh = np.array([[0.0, 0.0, 5.0, np.pi / 2], [0.0, 0.0, 5.0, 0.0]])
    from jaxcal import Robot

    robot = Robot(dh, convention="sdh", q_limits=np.array([[-1.5, 1.5], [-0.8, 0.8]]), name="pan-tilt")
    rng = np.random.default_rng(0)
    q = np.c_[rng.uniform(-1.2, 1.2, 60), rng.uniform(-0.6, 0.6, 60)]
    T = dh_fk(dh + rng.normal(0, [0.002, 0.3, 0.3, 0.002], dh.shape), q)
    p = np.einsum("kij,j->ki", T[:, :3, :3], [400.0, 30.0, -20.0]) + T[:, :3, 3]
    rep = calibrate_data(
        robot, Measurements(q, p[:, None] + rng.normal(0, 0.02, (60, 1, 3))), nested_max_poses=0
    ).report
    assert rep["plausible"] and rep["heldout_rms_mm"] < 0.1


@pytest.mark.parametrize("exchanged", [False, True])
@pytest.mark.parametrize("forced", [False, True])
def test_a_pruning_the_linearisation_misjudged_is_undone(monkeypatch, exchanged, forced):
    """``tests/data/custom_arm`` (its README): an odd arm whose joint origins are a millimetre and
    a few mrad off, measured as exact poses. The selection keeps what the full fit needs, with the
    base set of the parameter order alone or the default one (exchanged after the order,
    ``jaxcal.identifiability.DOMINANCE``). Where the linearised problem nonetheless finds y3 and
    ry4 of no use (``forced``: as its unscaled normal equations once did), the model without them,
    fitted in full, leaves several times the residual of the chosen set: nothing is pruned and a
    note says why. Either way the model is within the noise of the truth on new postures."""
    import jaxcal.identifiability
    from jaxcal import load_robot, read_measurements
    from jaxcal.calibration import _selection
    from jaxcal.model import predict

    if not exchanged:
        monkeypatch.setattr(jaxcal.identifiability, "DOMINANCE", np.inf)
    d = Path(__file__).resolve().parents[1] / "data" / "custom_arm"
    robot = load_robot(d / "custom.urdf", base_link="base_link", tip_link="flange")
    if forced:
        prune, names = _selection.prune, robot.param_names()

        def misjudged(lin, rule, free, prior, prunable):
            kept, dropped, kept_t = prune(lin, rule, free, prior, prunable)
            kept = kept.copy()
            for name in ("ry4", "y3"):
                j = names.index(name)
                if kept[j] and prunable[j]:  # not once the pruning is undone
                    kept[j] = False
                    dropped += ((j, 0.1, 0.0),)
            return kept, dropped, kept_t

        monkeypatch.setattr(_selection, "prune", misjudged)
    # the order's set writes a link 67 mm off the arm, beyond the default limit (the exchange is why)
    far = {} if exchanged else dict(max_length_change_mm=250.0)
    res = calibrate_data(robot, read_measurements(d / "poses_train.csv", robot), **far)
    assert res.report["plausible"], res.report["implausible"]
    undone = [n for n in res.report["notes"] if n.startswith("not pruned: the selection would drop")]
    assert bool(undone) == forced
    if forced:
        assert "drop ry4" in undone[0]  # (y3 is not in the exchanged set)
    assert not res.report["selection"]["dropped"]
    new = read_measurements(d / "truth_new.csv", robot)
    err = np.asarray(predict(res.model, new.q))[:, :3, 3] - new.measured[:, 0]
    assert np.sqrt(np.mean(np.sum(err**2, -1))) < 0.03  # noise-free truth; the data's noise 0.03 mm


def test_known_frames_are_a_model_to_choose_from():
    """Base and tool known (--no-estimate-base --no-estimate-tool): the simplest candidate has no
    parameter at all, which the choice took the condition of (an IndexError, exit 1). Data of a
    paper-6r with DH errors measured in its own base frame (NumPy FK): the default model is chosen
    and predicts new poses of the true arm near the noise."""
    r = preset("paper-6r")
    rng = np.random.default_rng(11)
    lim = np.asarray(r.q_limits)
    q = lim[:, 0] + rng.uniform(size=(40, 6)) * (lim[:, 1] - lim[:, 0])
    dh = np.asarray(r.dh) + rng.normal(size=(6, 4)) * [0.002, 0.3, 0.3, 0.002]
    fk_np = lambda qq: dh_fk(dh, qq, convention=r.convention, base=r.base, tool=r.tool)[:, :3, 3]  # noqa: E731
    points = fk_np(q) + rng.normal(0, 0.02, (40, 3))
    kw = dict(estimate_base=False, estimate_tool=False, folds=3, max_residual_mm=7.0)
    res = calibrate_data(r, Measurements(q, points[:, None]), **kw)
    assert res.report["converged"] and res.report["plausible"]
    # the report holds every option as given (a rerun's), and the limits the fit was judged against
    assert res.report["options"] == dataclasses.asdict(Options(**kw))
    assert res.report["plausibility_limits"]["max_residual_mm"] == 7.0
    assert res.report["plausibility_limits"]["max_angle_change_deg"] == pytest.approx(Options().max_angle_change_deg)
    assert res.report["cv"][0]["name"] == "frames" and res.report["cv"][0]["free_parameters"] == 0
    qv = lim[:, 0] + rng.uniform(size=(50, 6)) * (lim[:, 1] - lim[:, 0])
    fit = res.robot
    pred = dh_fk(np.asarray(fit.dh), qv, convention=fit.convention, base=fit.base, tool=fit.tool)[:, :3, 3]
    assert np.sqrt(np.mean(np.sum((pred - fk_np(qv)) ** 2, -1))) < 0.1


def test_a_prior_given_with_the_automatic_choice_is_refused():
    """ridge_mm is the prior of an explicit params set; with params 'auto' (which chooses its own)
    it was ignored without a word."""
    r = preset("paper-6r")
    q = np.random.default_rng(1).uniform(-1.0, 1.0, (20, 6))
    with pytest.raises(DataError, match=r"ridge_mm 0.5: a prior for an explicit params set"):
        calibrate_data(r, Measurements(q, np.zeros((20, 1, 3))), ridge_mm=0.5)


def test_a_small_session_tries_the_candidates_it_can_fit():
    """Eight poses of a UR5 whose joint offsets drifted (a recalibration session): params auto
    refused them ("too few poses ... 27 parameters") although joint offsets alone fit them. The
    candidates a training set cannot identify are left out and named. NumPy FK of the arm."""
    r = preset("ur5")
    rng = np.random.default_rng(8)
    dh = np.asarray(r.dh).copy()
    dh[:, 0] += rng.normal(0, 2e-3, 6)  # the offsets drifted
    lim = np.asarray(r.q_limits)
    q, qv = rng.uniform(lim[:, 0], lim[:, 1], (8, 6)), rng.uniform(lim[:, 0], lim[:, 1], (100, 6))
    tool = np.eye(4)
    tool[:3, 3] = [20.0, -10.0, 100.0]
    points = lambda qq: dh_fk(dh, qq, tool=tool)[:, :3, 3]  # noqa: E731
    res = calibrate_data(r, Measurements(q, (points(q) + rng.normal(0, 0.02, (8, 3)))[:, None]), compliance="no")
    rep = res.report
    assert rep["converged"] and rep["plausible"]
    assert {c["name"] for c in rep["cv"]} == {"frames", "offsets"} and rep["choice"].startswith("offsets")
    assert any("not tried" in n and "all, prior 1 mm" in n for n in rep["notes"])
    pred = np.asarray(fk(res.robot, qv))[:, :3, 3]  # its tool is the measured point
    assert np.sqrt(np.mean(np.sum((pred - points(qv)) ** 2, -1))) < 0.2


@pytest.mark.parametrize("poses", [False, True])
def test_a_scara_keeps_its_tool_where_the_data_cannot_place_it(poses):
    """A SCARA (R, R, P, R: every axis parallel; NumPy FK) measured by a tracker 2 m below its
    base: a shift along the axes sits in the base or the tool alike, and the data cannot tell
    which. The tool keeps the robot file's height (the base, unknown anyway, takes the shift);
    the start split it between the two and wrote the tool 995 mm off the flange."""
    from jaxcal import Robot
    from jaxcal.model import measured_robot, predict

    dh = np.array([[0.0, 400.0, 325.0, 0.0], [0.0, 0.0, 275.0, np.pi], [0.0, 0.0, 0.0, 0.0], [0.0, 50.0, 0.0, 0.0]])
    tool = np.eye(4)
    tool[:3, 3] = [40.0, 15.0, 90.0]
    lim = np.array([[-2.6, 2.6], [-2.5, 2.5], [0.0, 200.0], [-3.0, 3.0]])
    robot = Robot(dh, joint_types=["R", "R", "P", "R"], q_limits=lim, tool=tool, name="scara")
    rng = np.random.default_rng(3)
    true_dh = dh + rng.normal(0, [0.001, 0.3, 0.5, 0.001], dh.shape)
    true_tool = tool.copy()
    true_tool[:3, 3] += [-0.3, -0.8, -0.45]
    base = random_transform(rng, 10.0)
    base[:3, :3] = np.eye(3)  # the tracker's axes near the robot's, its origin 2 m below
    base[2, 3] = -2000.0
    q = lim[:, 0] + (lim[:, 1] - lim[:, 0]) * rng.uniform(0.05, 0.95, (50, 4))
    T = dh_fk(true_dh, q, joint_types="RRPR", base=base, tool=true_tool)
    if poses:
        measured = T.copy()
        measured[:, :3, 3] += rng.normal(0, 0.02, (50, 3))
    else:
        measured = T[:, None, :3, 3] + rng.normal(0, 0.02, (50, 1, 3))
    res = calibrate_data(robot, Measurements(q, measured), nested_max_poses=0)
    assert res.report["plausible"] and "tool_z" in res.report["not_estimated"]
    written = np.asarray(measured_robot(res.model).tool)[:3, 3]
    assert written[2] == pytest.approx(90.0, abs=0.05)  # the file's height, not the truth's (unobservable)
    assert np.asarray(res.model.robot.base)[2, 3] == pytest.approx(-2000.0, abs=5.0)  # with the d errors
    q_new = lim[:, 0] + (lim[:, 1] - lim[:, 0]) * rng.uniform(0.05, 0.95, (30, 4))  # and predicts as well
    want = dh_fk(true_dh, q_new, joint_types="RRPR", base=base, tool=true_tool)[:, :3, 3]
    got = np.asarray(predict(res.model, q_new)).reshape(30, -1)
    got = got[:, :3] if not poses else np.asarray(predict(res.model, q_new))[:, :3, 3]
    assert np.sqrt(np.mean(np.sum((got - want) ** 2, -1))) < 0.05
