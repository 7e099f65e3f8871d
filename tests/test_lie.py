"""The rotation conversions of the file formats (``jaxcal.lie``) against scipy's, for NumPy and
JAX input."""

import jax.numpy as jnp
import numpy as np
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from jaxcal.lie import matrix_to_rpy, quat_to_matrix, rpy_to_matrix


def test_rpy_to_matrix_is_scipys_fixed_axes_xyz():
    rng = np.random.default_rng(1)
    rpy = rng.uniform(-np.pi, np.pi, size=(200, 3)) * [1.0, 0.5, 1.0]
    R = rpy_to_matrix(rpy)
    assert isinstance(R, np.ndarray)  # NumPy in, NumPy out: nothing compiled
    assert_allclose(R, Rotation.from_euler("xyz", rpy).as_matrix(), atol=1e-15)
    assert_allclose(np.asarray(rpy_to_matrix(jnp.asarray(rpy))), R, atol=1e-15)


def test_matrix_to_rpy_inverts_it_at_every_pitch():
    rng = np.random.default_rng(2)
    rpy = rng.uniform(-np.pi, np.pi, size=(200, 3)) * [1.0, 0.5, 1.0]
    assert_allclose(matrix_to_rpy(rpy_to_matrix(rpy)), rpy, atol=1e-12)
    assert_allclose(matrix_to_rpy(Rotation.from_euler("xyz", rpy).as_matrix()), rpy, atol=1e-12)
    # at pitch +-pi/2 only yaw -+ roll is defined: the same rotation comes back, with roll 0
    locked = np.array([[0.3, np.pi / 2, 0.2], [0.1, -np.pi / 2, -0.4], [2.0, np.pi / 2, -3.0]])
    back = matrix_to_rpy(rpy_to_matrix(locked))
    assert_allclose(back[:, 0], 0.0, atol=0)
    assert_allclose(rpy_to_matrix(back), rpy_to_matrix(locked), atol=1e-12)


def test_quat_to_matrix_is_scipys():
    rng = np.random.default_rng(3)
    q = rng.normal(size=(100, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    R = quat_to_matrix(q)
    assert isinstance(R, np.ndarray)
    assert_allclose(R, Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix(), atol=1e-15)  # scipy: scalar last
    assert_allclose(np.asarray(quat_to_matrix(jnp.asarray(q))), R, atol=1e-15)
