"""Measurement models of a camera on the flange that reports its pose w.r.t. a fixed target.

Camera-on-flange data (``jaxcal calibrate --camera-model``) measure the camera's pose ``T =
(R, p)`` in the target's frame, usually from PnP on a checkerboard. A PnP solution inherits the
camera's intrinsic-calibration errors as *systematic*, view-dependent position errors: a
focal length off by ``e`` scales the depth (distance along the optical axis) by ``1 + e``, a
principal point off by ``d`` pixels shears the lateral position by ``d/f`` per unit depth, and
so on. On the Franka data, repeated joint positions reproduce to ~0.1 mm while the calibrated
model misses by ~1.2 mm RMS, so the leftover error is systematic, and part of it is of this
kind (``docs/franka/``).

A model maps the pose the robot model predicts to what the camera is predicted to report. In
the camera's own axes the target origin is at ``t = -R^T p``; the camera reports ``t' = (I +
A) t`` (orientation unchanged), i.e. in the target frame

    ``p' = p + R A R^T p``,   ``A = sum_k c_k E_k``

with ``c`` the model's unknowns and ``E_k`` fixed 3x3 basis matrices (camera axes):

* ``none``: no unknowns;
* ``depth``: ``A = s e_z e_z^T`` (one unknown, the depth scale ``s``): ``p' = p + s (z.p) z``;
* ``linear``: ``A`` a 3x3 matrix with ``A_xx = -A_yy``: eight unknowns, the depth scale
  ``A_zz``, the lateral anisotropy ``A_xx = -A_yy`` and the six off-diagonal entries (``A_xz,
  A_yz``: principal-point shears; ``A_xy, A_yx``: rotation and shear of the lateral position about
  the optical axis relative to the orientation estimate). The ninth direction, a uniform scale
  ``A = a I``, is left out because it is exactly a uniform scale of every length of the robot and
  its frames (the calibrated robot carries it); a lateral scale ``a (e_x e_x^T + e_y e_y^T)`` is
  that uniform scale plus a depth scale ``-a``.

These are measurement parameters: they are estimated with the robot and enter every prediction
(so held-out errors are of what the camera reports), but they are not part of the calibrated
robot. They need full poses (the camera's axes).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

CAMERA_MODELS = ("none", "depth", "linear")
_AXES = "xyz"
_OFF = [(a, b) for a in _AXES for b in _AXES if a != b]


def _check(model: str) -> None:
    if model not in CAMERA_MODELS:
        raise ValueError(f"camera model must be one of {', '.join(CAMERA_MODELS)}, got {model!r}")


def n_params(model: str) -> int:
    """Number of unknowns of a camera model."""
    _check(model)
    return {"none": 0, "depth": 1, "linear": 8}[model]


def param_names(model: str) -> list[str]:
    """Names of the unknowns, in order: ``camera_depth_scale`` (``A_zz``), then for ``linear``
    ``camera_anisotropy`` (``A_xx = -A_yy``) and ``camera_A_xy, A_xz, A_yx, A_yz, A_zx, A_zy``."""
    _check(model)
    names = ["camera_depth_scale", "camera_anisotropy"] + [f"camera_A_{a}{b}" for a, b in _OFF]
    return names[:n_params(model)]


def basis(model: str) -> np.ndarray:
    """The basis matrices ``E_k`` ``(m, 3, 3)`` in camera axes."""
    E = np.zeros((8, 3, 3))
    E[0, 2, 2] = 1.0
    E[1, 0, 0], E[1, 1, 1] = 1.0, -1.0
    for k, (a, b) in enumerate(_OFF):
        E[2 + k, _AXES.index(a), _AXES.index(b)] = 1.0
    return E[:n_params(model)]


def apply_camera(T: Float[Array, "*b 4 4"], c: Float[Array, " m"], model: str) -> Float[Array, "*b 4 4"]:
    """What the camera reports when its true pose is ``T`` (position ``p' = p + R A R^T p``,
    rotation unchanged)."""
    T = jnp.asarray(T)
    if model == "none":
        _check(model)
        return T
    A = jnp.einsum("m,mij->ij", jnp.asarray(c), jnp.asarray(basis(model)))
    R, p = T[..., :3, :3], T[..., :3, 3]
    u = jnp.einsum("...ji,...j->...i", R, p)                 # R^T p = -t
    return T.at[..., :3, 3].add(jnp.einsum("...ij,jk,...k->...i", R, A, u))


def camera_jacobian(J: Float[Array, "*b 6 p"], T: Float[Array, "*b 4 4"], c: Float[Array, " m"],
                    model: str) -> Float[Array, "*b 6 p+m"]:
    """Rows of the identification Jacobian ``J`` (derivatives of the modelled pose ``T``: position
    ``dp`` and spatial rotation ``w``, ``dR = [w] R``) turned into derivatives of
    :func:`apply_camera` ``(T, c)``, plus one column per unknown ``d p'/d c_k = R E_k R^T p``.

    ``d p' = dp + w x (R A u) + R A R^T (dp - w x p)``, ``u = R^T p``; rotation rows unchanged.
    """
    if model == "none":
        _check(model)
        return J
    E = jnp.asarray(basis(model))
    A = jnp.einsum("m,mij->ij", jnp.asarray(c), E)
    R, p = T[..., :3, :3], T[..., :3, 3]
    u = jnp.einsum("...ji,...j->...i", R, p)
    dp, w = J[..., :3, :], J[..., 3:, :]
    v = jnp.einsum("...ij,jk,...k->...i", R, A, u)                        # R A u
    cross = lambda a, b: jnp.cross(a, b, axisa=-2, axisb=-2, axisc=-2)    # column-wise
    M = jnp.einsum("...ij,jk,...lk->...il", R, A, R)                       # R A R^T
    dp2 = dp + cross(w, v[..., :, None]) + M @ (dp - cross(w, p[..., :, None]))
    cols = jnp.einsum("...ij,mjk,...k->...im", R, E, u)                   # (..., 3, m)
    cols = jnp.concatenate([cols, jnp.zeros_like(cols)], -2)
    return jnp.concatenate([jnp.concatenate([dp2, w], -2), cols], -1)
