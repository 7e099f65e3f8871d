"""What the report of ``calibrate_data`` says about the data (``jaxcal/calibration/_report.py``)."""

import warnings

import numpy as np
import pytest
from helpers import dh_fk, random_transform

import jaxcal
from jaxcal import Measurements, calibrate_data, preset

MARKERS_MM = np.array([[60.0, 0.0, 40.0], [-50.0, 40.0, 60.0], [0.0, -70.0, 90.0], [30.0, 50.0, 120.0]])


def _four_markers(slip_mm: float, noise3_mm: float = 0.1, marker4_link: int = 6):
    """A UR5 with small DH errors measured at four markers (an independent NumPy FK, 0.1 mm noise,
    marker 3's ``noise3_mm``); marker 3 moved ``slip_mm`` on the tool from pose 26 on; marker 4 on
    link ``marker4_link`` (6: the tool)."""
    rng = np.random.default_rng(5)
    ur5 = preset("ur5")
    dh = np.asarray(ur5.dh) + rng.normal(0.0, [1e-3, 0.3, 0.3, 1e-3], (6, 4))
    q = rng.uniform(-np.pi, np.pi, (50, 6))
    base = random_transform(rng, 1000.0)
    T = dh_fk(dh, q, base=base)
    markers = np.broadcast_to(MARKERS_MM, (50, 4, 3)).copy()
    markers[25:, 2] += slip_mm * np.array([0.6, 0.0, 0.8])
    p = np.einsum("kij,kmj->kmi", T[:, :3, :3], markers) + T[:, None, :3, 3]
    L = dh_fk(dh[:marker4_link], q[:, :marker4_link], base=base)
    p[:, 3] = np.einsum("kij,j->ki", L[:, :3, :3], MARKERS_MM[3]) + L[:, :3, 3]
    return ur5, q, p + rng.normal(scale=[[0.1], [0.1], [noise3_mm], [0.1]], size=p.shape)


def test_the_noise_is_the_measurements_not_the_residuals():
    """30 poses of one point and 25 parameters: the residuals are about ``sqrt(1 - 25/90)``, 0.85,
    of the simulated noise (the fit absorbs the rest); ``noise_pos_mm`` is the noise itself, on
    average over twelve robots (each estimate spreads about 7 %)."""
    rng = np.random.default_rng(41)
    ur5, sigma = preset("ur5"), 0.05
    ratios = []
    for _ in range(12):
        dh = np.asarray(ur5.dh) + rng.normal(0.0, [1e-3, 0.3, 0.3, 1e-3], (6, 4))
        q = rng.uniform(-np.pi, np.pi, (30, 6))
        T = dh_fk(dh, q, base=random_transform(rng, 1000.0))
        tool = np.array([20.0, -30.0, 80.0])
        p = np.einsum("kij,j->ki", T[:, :3, :3], tool) + T[:, :3, 3] + rng.normal(scale=sigma, size=(30, 3))
        rep = calibrate_data(ur5, Measurements(q=q, measured=p[:, None]), params="all", nested_max_poses=0).report
        ratios.append(rep["noise_pos_mm"] / sigma)
    assert 0.92 < np.mean(ratios) < 1.08, ratios


def test_a_marker_that_slipped_on_the_tool_is_named_with_the_row():
    """One noise weight for all markers hides the slip (nothing is an outlier); the step in the
    marker's error relative to the others' names it and where it moved, and the fit is refused:
    one place for the marker fits neither part, and the arm's parameters take up the rest."""
    for slip, named in ((3.0, True), (0.0, False)):
        robot, q, p = _four_markers(slip)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", jaxcal.CalibrationWarning)
            rep = calibrate_data(robot, Measurements(q=q, measured=p), params="all", folds=2).report
        notes = rep["notes"]
        said = [n for n in notes if n.startswith("point 3 seems to have moved on the tool between rows 25 and 26")]
        assert bool(said) == named and all("--points 1,2,4" in n for n in said), notes
        assert not any(n.startswith(("point 1 ", "point 2 ", "point 4 ")) for n in notes)
        assert rep["plausible"] != named
        if named:
            assert (
                "a measured point moved on the tool during the session. Likely cause: point 3 seems"
                in (rep["implausible"])
            )


def test_a_marker_much_noisier_than_the_others_is_named():
    """No step, but marker 3 five times noisier: its held-out error stands out."""
    robot, q, p = _four_markers(0.0, noise3_mm=0.5)
    notes = calibrate_data(robot, Measurements(q=q, measured=p), params="all", folds=2).report["notes"]
    assert any(n.startswith("point 3 errs") and "--points 1,2,4" in n for n in notes), notes
    assert not any("seems to have moved" in n for n in notes)


def test_a_marker_seen_in_few_rows_is_not_blamed_for_its_held_out_error():
    """The bundled TIAGo file with marker 4 kept in three rows only (nothing wrong with it): held
    out, it errs several times the others, since its place on the tool rests on those rows; the
    note says so, not that it moved or is noisy."""
    from jaxcal import load_robot, read_measurements
    from jaxcal.measurements import tiago_paths

    urdf, csv = tiago_paths()
    robot = load_robot(urdf)
    m = read_measurements(csv, robot)
    p = np.array(m.measured, copy=True)
    p[np.setdiff1d(np.arange(len(p)), [0, 23, 28]), 3] = np.nan
    kw = dict(nested_max_poses=0, params="all", ridge_mm=3.0, compliance="no")  # test_outliers' TIAGo fits
    notes = calibrate_data(robot, Measurements(q=m.q, measured=p), **kw).report["notes"]
    assert any(n.startswith("point 4 is seen in only 3 rows") and "--points 1,2,3" in n for n in notes), notes
    assert not any("moved" in n or "mislabelled" in n for n in notes), notes


def test_cross_validation_fits_that_did_not_converge_are_noted():
    """Two steps are too few for most fits: the held-out figures come from where they stopped,
    and the report's notes say how many (the JSON's counts agree), not only a summary count."""
    import warnings

    rng = np.random.default_rng(44)
    ur5 = preset("ur5")
    dh = np.asarray(ur5.dh) + rng.normal(0.0, [1e-3, 0.3, 0.3, 1e-3], (6, 4))
    q = rng.uniform(-np.pi, np.pi, (30, 6))
    p = dh_fk(dh, q, base=random_transform(rng, 1000.0))[:, :3, 3] + rng.normal(0, 0.05, (30, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the final fit's own warning is not the point
        rep = calibrate_data(
            ur5, Measurements(q, p[:, None]), params="all", max_steps=2, compliance="no", nested_max_poses=0
        ).report
    missed = rep["cv_fits"] - rep["cv_fits_converged"]
    said = [n for n in rep["notes"] if "cross-validation fits did not converge" in n]
    assert missed > 0 and len(said) == 1 and said[0].startswith(f"{missed} of the {rep['cv_fits']} ")


def test_a_marker_not_fixed_to_the_tool_is_refused_before_any_fit():
    """Marker 4 on the UR5's fifth link, which joint 6 does not turn (NumPy FK of that link):
    its distances to the tool's three markers change over the rows by millimetres, theirs by the
    noise. Refused before anything is fitted, naming it and the points to keep; with the four
    markers on the tool, nothing is said."""
    from jaxcal.calibration._checks import check_rigid_points

    robot, q, loose = _four_markers(0.0, marker4_link=5)
    with pytest.raises(jaxcal.DataError, match=r"point 4 does not keep its distances to points 1, 2, 3") as e:
        calibrate_data(robot, Measurements(q=q, measured=loose))
    assert "(--points 1,2,3)" in str(e.value)
    with pytest.raises(jaxcal.DataError, match=r"point 4 does not keep"):
        jaxcal.calibrate(robot, q, loose)
    check_rigid_points(_four_markers(0.0)[2])


def test_a_point_seen_only_at_outlier_poses_is_refused():
    """A fifth point (a reflection) seen at four poses only, far from any marker: those poses are
    outliers, and the point's place on the tool is estimated from none. Refused, naming it, its
    rows and the points to keep (the model wrote it at the tool's origin)."""
    robot, q, p = _four_markers(0.0)
    ghost = np.full((50, 1, 3), np.nan)
    ghost[[5, 21, 37, 48], 0] = p[[5, 21, 37, 48], 0] + [[150.0, 20.0, -40.0]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", jaxcal.CalibrationWarning)
        rep = calibrate_data(robot, Measurements(q=q, measured=np.concatenate([p, ghost], 1)), params="all").report
    assert not rep["plausible"]
    assert "point 5 is measured only at rows left out as outliers (6, 22, 38, 49)" in rep["implausible"]
    assert "(--points 1,2,3,4)" in rep["implausible"]
    # a reflection fixed in the room, seen at six poses: five are outliers, the sixth fits it exactly
    fixed = np.full((50, 1, 3), np.nan)
    fixed[[3, 9, 20, 33, 44, 51 - 2]] = [1500.0, 200.0, 900.0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", jaxcal.CalibrationWarning)
        rep = calibrate_data(robot, Measurements(q=q, measured=np.concatenate([p, fixed], 1)), params="all").report
    assert not rep["plausible"] and "point 5 is measured only at rows left out as outliers" in rep["implausible"]
    assert "and at one pose fitted (row " in rep["implausible"] and "checked by none" in rep["implausible"]


def test_a_row_written_twice_is_named():
    """Row 20 of the four-marker UR5 file copied as row 51, to the last digit (a lost point too):
    a note names both rows. A posture measured again (its noise drawn anew) is not named."""
    from jaxcal.calibration._checks import duplicate_rows_note

    robot, q, p = _four_markers(0.0)
    p[19, 1] = np.nan
    rows = np.arange(1, 52)
    twice = duplicate_rows_note(np.r_[q, q[19:20]], np.r_[p, p[19:20]], rows)
    assert len(twice) == 1 and twice[0].startswith("row(s) 51 (row 20) repeat the row named beside them")
    again = p[19:20] + np.random.default_rng(1).normal(0, 0.1, (1, 4, 3))
    assert duplicate_rows_note(np.r_[q, q[19:20]], np.r_[p, again], rows) == ()
    rep = calibrate_data(robot, Measurements(q=np.r_[q, q[19:20]], measured=np.r_[p, p[19:20]]), params="frames")
    assert any(n.startswith("row(s) 51 (row 20) repeat") for n in rep.report["notes"])


def test_a_calibration_worse_than_the_frames_alone_says_so():
    """A UR5 exactly as its table (NumPy FK), 18 poses with 0.3 mm noise: ``params all`` fits the
    noise, and predicts postures held out worse than the nominal kinematics with the frames
    alone. The report says so, with both figures (the page's test: and says nothing of a model
    that predicts better)."""
    ur5 = preset("ur5")
    rng = np.random.default_rng(12)
    q = rng.uniform(-np.pi, np.pi, (18, 6))
    T = dh_fk(np.asarray(ur5.dh), q, base=random_transform(rng, 1000.0))
    p = np.einsum("kij,j->ki", T[:, :3, :3], [30.0, -20.0, 60.0]) + T[:, :3, 3] + rng.normal(0, 0.3, (18, 3))
    rep = calibrate_data(ur5, Measurements(q=q, measured=p[:, None]), params="all").report
    assert rep["heldout_rms_mm"] > rep["frames_only_heldout_rms_mm"]
    said = rep["worse_than_frames_only"]
    assert said.startswith("the calibrated model predicts postures held out worse than the nominal kinematics")
    assert f"new postures {rep['heldout_rms_mm']:.3g} against {rep['frames_only_heldout_rms_mm']:.3g} mm" in said
    assert said in rep["notes"] and "--params auto" in said
