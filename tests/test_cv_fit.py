"""The batched fitting engine (jaxcal.cv_fit): nested camera models share one setup, a
candidate's unused camera unknowns are held at 0, and the pose-count check names the numbers."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest
from numpy.testing import assert_allclose

from jaxcal import DataError, fk, preset
from jaxcal.camera import apply_camera
from jaxcal.cv_fit import fit_many, make_setup
from jaxcal.lie import make_transform, rpy_to_matrix
from jaxcal.measurements import franka_csv_path, read_measurements
from jaxcal.param_sets import parse_params


def _camera_data(rng, k=50):
    """Franka joint angles and camera geometry, noise-free, seen through a quadratic camera."""
    r = preset("panda")
    q = np.asarray(read_measurements(franka_csv_path(), r, length_unit="m").q)[:k]
    B = make_transform(rpy_to_matrix(np.radians([-0.1, 0.61, -0.02])), np.array([-656.0, 589.0, 7.2]))
    X = make_transform(rpy_to_matrix(np.radians([0.5, -0.9, 88.2])), np.array([91.2, -11.6, 142.7]))
    c = np.r_[0.005, 0.002, 0.004, -0.002, -0.01, 0.001, 0.003, 0.003, rng.normal(0, 0.01, 9)]
    meas = np.asarray(apply_camera(fk(r.replace(base=B, tool=X), jnp.asarray(q)), c, "quadratic"))
    return r, q, meas, c


def test_candidate_frees_only_its_camera_models_unknowns(rng):
    """In a setup carrying the quadratic model's 17 unknowns, a 'linear' candidate holds the nine
    field terms at 0 and fits as the linear setup does; the 'quadratic' candidate recovers them."""
    r, q, meas, c = _camera_data(rng)
    (frames,) = parse_params("frames", r)
    lin, quad = (dataclasses.replace(frames, camera=m) for m in ("linear", "quadratic"))
    mask = np.ones((1, len(q)), bool)
    big = fit_many(make_setup(r, q, meas, position_only=False, candidates=[lin, quad], camera="quadratic"), mask,
                   [lin, quad])
    small = fit_many(make_setup(r, q, meas, position_only=False, candidates=[lin], camera="linear"), mask, [lin])
    assert big["camera"].shape == (1, 2, 17) and small["camera"].shape == (1, 1, 8)
    assert np.abs(big["camera"][0, 0, 8:]).max() < 1e-9                    # held at 0 by the pin
    assert_allclose(big["camera"][0, 0, :8], small["camera"][0, 0], atol=1e-7)
    assert_allclose(big["pred"][0, 0], small["pred"][0, 0], atol=1e-5)
    assert_allclose(big["camera"][0, 1], c, atol=1e-6)                     # noise-free: exact recovery
    assert np.abs(big["pred"][0, 1] - meas).max() < 1e-6


def test_too_few_poses_names_equations_and_parameters(rng):
    r, q, meas, _ = _camera_data(rng, k=8)
    cands = parse_params("all", r)
    with pytest.raises(DataError, match=r"too few poses: 8 poses x 6 rows = 48 equations for \d+ parameters"):
        make_setup(r, q, meas, position_only=False, candidates=cands, camera="quadratic")
    with pytest.raises(DataError, match="--method must be one of gn, lm, linear"):
        make_setup(r, q, meas, position_only=False, candidates=cands, method="elimination")
