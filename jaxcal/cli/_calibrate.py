"""``jaxcal calibrate``: the real-data workflow (:func:`jaxcal.calibrate_data`)."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table

from ..calibration import Options
from ._app import (
    BASE_LINK_HELP,
    ROBOT_HELP,
    TIP_LINK_HELP,
    app,
    check_outputs,
    console,
    err_console,
    load_robot_arg,
    lost_notes,
    parse_points,
    progress,
)

_D = Options()


def _fmt(v, spec=".3f"):
    return "-" if v is None else format(v, spec)


@app.command()
def calibrate(
    robot: str = typer.Argument(..., help=ROBOT_HELP + ": the nominal model"),
    data: Path = typer.Argument(
        ..., help="measurement CSV: joints (q1..qN or names), x, y, z [, qw, qx, qy, qz] or x1, y1, z1 ... xM, yM, zM"
    ),
    method: str = typer.Option(_D.method, help="gn | lm | linear"),
    params: str = typer.Option(
        _D.params,
        help="auto (chosen by held-out error, down to single parameters) | frames | offsets | angles | all | "
        "comma list of theta, d, a, alpha or names like theta2",
    ),
    ridge_mm: float = typer.Option(
        None,
        "--ridge-mm",
        "--ridge",
        help="prior std on the parameters of an explicit --params: how far (mm) each "
        "is expected to move the measured points",
    ),
    estimate_base: bool = typer.Option(_D.estimate_base, "--estimate-base/--no-estimate-base"),
    estimate_tool: bool = typer.Option(_D.estimate_tool, "--estimate-tool/--no-estimate-tool"),
    camera: str = typer.Option(
        _D.camera,
        "--camera-model",
        help="none | depth | linear | quadratic | auto: a "
        "measurement model of a camera on the flange reporting its pose to a fixed target",
    ),
    compliance: str = typer.Option(
        _D.compliance,
        help="auto | yes | no: a compliance per revolute joint (a turn proportional to the gravity moment of "
        "a weight at the tool) among the candidates (auto: when the moments vary over the data)",
    ),
    loss: str = typer.Option(_D.loss, help="l2 | huber | cauchy (robust to outlier poses)"),
    loss_scale: float = typer.Option(None, help="robust loss scale in units of sigma (default: estimated)"),
    outlier_sigmas: float = typer.Option(
        _D.outlier_sigmas,
        help="a pose whose residual is as improbable as this many sigmas of a normal deviation is an outlier",
    ),
    keep_outliers: bool = typer.Option(
        _D.keep_outliers, "--keep-outliers", help="name the outlier poses but fit them (default: left out)"
    ),
    max_outlier_fraction: float = typer.Option(
        _D.max_outlier_fraction, help="refuse the fit when more than this share of the poses are outliers"
    ),
    sigma_pos_mm: float = typer.Option(
        None, help="position noise per coordinate, the fits' weight (default: the frames-only fit's residual)"
    ),
    sigma_rot_rad: float = typer.Option(
        None,
        help="rotation noise per axis of full poses, the fits' weight (default: the position weight at the "
        "noise's ratio)",
    ),
    max_steps: int = typer.Option(_D.max_steps, help="solver step limit"),
    rtol: float = typer.Option(_D.rtol, help="solver relative tolerance"),
    atol: float = typer.Option(_D.atol, help="solver absolute tolerance"),
    folds: int = typer.Option(_D.folds, help="K of the K-fold cross-validation"),
    seed: int = typer.Option(_D.seed, help="seed of the fold assignment"),
    nested_max_poses: int = typer.Option(_D.nested_max_poses, help="nested cross-validation up to this many poses"),
    memory_mb: float = typer.Option(_D.memory_mb, help="memory budget of the batched fits (MB)"),
    length_unit: str = typer.Option(None, help="m | mm (default: the robot file's)"),
    angle_unit: str = typer.Option(None, help="rad | deg (default: the robot file's)"),
    max_residual_mm: float = typer.Option(
        None, help="plausibility: largest calibrated position RMS (default: 1 % of the robot's reach)"
    ),
    max_rotation_deg: float = typer.Option(_D.max_rotation_deg, help="plausibility: largest rotation RMS"),
    max_length_change_mm: float = typer.Option(
        None, help="plausibility: largest DH length or URDF joint origin shift change (default: 5 % of the reach)"
    ),
    max_angle_change_deg: float = typer.Option(
        _D.max_angle_change_deg, help="plausibility: largest DH angle, URDF joint offset or origin turn change"
    ),
    max_camera_change: float = typer.Option(
        _D.max_camera_change, help="plausibility: largest camera unknown (0.1: positions off by 10 %)"
    ),
    json_out: Path = typer.Option(None, "--json", help="write the JSON report here"),
    out_robot: Path = typer.Option(
        None,
        help="write the calibrated robot here (a DH robot: TOML, one measured point as the tool, several as points; "
        "a URDF robot: its URDF, as --out-model)",
    ),
    out_model: Path = typer.Option(
        None,
        help="write the calibrated model here: URDF (.urdf, a URDF robot: the nominal file with the "
        "corrections in its joints' origins, the measurement frame and the points as links) or, for a DH robot, "
        "TOML",
    ),
    plots: Path = typer.Option(None, help="write plots into this folder"),
    out_ur_kinematics: Path = typer.Option(
        None, help="write the calibrated arm as a UR kinematics file (YAML, ur_robot_driver's kinematics_params_file)"
    ),
    out_dh: Path = typer.Option(None, help="write the DH table: nominal, calibrated, delta, std error (CSV)"),
    report: Path = typer.Option(None, help="write a one-page report (self-contained HTML)"),
    points: str = typer.Option(None, help="use only these measured points, e.g. 1 or 1,3 (default: all)"),
    base_link: str = typer.Option(None, help=BASE_LINK_HELP),
    tip_link: str = typer.Option(None, help=TIP_LINK_HELP),
):
    """Calibrate from measured data with K-fold held-out validation (base and tool estimated)."""
    import warnings

    import numpy as np

    from .._io import all_or_nothing, write_atomic
    from ..calibration import GAUGE, JOINT_GAUGE, calibrate_data
    from ..errors import CalibrationWarning, DataError, ImplausibleFitError
    from ..export import check_dh, check_ur
    from ..kinematics import to_joint
    from ..measurements import joints_left_out, read_measurements
    from ..model import Model, save_model
    from ..robot import PRESETS, UR_BASE, calibrated_chain, read_movable_joints, save_robot

    outputs = {"json_out": json_out, "out_robot": out_robot, "out_model": out_model, "plots": plots}
    outputs |= {"out_ur_kinematics": out_ur_kinematics, "out_dh": out_dh, "report": report}
    check_outputs(outputs, {"robot": robot, "data": data})
    nominal = load_robot_arg(robot, base_link, tip_link)
    # a chain in UR's own frames, from base_link_inertia (UR's base), is written back as a UR file
    from_ur = Path(robot).suffix.lower() in (".yaml", ".yml")
    recorded = calibrated_chain(robot) if robot not in PRESETS else None
    ur_chain = from_ur or UR_BASE in (base_link, recorded and recorded[0])
    if out_ur_kinematics is not None:
        check_ur(nominal, "out_ur_kinematics", ur_chain=ur_chain)
    if out_dh is not None:
        check_dh(nominal, "out_dh")
    if out_ur_kinematics is not None and out_ur_kinematics.suffix.lower() not in (".yaml", ".yml"):
        raise DataError(
            "out_ur_kinematics: a UR kinematics file is YAML (.yaml, .yml); nothing was computed",
            option="out_ur_kinematics",
        )
    for name, path in (("out_robot", out_robot), ("out_model", out_model)):
        if path is not None and path.suffix.lower() in (".yaml", ".yml"):  # read back as UR's format
            raise DataError(
                f"{name}: a robot file is TOML (.toml) or URDF (.urdf); .yaml is --out-ur-kinematics's format; "
                "nothing was computed",
                option=name,
            )
        urdf_out = path is not None and path.suffix.lower() in (".urdf", ".xml")
        # a DH model as URDF: --out-model converts it to joint frames (its points and compliances kept)
        if path is not None and urdf_out != (nominal.convention == "joint") and not (urdf_out and name == "out_model"):
            kind = (
                "a joint-frame robot (a URDF, or a UR factory calibration) is written as URDF (.urdf, .xml)"
                if nominal.convention == "joint"
                else "a DH robot is written as TOML (.toml); --out-model with a .urdf path writes the calibrated "
                "model as a URDF in joint frames"
            )
            raise DataError(f"{name}: {kind}; nothing was computed", option=name)
    chosen = None if points is None else parse_points(points)
    meas = read_measurements(data, nominal, length_unit=length_unit, angle_unit=angle_unit, points=chosen)
    opts = Options(
        method=method,
        params=params,
        ridge_mm=ridge_mm,
        estimate_base=estimate_base,
        estimate_tool=estimate_tool,
        camera=camera,
        compliance=compliance,
        loss=loss,
        loss_scale=loss_scale,
        outlier_sigmas=outlier_sigmas,
        keep_outliers=keep_outliers,
        max_outlier_fraction=max_outlier_fraction,
        sigma_pos_mm=sigma_pos_mm,
        sigma_rot_rad=sigma_rot_rad,
        max_steps=max_steps,
        rtol=rtol,
        atol=atol,
        folds=folds,
        seed=seed,
        nested_max_poses=nested_max_poses,
        memory_mb=memory_mb,
        max_residual_mm=max_residual_mm,
        max_rotation_deg=max_rotation_deg,
        max_length_change_mm=max_length_change_mm,
        max_angle_change_deg=max_angle_change_deg,
        max_camera_change=max_camera_change,
    )
    with progress("calibrating") as bar:
        with warnings.catch_warnings():  # an unusable fit is refused below, in the command's words
            warnings.simplefilter("ignore", CalibrationWarning)
            res = calibrate_data(nominal, meas, opts, progress=bar)
    rep = res.report
    above = base_link or (calibrated_chain(robot) or (None,))[0]  # the chain's base link (None: the root)
    left_out = joints_left_out(meas, nominal, read_movable_joints(robot, above))
    rep["notes"] = list(left_out.values()) + rep["notes"]
    # a model with compliances: its rigid geometry's error on the data, for the files other tools read
    bent = (
        (rep["rms_mm_on_the_data_with_compliance"], rep["rigid_geometry_rms_mm_on_the_data"])
        if ("rigid_geometry_rms_mm_on_the_data" in rep)
        else None
    )
    show(rep, meas)
    # a fit that stopped short is judged where it stopped: refused as implausible only where an
    # input mistake the check names explains it (reversed joints, units, swapped axes), else said
    # not to have converged
    if not rep["converged"] and not rep["likely_input_mistake"]:
        err_console.print(
            f"[red]error:[/red] the final fit did not converge in {rep['steps']} step(s) (--max-steps "
            f"{opts.max_steps}); nothing was written",
            highlight=False,
            soft_wrap=True,
        )
        raise typer.Exit(1)
    if not rep["plausible"]:
        cause = f"; likely: {', '.join(left_out)} moved but is not in the chain (note above)" if left_out else ""
        raise ImplausibleFitError(rep["implausible"] + cause + "; nothing was written")
    # every output or none: one that fails late (a plot, an export) leaves no others behind; what
    # the block says ("written to ...") is said once the files are
    with console.capture() as said, all_or_nothing():
        comment = {
            "data": str(data),
            "heldout_rms_mm": rep["heldout_rms_mm"],
            "choice": rep["choice"],
            "convention": res.robot.convention,
            "gauge": JOINT_GAUGE if res.robot.convention == "joint" else GAUGE,
        }
        writes = any(p is not None for p in (out_robot, out_model, out_ur_kinematics, out_dh))
        if rep["camera_model"] != "none" and writes:  # the files hold the robot alone, not the sensor's model
            from ..calibration import evaluate

            fitted = ~np.isin(meas.rows, [o["row"] for o in rep["outliers"] if o["excluded"]])
            alone = evaluate(Model(res.model.robot, res.model.points), meas.subset(fitted))["position_rms_mm"]
            comment |= {"camera_model": rep["camera_model"], "robot_alone_train_rms_mm": alone}
            console.print(
                f"[yellow]warning:[/yellow] the camera model ({rep['camera_model']}) corrects the camera's "
                f"measurements and is not in the robot files: without it the calibrated robot predicts the "
                f"fitted poses to {alone:.3g} mm RMS (with it {rep['train_rms_mm']:.3g} mm; the held-out "
                f"figures are with it too); its values are the report's camera_parameters",
                highlight=False,
            )
        # the data file's number of each point, so that evaluate and compensate read the same ones
        numbers = meas.numbers or None
        if out_robot is not None and nominal.convention != "joint":
            several = res.model.n_points > 1  # no one point is the tool: they are written beside it
            # one point is the tool's origin, written as the point (0, 0, 0): the file then says that
            # only positions were measured (the tool's orientation is the nominal one, not calibrated)
            points = np.asarray(res.model.points) if several else np.zeros((res.model.n_points, 3))
            save_robot(
                res.robot.replace(name=f"{nominal.name}-calibrated"), out_robot, comment=comment,
                training_ranges=res.training_ranges, points=points, point_numbers=numbers,
            )  # fmt: skip
            console.print(f"calibrated robot written to {out_robot}", soft_wrap=True, highlight=False, markup=False)
            if res.model.n_points == 1:
                console.print(
                    "  its tool origin is the measured point; the tool's orientation was not measured (the nominal "
                    "one), so the file marks the point (`points`) and pose targets are refused",
                    highlight=False,
                )
            if several:
                console.print(
                    f"  with the {res.model.n_points} measured points (`points`, tool frame); its tool frame is where "
                    f"they hang, not one of them",
                    highlight=False,
                )
        # a URDF robot's --out-robot is its model too: the points are links of the written URDF
        for path in (out_robot, out_model) if nominal.convention == "joint" else (out_model,):
            if path is None:
                continue
            urdf = Path(robot) if Path(robot).suffix.lower() in (".urdf", ".xml") else None
            model = Model(res.model.robot.replace(name=f"{nominal.name}-calibrated"), res.model.points)
            to_urdf = Path(path).suffix.lower() in (".urdf", ".xml")
            urdf_bent = bent if to_urdf else None
            if nominal.convention != "joint" and to_urdf:
                model = Model(to_joint(model.robot), model.points)  # the same arm in joint frames
            save_model(
                model, path,
                comment=comment if urdf_bent is None else comment | _rigid_comment(urdf_bent, "URDF readers"),
                template=urdf, base_link=UR_BASE if from_ur else base_link, tip_link=tip_link,
                training_ranges=res.training_ranges,
                point_numbers=numbers,
            )  # fmt: skip
            console.print(f"calibrated model written to {path}", soft_wrap=True, highlight=False, markup=False)
            unit = getattr(meas, "units", ("m",))[0]
            if to_urdf and unit != "m":  # a URDF's data files are read in its metres
                console.print(
                    f"  a URDF is in metres: evaluate or compensate it on data in {unit} with --length-unit {unit}",
                    highlight=False,
                )
            if urdf_bent is not None:
                console.print(
                    f"[yellow]warning:[/yellow] the model has joint compliances, written as <jaxcal_compliance> "
                    f"elements that only jaxcal reads: other URDF readers (ROS, MoveIt) see the rigid geometry, "
                    f"which errs {bent[1]:.3g} mm RMS on the data, the model with them {bent[0]:.3g} mm (every "
                    f"pose); --compliance no fits the best rigid model",
                    highlight=False,
                )
        if json_out is not None:
            write_atomic(json_out, res.to_json())
            console.print(f"report written to {json_out}", soft_wrap=True, highlight=False, markup=False)
        if plots is not None:
            from ..plots import calibration_figures

            for p in calibration_figures(res, plots):
                console.print(f"plot written to {p}", soft_wrap=True, highlight=False, markup=False)
        like = robot if from_ur else None  # the UR file calibrated: its angles' branches are kept
        _write_exports(res, meas, out_ur_kinematics, out_dh, report, comment, bent, ur_chain, like)
    console.file.write(said.get())


def _rigid_comment(bent: tuple[float, float], readers: str) -> dict:
    """Header figures for a file that other tools (``readers``) read as rigid geometry: that
    geometry's error on the data beside the model's with its compliances."""
    return {
        "compliance": f"estimated; {readers} apply the rigid geometry only",
        "rigid_geometry_rms_mm_on_the_data": bent[1],
        "rms_mm_on_the_data_with_compliance": bent[0],
    }


def _write_exports(res, meas, out_ur_kinematics, out_dh, report, comment, bent, ur_chain, like) -> None:
    """The forms other tools load (:mod:`jaxcal.export`), each written atomically; the UR file's angles
    follow ``like``'s, the UR file calibrated (:func:`jaxcal.export.ur_kinematics`)."""
    import numpy as np

    from ..export import save_dh_table, save_report, save_ur_kinematics
    from ..lie import matrix_to_rpy

    if out_ur_kinematics is not None:
        robot = res.robot.replace(name=f"{res.nominal.name}-calibrated")
        # the controller's model is rigid: ``bent`` its figures (:func:`_rigid_figures`), None for a rigid arm
        if bent is not None:
            with_c, without = bent
            # the file's own figure: its rigid geometry's, not the held-out error of the model with compliances
            comment = dict(comment)  # the other files' comment stays as it is
            held = comment.pop("heldout_rms_mm", None)
            comment = comment | {
                "compliance": "estimated, not in this file (rigid geometry only)",
                "rigid_geometry_rms_mm_on_the_data": without,
                "heldout_rms_mm_with_compliance": held,
            }
        base, tool = save_ur_kinematics(robot, out_ur_kinematics, comment=comment, ur_chain=ur_chain, like=like)
        console.print(
            f"UR kinematics written to {out_ur_kinematics}; not in it (set them where you use it):",
            soft_wrap=True,
            highlight=False,
            markup=False,
        )
        for what, T in (("base (measurement frame -> base)", base), ("tool (tool0 -> TCP)", tool)):
            xyz = ", ".join(f"{v:.4f}" for v in T[:3, 3])
            rpy = ", ".join(f"{v + 0.0:.6f}" for v in np.asarray(matrix_to_rpy(np.asarray(T)[:3, :3])))
            console.print(f"  {what}: xyz {xyz} mm, rpy {rpy} rad", highlight=False)
        if bent:
            console.print(
                f"[yellow]warning:[/yellow] the model has joint compliances, which a UR kinematics file cannot hold: "
                f"the file's rigid geometry errs {without:.3g} mm RMS on the data, the model with them {with_c:.3g} mm "
                f"(every pose); --compliance no fits the best rigid model",
                highlight=False,
            )
        if res.model.n_points > 1:
            console.print(
                f"  the {res.model.n_points} measured points are not in it either (tool0 is the TCP there): "
                f"--out-robot CAL.{'urdf' if res.robot.convention == 'joint' else 'toml'} keeps them",
                highlight=False,
            )
    if out_dh is not None:
        save_dh_table(res, out_dh)
        console.print(f"DH table written to {out_dh}", soft_wrap=True, highlight=False, markup=False)
    if report is not None:
        save_report(res, meas, report)
        console.print(f"report written to {report}", soft_wrap=True, highlight=False, markup=False)


def _weight_source(rep: dict, which: str) -> str:
    """Where a fit's weight came from: the option given, else the data (docs/conventions.md)."""
    if rep.get("sigma_given", {}).get(which):
        return "--sigma-pos-mm" if which == "pos" else "--sigma-rot-rad"
    return "the frames-only residual" if which == "pos" else "the noise's ratio to the position's"


def show(rep: dict, meas) -> None:
    """Print a calibration report."""
    from ..measurements import orientation_like

    title = (
        f"candidate models on {rep['poses']} poses ({meas.source}): held-out error of {rep['folds']}-fold and "
        f"{rep['range_end_folds']} range-end folds (linearised)"
    )
    cv = Table(title=title)
    for col in ("parameter set", "score (mm)", "new postures (mm)", "beyond the ranges (mm)", "free"):
        cv.add_column(col, justify="right" if col != "parameter set" else "left")
    for row in rep["cv"]:
        mark = " *" if row["name"] == rep["choice"] else ""
        cv.add_row(
            row["name"] + mark,
            _fmt(row["score_mm"]),
            _fmt(row["heldout_rms_mm"]),
            _fmt(row["extrapolation_rms_mm"]),
            str(row["free_parameters"]),
        )
    console.print(cv)
    for row in rep["cv"]:
        if row.get("failure"):
            console.print(f"[yellow]failed:[/yellow] {row['name']}: {row['failure']}", highlight=False)
    sel = rep["selection"]
    if sel["dropped"]:
        console.print(
            f"selection: {rep['choice']}, {len(sel['dropped'])} parameters dropped (score {sel['score_mm']:.3f} -> "
            f"{sel['pruned_score_mm']:.3f} mm); kept: {', '.join(sel['kept']) or 'none'}",
            highlight=False,
        )
    kind = "nested cross-validation" if rep["nested"] else "K-fold cross-validation"
    summary = Table(title=f"summary (held-out = {kind})")
    cols = ("model", "train RMS (mm)", "held-out: new postures", "beyond the training ranges", "held-out max (mm)")
    for col in cols + (("held-out rot RMS (deg)",) if rep["points"] == 0 else ()):
        summary.add_column(col, justify="right" if col != "model" else "left")
    rot = (lambda v: (_fmt(v),)) if rep["points"] == 0 else (lambda v: ())
    summary.add_row(
        "frames only (nominal kinematics)",
        _fmt(rep["frames_only_train_rms_mm"]),
        _fmt(rep["frames_only_heldout_rms_mm"]),
        _fmt(rep["frames_only_extrapolation_rms_mm"]),
        _fmt(rep["frames_only_heldout_max_mm"]),
        *rot(rep["frames_only_heldout_rot_rms_deg"]),
    )
    cam = rep["camera_model"] != "none" and rep["camera_model_option"] != "auto"
    summary.add_row(
        f"calibrated ({rep['choice']})" + (f" + camera model {rep['camera_model']}" if cam else ""),
        _fmt(rep["train_rms_mm"]),
        _fmt(rep["heldout_rms_mm"]),
        _fmt(rep["extrapolation_rms_mm"]),
        _fmt(rep["heldout_max_mm"]),
        *rot(rep["heldout_rot_rms_deg"]),
    )
    console.print(summary)
    pt = Table(title="estimated parameters (all poses)")
    for col in ("parameter", "delta", "std err", "unit"):
        pt.add_column(col, justify="right")
    moved = [n for n in rep["parameters"] if n in rep["not_estimated"]]  # an offset its compliance moved
    for name, p in rep["parameters"].items():
        pt.add_row(name + " *" * (name in moved), f"{p['value']:+.4g}", f"{p['std_error']:.2g}", p["unit"])
    console.print(pt)
    if moved:
        console.print(
            "*: not estimated; moved by its joint's compliance times the shift of its reference moment to the mean "
            "moment arm over the data (the offset of the arm at its mean load), its error the compliance's times "
            "that shift",
            highlight=False,
        )
    if any(n.startswith(("base_", "tool_")) for n in rep["parameters"]):
        console.print(
            "delta: from the robot file; base_* and tool_*: from the closed-form starting frames (the frames "
            "themselves: base and tool below, and in --json)",
            highlight=False,
        )
    for note in rep.get("notes", []):
        console.print(f"[yellow]note:[/yellow] {note}", highlight=False)
    held = rep["not_estimated"]
    if held:
        console.print("not estimated (held at 0 unless said):")
        for name, why in held.items():
            console.print(f"  {name}: {why}", highlight=False)
    console.print(
        f"noise of the fit {rep['noise_pos_mm']:.3g} mm per coordinate; weights: sigma_pos "
        f"{rep['sigma_pos_mm']:.3g} mm ({_weight_source(rep, 'pos')})"
        + (f", sigma_rot {rep['sigma_rot_deg']:.3g} deg ({_weight_source(rep, 'rot')})" if rep["points"] == 0 else "")
        + f"; condition number {rep['condition_number']:.3g}; converged {rep['converged']} in "
        f"{rep['steps']} step{'' if rep['steps'] == 1 else 's'} "
        f"({rep['cv_fits_converged']}/{rep['cv_fits']} cross-validation fits converged"
        + (f"; {rep['lm_refits']} fitted again by Levenberg-Marquardt after Gauss-Newton" if rep["lm_refits"] else "")
        + ")"
    )
    console.print(
        "base: xyz {} mm, rpy {} deg; tool: xyz {} mm, rpy {} deg".format(
            *(", ".join(f"{v:.2f}" for v in rep[k][u]) for k in ("base", "tool") for u in ("xyz_mm", "rpy_deg"))
        )
    )
    if rep.get("points_mm"):
        for j, p in zip(rep.get("point_numbers") or range(1, len(rep["points_mm"]) + 1), rep["points_mm"]):
            console.print(f"point {j} on the tool: " + ", ".join(f"{v:.2f}" for v in p) + " mm")
    if rep["camera_parameters"]:
        vals = ", ".join(
            f"{k.removeprefix('camera_')} {v['value']:+.5f} ± {v['std_error']:.1g}"
            for k, v in rep["camera_parameters"].items()
        )
        console.print(f"camera model {rep['camera_model']}: {vals} (a sensor property, not written to the robot file)")
    if rep.get("ignored_columns"):
        console.print(f"ignored columns: {', '.join(rep['ignored_columns'])}")
        rot = orientation_like(rep["ignored_columns"])
        if rot and rep["position_only"]:
            console.print(
                f"[yellow]warning:[/yellow] columns {', '.join(rot)} look like orientations; jaxcal reads an "
                "orientation only as a quaternion (qw, qx, qy, qz) beside one point, so this calibration used the "
                "positions alone",
                highlight=False,
            )
    lost_notes(meas)
    show_outliers(rep)


def show_outliers(rep: dict) -> None:
    """The outlier poses by file row, or that there were none, with the threshold."""
    d, found = rep["outlier_detection"], rep["outliers"]
    noise = f"{d['noise_pos_mm']:.3g} mm" + (f", {d['noise_rot_deg']:.3g} deg" if d.get("noise_rot_deg") else "")
    rule = (
        f"a residual beyond {d['threshold_sigmas']:.3g} sigma of the noise ({noise} per coordinate, robust, "
        "over every pose: the outliers too)"
    )
    if not found:
        console.print(f"outliers: none ({rule})")
        return
    t = Table(title=f"{len(found)} outlier pose(s)")
    rot, worst = "rotation_deg" in found[0], "worst_point" in found[0]
    cols = ("row", "position error (mm)") + (("rotation error (deg)",) if rot else ())
    for col in cols + (("worst point: error (mm)",) if worst else ()) + ("sigmas",):
        t.add_column(col, justify="right")
    for o in found:
        cells = [str(o["row"]), f"{o['position_mm']:.3f}"] + ([f"{o['rotation_deg']:.3f}"] if rot else [])
        cells += [f"{o['worst_point']}: {o['worst_point_mm']:.3f}"] if worst else []
        t.add_row(*cells, f"{o['sigmas']:.1f}")
    console.print(t)
    if d["excluded"] and d.get("region"):
        rows = d["region"]["rows"]
        listed = ", ".join(map(str, rows[:8])) + (f" and {len(rows) - 8} more" if len(rows) > 8 else "")
        others = len(found) > len(rows)  # scattered ones besides: out of the figures, as without a region
        console.print(
            f"outliers: {rule}; left out of the fit; rows {listed} lie together in one part of a joint's range "
            "(see the notes) and are counted in the held-out figures"
            + (f"; held-out RMS with the others scored too: {d['heldout_rms_mm_all_poses']:.3f} mm" if others else "")
        )
    elif d["excluded"]:
        console.print(
            f"outliers: {rule}; left out of the fit and of the held-out figures (held-out RMS with them "
            f"scored too: {d['heldout_rms_mm_all_poses']:.3f} mm"
            + (f", {d['heldout_rot_rms_deg_all_poses']:.3g} deg" if d.get("heldout_rot_rms_deg_all_poses") else "")
            + "; --keep-outliers fits them)"
        )
    else:
        console.print(f"outliers: {rule}; kept in the fit (--keep-outliers)")
