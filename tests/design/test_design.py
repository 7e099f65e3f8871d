"""Pose design: the criteria against finite differences and against the Cramér–Rao bound
computed apart (identifiability.crlb on error_model's Jacobian), designs within the limits and
constraints, and the pool exchange against a brute-force check of every single swap.

One small problem (paper 6R arm, full pose, frames known, 8 poses, 2 starts) serves every test,
so that they share their compiled programs with the command-line test."""

import dataclasses
import inspect

import jax
import numpy as np
import pytest

import jaxcal
from jaxcal import design
from jaxcal.error_model import identification_jacobian
from jaxcal.errors import DataError
from jaxcal.identifiability import analyze, crlb, row_sigmas

N, STARTS = 8, 2
FRAMES_KNOWN = dict(estimate_base=False, estimate_tool=False)


@pytest.fixture(scope="module")
def robot():
    return jaxcal.preset("paper-6r")


@pytest.fixture(scope="module")
def problem(robot):
    return design.design_problem(robot, n_val=60, seed=1, **FRAMES_KNOWN)


def _random_q(robot, k, seed):
    lim = np.asarray(robot.q_limits)
    return lim[:, 0] + np.random.default_rng(seed).uniform(size=(k, len(lim))) * (lim[:, 1] - lim[:, 0])


@pytest.mark.parametrize("criterion", design.CRITERIA)
def test_loss_gradient_matches_central_differences(robot, problem, criterion):
    pb = design.with_criterion(problem, criterion)
    q = _random_q(robot, N, 3)
    value, grad = (np.asarray(a) for a in design.objective_and_grad(pb, q))
    rng = np.random.default_rng(4)
    for _ in range(3):
        v = rng.normal(size=q.shape)
        h = 1e-5
        plus = float(design.objective_and_grad(pb, q + h * v)[0])
        minus = float(design.objective_and_grad(pb, q - h * v)[0])
        fd = (plus - minus) / (2 * h)
        assert np.isfinite(value)
        np.testing.assert_allclose(np.sum(grad * v), fd, rtol=1e-6, atol=1e-9)


def test_criteria_are_the_crlb_computed_apart(robot, problem):
    """log det, trace and the validation RMS from identifiability.crlb on error_model's Jacobian
    (another implementation than the design's model.jacobian), on the base set that
    identifiability.analyze finds at the problem's validation poses."""
    sp, sr = 0.02, 2e-5  # the design's default noise
    q = _random_q(robot, N, 5)
    got = design.evaluate(problem, q)
    lim = np.asarray(robot.q_limits)  # the problem's validation poses (seed 1)
    qv = lim[:, 0] + np.random.default_rng([1, 1]).uniform(size=(60, 6)) * (lim[:, 1] - lim[:, 0])
    J = np.asarray(identification_jacobian(robot, np.concatenate([q, qv])))  # one compiled shape
    ident = analyze(J[N:], robot.param_names())  # frames known: the column order is calibrate's
    assert problem.base_names() == ident.base_names == tuple(n for n in robot.param_names() if n != "d3")
    cov = crlb(J[:N], row_sigmas(N, sigma_pos_mm=sp, sigma_rot_rad=sr), ident)
    scale = np.asarray(problem.scale)
    np.testing.assert_allclose(got["log_det"], -np.linalg.slogdet(cov)[1] + 2 * np.log(scale).sum(), rtol=1e-9)
    np.testing.assert_allclose(got["a_trace"], np.trace(cov / np.outer(scale, scale)), rtol=1e-9)
    # expected squared position error at the validation poses
    G = J[N:, :3][..., list(ident.base)]
    expected = np.sqrt(np.mean(np.einsum("vrb,bc,vrc->v", G, cov, G)))
    np.testing.assert_allclose(got["validation_rms_mm"], expected, rtol=1e-9)


def test_few_or_narrow_validation_poses_keep_the_parameters_a_calibration_estimates(robot, problem):
    """Validation poses say where the arm will work, not what a calibration of the designed poses
    estimates: with three of them, or with joints 1, 4 and 5 held still, the base set is the one
    the whole range gives, and the validation RMS is the CRLB of that set (computed apart)
    propagated to those poses. Taken from them, the set lost parameters and the design claimed
    errors a calibration does not reach."""
    sp, sr = 0.02, 2e-5
    q = _random_q(robot, N, 5)
    held = _random_q(robot, 40, 7)
    held[:, [0, 3, 4]] = [0.3, -0.4, 1.1]
    for qv in (_random_q(robot, 3, 6), held):
        pb = design.design_problem(robot, q_val=qv, seed=1, **FRAMES_KNOWN)
        assert pb.base_names() == problem.base_names()
        J = np.asarray(identification_jacobian(robot, np.concatenate([q, qv])))
        ident = analyze(J[:N], robot.param_names())  # the designed poses identify the whole set
        assert ident.base_names == pb.base_names()
        cov = crlb(J[:N], row_sigmas(N, sigma_pos_mm=sp, sigma_rot_rad=sr), ident)
        G = J[N:, :3][..., list(ident.base)]
        expected = np.sqrt(np.mean(np.einsum("vrb,bc,vrc->v", G, cov, G)))
        np.testing.assert_allclose(design.evaluate(pb, q)["validation_rms_mm"], expected, rtol=1e-9)


def test_design_respects_limits_spread_and_region(robot):
    """Narrow joint limits, a minimum spread and a box for the tool: all hold, and the design
    beats random poses of the same count on its criterion. The poses stay 2 % of each range
    inside the limits (a real arm faults at them), and the optimum presses on that margin."""
    lim = np.array([[-0.4, 0.9], [-0.8, 0.3], [-0.5, 0.5], [-1.0, 1.0], [-0.7, 0.2], [-2.0, 2.0]])
    narrow = robot.replace(q_limits=lim)
    pb = design.design_problem(narrow, n_val=60, seed=1, **FRAMES_KNOWN)
    box = ([300.0, -600.0, -800.0], [1500.0, 600.0, 400.0])
    d = design.optimal_poses(pb, N, starts=STARTS, seed=2, min_spread=0.4, region=box, n_random=50)
    q = d.q
    assert q.shape == (N, 6) and d.feasible
    margin = 0.02 * (lim[:, 1] - lim[:, 0])
    assert np.all(q >= lim[:, 0] + margin - 1e-12) and np.all(q <= lim[:, 1] - margin + 1e-12)
    assert np.min(np.minimum(q - lim[:, 0] - margin, lim[:, 1] - margin - q)) < 1e-6
    dist = np.sqrt(((q[:, None] - q[None]) ** 2).sum(-1))[np.triu_indices(N, 1)]
    assert dist.min() >= 0.4
    p = np.asarray(jaxcal.fk(narrow, q))[:, :3, 3]
    assert np.all(p >= box[0]) and np.all(p <= box[1])
    assert d.random_fraction_better() == 0.0
    with pytest.raises(DataError, match="region: lower y"):
        design.optimal_poses(pb, N, region=([0, 1, 0], [1, 0, 1]))


def test_the_limit_margin_holds_given_limits_only():
    """2 % of each range at either end of limits the robot gives (the Panda's); none for joints
    given none (the UR5's +-pi is a sampling range); 0 turns it off; a share outside [0, 0.5)
    is refused naming the option."""
    panda, ur5 = jaxcal.preset("panda"), jaxcal.preset("ur5")
    lim = np.asarray(panda.q_limits)
    kw = dict(n_val=10, **FRAMES_KNOWN)
    np.testing.assert_allclose(np.asarray(design.design_problem(panda, **kw).margin), 0.02 * (lim[:, 1] - lim[:, 0]))
    assert not np.any(np.asarray(design.design_problem(ur5, **kw).margin))
    assert not np.any(np.asarray(design.design_problem(panda, limit_margin=0, **kw).margin))
    with pytest.raises(DataError, match="limit_margin must be a share") as e:
        design.design_problem(panda, limit_margin=0.5, **kw)
    assert e.value.option == "limit_margin"
    from jaxcal.cli._design import design as command  # its help gives the default it does not import

    assert f"default {design.LIMIT_MARGIN:g}" in inspect.signature(command).parameters["limit_margin"].default.help


VIEW = ([2500.0, 0.0, 300.0], [-1.0, 0.0, 0.0], np.radians(12.0), 1500.0, 3500.0)
"""A camera 2.5 m in front of the arm looking back at it: about a third of random poses in view."""


def _in_view(robot, q):
    """Angle from the camera's axis (rad) and distance along it (mm) of the tool point, by the
    NumPy forward kinematics of the tests (apart from jaxcal's)."""
    from helpers import dh_fk

    T = dh_fk(robot.dh, q, convention=robot.convention, joint_types=robot.joint_types, base=robot.base, tool=robot.tool)
    v = T[:, :3, 3] - VIEW[0]
    along = v @ VIEW[1]
    radial = np.linalg.norm(v - along[:, None] * np.asarray(VIEW[1]), axis=1)
    return np.arctan2(radial, along), along


def test_design_and_pool_keep_the_tool_in_a_camera_view(robot, problem):
    """The gradient design and the pool selection keep every tool point inside the view cone and
    its range; random starts of the comparison are drawn inside it too."""
    d = design.optimal_poses(problem, N, starts=STARTS, seed=2, view=VIEW, n_random=20)
    assert d.feasible
    angle, along = _in_view(robot, d.q)
    assert np.all(angle <= VIEW[2]) and np.all((along >= VIEW[3]) & (along <= VIEW[4])), (angle, along)
    pool = _random_q(robot, 120, 8)
    angle_pool, _ = _in_view(robot, pool)
    assert 0.1 < np.mean(angle_pool <= VIEW[2]) < 0.6  # the cone really excludes poses
    s = design.select_poses(problem, pool, N, view=VIEW, n_random=20)
    angle, along = _in_view(robot, s.q)
    assert np.all(angle <= VIEW[2]) and np.all((along >= VIEW[3]) & (along <= VIEW[4]))


@pytest.mark.parametrize(
    "view, msg",
    [
        (([0, 0, 0], [1, 0, 0], np.radians(95)), "half-angle must be between 0 and 90 deg"),
        (([0, 0, 0], [0, 0, 0], 0.3), "axis must not be zero"),
        (([0, 0, 0], [1, 0, 0], 0.3, 500.0, 100.0), "need 0 <= near < far"),
        (([0, 0, 0], [1, 0, 0]), "view must be"),
        (([5000, 0, 0], [1, 0, 0], 0.1), r"view: only 0 of \d+ random configurations .* in the view cone"),
    ],
)
def test_bad_view_is_named(problem, view, msg):
    with pytest.raises(DataError, match=msg):
        design.optimal_poses(problem, N, view=view)


def test_pool_selection_no_single_swap_improves(robot, problem):
    """The exchange's Woodbury scores against every swap evaluated directly."""
    pool = _random_q(robot, 30, 7)
    d = design.select_poses(problem, pool, N, n_random=50)
    idx = d.details["indices"]
    assert len(set(idx)) == N and np.array_equal(d.q, pool[idx])
    rest = [j for j in range(len(pool)) if j not in idx]
    swaps = np.array([np.where(np.arange(N) == i, j, idx) for i in range(N) for j in rest])
    loss = lambda ids: float(design.objective_and_grad(problem, pool[ids])[0])  # noqa: E731
    best = loss(idx)
    assert min(loss(s) for s in swaps[::7]) >= best - 1e-12
    ref = [loss(np.array(s)) for s in swaps]
    assert min(ref) >= best - 1e-12
    with pytest.raises(DataError, match=r"pool: row 2, joint 3: .* outside the joint limits"):
        bad = pool.copy()
        bad[2, 2] = 4.0
        design.select_poses(problem, bad, N)
    # a pool of 6 postures listed 5 times each: the design must repeat some, and says so
    with pytest.warns(UserWarning, match=r"the pool has 6 distinct rows of 30: the design repeats 2 of its 8"):
        design.select_poses(problem, np.tile(pool[:6], (5, 1)), N, n_random=50)


def test_pool_selection_of_the_fewest_poses_that_identify_finds_the_best_set():
    """UR5, base and tool estimated (28 base parameters, 6 rows a pose): 5 of 6 random poses
    identify, 4 do not, so removing a chosen pose leaves a singular information the Woodbury
    swap cannot use. The selection is the best of the six sets, found by evaluating each; with
    one point measured, no single exchange improves the fewest poses selected."""
    robot = jaxcal.preset("ur5")
    problem = design.design_problem(robot)
    lim = np.asarray(robot.q_limits)
    for seed in (1, 4):  # pools where the greedy start alone is 2.7x and 7.7x off the best
        pool = np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], (6, 6))
        d = design.select_poses(problem, pool, 5, n_random=5)
        sets = [[j for j in range(6) if j != i] for i in range(6)]
        best = min(design.evaluate(problem, pool[s])["validation_rms_mm"] for s in sets)
        assert d.values["validation_rms_mm"] == pytest.approx(best, rel=1e-9)
    # one point (3 rows a pose): a set less one pose is one rank short, and its factor can be finite
    # on a rounding-level pivot; no single exchange of the selection improves it, each evaluated
    # directly (pools whose selection one exchange improved by 1.3-1.6x, with and without XLA's
    # optimisations)
    for name, criterion, seed in (("paper-6r", "validation", 5), ("paper-6r", "validation", 8), ("ur5", "a", 5)):
        arm = jaxcal.preset(name)
        problem = design.design_problem(arm, n_points=1, criterion=criterion)
        key = {"a": "a_trace", "validation": "validation_rms_mm"}[criterion]
        n, lim = -(-problem.n_base // 3), np.asarray(arm.q_limits)
        pool = np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], (n + 4, 6))
        d = design.select_poses(problem, pool, n, n_random=2)
        idx = list(d.details["indices"])
        rest = [j for j in range(len(pool)) if j not in idx]
        swapped = [idx[:i] + [j] + idx[i + 1 :] for i in range(n) for j in rest]
        best = min(design.evaluate(problem, pool[s])[key] for s in swapped)
        assert d.values[key] <= best * (1 + 1e-9), (name, criterion, seed)


def test_pose_file_round_trip_and_errors(robot, tmp_path):
    named = robot.replace(joint_names=[f"j{i}" for i in range(6)], units=("m", "deg"))
    q = _random_q(robot, 5, 8)
    keep = q.copy()
    design.write_poses(tmp_path / "p.csv", q, named)
    assert np.array_equal(q, keep)
    text = (tmp_path / "p.csv").read_text()
    assert text.startswith("j0,j1,j2,j3,j4,j5\n")
    np.testing.assert_allclose(float(text.splitlines()[1].split(",")[0]), np.rad2deg(q[0, 0]), rtol=1e-15)
    np.testing.assert_allclose(design.read_poses(tmp_path / "p.csv", named), q, rtol=1e-14)
    # limits of a robot in degrees made in a script (deg * pi / 180), and a design at both of
    # them: read back at the limits, not refused for the last bits the unit conversion moved (a
    # value beyond them by more still is)
    rng = np.random.default_rng(3)
    deg = np.round(np.stack([-rng.uniform(10, 179, (30, 6)), rng.uniform(10, 179, (30, 6))], -1), 4)
    for lim in deg * np.pi / 180:
        r = named.replace(q_limits=lim)
        design.write_poses(tmp_path / "lim.csv", lim.T, r)
        back = design.read_poses(tmp_path / "lim.csv", r)
        assert np.all(back >= lim[:, 0]) and np.all(back <= lim[:, 1])
        np.testing.assert_allclose(back, lim.T, rtol=1e-14)
    text = (tmp_path / "lim.csv").read_text().splitlines()
    over = text[1].split(",")
    over[2] = repr(float(over[2]) - 1e-9)  # a nanodegree beyond the lower limit
    (tmp_path / "over.csv").write_text("\n".join([text[0], ",".join(over)]) + "\n")
    with pytest.raises(DataError, match=r"row 1 .*column 'j2'.*outside the joint limits"):
        design.read_poses(tmp_path / "over.csv", r)
    (tmp_path / "bad.csv").write_text("q1,q2,q3,q4,q5,q6\n0,0,0,0,x,0\n")
    with pytest.raises(DataError, match=r"row 1 .*column 'q5'"):
        design.read_poses(tmp_path / "bad.csv", robot)
    (tmp_path / "short.csv").write_text("q1,q2,q3,q4,q5\n0,0,0,0,0\n")
    with pytest.raises(DataError, match="q1..q5"):
        design.read_poses(tmp_path / "short.csv", robot)


def test_random_poses_keep_the_conditions_and_depend_on_the_set_index(robot):
    """The sampler the design and the Monte Carlo share: every pose in the view cone (and, with a
    box, in the box) by the NumPy forward kinematics, the spread kept, and set i the same
    whichever sets are drawn with it."""
    from helpers import dh_fk

    q = design.random_poses(robot, N, n_sets=3, view=VIEW, min_spread=0.5, seed=4)
    assert q.shape == (3, N, 6)
    lim = np.asarray(robot.q_limits)
    assert np.all(q >= lim[:, 0]) and np.all(q <= lim[:, 1])
    angle, along = _in_view(robot, q.reshape(-1, 6))
    assert np.all(angle <= VIEW[2]) and np.all((along >= VIEW[3]) & (along <= VIEW[4]))
    assert min(design.min_distance(s) for s in q) >= 0.5
    assert len(np.unique(q.reshape(-1, 6), axis=0)) == 3 * N
    box = ([300.0, -600.0, -800.0], [1500.0, 600.0, 400.0])
    qb = design.random_poses(robot, N, region=box, seed=1)
    p = dh_fk(robot.dh, qb, convention=robot.convention, base=robot.base, tool=robot.tool)[:, :3, 3]
    assert np.all(p >= box[0]) and np.all(p <= box[1])
    sampler = design.PoseSampler(design.workspace(robot), design.constraints(0.0, None, VIEW), N, jax.random.PRNGKey(2))
    assert 0.1 < sampler.acceptance < 0.6  # the cone really excludes configurations
    np.testing.assert_array_equal(sampler.sets([0, 1, 2, 3])[3], sampler.sets([3])[0])
    with pytest.raises(DataError, match="min_spread: fewer than"):
        design.random_poses(robot, N, view=VIEW, min_spread=20.0)


def test_params_from_a_calibration_report(robot, tmp_path):
    """design_problem(params_from=report) designs for the parameters a real calibrate_data
    report estimated, as if they were given by name; names the robot lacks are refused."""
    import json

    from jaxcal.simulation import simulate

    sim = simulate(robot, n_robots=1, n_poses=30, seed=5, sigma_pos=0.02, sigma_rot=2e-5)
    rep = jaxcal.calibrate_data(robot, jaxcal.Measurements(sim.q[0], sim.measured[0]), params="offsets", folds=2)
    path = tmp_path / "report.json"
    path.write_text(rep.to_json())
    names = json.loads(path.read_text())["estimated_dh"]
    assert names and all(n.startswith("theta") for n in names)
    got = design.design_problem(robot, params_from=path, n_val=60, seed=1)
    ref = design.design_problem(
        robot, params=",".join(names), estimate_base=rep.report["estimate_base"],
        estimate_tool=rep.report["estimate_tool"], n_val=60, seed=1,
    )  # fmt: skip
    assert got.base_names() == ref.base_names()
    assert [n for n in got.base_names() if not n.startswith(("base_", "tool_"))] == names
    assert design.report_options({"parameters": {"theta2": {}, "base_x": {}}}, robot)["params"] == "theta2"
    got = design.report_options({"estimated_dh": ["theta2"], "ridge_mm": 1.0, "compliance": False}, robot)
    assert got == {"params": "theta2", "ridge_mm": 1.0, "compliance": "no"}
    with pytest.raises(DataError, match=r"params_from: 'ridge_mm' must be a prior"):
        design.report_options({"estimated_dh": ["theta2"], "ridge_mm": -1}, robot)
    assert design.report_options({"estimated_dh": []}, robot)["params"] == "frames"
    with pytest.raises(DataError, match=r"params_from: .*theta7 is not a parameter of robot"):
        design.design_problem(robot, params_from={"estimated_dh": ["theta2", "theta7"], "robot": "other"})
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(DataError, match=r"params_from: .*bad.json: not JSON"):
        design.design_problem(robot, params_from=tmp_path / "bad.json")


def test_params_from_the_committed_franka_report():
    """The report docs/make_results.sh writes with jaxcal calibrate (the Franka data, a sparse
    set under a prior): its estimated kinematic parameters, frames, compliance and prior."""
    import json
    from pathlib import Path

    rep = json.loads((Path(__file__).parents[2] / "docs/franka/report.json").read_text())
    got = design.report_options(rep, jaxcal.preset(rep["robot"]))
    assert got["params"].split(",") == rep["estimated_dh"]  # the robot's order, as the report's
    assert (got["estimate_base"], got["estimate_tool"]) == (rep["estimate_base"], rep["estimate_tool"])
    assert got["compliance"] == ("yes" if rep["compliance"] else "no")
    assert got.get("ridge_mm") == rep.get("ridge_mm")


def test_ridge_prior_is_physically_scaled(robot, problem):
    """With ridge_mm the design's prior is the calibration's, weight lever / ridge_mm, the lever
    the RMS position change per unit of each parameter over poses uniform within the limits (from
    error_model's Jacobian; exactly 1 for a length): in the scaled information, (lever * scale /
    ridge)^2, and information() adds it to the poses' information."""
    from jaxcal.design._problem import STRUCTURE_POSES

    ridge = 0.5
    pb = design.design_problem(robot, n_val=60, seed=1, ridge_mm=ridge, **FRAMES_KNOWN)
    assert pb.base_names() == problem.base_names()
    lim = np.asarray(robot.q_limits)  # the problems' poses over the whole range (seed 1)
    qv = lim[:, 0] + np.random.default_rng([1, 1]).uniform(size=(STRUCTURE_POSES, 6)) * (lim[:, 1] - lim[:, 0])
    J = np.asarray(identification_jacobian(robot, qv))[:, :3][..., list(pb.base)]  # position rows
    lever = np.sqrt(np.mean(np.sum(J**2, 1), 0))
    lengths = [i for i, n in enumerate(pb.base_names()) if n[0] in "ad" and not n.startswith("alpha")]
    np.testing.assert_allclose(lever[lengths], 1.0, rtol=1e-12)
    np.testing.assert_allclose(pb.scale, problem.scale, rtol=1e-12)
    expected = (lever * np.asarray(pb.scale) / ridge) ** 2
    np.testing.assert_allclose(pb.prior, expected, rtol=1e-9)
    q = _random_q(robot, N, 5)
    added = np.asarray(design.information(pb, q)) - np.asarray(design.information(problem, q))
    np.testing.assert_allclose(added, np.diag(expected), atol=1e-9 * np.abs(added).max())


@pytest.mark.parametrize("case", ["pose, base and tool", "two points, tool", "joint frames", "camera"])
def test_design_jacobian_is_the_model_jacobian(robot, case):
    """The design's Jacobian (autodiff of the measurement model) against the analytic
    jaxcal.model.jacobian, for poses, points, a joint-frame robot and a camera model, at a
    perturbed camera and frames (so no entry is trivially zero)."""
    from helpers import random_transform

    from jaxcal.design._problem import identification_jacobian
    from jaxcal.kinematics import to_joint
    from jaxcal.model import Layout, Model, jacobian

    rng = np.random.default_rng(6)
    r, points, camera, cam_params = robot, None, "none", None
    if case == "joint frames":
        r = to_joint(robot)
    if case == "two points, tool":
        points = rng.normal(size=(2, 3)) * 50.0
    if case == "camera":
        camera, cam_params = "linear", rng.normal(size=8) * 1e-3
    r = r.replace(base=random_transform(rng, 300.0), tool=random_transform(rng, 100.0))
    layout = Layout.of(r, base=True, tool=True, n_points=0 if points is None else len(points), camera=camera)
    model = Model(r, points, cam_params, camera=camera)
    q = _random_q(robot, 5, 9)
    # one program, not one per operation
    got, ref = map(
        np.asarray, jax.jit(lambda q: (identification_jacobian(model, layout, q), jacobian(model, layout, q)))(q)
    )
    assert got.shape == ref.shape
    np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())


@pytest.mark.parametrize("criterion", ["validation", "d"])
def test_design_bound_holds_for_every_design_of_the_candidates(robot, problem, criterion):
    """No N poses of the candidates beat the bound: not the exchange's choice, not random
    subsets, not all candidates with equal weights (evaluate on the whole pool, scaled to N); the
    relaxed optimum sits within its tolerance of the bound."""
    pb = design.with_criterion(problem, criterion)
    pool = _random_q(robot, 60, 12)
    b = design.design_bound(pb, pool, N, tol=1e-4)
    assert b["candidates"] == 60 and b["weights"].shape == (60,) and abs(b["weights"].sum() - 1) < 1e-12
    rng = np.random.default_rng(3)
    subsets = [design.evaluate(pb, pool[rng.choice(60, N, replace=False)]) for _ in range(30)]
    chosen = design.select_poses(pb, pool, N, n_random=10).values
    key = {"validation": "validation_rms_mm", "d": "log_det"}[criterion]
    uniform = design.evaluate(pb, pool)[key]  # equal weights: the information scaled by N / 60
    uniform = uniform * np.sqrt(60 / N) if criterion == "validation" else uniform + pb.n_base * np.log(N / 60)
    if criterion == "validation":
        assert all(b["bound"] <= v[key] for v in [*subsets, chosen])
        assert b["bound"] <= b["relaxed"][key] <= min(uniform, chosen[key])
        assert b["relaxed"][key] <= b["bound"] * np.exp(1e-4)
    else:  # log det: larger is better, the bound an upper one
        assert all(b["bound"] >= v[key] for v in [*subsets, chosen])
        assert b["bound"] >= b["relaxed"][key] >= max(uniform, chosen[key])
        assert b["relaxed"][key] >= b["bound"] - 1e-4


def test_a_pool_in_a_box_random_poses_rarely_reach_is_compared_with_its_own_rows(robot, problem):
    """A 20 mm box: random configurations within the joint limits almost never put the tool there,
    so the random comparison draws sets of the pool's rows instead of refusing the box. The pool
    comes from an IK on an independent FK (NumPy DH products)."""
    from helpers import dh_fk
    from scipy.optimize import least_squares

    dh, lim = np.asarray(robot.dh), np.asarray(robot.q_limits)
    rng = np.random.default_rng(0)
    centre = dh_fk(dh, rng.uniform(lim[:, 0], lim[:, 1])[None])[0, :3, 3]
    lo, hi = centre - 10.0, centre + 10.0
    pool = []
    while len(pool) < 30:
        target = rng.uniform(lo + 2.0, hi - 2.0)
        fit = least_squares(
            lambda q, t=target: dh_fk(dh, q[None])[0, :3, 3] - t, rng.uniform(lim[:, 0], lim[:, 1]), bounds=lim.T
        )
        if fit.cost < 1e-10:
            pool.append(fit.x)
    d = design.select_poses(problem, np.array(pool), N, region=(lo, hi), n_random=20)
    assert d.details["random_from"] == "pool" and d.feasible and "of the pool's poses" in d.report()
    tool = dh_fk(dh, d.q)[:, :3, 3]
    assert np.all((tool >= lo) & (tool <= hi))
    assert len(d.random_values["validation_rms_mm"]) == 20
    assert d.random_by_count["counts"][-1] <= 30 and np.isfinite(d.equivalent_random_poses())


def test_random_poses_to_match_a_small_design_are_counted_not_extrapolated(robot, problem):
    """A design of 5 poses for 23 base parameters: random sets of 5 are nearly singular, so
    letting the information grow in proportion to the pose count from them gives some 28 random
    poses. The count is checked against the median of random sets of each count drawn here
    (uniform within the limits, evaluated one by one), interpolated where it crosses the
    design's value."""
    d = design.optimal_poses(problem, 5, starts=STARTS, seed=0, n_random=40)
    target = d.values["validation_rms_mm"]
    ks = np.arange(6, 13)
    med = np.array([np.median([design.evaluate(problem, _random_q(robot, k, 100 * k + s))["validation_rms_mm"]
                               for s in range(40)]) for k in ks])  # fmt: skip
    assert med[0] > target > med[-1]
    i = int(np.flatnonzero(med <= target)[0])
    t = np.log(med[i - 1] / target) / np.log(med[i - 1] / med[i])
    expected = ks[i - 1] * (ks[i] / ks[i - 1]) ** t
    assert d.equivalent_random_poses() == pytest.approx(expected, rel=0.15)
    assert d.to_dict()["equivalent_random_poses"]["validation"] == d.equivalent_random_poses()


def test_matching_count_interpolates_and_extrapolates_in_log_count():
    """RMS proportional to K^-1/2: the count where it reaches a target is exact inside the
    counts and beyond them; counts with no finite figure (singular sets) are left out."""
    ks = np.array([2, 4, 8, 16, 32])
    y = 0.5 * np.log(ks.astype(float))
    y[0] = -np.inf
    for k in (5.0, 11.0, 100.0, 3.0):
        assert design.matching_count(ks, y, 0.5 * np.log(k)) == pytest.approx(k, rel=1e-12)
    assert np.isnan(design.matching_count(ks[:2], y[:2], 1.0))
    # a dip or a flat tail (sampling noise) is never extrapolated back to a small count
    five = [5, 7, 10, 14, 20]
    assert design.matching_count(five, [1, 2, 3, 4, 3.9], 4.5) == np.inf
    assert design.matching_count(five, [1, 2, 3, 4, 4], 4.5) == np.inf
    assert design.matching_count(five, [2, 2, 3, 4, 5], 1.0) == pytest.approx(5.0)  # at the smallest count


def test_the_report_shows_a_bound_beyond_the_largest_count_and_a_dash_where_none_can_be_told():
    """The 'random poses to match' cell: a count within those drawn is interpolated (random
    medians of RMS 1/sqrt(K), so the design's 1/5 is matched by 25 poses), one beyond the largest
    drawn is only its bound, and a criterion whose random figures are singular at all but one
    count has none."""
    counts = [10, 20, 30]
    validation = [1 / np.sqrt(k) for k in counts]
    d = design.PoseDesign(
        q=np.zeros((12, 2)),
        criterion="validation",
        values={"log_det": 100.0, "a_trace": 0.5, "validation_rms_mm": 1 / np.sqrt(25.0)},
        random_values={"log_det": np.zeros(3), "a_trace": np.ones(3), "validation_rms_mm": np.ones(3)},
        method="pool",
        base_names=("a", "b"),
        feasible=True,
        min_distance=0.1,
        random_by_count={
            "counts": counts,
            "log_det": [1.0, 2.0, 3.0],  # 100 is far beyond: extrapolated past 30
            "a_trace": [np.inf, np.inf, 0.1],  # singular at 10 and 20: one count left
            "validation_rms_mm": validation,
        },
    )
    cells = {line[:44].strip(): line[-22:].strip() for line in d.report().splitlines()[2:5]}
    assert cells == {
        "log det information (D, larger is better)": "> 30",
        "trace of scaled covariance (A)": "-",
        "expected validation RMS, mm (CRLB)": "25.0",
    }
    assert d.equivalent_random_poses("validation") == pytest.approx(25.0, rel=1e-12)
    assert np.isnan(d.to_dict()["equivalent_random_poses"]["a"])
    # a design none of whose optimiser starts converged says so
    assert "converged" not in d.report()
    stopped = dataclasses.replace(d, details={"starts": 2, "converged_starts": 0, "max_evaluations": 500})
    assert "warning: none of the 2 optimiser starts converged (the most evaluations one used: 500)" in stopped.report()
    # where the feasible starts end together it is a flat optimum: a note giving their spread in
    # the criterion (the validation loss is the log of the squared RMS: 0.0005 apart is 0.025 %
    # in the RMS; D's, minus log det per parameter: 0.05 %); apart, or one alone, still a warning
    starts = {"starts": 3, "converged_starts": 0, "max_evaluations": 500}
    together = dict(starts, start_losses=[-8.2469, -8.2474, 3.0], start_feasible=[True, True, False])
    line = dataclasses.replace(d, details=together).report().splitlines()[-1]
    assert line.startswith("note: none of the 3 optimiser starts converged")
    assert "within 0.03% of one another in the expected validation RMS" in line
    line = dataclasses.replace(d, details=together, criterion="d").report().splitlines()[-1]
    assert "within 0.05% of one another in the D-efficiency" in line
    apart = dict(together, start_losses=[-8.2, -8.3, 3.0])
    line = dataclasses.replace(d, details=apart).report().splitlines()[-1]
    assert line.startswith("warning:") and "5.1% apart in the expected validation RMS" in line
    alone = dict(together, start_feasible=[True, False, False])
    assert dataclasses.replace(d, details=alone).report().splitlines()[-1].startswith("warning:")


def test_a_position_only_design_without_a_point_is_for_a_marker_off_the_last_axis(robot):
    """The tool origin of a DH flange lies on the last joint's axis, where a point hides that
    joint's parameters (22 base parameters instead of 26) and the bound is over 15 % optimistic
    for any real marker. Without a point the design takes one just off the axis: the set and the
    bound of a marker 5 mm off it (the bound moves a few % with the marker's direction)."""
    kw = dict(estimate_base=True, estimate_tool=True, q_val=_random_q(robot, 60, 1))
    default = design.design_problem(robot, n_points=1, **kw)
    on_axis = design.design_problem(robot, points=[[0.0, 0.0, 0.0]], **kw)
    off_axis = design.design_problem(robot, points=[[3.0, -4.0, 0.0]], **kw)
    assert default.n_base == off_axis.n_base == 26 and on_axis.n_base == 22
    assert np.linalg.norm(np.asarray(default.model.points)) == pytest.approx(design.DEFAULT_POINT_MM)
    q = _random_q(robot, 12, 8)
    rms = [design.evaluate(p, q)["validation_rms_mm"] for p in (default, off_axis)]
    assert rms[0] == pytest.approx(rms[1], rel=0.05)
    assert design.evaluate(on_axis, q)["validation_rms_mm"] < 0.85 * rms[1]


def test_more_poses_than_the_gradient_design_can_hold_are_refused_up_front(problem):
    """The BFGS inverse Hessian of K poses x n joints has (K n)^2 entries: 100000 poses would ask
    for terabytes, refused before anything is drawn or compiled, with the most it allows."""
    with pytest.raises(DataError, match=r"n_poses: the gradient design of 100000 poses .* at most \d+ poses"):
        design.optimal_poses(problem, 100000)


def test_a_pool_may_turn_a_joint_given_no_limits_beyond_the_design_range(robot, problem):
    """A pool value beyond a joint's limits is refused where the robot file gives them; a joint
    given none (its range only the one designs are drawn in) may turn beyond it, as a UR5's does."""
    pool = _random_q(robot, 10, 9)
    pool[3, 1] = 3.3  # beyond paper-6r's limits, +-2.97 rad
    with pytest.raises(DataError, match="row 3, joint 2: 3.3 is outside the joint limits"):
        design.select_poses(problem, pool, 11)
    free = dataclasses.replace(problem, bounded=(True, False, True, True, True, True))
    with pytest.raises(DataError, match="fewer than the 11 asked for"):  # past the limits' check
        design.select_poses(free, pool, 11)
