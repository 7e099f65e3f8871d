"""``jaxcal verify`` and ``jaxcal info``."""

from __future__ import annotations

import typer
from rich.table import Table

from ._app import app, console, load_robot_arg


@app.command()
def verify(points: int = typer.Option(2000, help="random parameter points per check"),
           seed: int = typer.Option(0)):
    """Check every analytic matrix of the paper (eq. 3-10) against jax.jacfwd."""
    from ..errors import DataError
    from ..verify import check_all

    if points < 40:
        raise DataError(f"--points must be >= 40 (the fixed special-angle points come first), got {points}")
    if seed < 0:
        raise DataError(f"--seed must be >= 0, got {seed}")
    rows = check_all(points, seed)
    table = Table(title="analytic vs jax.jacfwd (float64)")
    for col in ("matrix", "max |error|", "tolerance", "ok"):
        table.add_column(col)
    ok_all = True
    for what, err, tol in rows:
        ok = err <= tol
        ok_all &= ok
        table.add_row(what, f"{err:.2e}", f"{tol:.0e}", "yes" if ok else "[red]NO[/red]")
    console.print(table)
    from .. import _native
    in_use, why = _native.status()
    console.print(f"native kernel: {'in use' if in_use else 'not in use'} ({why})")
    console.print("Paper errata: see docs/errata.md")
    raise typer.Exit(0 if ok_all else 1)


@app.command()
def info(robot: str = typer.Argument(..., help="robot TOML file or preset name")):
    """Print a robot's DH table (mm, rad)."""
    import numpy as np

    r = load_robot_arg(robot)
    table = Table(title=f"{r.name} ({r.convention})")
    for col in ("joint", "type", "theta", "d (mm)", "a (mm)", "alpha"):
        table.add_column(col)
    for i, (row, t) in enumerate(zip(np.asarray(r.dh), r.joint_types), start=1):
        table.add_row(str(i), t, *(f"{v:.6g}" for v in row))
    console.print(table)
