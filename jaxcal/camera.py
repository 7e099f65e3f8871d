"""Measurement models of a camera on the flange that reports its pose w.r.t. a fixed target.

Camera-on-flange data (``jaxcal calibrate --camera-model``) measure the camera's pose ``T =
(R, p)`` in the target's frame, usually from PnP on a checkerboard. A PnP solution inherits the
camera's intrinsic-calibration errors as *systematic*, view-dependent position errors: a
focal length off by ``e`` scales the depth (distance along the optical axis) by ``1 + e``, a
principal point off by ``d`` pixels shears the lateral position by ``d/f`` per unit depth, and
so on. On the Franka data, repeated joint positions reproduce far better than the calibrated
model predicts them, so the leftover error is systematic, and part of it is of this kind
(``docs/franka.md``).

A model maps the pose the robot model predicts to what the camera is predicted to report. In
the camera's own axes the target origin is at ``t = -R^T p``; the camera reports ``t' = t +
G(t)`` (orientation unchanged), i.e. in the target frame ``p' = p - R G(t)``. For the linear
models ``G(t) = A t``:

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
  that uniform scale plus a depth scale ``-a``;
* ``quadratic``: ``linear`` plus a second-order field term in the normalised image
  coordinates ``(u, v) = (x/z, y/z)`` of the target origin: ``t' = (I + A) t + z Q h(u, v)``
  with ``h = (u^2, v^2, uv)`` and ``Q`` a free 3x3 matrix (nine more unknowns, 17 in all;
  ``camera_Q_<axis>_<uu|vv|uv>``). It is the first term left over by a lens-distortion model
  that is not quite right (decentring and thin-prism terms are quadratic in ``(u, v)``); the
  term is homogeneous of degree 1 in ``t``, so it does not trade with the robot's scale. It
  needs the target in front of the camera (``z > 0``).

These are measurement parameters: they are estimated with the robot and enter every prediction
(so held-out errors are of what the camera reports), but they are not part of the calibrated
robot. They need full poses (the camera's axes).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .errors import DataError

CAMERA_MODELS = ("none", "depth", "linear", "quadratic")
_AXES = "xyz"
_OFF = [(a, b) for a in _AXES for b in _AXES if a != b]
_FEATURES = ("uu", "vv", "uv")
_N_LINEAR = 8


def _check(model: str) -> None:
    if model not in CAMERA_MODELS:
        raise ValueError(f"camera model must be one of {', '.join(CAMERA_MODELS)}, got {model!r}")


def n_params(model: str) -> int:
    """Number of unknowns of a camera model."""
    _check(model)
    return {"none": 0, "depth": 1, "linear": 8, "quadratic": 17}[model]


def param_names(model: str) -> list[str]:
    """Names of the unknowns, in order: ``camera_depth_scale`` (``A_zz``), then for ``linear``
    ``camera_anisotropy`` (``A_xx = -A_yy``) and ``camera_A_xy, A_xz, A_yx, A_yz, A_zx, A_zy``,
    then for ``quadratic`` ``camera_Q_x_uu, Q_x_vv, Q_x_uv, Q_y_uu, ..., Q_z_uv`` (row = axis of
    the reported position, column = image feature)."""
    _check(model)
    names = ["camera_depth_scale", "camera_anisotropy"] + [f"camera_A_{a}{b}" for a, b in _OFF]
    names += [f"camera_Q_{a}_{f}" for a in _AXES for f in _FEATURES]
    return names[: n_params(model)]


def basis(model: str) -> np.ndarray:
    """The basis matrices ``E_k`` ``(m_lin, 3, 3)`` of the linear part ``A``, in camera axes
    (``quadratic`` has the eight of ``linear``; its ``Q`` is not a linear map of ``t``)."""
    E = np.zeros((_N_LINEAR, 3, 3))
    E[0, 2, 2] = 1.0
    E[1, 0, 0], E[1, 1, 1] = 1.0, -1.0
    for k, (a, b) in enumerate(_OFF):
        E[2 + k, _AXES.index(a), _AXES.index(b)] = 1.0
    return E[: min(n_params(model), _N_LINEAR)]


def check_target_in_front(measured: Float[np.ndarray, "k 4 4"], what: str = "quadratic", rows=None) -> None:
    """Raise :class:`jaxcal.DataError` naming the first measured pose (and its data row, when
    ``rows`` gives them) whose target origin is not in front of the camera (``z <= 0`` in the
    camera's axes), where the image coordinates ``x/z, y/z`` of ``quadratic`` are undefined."""
    measured = np.asarray(measured)
    z = -np.einsum("ki,ki->k", measured[:, :3, 2], measured[:, :3, 3])
    bad = np.flatnonzero(~(z > 1e-6 * np.abs(measured[:, :3, 3]).max(initial=1.0)))
    if bad.size:
        raise DataError(
            f"the camera model {what} needs the target in front of the camera (z > 0 in the camera's "
            f"axes); pose {bad[0]}{'' if rows is None else f' (data row {rows[bad[0]]})'} has z = "
            f"{z[bad[0]]:.3g} mm ({bad.size} such poses)"
        )


def _features(t):
    """``z h(u, v) = (x^2/z, y^2/z, xy/z)`` ``(..., 3)`` and its derivative ``(..., 3, 3)``
    (feature, coordinate) for target origins ``t`` ``(..., 3)`` in camera axes."""
    x, y, z = t[..., 0], t[..., 1], t[..., 2]
    u, v = x / z, y / z
    h = jnp.stack([x * u, y * v, x * v], -1)
    zero = jnp.zeros_like(u)
    dh = jnp.stack(
        [jnp.stack([2 * u, zero, -u * u], -1), jnp.stack([zero, 2 * v, -v * v], -1), jnp.stack([v, u, -u * v], -1)], -2
    )
    return h, dh


def _correction(model: str, c, t):
    """``G(t)`` ``(..., 3)``, its derivative ``DG`` ``(..., 3, 3)`` and ``dG/dc`` ``(..., 3, m)``
    for target origins ``t`` ``(..., 3)`` in camera axes: ``G = A t`` (+ ``Q z h(u, v)`` for
    ``quadratic``). Under jit, what a caller does not use is not computed."""
    c = jnp.asarray(c)
    E = jnp.asarray(basis(model))
    A = jnp.einsum("m,mij->ij", c[:_N_LINEAR], E)
    G = jnp.einsum("ij,...j->...i", A, t)
    DG = jnp.broadcast_to(A, t.shape + (3,))
    dc = jnp.einsum("mjk,...k->...jm", E, t)  # (..., 3, m_lin)
    if model == "quadratic":
        Q = c[_N_LINEAR:].reshape(3, 3)
        h, dh = _features(t)
        G = G + jnp.einsum("ij,...j->...i", Q, h)
        DG = DG + jnp.einsum("ij,...jk->...ik", Q, dh)
        dq = jnp.eye(3)[:, :, None] * h[..., None, None, :]  # (..., 3, axis, feature)
        dc = jnp.concatenate([dc, dq.reshape(dq.shape[:-2] + (9,))], -1)
    return G, DG, dc


def _target_in_camera(T):
    R, p = T[..., :3, :3], T[..., :3, 3]
    return R, p, -jnp.einsum("...ji,...j->...i", R, p)  # t = -R^T p


def apply_camera(T: Float[Array, "*b 4 4"], c: Float[Array, " m"], model: str) -> Float[Array, "*b 4 4"]:
    """What the camera reports when its true pose is ``T`` (position ``p' = p - R G(t)``,
    ``t = -R^T p``, rotation unchanged; ``G(t) = A t`` for the linear models)."""
    T = jnp.asarray(T)
    _check(model)
    if model == "none":
        return T
    R, _, t = _target_in_camera(T)
    G = _correction(model, c, t)[0]
    return T.at[..., :3, 3].add(-jnp.einsum("...ij,...j->...i", R, G))


def camera_jacobian(
    J: Float[Array, "*b 6 p"], T: Float[Array, "*b 4 4"], c: Float[Array, " m"], model: str
) -> Float[Array, "*b 6 p+m"]:
    """Rows of the identification Jacobian ``J`` (derivatives of the modelled pose ``T``: position
    ``dp`` and spatial rotation ``w``, ``dR = [w] R``) turned into derivatives of
    :func:`apply_camera` ``(T, c)``, plus one column per unknown ``d p'/d c_k = -R dG/dc_k``.

    With ``dt = -R^T (dp - w x p)``: ``d p' = dp - w x (R G) + R DG R^T (dp - w x p)``, ``DG =
    A + Q Dh`` the derivative of ``G`` at ``t``; rotation rows unchanged.
    """
    _check(model)
    if model == "none":
        return J
    R, p, t = _target_in_camera(T)
    G, DG, dc = _correction(model, c, t)
    cols = -R @ dc  # (..., 3, m)
    dp, w = J[..., :3, :], J[..., 3:, :]
    v = -jnp.einsum("...ij,...j->...i", R, G)  # -R G
    cross = lambda a, b: jnp.cross(a, b, axisa=-2, axisb=-2, axisc=-2)  # column-wise
    M = jnp.einsum("...ij,...jk,...lk->...il", R, DG, R)  # R DG R^T
    dp2 = dp + cross(w, v[..., :, None]) + M @ (dp - cross(w, p[..., :, None]))
    cols = jnp.concatenate([cols, jnp.zeros_like(cols)], -2)
    return jnp.concatenate([jnp.concatenate([dp2, w], -2), cols], -1)
