"""Smoke test of the peer comparison benchmark (without pybotics, which needs its own venv):
jaxcal's GN and scipy's finite-difference least squares on the same problem reach the same
optimum, and the script says that pybotics was not compared."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks" / "bench_vs_pybotics.py"


@pytest.mark.parametrize("robot", ["panda", "ur10"])
def test_bench_vs_pybotics_standin(tmp_path, robot):
    """ur10: pybotics' model from a robot file with the probe estimated, whose chart (an offset in
    the tool frame) the stand-in's residual and the accuracy share with jaxcal's result."""
    out = tmp_path / "r.json"
    p = subprocess.run(
        [
            sys.executable,
            str(BENCH),
            "--robot",
            robot,
            "--pybotics-python",
            str(tmp_path / "none"),
            "--poses",
            "40",
            "--val",
            "20",
            "--repeats",
            "1",
            "--pybotics-repeats",
            "1",
            "--processes",
            "0",
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert p.returncode == 0, p.stderr[-2000:]
    assert "pybotics not found" in p.stdout
    rows = {r["tool"]: r for r in json.loads(out.read_text())["rows"]}
    jx, sc = rows["jaxcal gn (calibrate)"], rows["scipy least_squares FD on jaxcal residual"]
    assert jx["converged"] and sc["converged"]
    # noise 0.02 mm: both land on the same least-squares optimum, near the truth
    assert abs(jx["val_rms_mm"] - sc["val_rms_mm"]) < 1e-4
    assert jx["val_rms_mm"] < 0.05
