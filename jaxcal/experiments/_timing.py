"""Describe the machine a measurement ran on (recorded with every timing)."""

from __future__ import annotations

import os
import platform

import jax


def machine_info() -> dict:
    dev = jax.devices()[0]
    return {"platform": dev.platform, "device": str(getattr(dev, "device_kind", dev.platform)),
            "cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
            "python": platform.python_version(), "jax": jax.__version__,
            "xla_flags": os.environ.get("XLA_FLAGS", "")}
