"""Pose designs for the elimination method (paper section 2.3, eq. 11).

A design for an ``N``-joint arm is one ``(K, N)`` array of joint values laid out as

* for each step ``n = N, N-1, ..., 2`` (the joint being calibrated), ``n_pairs`` pairs of poses,
  rows ``(2j, 2j + 1)`` of the step's block: both poses share joints ``1..n-2`` and draw joints
  ``n-1..N`` independently (``vary_later=True``) or only joints ``n-1, n`` (the later ones shared);
* then ``n_abs`` unconstrained ("absolute") poses, used for joint 1's ``theta`` and ``d``.

``K = 2 (N - 1) n_pairs + n_abs``. Every pose lies within ``robot.q_limits``. Any pose array
with this structure can be measured with :func:`jaxcal.simulate.simulate` (``q=``) and solved by
the elimination solver (:mod:`jaxcal.solvers`); :func:`infer_layout` recovers the layout from the array.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..errors import DataError
from ..robot import Robot


@dataclasses.dataclass(frozen=True)
class PairLayout:
    """Where each step's pairs sit in a design (hashable: usable as a static jit argument)."""

    n_joints: int
    """``N``: number of joints."""
    n_pairs: int
    """Pairs per step."""
    n_abs: int
    """Absolute poses at the end."""

    @property
    def steps(self) -> tuple[int, ...]:
        """Joint numbers (1-based) calibrated by the differencing steps, in solve order."""
        return tuple(range(self.n_joints, 1, -1))

    @property
    def n_poses(self) -> int:
        return 2 * (self.n_joints - 1) * self.n_pairs + self.n_abs

    def rows(self, n: int) -> tuple[int, int]:
        """``[start, stop)`` rows of step ``n``'s block (``2 n_pairs`` rows, pairs interleaved)."""
        s = (self.n_joints - n) * 2 * self.n_pairs
        return s, s + 2 * self.n_pairs

    def abs_rows(self) -> tuple[int, int]:
        return self.n_poses - self.n_abs, self.n_poses


def design_poses(
    key, robot: Robot, *, n_pairs: int = 4, n_abs: int = 2, vary_later: bool = True, batch_shape=()
) -> Float[Array, "*batch K n"]:
    """Draw an elimination design (uniform within ``robot.q_limits``), seeded by ``key``.

    **Arguments**: ``n_pairs`` pairs per step; ``n_abs`` absolute poses; ``vary_later``: the
    two poses of a step-``n`` pair also differ in joints ``n+1..N`` (default; better
    conditioned) or share them; ``batch_shape`` e.g. ``(R,)`` for one design per robot.

    **Returns** ``(*batch_shape, 2 (N-1) n_pairs + n_abs, N)`` joint values.
    """
    N = robot.n_joints
    if N < 2:
        raise DataError("the elimination method needs at least 2 joints")
    if n_pairs < 1 or n_abs < 0:
        raise DataError(f"need n_pairs >= 1 and n_abs >= 0, got {n_pairs}, {n_abs}")
    lo, hi = robot.q_limits[:, 0], robot.q_limits[:, 1]
    batch_shape = tuple(batch_shape)
    keys = jax.random.split(key, N + 1)
    blocks = []
    for s, n in enumerate(range(N, 1, -1)):
        u = jax.random.uniform(keys[s], batch_shape + (n_pairs, 2, N), dtype=jnp.float64)
        q = lo + u * (hi - lo)
        first = jnp.arange(N) < (n - 2) if vary_later else (jnp.arange(N) < n - 2) | (jnp.arange(N) >= n)
        q = jnp.where(first, q[..., :1, :], q)  # shared joints copied from the pair's first pose
        blocks.append(q.reshape(batch_shape + (2 * n_pairs, N)))
    u = jax.random.uniform(keys[N], batch_shape + (n_abs, N), dtype=jnp.float64)
    blocks.append(lo + u * (hi - lo))
    return jnp.concatenate(blocks, -2)


def check_design(q, layout: PairLayout) -> None:
    """Raise :class:`DataError` unless ``q`` ``(..., K, N)`` has ``layout``'s pair structure: the
    two poses of a step-``n`` pair are equal in joints ``1..n-2`` and differ in joints ``n-1``
    and ``n``."""
    q = np.asarray(q)
    N = layout.n_joints
    if q.ndim < 2 or q.shape[-2:] != (layout.n_poses, N):
        raise DataError(f"design must have shape (..., {layout.n_poses}, {N}), got {q.shape}")
    for n in layout.steps:
        r0, r1 = layout.rows(n)
        a, b = q[..., r0:r1:2, :], q[..., r0 + 1 : r1 : 2, :]
        if not np.array_equal(a[..., : n - 2], b[..., : n - 2]):
            raise DataError(f"step {n}: the poses of a pair must share joints 1..{n - 2} exactly")
        if np.any(a[..., n - 2] == b[..., n - 2]) or np.any(a[..., n - 1] == b[..., n - 1]):
            raise DataError(f"step {n}: the poses of a pair must differ in joints {n - 1} and {n}")


def infer_layout(q, n_joints: int) -> PairLayout:
    """The layout of a design ``q`` ``(..., K, N)`` (all members checked): the largest ``n_pairs`` whose structure
    :func:`check_design` accepts. Raises :class:`DataError` if none does."""
    q = np.asarray(q)
    K = q.shape[-2]
    for p in range(K // (2 * (n_joints - 1)), 0, -1):
        lay = PairLayout(n_joints, p, K - 2 * (n_joints - 1) * p)
        try:
            check_design(q, lay)
            return lay
        except DataError:
            continue
    raise DataError(
        "q is not an elimination design (pairs sharing joints 1..n-2, per step n = N..2, "
        "then absolute poses): draw one with jaxcal.solvers.design_poses"
    )
