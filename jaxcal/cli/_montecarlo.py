"""``jaxcal montecarlo``: N simulated calibrations, in chunks shared over devices, resumable."""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path

import typer
from rich.table import Table

from ._app import (
    BASE_LINK_HELP,
    ROBOT_HELP,
    TIP_LINK_HELP,
    app,
    check_outputs,
    console,
    err_console,
    load_robot_arg,
    progress,
)
from ._conditions import REGION_HELP, SPREAD_HELP, VIEW_HELP, numbers, read_poses_for, region_arg, view_arg


@contextlib.contextmanager
def _kept_on_interrupt(out_dir):
    """Ctrl-C during a study with a folder: one line saying what is kept, exit 130 at once (as
    :func:`jaxcal.cli.main` does for every command; its line says nothing was written)."""
    try:
        yield
    except KeyboardInterrupt:
        if out_dir is None:
            raise
        err_console.print(
            f"interrupted: the finished chunks are kept in {out_dir}; rerun to continue",
            soft_wrap=True,
            highlight=False,
            markup=False,
        )
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)


def _conditions_line(c: dict, n_val: int) -> str:
    """The study's conditions in a line: where the calibration and inspection poses came from
    (given poses: whether they meet the conditions, as checked)."""
    conds = []
    if c["region"]:
        conds.append("in the box")
    if c["view"]:
        conds.append(f"in the view cone ({c['view']['half_angle_deg']:g} deg)")
    if c["min_spread"]:
        conds.append(f"{c['min_spread']:g} apart")
    if c.get("given_poses_meet_conditions") is False:
        conds = ["NOT all " + " and ".join(conds)]
    where = [f"calibration poses {c['calibration_poses']}", *conds]
    if c["acceptance"] is not None:
        where.append(f"{c['acceptance']:.0%} of random configurations admitted")
    return ", ".join(where) + f"; {n_val} inspection poses {c['validation_poses']}"


@app.command()
def montecarlo(
    robot: str = typer.Argument(..., help=ROBOT_HELP),
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
    base_link: str = typer.Option(None, help=BASE_LINK_HELP),
    tip_link: str = typer.Option(None, help=TIP_LINK_HELP),
    poses_file: Path = typer.Option(
        None, "--poses-file", help="calibrate every robot on these poses (a pose file, e.g. from jaxcal design)"
    ),
    devices: str = typer.Option("all", "--devices", help="devices to share the robots over: all | N"),
    out_dir: Path = typer.Option(
        None, "--out", help="study folder: each chunk's results written as it completes; a rerun continues"
    ),
    memory_mb: float = typer.Option(1024.0, "--memory-mb", help="memory budget of a chunk of robots (MB)"),
    max_chunks: int = typer.Option(None, "--max-chunks", help="stop after this many chunks (rerun to continue)"),
    region: str = typer.Option(None, help=REGION_HELP + "; constrains the random calibration poses"),
    view: str = typer.Option(None, help=VIEW_HELP + "; constrains the random calibration poses"),
    min_spread: float = typer.Option(0.0, help=SPREAD_HELP + "; constrains the random calibration poses"),
    validation: Path = typer.Option(
        None, "--validation", help="pose file of the inspection poses (where the calibrated arm will work)"
    ),
    outliers: float = typer.Option(0.0, "--outliers", help="share of each robot's poses given a gross position error"),
    outlier_mm: str = typer.Option("3,6", "--outlier-mm", help="A,B: the gross errors' length, uniform in [A, B] mm"),
    keep_outliers: bool = typer.Option(False, "--keep-outliers", help="fit the outlier poses (default: left out)"),
    point: list[str] = typer.Option(
        None,
        "--point",
        help="X,Y,Z: the measured point on the tool (mm, tool frame), as `design --point` took it (one point)",
    ),
):
    """Calibrate N simulated robots; report speed, accuracy vs truth and vs the CRLB."""
    import numpy as np

    from .._io import check_writable, json_text, write_atomic
    from ..errors import DataError
    from ..experiments import run_montecarlo

    inputs = {"robot": robot, "--poses-file": poses_file, "--validation": validation}
    check_outputs({"json_out": json_out}, inputs)
    if out_dir is not None:
        check_writable(out_dir / "study.json", "out")
        own = json_out is not None and json_out.resolve().parent == out_dir.resolve()
        if own and (json_out.name in ("study.json", "summary.json") or json_out.name.startswith("chunk-")):
            raise DataError(f"json_out {json_out}: is one of the study's own files in --out; write it elsewhere",
                            option="json_out")  # fmt: skip
    r = load_robot_arg(robot, base_link, tip_link)
    if point and len(point) > 1:  # the study measures one point: the tool origin, put there
        raise DataError(
            f"--point given {len(point)} times: montecarlo measures one point on the tool; judge a design for "
            "several points by each point alone, or with jaxcal.design's criteria",
            option="point",
        )
    point = point[0] if point else None
    if point is not None:  # the study measures the tool origin: put it at the point
        if not position_only:
            raise DataError("--point: a measured point is measured by position alone; add --position-only",
                            option="point")  # fmt: skip
        at = np.eye(4)
        at[:3, 3] = numbers(point, 3, "point")
        r = r.replace(tool=np.asarray(r.tool) @ at)
    q = read_poses_for(poses_file, r, "poses_file")
    poses = poses if q is None else len(q)
    q_val = read_poses_for(validation, r, "validation")
    with progress(f"{robots} robots x {poses} poses, {method}") as bar, _kept_on_interrupt(out_dir):
        out = run_montecarlo(
            r,
            n_robots=robots,
            n_poses=poses,
            n_val=val_poses,
            sigma_pos=noise_mm,
            sigma_rot=noise_rad,
            method=method,
            seed=seed,
            position_only=position_only,
            estimate_base=estimate_base,
            estimate_tool=estimate_tool,
            repeats=repeats,
            q=q,
            progress=bar,
            devices=devices,
            out=out_dir,
            memory_mb=memory_mb,
            max_chunks=max_chunks,
            region=region_arg(region),
            view=view_arg(view),
            min_spread=min_spread,
            q_val=q_val,
            outliers=outliers,
            outlier_mm=_pair(outlier_mm),
            keep_outliers=keep_outliers,
        )
    files = {"calibration_poses_file": poses_file, "validation_poses_file": validation}
    out["conditions"] |= {k: str(v) for k, v in files.items() if v is not None}
    if point is not None:
        out["conditions"]["point_mm"] = [float(v) for v in at[:3, 3]]
    if not out["complete"]:
        console.print(
            f"stopped after {out['chunks_done']} of {out['chunks']} chunks ({out['robots_done']} robots): "
            f"rerun the same command to continue"
        )
    t = Table(
        title=f"Monte Carlo: {r.name}, {out['robots_done']} of {robots} robots x {out['n_poses']} poses, {method}"
    )
    t.add_column("quantity")
    t.add_column("value", justify="right")
    timed = out["robots_per_second"] is not None  # None: nothing run warm (every chunk done before, or --repeats 0)
    rows = [
        ("devices", ", ".join(out["devices"])),
        ("chunks (robots each)", f"{out['chunks_done']} / {out['chunks']} ({out['chunk_robots']})"),
        ("robots / second (after compile)", f"{out['robots_per_second']:,.0f}" if timed else "-"),
        ("compile time (s)", f"{out['compile_seconds']:.2f}" if timed else "-"),
        ("converged", f"{out['converged_fraction']:.1%} (max {out['max_steps_taken']} steps)"),
        ("rank / parameters", f"{out['rank']} / {out['n_params']}"),
        ("fixed (not identifiable)", ", ".join(out["fixed"]) or "none"),
        ("identifiable combinations", "; ".join(out["combinations"]) or "none"),
        ("parameter RMS error vs truth, worst", f"{out['param_rms_error_max']:.3g}"),
        ("validation position RMS (mm)", f"{out['validation_pos_rms_mm']:.4g}"),
    ]
    if "outliers" in out or out["false_alarms"]:
        rows.append(
            (
                "outlier poses found / missed; clean poses flagged",
                f"{out['outliers_found']} / {out['outliers_missed']}; {out['false_alarms']}"
                + (" (kept in the fits)" if keep_outliers else ""),
            )
        )
    if "crlb_efficiency_mean" in out:
        each = out["crlb_efficiency_rel_se_each"]
        lo, hi = 100 * min(each.values()), 100 * out["crlb_efficiency_rel_se"]
        se = f"{lo:.2g} %" if f"{lo:.2g}" == f"{hi:.2g}" else f"{lo:.2g} to {hi:.2g} %"
        rows.append(
            (
                "CRLB efficiency (CRLB var / mean squared error against the truth), mean",
                f"{out['crlb_efficiency_mean']:.3f} (each parameter's ± {se})",
            )
        )
        worst = out["crlb_efficiency_worst"]
        rows.append(
            (
                "CRLB efficiency, worst parameter",
                f"{worst['parameter']} {worst['efficiency']:.3f} (± {100 * each[worst['parameter']]:.2g} %)",
            )
        )
    if "crlb_validation_pos_rms_mm" in out:
        rows.append(("validation position RMS by the CRLB (mm)", f"{out['crlb_validation_pos_rms_mm']:.4g}"))
    rows.append(("conditions", _conditions_line(out["conditions"], out["n_val"])))
    for k, v in rows:
        t.add_row(k, v)
    console.print(t)
    if out["converged_fraction"] < 1:  # the figures are over every robot, converged or not
        stopped = out["robots_done"] - round(out["converged_fraction"] * out["robots_done"])
        pairs = (
            "; one pose pair per elimination step: more --poses give more pairs"
            if out["elimination_pairs_per_step"] == 1
            else ""
        )
        console.print(
            f"[yellow]warning:[/yellow] {stopped} of {out['robots_done']} robots did not converge (most steps "
            f"taken: {out['max_steps_taken']}); the figures above include their estimates{pairs}",
            highlight=False,
        )
    for note in out.get("still_joints") or ():
        console.print(
            f"[yellow]warning:[/yellow] calibration poses: {note}; the validation RMS includes the robots' errors in "
            "what it holds, which the CRLB (of the parameters estimated) leaves out",
            highlight=False,
        )
    if out.get("crlb_efficiency_note"):
        console.print(f"[yellow]warning:[/yellow] {out['crlb_efficiency_note']}", highlight=False)
    if out["conditions"].get("given_poses_meet_conditions") is False:
        console.print(
            "[yellow]warning:[/yellow] some of the given calibration poses are outside the --region/--view or "
            "closer than --min-spread: the study calibrates on them as given",
            highlight=False,
        )
    if json_out and out["complete"]:  # a summary of part of a study is not written
        write_atomic(json_out, json_text(out))
        console.print(f"wrote {json_out}", soft_wrap=True, highlight=False, markup=False)


def _pair(text: str) -> tuple[float, float]:
    """``--outlier-mm A,B``."""
    from ..errors import DataError

    try:
        a, b = (float(v) for v in text.split(","))
    except ValueError:
        raise DataError(f"outlier_mm must be A,B in mm (e.g. 3,6), got {text!r}", option="outlier_mm") from None
    return a, b
