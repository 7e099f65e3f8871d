"""The research notebooks (jupytext percent scripts) run end to end, in their small size."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

NB = sorted((Path(__file__).parent.parent / "notebooks").glob("*.py"))


def test_there_are_at_least_three_notebooks():
    assert len(NB) >= 3


@pytest.mark.parametrize("path", NB, ids=[p.stem for p in NB])
def test_notebook_runs(path, tmp_path):
    import jupytext

    nb = jupytext.read(path)
    assert sum(c.cell_type == "markdown" for c in nb.cells) >= 2 and sum(c.cell_type == "code" for c in nb.cells) >= 2
    env = dict(os.environ, JAXCAL_NB_SMALL="1", MPLBACKEND="Agg", JAXCAL_NB_OUT=str(tmp_path))
    r = subprocess.run([sys.executable, str(path)], cwd=tmp_path, env=env, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
