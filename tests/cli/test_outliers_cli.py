"""`jaxcal calibrate` with its defaults on files with gross outliers and lost markers (issue
33): outliers named in the terminal and the JSON and kept out of the model; too many refused
with nothing written; occluded markers dropped by row and point; `evaluate --points`. Models
are scored against the simulated truth by the NumPy forward kinematics of tests/helpers.py."""

import json
import re

import numpy as np
import pytest
from helpers import dh_fk, run_cli

import jaxcal
from jaxcal.compensation import tool_note
from jaxcal.measurements import write_measurements
from jaxcal.simulation import simulate

K, NOISE = 60, 0.02  # 60 poses: the pose bucket (64) of other tests' fits, one compile for both
ARGS = ("--params", "all", "--folds", "3", "--compliance", "no")  # outliers and markers, not compliance


def _study(outliers: float):
    robot = jaxcal.preset("ur5")
    kw = dict(n_poses=K, n_val=200, seed=9, sigma_pos=NOISE, sigma_rot=2e-5, base=True, tool=True)
    return simulate(robot, outliers=outliers, **kw)


def _val_rms(path, sim) -> float:
    r = jaxcal.load_robot(path)
    T = dh_fk(np.asarray(r.dh), sim.q_val[0], base=np.asarray(r.base), tool=np.asarray(r.tool))
    return float(np.sqrt(np.mean(np.sum((T[:, :3, 3] - sim.true_val[0][:, :3, 3]) ** 2, -1))))


def _calibrate(tmp_path, monkeypatch, capsys, sim, name, *extra):
    data = tmp_path / f"{name}.csv"
    write_measurements(data, sim.q[0], sim.measured[0])
    out = dict(json=tmp_path / f"{name}.json", robot=tmp_path / f"{name}.toml")
    code, stdout, err = run_cli(
        monkeypatch, capsys, "calibrate", "ur5", data, *ARGS, *extra, "--json", out["json"], "--out-robot", out["robot"]
    )
    return code, stdout, err, out, data


@pytest.fixture(scope="module")
def clean_sim():
    return _study(0.0)


def test_five_percent_outliers_named_and_left_out(tmp_path, monkeypatch, capsys, clean_sim):
    bad = _study(0.05)
    injected = [int(k) + 1 for k in np.flatnonzero(bad.outlier_mask[0])]  # file rows
    code, clean_text, err, clean_out, clean_csv = _calibrate(tmp_path, monkeypatch, capsys, clean_sim, "clean")
    assert code in (0, None), err
    code, out, err, bad_out, _ = _calibrate(tmp_path, monkeypatch, capsys, bad, "bad")
    assert code in (0, None), err
    rep = json.loads(bad_out["json"].read_text())
    assert sorted(o["row"] for o in rep["outliers"]) == injected and len(injected) == 3
    assert all(3.0 * 0.5 < o["position_mm"] and o["sigmas"] > o["threshold_sigmas"] for o in rep["outliers"])
    assert rep["outlier_detection"]["excluded"] and rep["outlier_detection"]["threshold_sigmas"] == pytest.approx(
        6.405, abs=1e-3
    )
    for row in injected:
        assert f"│ {row:>3} │" in out  # the terminal's outlier table names the row
    e_clean, e_bad = _val_rms(clean_out["robot"], clean_sim), _val_rms(bad_out["robot"], bad)
    assert e_bad <= 2 * e_clean, (e_clean, e_bad)
    # the held-out figures leave the flagged poses out; the report says what they would add
    assert rep["heldout_rms_mm"] < 0.1 < rep["outlier_detection"]["heldout_rms_mm_all_poses"]
    # poses: the rotation's too (a pose may stand out in its orientation alone)
    all_rot = rep["outlier_detection"]["heldout_rot_rms_deg_all_poses"]
    assert 0 < all_rot < 1 and f"{all_rot:.3g} deg; --keep-outliers" in " ".join(out.split())
    # clean data: nothing flagged, and the same model as without detection
    crep = json.loads(clean_out["json"].read_text())
    assert crep["outliers"] == [] and "outliers: none" in clean_text
    kept = jaxcal.calibrate_data(
        jaxcal.preset("ur5"),
        jaxcal.read_measurements(clean_csv, jaxcal.preset("ur5")),
        params="all",
        folds=3,
        compliance="no",
        keep_outliers=True,
    )
    q = clean_sim.q_val[0]
    np.testing.assert_allclose(
        np.asarray(jaxcal.fk(jaxcal.load_robot(clean_out["robot"]), q)), np.asarray(jaxcal.fk(kept.robot, q)), atol=1e-9
    )
    assert kept.report["heldout_rms_mm"] == pytest.approx(crep["heldout_rms_mm"], abs=1e-12)


def test_thirty_percent_outliers_refused_nothing_written(tmp_path, monkeypatch, capsys):
    bad = _study(0.3)
    code, _, err, out, _ = _calibrate(tmp_path, monkeypatch, capsys, bad, "bad")
    assert code == 3, err
    assert not out["json"].exists() and not out["robot"].exists()
    msg = " ".join(err.split())
    assert (
        "18 of 60 poses (30 %) are outliers, more than max_outlier_fraction 20 %" in msg
        and "nothing was written" in msg
    )
    listed = re.findall(r"(\d+) \([\d.]+ mm, [\d.]+ deg, [\d.]+ sigma\)", msg.split("worst rows: ")[1])  # poses
    assert len(listed) == 5 and {int(r) - 1 for r in listed} <= set(np.flatnonzero(bad.outlier_mask[0]))
    # --keep-outliers does not hide them, and a looser limit lets the fit through
    code, _, err, out, _ = _calibrate(tmp_path, monkeypatch, capsys, bad, "loose", "--max-outlier-fraction", "0.35")
    assert code in (0, None), err
    assert len(json.loads(out["json"].read_text())["outliers"]) == 18


def _four_points(tmp_path):
    """A UR5 with four markers on its flange, 30 poses; the csv written without jaxcal, three
    (row, point) cells left empty (occluded) and one row with no marker at all."""
    robot = jaxcal.preset("ur5")
    sim = simulate(robot, n_poses=30, n_val=1, seed=12, sigma_pos=NOISE)
    offsets = np.array([[0.0, 0, 0], [60.0, 0, 0], [0, 60.0, 0], [0, 0, 60.0]])
    T = sim.measured[0]
    pts = np.einsum("kij,mj->kmi", T[:, :3, :3], offsets) + T[:, None, :3, 3]
    header = [f"q{j}" for j in range(1, 7)] + [f"{a}{m}" for m in range(1, 5) for a in "xyz"]
    occluded = {(4, 2), (11, 4), (20, 1)}  # (row, point), 1-based
    lines = [",".join(header)]
    for k in range(30):
        cells = [repr(float(v)) for v in sim.q[0][k]]
        for m in range(4):
            gone = (k + 1, m + 1) in occluded or k + 1 == 25
            cells += [""] * 3 if gone else [repr(float(v)) for v in pts[k, m]]
        lines.append(",".join(cells))
    path = tmp_path / "four.csv"
    path.write_text("\n".join(lines) + "\n")
    return path, sorted(occluded)


def test_four_points_with_occluded_markers(tmp_path, monkeypatch, capsys):
    data, occluded = _four_points(tmp_path)
    code, out, err = run_cli(
        monkeypatch,
        capsys,
        "calibrate",
        "ur5",
        data,
        *ARGS,
        "--json",
        tmp_path / "r.json",
        "--out-model",
        tmp_path / "m4.toml",
    )
    assert code in (0, None), err
    rep = json.loads((tmp_path / "r.json").read_text())
    assert [(p["row"], p["point"]) for p in rep["lost_points"]] == occluded
    assert rep["dropped_rows"] == [25] and rep["poses"] == 29 and rep["points"] == 4
    assert rep["converged"] and rep["outliers"] == [] and rep["heldout_rms_mm"] < 0.1
    text = " ".join(out.split())
    assert "3 point(s) not seen, left out: row 4 point 2, row 11 point 4, row 20 point 1" in text
    assert "row(s) 25 dropped" in text
    # a model fitted on point 1 alone, scored on the four-point file's point 1
    code, _, err = run_cli(
        monkeypatch, capsys, "calibrate", "ur5", data, *ARGS, "--points", "1", "--out-robot", tmp_path / "p1.toml"
    )
    assert code in (0, None), err
    code, out, err = run_cli(
        monkeypatch, capsys, "evaluate", tmp_path / "p1.toml", data, "--points", "1", "--json", tmp_path / "e.json"
    )
    assert code in (0, None), err
    ev = json.loads((tmp_path / "e.json").read_text())
    assert len(ev["points"]) == 1 and ev["poses_evaluated"] == 28  # rows 20 (point 1 lost) and 25 dropped
    assert ev["dropped_rows"] == [20, 25] and ev["position_rms_mm"] < 0.1
    # row 20 has other points: the note says none of those read (point 1) was seen
    assert "row(s) 20, 25 dropped: none of the point(s) 1 read was seen" in " ".join(out.split())
    # the one point is the tool origin, marked so: a pose file is not scored as poses, and pose
    # targets are refused (the tool's orientation was never measured: rows flagged as reaching
    # orientations the arm misses by degrees), nothing written
    p1 = jaxcal.load_model(tmp_path / "p1.toml")
    assert p1.n_points == 1 and np.all(np.asarray(p1.points) == 0)
    targets = tmp_path / "poses.csv"
    targets.write_text("x,y,z,qw,qx,qy,qz\n400,200,300,1,0,0,0\n")
    out_csv = tmp_path / "c.csv"
    code, _, err = run_cli(monkeypatch, capsys, "compensate", tmp_path / "p1.toml", targets, "--out", out_csv)
    assert code == 2 and "tool's orientation was never measured" in " ".join(err.split()), err
    assert not out_csv.exists()
    # joint commands alone: their targets are the nominal tool's, and the model's tool is point 1,
    # which the data put at the simulated tool: 50 mm from a nominal whose tool is 50 mm further
    ur5 = jaxcal.preset("ur5")
    shift = np.eye(4)
    shift[2, 3] = 50.0
    further = np.asarray(ur5.tool) @ shift
    note = tool_note(p1.n_points, p1.robot, ur5.replace(tool=further), "p1.toml", commands_only=True)
    assert abs(float(re.search(r"there, ([\d.]+) mm from the nominal robot's tool", note).group(1)) - 50.0) < 1.0
    assert tool_note(p1.n_points, p1.robot, ur5, "p1.toml", commands_only=False) == ""  # x, y, z targets
    # all four points of a four-point model: the lost ones are None per pose and left out of the figures
    code, out, err = run_cli(
        monkeypatch, capsys, "evaluate", tmp_path / "m4.toml", data, "--json", tmp_path / "e4.json"
    )
    assert code in (0, None), err
    ev = json.loads((tmp_path / "e4.json").read_text())
    row4 = next(p for p in ev["poses"] if p["row"] == 4)
    assert row4["error_mm"][1] is None and all(v is not None for v in row4["error_mm"][::2])
    assert np.isfinite(ev["position_rms_mm"]) and len(ev["lost_points"]) == 3
    # the same file with marker 2's columns cut out: --points 1,3,4 read by their numbers, as from
    # the whole file (it was refused: "point 2: missing column(s)")
    header, *lines = data.read_text().splitlines()
    keep = [i for i, c in enumerate(header.split(",")) if c not in ("x2", "y2", "z2")]
    cut = tmp_path / "cut.csv"
    cut.write_text("\n".join(",".join(r.split(",")[i] for i in keep) for r in [header, *lines]) + "\n")
    for src, js in ((data, "e134.json"), (cut, "c134.json")):
        code, _, err = run_cli(
            monkeypatch, capsys, "evaluate", tmp_path / "m4.toml", src, "--points", "1,3,4", "--json", tmp_path / js
        )  # fmt: skip
        assert code in (0, None), err
    whole, part = (json.loads((tmp_path / js).read_text()) for js in ("e134.json", "c134.json"))
    assert [p["point"] for p in part["points"]] == [1, 3, 4]
    assert part["position_rms_mm"] == pytest.approx(whole["position_rms_mm"], rel=1e-12)
