"""User-facing error types of cwrend.

Every error a user can cause (a bad config file, a bad override, a bad data
file) is raised as a subclass of :class:`CwrendError`. The CLI turns these into
a one-line ``error: ...`` message on stderr and exit code 2, never a traceback.
Anything else that escapes is a bug and keeps its traceback.
"""

from __future__ import annotations

from collections.abc import Sequence

from cwrend_cli.physics.errors import CwrendError, ScenarioError

__all__ = ["ConfigError", "CwrendError", "InputDataError", "ScenarioError"]


class ConfigError(CwrendError):
    """Invalid configuration: missing/malformed file, bad override or failed validation.

    ``problems`` holds one human-readable line per problem, each naming the
    offending field as a dotted path (e.g. ``schedule.eps_min``); the exception
    message is the header (if any) followed by those lines.
    """

    def __init__(self, message: str, problems: Sequence[str] = ()) -> None:
        self.problems: tuple[str, ...] = tuple(problems)
        lines = [message] if message else []
        lines.extend(f"  {p}" for p in self.problems)
        super().__init__("\n".join(lines))


class InputDataError(CwrendError):
    """A data file referenced by the configuration (e.g. a noise file) is unusable."""
