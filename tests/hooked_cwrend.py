"""``cwrend`` with a signal sent at a state of the campaign, not at a time (for the tests).

    python tests/hooked_cwrend.py WHEN N SIGNAL cwrend-arguments…

sends ``SIGNAL`` once the driver has seen the ``N``-th state ``WHEN``:

* ``journal``: the driver appended to ``events.jsonl`` (a task journaled);
* ``run``: the driver heard a run finish (a per-run signal of a task in flight);
* ``statistics``: the command is about to write a campaign's statistics (its runs done);
* ``pool``: the driver opened its process pool (the workers started, still importing);
* ``compile``: this process starts its ``N``-th run, which first "compiles": compiled
  code calling back into Python (a ctypes callback, as numba's compiler does after each
  module), the signal sent from inside the callback, where its exception cannot
  propagate, then Python and callbacks in turn until the stop lands (the run is then
  dropped) or :data:`HANG_S` passes (it then runs).

SIGKILL (``kill -9``), SIGSTOP (the test then acts while the campaign is
frozen at that state, and lets it go on with SIGCONT) and a signal written
``NAME:self`` (``kill <pid>``) go to the campaign process alone; any other
signal to its process group, as a terminal's Ctrl-C or hang-up reaches the
workers too (tests start the child in a session of its own). So the signal
lands at the same point of the campaign however fast the machine is. The
driver's wait for the tasks in flight after Ctrl-C (``STOP_GRACE_S``) is set
to an hour: what a stop keeps must not depend on the machine's speed either.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from cwrend_cli import campaign
from cwrend_cli.campaign import driver
from cwrend_cli.output.layout import EVENTS

#: This script, for the tests to run (``[sys.executable, str(HOOKED), WHEN, N, SIGNAL, …]``).
HOOKED = Path(__file__)
#: Guards against a hang only: no assertion depends on how long a campaign takes [s].
HANG_S = 600.0


def wait_stopped(proc: subprocess.Popen[str], poll_s: float = 0.02) -> None:
    """Wait until ``proc`` has stopped itself (SIGSTOP at its state); fail if it ended first.

    Polls the child's state every ``poll_s`` s (``waitpid`` with ``WUNTRACED``);
    after :data:`HANG_S` s without a stop the campaign hangs, and is killed.
    """
    hang = time.monotonic() + HANG_S
    while time.monotonic() < hang:
        pid, status = os.waitpid(proc.pid, os.WUNTRACED | os.WNOHANG)
        if pid:
            assert os.WIFSTOPPED(status), "the campaign ended before its state"
            return
        time.sleep(poll_s)
    proc.kill()
    raise AssertionError(f"no state reached in {HANG_S:g} s: the campaign hangs")


def _send(signum: signal.Signals, alone: bool) -> None:
    if alone or signum in (signal.SIGKILL, signal.SIGSTOP):
        os.kill(os.getpid(), signum)
    else:
        os.killpg(os.getpgrp(), signum)


def _hook(when: str, after: int, signum: signal.Signals, alone: bool) -> None:
    seen = [0]

    def count() -> None:
        seen[0] += 1
        if seen[0] == after:
            _send(signum, alone)

    if when == "journal":
        append = driver.append_events  # type: ignore[attr-defined]

        def appended(path: Any, *args: Any, **kwargs: Any) -> None:
            append(path, *args, **kwargs)
            if Path(path).name == EVENTS:  # not another file the driver appends to
                count()

        driver.append_events = appended  # type: ignore[attr-defined]
    elif when == "run":
        heard = driver._RunTally.heard

        def heard_run(self: driver._RunTally, token: int, ok: bool) -> None:
            heard(self, token, ok)
            count()

        driver._RunTally.heard = heard_run  # type: ignore[method-assign]
    elif when == "statistics":
        write = campaign.write_statistics

        def writing(*args: Any, **kwargs: Any) -> Any:
            count()
            return write(*args, **kwargs)

        campaign.write_statistics = writing
    elif when == "pool":
        opened = driver.open_executor  # type: ignore[attr-defined]

        @contextlib.contextmanager
        def opening(*args: Any, **kwargs: Any) -> Iterator[Any]:
            with opened(*args, **kwargs) as pool:
                count()
                yield pool

        driver.open_executor = opening  # type: ignore[attr-defined]
    elif when == "compile":
        from cwrend_cli.physics import simulation

        real = simulation.simulate
        started = [0]
        signalled = ctypes.CFUNCTYPE(None)(lambda: (count(), [None for _ in range(3)]))
        compiled = ctypes.CFUNCTYPE(None)(lambda: None)

        def simulate(*args: Any, **kwargs: Any) -> Any:
            started[0] += 1
            if started[0] == after:
                signalled()  # the handler runs in the callback (its loop checks for signals)
                hang = time.monotonic() + HANG_S
                while time.monotonic() < hang:  # compiling: Python, then compiled code
                    time.sleep(0.01)
                    compiled()
            return real(*args, **kwargs)

        simulation.simulate = simulate  # type: ignore[assignment]
        seen[0] = after - 1  # count() sends at once
    else:
        raise SystemExit(f"unknown state {when!r}")


if __name__ == "__main__":
    when, after, target = sys.argv[1:4]
    name, _, alone = target.partition(":")
    driver.STOP_GRACE_S = 3600.0
    _hook(when, int(after), signal.Signals[name], alone == "self")
    sys.argv = ["cwrend", *sys.argv[4:]]
    from cwrend_cli.__main__ import main

    main()
