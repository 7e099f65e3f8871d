"""The one timing helper of experiments and benchmarks: medians over repeated calls, compile
time apart, and the machine they ran on."""

from __future__ import annotations

import os
import platform
import statistics
import time

import jax


def machine_info() -> dict:
    """The device, CPU, core count and versions a measurement ran on."""
    dev = jax.devices()[0]
    return {
        "platform": dev.platform,
        "device": str(getattr(dev, "device_kind", dev.platform)),
        "devices": jax.device_count(),
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
    }


def cpu_model() -> str:
    """Model name, family/model and vector ISA from /proc/cpuinfo (hosts of the same name differ)."""
    try:
        info = {}
        with open("/proc/cpuinfo") as f:
            for line in f:
                k, _, v = line.partition(":")
                info.setdefault(k.strip(), v.strip())
    except OSError:
        return platform.processor() or platform.machine()
    flags = info.get("flags", "").split()
    isa = next((x for x in ("avx512f", "avx2", "avx", "sse4_2") if x in flags), "?")
    return f"{info.get('model name', '?')} (family {info.get('cpu family', '?')} model {info.get('model', '?')}, {isa})"


def timed(fn, repeats: int = 5):
    """``(result, first_call_seconds, [seconds of each further call])``: the first call includes
    compilation; the others are run time only (``jax.block_until_ready`` on every result)."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    first = time.perf_counter() - t0
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        runs.append(time.perf_counter() - t0)
    return out, first, runs


def summary(runs) -> str:
    """``median x ms (min a, max b)``."""
    return f"median {1e3 * statistics.median(runs):9.3f} ms  (min {1e3 * min(runs):.3f}, max {1e3 * max(runs):.3f})"
