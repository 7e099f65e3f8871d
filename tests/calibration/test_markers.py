"""A point that moved on the tool partway through the data (``jaxcal/calibration/_markers.py``),
on residuals made here: random tool rotations, noise, and a step in one point's tool-frame
position."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jaxcal.calibration._markers import moved_point

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
