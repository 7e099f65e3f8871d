"""Monte Carlo study: GN is efficient (its variance reaches the Cramér–Rao bound)."""

import json

import numpy as np
import pytest

import jaxcal
from jaxcal.calibration import calibrate_batch, identify
from jaxcal.experiments import crlb_batch, crlb_variances, run_montecarlo
from jaxcal.simulation import simulate

DH = dict(estimate_base=False, estimate_tool=False)


@pytest.fixture(scope="module")
def gn_study():
    return run_montecarlo(
        jaxcal.preset("paper-6r"),
        n_robots=300,
        n_poses=30,
        n_val=20,
        sigma_pos=0.02,
        sigma_rot=2e-5,
        method="gn",
        seed=11,
        repeats=1,
    )


def test_gn_variance_within_10_percent_of_crlb(gn_study):
    assert gn_study["converged_fraction"] == 1.0
    assert 0.9 < gn_study["crlb_efficiency_mean"] < 1.1, gn_study["crlb_efficiency"]
    assert gn_study["fixed"] == ["d3"] and gn_study["rank"] == 23


def test_validation_error_at_noise_level(gn_study):
    # calibrated models reproduce the true robots to the noise level (0.02 mm), far below
    # the uncalibrated error (~ several mm for the paper's error scales)
    assert gn_study["validation_pos_rms_mm"] < 0.02


def test_a_badly_weighted_estimator_is_detected():
    """Same data, but rotation rows weighted 100x too strongly: no longer the ML estimator,
    so its variance exceeds the CRLB; the efficiency measure must show it."""
    robot = jaxcal.preset("paper-6r")
    sim = simulate(robot, n_robots=200, n_poses=30, seed=11, sigma_pos=0.02, sigma_rot=2e-5)
    ident = identify(robot, sim.q[0], **DH)
    res = calibrate_batch(robot, sim.q, sim.measured, sigma_pos_mm=0.02, sigma_rot_rad=2e-7, ident=ident, **DH)
    err = res.x[:, list(ident.base)] - sim.x_true @ ident.combination_matrix.T
    cov = crlb_batch(robot, sim.q, ident, res.layout, sigma_pos=0.02, sigma_rot=2e-5)
    eff = np.diag(cov) / np.mean(err**2, 0)
    assert eff.mean() < 0.8


def test_cli_montecarlo_writes_json(tmp_path):
    from typer.testing import CliRunner

    from jaxcal.cli import app

    out = tmp_path / "mc.json"
    r = CliRunner().invoke(
        app, ["montecarlo", "paper-6r", "--robots", "8", "--poses", "20", "--repeats", "1", "--json", str(out)]
    )
    assert r.exit_code == 0, r.output
    d = json.loads(out.read_text())
    for key in (
        "robots_per_second",
        "compile_seconds",
        "param_rms_error",
        "crlb_efficiency",
        "crlb_efficiency_mean",
        "validation_pos_rms_mm",
        "machine",
    ):
        assert key in d
    assert d["n_robots"] == 8 and d["robots_per_second"] > 0
    # --json onto the study folder's own summary is refused before any work
    study = tmp_path / "study"
    r = CliRunner().invoke(app, ["montecarlo", "paper-6r", "--out", str(study), "--json", str(study / "summary.json")])
    assert isinstance(r.exception, jaxcal.DataError) and r.exception.option == "json_out"
    assert not (study / "study.json").exists()


def test_cli_montecarlo_with_gross_outliers(tmp_path):
    """--outliers 0.1 --outlier-mm 3,6: two of each robot's 20 poses moved by 3-6 mm; found and
    left out, the models are as good as on clean data; kept in (--keep-outliers), far worse."""
    from typer.testing import CliRunner

    from jaxcal.cli import app

    def study(*extra):
        out = tmp_path / f"mc{len(extra)}.json"
        args = ["montecarlo", "paper-6r", "--robots", "8", "--poses", "20", "--repeats", "0", "--json", str(out)]
        r = CliRunner().invoke(app, args + list(extra))
        assert r.exit_code == 0, r.output
        return json.loads(out.read_text()), r.output

    clean, _ = study()
    found, text = study("--outliers", "0.1", "--outlier-mm", "3,6")
    kept, _ = study("--outliers", "0.1", "--outlier-mm", "3,6", "--keep-outliers")
    assert clean["false_alarms"] == 0 and "outliers" not in clean
    assert (found["outliers_found"], found["outliers_missed"], found["false_alarms"]) == (16, 0, 0)
    assert found["outliers"] == {"fraction": 0.1, "outlier_mm": [3.0, 6.0]} and "16 / 0; 0" in text
    assert found["validation_pos_rms_mm"] < 1.5 * clean["validation_pos_rms_mm"]
    # the bound is of the 18 poses each fit kept (the same robots and poses as the clean study):
    # about sqrt(20 / 18) above the clean one, not equal to it
    ratio = found["crlb_validation_pos_rms_mm"] / clean["crlb_validation_pos_rms_mm"]
    assert 1.02 < ratio < 1.15, ratio
    assert kept["validation_pos_rms_mm"] > 5 * clean["validation_pos_rms_mm"] and kept["keep_outliers"]
    r = CliRunner().invoke(app, ["montecarlo", "paper-6r", "--robots", "2", "--outlier-mm", "6"])
    assert isinstance(r.exception, jaxcal.DataError) and r.exception.option == "outlier_mm"


def test_montecarlo_elimination_uses_its_pair_design():
    """--method elimination draws the pair design (n_poses sets the pairs per step) and
    recovers noise-free truths with zero error on the held parameter."""

    out = run_montecarlo(
        jaxcal.preset("paper-6r"),
        n_robots=4,
        n_poses=22,
        n_val=10,
        sigma_pos=0.0,
        sigma_rot=0.0,
        method="elimination",
        seed=3,
        repeats=1,
    )
    assert out["n_poses"] == 2 * 5 * 2 + 2  # 2 pairs per step x 5 steps + 2 absolute poses
    assert "pair design" in out["conditions"]["calibration_poses"]  # not "random"
    assert out["conditions"]["calibration_poses"].endswith("= 22 poses")  # as asked: no "(of the ... asked)"
    assert out["converged_fraction"] == 1.0 and out["elimination_pairs_per_step"] == 2
    assert out["validation_pos_rms_mm"] < 1e-4  # only the d3 truth error's second-order trace


def test_cli_montecarlo_says_how_many_robots_did_not_converge(tmp_path):
    """One pose pair per elimination step (10 poses asked): robots that do not converge are
    counted in a warning, which says the figures include them and what gives more pairs."""
    from typer.testing import CliRunner

    from jaxcal.cli import app

    out = tmp_path / "mc.json"
    args = ["montecarlo", "paper-6r", "--robots", "8", "--poses", "10", "--method", "elimination"]
    r = CliRunner().invoke(app, args + ["--repeats", "0", "--json", str(out)])
    assert r.exit_code == 0, r.output
    d = json.loads(out.read_text())
    stopped = round(8 * (1 - d["converged_fraction"]))
    assert d["elimination_pairs_per_step"] == 1 and stopped > 0
    text = " ".join(r.output.split())
    assert f"warning: {stopped} of 8 robots did not converge (most steps taken: {d['max_steps_taken']})" in text
    assert "more --poses give more pairs" in text


def test_batched_crlb_equals_per_robot_crlb():
    """The Monte Carlo CRLB (all robots' Jacobians stacked) against identifiability.crlb robot by
    robot: both use base_covariance, so this checks the stacking, the row weights and the mean."""
    from jaxcal.error_model import identification_jacobian
    from jaxcal.identifiability import crlb, row_sigmas
    from jaxcal.model import Layout

    robot = jaxcal.preset("puma560")
    for position_only in (False, True):
        q = simulate(robot, n_robots=4, n_poses=30, seed=3).q
        ident = identify(robot, q[0], n_points=int(position_only), **DH)
        sig = row_sigmas(
            30, position_only=position_only, sigma_pos_mm=0.02, sigma_rot_rad=None if position_only else 2e-5
        )
        ref = np.mean(
            [crlb(np.asarray(identification_jacobian(robot, qr, position_only=position_only)), sig, ident) for qr in q],
            axis=0,
        )
        got = crlb_batch(robot, q, ident, Layout.of(robot, n_points=int(position_only)), sigma_pos=0.02, sigma_rot=2e-5)
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
        each = crlb_variances(
            robot, q, ident, Layout.of(robot, n_points=int(position_only)), sigma_pos=0.02, sigma_rot=2e-5
        )  # the study's per-robot variances, from the information matrix
        np.testing.assert_allclose(each.mean(0), np.diag(ref), rtol=1e-9)


VIEW = ([2500.0, 0.0, 300.0], [-1.0, 0.0, 0.0], np.radians(12.0), 1500.0, 3500.0)
"""A camera in front of the paper's arm (as in tests/design): about a third of configurations in view."""


def test_montecarlo_in_a_view_cone_on_given_inspection_poses(tmp_path):
    """Random poses drawn in the view cone (NumPy forward kinematics), the inspection RMS at the
    given poses (recomputed from the saved estimates by the NumPy forward kinematics), and the
    CRLB prediction equal to the design's criterion on the same poses (another implementation)."""
    from helpers import dh_fk

    from jaxcal import design
    from jaxcal.experiments import study_sampler

    robot = jaxcal.preset("paper-6r")
    qv = design.random_poses(robot, 15, view=VIEW, seed=9)
    out = run_montecarlo(robot, n_robots=8, n_poses=20, seed=2, repeats=0, view=VIEW, q_val=qv, out=tmp_path / "s")
    c = out["conditions"]
    assert c["calibration_poses"] == "random, constrained" and c["validation_poses"] == "given"
    assert c["view"]["half_angle_deg"] == pytest.approx(12.0) and c["view"]["far_mm"] == 3500.0
    assert out["n_val"] == 15 and out["n_poses"] == 20 and out["converged_fraction"] == 1.0

    def fk_np(dh, q):
        return dh_fk(dh, q, convention=robot.convention, base=robot.base, tool=robot.tool)[:, :3, 3]

    q = study_sampler(robot, 20, seed=2, view=VIEW).sets(np.arange(8))
    v = fk_np(robot.dh, q.reshape(-1, 6)) - VIEW[0]
    along = v @ VIEW[1]
    angle = np.arctan2(np.linalg.norm(v - along[:, None] * np.asarray(VIEW[1]), axis=1), along)
    assert np.all(angle <= VIEW[2]) and np.all((along >= VIEW[3]) & (along <= VIEW[4]))

    problem = design.design_problem(robot, q_val=qv, **DH)
    crlb = np.array([design.evaluate(problem, qr)["validation_rms_mm"] for qr in q])
    np.testing.assert_allclose(out["crlb_validation_pos_rms_mm"], np.sqrt(np.mean(crlb**2)), rtol=1e-8)

    with np.load(tmp_path / "s" / "chunk-000000.npz") as rec:
        x, x_true, val = rec["x"], rec["x_true"], rec["val_rms"]
    for xr, tr, vr in zip(x, x_true, val):
        d = fk_np(robot.dh + xr.reshape(6, 4), qv) - fk_np(robot.dh + tr.reshape(6, 4), qv)
        np.testing.assert_allclose(vr, np.sqrt(np.mean(np.sum(d**2, -1))), rtol=1e-9)
    assert np.sqrt(np.mean(val**2)) == pytest.approx(out["validation_pos_rms_mm"], rel=1e-12)


def test_outliers_injected_in_a_view_cone_on_given_inspection_poses():
    """Gross outliers and the design's conditions together: two of each robot's 20 cone poses
    moved by 3-6 mm are found and left out (no clean pose flagged), the conditions are reported,
    and the models are as good at the given inspection poses as on the same clean data."""
    from jaxcal import design

    robot = jaxcal.preset("paper-6r")
    qv = design.random_poses(robot, 15, view=VIEW, seed=9)
    kw = dict(n_robots=8, n_poses=20, seed=2, repeats=0, view=VIEW, q_val=qv)
    clean = run_montecarlo(robot, **kw)
    out = run_montecarlo(robot, **kw, outliers=0.1, outlier_mm=(3.0, 6.0))
    assert (out["outliers_found"], out["outliers_missed"], out["false_alarms"]) == (16, 0, 0)
    assert out["outliers"] == {"fraction": 0.1, "outlier_mm": [3.0, 6.0]}
    assert out["conditions"] == clean["conditions"] and out["conditions"]["calibration_poses"] == "random, constrained"
    assert out["n_val"] == 15 and out["converged_fraction"] == 1.0
    # 18 clean poses of the same 20 instead of 20: a little less information, nothing of the gross errors
    assert out["validation_pos_rms_mm"] < 1.5 * clean["validation_pos_rms_mm"]


def test_position_only_study_estimates_every_parameter_a_tool_point_reveals():
    """Position-only data with the base and the tool estimated: the identifiable set is judged with
    the measured point off the tool origin (every simulated tool has one), so noise-free robots are
    fitted exactly. At the origin, rotations about the last axis would be held and every robot off
    by about 0.01 mm."""
    robot = jaxcal.preset("paper-6r")
    kw = dict(n_robots=3, n_poses=30, n_val=20, sigma_pos=0.0, sigma_rot=0.0, seed=4, repeats=0)
    out = run_montecarlo(robot, position_only=True, estimate_base=True, estimate_tool=True, **kw)
    assert out["rank"] == 26 and out["converged_fraction"] == 1.0
    assert out["validation_pos_rms_mm"] < 1e-4
    # each truth in the base set by its own noise-free fit, not a linear map that the frames'
    # absorption of DH errors makes miss by about 1e-3
    assert max(out["param_rms_error"].values()) < 2e-4, out["param_rms_error"]
    assert out["robots_per_second"] is None and out["compile_seconds"] is None  # no warm run: not measured


def test_a_robot_whose_fit_left_out_nearly_every_pose_keeps_a_finite_bound(monkeypatch):
    """The bound is of the poses each fit kept; where a fit left out so many that the rest bound
    nothing (here robot 0 keeps 3 of 20 poses), that robot keeps the bound of all its poses and
    the study still reports one, not a singular-matrix error."""
    import dataclasses

    import jaxcal.experiments._montecarlo as mc

    real = mc.calibrate_batch

    def flags_most(*a, **kw):
        res = real(*a, **kw)
        if res.outlier_mask is None:
            return res
        mask = np.array(res.outlier_mask)
        mask[0, 3:] = True
        return dataclasses.replace(res, outlier_mask=mask)

    monkeypatch.setattr(mc, "calibrate_batch", flags_most)
    out = run_montecarlo(jaxcal.preset("paper-6r"), n_robots=4, n_poses=20, n_val=5, repeats=0, seed=2)
    assert np.isfinite(out["crlb_validation_pos_rms_mm"]) and np.isfinite(out["crlb_efficiency_mean"])


def test_a_parameter_whose_bound_a_few_robots_dominate_is_named():
    """Forty robots, two parameters: one's bounds equal over the robots, the other's one robot's
    bound a thousand times the rest (its poses barely separate it, as a marker on a joint's axis
    does): the summary names the second, whose efficiency is one squared error. Its relative
    standard error follows from the bounds: sqrt(2 sum c^2) / sum c."""
    import jaxcal.experiments._montecarlo as mc

    n = 40
    c = np.ones((n, 2))
    c[0, 1] = 1000.0
    sums = mc._Sums(2)
    sums.add({"err": np.sqrt(c), "val_rms": np.zeros(n), "converged": np.ones(n), "steps": np.ones(n), "crlb_var": c})
    out = sums.summary(["even", "dominated"], noisy=True)
    rel = np.sqrt(2 * np.sum(c**2, 0)) / np.sum(c, 0)
    assert out["crlb_efficiency_rel_se_each"] == pytest.approx(dict(zip(["even", "dominated"], rel)))
    assert rel[0] < mc.DOMINATED_SE < rel[1]
    note = out["crlb_efficiency_note"]
    assert "efficiency of dominated rests on a few robots" in note and "even" not in note


def test_an_efficiency_from_too_few_robots_is_not_given_and_few_are_warned_about():
    """The bound over a mean of n squared errors is biased up by about n / (n - 2): no figure
    from one or two robots, and a note below thirty; the worst parameter is named. Four robots of
    nearly equal bounds: the stated spread is about sqrt(2 / 4)."""
    one = run_montecarlo(jaxcal.preset("paper-6r"), n_robots=1, n_poses=20, n_val=5, repeats=0, seed=2)
    assert "crlb_efficiency_mean" not in one and "needs at least 3" in one["crlb_efficiency_note"]
    few = run_montecarlo(jaxcal.preset("paper-6r"), n_robots=4, n_poses=20, n_val=5, repeats=0, seed=2)
    assert "biased up" in few["crlb_efficiency_note"]
    assert few["crlb_efficiency_rel_se"] == pytest.approx(np.sqrt(0.5), rel=0.05)
    worst = few["crlb_efficiency_worst"]
    assert worst["efficiency"] == pytest.approx(min(few["crlb_efficiency"].values()))
    assert few["crlb_efficiency"][worst["parameter"]] == worst["efficiency"]


def test_the_efficiencys_stated_spread_holds_when_the_robots_bounds_differ():
    """Errors drawn at each robot's bound (efficiency 1): the efficiency's relative spread over
    repeated studies (that of its inverse, the squared errors over the bounds, to first order) is
    the stated one, ``sqrt(2 / n)`` for equal bounds and several times that where a few robots'
    bounds dominate the sum (5 of 60 a thousand times the others')."""
    from jaxcal.experiments._montecarlo import _Sums

    rng = np.random.default_rng(12)
    n = 60
    equal = np.ones((n, 1))
    spread = np.where(np.arange(n) < 5, 1000.0, 1.0)[:, None]
    for c in (equal, spread):
        effs, stated = [], None
        for _ in range(3000):
            sums = _Sums.empty(1)
            sums.add({"err": rng.normal(size=(n, 1)) * np.sqrt(c), "converged": np.ones(n, bool),
                      "steps": np.ones(n, int), "val_rms": np.zeros(n), "crlb_var": c})  # fmt: skip
            out = sums.summary(["p"], noisy=True)
            effs.append(out["crlb_efficiency"]["p"])
            stated = out["crlb_efficiency_rel_se"]
        assert stated == pytest.approx(out["crlb_efficiency_rel_se_each"]["p"])
        assert np.std(1 / np.array(effs)) == pytest.approx(stated, rel=0.1)
        if c is equal:
            assert stated == pytest.approx(np.sqrt(2 / n))
    assert stated > 3 * np.sqrt(2 / n)


def test_a_joint_frame_robot_is_scored_against_the_truths_own_coordinates():
    """Full poses, no frames estimated, a URDF-style joint-frame robot: its base set's
    combinations (``offset1 + rz1 - ry2``) are not linear in the truth, and a linear map of it
    misses by more than the noise moves a turn; scored against each truth's own fit, every
    parameter is near its bound (40 robots: each efficiency uncertain by about 22 %)."""
    out = run_montecarlo(jaxcal.to_joint(jaxcal.preset("ur5")), n_robots=40, n_poses=30, n_val=5, repeats=0, seed=3)
    assert 0.8 < out["crlb_efficiency_mean"] < 1.25 and out["crlb_efficiency_worst"]["efficiency"] > 0.4, out


def test_points_alone_are_scored_against_the_truths_own_coordinates():
    """Positions only, no frames estimated, no noise: every robot's fit is its truth, so its error
    against the truth is zero; a linear map of the truth onto the set's combinations (``theta5 -
    c a5``) missed by micrometres, a bias of half the bound's spread under 0.02 mm noise."""
    out = run_montecarlo(
        jaxcal.preset("ur5"), n_robots=16, n_poses=40, n_val=5, repeats=0, seed=2, position_only=True,
        sigma_pos=0.0, sigma_rot=0.0,
    )  # fmt: skip
    assert out["converged_fraction"] == 1.0 and out["param_rms_error_max"] < 1e-6, out["param_rms_error"]


def test_given_poses_that_leave_a_joint_still_are_warned_about():
    """Calibration poses in which joint 3 only jitters (4e-4 rad): every fit holds what only that
    joint separates, whose bias the CRLB leaves out; the summary names the joint. Poses in which
    every joint moves name none."""
    robot = jaxcal.preset("paper-6r")
    lim = np.asarray(robot.q_limits)
    rng = np.random.default_rng(4)
    q = lim[:, 0] + rng.uniform(size=(20, 6)) * (lim[:, 1] - lim[:, 0])
    assert run_montecarlo(robot, n_robots=4, q=q, seed=2, repeats=0)["still_joints"] == []
    q[:, 2] = 0.3 + rng.uniform(-4e-4, 4e-4, 20)
    notes = run_montecarlo(robot, n_robots=4, q=q, seed=2, repeats=0)["still_joints"]
    assert len(notes) == 1 and notes[0].startswith("joint 3 (q3) never moves in the data beyond")
