"""The Typer application shared by every ``jaxcal`` command: consoles, progress display, and how
library errors are said on the command line."""

from __future__ import annotations

import contextlib
import re
from pathlib import Path

import typer
from rich.console import Console

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Calibrate the geometry of serial robot arms (JAX, float64).",
)
console = Console()
err_console = Console(stderr=True)

FLAGS = {"camera": "--camera-model", "json_out": "--json", "data": "DATA", "robot": "ROBOT"}
"""Library option names whose command-line spelling is not ``--`` + the name with dashes."""
COMMAND_FLAGS: dict[str, str] = {}
"""The running command's own spellings of library option names (set by the command: ``design``
says ``--poses`` for ``n_poses``)."""


NAMED_BESIDE = ("base_link", "tip_link")
"""Options a message may name in parentheses beside the one it is about."""


def flag(option: str) -> str:
    return COMMAND_FLAGS.get(option) or FLAGS.get(option, "--" + option.replace("_", "-"))


def check_outputs(outputs: dict, inputs: dict) -> None:
    """Each of ``outputs`` (option name -> path or None; ``plots``, a folder) writable
    (:func:`jaxcal._io.check_writable`), none of them one of the ``inputs`` (how the command names
    it -> path, preset name or None) and no two of them one file: else a :class:`DataError` naming
    both, before any work (an output would silently replace the data it was computed from, or
    another output)."""
    from .._io import check_writable
    from ..errors import DataError

    given = {k: Path(v) for k, v in outputs.items() if v is not None}
    for name, path in given.items():
        check_writable(path / "x.png" if name == "plots" else path, name)
    read = {k: Path(v).resolve() for k, v in inputs.items() if v is not None and Path(v).is_file()}
    seen: dict[Path, str] = {}
    for name, path in given.items():
        where = path.resolve()
        for other, src in read.items():
            if where == src:
                raise DataError(f"{name} {path}: is the {other} file; it would be overwritten", option=name)
        if where in seen:
            raise DataError(f"{name} {path}: is also {flag(seen[where])}; each output needs its own file", option=name)
        seen[where] = name


def say_error(message: str, option: str | None) -> str:
    """A library error in the command line's words: the option's name, where the message starts
    with it or names it in parentheses, becomes its flag."""
    for other in NAMED_BESIDE:  # a message about one link option names the other too
        message = message.replace(f"({other})", f"({flag(other)})")
    if not option:
        return message
    if message.startswith(option):
        message = flag(option) + message[len(option) :]
    message = re.sub(rf'\b{option}="([^"]*)"', lambda m: f"{flag(option)} {m.group(1)}", message)
    return message.replace(f"({option})", f"({flag(option)})")


def load_robot_arg(robot: str, base_link: str | None = None, tip_link: str | None = None):
    """A robot file (TOML or URDF; ``base_link``/``tip_link`` choose a URDF's chain) or a preset
    name."""
    from ..robot import PRESETS, load_robot, preset

    if robot in PRESETS:
        if base_link is not None or tip_link is not None:
            from ..errors import DataError

            option = "base_link" if base_link is not None else "tip_link"
            raise DataError(f"{robot}: a preset; base_link and tip_link choose the chain of a URDF file", option=option)
        return preset(robot)
    return load_robot(robot, base_link=base_link, tip_link=tip_link)


PRESET_NAMES = ("paper-6r", "puma560", "ur5", "ur10e", "panda")
"""The presets as help texts name them; written out, since the help is shown before jax loads
(a test keeps it equal to :data:`jaxcal.robot.PRESETS`)."""
ROBOT_HELP = f"robot file (TOML or URDF) or preset name ({', '.join(PRESET_NAMES)})"
BASE_LINK_HELP = "URDF: the chain's first link (default: a calibrated model's own, else the root)"
TIP_LINK_HELP = "URDF: the chain's last link (default: a calibrated model's own, else the one leaf)"


@contextlib.contextmanager
def progress(what: str):
    """A ``progress(done, total, stage)`` callback drawing rich's progress bar on a terminal;
    silent in pipes and CI (rich draws nothing where the console is not a terminal)."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    if not console.is_terminal:
        yield None
        return
    bar = Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=console,
        transient=True,
    )
    tasks: dict[str, int] = {}

    def update(done: int, total: int, stage: str) -> None:
        if stage not in tasks:
            tasks[stage] = bar.add_task(f"{what}: {stage}", total=total)
        bar.update(tasks[stage], completed=done, total=total)

    with bar:
        yield update


def parse_points(text: str) -> list[int]:
    """``--points 1,3`` as point numbers."""
    from ..errors import DataError

    try:
        return [int(p) for p in text.split(",") if p.strip()]
    except ValueError:
        raise DataError(f"points must be point numbers like 1 or 1,3, got {text!r}", option="points") from None


def lost_notes(meas, most: int = 10) -> None:
    """Print the points not seen (lost markers) and the rows dropped for having none."""
    lost = meas.lost_points
    if lost:
        listed = ", ".join(f"row {r} point {j}" for r, j in lost[:most]) + (", ..." if len(lost) > most else "")
        console.print(f"[yellow]note:[/yellow] {len(lost)} point(s) not seen, left out: {listed}", highlight=False)
    if meas.dropped_rows:
        rows = ", ".join(map(str, meas.dropped_rows))
        which = f"point(s) {', '.join(map(str, meas.point_numbers))}" if meas.point_numbers else "points"
        why = "no pose measured there" if meas.n_points == 0 else f"none of the {which} read was seen"
        console.print(f"[yellow]note:[/yellow] row(s) {rows} dropped: {why}", highlight=False)
