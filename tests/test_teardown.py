"""Ending without the interpreter's teardown (:mod:`cwrend_cli.teardown`, issue 17).

Each case runs in a fresh interpreter: the behaviour is the process's exit.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = """
import atexit, sys
from cwrend_cli.teardown import end_without_teardown
end_without_teardown(lambda: {code})
atexit.register(lambda: open(sys.argv[1], "w").write("ran"))  # registered later: runs first
sys.stdout.write("buffered, not yet flushed")
"""


def _run(code: str, tmp_path: Path) -> subprocess.CompletedProcess[str]:
    marker = tmp_path / "marker"
    return subprocess.run(
        [sys.executable, "-c", SCRIPT.format(code=code), str(marker)],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip


def test_the_process_ends_with_the_given_code_after_later_exit_handlers(tmp_path: Path) -> None:
    proc = _run("3", tmp_path)
    assert proc.returncode == 3
    assert (tmp_path / "marker").read_text() == "ran"
    assert proc.stdout == "buffered, not yet flushed"  # the standard streams were flushed


def test_an_unknown_code_leaves_the_usual_exit(tmp_path: Path) -> None:
    proc = _run("None", tmp_path)
    assert proc.returncode == 0
    assert (tmp_path / "marker").read_text() == "ran"
    assert proc.stdout == "buffered, not yet flushed"


def test_logging_set_up_before_it_is_still_shut_down(tmp_path: Path) -> None:
    """A pool worker imports logging before its initializer registers the handler: the
    records a buffering logging handler holds still reach their file at exit."""
    log = tmp_path / "log.txt"
    script = (
        "import logging, logging.handlers, sys\n"
        "target = logging.FileHandler(sys.argv[1])\n"
        "held = logging.handlers.MemoryHandler(100, logging.CRITICAL, target)\n"
        "logging.getLogger().addHandler(held)\n"
        "from cwrend_cli.teardown import end_without_teardown\n"
        "end_without_teardown(lambda: 0)\n"
        "logging.getLogger().warning('held until shutdown')\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", script, str(log)], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 0, proc.stderr
    assert log.read_text() == "held until shutdown\n"


def test_cwrend_keeps_its_exit_codes(tmp_path: Path) -> None:
    """A bad config file exits 2 with its message, as before the teardown was skipped."""
    proc = subprocess.run(
        [sys.executable, "-m", "cwrend_cli", "config", "validate", str(tmp_path / "no.toml")],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert proc.returncode == 2
    assert "config file not found" in proc.stderr


#: Starts multiprocessing's resource tracker (a spawn context's queue), prints its pid, ends.
TRACKER_SCRIPT = """
import multiprocessing
from multiprocessing import resource_tracker
from cwrend_cli.teardown import end_without_teardown
end_without_teardown(lambda: 0)
runs = multiprocessing.get_context("spawn").Queue()
print(resource_tracker._resource_tracker._pid, flush=True)
"""

#: Runs TRACKER_SCRIPT as a child of a subreaper: a tracker that outlives its process is
#: handed to this one (prctl PR_SET_CHILD_SUBREAPER = 36) and its waitpid finds it.
SUBREAPER_SCRIPT = """
import ctypes, os, subprocess, sys
assert ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0) == 0
child = subprocess.run([sys.executable, "-c", sys.argv[1]], stdout=subprocess.PIPE, text=True)
assert child.returncode == 0
try:
    os.waitpid(int(child.stdout), 0)
    print("the tracker outlived its process")
except ChildProcessError:
    print("the tracker ended with its process")
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl subreaper: Linux")
def test_the_resource_tracker_ends_with_the_process() -> None:
    """A campaign's pool starts multiprocessing's resource tracker; cwrend waits for it at
    exit, so no process of it is left running after the shell's prompt."""
    proc = subprocess.run(
        [sys.executable, "-c", SUBREAPER_SCRIPT, TRACKER_SCRIPT],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "the tracker ended with its process\n"
