"""The accuracy map's predicted position standard deviation (the parameter covariance of
`calibrate_data` propagated through the model) against Monte Carlo: over simulated robots (one
nominal, random true errors, base and tool, the assumed noise, the same poses) the spread of
the calibrated positions at fixed poses."""

import jax
import jax.numpy as jnp
import numpy as np
from helpers import UR5_TRACKER, ur5_tracker

import jaxcal
from jaxcal.calibration import position_std
from jaxcal.model import Model, apply, predict


def test_predicted_sigma_matches_monte_carlo():
    ur5, sim, data, res = ur5_tracker()
    R = sim.q.shape[0]
    # the predicted sigma of robot 0's calibration at the inspection poses
    pred = position_std(res.model, res.layout, res.covariance, sim.q_val[0])[:, 0]
    # every robot calibrated with the same options (one vmapped solve), then its tool point
    # predicted at the inspection poses, against the true one
    pts = sim.measured[:, :, None, :3, 3]
    batch = jaxcal.calibrate_batch(ur5, sim.q, pts, params=UR5_TRACKER["params"], sigma_pos_mm=UR5_TRACKER["sigma_pos"])
    assert batch.converged.all()
    ref = Model(ur5.stripped(), np.zeros((1, 3)))
    predicted = jax.jit(jax.vmap(lambda x: predict(apply(ref, batch.layout, x), jnp.asarray(sim.q_val[0]))))
    cal = predicted(jnp.asarray(batch.x))  # one program, not one per operation
    err = np.asarray(cal)[:, :, 0] - sim.true_val[:, :, :3, 3]  # (R, Kv, 3)
    assert np.abs(err.mean(0)).max() < 3 * pred.max() / np.sqrt(R)  # no bias beyond the spread's own noise
    spread = np.sqrt(np.mean(np.sum(err**2, -1), 0))  # RMS distance per pose
    ratio = spread / pred
    assert np.all(np.abs(ratio - 1) < 0.2), ratio
    assert abs(np.mean(ratio) - 1) < 0.1, ratio
