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
in 0.17-0.21 ms with 95-127 minor page faults and 155-185 us of system time per call, against
0.069-0.073 ms and none in the same process at other times, and none with this setting
(2026-11-23, getrusage per call; which calls fault depends on the heap's history)."""


def kernel_source(spec: str, tmp: str, root: str) -> str:
    """The ``chain.cc`` of a kernel version: a file path as is, or a git revision of the checkout
    at ``root``, whose ``jaxcal/_native/`` sources (``chain.cc`` and the headers it includes since
    2026-11-23) are written to a folder of their own under ``tmp``."""
    import subprocess
    if os.path.isfile(spec):
        return os.path.abspath(spec)
    ls = subprocess.run(["git", "-C", root, "ls-tree", "--name-only", spec, "jaxcal/_native/"], capture_output=True,
                        text=True)
    names = [n for n in ls.stdout.split() if n.endswith((".cc", ".h"))]
    if ls.returncode or "jaxcal/_native/chain.cc" not in names:
        raise SystemExit(f"{spec!r} is neither a file nor a git revision with jaxcal/_native/chain.cc "
                         f"({ls.stderr.strip()[:200]})")
    folder = os.path.join(tmp, spec.replace("/", "_"))
    os.makedirs(folder, exist_ok=True)
    for name in names:
        text = subprocess.run(["git", "-C", root, "show", f"{spec}:{name}"], capture_output=True, text=True,
                              check=True).stdout
        with open(os.path.join(folder, os.path.basename(name)), "w") as f:
            f.write(text)
    return os.path.join(folder, "chain.cc")


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


def compile_text(first: float, runs) -> str:
    """Compile time read off a first call: the first call minus the warm median. When the runs
    spread more than that difference, it is below the timing noise and says so (a negative
    "compile" was printed until 2026-11-24)."""
    med = statistics.median(runs)
    c = first - med
    if c <= max(runs) - min(runs):
        return f"first call {first:5.2f} s (compile below the runs' spread, {max(runs) - min(runs):.2f} s)"
    return f"compile {c:5.2f} s"


def summary(runs) -> str:
    return f"median {statistics.median(runs) * 1e3:9.3f} ms  (min {min(runs) * 1e3:.3f}, max {max(runs) * 1e3:.3f})"
