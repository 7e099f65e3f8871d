"""Process-wide settings :mod:`jaxcal` makes when imported: float64, the persistent compilation
cache, and how its small programs are compiled.

**Precision.** Importing :mod:`jaxcal` switches on ``jax_enable_x64``. Every public entry point
calls :func:`as_f64` on the arrays it receives, which

* raises :class:`jaxcal.PrecisionError` if something switched x64 off again after import
  (then ``jnp.asarray`` would silently truncate float64 to float32), and
* upcasts float32/float16/integer inputs to float64 (documented behaviour: a float32 input
  carries only float32 information, but the calibration itself never runs in float32).

**Compilation cache.** Importing :mod:`jaxcal` also points JAX's persistent compilation cache at
the user's cache folder (:func:`use_compilation_cache`), so a second process does not compile
what a first one did. ``JAXCAL_CACHE=0`` in the environment turns that off; a cache the user set
up (``JAX_COMPILATION_CACHE_DIR``, ``jax.config``) is used as it is. With jaxcal's own cache,
:func:`jit` also keeps the traced programs of the calibration's solver beside it (:mod:`jaxcal._kept`,
:func:`programs_folder`), so a second process does not trace them either.

**Import and exit.** JAX is imported with Python's cyclic garbage collector paused, and the
objects its modules made are then frozen (:func:`gc.freeze`): they live as long as the process,
and each full collection during the import would scan them all again. The objects still alive
when the interpreter exits are frozen too, so that its last collections do not scan them
(``benchmarks/bench_vs_pybotics.py`` times whole processes).

**Quick compiles.** A calibration compiles a few programs and runs each a few times on small
arrays: XLA's optimisations cost seconds and save milliseconds. :func:`jit` compiles such a
program with :data:`QUICK_COMPILE` on CPU, where the caller says its run time is small; the
options apply to that program alone, never to the user's own.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import gc
import os
from pathlib import Path

_collecting = gc.isenabled()
gc.disable()
try:  # JAX's modules: a million objects alive for the whole process, frozen rather than scanned
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    from . import _kept
    from .errors import DataError, PrecisionError
finally:
    gc.freeze()
    if _collecting:
        gc.enable()

jax.config.update("jax_enable_x64", True)

PROGRAMS_FOLDER = "JAXCAL_PROGRAMS"
"""Environment variable: a folder for the traced programs kept across processes
(:func:`programs_folder`)."""
CACHE_SWITCH = "JAXCAL_CACHE"
"""Environment variable: ``0`` (or ``false``, ``no``, ``off``) keeps jaxcal from setting up the
persistent compilation cache."""
MIN_CACHED_COMPILE_S = 0.05
"""Programs that compile faster than this are not written to the cache (JAX's default, 1 s,
would leave out every quick-compiled program)."""
QUICK_COMPILE = {
    "xla_backend_optimization_level": 0,
    "xla_llvm_disable_expensive_passes": True,
    "xla_cpu_use_fusion_emitters": False,
}
"""XLA options for a program whose run time is small next to its compile time: on CPU they
compile the calibration's programs several times faster, and run them a few times slower."""
LOOP_EMITTERS = {"xla_cpu_use_fusion_emitters": False}
"""XLA options for a program run for long (an optimiser's many iterations): XLA CPU's loop
emitters compile it in a fraction of the fusion emitters' time, and it runs about as fast."""


def ensure_x64() -> None:
    """Raise if float64 has been switched off since :mod:`jaxcal` was imported."""
    if not jax.config.jax_enable_x64:
        raise PrecisionError(
            "jax_enable_x64 is off: jaxcal refuses to calibrate in float32. "
            "Do not set JAX_ENABLE_X64=0 or jax.config.update('jax_enable_x64', False) "
            "after importing jaxcal."
        )


def as_f64(x, name: str = "array") -> jax.Array:
    """Return ``x`` as a float64 JAX array (a copy; the caller's array is never touched).

    Raises :class:`DataError` for complex or non-numeric input, :class:`PrecisionError` when
    x64 is disabled. Tracers (inside ``jit``/``vmap``) are passed through after a dtype cast.
    """
    ensure_x64()
    if isinstance(x, jax.core.Tracer):
        return x.astype(jnp.float64)
    try:
        arr = np.asarray(x)
    except ValueError as e:  # nested lists of unequal lengths: say which argument, not numpy's words
        raise DataError(f"{name}: not a rectangular array of numbers (rows of unequal length?): {e}") from None
    if arr.dtype == object or not (
        np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer) or arr.dtype == np.bool_
    ):
        raise DataError(f"{name}: expected real numbers, got dtype {arr.dtype}")
    # jnp.asarray may alias a float64 NumPy buffer on CPU: the caller's later writes would change it
    return jnp.array(arr, dtype=jnp.float64, copy=True)


def cache_folder() -> Path:
    """Where jaxcal keeps compiled programs: ``$XDG_CACHE_HOME/jaxcal/xla`` (default
    ``~/.cache/jaxcal/xla``). Deleting it is safe: programs are compiled again."""
    root = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(root) / "jaxcal" / "xla"


def use_compilation_cache() -> str | None:
    """Keep compiled programs in :func:`cache_folder`, unless ``JAXCAL_CACHE=0`` or the user
    configured JAX's cache (then theirs is used, with their settings); returns the folder in
    use, or None. Every program the process compiles for :data:`MIN_CACHED_COMPILE_S` or more
    is kept, the user's own too (JAX's cache is one per process)."""
    if os.environ.get(CACHE_SWITCH, "1").strip().lower() in ("0", "false", "no", "off"):
        return None
    if jax.config.jax_compilation_cache_dir:
        return jax.config.jax_compilation_cache_dir
    if not jax.config.jax_enable_compilation_cache:
        return None
    path = cache_folder()
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None  # a read-only home: compile every time, as without the cache
    jax.config.update("jax_compilation_cache_dir", str(path))
    if "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_CACHED_COMPILE_S)
    return str(path)


use_compilation_cache()

# At exit the interpreter's last collections scan every object JAX's modules made, a noticeable
# part of a short process; frozen, they are not scanned and their memory goes back with the
# process's (Python does not promise finalisers at exit in any case).
atexit.register(gc.freeze)


def programs_folder() -> str | None:
    """Where traced programs are kept across processes (:mod:`jaxcal._kept`): ``$JAXCAL_PROGRAMS``
    if set, else ``programs`` beside jaxcal's own compilation cache; None when the cache is off
    or the user's own JAX cache is in use (their settings are left as they are)."""
    if os.environ.get(CACHE_SWITCH, "1").strip().lower() in ("0", "false", "no", "off"):
        return None
    if os.environ.get(PROGRAMS_FOLDER):
        return os.environ[PROGRAMS_FOLDER]
    own = str(cache_folder())
    return str(cache_folder().parent / "programs") if jax.config.jax_compilation_cache_dir == own else None


class _Jit:
    """A function jitted twice (:func:`jax.jit` through :func:`equinox.filter_jit`): with XLA's
    default optimisations, and with ``options`` (:data:`QUICK_COMPILE`). ``quick=True`` (the
    default) calls the quick one when JAX's default backend is the CPU. With ``keep`` and the
    persistent cache on, a call goes through the traced program kept for its arguments
    (:mod:`._kept`)."""

    def __init__(self, fn, options, keep):
        functools.update_wrapper(self, fn)
        self.full = eqx.filter_jit(fn)
        self.quick = eqx.filter_jit(fn, compiler_options=options)
        name = f"{fn.__module__}.{fn.__qualname__}"
        self.kept = {True: _kept.Store(fn, name, options), False: _kept.Store(fn, name, {})} if keep else None

    def __call__(self, *args, quick: bool = True, **kwargs):
        fast = quick and jax.default_backend() == "cpu"
        with gc_paused():
            folder = programs_folder() if self.kept else None
            if folder is not None:
                out = self.kept[fast].call(folder, args, kwargs)
                if out is not _kept.MISSING:
                    return out
            return (self.quick if fast else self.full)(*args, **kwargs)

    def prepare(self, *args, quick: bool = True, **kwargs) -> bool:
        """Load or trace now the kept program that a call with arguments of these shapes and
        static values (their values do not matter) will run, and start its compile in a
        background thread (:meth:`jaxcal._kept.Store.prepare`). False where nothing was started:
        not a kept function, the cache off, or the program already there."""
        folder = programs_folder() if self.kept else None
        if folder is None:
            return False
        return self.kept[quick and jax.default_backend() == "cpu"].prepare(folder, args, kwargs)


@contextlib.contextmanager
def gc_paused():
    """Python's cyclic garbage collector off for the block: tracing and compiling create many
    objects, and each full collection would scan every object of JAX's modules again. Cycles
    made meanwhile are collected after it."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def jit(fn=None, *, options: dict = QUICK_COMPILE, keep: bool = False):
    """``equinox.filter_jit(fn)``, compiled quickly on CPU (XLA ``options``) unless called with
    ``quick=False`` (for a call whose run time matters more than its compile time). As
    ``@jit`` or ``@jit(options=LOOP_EMITTERS)``. ``keep``: its traced programs are kept across
    processes (:mod:`._kept`), for a program whose tracing and lowering cost more than its
    compile (exporting costs a little more the first time)."""
    if fn is None:
        return functools.partial(jit, options=options, keep=keep)
    return _Jit(fn, options, keep)
