"""``jaxcal design`` writes a pose file that ``jaxcal montecarlo --poses-file`` calibrates on; the
simulated calibration lands near the design's predicted validation RMS."""

import json

from helpers import run_cli


def test_design_then_montecarlo_on_its_poses(monkeypatch, capsys, tmp_path):
    out, js, mc = tmp_path / "poses.csv", tmp_path / "design.json", tmp_path / "mc.json"
    code, stdout, err = run_cli(
        monkeypatch, capsys, "design", "paper-6r", "--poses", "8", "--out", out, "--starts", "2",
        "--no-estimate-base", "--no-estimate-tool", "--random-sets", "50", "--json", js,
    )  # fmt: skip
    assert code in (0, None), err
    assert "random median" in stdout
    d = json.loads(js.read_text())
    assert out.read_text().startswith("q1,q2,q3,q4,q5,q6\n") and d["feasible"]
    code, stdout, err = run_cli(
        monkeypatch, capsys, "montecarlo", "paper-6r", "--poses-file", out, "--robots", "64", "--repeats", "0",
        "--json", mc,
    )  # fmt: skip
    assert code in (0, None), err
    m = json.loads(mc.read_text())
    assert m["n_poses"] == 8
    predicted = d["values"]["validation_rms_mm"]
    # 64 robots x 50 validation poses: the empirical RMS within ~15 % of the bound it attains
    assert 0.8 * predicted < m["validation_pos_rms_mm"] < 1.3 * predicted


def test_design_bad_region_names_the_flag(monkeypatch, capsys, tmp_path):
    code, _, err = run_cli(
        monkeypatch, capsys, "design", "paper-6r", "--poses", "8", "--out", tmp_path / "p.csv", "--region", "1,2,3"
    )
    assert code == 2 and "--region" in err and not (tmp_path / "p.csv").exists()
