"""Outputs are written atomically, as ordinary files (the process's umask, not private)."""

import json
import os
import stat

import numpy as np

from jaxcal._io import json_text, write_atomic


def test_written_file_has_ordinary_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        write_atomic(tmp_path / "a.txt", "x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o644
    assert (tmp_path / "a.txt").read_text() == "x"
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]  # no temporary file left behind


def test_json_text_writes_non_finite_numbers_as_null():
    """A strict reader (one that refuses NaN and Infinity, as JSON itself does) reads every value."""
    obj = {
        "a": float("nan"),
        "b": [1.5, np.inf, np.float64(-np.inf)],
        "c": np.array([[2.0, np.nan]]),
        "d": (np.int64(3),),
    }

    def refuse(token):
        raise ValueError(token)

    back = json.loads(json_text(obj), parse_constant=refuse)
    assert back == {"a": None, "b": [1.5, None, None], "c": [[2.0, None]], "d": [3]}
