"""Model selection (jaxcal.calibration._selection and the workflow's use of it): the physically
scaled prior against its formula, the folds of the scoring rule, the linearised fit against the
full one, and the selection on simulated robots whose true errors are known."""

import equinox as eqx
import numpy as np
import pytest
from helpers import bent_ur5, dh_fk, random_transform
from numpy.testing import assert_allclose

import jaxcal
from jaxcal import Measurements, preset
from jaxcal.calibration import _selection as selection
from jaxcal.calibration import calibrate_data, identify
from jaxcal.model import Layout, Model, jacobian


def test_lever_is_the_rms_distance_of_the_points_from_the_axis(rng):
    """A joint offset's lever is the RMS distance of the measured points from the joint's axis
    (NumPy frames, written apart from jaxcal); a length's is 1."""
    ur5 = preset("ur5")
    dh = np.asarray(ur5.dh)
    q = rng.uniform(-2, 2, (25, 6))
    pts = rng.normal(0, 80.0, (2, 3))
    T = dh_fk(dh, q)
    P = np.einsum("kij,mj->kmi", T[:, :3, :3], pts) + T[:, None, :3, 3]
    lay = Layout.of(ur5, n_points=2)
    lev = selection.lever(np.asarray(eqx.filter_jit(jacobian)(Model(ur5, pts), lay, q)), 2)
    for i in range(6):  # standard DH: joint i turns about z of frame i-1
        F = np.broadcast_to(np.eye(4), (25, 4, 4)) if i == 0 else dh_fk(dh[:i], q[:, :i])
        u, o = F[:, None, :3, 2], F[:, None, :3, 3]
        dist = np.linalg.norm(np.cross(P - o, u), axis=-1)
        assert_allclose(lev[4 * i], np.sqrt(np.mean(dist**2)), rtol=1e-9)
        assert_allclose(lev[4 * i + 1], 1.0, rtol=1e-12)  # d_i moves every point by itself
    assert lev[4 * 2] > 100.0  # the test can fail: levers of hundreds of mm


def test_prior_of_scales_each_parameter_by_its_lever(rng):
    """The prior of ``ridge_mm = s`` holds a parameter with weight lever / s: an angle whose lever
    is 400 mm is held as tightly as the 1 / 400 rad that moves the points s mm."""
    from jaxcal.calibration import Candidate
    from jaxcal.calibration._single import prior_of

    r = preset("ur5")
    q = rng.uniform(-2, 2, (30, 6))
    lay = Layout.of(r, n_points=1)
    ident = identify(r, q, n_points=1, estimate_base=False, estimate_tool=False)
    lever = rng.uniform(1.0, 500.0, lay.size)
    cand = Candidate("all", tuple(range(24)), 2.0)
    p = prior_of(lay, ident, cand, lever=lever)
    for i in ident.base:
        assert p[i] == pytest.approx(lever[i] / 2.0)


def test_range_end_folds_hold_out_what_they_claim(rng):
    """Each range-end set holds out the poses with the lowest (or highest) values of one joint, all
    beyond the range of the poses left to fit; a joint that does not move has none."""
    q = rng.uniform(-1, 1, (40, 4))
    q[:, 2] = 0.3  # never moves
    valid = np.ones(40, bool)
    valid[[3, 9]] = False
    held = selection.range_end_held(q, valid)
    assert held.shape == (6, 40)  # joints 1, 2, 4: two ends each
    assert not held[:, ~valid].any()
    n = round(selection.END_FRACTION * valid.sum())
    for f, (j, end) in enumerate([(0, "lo"), (0, "hi"), (1, "lo"), (1, "hi"), (3, "lo"), (3, "hi")]):
        h, rest = held[f], valid & ~held[f]
        assert h.sum() == n
        if end == "lo":
            assert q[h, j].max() < q[rest, j].min()
        else:
            assert q[h, j].min() > q[rest, j].max()
    kf = selection.kfold_held(valid, 5, seed=1)
    assert_allclose(kf.sum(0), valid.astype(int))  # every valid pose held out exactly once


def test_linearised_fit_is_the_full_fit_to_second_order(rng):
    """Near the truth the linearised fit of all parameters predicts what the full (Gauss-Newton)
    fit predicts, to second order in the errors: at the data's poses the two models' point
    positions agree far better than either agrees with the frames-only model they start from."""
    r = preset("ur5")
    q = rng.uniform(-2, 2, (40, 6))
    dx = rng.normal(0, [1e-4, 0.02, 0.02, 1e-4], (6, 4))  # small DH errors (rad, mm)
    points = dh_fk(np.asarray(r.dh) + dx, q, base=random_transform(rng, 400.0))[:, :3, 3]
    res = jaxcal.calibrate(r, q, points, params="all", keep_outliers=True)
    ref = jaxcal.calibrate(r, q, points, params="frames", keep_outliers=True).model
    J = np.asarray(eqx.filter_jit(jacobian)(ref, res.layout, q))  # compiled: one program, not one per operation
    predict = eqx.filter_jit(jaxcal.model.predict)
    p0 = np.asarray(predict(ref, q))[:, 0]
    lin = selection.linearise(J, points - p0, np.ones(3), 1)
    free = np.zeros(res.layout.size, bool)
    free[list(res.identifiability.base)] = True
    x = selection.fit(lin, np.ones((1, 40)), free[None], np.zeros((1, res.layout.size)))[0, 0]
    moved_lin = np.einsum("krm,m->kr", J, x)
    moved_full = np.asarray(predict(res.model, q))[:, 0] - p0
    assert np.abs(moved_full).max() > 0.05  # the calibration moves the points
    assert np.abs(moved_lin - moved_full).max() < 1e-2 * np.abs(moved_full).max()


def _simulated(robot, x_dh, rng, *, compliance=None, n=60, sigma=0.02):
    """Points on a tool of ``robot`` with DH errors ``x_dh`` (and joint ``compliance``), an unknown
    measurement frame, ``sigma`` mm noise: data from jaxcal's forward kinematics of the true arm."""
    true = robot.replace(dh=np.asarray(robot.dh) + x_dh, base=random_transform(rng, 400.0), compliance=compliance)
    lim = np.asarray(robot.q_limits) * 0.9
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, robot.n_joints))
    tip = np.array([30.0, -20.0, 60.0])
    T = np.asarray(jaxcal.fk(true, q))
    pts = T[:, :3, :3] @ tip + T[:, :3, 3] + rng.normal(0, sigma, (n, 3))
    return Measurements(q, pts[:, None, :])


def test_selection_keeps_the_perturbed_parameters_of_a_sparse_truth(rng):
    """Only four identifiable DH parameters of a Panda are wrong (0.5 mm, 1 mrad; noise 0.02 mm).
    In three data sets the selection never drops one of them, keeps exactly those four in at
    least two (a null parameter estimated 3 standard errors from 0 happens about once in three
    data sets of 22 null parameters), says why every other parameter was dropped, and predicts
    new postures at the noise level. The arm is rigid: no compliance is chosen."""
    r = preset("panda")
    names = r.param_names()
    wrong = {"a4": 0.5, "theta3": 1e-3, "d5": -0.5, "alpha5": -1e-3}
    x = np.zeros(28)
    for k, v in wrong.items():
        x[names.index(k)] = v
    exact = 0
    for seed in (7, 8, 9):
        meas = _simulated(r, x.reshape(7, 4), np.random.default_rng(seed))
        ident = identify(r, meas.q, n_points=1)
        base = {names[i] for i in ident.base if i < len(names)}
        assert set(wrong) <= base
        res = calibrate_data(r, meas)
        rep = res.report
        kept = set(rep["selection"]["kept"])
        assert set(wrong) <= kept and not rep["compliance"]
        # a rigid model, not one of zero compliances: its files hold none (a candidate had them)
        assert any(c["name"].endswith("compliance") or "+ compliance" in c["name"] for c in rep["cv"])
        assert res.robot.compliance is None and res.model.robot.compliance is None
        exact += kept == set(wrong)
        for k in base - kept:
            why = rep["not_estimated"][k]
            assert "dropped by the selection" in why or "not in the chosen set" in why
        for k, v in wrong.items():
            assert rep["parameters"][k]["value"] == pytest.approx(v, abs=4 * rep["parameters"][k]["std_error"])
        assert rep["heldout_rms_mm"] < 2 * np.sqrt(3) * 0.02
    assert exact >= 2


def test_selection_chooses_compliance_for_a_compliant_arm(rng):
    """A Panda whose joints 2 and 4 turn under gravity (about 3 mrad at full moment): a model with
    compliances is chosen, those two are kept, and the held-out error is near the noise; the same
    run with compliance="no" is far worse."""
    r = preset("panda")
    c = np.zeros(7)
    c[[1, 3]] = [4e-6, 6e-6]
    meas = _simulated(r, np.zeros((7, 4)), rng, compliance=c)
    rep = calibrate_data(r, meas).report
    assert rep["compliance"] and {"compliance2", "compliance4"} <= set(rep["selection"]["kept"])
    for k in ("compliance2", "compliance4"):
        want = c[int(k[-1]) - 1]
        assert rep["parameters"][k]["value"] == pytest.approx(want, rel=0.1)
    assert rep["heldout_rms_mm"] < 2 * np.sqrt(3) * 0.02
    rigid = calibrate_data(r, meas, compliance="no").report
    assert rigid["heldout_rms_mm"] > 3 * rep["heldout_rms_mm"]


def test_each_fold_prunes_in_its_own_order(rng):
    """How many parameters to drop is scored by folds that each order the parameters by a fit on
    their own training poses: against a loop over the folds written with plain least squares
    (np.linalg.lstsq on the stacked rows, sandwich standard errors from the training residual),
    and with nothing dropped the score is the candidate's own."""
    K, rows, m = 30, 3, 8
    J = rng.normal(size=(K, rows, m))
    x_true = np.r_[rng.normal(0, 2.0, 4), np.zeros(m - 4)]  # four live, four null parameters
    r = np.einsum("krm,m->kr", J, x_true) + rng.normal(0, 1.0, (K, rows))
    lin = selection.linearise(J, r, np.ones(rows), n_points=1)
    q = rng.uniform(-1, 1, (K, 2))
    rule = selection.Rule.of(lin, q, np.ones(K, bool), 5, seed=3)
    free, prior = np.ones(m, bool), np.zeros(m)
    prunable = np.arange(m) >= 2  # the first two are frames: never dropped
    scores, _ = selection.pruned_scores(lin, rule, free, prior, prunable, steps=6)
    assert scores[0] == pytest.approx(selection.score(lin, rule, free[None], prior[None])[0], rel=1e-9)
    sq = [[] for _ in range(7)]
    for f, held in enumerate(rule.held):
        train = ~held
        A, b = J[train].reshape(-1, m), r[train].reshape(-1)
        keep = free.copy()
        for n in range(7):
            x = np.zeros(m)
            x[keep] = np.linalg.lstsq(A[:, keep], b, rcond=None)[0]
            e = r[held] - np.einsum("krm,m->kr", J[held], x)
            sq[n].append((f, np.sum(e**2, -1)))
            res = b - A @ x
            s2 = res @ res / (len(b) - keep.sum())
            se = np.zeros(m)
            se[keep] = np.sqrt(s2 * np.diag(np.linalg.inv(A[:, keep].T @ A[:, keep])))
            t = np.where(keep & prunable, np.abs(x) / np.where(se > 0, se, 1), np.inf)
            keep[np.argmin(t)] = False
    for n in range(7):
        kf = np.concatenate([e for f, e in sq[n] if f < rule.n_kfold])
        ends = np.concatenate([e for f, e in sq[n] if f >= rule.n_kfold])
        assert scores[n] == pytest.approx(np.sqrt(0.5 * kf.mean() + 0.5 * ends.mean()), rel=1e-6)
    assert np.argmin(scores) >= 3  # the test can fail: dropping the null parameters helps


def test_a_compliance_candidate_scores_as_its_full_fits_predict():
    """The bent UR5 (:func:`helpers.bent_ur5`), 0.05 mm noise. The linearised score of ``all +
    compliance`` is the held-out error of its fits in full (nested cross-validation, the same
    folds): the compliances' columns (rad/mm, ~1e5 mm per unit) beside the millimetres once held
    the other parameters by their scale, and scored the compliant model up to a fifth worse than
    its fits (5 % here), no better than the rigid one."""
    ur5 = preset("ur5")
    dh, base, c, tau, q, p = bent_ur5()
    res = calibrate_data(ur5, Measurements(q, p[:, None, :]), params="all", compliance="yes")
    rep = res.report
    (cand,) = rep["cv"]
    assert cand["name"] == "all + compliance"
    assert cand["heldout_rms_mm"] == pytest.approx(rep["heldout_rms_mm"], rel=0.01)
    assert rep["parameters"]["compliance2"]["value"] == pytest.approx(c[1], rel=0.2)
    # the report says what the rigid geometry alone (what a URDF or UR file reader loads) errs on
    # the data: NumPy FK of the calibrated table without its compliances
    r = res.model.robot
    F = dh_fk(np.asarray(r.dh), q, base=np.asarray(r.base), tool=np.asarray(r.tool))
    rigid = F[:, :3, :3] @ np.asarray(res.model.points)[0] + F[:, :3, 3]
    want = np.sqrt(np.mean(np.sum((rigid - p) ** 2, -1)))
    assert rep["rigid_geometry_rms_mm_on_the_data"] == pytest.approx(want, rel=1e-6)
    assert want > 3 * rep["rms_mm_on_the_data_with_compliance"]
    assert any("a reader of the rigid geometry" in n for n in rep["notes"])
    # that rigid geometry is the arm at its mean load over the data, not weightless: the shoulder's
    # offset is the truth's plus compliance x mean moment (3.7e-4 rad; its standard error 3e-5),
    # and the table errs about as the true arm frozen at that load (0.47 mm weightless)
    m = tau(q).mean(0)
    assert_allclose(np.asarray(r.moment_ref), m, rtol=0.01, atol=0.5)
    assert np.asarray(r.dh)[1, 0] - dh[1, 0] == pytest.approx(c[1] * m[1], abs=1e-4)
    frozen = base @ dh_fk(dh, q + c * m)
    frozen = frozen[:, :3, :3] @ np.array([40.0, -30.0, 90.0]) + frozen[:, :3, 3]
    assert want < 1.1 * np.sqrt(np.mean(np.sum((frozen - p) ** 2, -1)))
    (row,) = [row for row in jaxcal.export.dh_rows(res) if row["parameter"] == "reference_moment2"]
    assert row["calibrated"] == pytest.approx(m[1], rel=0.01) and row["std_error"] is None
