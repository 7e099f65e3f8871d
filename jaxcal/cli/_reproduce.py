"""``jaxcal reproduce``: the paper's Table 2 and Figures 3-6."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import typer
from rich.table import Table

from ._app import app, console


@app.command()
def reproduce(
    out: Path = typer.Option(Path("results"), "--out", help="output folder"),
    seed: int = typer.Option(0, "--seed"),
    noise_mm: float = typer.Option(0.0, "--noise-mm", help="position noise sigma (mm)"),
    noise_rad: float = typer.Option(0.0, "--noise-rad", help="rotation noise sigma (rad)"),
    pairs: int = typer.Option(4, "--pairs", help="pose pairs per elimination step"),
    inspect: int = typer.Option(30, "--inspect", help="inspection poses (not used in calibration)"),
    repeats: int = typer.Option(30, "--repeats", help="timed runs per method"),
):
    """Reproduce the paper's simulation experiment on its Table 1 arm (Table 2, Figs. 3-6)."""
    from .._io import check_writable
    from ..experiments import run_reproduce

    check_writable(out / "summary.json", "out")
    with console.status("starting") as status:
        s = run_reproduce(
            out,
            seed=seed,
            sigma_pos=noise_mm,
            sigma_rot=noise_rad,
            n_pairs=pairs,
            n_inspect=inspect,
            repeats=repeats,
            progress=lambda m: status.update(m),
        )
    t = Table(title=f"Table 2 (injected = paper's 'traditional' column), noise {noise_mm:g} mm / {noise_rad:g} rad")
    METHODS = list(s["time_s"])
    cols = ["parameter", "true"] + METHODS
    short = {"elimination": "elim.", "elimination-literal": "elim. literal"}
    for c in cols:
        t.add_column(short.get(c, c), justify="right")
    with open(out / "table2.csv") as f:
        for row in csv.DictReader(f):
            mark = {"yes": "", "combination": " *"}.get(
                row["identifiable"], " (fixed)" if "fixed" in row["identifiable"] else " (in *)"
            )
            t.add_row(row["parameter"] + mark, *(f"{float(row[c]):.6g}" for c in cols[1:]))
    console.print(t)
    s2 = Table(title="Inspection set and timing")
    for c in ("model", "inspection RMS (mm)", "max param error", "time, median (ms)", "compile (s)", "iterations"):
        s2.add_column(c, justify="right")
    s2.add_row("nominal", f"{s['inspection_rms_mm']['nominal']:.4g}", "", "", "", "")
    for mth in METHODS:
        s2.add_row(
            mth,
            *(
                "no estimate" if math.isnan(v) else f"{v:.3g}"
                for v in (s["inspection_rms_mm"][mth], s["max_param_error"][mth])
            ),
            f"{s['time_s'][mth] * 1e3:.3f}",
            f"{s['compile_s'][mth]:.2f}",
            f"{s['num_steps'][mth]}"
            + (
                ""
                if mth == "linear"  # one step by design
                else (" (converged)" if s["converged"][mth] else " (NOT converged)")
            ),
        )
    console.print(s2)
    for mth, why in s["problems"].items():
        console.print(f"[bold]{mth}[/bold]: {why}")
    console.print(
        f"* identifiable combination; fixed parameters are not identifiable (rank "
        f"{s['identifiable']['rank']}/{s['identifiable']['of']})."
    )
    console.print(
        f"Wrote {out}/: table2.csv, fig3_x.png, fig4_y.png, fig5_z.png, fig6_time.png, summary.json",
        soft_wrap=True,
        highlight=False,
        markup=False,
    )
