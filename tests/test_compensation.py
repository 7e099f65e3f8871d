"""Compensation by inverse kinematics of the calibrated model, checked against simulated truth."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from jaxcal import DataError, fk, preset
from jaxcal.compensate import compensate, compensate_targets, read_targets
from jaxcal.crossval import calibrate_measurements
from jaxcal.error_model import perturb
from jaxcal.simulate import simulate


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
    res = calibrate_measurements(r, sim.q[0], sim.measured[0], position_only=False, params="all", folds=3)
    true_robot = perturb(r, sim.x_true[0], base=True, tool=True)
    q_cmd = np.asarray(sim.q_val[0])
    targets = np.asarray(fk(r, q_cmd))            # where the nominal model says the commands go
    before = np.linalg.norm(np.asarray(fk(true_robot, q_cmd))[:, :3, 3] - targets[:, :3, 3], axis=1)
    comp = compensate(res.robot, targets, q_cmd)
    # a few random targets sit near a singularity / the calibrated workspace boundary: reported, not hidden
    ok = comp.converged
    assert ok.mean() >= 0.9 and comp.pos_residual_mm[ok].max() < 1e-6
    assert (comp.pos_residual_mm[~ok] > 1e-6).all()
    after = np.linalg.norm(np.asarray(fk(true_robot, comp.q))[:, :3, 3] - targets[:, :3, 3], axis=1)[ok]
    rms_before, rms_after = np.sqrt(np.mean(before[ok] ** 2)), np.sqrt(np.mean(after ** 2))
    assert rms_before > 2.0                        # mm: the uncompensated arm is well off
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


@pytest.mark.parametrize("text, msg", [
    ("x,y\n1,2\n", "missing column\\(s\\) 'z'"),
    ("x,y,z,w\n1,2,3,4\n", "unknown column\\(s\\) 'w'"),
    ("q1,q2\n0,0\n", "do not match the robot's 6 joints"),
    ("x,y,z,qw\n1,2,3,1\n", "quaternion columns need all"),
    ("x,y,z\n1,abc,3\n", "row 1 \\(line 2\\), column 'y': not a number: 'abc'"),
    ("x,y,z\n1,2,inf\n", "row 1 \\(line 2\\), column 'z': value 'inf' is not finite"),
    ("x,y,z,qw,qx,qy,qz\n1,2,3,1,1,0,0\n", "row 1 \\(line 2\\): quaternion .* has norm 1.41421"),
    ("x,y,z\n", "header only"),
])
def test_targets_bad_input(tmp_path, text, msg):
    p = tmp_path / "t.csv"
    p.write_text(text)
    with pytest.raises(DataError, match=msg):
        read_targets(p, preset("paper-6r"))
