"""Smoke test of the peer comparison benchmark (without pybotics, which needs its own venv):
jaxcal's GN and scipy's finite-difference least squares on the same problem reach the same
optimum, and the script says that pybotics was not compared. And the kernel A/B script runs
on a git revision (in a git checkout) and on a file, and names a version it cannot find."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from jaxcal import _native

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks" / "bench_vs_pybotics.py"
AB = ROOT / "benchmarks" / "bench_kernel_ab.py"


def test_bench_vs_pybotics_standin(tmp_path):
    out = tmp_path / "r.json"
    p = subprocess.run([sys.executable, str(BENCH), "--pybotics-python", str(tmp_path / "none"), "--poses", "40",
                        "--val", "20", "--repeats", "1", "--pybotics-repeats", "1", "--json", str(out)],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    assert "pybotics not found" in p.stdout
    rows = {r["tool"]: r for r in json.loads(out.read_text())["rows"]}
    jx, sc = rows["jaxcal gn (calibrate)"], rows["scipy least_squares FD on jaxcal residual"]
    assert jx["converged"] and sc["converged"]
    # noise 0.02 mm: both land on the same least-squares optimum, near the truth
    assert abs(jx["val_rms_mm"] - sc["val_rms_mm"]) < 1e-4
    assert jx["val_rms_mm"] < 0.05


@pytest.mark.skipif(not _native.available(), reason="native kernel not in use")
def test_bench_kernel_ab_runs_and_names_bad_versions():
    src = str(ROOT / "jaxcal" / "_native" / "chain.cc")
    in_git = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True).returncode == 0
    base = "HEAD" if in_git else src  # a git revision where there is a checkout (CI's clean clone is one)
    p = subprocess.run([sys.executable, str(AB), base, f"{src}@-DJAXCAL_AB_SMOKE=1", "--rounds", "1", "--repeats", "1"],
                       capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert p.returncode == 0, p.stderr[-2000:]
    rows = [line for line in p.stdout.splitlines() if " poses/call " in line]
    assert len(rows) == 8 and all(" ms [" in r for r in rows)  # 2 ops x 2 sizes x 2 versions
    assert f" {base} " in rows[0] and rows[0].rstrip().endswith("x 1.00")  # the baseline, against itself
    bad = subprocess.run([sys.executable, str(AB), "no-such-revision-xyz", "--rounds", "1"], capture_output=True,
                         text=True, timeout=120, cwd=ROOT)
    assert bad.returncode != 0 and "no-such-revision-xyz" in bad.stderr
    # flags after @ reach the compiler: one it does not know fails the build, and the error says so
    bad = subprocess.run([sys.executable, str(AB), f"{src}@-fno-such-flag-xyz", "--rounds", "1", "--repeats", "1"],
                         capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert bad.returncode != 0 and "no-such-flag-xyz" in bad.stderr


@pytest.mark.skipif(not _native.available(), reason="native kernel not in use")
def test_bench_kernel_phases_runs():
    """The harness builds against the kernel's source, checks that both FK layouts write the
    same poses, and prints every phase and every whole-kernel row, the small (in-cache) passes
    included. (The phases are differences of cumulative stages, so they add up to the whole block
    by construction: nothing to assert there.)"""
    p = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_kernel_phases.py"), "--poses", "640",
                        "--repeats", "3", "--cache-poses", "128", "--peak", "100"], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert p.returncode == 0, p.stderr[-2000:]
    lines = p.stdout.splitlines()
    # the one-thread rows must run on one thread: the harness sets the kernel's own pool (it ran on
    # both cores while the pool's header went unrecognised, 56880a1 until 2026-11-24)
    assert any(line.startswith("kernel: ") and "(set by pool)" in line for line in lines), p.stdout[:600]
    phases = [line for line in lines if line.startswith("FK phases")]
    assert len(phases) == 2 and all("sincos" in line and "chain" in line for line in phases)
    # the Jacobian's phases, over the small passes
    jph = [line for line in lines if line.startswith("Jacobian phases, 128 poses per pass")]
    assert len(jph) == 1 and all(k in jph[0] for k in ("frames and end poses", "columns", "transposed store of J"))
    names = [line.split(" median")[0].strip() for line in lines if " ns/pose " in line]
    assert {"FK pose-major, 1 thread(s)", "FK pose-last, 1 thread(s)", "Jacobian, 1 thread(s)",
            "FK pose-major (128 poses per pass), 1 thread(s)", "Jacobian (128 poses per pass), 1 thread(s)"} <= set(names)
