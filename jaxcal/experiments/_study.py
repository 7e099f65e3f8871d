"""A study's folder: what defines it, one file of results per chunk of robots, and its summary,
so that a study interrupted anywhere continues where it stopped.

::

    out/study.json         what the study is (robot, counts, noise, seed, ...) and its chunking
    out/chunk-000000.npz   robots [0, c): their estimates, truths, errors, ... (written whole)
    out/summary.json       the summary, once every chunk is done

Every file is written atomically (:func:`jaxcal._io.write_atomic`), so a chunk file exists only
complete. A rerun with the same folder checks that it asks for the same study, then computes
only the chunks without a file. With several processes (:func:`jax.distributed.initialize`),
process 0 writes and every process reads: the folder must be on a file system they share.
"""

from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path

import jax
import numpy as np

from .._io import json_text, write_atomic
from ..errors import DataError

FORMAT = 2
"""What a study's chunks hold and how their errors are measured: a folder of another format is
another study, refused rather than mixed with this one's chunks."""


def fingerprint(tree) -> str:
    """A hash of a pytree's structure and values (a robot, a pose design): two studies of the
    same name but different numbers differ here."""
    leaves, treedef = jax.tree.flatten(tree)
    h = hashlib.sha256(str(treedef).encode())
    for a in leaves:
        a = np.ascontiguousarray(np.asarray(a, dtype=np.float64))
        h.update(str(a.shape).encode() + a.tobytes())
    return h.hexdigest()[:16]


class StudyFolder:
    """The files of one study (see the module docstring)."""

    def __init__(self, path, definition: dict):
        self.path = Path(path)
        if self.path.exists() and not self.path.is_dir():
            raise DataError(f"out {self.path}: is a file, not a folder", option="out")
        self.definition = dict(definition, format=FORMAT)
        manifest = self.path / "study.json"
        if manifest.exists():
            old = json.loads(manifest.read_text())
            for k in sorted(set(old) | set(self.definition)):
                if k != "chunk_robots" and old.get(k) != self.definition.get(k):
                    raise DataError(
                        f"out {self.path} holds another study ({k}: {old.get(k)!r} there, "
                        f"{self.definition.get(k)!r} now): use another folder, or delete it to start over",
                        option="out",
                    )
            self.definition["chunk_robots"] = old["chunk_robots"]  # its chunking, whatever the budget now
        elif jax.process_index() == 0:
            write_atomic(manifest, json.dumps(self.definition, indent=2))

    @property
    def chunk_robots(self) -> int:
        return int(self.definition["chunk_robots"])

    def chunk_path(self, i: int) -> Path:
        return self.path / f"chunk-{i:06d}.npz"

    def done(self, n_chunks: int) -> np.ndarray:
        """Which chunks have their file; every process takes process 0's answer, so all compute
        the same chunks."""
        have = np.array([self.chunk_path(i).exists() for i in range(n_chunks)])
        if jax.process_count() > 1:
            from jax.experimental import multihost_utils

            have = np.asarray(multihost_utils.broadcast_one_to_all(have))
        return have

    def save(self, i: int, record: dict) -> None:
        if jax.process_index() != 0:
            return
        buf = io.BytesIO()
        np.savez(buf, **record)
        write_atomic(self.chunk_path(i), buf.getvalue())

    def load(self, i: int) -> dict:
        with np.load(self.chunk_path(i)) as f:
            return {k: f[k] for k in f.files}

    def write_summary(self, summary: dict) -> None:
        if jax.process_index() == 0:
            write_atomic(self.path / "summary.json", json_text(summary))
