"""Tasks for the tests to submit to a cwrend process pool (importable by its spawned workers)."""

from __future__ import annotations

import os
import time
from pathlib import Path


def hold(marker: str) -> None:
    """Write this worker's pid to ``marker``, then wait until the process is ended.

    The stop signals only note a stop (no task of cwrend's runs here), so
    SIGTERM does not end it: a worker that outlives its pool's ``terminate()``,
    as a cwrend worker busy in a long solver call does.
    """
    Path(marker).write_text(str(os.getpid()))
    while True:
        time.sleep(0.05)
