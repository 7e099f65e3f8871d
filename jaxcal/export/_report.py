"""A calibration on one page: a self-contained HTML file (``--report``) with the summary, the
parameters and their standard errors, outliers, the held-out errors and the accuracy map (the
calibrated model's predicted position standard deviation over the workspace,
:func:`jaxcal.calibration.position_std`). Figures are embedded as PNG; nothing is linked."""

from __future__ import annotations

import base64
import html
import io
import itertools

import numpy as np

from .._io import write_atomic
from ..calibration import position_std
from ..model import Model, predict
from ._dh import dh_rows


def _base_frame_positions(model: Model, q) -> np.ndarray:
    """``(K, 3)``: the first measured point (or the tool origin) in the robot's base frame."""
    m = Model(model.robot.replace(base=np.eye(4)), model.points if model.n_points else None)
    p = np.asarray(predict(m, np.asarray(q)))
    return p[:, 0] if model.n_points else p[:, :3, 3]


def accuracy_map(result, q, *, workspace_poses: int = 400, seed: int = 0) -> dict:
    """The accuracy map of a :class:`jaxcal.DataCalibration` whose data had joint values ``q``:
    ``data`` and ``workspace`` (``workspace_poses`` seeded poses uniform within the joint limits)
    as ``(positions (K, 3) in the base frame, predicted sigma (K,) mm)``, the sigma the RMS over a
    pose's points; ``heldout`` the measured held-out error per data pose (NaN for an outlier left
    out of the held-out figures); ``noise_mm`` the final
    fit's noise (``noise_pos_mm``, per coordinate) as an RMS distance, ``sqrt(3)`` times it."""
    from ..plots import heldout_errors

    # the poses the report's held-out figures leave out (outliers, except those of a region)
    left_out = ~np.asarray(result.per_pose["scored"], bool)

    lim = np.asarray(result.nominal.q_limits)
    qw = lim[:, 0] + np.random.default_rng(seed).uniform(size=(workspace_poses, len(lim))) * (lim[:, 1] - lim[:, 0])

    def at(qq):
        s = position_std(result.model, result.layout, result.covariance, qq)
        return _base_frame_positions(result.model, qq), np.sqrt(np.mean(s**2, -1))

    return {
        "data": at(np.asarray(q)),
        "workspace": at(qw),
        "heldout": np.where(left_out, np.nan, heldout_errors(result)[0]),
        "noise_mm": float(np.sqrt(3.0) * result.report["noise_pos_mm"]),
    }


OUTLIER_HEADS = {
    "position_mm": "position error (mm)",
    "rotation_deg": "rotation error (deg)",
    "worst_point_mm": "worst point: error (mm)",
    "threshold_sigmas": "threshold (sigmas)",
    "excluded": "left out of the fit",
}
"""The outlier table's column headings, in the command's words (other keys: spaces for
underscores)."""


def _png(fig) -> str:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _fmt(v) -> str:
    if v is None:
        return "–"
    if isinstance(v, bool) or not isinstance(v, (float, np.floating)):
        return html.escape(str(v))
    return f"{v:.6g}"


def _table(tid: str, head, rows) -> str:
    th = "".join(f"<th>{html.escape(str(h))}</th>" for h in head)
    body = "".join("<tr>" + "".join(f"<td>{_fmt(v)}</td>" for v in r) + "</tr>" for r in rows)
    return f'<table id="{tid}"><thead><tr>{th}</tr></thead><tbody>{body}</tbody></table>'


def _figure(fid: str, fig, caption: str) -> str:
    return (
        f'<figure id="{fid}"><img alt="{html.escape(caption)}" src="data:image/png;base64,{_png(fig)}">'
        f"<figcaption>{html.escape(caption)}</figcaption></figure>"
    )


CSS = (
    "body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}"
    "table{border-collapse:collapse;margin:.5em 0 1.5em}td,th{border:1px solid #ccc;padding:.2em .6em;"
    "text-align:right}th{background:#f3f3f3}td:first-child{text-align:left}img{max-width:100%}"
    "figcaption{font-size:.9em;color:#555}"
)


def _unusable(rep: dict) -> str:
    """A fit not to use (the command refuses to write one; the Python API writes what it is
    given), said first: unconverged or implausible, with the report's reason. Empty otherwise."""
    if not rep["plausible"]:  # its reason says first when the fit did not converge
        why = str(rep["implausible"])
    elif not rep["converged"]:
        why = f"the final fit did not converge in {rep['steps']} step(s)"
    else:
        return ""
    return _box("#c00", "#fee", "Not a calibration to use:", why)


def _box(border: str, background: str, title: str, text: str) -> str:
    """A framed paragraph said before the figures: a bold ``title``, then ``text`` (escaped)."""
    return (
        f'<p style="border:2px solid {border};padding:.5em;background:{background}"><strong>{title}</strong> '
        + html.escape(text)
        + "</p>"
    )


def _worse(rep: dict) -> str:
    """A calibrated model that predicts postures held out worse than the nominal kinematics with
    the frames alone, said before the figures; empty otherwise."""
    said = rep.get("worse_than_frames_only")
    return _box("#c80", "#ffd", "Worse than not calibrating:", said) if said else ""


def _provenance(rep: dict) -> str:
    """What made the page: jaxcal's version, the data's units and the options given."""
    from .. import __version__

    opts = rep.get("options") or {}
    given = ", ".join(
        f"{k} {opts[k]}"
        for k in ("params", "ridge_mm", "compliance", "camera", "keep_outliers", "loss", "sigma_pos_mm")
        if k in opts and opts[k] is not None
    )
    units = rep.get("units") or ["mm", "rad"]
    return (
        f"<p>jaxcal {html.escape(__version__)}; the data read in {html.escape(units[0])} and {html.escape(units[1])} "
        f"(figures here in mm and degrees); options: {html.escape(given)}.</p>"
    )


def _rigid(rep: dict) -> str:
    """What the rigid geometry alone (a URDF in ROS, a UR file, the DH table) errs, beside the
    model with its compliances, for a model that has them; empty otherwise."""
    rigid, bent = rep.get("rigid_geometry_rms_mm_on_the_data"), rep.get("rms_mm_on_the_data_with_compliance")
    if rigid is None or bent is None:
        return ""
    return (
        "<p><strong>Joint compliances</strong> are applied by jaxcal alone (evaluate, compensate, its TOML and "
        "URDF): the rigid geometry that other readers load (a URDF in ROS or MoveIt, a UR kinematics file, the DH "
        f"table without its compliance rows) errs {rigid:.3g} mm RMS on every pose of the data, the model with "
        f"them {bent:.3g} mm (the train RMS above is over the poses fitted); --compliance no fits the best "
        "rigid model.</p>"
    )


def _ranges(rep: dict, robot) -> str:
    """The joint ranges the model was fitted over (the data file's units): beyond them it
    extrapolates."""
    ranges = rep.get("training_ranges")
    if not ranges:
        return ""
    length, angle = rep.get("training_ranges_units") or robot.units
    kind = dict(zip(robot.joint_names, robot.joint_types))
    return "<h2>Training ranges</h2>" + _table(
        "ranges",
        ["joint", "lowest", "highest", "unit"],
        [[name, lo, hi, angle if kind.get(name) == "R" else length] for name, (lo, hi) in ranges.items()],
    )


def _outlier_effect(rep: dict) -> str:
    """What the outliers do to the figures above: left out of them (or fitted), the held-out RMS
    with them scored, and the noise their sigmas are measured in."""
    det = rep.get("outlier_detection") or {}
    if not det:
        return ""
    rot = det.get("heldout_rot_rms_deg_all_poses")
    noise = f"{det['noise_pos_mm']:.3g} mm per coordinate" + (
        f" and {det['noise_rot_deg']:.3g} deg" if det.get("noise_rot_deg") is not None else ""
    )
    with_them = f"{det['heldout_rms_mm_all_poses']:.4g} mm" + (f", {rot:.3g} deg" if rot is not None else "")
    if det.get("excluded"):
        said = f"Left out of the fit and of the figures above; the held-out RMS with them scored: {with_them}"
    else:
        said = "Named, and fitted (--keep-outliers)"
    return f"<p>{said}. Sigmas are in the robust noise of the fit: {noise}.</p>"


def _lost(rep: dict) -> str:
    """The data file's rows read without a pose (every point lost) and the points not seen, as
    the command's notes and the JSON name them; empty when every point was seen."""
    lost, dropped = rep.get("lost_points") or [], rep.get("dropped_rows") or []
    if not lost and not dropped:
        return ""
    said = []
    if dropped:
        said.append(f"rows {', '.join(map(str, dropped))} left out: none of the points read was seen")
    if lost:
        cells = ", ".join(f"row {d['row']} point {d['point']}" for d in lost)
        said.append(f"{len(lost)} point(s) not seen, each fitted without it: {html.escape(cells)}")
    return "<p>Lost markers: " + "; ".join(said) + ".</p>"


def report_html(result, data, *, workspace_poses: int = 400, seed: int = 0) -> str:
    """The report page of a :class:`jaxcal.DataCalibration` of the measurements ``data``
    (:class:`jaxcal.Measurements`; their joint values place the accuracy map), as HTML text."""
    from ..plots import accuracy_figure, parameter_kind, parameters_figure, pose_errors_figure

    rep = result.report
    kind = "nested cross-validation" if rep["nested"] else "K-fold cross-validation"
    parts = [
        f"<h1>Calibration of {html.escape(rep['robot'])}</h1>",
        f"<p>Data: {html.escape(str(rep['data']))}, {rep['poses']} poses, "
        + (f"{rep['points']} measured point(s) per pose" if rep["points"] else "tool poses measured")
        + f". Parameter set: {html.escape(rep['choice'])}. "
        f"Held-out errors from {kind} ({rep['folds']} folds): every pose scored by a model fitted "
        "without it.</p>",
        _provenance(rep),
        _unusable(rep),
        _worse(rep),
        _lost(rep),
        "<h2>Summary</h2>",
        _table(
            "summary",
            [
                "model",
                "train RMS (mm)",
                "held-out RMS: new postures (mm)",
                "beyond the training ranges (mm)",
                "held-out max (mm)",
                "held-out median (mm)",
                "held-out rot RMS (deg)",
            ],
            [
                [
                    "frames only (nominal kinematics)",
                    rep["frames_only_train_rms_mm"],
                    rep["frames_only_heldout_rms_mm"],
                    rep["frames_only_extrapolation_rms_mm"],
                    rep["frames_only_heldout_max_mm"],
                    rep["frames_only_heldout_median_mm"],
                    rep["frames_only_heldout_rot_rms_deg"],
                ],
                [
                    f"calibrated ({rep['choice']}"
                    + ("" if rep["camera_model"] == "none" else f", camera model {rep['camera_model']}")
                    + ")",
                    rep["train_rms_mm"],
                    rep["heldout_rms_mm"],
                    rep["extrapolation_rms_mm"],
                    rep["heldout_max_mm"],
                    rep["heldout_median_mm"],
                    rep["heldout_rot_rms_deg"],
                ],
            ],
        ),  # fmt: skip
        _rigid(rep),
        _table(
            "fit",
            [
                "noise of the fit (mm per coordinate)",
                "weights: sigma_pos (mm)",
                "sigma_rot (deg)",
                "condition number",
                "converged",
                "steps",
                "CV fits converged",
            ],
            [
                [
                    rep["noise_pos_mm"],
                    rep["sigma_pos_mm"],
                    rep["sigma_rot_deg"],
                    rep["condition_number"],
                    rep["converged"],
                    rep["steps"],
                    f"{rep['cv_fits_converged']}/{rep['cv_fits']}",
                ]
            ],
        ),  # fmt: skip
        "<h2>Parameter sets compared</h2>",
        _table(
            "cv",
            ["parameter set", "score (mm)", "new postures (mm)", "beyond the ranges (mm)", "free", "failure"],
            [
                [
                    c["name"] + (" (chosen)" if c["name"] == rep["choice"] else ""),
                    c["score_mm"],
                    c["heldout_rms_mm"],
                    c["extrapolation_rms_mm"],
                    c["free_parameters"],
                    c["failure"] or "",
                ]
                for c in rep["cv"]
            ],
        ),  # fmt: skip
        "<p>Scores are linearised held-out errors of the candidates; "
        + (
            "the chosen set was then pruned to "
            + html.escape(", ".join(rep["selection"]["kept"]) or "no kinematic parameter")
            if rep["selection"]["dropped"]
            else "the chosen set was estimated whole"
        )
        + f" ({html.escape(rep['choice_rule'])}).</p>",
        _ranges(rep, result.nominal),
        "<h2>Parameters</h2>",
        "<p>Kinematic parameters in the robot file's units; a standard error is 1 sigma.</p>",
        _table(
            "parameters",
            ["parameter", "joint", "unit", "nominal", "calibrated", "delta", "std error", "status"],
            [
                [
                    r["parameter"],
                    f"{r['joint']} ({result.nominal.joint_names[r['joint'] - 1]})",
                    r["unit"],
                    r["nominal"],
                    r["calibrated"],
                    r["delta"],
                    r["std_error"],
                    r["status"],
                ]
                for r in dh_rows(result)
            ],
        ),  # fmt: skip
        _table(
            "frames",
            ["frame", "x (mm)", "y (mm)", "z (mm)", "roll (deg)", "pitch (deg)", "yaw (deg)"],
            [
                [
                    k + (" (measurement frame → robot base)" if k == "base" else " (flange → tool)"),
                    *rep[k]["xyz_mm"],
                    *rep[k]["rpy_deg"],
                ]
                for k in ("base", "tool")
            ]
            + [
                [f"point {j} on the tool", *p, None, None, None]
                for j, p in zip(rep.get("point_numbers") or itertools.count(1), rep.get("points_mm") or [])
            ],
        ),  # fmt: skip
    ]
    frame_se = [(k, v) for k, v in result.deltas.items() if k.startswith(("base_", "tool_", "point"))]
    if frame_se:
        parts.append(
            _table("frame-errors", ["frame parameter", "std error", "unit"], [[k, v[1], v[2]] for k, v in frame_se])
        )
    if rep.get("camera_parameters"):  # the sensor's unknowns: values too, as they are in no robot file
        parts.append(
            f"<p>Camera model {html.escape(rep['camera_model'])}: its unknowns, not written to the robot files "
            "(the robot alone does not predict the raw measurements as well).</p>"
        )
        cam = rep["camera_parameters"]
        parts.append(
            _table(
                "camera",
                ["camera parameter", "value", "std error"],
                [[k, v["value"], v["std_error"]] for k, v in cam.items()],
            )
        )
    parts.append("<h2>Outliers</h2>")
    outliers = rep.get("outliers")
    if outliers:
        cols = list(dict.fromkeys(k for o in outliers for k in o))
        heads = [OUTLIER_HEADS.get(c, c.replace("_", " ")) for c in cols]
        parts.append(_table("outliers", heads, [[o.get(c) for c in cols] for o in outliers]))
        parts.append(_outlier_effect(rep))
    else:
        parts.append(
            "<p>No outlier poses reported.</p>"
            if outliers is not None
            else "<p>No outlier analysis in this report.</p>"
        )
    parts.append("<h2>Accuracy map</h2>")
    if result.covariance is not None:
        acc = accuracy_map(result, data.q, workspace_poses=workspace_poses, seed=seed)
        sw, sd = acc["workspace"][1], acc["data"][1]
        parts.append(
            "<p>The calibrated model's predicted position standard deviation (the parameter covariance "
            "propagated through the model, sqrt(trace(J Σ J<sup>T</sup>)), an RMS distance) at "
            f"{len(sw)} poses drawn within the joint limits and at the data's poses, beside the measured held-out "
            "errors. A held-out error adds the measurement noise to the model's: the right panel compares "
            "the measured errors with sqrt(σ<sub>model</sub>² + 3 σ<sub>pos</sub>²).</p>"
            + (
                ""
                if rep["camera_model"] == "none"
                else f"<p>With the camera model ({html.escape(rep['camera_model'])}) the predicted σ is of the "
                "robot alone, its base and tool uncertain by what they trade with the camera unknowns, while the "
                "measured errors are of the measurements the camera model corrects: the panels do not compare "
                "like with like.</p>"
            )
        )
        parts.append(
            _table(
                "accuracy",
                ["poses", "predicted sigma, median (mm)", "predicted sigma, max (mm)"],
                [
                    [
                        "sampled within the joint limits"
                        + ("" if np.all(result.nominal.limits_given()) else " (a turn where the file gives none)"),
                        float(np.median(sw)),
                        float(np.max(sw)),
                    ],
                    ["data poses", float(np.median(sd)), float(np.max(sd))],
                ],
            )  # fmt: skip
        )
        fig = accuracy_figure(acc["workspace"], acc["data"], acc["heldout"], acc["noise_mm"])
        parts.append(
            _figure(
                "accuracy-map",
                fig,
                "accuracy map: predicted std. dev. over the workspace; measured vs predicted held-out errors",
            )
        )
    else:
        parts.append("<p>No parameter covariance in this result.</p>")
    parts += [
        "<h2>Held-out errors</h2>",
        _figure("pose-errors", pose_errors_figure(result), "held-out position error per pose"),
        f"<h2>Estimated {parameter_kind(result.robot)} errors</h2>",
        _figure(
            "parameter-errors",
            parameters_figure(result),
            f"estimated {parameter_kind(result.robot)} errors with 1-sigma error bars",
        ),
    ]
    said = rep.get("worse_than_frames_only")
    notes = [n for n in rep.get("notes", []) if n != said]
    notes += [f"{k}: {v}" for k, v in rep.get("not_estimated", {}).items()]
    if notes:
        parts += ["<h2>Notes</h2>", "<ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in notes) + "</ul>"]
    title = html.escape(f"jaxcal calibration report: {rep['robot']}")
    return (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{title}</title>'
        f"<style>{CSS}</style></head><body>\n" + "\n".join(parts) + "\n</body></html>\n"
    )


def save_report(result, data, path, **kw) -> None:
    """Write :func:`report_html` atomically."""
    write_atomic(path, report_html(result, data, **kw))
