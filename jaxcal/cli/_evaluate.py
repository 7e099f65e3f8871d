"""``jaxcal evaluate``: a saved model's errors on a data file (:func:`jaxcal.evaluate`)."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table

from ._app import BASE_LINK_HELP, ROBOT_HELP, TIP_LINK_HELP, app, check_outputs, console, lost_notes, parse_points


def _fmt(v):
    return "-" if v is None else f"{v:.3f}"


@app.command(short_help="Predict a data file with a saved model (nothing re-fitted); errors in mm and deg.")
def evaluate(
    model: Path = typer.Argument(..., help="a saved model (calibrate --out-model: URDF or TOML), or a " + ROBOT_HELP),
    data: Path = typer.Argument(..., help="measurement CSV, as for calibrate"),
    training: Path = typer.Option(
        None, help="the training CSV: errors by posture group (repeated / new / out of range)"
    ),
    json_out: Path = typer.Option(None, "--json", help="write the JSON report here"),
    points: str = typer.Option(
        None,
        help="score only these of the file's measured points, e.g. 1 or 1,3 (default: the ones the model was "
        "fitted on, as its file records them; else all)",
    ),
    length_unit: str = typer.Option(None, help="m | mm (default: the model file's)"),
    angle_unit: str = typer.Option(None, help="rad | deg (default: the model file's)"),
    base_link: str = typer.Option(None, help=BASE_LINK_HELP),
    tip_link: str = typer.Option(None, help=TIP_LINK_HELP),
):
    """Predict a data file's measurements with a saved model (frames included, nothing
    re-fitted) and report the errors in mm (rotation in deg)."""

    from .._io import json_text, write_atomic
    from ..calibration import evaluate as run
    from ..measurements import joints_left_out, measurement_columns, point_numbers_of, read_measurements, read_table
    from ..model import Model, load_model, model_points

    check_outputs({"json_out": json_out}, {"model": model, "data": data, "--training": training})
    from ..robot import (
        PRESETS,
        calibrated_chain,
        read_movable_joints,
        read_point_numbers,
        read_training_ranges,
    )
    from ._app import load_robot_arg  # a preset (refusing chain links), or a robot file

    nominal = not model.exists() and str(model) in PRESETS  # a preset: the nominal table, never calibrated
    m = (
        Model(load_robot_arg(str(model), base_link, tip_link))
        if nominal
        else load_model(model, base_link=base_link, tip_link=tip_link)
    )
    chosen = None if points is None else parse_points(points)
    src, header, _ = read_table(data, "expected a header row of joint and measurement columns, as for calibrate")
    columns, quat = measurement_columns(header, src)
    in_file = () if quat else point_numbers_of(columns)  # a pose file has no points to choose
    recorded = None if nominal else read_point_numbers(model)
    if recorded is not None and len(recorded) == m.n_points and in_file:
        # the file's points the model was fitted on, by default; a file without the points they
        # name is another export, read as it is
        chosen = chosen or (list(recorded) if set(recorded) <= set(in_file) else None)
        m = m if chosen is None else model_points(m, recorded, chosen)
    elif chosen is not None and 1 < m.n_points == len(in_file):  # the model's points are the file's
        m = model_points(m, in_file, chosen)
    # chosen before the unit checks, so that a point left out (a lost marker's sentinel) is not read
    meas = read_measurements(data, m.robot, length_unit=length_unit, angle_unit=angle_unit, points=chosen)
    train = None
    if training is not None:
        # only its joint values are used: the same points when it has them, so that the file calibrate
        # read with --points is read here (a sentinel in a point left out does not refuse it)
        src, header, _ = read_table(training, "")
        have = set(point_numbers_of(measurement_columns(header, src)[0]))
        same = chosen if chosen is not None and set(chosen) <= have else None
        train = read_measurements(
            training, m.robot, length_unit=length_unit, angle_unit=angle_unit, points=same, drop_unseen=True
        )
    rep = run(m, meas, training=train, ranges=None if nominal else read_training_ranges(model))
    if not nominal:  # the joints above the chain's base link, which move the whole chain
        above = base_link or (calibrated_chain(model) or (None,))[0]
        rep["warnings"] += list(joints_left_out(meas, m.robot, read_movable_joints(model, above)).values())
    if not nominal and model.suffix.lower() in (".yaml", ".yml"):  # UR's format: the arm alone
        rep["warnings"].append(
            f"{model.name} is a UR kinematics file, which holds no base or tool frame: the data are predicted "
            "with the base at the measurement frame and the tool at tool0; the --out-robot file of the same "
            "calibration holds both (its header comments give them too)"
        )
    table = Table(title=f"{model.name} on {meas.source}: {len(meas)} poses, nothing re-fitted")
    for col in ("point", "RMS (mm)", "max (mm)", "median (mm)"):
        table.add_column(col, justify="right")
    numbers = meas.point_numbers or range(1, len(rep["points"]) + 1)  # the file's numbers
    for j, p in zip(numbers, rep["points"]):
        table.add_row(str(j) if meas.n_points else "tool", _fmt(p["rms_mm"]), _fmt(p["max_mm"]), _fmt(p["median_mm"]))
    table.add_row("all", _fmt(rep["position_rms_mm"]), _fmt(rep["position_max_mm"]), _fmt(rep["position_median_mm"]))
    console.print(table)
    lost_notes(meas)
    if rep["ignored_columns"]:
        console.print(f"ignored columns: {', '.join(rep['ignored_columns'])}", highlight=False)
    if "rotation_rms_deg" in rep:
        console.print(f"rotation: RMS {rep['rotation_rms_deg']:.4f} deg, max {rep['rotation_max_deg']:.4f} deg")
    if "groups" in rep:
        groups = Table(title="by posture, relative to the training data")
        for col in ("postures", "poses", "RMS (mm)", "max (mm)"):
            groups.add_column(col, justify="right")
        for name, g in rep["groups"].items():
            groups.add_row(name, str(g["poses"]), _fmt(g["position_rms_mm"]), _fmt(g["position_max_mm"]))
        console.print(groups)
    for w in rep["warnings"]:
        console.print(f"[yellow]warning:[/yellow] {w}", highlight=False)
    if json_out is not None:
        write_atomic(json_out, json_text(rep))
        console.print(f"report written to {json_out}", soft_wrap=True, highlight=False, markup=False)
