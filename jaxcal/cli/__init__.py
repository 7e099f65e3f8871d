"""The ``jaxcal`` command line: each command parses its arguments, calls the library, and
prints. One module per command."""

from __future__ import annotations

from .._config import use_compilation_cache
from . import (  # noqa: F401  (register commands)
    _calibrate,
    _compensate,
    _design,
    _evaluate,
    _info,
    _montecarlo,
    _reproduce,
    _verify,
)
from ._app import COMMAND_FLAGS, app, err_console, say_error


def main():
    """Entry point: a jaxcal error prints as one line, exit code 2 (3 for a fit that is not a
    calibration); Ctrl-C as one line, 130."""
    import warnings

    from ..errors import ImplausibleFitError, JaxcalError

    shown = warnings.showwarning
    warnings.showwarning = _warned
    try:
        use_compilation_cache()
        COMMAND_FLAGS.clear()  # a command sets its own spellings; none carried from an earlier run in-process
        app()
    except SystemExit as e:
        if e.code == 130:  # typer's exit for Ctrl-C, silent by itself
            _interrupted()
        raise
    except JaxcalError as e:
        # one line however long (rich would wrap at the terminal width); markup off so that
        # brackets in the message ([tool].xyz, measured[3]) are printed as they are
        err_console.print("[red]error:[/red] ", end="", highlight=False)
        err_console.print(say_error(str(e), e.option), highlight=False, markup=False, soft_wrap=True)
        raise SystemExit(3 if isinstance(e, ImplausibleFitError) else 2) from None
    except KeyboardInterrupt:
        _interrupted()
    finally:
        warnings.showwarning = shown


def _warned(message, category, filename, lineno, file=None, line=None):
    """A library warning the command does not say in its own words, as one line in the command's
    form (``warning: ...``), without Python's file and line."""
    err_console.print("[yellow]warning:[/yellow] ", end="", highlight=False)
    err_console.print(str(message), highlight=False, markup=False, soft_wrap=True)


def _interrupted():
    """One line, then exit 130 at once: an interrupted compile or solve leaves XLA's threads
    running, and tearing the interpreter down under them can crash. Outputs are written
    atomically, so there is nothing to clean up."""
    import os
    import sys

    err_console.print("interrupted: nothing was written", highlight=False)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(130)
