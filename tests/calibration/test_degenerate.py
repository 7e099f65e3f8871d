"""Degenerate designs (issue 8): all poses identical, joints that never move, rank-deficient
designs. The result says which parameters could not be identified and why, and never returns
NaN, for calibrate and calibrate_batch with gn, lm and linear."""

import numpy as np
import pytest

import jaxcal
from jaxcal.calibration import calibrate, calibrate_batch
from jaxcal.simulation import sample_poses, simulate

ROBOT = jaxcal.preset("paper-6r")
K = 12
DH = dict(estimate_base=False, estimate_tool=False)  # the DH table alone: its identifiability is the point
_rng = np.random.default_rng(11)
_q = np.asarray(sample_poses(__import__("jax").random.PRNGKey(3), ROBOT, (K,)))


def _identical():
    return np.tile(_q[:1], (K, 1))


def _joint6_still():
    q = _q.copy()
    q[:, 5] = 0.3
    return q


def _wrist_still():
    q = _q.copy()
    q[:, 3:] = 0.0
    return q


def _one_joint_moves():
    q = np.tile(_q[:1], (K, 1))
    q[:, 0] = np.linspace(-1, 1, K)
    return q


DESIGNS = {
    "identical poses": _identical,
    "joint 6 never moves": _joint6_still,
    "wrist never moves": _wrist_still,
    "only joint 1 moves": _one_joint_moves,
}


def _check_result(x, ident, converged=True):
    assert np.all(np.isfinite(x))
    assert np.all(x[..., list(ident.fixed)] == 0.0)
    reasons = ident.reasons()
    assert set(reasons) == set(ident.fixed_names) and len(reasons) > 0
    assert all(isinstance(v, str) and v for v in reasons.values())


@pytest.mark.parametrize("method", ["gn", "lm", "linear"])
@pytest.mark.parametrize("design", list(DESIGNS))
def test_calibrate_degenerate(design, method):
    q = DESIGNS[design]()
    sim = simulate(ROBOT, q=q, seed=2, sigma_pos=0.01, sigma_rot=1e-5)
    res = calibrate(ROBOT, q, sim.measured[0], method=method, **DH)
    ident = res.identifiability
    assert ident.rank < 24
    _check_result(res.x, ident)
    why = res.not_identified()
    assert set(why) == set(ident.reasons())
    if design == "joint 6 never moves":  # the still joint is named, in the notes and as the cause
        assert any("joint 6 (q6) never moves" in n for n in res.notes)
        assert all("joint 6 (q6) never moves in the data" in v for v in why.values())
    # the fit is no worse than the nominal model on its own data
    assert res.after["pos_rms_mm"] <= res.before["pos_rms_mm"] + 1e-9
    assert np.all(np.isfinite(res.std_errors))


@pytest.mark.parametrize("method", ["gn", "lm", "linear"])
@pytest.mark.parametrize("design", list(DESIGNS))
def test_calibrate_batch_degenerate(design, method):
    q = DESIGNS[design]()
    sim = simulate(ROBOT, n_robots=1, q=q, seed=2, sigma_pos=0.01, sigma_rot=1e-5)  # R=1: shares the compile
    res = calibrate_batch(ROBOT, sim.q, sim.measured, method=method, **DH)
    _check_result(res.x, res.identifiability)
    assert not res.nonfinite.any()


def test_identical_poses_rank_and_reasons():
    """K identical full poses give 6 independent equations: rank 6, and the reasons say why."""
    q = _identical()
    sim = simulate(ROBOT, q=q, seed=2)
    res = calibrate(ROBOT, q, sim.measured[0], **DH)
    assert res.identifiability.rank == 6
    why = res.not_identified()
    assert len(why) == 18
    assert all(("not separable" in v) or ("no effect" in v) or ("dependent" in v) for v in why.values())


def test_joint_that_never_moves_names_its_offset():
    """Joint 6 fixed: theta6 is not separable from the tool-side parameters; with the wrist
    still, the reasons name combinations (rank 23 of 24 or lower)."""
    res = calibrate(ROBOT, _wrist_still(), simulate(ROBOT, q=_wrist_still(), seed=2).measured[0], **DH)
    why = res.not_identified()
    assert any(k.endswith(("4", "5", "6")) for k in why)
    assert all("rank" in v or "no effect" in v for v in why.values())


@pytest.mark.filterwarnings("error::RuntimeWarning")  # nor numpy's empty-slice warnings in the user's console
def test_batch_data_set_with_its_own_degeneracy_never_nan():
    """The base set comes from data set 0 (data set 1, identical poses, moves no joint), so data set
    1's normal equations are singular on that base set. No NaN: reported and zeroed."""
    q0 = _q
    q1 = _identical()
    sim = simulate(ROBOT, n_robots=2, q=np.stack([q0, q1]), seed=4)
    for method in ("gn", "lm", "linear"):
        res = calibrate_batch(ROBOT, sim.q, sim.measured, method=method, **DH)
        assert np.all(np.isfinite(res.x)), method
        if res.nonfinite[1]:
            assert not res.converged[1] and np.all(res.x[1] == 0)
        assert not res.nonfinite[0]


def test_too_few_poses_says_how_many():
    q = _q[:3]
    sim = simulate(ROBOT, q=q, seed=2)
    with pytest.raises(jaxcal.DataError, match=r"3 poses x 6 rows = 18 equations for 23 parameters"):
        calibrate(ROBOT, q, sim.measured[0], **DH)  # 23: d2 and d3 are one parameter on this arm
    with pytest.raises(jaxcal.DataError, match=r"3 poses x 6 rows = 18 equations for 29 parameters"):
        calibrate(ROBOT, q, sim.measured[0])  # with the frames, which absorb 6 DH errors
    with pytest.raises(jaxcal.DataError, match="too few poses"):
        calibrate_batch(ROBOT, sim.q, sim.measured, **DH)


def test_divergence_is_a_result_code_not_nan():
    """Absurd data (every measured pose from a wildly wrong robot): converged False or a finite
    estimate, never NaN/inf; not converged within max_steps is reported."""
    rng = np.random.default_rng(0)
    sim = simulate(ROBOT, q=_q, seed=5, x_true=rng.normal(size=24) * np.tile([0.5, 30, 30, 0.5], 6))
    for method in ("gn", "lm"):
        try:
            res = calibrate(ROBOT, _q, sim.measured[0], method=method, max_steps=3, **DH)
        except jaxcal.DataError as e:  # non-finite solver output is refused, typed
            assert "non-finite" in str(e)
            continue
        assert np.all(np.isfinite(res.x)) and not res.converged


def test_batch_set_does_not_come_from_a_degenerate_data_set():
    """Four noise-free data sets of paper-6r with base and tool (NumPy FK, tests.helpers); in the
    first, joints 2 and 3 move together (q3 = 0.7 - q2: every joint moves, yet the poses cannot
    separate the set, and the batch fitted it with parameters calibrate alone holds, 1 mm off the
    truth); in the second, joint 3 only jitters (4e-4 rad, an encoder's
    read-back of a joint not moved, which calibrate takes as still); in the last, no joint does.
    They must not take parameters from the others (the jittering one was fitted in full, 2.5 mm
    off its single fit): the good one fits its poses exactly and converges; they are flagged,
    naming why, and not converged."""
    from tests.helpers import dh_fk, random_transform

    rng = np.random.default_rng(2)
    dh0, lim = np.asarray(ROBOT.dh), np.asarray(ROBOT.q_limits)
    q = lim[:, 0] + rng.uniform(size=(4, 30, 6)) * (lim[:, 1] - lim[:, 0])
    q[0, :, 2] = 0.7 - q[0, :, 1]
    q[1, :, 2] = 0.3 + np.random.default_rng(5).uniform(-4e-4, 4e-4, 30)
    q[3] = q[3, :1]
    truths = [
        (dh0 + rng.normal(size=dh0.shape) * [0.005, 0.05, 0.05, 0.005], random_transform(rng), random_transform(rng))
        for _ in range(4)
    ]
    poses = np.stack([dh_fk(t[0], q[i], base=t[1], tool=t[2]) for i, t in enumerate(truths)])
    res = calibrate_batch(ROBOT, q, poses)
    assert res.identifiability.rank == 29  # every data set that moves all joints identifies 29
    assert not res.converged[0] and res.problems[0].startswith("its poses do not separate the parameters")
    assert not res.converged[1] and res.problems[1] == "joint 3 (q3) never moves beyond 0.001 rad"
    assert not res.converged[3] and res.problems[3].startswith("no joint moves")
    for r in (0, 1, 3):  # named in problems: nothing estimated, and x says so
        assert not res.estimated[r].any() and np.all(res.x[r] == 0.0)
    qv = lim[:, 0] + rng.uniform(size=(100, 6)) * (lim[:, 1] - lim[:, 0])
    for r in (2,):
        assert res.converged[r] and res.problems[r] == ""
        single = calibrate(ROBOT, q[r], poses[r])  # the batch's fit is the single one...
        np.testing.assert_allclose(res.x[r], single.x, atol=1e-6)
        f, t = single.robot, truths[r]  # ...which predicts new poses of the true arm
        err = dh_fk(np.asarray(f.dh), qv, base=f.base, tool=f.tool) - dh_fk(t[0], qv, base=t[1], tool=t[2])
        assert np.abs(err[:, :3, 3]).max() < 1e-4


@pytest.mark.filterwarnings("ignore:greedy base set")  # near-repeated poses: a rank near its threshold
def test_rows_repeating_a_few_joint_vectors_are_not_a_calibration():
    """30 rows repeating 4 postures (read back with 1e-7 rad of encoder noise) give 12 equations, not
    90: the single fit is marked implausible, naming the repeats, and the data workflow refuses them."""
    q = np.repeat(_q[:4], [8, 8, 7, 7], axis=0) + np.random.default_rng(3).normal(scale=1e-7, size=(30, 6))
    points = simulate(ROBOT, q=q, seed=2, tool=True).measured[0, :, :3, 3]
    res = calibrate(ROBOT, q, points, estimate_base=False)
    assert not res.plausible and "only 4 of the 30 data rows have distinct joint values" in res.implausible
    with pytest.raises(jaxcal.DataError, match=r"4 distinct poses \(the other 26 of 30 rows repeat"):
        jaxcal.calibrate_data(ROBOT, jaxcal.Measurements(q, points[:, None]))


def test_a_batch_data_set_that_lost_a_pose_or_never_saw_a_point_does_not_stop_the_others():
    """Three data sets of paper-6r measured at two points on the tool (NumPy FK, tests.helpers):
    the second lost both points at one pose, the third never saw point 2. The second is fitted
    as calibrate fits it without that pose; the third is named in problems, not converged, with
    nothing estimated; the first is fitted as alone."""
    from tests.helpers import dh_fk, random_transform

    rng = np.random.default_rng(5)
    dh0, lim = np.asarray(ROBOT.dh), np.asarray(ROBOT.q_limits)
    q = lim[:, 0] + rng.uniform(size=(3, 30, 6)) * (lim[:, 1] - lim[:, 0])
    offsets = np.array([[0.0, 0.0, 60.0], [40.0, 30.0, 10.0]])
    pts = []
    for r in range(3):
        dh = dh0 + rng.normal(size=dh0.shape) * [0.005, 0.05, 0.05, 0.005]
        T = dh_fk(dh, q[r], base=random_transform(rng), tool=random_transform(rng))
        pts.append(np.einsum("kij,mj->kmi", T[:, :3, :3], offsets) + T[:, None, :3, 3])
    pts = np.stack(pts) + rng.normal(size=(3, 30, 2, 3)) * 0.02
    pts[1, 7] = np.nan
    pts[2, :, 1] = np.nan
    given = pts.copy()
    kw = dict(ridge_mm=0.5)  # each data set's prior scaled by its own levers, over the poses it measured
    res = calibrate_batch(ROBOT, q, pts, **kw)
    np.testing.assert_array_equal(pts, given)  # the caller's arrays untouched
    assert res.problems == ("", "", "point(s) 2 never measured")
    assert list(res.converged) == [True, True, False]
    assert not res.estimated[2].any() and np.all(res.x[2] == 0.0) and not res.outlier_mask[2].any()
    assert res.implausible[2] == "" and res.num_steps[2] == 0 and not res.nonfinite[2]  # nothing of another's
    assert not res.outlier_mask[1, 7]  # a lost pose is no outlier
    keep = np.arange(30) != 7
    np.testing.assert_allclose(res.x[1], calibrate(ROBOT, q[1, keep], pts[1, keep], **kw).x, atol=1e-6)
    np.testing.assert_allclose(res.x[0], calibrate(ROBOT, q[0], pts[0], **kw).x, atol=1e-6)


def test_a_batch_data_set_whose_camera_missed_a_pose_does_not_stop_the_others():
    """Three data sets of full poses (paper-6r, NumPy FK): the second has one pose NaN (a camera
    that did not find its target), the third none measured. The second is fitted as calibrate
    fits it without that pose, the third named in problems; a single fit refuses the NaN pose,
    naming it (the whole batch was refused)."""
    from tests.helpers import dh_fk, random_transform

    rng = np.random.default_rng(6)
    dh0, lim = np.asarray(ROBOT.dh), np.asarray(ROBOT.q_limits)
    q = lim[:, 0] + rng.uniform(size=(3, 30, 6)) * (lim[:, 1] - lim[:, 0])
    T = np.stack(
        [
            dh_fk(dh0 + rng.normal(size=dh0.shape) * [0.005, 0.05, 0.05, 0.005], q[r], base=random_transform(rng),
                  tool=random_transform(rng))
            for r in range(3)
        ]
    )  # fmt: skip
    T[..., :3, 3] += rng.normal(size=(3, 30, 3)) * 0.02
    T[1, 7, :3] = np.nan
    T[2] = np.nan
    res = calibrate_batch(ROBOT, q, T)
    assert res.problems == ("", "", "no pose measured at any pose") and list(res.converged) == [True, True, False]
    keep = np.arange(30) != 7
    np.testing.assert_allclose(res.x[1], calibrate(ROBOT, q[1, keep], T[1, keep]).x, atol=1e-6)
    with pytest.raises(jaxcal.DataError, match=r"measured\[7\]: no pose measured at this pose"):
        calibrate(ROBOT, q[1], T[1])


def test_a_joint_held_still_with_an_encoders_jitter_is_taken_as_still():
    """A UR5 (DH errors, base and tool; NumPy FK, tests.helpers) measured at 40 poses with its joint
    4 held at 0.3 rad, read back with 1e-4 rad of jitter. The jitter separates nothing the noise
    does not swamp: the set identified is the one for the joint exactly still, the note names it,
    and the model predicts poses where joint 4 moves as the still joint's model does, not tens of
    millimetres off along what the still joint leaves undetermined."""
    from tests.helpers import dh_fk, random_transform

    ur5 = jaxcal.preset("ur5")
    rng = np.random.default_rng(5)
    dh = np.asarray(ur5.dh) + rng.normal(size=(6, 4)) * [2e-3, 0.5, 0.5, 2e-3]
    base, tool = random_transform(rng, 1000.0), random_transform(rng, 100.0)
    q = rng.uniform(-np.pi, np.pi, (140, 6))
    truth = dh_fk(dh, q, base=base, tool=tool)[:, :3, 3]
    still = q[:40].copy()
    still[:, 3] = 0.3
    jitter = still.copy()
    jitter[:, 3] += rng.normal(scale=1e-4, size=40)
    measured = dh_fk(dh, still, base=base, tool=tool)[:, :3, 3]
    shaken = dh_fk(dh, jitter, base=base, tool=tool)[:, :3, 3]
    noise = rng.normal(scale=0.03, size=(40, 3))
    fits = [calibrate(ur5, qq, m + noise) for qq, m in ((still, measured), (jitter, shaken))]
    assert set(fits[1].identifiability.base) == set(fits[0].identifiability.base)
    assert any("joint 4 (q4) never moves in the data beyond" in n and "taken as still" in n for n in fits[1].notes)
    from jaxcal.model import predict

    errs = [
        np.sqrt(np.mean(np.sum((np.asarray(predict(f.model, q[40:])).reshape(-1, 3) - truth[40:]) ** 2, -1)))
        for f in fits
    ]
    assert errs[1] < 1.5 * errs[0] + 0.1, errs


def test_a_joint_moved_over_a_sliver_of_its_range_is_named():
    """UR5 poses over the whole of every joint's turn but joint 2, over 0.012 rad: the note names
    joint 2 and its span (the model is only checked there); the same poses with joint 2 over its
    turn, or a robot file's limits that the span fills, give no such note."""
    from jaxcal.calibration._single import narrow_joint_notes

    ur5 = jaxcal.preset("ur5")
    q = np.random.default_rng(7).uniform(-np.pi, np.pi, (30, 6))
    (note,) = narrow_joint_notes(ur5, np.c_[q[:, :1], 0.5 + 0.012 * np.linspace(0, 1, 30), q[:, 2:]])
    assert note.startswith("joint 2 (q2) moves over only 0.012 rad in the data (0.5 to 0.512, 0.2 % of a turn)")
    assert narrow_joint_notes(ur5, q) == ()
    tight = ur5.replace(q_limits=np.where(np.arange(6)[:, None] == 1, [[0.49, 0.52]], [[-np.pi, np.pi]]))
    assert narrow_joint_notes(tight, np.c_[q[:, :1], 0.5 + 0.012 * np.linspace(0, 1, 30), q[:, 2:]]) == ()
