"""What moved during the session (``jaxcal/calibration/_markers.py``): a point on the tool partway
through the data, on residuals made here (random tool rotations, noise, and a step in one point's
tool-frame position); the measurement frame drifting along the file, on residuals made here and
through a calibration of a simulated arm (NumPy FK)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jaxcal.calibration._markers import drift, moved_point

K, M, SIGMA = 40, 4, 0.3


def _residuals(seed, step=None, at=None, j=None, common=None):
    """Measured minus predicted (mm, measurement frame): noise, a tool-frame step of point ``j``
    from pose ``at`` (half before it, half after, as a fit centred on it leaves it), and a
    tool-frame error shared by every point (``common (K, 3)``)."""
    rng = np.random.default_rng(seed)
    R = Rotation.random(K, random_state=seed).as_matrix()
    tool = np.zeros((K, M, 3))
    if step is not None:
        tool[:at, j] -= np.asarray(step) / 2
        tool[at:, j] += np.asarray(step) / 2
    if common is not None:
        tool += common[:, None]
    return R, np.einsum("kij,kmj->kmi", R, tool) + rng.normal(0, SIGMA, (K, M, 3))


def test_the_point_that_moved_and_where_are_found():
    R, r = _residuals(0, step=[2.0, -1.0, 1.0], at=23, j=2)
    j, last, first, step, sigmas = moved_point(R, r, np.ones(K, bool), SIGMA)
    assert (j, last, first) == (2, 22, 23) and sigmas > 5
    np.testing.assert_allclose(step, [2.0, -1.0, 1.0], atol=0.5)


def test_with_two_points_which_one_moved_is_not_told():
    """Each of two points' error relative to the other's is the other's turned round: the move and
    where are found, not which point made it."""
    for j in (0, 1):
        R, r = _residuals(4, step=[0.0, 0.0, 3.0], at=15, j=j)
        found = moved_point(R, r[:, :2], np.ones(K, bool), SIGMA)
        assert found[:3] == (-1, 14, 15)


def test_noise_a_drift_of_the_arms_error_and_one_point_are_not_a_move():
    """A tool-frame error that every point shares (the arm's, drifting along the file) moves no
    point against the others; one point has no others to compare with."""
    drift = np.linspace(-5.0, 5.0, K)[:, None] * np.array([1.0, 0.5, -0.5])
    for common in (None, drift):
        R, r = _residuals(1, common=common)
        assert moved_point(R, r, np.ones(K, bool), SIGMA) is None
    R, r = _residuals(2, step=[5.0, 0.0, 0.0], at=20, j=0)
    assert moved_point(R, r[:, :1], np.ones(K, bool), SIGMA) is None


@pytest.mark.parametrize("lost", [False, True])
def test_lost_points_and_left_out_poses_are_skipped(lost):
    """A point not seen (NaN) at some poses and poses left out as outliers: the step is still
    found, at the first pose kept after it."""
    R, r = _residuals(3, step=[0.0, 3.0, 0.0], at=18, j=1)
    valid = np.ones(K, bool)
    valid[[5, 18, 30]] = False
    if lost:  # not seen just before and just after the move: it lies between the poses it was seen at
        r[[17, 19, 33], 1] = np.nan
        r[[7, 25], 3] = np.nan
    j, last, first, _, _ = moved_point(R, r, valid, SIGMA)
    assert (j, last, first) == ((1, 16, 20) if lost else (1, 17, 19))


def test_a_drift_along_the_rows_is_found_and_noise_or_a_small_one_is_not():
    """Residuals made here: a linear drift of (0.3, 0, 0.2) mm from the first row to the last,
    0.02 mm noise, rows with gaps, a pose left out: the drift found is the one made; noise alone,
    or a drift under three times the noise, is not named."""
    rng = np.random.default_rng(5)
    rows = np.cumsum(rng.integers(1, 3, 60))
    made = np.array([0.3, 0.0, 0.2])
    trend = (rows - rows[0])[:, None] / (rows[-1] - rows[0]) * made
    r = trend[:, None] + rng.normal(0, 0.02, (60, 2, 3))
    r[7, 1] = np.nan  # a point not seen
    valid = np.ones(60, bool)
    valid[30] = False
    d = drift(rows, r, valid)
    np.testing.assert_allclose(d.change, made, atol=0.03)
    assert d.step is None and d.sigmas > 10 and d.noise == pytest.approx(0.02 / np.sqrt(2), rel=0.25)  # 2 points
    assert d.rows.tolist() == np.delete(rows, 30).tolist()
    assert drift(rows, r - trend[:, None], valid) is None
    # the same rows, the tracker knocked by (0.3, 0, 0.2) mm between the 25th and 26th: a step there
    knocked = np.where((np.arange(60) >= 25)[:, None, None], made, 0.0) + rng.normal(0, 0.02, (60, 2, 3))
    d = drift(rows, knocked, valid)
    np.testing.assert_allclose(d.change, made, atol=0.03)
    assert d.rows[d.step - 1 : d.step + 1].tolist() == rows[24:26].tolist()
    # 5000 rows: a drift of 0.036 mm is a trend far beyond chance, but under three times the noise
    rows = np.arange(5000)
    small = 0.1 * made * rows[:, None] / rows[-1]
    r = small[:, None] + rng.normal(0, 0.02, (5000, 1, 3))
    assert drift(rows, r, np.ones(5000, bool)) is None
    assert drift(rows, r + 9 * small[:, None], np.ones(5000, bool)) is not None


def test_a_tracker_that_drifts_during_the_session_is_named():
    """A UR5 (NumPy FK) measured at 60 postures by a tracker whose frame drifts 0.36 mm along the
    session: one base frame averages it, no pose stands out; the report names the drift, its size
    and direction. The same data without the drift: nothing named."""
    from helpers import dh_fk

    import jaxcal

    robot = jaxcal.preset("ur5")
    rng = np.random.default_rng(2)
    dh = np.asarray(robot.dh, float) + rng.normal(0, [1e-3, 0.5, 0.5, 1e-3], (6, 4))
    base = np.eye(4)
    base[:3, :3], base[:3, 3] = Rotation.from_euler("z", 0.5).as_matrix(), [1500.0, 200.0, -300.0]
    q = rng.uniform(-2.8, 2.8, (60, 6))
    T = dh_fk(dh, q, base=base)
    points = T[:, :3, :3] @ np.array([30.0, -20.0, 120.0]) + T[:, :3, 3] + rng.normal(0, 0.02, (60, 3))
    made = np.array([0.3, 0.0, 0.2])
    moved = points + np.linspace(0, 1, 60)[:, None] * made
    rep = jaxcal.calibrate_data(robot, jaxcal.Measurements(q, moved[:, None]), nested_max_poses=0).report
    d = rep["drift"]
    assert d["kind"] == "linear" and (d["from_row"], d["to_row"]) == (1, 60)
    assert d["mm"] == pytest.approx(np.linalg.norm(made), rel=0.15)
    assert np.dot(d["direction"], made / np.linalg.norm(made)) > 0.98 and rep["outliers"] == []
    assert any(n.startswith("the measurements drift along the file") for n in rep["notes"])
    clean = jaxcal.calibrate_data(robot, jaxcal.Measurements(q, points[:, None]), nested_max_poses=0).report
    assert clean["drift"] is None and not any("drift" in n for n in clean["notes"])
