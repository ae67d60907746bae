"""Ending a process without tearing the interpreter down (issue 17: time after the work).

A process that has loaded numba, pandas, pyarrow and rerun spends 0.5–0.8 s
at exit freeing every module and object one by one (measured on a 2-core
AMD EPYC guest: ``python -c "import cwrend_cli.campaign.worker, pandas,
pyarrow, rerun"`` exits 0.55–0.64 s after its last statement). Nothing of
cwrend needs that teardown: files are written whole and renamed in place
(:func:`cwrend_cli.output.files.atomic_path`), recordings are flushed before
they are renamed, and the exit handlers that do matter still run.

:func:`end_without_teardown` registers an exit handler that runs after every
handler registered later (``atexit`` runs them last-in, first-out: rerun's,
and multiprocessing's in ``cwrend`` itself), shuts logging down if it was
imported (its handler was registered earlier in a pool worker, whose
initializer runs after ``logging`` is imported, and would not run), flushes
the standard streams, waits for multiprocessing's resource tracker if this
process started one (:func:`stop_resource_tracker`) and ends the process with
``os._exit``. The campaign's
pool workers use it from their initializer; ``cwrend`` itself from
:func:`cwrend_cli.__main__.main`, with the exit code of the command.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import signal
import sys
from collections.abc import Callable
from types import FrameType


def end_without_teardown(exit_code: Callable[[], int | None]) -> None:
    """At exit, after the handlers registered later: flush stdio and ``os._exit(exit_code())``.

    ``exit_code()`` is asked at exit; ``None`` (the code is not known, e.g.
    an uncaught exception is on its way to a traceback and exit status 1)
    leaves the interpreter to end as usual.
    """

    def _end() -> None:
        code = exit_code()
        if code is None:
            return
        logging = sys.modules.get("logging")
        if logging is not None:  # flush and close its handlers, as its own exit handler does
            logging.shutdown()
        for stream in (sys.stdout, sys.stderr):
            # a closed pipe (``| head``) or a closed stream has nothing left to flush
            with contextlib.suppress(OSError, ValueError):
                stream.flush()
        stop_resource_tracker()
        os._exit(code)

    atexit.register(_end)


def stop_resource_tracker() -> None:
    """End multiprocessing's resource tracker if this process started it, and wait for it.

    A process pool's first semaphore starts the tracker, a process of its own
    that lives until the pipe to it closes: at this process's exit, so it
    outlived ``cwrend`` by a moment (a stray process after the shell's prompt,
    and its warnings, if any, printed after it). Stopped here, it is gone when
    the pool is; the next pool starts another. In a pool's worker (which
    shares its parent's tracker) nothing is done.
    """
    resource_tracker = sys.modules.get("multiprocessing.resource_tracker")
    tracker = getattr(resource_tracker, "_resource_tracker", None)
    if tracker is None or getattr(tracker, "_pid", None) is None:
        return  # never started here, or started by the parent process
    with contextlib.suppress(OSError):  # already gone
        tracker._stop()


#: Signals that stop cwrend as Ctrl-C does (issue 36 item 12): a summary, the manifest
#: finished, the pool shut down; exit status 128 + the signal's number, the shell's
#: convention that Ctrl-C's 130 already follows (143 for SIGTERM, 129 for SIGHUP).
STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)
#: The stop signals this process received, in order (Ctrl-C is not recorded: 130).
_RECEIVED: list[int] = []


class StopSignal(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised in the main thread as a Ctrl-C is (its message: which;
    :func:`stop_exit_code` reads the signal from :data:`_RECEIVED`)."""


def _stop(signum: int, frame: FrameType | None) -> None:
    _RECEIVED.append(signum)
    raise StopSignal(signal.Signals(signum).name)


def stop_on_signals() -> None:
    """Handle :data:`STOP_SIGNALS` as Ctrl-C in this process (cwrend's own, not its workers).

    Everything that keeps a Ctrl-C's work (the campaign's journal of the runs
    finished, its summary and manifest) then keeps theirs; a signal ignored
    when cwrend started (``nohup``) stays ignored.
    """
    for signum in STOP_SIGNALS:
        if signal.getsignal(signum) is not signal.SIG_IGN:
            signal.signal(signum, _stop)


def stop_exit_code() -> int:
    """The exit status of a command stopped by a signal: 128 + the stop signal received
    (the first, :data:`STOP_SIGNALS`), else 130 (Ctrl-C)."""
    return 128 + (_RECEIVED[0] if _RECEIVED else signal.SIGINT)
