"""Robust losses and outlier reporting (issue 8): 10 % gross outliers (20-50 mm) injected into
simulated data; validation against the *true* robot on held-out poses. "Plain" fits keep every
pose (``keep_outliers``): the default leaves the outliers out (tests/calibration/test_outliers.py)."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxcal
from jaxcal.calibration import calibrate, calibrate_batch
from jaxcal.simulation import simulate

ROBOT = jaxcal.preset("paper-6r")
SIM = simulate(ROBOT, n_poses=60, n_val=100, seed=3, sigma_pos=0.02, sigma_rot=2e-5)
Q, CLEAN = SIM.q[0], SIM.measured[0]
KW = dict(sigma_pos_mm=0.02, sigma_rot_rad=2e-5, estimate_base=False, estimate_tool=False)


def _inject(measured, frac=0.1, seed=7):
    rng = np.random.default_rng(seed)
    K = len(measured)
    idx = np.sort(rng.choice(K, int(round(frac * K)), replace=False))
    d = rng.normal(size=(len(idx), 3))
    d *= rng.uniform(20.0, 50.0, (len(idx), 1)) / np.linalg.norm(d, axis=1, keepdims=True)
    bad = np.array(measured, copy=True)
    bad[idx, :3, 3] += d
    return bad, idx


BAD, IDX = _inject(CLEAN)


def val_rms(robot):
    """Position RMS (mm) of a model vs the true robot on the held-out poses."""
    T = np.asarray(jaxcal.fk(robot, jnp.asarray(SIM.q_val[0])))
    return float(np.sqrt(np.mean(np.sum((T[:, :3, 3] - SIM.true_val[0][:, :3, 3]) ** 2, -1))))


@pytest.fixture(scope="module")
def clean_fit():
    return calibrate(ROBOT, Q, CLEAN, **KW)


@pytest.mark.parametrize("method", ["gn", "lm"])
@pytest.mark.parametrize("loss", ["huber", "cauchy"])
def test_robust_fit_survives_outliers(clean_fit, method, loss):
    plain = calibrate(ROBOT, Q, BAD, method=method, keep_outliers=True, **KW)
    robust = calibrate(ROBOT, Q, BAD, method=method, loss=loss, keep_outliers=True, **KW)
    clean, p, r = val_rms(clean_fit.robot), val_rms(plain.robot), val_rms(robust.robot)
    assert clean < 0.05  # the clean fit itself is good (noise 0.02 mm)
    assert p > 10 * clean  # outliers really do spoil the plain fit
    assert r <= 1.5 * clean, (clean, p, r)  # the robust fit does not
    assert robust.converged and robust.loss == loss and not robust.degraded
    assert plain.degraded and not clean_fit.degraded and clean_fit.outliers == ()
    assert robust.outliers == tuple(IDX) and plain.outliers == tuple(IDX)


def test_position_only_huber():
    kw = dict(position_only=True, sigma_pos_mm=0.02, estimate_base=False, estimate_tool=False)
    clean = val_rms(calibrate(ROBOT, Q, CLEAN, **kw).robot)
    robust = calibrate(ROBOT, Q, BAD, loss="huber", keep_outliers=True, **kw)
    assert val_rms(robust.robot) <= 1.5 * clean and robust.outliers == tuple(IDX)


def test_batch_reports_outliers_per_data_set():
    Qb, Mb = np.stack([Q, Q]), np.stack([CLEAN, BAD])
    plain = calibrate_batch(ROBOT, Qb, Mb, keep_outliers=True, **KW)
    robust = calibrate_batch(ROBOT, Qb, Mb, loss="huber", keep_outliers=True, **KW)
    assert plain.outliers(0) == () and plain.outliers(1) == tuple(IDX)
    assert list(plain.degraded) == [False, True] and not robust.degraded.any() and robust.converged.all()
    single = calibrate(ROBOT, Q, BAD, loss="huber", keep_outliers=True, **KW)
    np.testing.assert_allclose(robust.x[1], single.x, atol=1e-12)


def test_robust_loss_is_harmless_without_outliers(clean_fit):
    """On clean Gaussian data Huber changes the estimate only marginally."""
    r = calibrate(ROBOT, Q, CLEAN, loss="huber", **KW)
    assert val_rms(r.robot) <= 1.2 * val_rms(clean_fit.robot) and r.outliers == ()


def test_given_loss_scale():
    r = calibrate(ROBOT, Q, BAD, loss="cauchy", loss_scale=1.0, keep_outliers=True, **KW)  # 1 sigma = the true noise
    assert r.outliers == tuple(IDX) and r.robust_scale == 1.0


def test_noise_free_no_spurious_outliers():
    sim = simulate(ROBOT, q=Q, seed=1)  # same pose count: no recompilation
    r = calibrate(ROBOT, sim.q[0], sim.measured[0], loss="huber", estimate_base=False, estimate_tool=False)
    assert r.outliers == () and not r.degraded and r.converged
