"""``jaxcal info``: a robot's table."""

from __future__ import annotations

import typer
from rich.table import Table

from ._app import app, console, load_robot_arg


@app.command()
def info(robot: str = typer.Argument(..., help="robot file (TOML or URDF) or preset name")):
    """Print a robot's DH table (mm, rad)."""
    import numpy as np

    r = load_robot_arg(robot)
    table = Table(title=f"{r.name} ({r.convention}, file units {r.units[0]}, {r.units[1]})")
    for col in ("joint", "name", "type", "theta", "d (mm)", "a (mm)", "alpha"):
        table.add_column(col)
    for i, (row, t, n) in enumerate(zip(np.asarray(r.dh), r.joint_types, r.joint_names), start=1):
        table.add_row(str(i), n, t, *(f"{v:.6g}" for v in row))
    console.print(table)
