"""The Typer application and console shared by every ``jaxcal`` sub-command module."""

import typer
from rich.console import Console

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Calibrate the DH parameters of serial robot arms (JAX, float64).")
console = Console()
err_console = Console(stderr=True)


def load_robot_arg(robot: str):
    """A robot TOML path or a preset name."""
    from ..presets import PRESETS, preset
    from ..robot_io import load_robot

    return preset(robot) if robot in PRESETS else load_robot(robot)
