"""``jaxcal design``: calibration poses optimised by gradient, or the best of a candidate pool."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import typer

from ._app import app, console, load_robot_arg


def _numbers(text: str, count: int | tuple[int, ...], option: str) -> list[float]:
    from ..errors import DataError

    counts = (count,) if isinstance(count, int) else count
    try:
        out = [float(t) for t in text.split(",")]
    except ValueError:
        out = []
    if len(out) not in counts:
        said = " or ".join(map(str, counts))
        raise DataError(f"{option} must be {said} comma-separated numbers, got {text!r}", option=option)
    return out


def _read_poses_for(path, robot, option: str):
    """The pose file given to ``option`` (None if not given); its errors are said of the option."""
    from ..design import read_poses
    from ..errors import DataError

    if path is None:
        return None
    try:
        return read_poses(path, robot)
    except DataError as e:
        raise DataError(f"{option}: {e}", option=option) from None


@app.command()
def design(
    robot: str = typer.Argument(..., help="robot file (TOML or URDF) or preset name (paper-6r, puma560, ur5, panda)"),
    poses: int = typer.Option(..., "--poses", help="number of poses to design"),
    out: Path = typer.Option(..., "--out", help="pose file to write (CSV: q1..qN or the joint names)"),
    criterion: str = typer.Option(
        "validation", help="validation (expected position RMS from the CRLB) | d (log det) | a (trace of covariance)"
    ),
    pool: Path = typer.Option(None, "--pool", help="candidate pose file: choose the best --poses of its rows"),
    position_only: bool = typer.Option(False, "--position-only/--full-pose", help="measure the tool point only"),
    point: list[str] = typer.Option(
        None, "--point", help="a measured point X,Y,Z on the tool (mm, tool frame); repeat for several"
    ),
    estimate_base: bool = typer.Option(True, "--estimate-base/--no-estimate-base"),
    estimate_tool: bool = typer.Option(True, "--estimate-tool/--no-estimate-tool"),
    params: str = typer.Option("all", help="DH errors calibrated: frames | offsets | angles | all | a comma list"),
    noise_mm: float = typer.Option(0.02, "--noise-mm", help="position noise sigma (mm)"),
    noise_rad: float = typer.Option(2e-5, "--noise-rad", help="rotation noise sigma (rad)"),
    starts: int = typer.Option(4, help="optimiser starts (gradient design)"),
    seed: int = typer.Option(0),
    min_spread: float = typer.Option(0.0, help="smallest joint-space distance between two poses (rad)"),
    region: str = typer.Option(
        None, help="box the measured point(s) must stay in: xmin,ymin,zmin,xmax,ymax,zmax (mm, robot base frame)"
    ),
    view: str = typer.Option(
        None,
        help="a camera's view cone the measured point(s) must stay in: X,Y,Z,DX,DY,DZ,HALF_ANGLE[,NEAR,FAR] "
        "(camera position and viewing direction in mm, robot base frame; half-angle in deg; range along "
        "the axis in mm)",
    ),
    val_poses: int = typer.Option(200, "--val-poses", help="random validation poses of the validation criterion"),
    validation: Path = typer.Option(
        None,
        "--validation",
        help="pose file of the validation criterion's poses (where the calibrated arm will work); "
        "replaces the --val-poses random ones",
    ),
    random_sets: int = typer.Option(200, "--random-sets", help="random pose sets to compare the design with"),
    json_out: Path = typer.Option(None, "--json", help="write the design's summary as JSON"),
):
    """Design calibration poses: optimised by gradient through the identification Jacobian, or
    chosen from a pool; compared with random poses of the same count."""
    from .._io import check_writable, write_atomic
    from ..design import design_problem, optimal_poses, select_poses, write_poses

    check_writable(out, "out")
    if json_out is not None:
        check_writable(json_out, "json_out")
    r = load_robot_arg(robot)
    box = None
    if region is not None:
        v = _numbers(region, 6, "region")
        box = (v[:3], v[3:])
    cone = None
    if view is not None:
        v = _numbers(view, (7, 9), "view")
        cone = (v[:3], v[3:6], np.radians(v[6]), *v[7:])
    points = [_numbers(p, 3, "point") for p in point] if point else None
    n_points = len(points) if points else int(position_only)
    candidates = _read_poses_for(pool, r, "pool")
    q_val = _read_poses_for(validation, r, "validation")
    with console.status("building the design problem") as status:
        problem = design_problem(
            r,
            criterion=criterion,
            n_points=n_points,
            points=points,
            n_val=val_poses,
            q_val=q_val,
            seed=seed,
            estimate_base=estimate_base,
            estimate_tool=estimate_tool,
            params=params,
            sigma_pos_mm=noise_mm,
            sigma_rot_rad=noise_rad,
        )
        status.update(f"designing {poses} poses ({'pool' if pool else 'gradient'}, {criterion})")
        common = dict(min_spread=min_spread, region=box, view=cone, seed=seed, n_random=random_sets)
        if candidates is not None:
            result = select_poses(problem, candidates, poses, **common)
        else:
            result = optimal_poses(problem, poses, starts=starts, **common)
    if q_val is not None:
        console.print(f"validation poses: {len(q_val)} from {validation}", highlight=False, markup=False)
    console.print(result.report(), highlight=False, markup=False, soft_wrap=True)
    write_poses(out, result.q, r)
    console.print(f"wrote {out}")
    if json_out is not None:
        summary = result.to_dict()
        summary["validation_poses"] = (
            {"file": str(validation), "count": len(q_val)} if q_val is not None else {"random": val_poses, "seed": seed}
        )
        write_atomic(json_out, json.dumps(summary, indent=2))
        console.print(f"wrote {json_out}")
