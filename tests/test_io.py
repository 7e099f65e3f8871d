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


def test_all_or_nothing_writes_none_when_the_block_fails(tmp_path):
    """A command's outputs are written together: an error after the first leaves none of them,
    and an older file in place."""
    import pytest

    from jaxcal._io import all_or_nothing

    (tmp_path / "b.txt").write_text("old")
    with pytest.raises(RuntimeError), all_or_nothing():
        write_atomic(tmp_path / "a.txt", "new")
        write_atomic(tmp_path / "b.txt", "new")
        raise RuntimeError("a later output failed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.txt"] and (tmp_path / "b.txt").read_text() == "old"
    with all_or_nothing():
        write_atomic(tmp_path / "a.txt", "new")
        assert not (tmp_path / "a.txt").exists()  # held until the block ends
    assert (tmp_path / "a.txt").read_text() == "new"


def test_all_or_nothing_checks_every_output_before_writing_one(tmp_path):
    import pytest

    from jaxcal._io import all_or_nothing
    from jaxcal.errors import DataError

    (tmp_path / "plots" / "parameters.png").mkdir(parents=True)  # a folder where a file goes
    with pytest.raises(DataError, match="parameters.png: is a directory"), all_or_nothing():
        write_atomic(tmp_path / "a.txt", "new")
        write_atomic(tmp_path / "plots" / "parameters.png", b"png")
    assert not (tmp_path / "a.txt").exists()


def test_a_link_keeps_pointing_at_the_file_it_names(tmp_path):
    """An output named by a symbolic link (a package's file linked into a workspace) replaces
    the link's target, not the link: whatever reads the target reads the new file."""
    (tmp_path / "pkg").mkdir()
    target = tmp_path / "pkg" / "cal.yaml"
    target.write_text("old")
    (tmp_path / "cal.yaml").symlink_to(target)
    write_atomic(tmp_path / "cal.yaml", "new")
    assert (tmp_path / "cal.yaml").is_symlink() and target.read_text() == "new"


def test_all_or_nothing_checks_where_a_link_points(tmp_path):
    """A link whose target cannot be written (its folder is a file) is refused before any output
    is written, naming the target; the other output keeps its old content."""
    import pytest

    from jaxcal._io import all_or_nothing
    from jaxcal.errors import DataError

    (tmp_path / "a.txt").write_text("old")
    (tmp_path / "afile").write_text("a file, not a folder")
    (tmp_path / "b.txt").symlink_to(tmp_path / "afile" / "b.txt")
    with pytest.raises(DataError, match="is a file, not a folder"), all_or_nothing():
        write_atomic(tmp_path / "a.txt", "new")
        write_atomic(tmp_path / "b.txt", "new")
    assert (tmp_path / "a.txt").read_text() == "old"
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_a_directory_or_a_special_file_is_refused_and_left_as_it_is(tmp_path):
    """A file is written beside the path and renamed over it: over a directory that fails late,
    over a pipe or a device it replaces it. Both are refused before anything is written, naming
    the path, for the API's writers (here the one they share) as for the CLI's checks."""
    import pytest

    from jaxcal import DataError
    from jaxcal._io import check_writable

    pipe = tmp_path / "pipe"
    os.mkfifo(pipe)
    for path, said in ((tmp_path, "is a directory"), (pipe, "not a regular file")):
        with pytest.raises(DataError, match=said):
            write_atomic(path, "x")
        with pytest.raises(DataError, match=said):
            check_writable(path, "out")
    assert stat.S_ISFIFO(pipe.stat().st_mode) and sorted(p.name for p in tmp_path.iterdir()) == ["pipe"]
    link = tmp_path / "to-pipe"
    link.symlink_to(pipe)
    with pytest.raises(DataError, match="not a regular file"):
        write_atomic(link, "x")


def test_a_cache_write_that_cannot_be_made_fails_as_an_os_error(tmp_path):
    """A cache write (``now``) is not an output: where it cannot be made it fails as the OS says,
    which the program cache skips, not with the outputs' DataError that would stop a run."""
    import pytest

    from jaxcal import DataError

    (tmp_path / "afile").write_text("x")
    with pytest.raises(OSError) as e:
        write_atomic(tmp_path / "afile" / "sub" / "k.bin", b"x", now=True)
    assert not isinstance(e.value, DataError)


def test_a_folder_the_os_will_not_write_in_is_refused_before_anything_runs(tmp_path, monkeypatch, capsys):
    """Where the folder's permissions say yes but no file can be made there (as root: a read-only
    file system, /proc), the output is refused by the check before the fit, as a command's
    one-line error (exit 2), not a traceback after it."""
    import sys

    import pytest
    from helpers import run_cli

    from jaxcal import DataError
    from jaxcal._io import check_writable

    if not sys.platform.startswith("linux"):
        pytest.skip("/proc is Linux's")
    with pytest.raises(DataError, match="folder /proc is not writable"):
        check_writable("/proc/jaxcal-out.toml", "out")
    data = tmp_path / "data.csv"
    data.write_text("q1,q2,q3,q4,q5,q6,x,y,z\n" + "0,0,0,0,0,0,1,2,3\n" * 20)
    code, _, err = run_cli(monkeypatch, capsys, "calibrate", "ur5", data, "--out-robot", "/proc/jaxcal-out.toml")
    assert code == 2 and " ".join(err.split()).startswith("error: --out-robot /proc/jaxcal-out.toml: folder /proc")


def test_an_output_that_fails_as_it_is_written_is_an_error_naming_it_and_none_is_written(tmp_path, monkeypatch):
    """The disk fills up after the check: the command's error names the file, and neither output
    of the block is left, whole or half."""
    import errno

    import pytest

    import jaxcal._io as io_
    from jaxcal import DataError

    made = io_._temporary

    def full(path, data):
        if path.name == "b.txt":
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
        return made(path, data)

    monkeypatch.setattr(io_, "_temporary", full)
    with pytest.raises(DataError, match=r"b\.txt: could not be written \(No space left on device\)"):
        with io_.all_or_nothing():
            write_atomic(tmp_path / "a.txt", "a")
            write_atomic(tmp_path / "b.txt", "b")
    with pytest.raises(DataError, match=r"b\.txt: could not be written"):
        write_atomic(tmp_path / "b.txt", "b")
    assert list(tmp_path.iterdir()) == []
