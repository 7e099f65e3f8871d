"""Spreading many independent fits over devices: which devices, a one-axis mesh over them, and
moving a batch onto it and back.

A batch of members (robots, data sets) is split along its leading axis over a
:class:`jax.sharding.Mesh` with one axis, ``"members"``; a compiled solve given arrays sharded
this way runs each device's share on that device (XLA's SPMD partitioner), and its results come
back to NumPy on every process. One host with several devices (GPUs, or CPU devices made with
``XLA_FLAGS=--xla_force_host_platform_device_count=N``) and several hosts joined by
:func:`jax.distributed.initialize` work the same way: ``jax.devices()`` then lists every host's
devices, each process holds the whole (seeded, identical) batch in NumPy and contributes the
shares of its own devices. ``docs/scale-out.md`` shows how to launch it.
"""

from __future__ import annotations

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .errors import DataError

AXIS = "members"
"""Name of the mesh axis the members are split along."""


def select_devices(spec: str | int | None = "all") -> tuple[jax.Device, ...]:
    """The devices to use: ``"all"`` (every device of every process), ``N`` (the first ``N``;
    an integer or its text), ``None`` (the default device alone, nothing sharded), or the
    devices themselves.

    **Raises** :class:`jaxcal.DataError` naming ``devices`` for a count that is not a positive
    integer or is more than there are.
    """
    if spec is None:
        return (jax.local_devices()[0],)
    if isinstance(spec, (list, tuple)) and spec and all(isinstance(d, jax.Device) for d in spec):
        return tuple(spec)  # already chosen
    every = jax.devices()
    if isinstance(spec, str) and spec.strip().lower() == "all":
        return tuple(every)
    try:
        n = int(spec) if not isinstance(spec, (bool, float)) else None
    except (TypeError, ValueError):
        n = None
    if n is None or n < 1:
        raise DataError(f"devices must be 'all' or a positive integer, got {spec!r}", option="devices")
    if n > len(every):
        raise DataError(
            f"devices: {n} requested, but {len(every)} {every[0].platform} device"
            f"{'s are' if len(every) > 1 else ' is'} available (on CPU, set "
            f"XLA_FLAGS=--xla_force_host_platform_device_count=N before starting Python)",
            option="devices",
        )
    if jax.process_count() > 1 and n % jax.process_count():
        raise DataError(f"devices: {n} is not a multiple of the {jax.process_count()} processes", option="devices")
    # a subset over several processes takes the same number from each, so every process computes
    per = n // jax.process_count()
    return tuple(d for p in range(jax.process_count()) for d in [e for e in every if e.process_index == p][:per])


def describe(devices) -> list[str]:
    """One line per device for a report: ``"cpu:0 (process 0)"``."""
    return [f"{d.platform}:{d.id} (process {d.process_index})" for d in devices]


def member_mesh(devices) -> Mesh:
    """A one-axis mesh, :data:`AXIS`, over ``devices``."""
    return Mesh(np.asarray(devices, dtype=object), (AXIS,))


def sharded(mesh: Mesh) -> bool:
    """Whether arrays must be placed on ``mesh`` (several devices, or another process's)."""
    return mesh.size > 1 or jax.process_count() > 1


def distribute(tree, mesh: Mesh, *, split: bool = True):
    """NumPy arrays (the same on every process) as global arrays on ``mesh``: split along their
    leading axis (its length a multiple of ``mesh.size``), or with ``split=False`` whole on
    every device. Each process builds only its own devices' shares."""
    spec = PartitionSpec(AXIS) if split else PartitionSpec()
    sharding = NamedSharding(mesh, spec)

    def put(a):
        a = np.asarray(a)
        return jax.make_array_from_callback(a.shape, sharding, lambda idx: a[idx])

    return jax.tree.map(put, tree)


def assemble(parts, mesh: Mesh):
    """Global arrays on ``mesh`` split along their leading axis, from ``parts``: one pytree per
    device of this process (each leaf on its device, the device's consecutive share), in any
    order. What :func:`gather` takes back to NumPy where each device solved its own share."""
    sharding = NamedSharding(mesh, PartitionSpec(AXIS))

    def join(*leaves):
        shape = (leaves[0].shape[0] * mesh.size,) + tuple(leaves[0].shape[1:])
        return jax.make_array_from_single_device_arrays(shape, sharding, list(leaves))

    return jax.tree.map(join, *parts)


def gather(tree):
    """Global arrays back to NumPy, whole, on every process."""
    from jax.experimental import multihost_utils

    def get(a):
        if getattr(a, "is_fully_addressable", True):
            return np.asarray(a)
        return np.asarray(multihost_utils.process_allgather(a, tiled=True))

    return jax.tree.map(get, tree)
