"""The README's quick start runs as written, and does what it says: the calibrated model it saves
predicts a simulated arm's tool point at poses the calibration never saw (simulated truth)."""

import re
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[1] / "README.md"


def blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README.read_text(), flags=re.S)


def test_readme_is_short_and_opens_with_the_two_commands():
    text = README.read_text()
    assert len(text.splitlines()) <= 125
    first = blocks("bash")[0]
    assert "pip install -e . && jaxcal reproduce --out results" in first
    assert 'pip install -e ".[test]" && pytest -n 2' in first


def test_python_quick_start_runs(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    exec(compile(blocks("python")[0], "README.md", "exec"), ns)
    import jaxcal

    res, sim = ns["result"], ns["sim"]
    assert res.converged and res.plausible
    saved = jaxcal.load_robot(tmp_path / "ur5-calibrated.toml")
    predicted = np.asarray(jaxcal.fk(saved, sim.q_val[0]))[:, :3, 3]
    truth = sim.true_val[0][:, :3, 3]
    nominal = np.asarray(jaxcal.fk(jaxcal.preset("ur5"), sim.q_val[0]))[:, :3, 3]
    assert np.sqrt(np.mean(np.sum((predicted - truth) ** 2, -1))) < 0.1  # noise is 0.02 mm
    assert np.sqrt(np.mean(np.sum((nominal - truth) ** 2, -1))) > 1.0  # the errors were real
    assert "parameter" in capsys.readouterr().out


def test_urdf_block_runs(tmp_path, monkeypatch, capsys):
    """The URDF example, as written, from a folder of its own (data paths made absolute)."""
    import json
    import shlex

    from helpers import run_cli

    (block,) = [b for b in blocks("bash") if "tiago_arm.urdf" in b]
    root = README.parent
    monkeypatch.chdir(tmp_path)
    for line in block.replace("\\\n", " ").splitlines():
        args = [str(root / a) if a.startswith("jaxcal/data/") else a for a in shlex.split(line)]
        assert args[0] == "jaxcal"
        code, _, err = run_cli(monkeypatch, capsys, *args[1:])
        assert code in (0, None), err
    ev = json.loads((tmp_path / "evaluation.json").read_text())
    assert len(ev["points"]) == 4 and 1.0 < ev["position_rms_mm"] < 5.0  # the data set's README: 2.9-4.1 mm
