"""Shared benchmark helpers: timing with medians, machine description."""

from __future__ import annotations

import os
import platform
import statistics
import time

import jax

HUGETLB = "GLIBC_TUNABLES=glibc.malloc.hugetlb=1"
"""glibc (2.35+) then asks Linux for 2 MiB pages behind the large blocks it maps for malloc, so
XLA's fresh buffers fault in 512x fewer times (read at process start: a fresh process each)."""

KEEP_HEAP = ("GLIBC_TUNABLES=glibc.malloc.trim_threshold=536870912:glibc.malloc.mmap_threshold=33554432:"
             "glibc.malloc.top_pad=67108864")
"""glibc keeps freed memory (up to 512 MB) in the process and maps nothing below 32 MB apart. By
default it returns the top of its heap to Linux when enough is free, and XLA's next output buffer
of that size is faulted in again page by page: FK on 10^4 poses per call (1.3 MB out) then ran
in 0.12-0.16 ms with 36-70 minor page faults and 70-110 us of system time per call, against
0.067-0.075 ms and none with this setting (2026-11-23, getrusage per call; which calls fault
depends on the heap's history, so a long process drifts between the two)."""

SYNC = "jax_cpu_enable_async_dispatch=False"
"""JAX runs a computation in the calling thread instead of handing it to a worker thread (a JAX
config update; no environment variable reads it). After large computations in the same process,
each FK call of 10^4 poses here took 2 context switches and 25-45 us of system time, 0.16 ms
instead of 0.07 (getrusage per call, 2026-11-23); with this setting it did not."""


def cpu_model() -> str:
    """Model name, family/model and the vector ISA from /proc/cpuinfo: the same VM image has run
    on Zen 5 (AVX-512) and Zen 3 (AVX2) hosts here, with 2-5x different kernel speeds."""
    try:
        info = {}
        for line in open("/proc/cpuinfo"):
            k, _, v = line.partition(":")
            info.setdefault(k.strip(), v.strip())
    except OSError:
        return platform.processor() or platform.machine()
    flags = info.get("flags", "").split()
    isa = next((x for x in ("avx512f", "avx2", "avx", "sse4_2") if x in flags), "?")
    return f"{info.get('model name', '?')} (family {info.get('cpu family', '?')} model {info.get('model', '?')}, {isa})"


def machine() -> dict:
    dev = jax.devices()[0]
    return {"platform": dev.platform, "device": str(getattr(dev, "device_kind", dev)),
            "cpu": cpu_model(), "cores": os.cpu_count(),
            "python": platform.python_version(), "jax": jax.__version__,
            "xla_flags": os.environ.get("XLA_FLAGS", "")}


def block(x):
    return jax.tree.map(lambda a: a.block_until_ready() if hasattr(a, "block_until_ready") else a, x)


def timed(fn, *args, repeats=7):
    """(compile+first-run seconds, list of warm run seconds)."""
    t0 = time.perf_counter()
    block(fn(*args))
    first = time.perf_counter() - t0
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        block(fn(*args))
        runs.append(time.perf_counter() - t0)
    return first, runs


def summary(runs) -> str:
    return f"median {statistics.median(runs) * 1e3:9.3f} ms  (min {min(runs) * 1e3:.3f}, max {max(runs) * 1e3:.3f})"
