"""A Monte Carlo study in chunks: interrupted after a chunk, rerun with the same folder, it
computes only the missing chunks and ends with the summary of an uninterrupted study."""

import json

import numpy as np
import pytest

import jaxcal
from jaxcal.errors import DataError
from jaxcal.experiments import run_montecarlo
from jaxcal.simulation import error_scales

ROBOT = jaxcal.preset("paper-6r")
STUDY = dict(n_robots=20, n_poses=12, n_val=4, seed=7, chunk_robots=8, repeats=0, devices=None)
SAME = ("robots_done", "converged_fraction", "max_steps_taken", "param_rms_error", "validation_pos_rms_mm")


def _chunks(folder):
    return sorted(folder.glob("chunk-*.npz"))


def test_an_interrupted_study_resumes_where_it_stopped(tmp_path):
    whole = run_montecarlo(ROBOT, out=tmp_path / "whole", **STUDY)
    assert whole["complete"] and whole["chunks"] == 3 and whole["chunks_computed"] == 3
    assert whole["devices"] == ["cpu:0 (process 0)"]  # the report names the devices used
    assert json.loads((tmp_path / "whole" / "summary.json").read_text())["robots_done"] == 20

    part = tmp_path / "part"
    a = run_montecarlo(ROBOT, out=part, max_chunks=1, **STUDY)
    assert not a["complete"] and a["robots_done"] == 8 and len(_chunks(part)) == 1
    assert not (part / "summary.json").exists()
    first = _chunks(part)[0].read_bytes()
    b = run_montecarlo(ROBOT, out=part, **STUDY)
    assert b["complete"] and b["chunks_computed"] == 2 and b["chunks_done"] == 3
    assert _chunks(part)[0].read_bytes() == first  # the finished chunk was not computed again
    for k in SAME:
        assert b[k] == pytest.approx(whole[k], rel=1e-12, abs=0), k
    # every robot's results in the files, the last chunk without its padding
    x = np.concatenate([np.load(f)["x"] for f in _chunks(part)])
    ref = np.concatenate([np.load(f)["x"] for f in _chunks(tmp_path / "whole")])
    assert x.shape == (20, 24) and np.abs(x - ref).max() < 1e-12
    # the truths are the simulated errors: distinct robots, at the documented scales
    xt = np.concatenate([np.load(f)["x_true"] for f in _chunks(part)])
    assert len(np.unique(xt[:, 0])) == 20
    assert np.std(xt / error_scales(ROBOT), axis=0).mean() == pytest.approx(1.0, abs=0.25)


def test_a_folder_of_another_study_is_refused(tmp_path):
    run_montecarlo(ROBOT, out=tmp_path, max_chunks=1, **STUDY)
    with pytest.raises(DataError, match=r"holds another study \(n_poses: 12 there, 14 now\)"):
        run_montecarlo(ROBOT, out=tmp_path, **dict(STUDY, n_poses=14))
    (tmp_path / "file").write_text("")
    with pytest.raises(DataError, match="is a file, not a folder"):
        run_montecarlo(ROBOT, out=tmp_path / "file", **STUDY)


def test_a_chunk_of_another_study_or_a_damaged_one_is_refused_by_name(tmp_path):
    """Chunk files are checked as they are read: one of another study (the folder's study.json
    deleted and the folder reused with another seed, or a file copied in), one in another
    chunk's place, and a truncated one are each refused naming the file and what to delete;
    the same study rerun after its study.json was deleted reads its own chunks."""
    a, b = tmp_path / "a", tmp_path / "b"
    run_montecarlo(ROBOT, out=a, max_chunks=2, **STUDY)
    run_montecarlo(ROBOT, out=b, max_chunks=1, **dict(STUDY, seed=8))
    (a / "study.json").unlink()  # the same study again: its own chunks are read
    again = run_montecarlo(ROBOT, out=a, max_chunks=1, **STUDY)
    assert again["chunks_done"] == 3 and again["chunks_computed"] == 1  # chunks 0 and 1 read, not computed
    (a / "study.json").unlink()
    with pytest.raises(DataError, match=r"chunk-000000\.npz: a chunk of another study .*delete that file"):
        run_montecarlo(ROBOT, out=a, max_chunks=1, **dict(STUDY, seed=8))
    (a / "study.json").unlink()
    run_montecarlo(ROBOT, out=a, max_chunks=1, **STUDY)  # back to its own study.json
    (a / "chunk-000000.npz").write_bytes((b / "chunk-000000.npz").read_bytes())
    with pytest.raises(DataError, match=r"chunk-000000\.npz: a chunk of another study"):
        run_montecarlo(ROBOT, out=a, max_chunks=1, **STUDY)
    (a / "chunk-000000.npz").write_bytes((a / "chunk-000001.npz").read_bytes())
    with pytest.raises(
        DataError, match=r"chunk-000000\.npz: holds robots \[8, 16\], where this chunk is robots \[0, 8\]"
    ):
        run_montecarlo(ROBOT, out=a, max_chunks=1, **STUDY)
    data = (a / "chunk-000001.npz").read_bytes()
    (a / "chunk-000000.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(DataError, match=r"chunk-000000\.npz: cannot be read \(BadZipFile"):
        run_montecarlo(ROBOT, out=a, max_chunks=1, **STUDY)


def test_a_study_resumed_with_equal_values_written_otherwise_reads_its_chunks(tmp_path):
    """A float where the first run gave an int, a NumPy integer for a count: the same study, its
    chunk read, not refused as another study's."""
    run_montecarlo(ROBOT, out=tmp_path, max_chunks=1, **dict(STUDY, sigma_pos=1))
    again = run_montecarlo(ROBOT, out=tmp_path, max_chunks=1, **dict(STUDY, sigma_pos=1.0, n_robots=np.int64(20)))
    assert again["chunks_done"] == 2 and again["chunks_computed"] == 1
