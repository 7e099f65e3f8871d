"""The research notebooks (jupytext percent scripts) stay in step with the library: every code
cell compiles, and every name they import from jaxcal exists. (Running them in full repeats the
reproduction and Monte Carlo tests; `python notebooks/NAME.py` does.)"""

import ast
import importlib
from pathlib import Path

import pytest

NB = sorted((Path(__file__).parent.parent / "notebooks").glob("*.py"))


def test_there_are_notebooks():
    assert len(NB) >= 3


@pytest.mark.parametrize("path", NB, ids=[p.stem for p in NB])
def test_notebook_cells_compile_and_imports_exist(path):
    import jupytext

    nb = jupytext.read(path)
    code = [c.source for c in nb.cells if c.cell_type == "code"]
    assert sum(c.cell_type == "markdown" for c in nb.cells) >= 2 and len(code) >= 2
    for src in code:
        tree = ast.parse(src)  # a syntax error fails here
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("jaxcal"):
                mod = importlib.import_module(node.module)
                for alias in node.names:
                    assert hasattr(mod, alias.name) or importlib.util.find_spec(f"{node.module}.{alias.name}"), (
                        f"{path.name}: {node.module}.{alias.name}"
                    )
            if isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name.startswith("jaxcal"):
                        importlib.import_module(alias.name)
