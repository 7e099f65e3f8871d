"""Fused CPU kernels for forward kinematics and the identification Jacobian (``chain.cc``),
called from JAX through the XLA FFI (``jax.ffi.ffi_call``).

On first use the kernel is compiled with the system C++ compiler (``$CXX`` or ``c++``,
``-O3 -march=native``, 512-bit vectors where the CPU has them, ``-fopenmp`` when the compiler
takes it, for the ``omp simd`` hints: the kernel's threads are its own, see ``chain.cc``) against
the FFI headers shipped in jaxlib, and cached in ``$XDG_CACHE_HOME/jaxcal`` (default
``~/.cache/jaxcal``), keyed by the sources (``chain.cc`` and the headers beside it), the flags, the jax version and the CPU. That takes 3–4 s once per machine.
``JAXCAL_NATIVE_FLAGS`` in the environment appends compiler flags (e.g. ``-mno-avx512f``, which the
tests use to check the kernel's paths for CPUs without AVX-512); ``JAXCAL_NATIVE_THREADS=N``
caps the threads a call uses (default: one per core), read when the kernel first runs. When it cannot be
built (no compiler, no headers), when the default JAX backend is not the CPU, or with
``JAXCAL_NATIVE=0`` in the environment, jaxcal uses its pure-JAX implementation
(:func:`jaxcal.kinematics._fk_xla`, :func:`jaxcal.error_model._columns_xla`), which is also
the reference the tests hold the kernels to. :func:`status` (``jaxcal.native_status()``) says
which is in use and why.

Both kernels are wrapped in a ``jax.custom_jvp`` whose tangent comes from the pure-JAX
implementation, so ``jax.jvp``/``jacfwd``/``grad`` work as before; ``vmap`` batches the call
(``vmap_method="broadcast_all"``: the kernel loops over robots and poses itself).
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
from pathlib import Path

import jax
import jax.numpy as jnp

SOURCE = _SHIPPED = Path(__file__).with_name("chain.cc")
MAX_JOINTS = 16
"""Longest chain the kernel takes (``MAXN`` in ``chain.cc``); longer ones use pure JAX."""
_FLAGS = ["-O3", "-march=native", "-std=c++17", "-shared", "-fPIC", "-fno-math-errno", "-w"]
if platform.machine().lower() in ("x86_64", "amd64"):
    # GCC tunes most AVX-512 CPUs to 256-bit vectors (-march=native on an Intel Xeon here meant
    # -mprefer-vector-width=256); with 512 the kernel ran FK 1.24x and the Jacobian 1.09x faster
    # at 10^4 poses per call on that host (docs/bench/kernel_ab.txt). No effect without AVX-512; GCC knows the flag on x86 only.
    _FLAGS.append("-mprefer-vector-width=512")
_state: dict = {}


def _cpu_id() -> str:
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
        return "".join(line for line in lines if line.startswith(("model name", "flags")))[:4000]
    except OSError:
        return platform.processor() or platform.machine()


def _cache_dir() -> Path:
    root = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "jaxcal"
    try:
        root.mkdir(parents=True, exist_ok=True)
        return root
    except OSError:
        return Path(tempfile.gettempdir())


def _build() -> Path:
    cxx = os.environ.get("CXX") or shutil.which("c++") or shutil.which("g++") or shutil.which("clang++")
    if not cxx:
        raise RuntimeError("no C++ compiler found (set CXX)")
    include = jax.ffi.include_dir()
    flags = _FLAGS + os.environ.get("JAXCAL_NATIVE_FLAGS", "").split()
    headers = b"".join(h.read_bytes() for h in sorted(SOURCE.parent.glob("*.h")))  # lanes.h, pool.h, stores.h
    key = hashlib.sha256(SOURCE.read_bytes() + headers + repr((flags, cxx, jax.__version__, _cpu_id())).encode()).hexdigest()
    lib = _cache_dir() / f"jaxcal-chain-{key[:20]}.so"
    if lib.exists():
        return lib
    errors = []
    for extra in (["-fopenmp"], []):  # omp simd hints (and older sources' loops, bench_kernel_ab.py); macOS clang lacks it
        tmp = lib.with_suffix(f".{os.getpid()}.tmp")
        cmd = [cxx, *flags, *extra, f"-I{include}", str(SOURCE), "-o", str(tmp)]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode == 0:
            os.replace(tmp, lib)  # atomic: concurrent builds (pytest -n) do not see half a file
            return lib
        tmp.unlink(missing_ok=True)
        last = (proc.stderr.strip().splitlines() or [f"exit status {proc.returncode}"])[-1]
        errors.append(f"{' '.join(extra) or 'without OpenMP'}: {last[:300]}")
    raise RuntimeError(f"compiling the native kernel with {cxx} failed ({'; '.join(errors)})")


def _load() -> None:
    if os.environ.get("JAXCAL_NATIVE", "1") == "0":
        _state.update(ok=False, reason="disabled by JAXCAL_NATIVE=0")
        return
    try:
        path = _build()
        lib = ctypes.cdll.LoadLibrary(str(path))
        jax.ffi.register_ffi_target("jaxcal_fk", jax.ffi.pycapsule(lib.JaxcalFk), platform="cpu")
        jax.ffi.register_ffi_target("jaxcal_jac", jax.ffi.pycapsule(lib.JaxcalJac), platform="cpu")
        if SOURCE == _SHIPPED or hasattr(lib, "JaxcalFkPoseLast"):  # older sources (bench_kernel_ab.py) lack it
            jax.ffi.register_ffi_target("jaxcal_fk_pose_last", jax.ffi.pycapsule(lib.JaxcalFkPoseLast), platform="cpu")
        _state.update(ok=True, reason=f"compiled kernel {path}")
    except Exception as e:  # any failure: fall back to pure JAX, say why in status()
        _state.update(ok=False, reason=f"native kernel unavailable: {e}")


def status() -> tuple[bool, str]:
    """``(in_use, reason)``: whether FK and the Jacobian run the native kernel, and why (not).
    Public as ``jaxcal.native_status()``; the first call builds or loads the kernel."""
    if not _state:
        _load()
    if _state["ok"] and jax.default_backend() != "cpu":
        return False, f"default JAX backend is {jax.default_backend()!r}, the kernel is CPU-only"
    return _state["ok"], _state["reason"]


def available() -> bool:
    """Whether the native kernel is built, loaded and the default backend is the CPU (checked
    when a function is traced; jit-compiled functions keep the path they were traced with)."""
    return status()[0]


def usable(robot) -> bool:
    """:func:`available` and the robot's chain is short enough for the kernel."""
    return robot.n_joints <= MAX_JOINTS and available()


def _robot_buffers(robot):
    return (robot.dh, robot.revolute_mask, robot.base, robot.tool)


def fk_call(robot, q2):
    """End poses ``(K, 4, 4)`` for ``q2 (K, n)`` (no JVP rule; see :func:`jaxcal.kinematics._fk`)."""
    call = jax.ffi.ffi_call("jaxcal_fk", jax.ShapeDtypeStruct((q2.shape[0], 4, 4), jnp.float64),
                            vmap_method="broadcast_all")
    return call(q2, *_robot_buffers(robot), mdh=int(robot.convention == "mdh"))


def fk_pose_last_call(robot, qT2):
    """End poses ``(4, 4, K)`` for ``qT2 (n, K)``, the pose axis last (no JVP rule; see
    :func:`jaxcal.kinematics.fk_pose_last`)."""
    call = jax.ffi.ffi_call("jaxcal_fk_pose_last", jax.ShapeDtypeStruct((4, 4, qT2.shape[1]), jnp.float64),
                            vmap_method="broadcast_all")
    return call(qT2, *_robot_buffers(robot), mdh=int(robot.convention == "mdh"))


def jac_call(robot, q2, rows: int):
    """``(J (K, rows, 4n), T (K, 4, 4))``: the DH columns of the identification Jacobian (pose
    rows) and the end poses for ``q2 (K, n)``."""
    K, n = q2.shape
    out = (jax.ShapeDtypeStruct((K, rows, 4 * n), jnp.float64), jax.ShapeDtypeStruct((K, 4, 4), jnp.float64))
    call = jax.ffi.ffi_call("jaxcal_jac", out, vmap_method="broadcast_all")
    return call(q2, *_robot_buffers(robot), mdh=int(robot.convention == "mdh"), rows=rows)
