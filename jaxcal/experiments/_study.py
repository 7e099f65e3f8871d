"""A study's folder: what defines it, one file of results per chunk of robots, and its summary,
so that a study interrupted anywhere continues where it stopped.

::

    out/study.json         what the study is (robot, counts, noise, seed, ...) and its chunking
    out/chunk-000000.npz   robots [0, c): their estimates, truths, errors, ... (written whole)
    out/summary.json       the summary, once every chunk is done

Every file is written atomically (:func:`jaxcal._io.write_atomic`), so a chunk file exists only
complete. A rerun with the same folder checks that it asks for the same study, then computes
only the chunks without a file; each chunk read holds its study's hash and its robots, so one
from another study (a folder whose ``study.json`` was replaced, a file copied in) or a damaged
one is refused by name, never summed in. With several processes (:func:`jax.distributed.initialize`),
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

FORMAT = 3
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
        # as study.json holds it (an int and a float of one value, numpy scalars): what is
        # compared, written and hashed is one text
        self.definition = json.loads(json_text(dict(definition, format=FORMAT)))
        manifest = self.path / "study.json"
        if manifest.exists():
            old = json.loads(manifest.read_text())
            for k in sorted(set(old) | set(self.definition)):
                if k != "chunk_robots" and old.get(k) != self.definition.get(k):
                    raise DataError(
                        f"out {self.path} holds another study ({k}: {old.get(k)!r} there, "
                        f"{self.definition.get(k)!r} now): use another folder, or delete the folder to start over",
                        option="out",
                    )
            self.definition = old  # equal, and its chunking, whatever the budget now
        elif jax.process_index() == 0:
            write_atomic(manifest, json.dumps(self.definition, indent=2))

    @property
    def chunk_robots(self) -> int:
        return int(self.definition["chunk_robots"])

    @property
    def study_id(self) -> str:
        """A hash of the definition (its chunking included): what every chunk file carries."""
        return hashlib.sha256(json.dumps(self.definition, sort_keys=True).encode()).hexdigest()[:16]

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
        np.savez(buf, **record, study=np.array(self.study_id))
        write_atomic(self.chunk_path(i), buf.getvalue())

    def load(self, i: int, n_robots: int) -> dict:
        """Chunk ``i``'s record, checked to be this study's chunk ``i`` of ``n_robots`` robots;
        :class:`DataError` naming the file otherwise."""
        path = self.chunk_path(i)
        again = "delete that file and rerun to compute its robots again (the other chunks are kept)"
        try:
            with np.load(path) as f:
                rec = {k: f[k] for k in f.files}
        except Exception as e:  # a truncated or damaged file: zip, CRC or pickle errors alike
            raise DataError(f"out {path}: cannot be read ({type(e).__name__}: {e}); {again}", option="out") from None
        c = self.chunk_robots
        want = [i * c, min((i + 1) * c, n_robots)]
        if str(rec.pop("study", "")) != self.study_id:
            raise DataError(f"out {path}: a chunk of another study than the folder's study.json; {again}", option="out")
        if rec.get("robots") is None or rec["robots"].tolist() != want:
            got = None if rec.get("robots") is None else rec["robots"].tolist()
            raise DataError(f"out {path}: holds robots {got}, where this chunk is robots {want}; {again}", option="out")
        return rec

    def write_summary(self, summary: dict) -> None:
        if jax.process_index() == 0:
            write_atomic(self.path / "summary.json", json_text(summary))
