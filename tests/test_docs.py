"""The docs' tables are what ``docs/tables.py`` makes of the stored results: a result file
regenerated without ``--write`` (or a table edited by hand) leaves a page quoting stale figures."""

import importlib.util
import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"


def _tables():
    spec = importlib.util.spec_from_file_location("docs_tables", DOCS / "tables.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


TABLES = _tables()


@pytest.mark.parametrize("name", sorted(TABLES.TABLES))
def test_each_table_in_the_docs_is_generated_from_its_results(name):
    pages = {p: (DOCS / p).read_text() for p in TABLES.PAGES}
    found = [
        m.group(1)
        for text in pages.values()
        for m in re.finditer(rf"<!-- table:{name} -->\n(.*?)<!-- /table -->", text, flags=re.S)
    ]
    assert found, f"no <!-- table:{name} --> in {TABLES.PAGES}"
    made = TABLES.TABLES[name]() + "\n"
    for text in found:
        assert text == made, f"docs table {name!r} differs from `python docs/tables.py`: run it with --write"


def test_each_stored_report_says_whether_it_estimates_a_compliance():
    """A report's ``compliance`` is whether the model estimates one (what ``jaxcal design
    --params-from`` designs for), not whether its candidate came with them: the Franka
    quadratic camera model's candidate "all + compliance" prunes every one."""
    import json

    reports = sorted((DOCS / "franka").glob("report*.json")) + sorted((DOCS / "tiago").glob("*pt.json"))
    assert len(reports) > 5
    for path in reports:
        rep = json.loads(path.read_text())
        kept = any(k.startswith("compliance") for k in rep["selection"]["kept"])
        assert rep["compliance"] == kept, path.name
