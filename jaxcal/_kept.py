"""Traced programs kept across processes (:mod:`jax.export`), next to the compilation cache.

JAX's persistent cache keeps compiled executables, but finds them by the lowered program, so a
new process still traces and lowers each of jaxcal's programs before it can load one: for the
calibration's solver that costs more than the cached compile saves. This store keeps the
lowered program itself (``jax.export`` serialisation), found by a key made of everything that
decides it: the function, the compile options, the static part of the arguments (by value), the
shapes and dtypes of the arrays, the source of the installed jaxcal, the versions of the
libraries that trace it and the JAX settings that change lowering. A new process then loads it
and only looks the executable up. :meth:`Store.prepare` does that before the call, from stand-in
arguments of the right shapes, and starts the compile in a background thread, which runs while
the caller computes what the program will be called with.

Used by :func:`jaxcal._config.jit` when the persistent cache is on; any case it cannot serve
(traced arguments, arrays spread over several devices, static arguments known only by their
address, a damaged file, a program ``jax.export`` does not take) runs the ordinary ``jit`` path
instead. Files are written atomically.
"""

from __future__ import annotations

import concurrent.futures
import hashlib
import importlib.metadata
import os
import pickle
from pathlib import Path

import equinox as eqx
import jax
import numpy as np

from ._io import write_atomic

MISSING = object()
"""Returned by :func:`call` when the store cannot serve the call (the caller runs ``jit``)."""

_LIBRARIES = ("jax", "jaxlib", "equinox", "optimistix", "lineax", "numpy")
_CONFIG = ("jax_enable_x64", "jax_default_matmul_precision", "jax_numpy_dtype_promotion")
_environment: bytes | None = None
_pool: concurrent.futures.ThreadPoolExecutor | None = None
_forks = 0
_usable: bool | None = None


def _environment_key() -> bytes | None:
    """The source of the installed jaxcal, the libraries' versions and the JAX settings that
    change what a trace produces: computed once per process; None (nothing kept) where the
    source cannot be read."""
    global _environment
    if _environment is None:
        h = hashlib.sha256()
        root = Path(__file__).resolve().parent
        try:
            for path in sorted(root.rglob("*.py")):
                h.update(str(path.relative_to(root)).encode())
                h.update(path.read_bytes())
        except OSError:
            _environment = b""
            return None
        for lib in _LIBRARIES:
            try:
                h.update(f"{lib}={importlib.metadata.version(lib)}".encode())
            except importlib.metadata.PackageNotFoundError:
                h.update(f"{lib}=none".encode())
        for name in _CONFIG:
            h.update(f"{name}={getattr(jax.config, name, None)}".encode())
        h.update(jax.default_backend().encode())
        _environment = h.digest()
    return _environment or None


def _serialisable() -> bool:
    """Whether ``jax.export`` can serialise here (it needs the ``flatbuffers`` package)."""
    global _usable
    if _usable is None:
        try:
            import flatbuffers  # noqa: F401  (jax.export's serialisation needs it)

            _usable = True
        except ImportError:
            _usable = False
    return _usable


class _Slot:
    """Where output array ``i`` goes in a kept program's output structure (its skeleton)."""

    def __init__(self, i: int):
        self.i = i


def _is_slot(x) -> bool:
    return isinstance(x, _Slot)


def _spec(x) -> jax.ShapeDtypeStruct:
    """Shape, dtype and weak type (which changes type promotion in the trace) of an argument."""
    return jax.ShapeDtypeStruct(
        np.shape(x),
        np.asarray(x).dtype if not hasattr(x, "dtype") else x.dtype,
        weak_type=bool(getattr(x, "weak_type", False)),
    )


def _single_device(leaf) -> bool:
    return not isinstance(leaf, jax.Array) or len(leaf.sharding.device_set) == 1


def _compiler() -> concurrent.futures.ThreadPoolExecutor:
    """The threads XLA compiles prepared programs in (the compile releases Python's lock), made on
    first use. Their threads are joined at exit: a process that ends meanwhile waits for a
    compile rather than stop it halfway."""
    global _pool
    if _pool is None:
        _pool = concurrent.futures.ThreadPoolExecutor(max_workers=2, thread_name_prefix="jaxcal-compile")
    return _pool


def _forget_pool() -> None:
    """In a forked child the pool's threads are gone: it makes its own on first use, and does not
    wait for the compiles the parent had under way."""
    global _pool, _forks
    _pool = None
    _forks += 1


os.register_at_fork(after_in_child=_forget_pool)


class Store:
    """The programs of one jitted function (``name``) compiled with ``options``: loaded or
    exported once per argument structure in a process, then called directly."""

    def __init__(self, fn, name: str, options: dict):
        self.fn, self.name, self.options = fn, name, options
        self.loaded: dict[str, tuple | None] = {}
        self.keys: dict[tuple, str] = {}
        self.pending: dict[str, tuple[int, concurrent.futures.Future]] = {}

    def call(self, folder: str, args, kwargs):
        """``fn(*args, **kwargs)`` through a kept program, or :data:`MISSING`."""
        found = self._find(args, kwargs)
        if found is None:
            return MISSING
        key, static, treedef, leaves = found
        if key in self.pending:  # prepared in the background: wait for it rather than trace again
            forks, compiled = self.pending.pop(key)
            try:
                if forks == _forks:  # (not a compile a parent process had under way)
                    self.loaded[key] = compiled.result()
            except Exception:  # traced afresh below
                pass
        if key not in self.loaded:  # a program export does not take is remembered as None
            self.loaded[key] = self._entry(folder, key, static, treedef, leaves)
        if self.loaded[key] is None:
            return MISSING
        run, skeleton = self.loaded[key]
        out = run(*leaves)
        return jax.tree.map(lambda s: out[s.i] if isinstance(s, _Slot) else s, skeleton, is_leaf=_is_slot)

    def prepare(self, folder: str, args, kwargs) -> bool:
        """Load or trace the program a later :meth:`call` with arguments of these shapes and
        static values will run, and start its compile in a background thread: the compile
        releases Python's lock, so it overlaps the caller's own work (tracing, which holds the
        lock, stays in the caller's thread). False when there is nothing to do."""
        found = self._find(args, kwargs)
        if found is None or found[0] in self.loaded or found[0] in self.pending:
            return False
        key, static, treedef, leaves = found
        entry = self._entry(folder, key, static, treedef, leaves)
        try:
            lowered = entry[0].lower(*map(_spec, leaves)) if entry is not None else None
        except Exception:  # the call itself will compile it (and say what is wrong)
            lowered = None
        self.pending[key] = (_forks, _compiler().submit(self._compiled, entry, lowered))
        return True

    @staticmethod
    def _compiled(entry, lowered):
        if lowered is not None:
            try:  # jit keeps what it compiles ahead of time for the same arguments
                lowered.compile()
            except Exception:  # the call itself will compile it (and say what is wrong)
                pass
        return entry

    def _entry(self, folder: str, key: str, static, treedef, leaves):
        return self._load(folder, key) or self._export(folder, key, static, treedef, leaves)

    def _find(self, args, kwargs):
        """``(key, static part, array structure, arrays)`` of a call, or None when no kept
        program can serve it."""
        if not _serialisable() or _environment_key() is None:
            return None
        dynamic, static = eqx.partition((args, kwargs), eqx.is_array)
        leaves, treedef = jax.tree.flatten(dynamic)
        if any(isinstance(x, jax.core.Tracer) or not _single_device(x) for x in leaves):
            return None
        fixed, fixed_def = jax.tree.flatten(static)
        specs = tuple(_spec(x) for x in leaves)
        try:  # a repeated call finds its key without printing its arguments again
            memo = (fixed_def, tuple((type(v), v) for v in fixed), treedef, specs)  # 1 is not 1.0
            key = self.keys.get(memo)
        except TypeError:  # an unhashable static value
            memo, key = None, None
        if key is None:
            key = self._key(fixed, fixed_def, treedef, specs)
            if key is None:
                return None
            if memo is not None:
                self.keys[memo] = key
        return key, static, treedef, leaves

    def _key(self, fixed, fixed_def, treedef, specs) -> str | None:
        # by value (a pickle would differ with which equal objects happen to be shared); an
        # object printed by its address has no stable key
        spec = f"{self.name}|{sorted(self.options.items())}|{fixed_def}|{fixed!r}|{treedef}|{specs}"
        if " at 0x" in spec:
            return None
        return f"{self.name}-{hashlib.sha256(_environment_key() + spec.encode()).hexdigest()[:40]}"

    def _runner(self, exported):
        def run(*xs):
            return exported.call(*xs)

        run.__name__ = run.__qualname__ = self.fn.__name__  # the program keeps the function's name
        return jax.jit(run, compiler_options=self.options or None)

    def _load(self, folder: str, key: str):
        path = Path(folder) / f"{key}.jaxcal"
        if not path.is_file():
            return None
        try:
            blob, skeleton = pickle.loads(path.read_bytes())
            return self._runner(jax.export.deserialize(bytearray(blob))), skeleton
        except Exception:  # damaged or from an incompatible version: trace afresh and replace it
            return None

    def _export(self, folder: str, key: str, static, treedef, leaves):
        shape = {}

        def flat(*xs):
            args, kwargs = eqx.combine(jax.tree.unflatten(treedef, xs), static)
            dyn, out_static = eqx.partition(self.fn(*args, **kwargs), eqx.is_array)
            out, out_treedef = jax.tree.flatten(dyn)
            slots = jax.tree.unflatten(out_treedef, [_Slot(i) for i in range(len(out))])
            shape["skeleton"] = eqx.combine(slots, out_static, is_leaf=_is_slot)
            return out

        try:
            exported = jax.export.export(jax.jit(flat))(*map(_spec, leaves))
            blob = pickle.dumps((exported.serialize(), shape["skeleton"]))
        except Exception:  # effects, callbacks or anything export does not take: plain jit
            return None
        try:
            write_atomic(Path(folder) / f"{key}.jaxcal", blob, now=True)
        except OSError:  # a read-only folder: this process still uses what it traced
            pass
        return self._runner(exported), shape["skeleton"]
