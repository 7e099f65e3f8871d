"""``jaxcal info``: a robot's table."""

from __future__ import annotations

import typer
from rich.table import Table

from ._app import BASE_LINK_HELP, ROBOT_HELP, TIP_LINK_HELP, app, console, load_robot_arg


@app.command()
def info(
    robot: str = typer.Argument(..., help=ROBOT_HELP),
    base_link: str = typer.Option(None, help=BASE_LINK_HELP),
    tip_link: str = typer.Option(None, help=TIP_LINK_HELP),
):
    """Print a robot's DH table, or its joint frames (mm, rad)."""
    import numpy as np

    from ..lie import matrix_to_rpy
    from ..robot import PRESETS, calibrated_chain, read_point_numbers, read_robot_file

    r = load_robot_arg(robot, base_link, tip_link)
    table = Table(title=f"{r.name} ({r.convention}, file units {r.units[0]}, {r.units[1]})")
    if r.convention == "joint":
        for col in ("joint", "name", "type", "axis", "origin xyz (mm)", "origin rpy (rad)", "limits (rad; P: mm)"):
            table.add_column(col)
        for i, (O, a, t, n, lim, given) in enumerate(
            zip(
                np.asarray(r.origins), np.asarray(r.axes), r.joint_types, r.joint_names, np.asarray(r.q_limits),
                r.limits_given(),
            ),
            1,
        ):  # fmt: skip
            rpy = np.asarray(matrix_to_rpy(O[:3, :3]))
            table.add_row(
                str(i), n, t, " ".join(f"{v:.3g}" for v in a), " ".join(f"{v:.6g}" for v in O[:3, 3]),
                " ".join(f"{v:.6g}" for v in rpy), _limits(lim, given),
            )  # fmt: skip
    else:
        for col in ("joint", "name", "type", "theta (rad)", "d (mm)", "a (mm)", "alpha (rad)", "limits (rad; P: mm)"):
            table.add_column(col)
        rows = zip(np.asarray(r.dh), r.joint_types, r.joint_names, np.asarray(r.q_limits), r.limits_given())
        for i, (row, t, n, lim, given) in enumerate(rows, start=1):
            table.add_row(str(i), n, t, *(f"{v:.6g}" for v in row), _limits(lim, given))
    console.print(table)
    # the frames a calibration estimates (identity in a nominal file): part of the model as the chain is
    for what in ("base", "tool"):
        T = np.asarray(getattr(r, what))
        xyz = " ".join(f"{v:.6g}" for v in T[:3, 3])
        rpy = " ".join(f"{v:.6g}" for v in np.asarray(matrix_to_rpy(T[:3, :3])))
        console.print(f"{what}: xyz {xyz} mm, rpy {rpy} rad", highlight=False)
    if r.compliance is not None and np.any(np.asarray(r.compliance) != 0):
        # what evaluate and compensate apply and other readers of the file may not: shown, not hidden
        c = ", ".join(f"{n} {v:.4g}" for n, v in zip(r.joint_names, np.asarray(r.compliance)) if v != 0)
        load = None if r.load is None else " ".join(f"{v:.6g}" for v in np.asarray(r.load))
        at = "the tool origin" if load is None else f"xyz {load} mm (tool frame)"
        console.print(f"joint compliances (rad per mm of moment arm): {c}; weight at {at}", highlight=False)
        if r.moment_ref is not None:  # the offsets above hold at these moments, not weightless
            refs = zip(r.joint_names, np.asarray(r.moment_ref), np.asarray(r.compliance))
            m = ", ".join(f"{n} {v:.6g}" for n, v, cj in refs if cj)
            console.print(f"joint offsets hold at the moment arms (mm): {m}", highlight=False)
    if robot not in PRESETS and not robot.lower().endswith((".yaml", ".yml")):  # a UR kinematics file has none
        points = read_robot_file(robot, base_link=base_link, tip_link=tip_link)[1]
        points = np.zeros((0, 3)) if points is None else np.asarray(points)
        numbers = read_point_numbers(robot) or range(1, len(points) + 1)
        for j, pt in zip(numbers, points):
            console.print(f"point {j} on the tool: xyz " + " ".join(f"{v:.6g}" for v in pt) + " mm", highlight=False)
    chain = calibrated_chain(robot)
    if chain is not None:
        console.print(
            f"a calibrated model of the chain {chain[0]} -> {chain[1]}: base = the measurement frame "
            "(jaxcal_measurement_frame), tool = jaxcal_tool",
            highlight=False,
        )


def _limits(lim, given: bool) -> str:
    """A joint's limits; a joint given none says so (its defaults are where poses are drawn)."""
    return f"{lim[0]:.4g} .. {lim[1]:.4g}" if given else f"none (sampled {lim[0]:.4g} .. {lim[1]:.4g})"
