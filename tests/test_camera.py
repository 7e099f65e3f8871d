"""Camera measurement models (jaxcal.camera): the models against their written-out formulas,
their Jacobian against autodiff."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import random_transform
from numpy.testing import assert_allclose

from jaxcal import fk, preset
from jaxcal.camera import CAMERA_MODELS, apply_camera, camera_jacobian, n_params, param_names
from jaxcal.error_model import identification_jacobian, perturb, pose_error


def _poses(rng, k=6):
    return np.stack([random_transform(rng, 600.0) for _ in range(k)])


def test_depth_model_is_the_depth_scale_formula(rng):
    """p' = p + s (z . p) z, z the optical axis, orientation unchanged."""
    T = _poses(rng)
    got = np.asarray(apply_camera(T, jnp.array([0.02]), "depth"))
    z, p = T[:, :3, 2], T[:, :3, 3]
    assert_allclose(got[:, :3, 3], p + 0.02 * np.sum(z * p, 1)[:, None] * z, rtol=1e-13, atol=1e-10)
    assert_allclose(got[:, :3, :3], T[:, :3, :3], rtol=0, atol=0)


def test_linear_model_maps_the_target_origin_in_camera_axes(rng):
    """The target origin in the camera's axes t = -R^T p is reported as (I + A) t."""
    T = _poses(rng)
    c = rng.normal(0, 0.01, 8)
    A = np.array([[c[1], c[2], c[3]], [c[4], -c[1], c[5]], [c[6], c[7], c[0]]])  # the documented layout
    got = np.asarray(apply_camera(T, jnp.asarray(c), "linear"))
    t = -np.einsum("kji,kj->ki", T[:, :3, :3], T[:, :3, 3])
    t_reported = -np.einsum("kji,kj->ki", got[:, :3, :3], got[:, :3, 3])
    assert_allclose(t_reported, t @ (np.eye(3) + A).T, rtol=1e-12, atol=1e-9)
    assert_allclose(got[:, :3, :3], T[:, :3, :3], rtol=0, atol=0)
    assert param_names("linear") == [
        "camera_depth_scale",
        "camera_anisotropy",
        "camera_A_xy",
        "camera_A_xz",
        "camera_A_yx",
        "camera_A_yz",
        "camera_A_zx",
        "camera_A_zy",
    ]


def test_quadratic_model_adds_the_image_field_term(rng):
    """t' = (I + A) t + z Q (u^2, v^2, uv), (u, v) = (x/z, y/z), written out per pose."""
    T = _poses(rng)
    c = rng.normal(0, 0.01, 17)
    A = np.array([[c[1], c[2], c[3]], [c[4], -c[1], c[5]], [c[6], c[7], c[0]]])
    Q = c[8:].reshape(3, 3)
    got = np.asarray(apply_camera(T, jnp.asarray(c), "quadratic"))
    for k in range(len(T)):
        t = -T[k, :3, :3].T @ T[k, :3, 3]
        u, v = t[0] / t[2], t[1] / t[2]
        want = t + A @ t + t[2] * Q @ np.array([u * u, v * v, u * v])
        assert_allclose(-got[k, :3, :3].T @ got[k, :3, 3], want, rtol=1e-12, atol=1e-9)
    assert_allclose(got[:, :3, :3], T[:, :3, :3], rtol=0, atol=0)
    assert param_names("quadratic")[8:11] == ["camera_Q_x_uu", "camera_Q_x_vv", "camera_Q_x_uv"]
    assert param_names("quadratic")[-1] == "camera_Q_z_uv"


def test_none_model_is_the_identity(rng):
    T = _poses(rng)
    assert_allclose(np.asarray(apply_camera(T, jnp.zeros(0), "none")), T, rtol=0, atol=0)
    with pytest.raises(ValueError, match="camera model must be one of"):
        n_params("pinhole")


@pytest.mark.parametrize("model", ["depth", "linear", "quadratic"])
def test_camera_jacobian_matches_autodiff(rng, model):
    """Rows (derivatives through the pose) and the camera columns against jax.jacfwd of the
    measurement model applied to the perturbed robot."""
    r = preset("panda").replace(base=random_transform(rng, 500.0), tool=random_transform(rng, 150.0))
    q = jnp.asarray(rng.uniform(-1.5, 1.5, (5, 7)))
    m, mc = 4 * r.n_joints + 12, n_params(model)
    c0 = jnp.asarray(rng.normal(0, 0.03, mc))

    def measured(xs):
        T = fk(perturb(r, xs[:m], base=True, tool=True), q)
        return pose_error(apply_camera(T, c0 + xs[m:], model), apply_camera(fk(r, q), c0, model))

    @jax.jit  # one program, not one per operation
    def both():
        auto = jax.jacfwd(measured)(jnp.zeros(m + mc))  # (5, 6, m + mc)
        return auto, camera_jacobian(identification_jacobian(r, q, base=True, tool=True), fk(r, q), c0, model)

    auto, ana = both()
    assert ana.shape == auto.shape
    assert_allclose(np.asarray(ana), np.asarray(auto), atol=1e-8 * float(np.abs(auto).max()))


def test_models_listed():
    assert CAMERA_MODELS == ("none", "depth", "linear", "quadratic")
    assert [n_params(m) for m in CAMERA_MODELS] == [0, 1, 8, 17]
    assert [len(param_names(m)) for m in CAMERA_MODELS] == [0, 1, 8, 17]


def _rank(M):
    return np.linalg.matrix_rank(M / np.linalg.norm(M, axis=0).clip(1e-300), tol=1e-9)


def _stacked_jacobian(rng, model):
    """Poses of a Panda with random base and tool, and the stacked Jacobian of the robot, its
    frames and the camera model's unknowns (last ``n_params(model)`` columns)."""
    r = preset("panda").replace(base=random_transform(rng, 500.0), tool=random_transform(rng, 100.0))
    q = jnp.asarray(rng.uniform(-1.5, 1.5, (60, 7)))
    T = fk(r, q)
    J = camera_jacobian(identification_jacobian(r, q, base=True, tool=True), T, jnp.zeros(n_params(model)), model)
    return np.asarray(T), np.asarray(J).reshape(-1, J.shape[-1])


def test_linear_model_leaves_out_exactly_the_robot_scale(rng):
    """With every length of the robot and its frames free, the camera's 8 unknowns add 8 to the
    rank (all identifiable), while a uniform scale A = a I would add nothing: it is a uniform
    scale of the robot."""
    T, J = _stacked_jacobian(rng, "linear")
    u = np.einsum("kji,kj->ki", T[:, :3, :3], T[:, :3, 3])
    iso = np.concatenate([np.einsum("kij,kj->ki", T[:, :3, :3], u), np.zeros((60, 3))], 1).reshape(-1, 1)
    assert _rank(J) == _rank(J[:, :-8]) + 8
    assert _rank(np.c_[J, iso]) == _rank(J)


def test_quadratic_model_terms_are_identifiable(rng):
    """All 17 unknowns (linear's 8 and the nine field terms) add to the rank on top of the robot
    and its frames."""
    _, J = _stacked_jacobian(rng, "quadratic")
    assert _rank(J) == _rank(J[:, :-17]) + 17


def test_calibrate_estimates_the_camera_model(rng):
    """A single fit with ``camera="linear"`` frees the camera's unknowns: noise-free poses seen
    through a known linear camera error give it back, and the robot's FK with it."""
    from jaxcal import calibrate

    true = preset("panda").replace(base=random_transform(rng, 500.0), tool=random_transform(rng, 100.0))
    q = rng.uniform(-1.5, 1.5, (40, 7))
    c_true = rng.normal(0, 3e-3, n_params("linear"))
    seen = np.asarray(apply_camera(fk(true, jnp.asarray(q)), jnp.asarray(c_true), "linear"))
    res = calibrate(preset("panda"), q, seen, camera="linear", params="frames")
    assert res.converged
    assert_allclose(np.asarray(res.model.camera_params), c_true, atol=1e-9)
    assert res.after["pos_rms_mm"] < 1e-6
