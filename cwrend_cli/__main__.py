"""The ``cwrend`` command (and ``python -m cwrend_cli``).

:func:`main` imports the command line inside a guard, so that a Ctrl-C
while the heavy libraries load (numba, scipy, pandas: about a second) exits
quietly with code 130 instead of printing an import traceback.
"""

from __future__ import annotations

import sys

#: Exit code of a command stopped by Ctrl-C (128 + SIGINT, the shell convention).
INTERRUPTED_EXIT = 130


def main() -> None:
    """Run the command line; Ctrl-C during start-up exits 130 without a traceback."""
    try:
        from cwrend_cli.cli import app
    except KeyboardInterrupt:
        sys.exit(INTERRUPTED_EXIT)
    app()


if __name__ == "__main__":
    main()
