"""User-facing error types of cwrend.

Every error a user can cause (a bad config file, a bad override, a bad data
file) is raised as a subclass of :class:`CwrendError`. The CLI turns these into
a one-line ``error: ...`` message on stderr and exit code 2, never a traceback.
Anything else that escapes is a bug and keeps its traceback.
"""

from __future__ import annotations

from collections.abc import Sequence

from cwrend_cli.limits import MAX_LISTED_PROBLEMS
from cwrend_cli.physics.errors import CwrendError, ScenarioError

__all__ = [
    "ConfigError",
    "CwrendError",
    "InfrastructureError",
    "InputDataError",
    "ScenarioError",
]

#: Exit code of a campaign stopped by an infrastructure fault (not by its input).
INFRASTRUCTURE_EXIT = 3


class ConfigError(CwrendError):
    """Invalid configuration: missing/malformed file, bad override or failed validation.

    ``problems`` holds one human-readable line per problem, each naming the
    offending field as a dotted path (e.g. ``schedule.eps_min``); the exception
    message is the header (if any) followed by the first
    :data:`~cwrend_cli.limits.MAX_LISTED_PROBLEMS` of those lines and a count of
    the rest (issue 36 item 11: 85,000 unknown keys printed 8.3 MB).
    """

    def __init__(self, message: str, problems: Sequence[str] = ()) -> None:
        self.problems: tuple[str, ...] = tuple(problems)
        lines = [message] if message else []
        if len(self.problems) <= MAX_LISTED_PROBLEMS + 1:  # a count would take a line too
            lines.extend(f"  {p}" for p in self.problems)
        else:
            lines.extend(f"  {p}" for p in self.problems[:MAX_LISTED_PROBLEMS])
            more = len(self.problems) - MAX_LISTED_PROBLEMS
            lines.append(f"  … and {more:,} more ({len(self.problems):,} in all)")
        super().__init__("\n".join(lines))


class InputDataError(CwrendError):
    """A data file referenced by the configuration (e.g. a noise file) is unusable."""


class InfrastructureError(CwrendError):
    """The machine failed, not a run: a campaign stopped by an infrastructure fault (exit 3).

    A worker process that died, a lost Dask scheduler or worker, a cancelled
    task or an I/O error writing results (disk full, permission) is retried a
    bounded number of times and never recorded as a run's result; when the
    retries are exhausted (at once for an I/O error) the campaign stops with
    this error. Everything journaled before stays; the same command resumes
    and computes exactly the missing runs.
    """

    exit_code = INFRASTRUCTURE_EXIT
