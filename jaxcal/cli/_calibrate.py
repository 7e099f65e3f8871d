"""``jaxcal calibrate`` (real data, cross-validated) and ``jaxcal compensate``."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.table import Table

from ._app import app, console, load_robot_arg


def _fmt(v, spec=".3f"):
    return "-" if v is None else format(v, spec)


@app.command()
def calibrate(
    robot: str = typer.Argument(..., help="robot TOML file or preset name (the nominal model)"),
    data: Path = typer.Argument(..., help="measurement CSV: q1..qN, x, y, z [, qw, qx, qy, qz]"),
    method: str = typer.Option("gn", help="gn | lm | linear"),
    params: str = typer.Option("auto", help="auto (chosen by cross-validation) | frames | offsets | angles | all | "
                                            "comma list of theta, d, a, alpha or names like theta2"),
    ridge: float = typer.Option(None, help="ridge prior std on DH errors for an explicit --params "
                                           "(mm for lengths, mrad for angles)"),
    estimate_base: bool = typer.Option(True, "--estimate-base/--no-estimate-base"),
    estimate_tool: bool = typer.Option(True, "--estimate-tool/--no-estimate-tool"),
    folds: int = typer.Option(5, help="K of the K-fold cross-validation"),
    length_unit: str = typer.Option(None, help="m | mm (default mm)"),
    angle_unit: str = typer.Option(None, help="rad | deg (default rad)"),
    json_out: Path = typer.Option(None, "--json", help="write the JSON report here"),
    out_robot: Path = typer.Option(None, help="write the calibrated robot TOML here"),
    plots: Path = typer.Option(None, help="write plots into this folder"),
    seed: int = typer.Option(0, help="seed of the fold assignment"),
    camera_model: str = typer.Option("none", help="none | depth | linear | quadratic | auto: also estimate a "
                                                  "measurement model of a camera on the flange that reports its pose "
                                                  "w.r.t. a fixed target (depth scale, a 3x3 linear map of the "
                                                  "position, or that plus a field term quadratic in the image "
                                                  "coordinates); auto chooses among them by cross-validation"),
):
    """Calibrate from measured data with K-fold held-out validation (base and tool estimated)."""
    from ..crossval import calibrate_measurements
    from ..errors import DataError
    from ..measurements import read_measurements
    from ..robot_io import save_robot

    nominal = load_robot_arg(robot)
    meas = read_measurements(data, nominal, length_unit=length_unit, angle_unit=angle_unit)
    if ridge is not None and ridge <= 0:
        raise DataError(f"--ridge must be positive, got {ridge}")
    res = calibrate_measurements(nominal, meas.q, meas.poses, position_only=meas.position_only, method=method,
                                 params=params, ridge_mm=ridge, estimate_base=estimate_base,
                                 estimate_tool=estimate_tool, folds=folds, seed=seed, rows=meas.rows,
                                 camera=camera_model)
    rep = dict(res.report, data=str(data))
    rot = not meas.position_only

    cv = Table(title=f"{folds}-fold cross-validation on {len(meas)} poses ({meas.source})")
    for col in ("parameter set", "held-out RMS (mm)", "held-out max (mm)", "held-out rot RMS (deg)",
                "train RMS (mm)"):
        cv.add_column(col, justify="right" if col != "parameter set" else "left")
    for row in rep["cv"]:
        mark = " *" if row["name"] == rep["choice"] else ""
        cv.add_row(row["name"] + mark, _fmt(row["heldout_rms_mm"]), _fmt(row["heldout_max_mm"]),
                   _fmt(row["heldout_rot_rms_deg"] if rot else None), _fmt(row["train_rms_mm"]))
    console.print(cv)

    summary = Table(title="summary (held-out = nested cross-validation)")
    for col in ("model", "train RMS (mm)", "held-out RMS (mm)", "held-out max (mm)", "held-out rot RMS (deg)"):
        summary.add_column(col, justify="right" if col != "model" else "left")
    summary.add_row("frames only (nominal DH)", _fmt(rep["frames_only_train_rms_mm"]),
                    _fmt(rep["frames_only_heldout_rms_mm"]), _fmt(rep["frames_only_heldout_max_mm"]),
                    _fmt(rep["frames_only_heldout_rot_rms_deg"]))
    cam = rep["camera_model"] != "none" and rep["camera_model_option"] != "auto"   # auto: in the choice's name
    summary.add_row(f"calibrated ({rep['choice']})" + (f" + camera model {rep['camera_model']}" if cam else ""),
                    _fmt(rep["train_rms_mm"]), _fmt(rep["heldout_rms_mm"]),
                    _fmt(rep["heldout_max_mm"]), _fmt(rep["heldout_rot_rms_deg"]))
    console.print(summary)

    pt = Table(title="estimated DH errors (all poses)")
    for col in ("parameter", "delta", "std err", "unit"):
        pt.add_column(col, justify="right")
    for name, p in rep["parameters"].items():
        if not name.startswith(("base_", "tool_")):
            pt.add_row(name, f"{p['value']:+.4g}", f"{p['std_error']:.2g}", p["unit"])
    console.print(pt)
    console.print(f"chosen parameter set: [bold]{rep['choice']}[/bold] ({rep['choice_rule']}); "
                  f"held at 0 (not identifiable, absorbed by base/tool): {', '.join(rep['unidentifiable']) or 'none'}")
    console.print(f"weights: sigma_pos {rep['sigma_pos_mm']:.3g} mm"
                  + (f", sigma_rot {rep['sigma_rot_deg']:.3g} deg" if rot else "")
                  + f" (frames-only residual); condition number {rep['condition_number']:.3g}; "
                  f"converged {rep['converged']} in {rep['steps']} steps "
                  f"({rep['cv_fits_converged']}/{rep['cv_fits']} cross-validation fits converged)")
    console.print("base: xyz {} mm, rpy {} deg; tool: xyz {} mm, rpy {} deg".format(
        *(", ".join(f"{v:.2f}" for v in rep[k][u]) for k in ("base", "tool") for u in ("xyz_mm", "rpy_deg"))))
    if rep["camera_parameters"]:
        vals = ", ".join(f"{k.removeprefix('camera_')} {v['value']:+.5f} ± {v['std_error']:.1g}"
                         for k, v in rep["camera_parameters"].items())
        console.print(f"camera model {rep['camera_model']}: {vals} (the camera reports t' = (I + A) t"
                      + (" + z Q (u², v², uv)" if rep["camera_model"] == "quadratic" else "")
                      + " for the target origin t in its axes; a sensor property, not written to the robot file)")
    if out_robot is not None:
        save_robot(res.robot, out_robot)
        console.print(f"calibrated robot written to {out_robot}")
    if json_out is not None:
        Path(json_out).parent.mkdir(parents=True, exist_ok=True)
        Path(json_out).write_text(json.dumps(rep, indent=2))
        console.print(f"report written to {json_out}")
    if plots is not None:
        from ..report import write_plots

        for p in write_plots(res, plots):
            console.print(f"plot written to {p}")
    if not rep["converged"]:
        console.print("[yellow]warning:[/yellow] the final fit did not converge")
        raise typer.Exit(1)


@app.command()
def compensate(
    calibrated: str = typer.Argument(..., help="calibrated robot TOML (e.g. from calibrate --out-robot)"),
    targets: Path = typer.Argument(..., help="CSV with x, y, z [, qw, qx, qy, qz] and/or q1..qN"),
    nominal: str = typer.Option(None, help="nominal robot (TOML or preset): targets = its FK of q1..qN"),
    out: Path = typer.Option(None, help="write the compensated joint commands here (CSV)"),
    length_unit: str = typer.Option(None, help="m | mm (default mm)"),
    angle_unit: str = typer.Option(None, help="rad | deg (default rad); also the unit written to --out"),
):
    """Joint commands that make the calibrated model reach the targets (damped Newton IK)."""
    import numpy as np

    from ..compensate import compensate_targets, read_targets
    from ..measurements import ANGLE_UNITS

    cal = load_robot_arg(calibrated)
    nom = load_robot_arg(nominal) if nominal is not None else None
    tg = read_targets(targets, cal, length_unit=length_unit, angle_unit=angle_unit)
    _, res = compensate_targets(cal, tg, nominal=nom)
    n_ok = int(res.converged.sum())
    table = Table(title=f"compensation of {len(res.q)} targets")
    for col in ("", "position residual (mm)", "rotation residual (deg)"):
        table.add_column(col, justify="right")
    table.add_row("max", f"{res.pos_residual_mm.max():.3g}", f"{res.rot_residual_deg.max():.3g}")
    table.add_row("RMS", f"{np.sqrt(np.mean(res.pos_residual_mm ** 2)):.3g}",
                  f"{np.sqrt(np.mean(res.rot_residual_deg ** 2)):.3g}")
    console.print(table)
    console.print(f"converged: {n_ok}/{len(res.q)} (max {int(res.steps.max())} steps)")
    if tg.q is not None:
        dq = np.degrees(np.abs(res.q - tg.q).max())
        console.print(f"largest joint correction: {dq:.4g} deg")
    if out is not None:
        au = ANGLE_UNITS[angle_unit or "rad"]
        scale = np.array([au if t == "R" else 1.0 for t in cal.joint_types])
        lu = {"mm": 1.0, "m": 1000.0}[length_unit or "mm"]
        scale = np.where(np.array([t == "P" for t in cal.joint_types]), lu, scale)
        header = [f"q{j}" for j in range(1, cal.n_joints + 1)] + ["pos_residual_mm", "rot_residual_deg", "converged"]
        lines = [",".join(header)]
        for qk, ep, er, ok in zip(res.q / scale, res.pos_residual_mm, res.rot_residual_deg, res.converged):
            lines.append(",".join([repr(float(v)) for v in qk] + [repr(float(ep)), repr(float(er)), str(int(ok))]))
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        Path(out).write_text("\n".join(lines) + "\n")
        console.print(f"compensated commands written to {out}")
    if n_ok < len(res.q):
        console.print(f"[yellow]warning:[/yellow] {len(res.q) - n_ok} target(s) did not converge")
        raise typer.Exit(1)
