"""Simulated calibration experiments: true parameter errors, poses, noisy measurements.

Everything is seeded and batched: one call draws ``R`` robots x ``K`` poses. Measurements come
from the *exact* nonlinear kinematics of each true robot (:func:`jaxcal.error_model.perturb`),
then Gaussian noise: ``N(0, sigma_pos)`` per position coordinate (mm) and a rotation
``exp(N(0, sigma_rot) per axis)`` applied on the left (rad).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._config import as_f64, jit
from .error_model import n_params, perturb
from .errors import DataError
from .kinematics import fk
from .lie import so3_exp
from .robot import Robot

# Default error scales, like the paper's Table 2: ~0.005 rad on theta/alpha, ~0.05 mm on d/a.
DEFAULT_DH_SCALES = (0.005, 0.05, 0.05, 0.005)
DEFAULT_FRAME_SCALES = (1.0, 1.0, 1.0, 0.01, 0.01, 0.01)  # mm, rad
DEFAULT_JOINT_SCALES = (0.005, 0.05, 0.05, 0.05, 0.005, 0.005, 0.005)
"""Joint frames: the offset (rad; a prismatic joint's in mm), the origin's shift (mm) and turn."""


def error_scales(
    robot: Robot,
    *,
    base: bool = False,
    tool: bool = False,
    dh_scales=DEFAULT_DH_SCALES,
    frame_scales=DEFAULT_FRAME_SCALES,
) -> np.ndarray:
    """Per-parameter standard deviation of the simulated true errors, in the layout of
    :func:`jaxcal.error_model.param_names` (``dh_scales`` per DH joint; joint-frame robots take
    :data:`DEFAULT_JOINT_SCALES`, a prismatic offset at the length scale)."""
    if robot.convention == "joint":
        s = [
            v * (10.0 if k == 0 and t == "P" else 1.0)
            for t in robot.joint_types
            for k, v in enumerate(DEFAULT_JOINT_SCALES)
        ]
    else:
        s = list(np.tile(dh_scales, robot.n_joints))
    s += list(frame_scales) * (int(base) + int(tool))
    return np.asarray(s, dtype=np.float64)


def sample_poses(key, robot: Robot, shape) -> Float[Array, "*shape n"]:
    """Joint values uniform within ``robot.q_limits``."""
    lo, hi = robot.q_limits[:, 0], robot.q_limits[:, 1]
    u = jax.random.uniform(key, tuple(shape) + (robot.n_joints,), dtype=jnp.float64)
    return lo + u * (hi - lo)


def measure(
    robot: Robot,
    x_true,
    q,
    key,
    *,
    sigma_pos: float = 0.0,
    sigma_rot: float = 0.0,
    base: bool = False,
    tool: bool = False,
) -> Float[Array, "*b 4 4"]:
    """Poses of the true robot ``perturb(robot, x_true)`` at ``q``, with measurement noise."""
    T = fk(perturb(robot, x_true, base=base, tool=tool), q)
    kp, kr = jax.random.split(key)
    dp = sigma_pos * jax.random.normal(kp, T.shape[:-2] + (3,), dtype=jnp.float64)
    dr = sigma_rot * jax.random.normal(kr, T.shape[:-2] + (3,), dtype=jnp.float64)
    R = so3_exp(dr) @ T[..., :3, :3]
    return T.at[..., :3, :3].set(R).at[..., :3, 3].add(dp)


def outlier_count(share: float, n_poses: int) -> int:
    """Poses per robot given a gross error for a ``share`` of ``n_poses``; a share that rounds to
    none is an error, not a study without outliers."""
    n = int(round(share * n_poses))
    if share > 0 and n == 0:
        raise DataError(
            f"outliers: a share of {share:g} of {n_poses} poses rounds to no pose; give at least "
            f"{1 / n_poses:.3g} (one pose) or 0",
            option="outliers",
        )
    return n


def inject_outliers(key, measured: Float[Array, "K 4 4"], n: int, lo_mm: float, hi_mm: float):
    """``n`` of the ``K`` measured poses (chosen at random) moved by a gross position error: a
    random direction, a length uniform in ``[lo_mm, hi_mm]`` (a slipped reflector, a swapped
    marker). **Returns** ``(measured, mask (K,))``, the mask True at the moved poses. Traceable
    (``n`` static)."""
    kp, kd, kl = jax.random.split(key, 3)
    K = measured.shape[0]
    mask = jnp.zeros(K, bool).at[jax.random.permutation(kp, K)[:n]].set(True)
    d = jax.random.normal(kd, (K, 3), dtype=jnp.float64)
    d = d / jnp.linalg.norm(d, axis=-1, keepdims=True) * jax.random.uniform(kl, (K, 1), jnp.float64, lo_mm, hi_mm)
    return measured.at[:, :3, 3].add(jnp.where(mask[:, None], d, 0.0)), mask


QUICK_POSES = 2**16
"""Simulated poses (robots x calibration and inspection poses) up to which the simulation is
compiled quickly (:func:`jaxcal._config.jit`): beyond, its run time outweighs the compile time
saved."""


@jit
def _measure_batch(robot: Robot, x, q, q_val, keys, sigma_pos, sigma_rot, *, base: bool, tool: bool, outliers=None):
    def run(x_, q_, qv, key):
        meas = measure(robot, x_, q_, key, sigma_pos=sigma_pos, sigma_rot=sigma_rot, base=base, tool=tool)
        mask = jnp.zeros(q_.shape[0], bool)
        if outliers is not None:  # a key of its own: the clean draws do not change
            meas, mask = inject_outliers(jax.random.fold_in(key, 1), meas, *outliers)
        return meas, fk(perturb(robot, x_, base=base, tool=tool), qv), mask

    return jax.vmap(run)(x, q, q_val, keys)


@dataclasses.dataclass(frozen=True)
class Simulation:
    """A batch of simulated calibrations (all arrays have a leading robot axis ``R``)."""

    robot: Robot  # nominal model
    x_true: np.ndarray  # (R, m) true parameter errors
    q: np.ndarray  # (R, K, n) calibration poses
    measured: np.ndarray  # (R, K, 4, 4) noisy measured poses
    q_val: np.ndarray  # (R, Kv, n) inspection (validation) poses
    true_val: np.ndarray  # (R, Kv, 4, 4) noise-free true poses at q_val
    sigma_pos: float
    sigma_rot: float
    base: bool
    tool: bool
    seed: int
    outlier_mask: np.ndarray | None = None  # (R, K) the poses given a gross error (simulate(outliers=...))


def simulate(
    robot: Robot,
    *,
    n_robots: int = 1,
    n_poses: int = 50,
    n_val: int = 50,
    seed: int = 0,
    sigma_pos: float = 0.0,
    sigma_rot: float = 0.0,
    base: bool = False,
    tool: bool = False,
    scales=None,
    x_true=None,
    q=None,
    q_val=None,
    outliers: float = 0.0,
    outlier_mm=(3.0, 6.0),
) -> Simulation:
    """Draw ``n_robots`` true robots around ``robot`` and measure ``n_poses`` poses of each.

    **Arguments**: ``scales`` per-parameter std of the true errors (default
    :func:`error_scales`); ``x_true`` fixes the true errors instead, shape ``(m,)`` or
    ``(R, m)``; ``sigma_pos`` (mm) and ``sigma_rot`` (rad) the measurement noise; ``q`` /
    ``q_val`` give the calibration / inspection poses instead of drawing them, shape ``(K, n)``
    (shared by all robots) or ``(R, K, n)`` (then ``n_poses`` / ``n_val`` are ignored);
    ``outliers`` the share of each robot's poses given a gross position error of ``outlier_mm =
    (A, B)`` mm (:func:`inject_outliers`; ``Simulation.outlier_mask`` says which).

    **Raises** :class:`jaxcal.DataError` for bad counts, negative or non-finite noise, wrong
    shapes and non-finite values, naming the argument.
    """
    if not isinstance(robot, Robot):
        raise DataError(f"robot must be a jaxcal.Robot, got {type(robot).__name__}")
    for name, v, lo in (("n_robots", n_robots, 1), ("n_poses", n_poses, 1), ("n_val", n_val, 0), ("seed", seed, 0)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise DataError(f"{name} must be an integer >= {lo}, got {v!r}")
    for name, v in (("sigma_pos", sigma_pos), ("sigma_rot", sigma_rot)):
        if (
            isinstance(v, bool)
            or not isinstance(v, (int, float, np.integer, np.floating))
            or not np.isfinite(v)
            or v < 0
        ):
            raise DataError(f"{name} must be a finite number >= 0, got {v!r}")
    if isinstance(outliers, bool) or not isinstance(outliers, (int, float, np.number)) or not 0 <= outliers <= 1:
        raise DataError(f"outliers must be a share of the poses in [0, 1], got {outliers!r}")
    lo_hi = np.asarray(outlier_mm, float) if np.shape(outlier_mm) == (2,) else np.full(2, np.nan)
    if not 0 <= lo_hi[0] <= lo_hi[1] < np.inf:
        raise DataError(f"outlier_mm must be (A, B) with 0 <= A <= B (mm), got {outlier_mm!r}")
    m = n_params(robot, base=base, tool=tool)
    k_err, k_q, k_noise, k_val = jax.random.split(jax.random.PRNGKey(seed), 4)
    if x_true is None:
        s = error_scales(robot, base=base, tool=tool) if scales is None else np.asarray(scales, float)
        if s.shape != (m,) or not np.all(np.isfinite(s)) or np.any(s < 0):
            raise DataError(f"scales must be {m} finite numbers >= 0, got shape {s.shape}")
        x_true = jax.random.normal(k_err, (n_robots, m), dtype=jnp.float64) * s
    x_true = as_f64(x_true, "x_true")
    if x_true.shape not in ((m,), (n_robots, m)) or not bool(jnp.all(jnp.isfinite(x_true))):
        raise DataError(f"x_true must be finite with shape ({m},) or ({n_robots}, {m}), got {x_true.shape}")
    x_true = jnp.broadcast_to(x_true, (n_robots, m))
    for name, a in (("q", q), ("q_val", q_val)):
        if a is None:
            continue
        a = np.asarray(as_f64(a, name))
        if a.ndim not in (2, 3) or a.shape[-1] != robot.n_joints or (a.ndim == 3 and a.shape[0] != n_robots):
            raise DataError(
                f"{name} must have shape (K, {robot.n_joints}) or ({n_robots}, K, {robot.n_joints}), got {a.shape}"
            )
        if name == "q" and a.shape[-2] < 1:
            raise DataError("q must hold at least one pose")
        if not np.all(np.isfinite(a)):
            raise DataError(
                f"{name}: non-finite value at index {tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])}"
            )
    n = robot.n_joints
    q = (
        sample_poses(k_q, robot, (n_robots, n_poses))
        if q is None
        else jnp.broadcast_to(jnp.asarray(q, jnp.float64), (n_robots,) + np.shape(q)[-2:])
    )
    q_val = (
        sample_poses(k_val, robot, (n_robots, n_val))
        if q_val is None
        else jnp.broadcast_to(jnp.asarray(q_val, jnp.float64), (n_robots,) + np.shape(q_val)[-2:])
    )
    if q.shape[-1] != n or q_val.shape[-1] != n:
        raise DataError(f"q and q_val must have {n} joint columns")
    keys = jax.random.split(k_noise, n_robots)
    n_out = outlier_count(outliers, q.shape[-2])
    meas, true_val, mask = _measure_batch(
        robot.stripped(),
        x_true,
        q,
        q_val,
        keys,
        jnp.float64(sigma_pos),
        jnp.float64(sigma_rot),
        base=base,
        tool=tool,
        outliers=(n_out, float(lo_hi[0]), float(lo_hi[1])) if n_out else None,
        quick=n_robots * (q.shape[-2] + q_val.shape[-2]) <= QUICK_POSES,
    )
    return Simulation(
        robot=robot,
        x_true=np.asarray(x_true),
        q=np.asarray(q),
        measured=np.asarray(meas),
        q_val=np.asarray(q_val),
        true_val=np.asarray(true_val),
        sigma_pos=float(sigma_pos),
        sigma_rot=float(sigma_rot),
        base=base,
        tool=tool,
        seed=seed,
        outlier_mask=np.asarray(mask),
    )
