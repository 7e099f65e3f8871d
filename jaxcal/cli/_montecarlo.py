"""``jaxcal montecarlo``: N simulated calibrations in one compiled call."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.table import Table

from ._app import app, console, load_robot_arg


@app.command()
def montecarlo(
    robot: str = typer.Argument(..., help="robot TOML file or preset name (paper-6r, puma560, ur5, panda)"),
    robots: int = typer.Option(1000, "--robots", help="number of simulated robots"),
    poses: int = typer.Option(100, "--poses", help="calibration poses per robot"),
    val_poses: int = typer.Option(50, "--val-poses", help="inspection poses per robot"),
    noise_mm: float = typer.Option(0.02, "--noise-mm", help="position noise sigma (mm)"),
    noise_rad: float = typer.Option(2e-5, "--noise-rad", help="rotation noise sigma (rad)"),
    method: str = typer.Option("gn", "--method", help="gn | lm | linear | elimination | elimination-literal"),
    seed: int = typer.Option(0, "--seed"),
    position_only: bool = typer.Option(False, "--position-only/--full-pose"),
    estimate_base: bool = typer.Option(False, "--estimate-base/--no-estimate-base"),
    estimate_tool: bool = typer.Option(False, "--estimate-tool/--no-estimate-tool"),
    repeats: int = typer.Option(3, "--repeats", help="timed runs after the first (compile) call"),
    json_out: Path = typer.Option(None, "--json", help="write the summary as JSON"),
):
    """Calibrate N simulated robots at once; report speed, accuracy vs truth and vs the CRLB.

    Thousands of robots on Linux: set GLIBC_TUNABLES=glibc.malloc.hugetlb=1
    first. XLA's fresh buffers then come in 2 MiB pages: 1.1-1.25x faster
    for 1,000 robots x 100 poses (benchmarks/bench_gn_batch.py).
    """
    from ..calibrate import ELIMINATION_METHODS, METHODS
    from ..errors import DataError
    from ..experiments.montecarlo import run_montecarlo

    r = load_robot_arg(robot)
    if robots < 1 or poses < 1 or val_poses < 1 or repeats < 1:
        raise DataError(f"--robots, --poses, --val-poses and --repeats must be >= 1, got {robots}, {poses}, "
                        f"{val_poses}, {repeats}")
    if method not in METHODS + ELIMINATION_METHODS:
        raise DataError(f"--method must be one of {', '.join(METHODS + ELIMINATION_METHODS)}, got {method!r}")
    if not (noise_mm >= 0 and noise_rad >= 0):
        raise DataError(f"--noise-mm and --noise-rad must be >= 0, got {noise_mm}, {noise_rad}")
    with console.status("starting") as status:
        out = run_montecarlo(r, n_robots=robots, n_poses=poses, n_val=val_poses, sigma_pos=noise_mm,
                             sigma_rot=noise_rad, method=method, seed=seed, position_only=position_only,
                             estimate_base=estimate_base, estimate_tool=estimate_tool, repeats=repeats,
                             progress=lambda s: status.update(f"{s} ({robots} robots x {poses} poses, {method})"))
    t = Table(title=f"Monte Carlo: {r.name}, {robots} robots x {poses} poses, {method}")
    t.add_column("quantity")
    t.add_column("value", justify="right")
    rows = [("robots / second (after compile)", f"{out['robots_per_second']:,.0f}"),
            ("run time, median (s)", f"{out['run_seconds']:.3f}"),
            ("compile time (s)", f"{out['compile_seconds']:.2f}"),
            ("converged", f"{out['converged_fraction']:.1%} (max {out['max_steps_taken']} steps)"),
            ("rank / parameters", f"{out['rank']} / {out['n_params']}"),
            ("fixed (not identifiable)", ", ".join(out["fixed"]) or "none"),
            ("identifiable combinations", "; ".join(out["combinations"]) or "none"),
            ("parameter RMS error vs truth, worst", f"{out['param_rms_error_max']:.3g}"),
            ("validation position RMS (mm)", f"{out['validation_pos_rms_mm']:.4g}")]
    if "crlb_efficiency_mean" in out:
        rows.append(("CRLB efficiency (CRLB var / empirical var), mean", f"{out['crlb_efficiency_mean']:.3f}"))
    for k, v in rows:
        t.add_row(k, v)
    console.print(t)
    if json_out:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps(out, indent=2))
        console.print(f"wrote {json_out}")
