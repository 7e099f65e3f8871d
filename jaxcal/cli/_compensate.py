"""``jaxcal compensate``: joint commands that make the calibrated model reach targets."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table

from ._app import PRESET_NAMES, app, check_outputs, console, load_robot_arg

NEAR_SHARE = 0.01
"""Targets without commands that all lie within this share of the reach of the measurement
frame's origin, where targets were missed, get a hint: metres read as millimetres?"""


@app.command(short_help="Joint commands that make the calibrated model reach the targets (damped Newton IK).")
def compensate(
    calibrated: str = typer.Argument(
        ...,
        help="calibrated robot file (e.g. from calibrate --out-robot), or a preset name ("
        + ", ".join(PRESET_NAMES)
        + ")",
    ),
    targets: Path = typer.Argument(..., help="CSV with x, y, z [, qw, qx, qy, qz] and/or the joint columns"),
    nominal: str = typer.Option(
        None,
        help="nominal robot (file or preset): targets = where it puts the tool at the file's joint values, "
        "relative to its base (they move with the calibrated base frame)",
    ),
    out: Path = typer.Option(
        None,
        help="write the compensated joint commands here (CSV), headed as the targets' joint columns "
        "(or the robot's joint names)",
    ),
    length_unit: str = typer.Option(
        None, help="m | mm (default: the robot file's); also the unit of prismatic commands written to --out"
    ),
    angle_unit: str = typer.Option(None, help="rad | deg (default: the robot file's); also the unit written to --out"),
    point: int = typer.Option(
        None,
        help="a model with measured points (--out-model): the point to bring to the targets, by its number in the "
        "data file it was fitted to (default: its only one)",
    ),
):
    """Joint commands that make the calibrated model reach the targets (damped Newton IK), on
    the branch of the nominal commands and checked against the joint limits. Targets without
    joint columns start from the middle of the joint limits: give commands near them where
    several branches can reach them."""
    import numpy as np

    from .._io import write_atomic
    from ..compensation import (
        MAX_MOVE_DEG,
        check_orientation,
        compensate_targets,
        frame_note,
        quaternion_note,
        read_targets,
        tool_note,
    )
    from ..measurements import unit_scale
    from ..robot import ANGLE_UNITS, LENGTH_UNITS, calibrated_chain

    check_outputs({"out": out}, {"calibrated robot": calibrated, "targets": targets, "--nominal": nominal})
    model = _model_of(calibrated)
    nom = None
    if nominal is not None:  # a nominal URDF: the chain the calibrated URDF records
        chain = calibrated_chain(calibrated)
        urdf = Path(nominal).suffix.lower() in (".urdf", ".xml") and calibrated_chain(nominal) is None
        nom = load_robot_arg(nominal, *(chain if chain and urdf else (None, None)))
    tg = read_targets(targets, model.robot, length_unit=length_unit, angle_unit=angle_unit)
    check_orientation(model.n_points, tg, str(calibrated))
    cal = _target_frame(model, calibrated, point, commands_only=tg.poses is None)
    if note := tool_note(model.n_points, cal, nom, str(calibrated), commands_only=tg.poses is None):
        console.print(f"[yellow]warning:[/yellow] {note}", highlight=False)
    poses, res = compensate_targets(cal, tg, nominal=nom)
    rot = not (tg.poses is not None and tg.position_only)  # position targets: no rotation was asked for
    table = Table(title=f"compensation of {len(res.q)} targets")
    for col in ("", "position residual (mm)", "rotation residual (deg)")[: 3 if rot else 2]:
        table.add_column(col, justify="right")
    rms = [np.sqrt(np.mean(res.pos_residual_mm**2)), np.sqrt(np.mean(res.rot_residual_deg**2))]
    table.add_row("max", *(f"{v:.3g}" for v in [res.pos_residual_mm.max(), res.rot_residual_deg.max()][: 1 + rot]))
    table.add_row("RMS", *(f"{v:.3g}" for v in rms[: 1 + rot]))
    console.print(table)
    n_ok, n_in, n_br, K = int(res.converged.sum()), int(res.within_limits.sum()), int(res.on_branch.sum()), len(res.q)
    console.print(
        f"reached: {n_ok}/{K} (max {int(res.steps.max())} steps); within the joint limits: {n_in}/{K}"
        + (f"; on the commands' branch: {n_br}/{K}" if tg.q is not None else "")
    )
    if tg.q is not None:
        rev = np.array([t == "R" for t in cal.joint_types])
        d = np.asarray(res.q - tg.q)
        moved = np.abs(np.where(rev, (d + np.pi) % (2 * np.pi) - np.pi, d))  # a whole turn into the limits: none
        parts = [f"{np.degrees(moved[:, rev].max()):.4g} deg"] if rev.any() else []
        parts += [f"{moved[:, ~rev].max():.4g} mm"] if (~rev).any() else []
        console.print(f"largest joint correction: {', '.join(parts)}")
    bad = np.flatnonzero(~res.ok)
    names = list(cal.joint_names)
    for k in bad[:10]:
        why = []
        if not res.converged[k]:
            why.append("not reached")
        out_of = np.flatnonzero(res.outside[k])
        if out_of.size:
            why.append(f"outside the joint limits ({', '.join(names[j] for j in out_of)})")
        if not res.on_branch[k]:
            why.append(
                f"a joint turned more than {MAX_MOVE_DEG:g} deg from its start: another branch of the inverse "
                "kinematics, or a singularity"
            )
        console.print(f"  row {int(tg.rows[k])}: {'; '.join(why)}", highlight=False)
    if bad.size > 10:
        console.print(f"  ... and {bad.size - 10} more (--out flags every row)", highlight=False)
    if out is not None:
        lu = unit_scale(length_unit, LENGTH_UNITS, "length_unit", cal.units[0])[0]
        au = unit_scale(angle_unit, ANGLE_UNITS, "angle_unit", cal.units[1])[0]
        scale = np.array([au if t == "R" else lu for t in cal.joint_types])
        flag_names = ["reached", "within_limits", "on_branch"]
        header = (
            list(tg.joint_columns or cal.joint_names) + ["pos_residual_mm", "rot_residual_deg"][: 1 + rot] + flag_names
        )
        lines = [",".join(header)]
        flags = np.stack([res.converged, res.within_limits, res.on_branch], -1).astype(int)
        for qk, ep, er, f in zip(res.q / scale, res.pos_residual_mm, res.rot_residual_deg, flags):
            values = [repr(float(v)) for v in qk] + [repr(float(ep)), repr(float(er))][: 1 + rot] + [str(v) for v in f]
            lines.append(",".join(values))
        write_atomic(out, "\n".join(lines) + "\n")
        console.print(
            f"compensated commands written to {out} (rows to send: reached, within_limits and on_branch = 1)",
            soft_wrap=True,
            highlight=False,
            markup=False,
        )
    if bad.size:
        hint = (
            "; without joint columns every solve starts at the middle of the joint limits: give the nominal "
            "commands (or any near each target) as joint columns beside the targets"
            if tg.q is None
            else ""
        )
        for note in (quaternion_note(cal, tg), frame_note(cal, tg)):
            hint += f"; {note}" if note else ""
        near = float(np.max(np.linalg.norm(np.asarray(poses)[:, :3, 3], axis=1)))
        if tg.q is None and near < NEAR_SHARE * cal.reach():  # a hint only: probes about a datum are fine
            hint += (
                f"; the targets all lie within {near:.4g} mm of the measurement frame's origin, under "
                f"{NEAR_SHARE:.0%} of the reach: written in metres (--length-unit m)?"
            )
        console.print(
            f"[yellow]warning:[/yellow] {bad.size} target(s) not reached, outside the joint limits or off the "
            f"starting commands' branch{hint}",
            highlight=False,
        )
        raise typer.Exit(1)


def _model_of(calibrated: str):
    from ..model import Model, load_model
    from ..robot import PRESETS

    return Model(load_robot_arg(calibrated)) if calibrated in PRESETS else load_model(calibrated)


def _target_frame(model, calibrated: str, point: int | None, *, commands_only: bool):
    """The robot whose tool is what the targets are for: for target positions, a model's
    measured point (the one the data determined; its tool frame is only where the points hang);
    for commands only, the tool, where the nominal robot puts its own."""

    from ..errors import DataError
    from ..model import Model, measured_robot, model_points
    from ..robot import read_point_numbers

    M = model.n_points
    if point is not None and (M == 0 or commands_only):
        why = "has no measured points" if M == 0 else "is given commands only: the targets are the nominal tool's"
        raise DataError(f"--point: {calibrated} {why}", option="point")
    if M == 0 or commands_only:
        return model.robot
    # the points by their numbers in the data file, where the model file records them
    numbers = read_point_numbers(calibrated)
    numbers = list(numbers) if numbers is not None and len(numbers) == M else list(range(1, M + 1))
    named = ", ".join(map(str, numbers))
    if point is None and M > 1:
        raise DataError(
            f"{calibrated} measures {M} points (the data file's {named}): choose the one the targets are for with "
            f"--point",
            option="point",
        )
    j = numbers[0] if point is None else point
    one = model_points(model, numbers, [j], option="point")
    console.print(
        f"compensating measured point {j} (the model's points: {named}; the targets are where it should go)",
        highlight=False,
    )
    return measured_robot(Model(one.robot, one.points))
