"""The ``jaxcal`` command line. Each sub-command lives in its own module and registers itself
on the shared Typer ``app`` when imported below."""

from __future__ import annotations

from ._app import app, console, err_console

# --- sub-command modules (one line each) ---
from . import _verify  # noqa: F401,E402
from . import _calibrate  # noqa: F401,E402
from . import _montecarlo  # noqa: F401,E402
from . import _reproduce  # noqa: F401,E402
# --- end of sub-command modules ---


def main():
    """Entry point: typed jaxcal errors print as one line, without a traceback, exit code 2."""
    from ..errors import JaxcalError

    try:
        app()
    except JaxcalError as e:
        # soft_wrap: one line however long (rich would wrap at the terminal width); markup off so
        # that brackets in the message ([tool].xyz, measured[3]) are printed as they are
        err_console.print("[red]error:[/red] ", end="", highlight=False)
        err_console.print(str(e), highlight=False, markup=False, soft_wrap=True)
        raise SystemExit(2)
