"""Writing output files safely: checked before the work starts, written whole or not at all."""

from __future__ import annotations

import contextlib
import contextvars
import io
import json
import math
import os
import tempfile
from pathlib import Path

import numpy as np

from .errors import DataError


def check_writable(path, what: str = "output") -> Path:
    """Raise :class:`DataError` now, before any computation, if ``path`` cannot be written: its
    parent exists as a file, a directory is in the way, or the folder is not writable."""
    path = Path(path)
    if path.is_dir():
        raise DataError(f"{what} {path}: is a directory", option=what)
    if path.exists() and not Path(os.path.realpath(path)).is_file():
        # a device, pipe or socket (/dev/stdout, /dev/null): a file is written beside it and renamed
        # over it, which would replace the special file, or fail after all the work
        raise DataError(f"{what} {path}: not a regular file (a device or a pipe); write to a file", option=what)
    parent = path.parent
    for p in (parent, *parent.parents):
        if p.exists():
            if not p.is_dir():
                raise DataError(f"{what} {path}: {p} is a file, not a folder", option=what)
            if not os.access(p, os.W_OK | os.X_OK):
                raise DataError(f"{what} {path}: folder {p} is not writable", option=what)
            try:  # as root, os.access says yes to a read-only file system (/sys, a read-only mount)
                fd, probe = tempfile.mkstemp(prefix=".jaxcal-probe.", dir=p)
                os.close(fd)
                os.unlink(probe)
            except OSError as e:
                raise DataError(f"{what} {path}: folder {p} is not writable ({e.strerror})", option=what) from None
            break
    return path


def _finite(o):
    if isinstance(o, dict):
        return {k: _finite(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_finite(v) for v in o]
    if isinstance(o, (np.ndarray, np.generic)):
        return _finite(o.tolist())
    if isinstance(o, float) and not math.isfinite(o):
        return None
    return o


def json_text(obj) -> str:
    """``obj`` as indented JSON with NaN and inf written as null: JSON has neither, and strict
    readers refuse the bare tokens Python would write."""
    return json.dumps(_finite(obj), indent=2, allow_nan=False)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_STAGED: contextvars.ContextVar[list | None] = contextvars.ContextVar("jaxcal_staged_outputs", default=None)


@contextlib.contextmanager
def all_or_nothing():
    """Hold every output :func:`write_atomic` is asked for inside the block, and write them when
    the block ends without an error, each atomically, after checking that every one can be: a
    command whose later output fails (a plot, an export) leaves none of its files, not half of
    them, and an earlier result beside a newer one."""
    staged: list = []
    token = _STAGED.set(staged)
    try:
        yield
    finally:
        _STAGED.reset(token)
    targets = [Path(os.path.realpath(path)) for path, _ in staged]  # where each is written
    for target in targets:
        check_writable(target)
    temps = []
    try:  # every file whole beside its target first; then the renames, which do not fail halfway
        for target, (_, data) in zip(targets, staged):
            temps.append(_temporary(target, data))
        for target, tmp in zip(targets, temps):
            os.replace(tmp, target)
    except BaseException as e:
        for tmp in temps:
            Path(tmp).unlink(missing_ok=True)
        if isinstance(e, OSError):  # the disk filled up, or the folder changed since the check
            raise _unwritten(e, targets[len(temps)] if len(temps) < len(targets) else e.filename) from None
        raise


def _unwritten(e: OSError, path) -> DataError:
    return DataError(f"{path}: could not be written ({e.strerror or e}); nothing was written")


def write_atomic(path, data: str | bytes, *, now: bool = False) -> None:
    """Write ``data`` to a temporary file beside ``path``, then rename it over ``path``: a reader
    (or a crash, or Ctrl-C) never leaves half a file, and an existing file is kept until the new
    one is complete. Inside :func:`all_or_nothing`, held until its block ends, unless ``now`` (a
    cache, not an output)."""
    if not now:  # an output: refused before anything is written (a cache write may just fail)
        check_writable(os.path.realpath(path))
    staged = _STAGED.get()
    if staged is not None and not now:
        staged.append((Path(path), data))
    elif now:
        _write_now(path, data)
    else:
        try:
            _write_now(path, data)
        except OSError as e:
            raise _unwritten(e, path) from None


def write_figure(fig, path, **kwargs) -> None:
    """A matplotlib figure as PNG through :func:`write_atomic`."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", **kwargs)
    write_atomic(path, buf.getvalue())


def _write_now(path, data: str | bytes) -> None:
    # a link (a package's file linked into a workspace) keeps pointing where it did: its target is
    # the file replaced, not the link
    path = Path(os.path.realpath(path))
    tmp = _temporary(path, data)
    try:
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _temporary(path: Path, data: str | bytes) -> str:
    """``data`` written and synced to a new file beside ``path``, with an ordinary file's mode."""
    path.parent.mkdir(parents=True, exist_ok=True)
    mode = "wb" if isinstance(data, bytes) else "w"
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, mode, **({} if mode == "wb" else {"encoding": "utf-8", "newline": ""})) as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes the file private; an output is an ordinary file
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return tmp
