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

The process's end on a signal lives here too: :func:`stop_on_signals` makes
Ctrl-C, SIGTERM and SIGHUP stop ``cwrend`` the same way, with the exit
status of the signal (:func:`stop_exit_code`). The stop is recorded
(:func:`stop_asked`, which the campaign's loops ask before each run and each
task) and raised in the main thread; a stop that compiled code swallowed (a
callback of numba's compiler, where an exception cannot propagate) is raised
again until it lands (:func:`unraisable_stop`): a Ctrl-C during a first
run's 30-90 s compile was lost or waited for the compile (issue 37 item 2's
follow-up).
"""

from __future__ import annotations

import _thread
import atexit
import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable
from types import FrameType
from typing import Any, NoReturn


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


#: Signals that stop cwrend (issue 36 item 12): Ctrl-C, ``kill <pid>`` or a batch
#: scheduler's time limit (SIGTERM), a closed terminal (SIGHUP). Each gives a summary, the
#: manifest finished, the pool shut down; exit status 128 + the signal's number, the
#: shell's convention (130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP).
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
#: How long after a stop was swallowed it is raised again [s] (:func:`unraisable_stop`):
#: long enough for the compiled code that swallowed it to have returned to C, short beside
#: a run; the next Python code the main thread runs then gets it.
REDELIVER_S = 0.05
#: The stop signals this process received, in order (:func:`on_stop`, or a pool worker's
#: handler through :func:`note_stop`).
_RECEIVED: list[int] = []
#: owed: a stop's exception was swallowed and nothing has acted on the stop since;
#: redelivering: the next handler call is :func:`_redeliver`'s, not a new signal.
_STATE = {"owed": False, "redelivering": False}
_TIMER: list[threading.Timer] = []


class StopSignal(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised in the main thread as a Ctrl-C is (its message: which;
    :func:`stop_exit_code` reads the signal from :data:`_RECEIVED`)."""


def stop_asked() -> bool:
    """Whether this process received a stop signal (every loop that starts work asks)."""
    return bool(_RECEIVED)


def note_stop(signum: int) -> None:
    """Record stop signal ``signum`` (a handler of its own: a pool worker's)."""
    _RECEIVED.append(signum)


def clear_stop() -> None:
    """Forget the stop (a library caller's campaign, whose next one starts afresh)."""
    _RECEIVED.clear()
    _STATE["owed"] = False


def raise_stop() -> NoReturn:
    """Raise the stop's exception here: ``KeyboardInterrupt``, or :class:`StopSignal` when
    the first stop was SIGTERM or SIGHUP. Whatever re-delivery was owed is then paid."""
    _STATE["owed"] = False
    first = _RECEIVED[0] if _RECEIVED else signal.SIGINT
    if first == signal.SIGINT:
        raise KeyboardInterrupt
    raise StopSignal(signal.Signals(first).name)


def redelivered() -> bool:
    """In a handler: whether this call is a re-delivery (:func:`redeliver`), consumed."""
    again = _STATE["redelivering"]
    _STATE["redelivering"] = False
    return again


def on_stop(signum: int, frame: FrameType | None) -> None:
    """cwrend's handler of :data:`STOP_SIGNALS`: record the signal, raise the stop.

    A re-delivery raises only if the stop is still owed (nothing has acted on
    it since it was swallowed); a second signal raises again (a second Ctrl-C
    abandons what the first one waits for).
    """
    if redelivered():
        if _STATE["owed"]:
            raise_stop()
        return
    _RECEIVED.append(signum)
    raise_stop()


def redeliver(delay_s: float = 0.0) -> None:
    """Owe the main thread the stop and raise it there after ``delay_s`` [s] (at its next
    Python code, through its handler of the first stop signal); one at a time."""
    _STATE["owed"] = True
    if _TIMER and _TIMER[0].is_alive():
        return
    timer = threading.Timer(delay_s, _redeliver)
    timer.daemon = True
    _TIMER[:] = [timer]
    timer.start()


def _redeliver() -> None:
    if _STATE["owed"] and _RECEIVED:
        _STATE["redelivering"] = True
        _thread.interrupt_main(signal.Signals(_RECEIVED[0]))


def unraisable_stop(unraisable: Any) -> None:
    """``sys.unraisablehook`` of a process that stops on signals: a stop's exception that
    compiled code swallowed is raised again, not printed.

    A handler runs at the main thread's next Python code; when that code is a
    callback from compiled code (numba's compiler calls Python through ctypes
    after each module it compiles: 0.3-1.9 s apart on a loaded 2-core AMD
    EPYC), the exception cannot propagate: ctypes hands it here and the
    compile goes on, 30-90 s on a first run. It is raised again
    :data:`REDELIVER_S` later (:func:`redeliver`), until it lands in code that
    acts on it. Anything else is printed as Python does.
    """
    if stop_asked() and isinstance(unraisable.exc_value, KeyboardInterrupt):
        redeliver(REDELIVER_S)
        return
    sys.__unraisablehook__(unraisable)


def stop_on_signals() -> None:
    """Stop on :data:`STOP_SIGNALS` in this process (cwrend's own, not its workers).

    Everything that keeps a Ctrl-C's work (the campaign's journal of the runs
    finished, its summary and manifest) then keeps theirs, and a stop that
    compiled code swallowed is raised again (:func:`unraisable_stop`); a signal
    ignored when cwrend started (``nohup``, a shell's ``cmd &`` for Ctrl-C)
    stays ignored.
    """
    for signum in STOP_SIGNALS:
        if signal.getsignal(signum) is not signal.SIG_IGN:
            signal.signal(signum, on_stop)
    sys.unraisablehook = unraisable_stop


def stop_exit_code() -> int:
    """The exit status of a command stopped by a signal: 128 + the first stop signal
    received (:data:`STOP_SIGNALS`), else 130 (Ctrl-C)."""
    return 128 + (_RECEIVED[0] if _RECEIVED else signal.SIGINT)
