"""The one-page report (`--report`): one self-contained HTML file whose tables and embedded
figures are there, parsed with the standard library's HTML parser."""

import base64
import dataclasses
from html.parser import HTMLParser

import numpy as np
import pytest
from helpers import UR5_TRACKER, ur5_tracker

from jaxcal.export import report_html


class Page(HTMLParser):
    """Tables (id -> header cells, body rows), images (figure id -> src), headings, outside links."""

    def __init__(self, text):
        super().__init__()
        self.tables, self.images, self.headings, self.external = {}, {}, [], []
        self._table = self._figure = self._cell = None
        self._row, self._in = None, []
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        for key in ("src", "href"):
            if key in a and not a[key].startswith("data:"):
                self.external.append(a[key])
        if tag == "table":
            self._table = a["id"]
            self.tables[self._table] = {"head": [], "rows": []}
        elif tag == "figure":
            self._figure = a["id"]
        elif tag == "img":
            self.images[self._figure] = a["src"]
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th", "h1", "h2"):
            self._cell = ""
        if tag not in ("img", "meta", "br", "link"):  # void elements have no end tag
            self._in.append(tag)

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data

    def handle_endtag(self, tag):
        self._in.pop()
        if tag in ("td", "th"):
            self._row.append(self._cell)
            self._cell = None
        elif tag in ("h1", "h2"):
            self.headings.append(self._cell)
            self._cell = None
        elif tag == "tr":
            t = self.tables[self._table]
            (t["head"].extend(self._row) if "thead" in self._in else t["rows"].append(self._row))
        elif tag == "table":
            self._table = None


@pytest.fixture(scope="module")
def page():
    """The report of the UR5 tracker calibration, with two outlier poses reported."""
    _, _, data, res = ur5_tracker()
    rep = dict(
        res.report,
        outliers=[{"row": 7, "residual_mm": 0.61, "position_mm": 0.6}, {"row": 19, "residual_mm": 0.4, "z": 4.2}],
    )
    res = dataclasses.replace(res, report=rep)
    return Page(report_html(res, data, workspace_poses=150)), res


def test_tables(page):
    p, res = page
    rep = res.report
    assert {"summary", "fit", "cv", "parameters", "frames", "accuracy", "outliers"} <= set(p.tables)
    summary = p.tables["summary"]
    assert summary["head"][:4] == [
        "model",
        "train RMS (mm)",
        "held-out RMS: new postures (mm)",
        "beyond the training ranges (mm)",
    ]
    assert float(summary["rows"][1][2]) == pytest.approx(rep["heldout_rms_mm"], rel=1e-5)
    assert float(summary["rows"][0][2]) == pytest.approx(rep["frames_only_heldout_rms_mm"], rel=1e-5)
    params = p.tables["parameters"]
    assert [r[0] for r in params["rows"]] == res.nominal.param_names()
    a2 = params["rows"][res.nominal.param_names().index("a2")]
    assert a2[1] == "2 (q2)"  # the joint by number and name (a URDF's chain numbers are not its names)
    assert float(a2[4]) == pytest.approx(float(np.asarray(res.robot.dh)[1, 2]), rel=1e-5)
    assert float(a2[6]) == pytest.approx(res.deltas["a2"][1], rel=1e-5)  # its standard error
    ranges = p.tables["ranges"]["rows"]  # the joint ranges fitted over, in the file's units
    assert [r[0] for r in ranges] == list(res.nominal.joint_names) and {r[3] for r in ranges} == {"rad"}
    lo, hi = res.report["training_ranges"]["q3"]
    assert [float(v) for v in ranges[2][1:3]] == pytest.approx([lo, hi], rel=1e-5)
    outliers = p.tables["outliers"]
    # headed in words: the command's for the keys it prints, spaces for underscores otherwise
    assert outliers["head"] == ["row", "residual mm", "position error (mm)", "z"]
    assert outliers["rows"][0][:3] == ["7", "0.61", "0.6"]
    assert "Accuracy map" in p.headings and "Outliers" in p.headings


def test_a_camera_model_is_named_with_its_values():
    """A calibration with a camera model: the summary row names it, and its unknowns are shown with
    their values (they are in no robot file), not only their standard errors."""
    _, _, data, res = ur5_tracker()
    cam = {"camera_depth_scale": {"value": -0.00723, "std_error": 0.00156}}
    rep = dict(res.report, camera_model="depth", camera_parameters=cam)
    p = Page(report_html(dataclasses.replace(res, report=rep), data, workspace_poses=20))
    assert p.tables["summary"]["rows"][1][0].endswith(", camera model depth)")
    assert p.tables["camera"]["rows"] == [["camera_depth_scale", "-0.00723", "0.00156"]]
    html = report_html(dataclasses.replace(res, report=rep), data, workspace_poses=20)
    assert "the panels do not compare like with like" in html


def test_figures_embedded(page):
    p, _ = page
    assert set(p.images) == {"accuracy-map", "pose-errors", "parameter-errors"}
    for src in p.images.values():
        assert src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"
    assert p.external == []  # self-contained: nothing to fetch


def test_accuracy_table_from_the_covariance(page):
    """The accuracy table's figures are the predicted sigma at the data's poses."""
    from jaxcal.calibration import position_std

    p, res = page
    _, _, data, _ = ur5_tracker()
    sd = position_std(res.model, res.layout, res.covariance, data.q)[:, 0]
    row = p.tables["accuracy"]["rows"][1]
    assert row[0] == "data poses"
    assert float(row[1]) == pytest.approx(np.median(sd), rel=1e-5)
    assert float(row[2]) == pytest.approx(np.max(sd), rel=1e-5)


def test_the_accuracy_maps_noise_is_the_fits_not_its_weights():
    """Without a given noise the fits are weighted by the frames-only residual, which holds the
    robot's own errors (mm here): the map adds the calibrated fit's noise, the simulated 0.05 mm
    per coordinate, and the predicted held-out RMS is that of the held-out errors measured, the
    two outliers left out of both."""
    import jaxcal
    from jaxcal.export import accuracy_map
    from jaxcal.simulation import simulate

    ur5 = jaxcal.preset("ur5")
    rng = np.random.default_rng(37)
    q = rng.uniform(-np.pi, np.pi, (UR5_TRACKER["n_poses"], 6))
    s = UR5_TRACKER["sigma_pos"]
    sim = simulate(ur5, n_robots=1, q=q, q_val=q[:5], seed=38, sigma_pos=s, base=True, tool=True)
    points = sim.measured[0, :, None, :3, 3].copy()
    points[[3, 11], 0] += [5.0, -4.0, 3.0]  # two gross outliers, left out of the fit and of the figures
    data = jaxcal.Measurements(q, points)
    res = jaxcal.calibrate_data(ur5, data, folds=UR5_TRACKER["folds"], params=UR5_TRACKER["params"])
    assert sorted(o["row"] for o in res.report["outliers"]) == [4, 12]
    assert res.report["sigma_pos_mm"] > 10 * s  # the weights: the robot's errors, not the noise
    acc = accuracy_map(res, q, workspace_poses=20)
    assert np.flatnonzero(np.isnan(acc["heldout"])).tolist() == [3, 11]
    assert acc["noise_mm"] == pytest.approx(np.sqrt(3) * s, rel=0.25)
    predicted = np.sqrt(np.mean(acc["data"][1] ** 2) + acc["noise_mm"] ** 2)
    measured = np.sqrt(np.nanmean(np.asarray(acc["heldout"]) ** 2))
    assert 0.6 < predicted / measured < 1.6
    clean = jaxcal.Measurements(q, sim.measured[0, :, None, :3, 3])
    huber = jaxcal.calibrate_data(ur5, clean, folds=UR5_TRACKER["folds"], params="all", loss="huber", loss_scale=1.0)
    assert huber.report["noise_pos_mm"] == pytest.approx(s, rel=0.25)  # a given loss scale does not set it


def test_lost_markers_and_rows_without_any_are_named():
    """The page says what the command's notes and the JSON say: rows read without a pose and the
    points not seen, by the file's row and point numbers."""
    _, _, data, res = ur5_tracker()
    rep = dict(res.report, lost_points=[{"row": 4, "point": 1}, {"row": 9, "point": 1}], dropped_rows=[20])
    text = report_html(dataclasses.replace(res, report=rep), data, workspace_poses=20)
    assert "rows 20 left out: none of the points read was seen" in text
    assert "2 point(s) not seen, each fitted without it: row 4 point 1, row 9 point 1" in text
    assert "Lost markers" not in report_html(res, data, workspace_poses=20)


def test_a_fit_not_to_use_says_so_first(page):
    """The command refuses to write such a fit; the Python API writes what it is given, and the
    page says first why it is not a calibration to use: the reason of an implausible fit (which
    names a fit that did not converge), or the steps of one that did not converge."""
    _, _, data, res = ur5_tracker()
    said = "Not a calibration to use:"
    assert said not in report_html(res, data, workspace_poses=20)
    assert "Estimated DH errors" in page[0].headings
    from jaxcal import load_robot
    from jaxcal.measurements import tiago_paths
    from jaxcal.plots import parameter_kind

    assert parameter_kind(load_robot(tiago_paths()[0])) == "joint-frame"  # a URDF's heading names its frames
    unconverged = dict(res.report, converged=False, steps=1)
    text = report_html(dataclasses.replace(res, report=unconverged), data, workspace_poses=20)
    assert f"{said}</strong> the final fit did not converge in 1 step(s)" in text
    assert text.index(said) < text.index("<h2>Summary</h2>")
    why = "not a calibration: d2 changes by 80 mm, more than 59.6 mm (max_length_change_mm)"
    implausible = dict(res.report, plausible=False, implausible=why)
    text = report_html(dataclasses.replace(res, report=implausible), data, workspace_poses=20)
    assert f"{said}</strong> {why}" in text


def test_what_the_figures_leave_out_is_said_beside_them():
    """An explicit parameter set is said to be given (nothing chosen or pruned); outliers left
    out of the figures come with the held-out RMS with them scored and the noise their sigmas are
    in; a model with compliances says what its rigid geometry errs; one worse than the frames
    alone says so before the summary."""
    _, _, data, res = ur5_tracker()
    text = report_html(res, data, workspace_poses=20)
    assert res.report["worse_than_frames_only"] is None and "Worse than not calibrating" not in text
    assert res.report["choice_rule"].startswith("given (params") and "the chosen set was estimated whole" in text
    det = dict(res.report["outlier_detection"], excluded=True, heldout_rms_mm_all_poses=0.7311, noise_pos_mm=0.052)
    rep = dict(res.report, outlier_detection=det, outliers=[{"row": 7, "position_mm": 0.6}])
    rep |= {"rigid_geometry_rms_mm_on_the_data": 3.36, "rms_mm_on_the_data_with_compliance": 2.43}
    rep |= {"worse_than_frames_only": "the calibrated model predicts postures held out worse (test)"}
    rep["notes"] = [*rep["notes"], rep["worse_than_frames_only"]]
    text = report_html(dataclasses.replace(res, report=rep), data, workspace_poses=20)
    assert "the held-out RMS with them scored: 0.7311 mm" in text and "robust noise of the fit: 0.052 mm" in text
    assert "errs 3.36 mm RMS on every pose of the data, the model with them 2.43 mm" in text
    box = "Worse than not calibrating:</strong> the calibrated model predicts postures held out worse (test)"
    assert text.index(box) < text.index("<h2>Summary</h2>") and text.count("held out worse (test)") == 1
