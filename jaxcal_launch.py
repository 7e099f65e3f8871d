"""The ``jaxcal`` command's entry point, outside the package so that a Ctrl-C while JAX is still
being imported also ends with one line and exit code 130: an interrupt inside an import can
surface as another exception (or none), so until the imports are done it exits at once, which
is safe because nothing has been written yet."""

import os
import signal
import sys

MESSAGE = "interrupted: nothing was written\n"


def _exit_now(signum, frame):
    sys.stderr.write(MESSAGE)
    sys.stderr.flush()
    os._exit(130)


def main():
    signal.signal(signal.SIGINT, _exit_now)
    from jaxcal.cli import main as run

    signal.signal(signal.SIGINT, signal.default_int_handler)
    run()
