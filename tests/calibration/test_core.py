"""The member solve's Levenberg–Marquardt fallback: the members Gauss–Newton left unconverged are
fitted again by LM, and only those; the others keep their Gauss–Newton fit bit for bit. The rows'
leverage under a prior."""

import numpy as np

import jaxcal
from jaxcal.calibration import _core as core
from jaxcal.model import Layout
from jaxcal.solvers import PIN


def test_unconverged_members_and_only_those_are_fitted_again_by_lm():
    robot = jaxcal.preset("paper-6r")
    sim = jaxcal.simulate(robot, n_poses=30, seed=7, sigma_pos=0.01, sigma_rot=1e-5)
    q, target = np.asarray(sim.q[0]), np.asarray(sim.measured[0])
    layout = Layout.of(robot, base=False, tool=False, n_points=0)
    models = core.broadcast_model(core.nominal_model(robot, layout), 3)
    J0 = core.analyse(core.member(models, 0), layout, q)[0]
    base = set(core.base_set(J0, layout).base)
    prior = np.repeat(np.array([[0.0 if i in base else PIN for i in range(layout.size)]]), 3, 0)
    weights = np.repeat(core.weights_of(layout, np.array([[0.01, 1e-5]])), 3, 0)
    x_true = np.asarray(sim.x_true[0])[: layout.size]
    # member 0 starts at the truth, members 1 and 2 far from it: three steps leave those unconverged
    x0 = np.stack([np.where(prior[0] < PIN, x_true, 0.0), np.full(layout.size, 0.3), np.full(layout.size, -0.3)])
    x0 = np.where(prior < PIN, x0, 0.0)
    args = (models, q, target, np.ones((3, len(q))), weights, prior)
    gn = core.Config(layout, "gn", max_steps=3, shared_data=True)
    plain = core.run_members(gn, *args, J0=J0, x0=x0)
    assert plain["converged"].tolist() == [True, False, False] and not plain["retried"].any()

    out = core.run_members(gn, *args, J0=J0, x0=x0, fallback=True)
    assert out["retried"].tolist() == [False, True, True]
    np.testing.assert_array_equal(out["x"][0], plain["x"][0])
    lm = core.run_members(
        core.Config(layout, "lm", max_steps=3, shared_data=True), *core.take(list(args[:1]), [1, 2]), q, target,
        np.ones((2, len(q))), weights[1:], prior[1:], J0=J0, x0=x0[1:], chunk=4,
    )  # fmt: skip
    # (in the first call's chunk of 4 members: the same program whatever the count retried)
    np.testing.assert_array_equal(out["x"][1:], lm["x"])
    np.testing.assert_array_equal(out["converged"][1:], lm["converged"])
    assert not np.array_equal(out["x"][1:], plain["x"][1:])


def test_leverage_is_the_hat_diagonal_of_the_data_and_prior_rows():
    """Against the hat matrix ``A (A^T A)^-1 A^T`` of the stacked weighted data rows and prior
    rows, with a pinned parameter, a ridge, a pose left out (weight 0) and a lost row."""
    rng = np.random.default_rng(3)
    K, rows, m = 7, 6, 5
    J = rng.normal(size=(K, rows, m))
    weights = rng.uniform(0.5, 2.0, rows)
    pose_w = np.array([1, 1, 0, 1, 1, 1, 1], float)
    seen = np.ones((K, rows), bool)
    seen[4, 2] = False
    prior = np.array([0.0, 0.7, PIN, 0.0, 2.0])
    st = core.fit_statistics(J, weights, pose_w, np.ones(K), loss="l2", loss_scale=None, rows=rows, seen=seen)
    h = core.leverage(J, weights, st, prior, seen)

    keep = prior < PIN
    data = (np.sqrt(pose_w)[:, None, None] * weights[None, :, None] * seen[:, :, None] * J)[:, :, keep]
    A = np.vstack([data.reshape(K * rows, -1), np.diag(prior[keep])])
    H = A @ np.linalg.solve(A.T @ A, A.T)
    np.testing.assert_allclose(h.ravel(), np.diag(H)[: K * rows], atol=1e-12)
    assert h[2].max() == 0 and h[4, 2] == 0
    assert np.sum(h) < keep.sum() - 0.05  # the ridge takes a share: fewer effective parameters
