"""``jaxcal design``: calibration poses optimised by gradient, or the best of a candidate pool."""

from __future__ import annotations

import warnings
from pathlib import Path

import typer

from ._app import BASE_LINK_HELP, COMMAND_FLAGS, ROBOT_HELP, TIP_LINK_HELP, app, check_outputs, console, load_robot_arg
from ._conditions import REGION_HELP, SPREAD_HELP, VIEW_HELP, numbers, read_poses_for, region_arg, view_arg


def _given(default: bool, **kw) -> dict:
    """The options given on the command line; with ``default``, the others at their defaults
    (estimated frames, all parameters), else left to the report."""
    defaults = {"estimate_base": True, "estimate_tool": True, "params": "all"}
    return {k: defaults[k] if v is None else v for k, v in kw.items() if v is not None or default}


@app.command(short_help="Design calibration poses (optimised, or chosen from a pool), compared with random ones.")
def design(
    robot: str = typer.Argument(..., help=ROBOT_HELP),
    poses: int = typer.Option(..., "--poses", help="number of poses to design"),
    out: Path = typer.Option(..., "--out", help="pose file to write (CSV: q1..qN or the joint names)"),
    criterion: str = typer.Option(
        "validation", help="validation (expected position RMS from the CRLB) | d (log det) | a (trace of covariance)"
    ),
    pool: Path = typer.Option(None, "--pool", help="candidate pose file: choose the best --poses of its rows"),
    position_only: bool = typer.Option(
        None, "--position-only/--full-pose", help="measure the tool point only (implied by --point)"
    ),
    point: list[str] = typer.Option(
        None, "--point", help="a measured point X,Y,Z on the tool (mm, tool frame); repeat for several"
    ),
    estimate_base: bool = typer.Option(
        None, "--estimate-base/--no-estimate-base", help="estimated (default; or as --params-from's report)"
    ),
    estimate_tool: bool = typer.Option(
        None, "--estimate-tool/--no-estimate-tool", help="estimated (default; or as --params-from's report)"
    ),
    params: str = typer.Option(
        None, help="DH errors calibrated: frames | offsets | angles | all (default) | a comma list"
    ),
    params_from: Path = typer.Option(
        None,
        "--params-from",
        help="a jaxcal calibrate --json report: design for the parameters it estimated (and its base/tool "
        "choice); --params, --estimate-base/--estimate-tool given here win",
    ),
    noise_mm: float = typer.Option(0.02, "--noise-mm", help="position noise sigma (mm)"),
    noise_rad: float = typer.Option(
        None, "--noise-rad", help="rotation noise sigma (rad) of full poses (default 2e-5); none for positions"
    ),
    starts: int = typer.Option(4, help="optimiser starts (gradient design)"),
    seed: int = typer.Option(0),
    min_spread: float = typer.Option(0.0, help=SPREAD_HELP),
    region: str = typer.Option(None, help=REGION_HELP),
    view: str = typer.Option(None, help=VIEW_HELP),
    val_poses: int = typer.Option(200, "--val-poses", help="random validation poses of the validation criterion"),
    validation: Path = typer.Option(
        None,
        "--validation",
        help="pose file of the validation criterion's poses (where the calibrated arm will work); "
        "replaces the --val-poses random ones",
    ),
    random_sets: int = typer.Option(200, "--random-sets", help="random pose sets to compare the design with"),
    limit_margin: float = typer.Option(
        None,
        "--limit-margin",
        help="share of each joint's range a gradient design keeps free at either end of the robot file's limits "
        "(a real arm faults at its hard limits; default 0.02); 0 for none",
    ),
    json_out: Path = typer.Option(None, "--json", help="write the design's summary as JSON"),
    base_link: str = typer.Option(None, help=BASE_LINK_HELP),
    tip_link: str = typer.Option(None, help=TIP_LINK_HELP),
):
    """Design calibration poses: optimised by gradient through the identification Jacobian, or
    chosen from a pool; compared with random poses of the same count."""
    import numpy as np

    from .._io import all_or_nothing, json_text, write_atomic
    from ..design import DEFAULT_POINT_MM, design_problem, optimal_poses, report_points, select_poses, write_poses
    from ..errors import DataError

    COMMAND_FLAGS.update(
        n_poses="--poses", sigma_pos_mm="--noise-mm", sigma_rot_rad="--noise-rad", n_random="--random-sets",
        n_val="--val-poses",
    )  # fmt: skip
    inputs = {"robot": robot, "--pool": pool, "--validation": validation, "--params-from": params_from}
    check_outputs({"out": out, "json_out": json_out}, inputs)
    r = load_robot_arg(robot, base_link, tip_link)
    box, cone = region_arg(region), view_arg(view)
    points = [numbers(p, 3, "point") for p in point] if point else None
    if points and position_only is False:  # a point is measured by its position alone
        raise DataError("--point designs for measured points (positions alone): drop --full-pose", option="point")
    n_points = len(points) if points else int(bool(position_only))
    if params_from is not None and position_only is None and not points:  # measured as the report's data were
        n_points = report_points(params_from)
        if n_points:
            console.print(
                f"measured: positions of {n_points} point(s) on the tool, as in the --params-from calibration "
                "(--full-pose to design for poses; --point to give where they are)",
                highlight=False,
                markup=False,
            )
    candidates = read_poses_for(pool, r, "pool")
    q_val = read_poses_for(validation, r, "validation")
    given = _given(params_from is None, estimate_base=estimate_base, estimate_tool=estimate_tool, params=params)
    with console.status("building the design problem") as status:
        problem = design_problem(
            r,
            criterion=criterion,
            n_points=n_points,
            points=points,
            n_val=val_poses,
            q_val=q_val,
            seed=seed,
            params_from=params_from,
            **({} if limit_margin is None else {"limit_margin": limit_margin}),
            **given,
            sigma_pos_mm=noise_mm,
            sigma_rot_rad=noise_rad,
        )
        status.update(f"designing {poses} poses ({'pool' if pool else 'gradient'}, {criterion})")
        common = dict(min_spread=min_spread, region=box, view=cone, seed=seed, n_random=random_sets)
        if candidates is not None:
            if limit_margin:
                console.print(
                    "[yellow]warning:[/yellow] --limit-margin holds a gradient design; the --pool's rows are "
                    "chosen as they are",
                    highlight=False,
                )
            result = select_poses(problem, candidates, poses, **common)
        else:
            with warnings.catch_warnings():  # refused below, in the command's words
                warnings.filterwarnings("ignore", message="no start met the constraints")
                result = optimal_poses(problem, poses, starts=starts, **common)
    measured = None if problem.model.points is None else np.asarray(problem.model.points)
    if points is None and measured is not None and np.any(measured):
        console.print(
            f"measured point: not given (--point); designed for a point {DEFAULT_POINT_MM:g} mm from the tool "
            "origin in a generic direction, off the last joint's axis as a real marker is"
            + (
                ""
                if criterion == "validation"
                else f"; criterion {criterion} weighs the last joint's parameters through that point's short "
                "lever (under 1 mm from the axis): give --point"
            ),
            highlight=False,
            markup=False,
        )
    if q_val is not None:
        console.print(f"validation poses: {len(q_val)} from {validation}", highlight=False, markup=False)
    elif box is not None or cone is not None:  # the criterion is not where the poses are drawn
        console.print(
            f"validation poses: {val_poses} random within the joint limits, not only in the "
            f"{'region' if box is not None else 'view'}; --validation FILE for where the arm will work",
            highlight=False,
            markup=False,
        )
    if params_from is not None:
        console.print(f"parameters of {params_from}: {', '.join(result.base_names)}", highlight=False, markup=False)
    console.print(result.report(), highlight=False, markup=False, soft_wrap=True)
    if not result.feasible:  # poses that leave the region, the view or the spread are not a design
        given = [o for o, v in (("--region", region), ("--view", view), ("--min-spread", min_spread)) if v]
        raise DataError(
            f"no start met {' and '.join(given) or 'the constraints'}; nothing was written (more --starts, or "
            f"looser {', '.join(given) or 'constraints'})",
            option=(given[0] if given else "--starts").lstrip("-").replace("-", "_"),
        )
    # the pose file and its summary together, or neither; said once written
    with console.capture() as said, all_or_nothing():
        write_poses(out, result.q, r)
        length, angle = r.units
        in_units = f"joint values in {angle}" + (f", {length} for prismatic joints" if "P" in r.joint_types else "")
        console.print(
            f"wrote {out} ({in_units}, the robot file's units)", soft_wrap=True, highlight=False, markup=False
        )
        if json_out is not None:
            summary = result.to_dict()
            summary["validation_poses"] = (
                {"file": str(validation), "count": len(q_val)}
                if q_val is not None
                else {"random": val_poses, "seed": seed, "within": "joint limits"}
            )
            summary["params_from"] = None if params_from is None else str(params_from)
            summary["points_mm"] = None if measured is None or not measured.size else measured.tolist()
            # jaxcal's own units, whatever the robot file's (the pose file --out is in those)
            summary["units"] = {
                "q": "rad, mm for prismatic joints",
                "min_distance": "rad, mm for prismatic joints",
                "pose_file": in_units,
            }
            write_atomic(json_out, json_text(summary))
            console.print(f"wrote {json_out}", soft_wrap=True, highlight=False, markup=False)
    console.file.write(said.get())
