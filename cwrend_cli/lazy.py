"""Package attributes imported on first use (PEP 562), for start-up time (issue 17).

A package whose ``__init__`` re-exports names from heavy submodules makes
every import of any of its submodules pay for all of them: importing
``cwrend_cli.report.labels`` (a few pandas helpers) ran the package's
``__init__``, which imported the figures and with them matplotlib and
``scipy.stats`` (about 1 s of every campaign command). With
:func:`lazy_attributes` the package names those attributes and their
submodules, and each is imported when it is first looked up.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any


def lazy_attributes(
    package: str, submodule_of: Mapping[str, str], namespace: dict[str, Any]
) -> Callable[[str], object]:
    """The module ``__getattr__`` of ``package``: ``name`` from ``package.<submodule_of[name]>``.

    ``namespace`` is the package's ``globals()``: a name looked up once is
    stored there, so later lookups do not come back here. An unknown name
    raises ``AttributeError`` as a module without ``__getattr__`` would.
    """

    def attribute(name: str) -> object:
        module = submodule_of.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{module}"), name)
        namespace[name] = value
        return value

    return attribute
