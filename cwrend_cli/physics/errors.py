"""The error the physics core raises when a problem cannot be flown.

:class:`CwrendError` is the root of every error caused by user input (the
CLI prints it as ``error: …`` and exits with code 2). It is defined here,
in the innermost layer, so that the physics core can raise user errors
without importing anything outside :mod:`cwrend_cli.physics`;
:mod:`cwrend_cli.errors` adds the configuration and data-file errors.
"""

from __future__ import annotations


class CwrendError(Exception):
    """Base class for errors caused by user input (CLI exit code 2)."""

    exit_code: int = 2


class ScenarioError(CwrendError):
    """The scenario itself cannot be flown (e.g. no bounded control reaches the target)."""
