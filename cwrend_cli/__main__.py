"""The ``cwrend`` command (and ``python -m cwrend_cli``).

:func:`main` imports the command line inside a guard, so that a Ctrl-C
while it loads exits quietly with code 130 instead of printing an import
traceback. The command line itself loads only Typer (and the pydantic it
converts arguments with); Rich, numpy and the heavy libraries (numba, scipy,
pandas, pyarrow, rerun, matplotlib: 1–4 s) load in the commands that use
them (see :mod:`cwrend_cli.cli`), where a Ctrl-C is handled by the command.

:func:`main` is the program: when the command has ended with an exit code,
the process ends without the interpreter's teardown (:mod:`cwrend_cli.teardown`,
0.5–0.8 s once the heavy libraries are loaded), after the exit handlers.
"""

from __future__ import annotations

import faulthandler
import signal
import sys

from cwrend_cli.physics.compiled import tune_for_compiling
from cwrend_cli.teardown import end_without_teardown, stop_exit_code, stop_on_signals

#: Exit code of a command stopped by Ctrl-C (128 + SIGINT, the shell convention).
INTERRUPTED_EXIT = 130


def main() -> None:
    """Run the command line; Ctrl-C during start-up exits 130 without a traceback.

    ``kill -USR1 <pid>`` prints every thread's stack to stderr (a campaign that
    seems stuck can say where), without stopping it. Ctrl-C, SIGTERM and SIGHUP
    stop it the same way (:func:`~cwrend_cli.teardown.stop_on_signals`, which
    also raises again a stop that compiled code swallowed), with exit status
    128 + the signal: 130, 143, 129.
    """
    tune_for_compiling()
    if hasattr(signal, "SIGUSR1"):
        faulthandler.register(signal.SIGUSR1, all_threads=True)
    stop_on_signals()
    exit_code: list[int] = []  # the command's, once it has ended with one
    end_without_teardown(lambda: exit_code[0] if exit_code else None)
    try:
        try:
            from cwrend_cli.cli import app

            app()  # Typer turns a Ctrl-C inside a command into exit 130 itself
        except KeyboardInterrupt:  # while importing, or while Typer builds the command line
            sys.exit(INTERRUPTED_EXIT)
    except SystemExit as exc:
        if exc.code == INTERRUPTED_EXIT:  # a stop signal's: Ctrl-C, SIGTERM or SIGHUP
            exc.code = stop_exit_code()
        if exc.code is None or isinstance(exc.code, int):  # a message the interpreter prints
            exit_code.append(exc.code or 0)
        raise


if __name__ == "__main__":
    main()
