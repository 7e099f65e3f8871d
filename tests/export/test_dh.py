"""The DH table (`--out-dh`): nominal, calibrated and delta per parameter with its standard
error, in the robot file's units, from a calibration of simulated UR5 tracker data."""

import csv
import dataclasses
import io

import numpy as np
import pytest
from helpers import ur5_tracker

import jaxcal
from jaxcal import RobotFileError
from jaxcal.export import check_dh, dh_rows, dh_table, save_dh_table


def _rows(res):
    return list(csv.DictReader(io.StringIO(dh_table(res))))


def test_table_agrees_with_the_model_and_covariance(tmp_path):
    ur5, _, _, res = ur5_tracker()
    save_dh_table(res, tmp_path / "dh.csv")
    rows = list(csv.DictReader((tmp_path / "dh.csv").open()))
    names = res.layout.names()
    se = np.sqrt(np.diag(res.covariance))
    nominal, calibrated = np.asarray(ur5.dh).ravel(), np.asarray(res.robot.dh).ravel()
    assert [r["parameter"] for r in rows] == ur5.param_names()
    for i, r in enumerate(rows):
        assert float(r["nominal"]) == nominal[i] and float(r["calibrated"]) == calibrated[i]
        assert abs(float(r["delta"]) - (calibrated[i] - nominal[i])) < 1e-12
        assert r["unit"] == ("rad" if r["parameter"].startswith(("theta", "alpha")) else "mm")
        assert int(r["joint"]) == i // 4 + 1
        if r["status"] == "estimated":
            assert float(r["std_error"]) == pytest.approx(se[names.index(r["parameter"])], rel=1e-12)
        else:
            assert r["std_error"] == "" and float(r["delta"]) == 0.0
            assert r["status"].startswith("not estimated: not separable from"), r
    # the base and the tool absorb theta1, d1 and the last link: held, with the reason
    held = {r["parameter"] for r in rows if r["status"] != "estimated"}
    assert {"theta1", "d1", "d6", "a6", "alpha6"} <= held


def test_table_in_the_robot_files_units():
    """A robot file in metres and degrees gives a table in metres and degrees."""
    _, _, _, res = ur5_tracker()
    mm_rad = _rows(res)
    m_deg = _rows(dataclasses.replace(res, nominal=res.nominal.replace(units=("m", "deg"))))
    for a, b in zip(mm_rad, m_deg):
        angle = a["unit"] == "rad"
        assert b["unit"] == ("deg" if angle else "m")
        f = (lambda v: np.degrees(v)) if angle else (lambda v: v / 1000.0)
        for col in ("nominal", "calibrated", "delta", "std_error"):
            if a[col]:
                assert float(b[col]) == pytest.approx(f(float(a[col])), rel=1e-12, abs=1e-15), (a, col)


def test_joint_frame_robot_refused():
    with pytest.raises(RobotFileError, match="out_dh: 'ur5' is described by joint frames"):
        check_dh(jaxcal.to_joint(jaxcal.preset("ur5")), "out_dh")


def test_estimated_compliances_are_rows_in_the_files_units():
    """A compliance of 3e-5 rad/mm in a file in metres and degrees is 3e-5 x 1000 / (pi/180)
    deg/m, its change from the nominal robot's 1e-5 and standard error alike; compliances not
    estimated get no row."""
    from types import SimpleNamespace

    nominal = jaxcal.preset("ur5").replace(units=("m", "deg"), compliance=np.r_[0.0, 1e-5, np.zeros(4)])
    comp = np.array([0.0, 3e-5, 1e-5, 0.0, 0.0, 0.0])
    result = SimpleNamespace(
        nominal=nominal,
        model=SimpleNamespace(robot=nominal.replace(compliance=comp)),
        deltas={"compliance2": (2e-5, 4e-7)},
        report={"not_estimated": {}, "choice": "all + compliance"},
    )
    rows = [r for r in dh_rows(result) if r["parameter"].startswith("compliance")]
    k = 1000.0 / (np.pi / 180.0)
    assert [r["parameter"] for r in rows] == ["compliance2"] and rows[0]["unit"] == "deg/m"
    got = [rows[0][c] for c in ("nominal", "calibrated", "delta", "std_error")]
    np.testing.assert_allclose(got, np.array([1e-5, 3e-5, 2e-5, 4e-7]) * k, rtol=1e-12)


def test_reference_moments_are_rows_and_a_moved_offset_says_it_was_not_estimated():
    """A model whose offsets hold at reference moments (jaxcal.Robot.moment_ref, mm) has a row
    per estimated compliance with its moment in the file's length unit (m: /1000); an offset the
    calibration did not estimate but its compliance moved keeps the reason it was not estimated
    (and the compliance's error), not 'estimated'."""
    from types import SimpleNamespace

    nominal = jaxcal.preset("ur5").replace(units=("m", "rad"))
    dh = np.array(nominal.dh)
    dh[1, 0] += 3e-5 * 250.0
    robot = nominal.replace(dh=dh, compliance=np.r_[0.0, 3e-5, np.zeros(4)], moment_ref=np.r_[0.0, 250.0, np.zeros(4)])
    why = "not in the chosen set (lengths); written moved by its joint's compliance ..."
    result = SimpleNamespace(
        nominal=nominal,
        model=SimpleNamespace(robot=robot),
        deltas={"compliance2": (3e-5, 4e-7), "theta2": (7.5e-3, 1e-4)},
        report={"not_estimated": {"theta2": why}, "choice": "lengths + compliance"},
    )
    rows = {r["parameter"]: r for r in dh_rows(result)}
    ref = rows["reference_moment2"]
    assert (ref["unit"], ref["std_error"]) == ("m", None) and "reference_moment1" not in rows
    np.testing.assert_allclose([ref["nominal"], ref["calibrated"]], [0.0, 0.25], rtol=1e-12)
    theta = rows["theta2"]
    assert theta["status"] == f"not estimated: {why}" and theta["std_error"] == pytest.approx(1e-4)
    assert theta["delta"] == pytest.approx(7.5e-3)


def test_a_result_without_the_tables_estimates_refused(tmp_path):
    """``jaxcal.calibrate`` returns no nominal table beside its estimates: the DH table is
    ``calibrate_data``'s, and saying so beats an attribute error."""
    r = jaxcal.preset("ur5")
    sim = jaxcal.simulate(r, n_poses=30, seed=1, sigma_pos=0.0)
    res = jaxcal.calibrate(r, sim.q[0], sim.measured[0, :, :3, 3])
    with pytest.raises(RobotFileError, match="save_dh_table takes the result of jaxcal.calibrate_data"):
        save_dh_table(res, tmp_path / "dh.csv")
    assert not (tmp_path / "dh.csv").exists()
