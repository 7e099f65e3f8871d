"""``jaxcal verify``: the paper's analytic matrices against autodiff, on this machine."""

from __future__ import annotations

import typer
from rich.table import Table

from ._app import app, console


@app.command()
def verify(points: int = typer.Option(2000, help="random parameter points per check"), seed: int = typer.Option(0)):
    """Check every analytic matrix of the paper (eq. 3-10) against jax.jacfwd."""
    from ..verify import check_all

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
    console.print("These are jaxcal's matrices; where the paper's printed ones differ from them: docs/errata.md")
    raise typer.Exit(0 if ok_all else 1)
