"""The package's layers import only downwards (issue 14).

``physics`` (the numerics) imports nothing outside itself and no I/O or
configuration library, so no physics function can take a pydantic model;
``config`` builds on physics; ``output`` writes physics results; ``campaign``
plans and runs on all three; ``report`` reads stored results through
``output`` and ``config`` and never recomputes physics. The CLI and console
at the top may import anything. The test reads every module's source (the
import statements, wherever they stand, including inside functions and
``TYPE_CHECKING`` blocks) so a violation fails without running the code.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "cwrend_cli"

#: What each layer may import from cwrend_cli (module-name prefixes).
ALLOWED: dict[str, tuple[str, ...]] = {
    "physics": ("cwrend_cli.physics",),
    "config": ("cwrend_cli.config", "cwrend_cli.physics", "cwrend_cli.errors", "cwrend_cli.limits"),
    "output": (
        "cwrend_cli.output",
        "cwrend_cli.physics",
        "cwrend_cli.errors",
        "cwrend_cli.limits",  # the bounds of inputs: a manifest's root seed (issue 36 item 10)
        "cwrend_cli",
    ),
    "campaign": (
        "cwrend_cli.campaign",
        "cwrend_cli.config",
        "cwrend_cli.output",
        "cwrend_cli.physics",
        "cwrend_cli.errors",
        "cwrend_cli.limits",
        "cwrend_cli.lazy",
        "cwrend_cli.teardown",
        "cwrend_cli",
    ),
    "report": (
        "cwrend_cli.report",
        "cwrend_cli.config",
        "cwrend_cli.output",
        "cwrend_cli.physics.params",
        "cwrend_cli.physics.metrics",
        "cwrend_cli.physics.constraints",  # the shapes of the keep-out zone and corridor drawn
        "cwrend_cli.errors",
        "cwrend_cli.lazy",
        "cwrend_cli",
    ),
}
#: Third-party packages the physics core may use: numerics only (llvmlite: numba's compiler,
#: for the compiled clock of physics/_clock.py).
PHYSICS_THIRD_PARTY = frozenset({"numpy", "scipy", "numba", "llvmlite", "clarabel"})


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
    """Absolute names of every module imported by the module at ``path``."""
    module = _module_name(path)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    return imports_of(path.read_text(encoding="utf-8"), package)


def imports_of(source: str, package: str) -> set[str]:
    """Imported names of ``source``: ``from a import b`` gives ``a``, and ``a.b`` within cwrend."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                module = ".".join([*base, node.module] if node.module else base)
            else:
                module = node.module or ""
            names.add(module)
            if module.startswith("cwrend_cli"):
                names.update(f"{module}.{alias.name}" for alias in node.names)
    return names


def _layer(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 2 and parts[1] in ALLOWED else None


def _own_imports(module_imports: set[str]) -> set[str]:
    """The cwrend_cli modules among the imports (attribute imports resolved to their module)."""
    out = set()
    for name in module_imports:
        if not name.startswith("cwrend_cli"):
            continue
        # ``from cwrend_cli.physics import params`` names a module; ``… import Problem`` does not.
        candidate = PACKAGE.parent / Path(*name.split("."))
        if candidate.with_suffix(".py").exists() or (candidate / "__init__.py").exists():
            out.add(name)
        else:
            out.add(name.rpartition(".")[0])
    return out


MODULES = sorted(p for p in PACKAGE.rglob("*.py"))


def violations(module: str, imported: set[str]) -> list[str]:
    """The cwrend modules ``module`` imports against its layer's rule (empty: none)."""
    layer = _layer(module)
    if layer is None:
        return []
    allowed = [a for a in ALLOWED[layer] if a != "cwrend_cli"]
    return sorted(
        name
        for name in _own_imports(imported)
        if name != "cwrend_cli" and not any(name == a or name.startswith(a + ".") for a in allowed)
    )


# The top-level modules (cli, console, errors, limits) may import any layer.
LAYERED = [p for p in MODULES if _layer(_module_name(p)) is not None]


@pytest.mark.parametrize("path", LAYERED, ids=_module_name)
def test_layer_imports_only_downwards(path: Path) -> None:
    module = _module_name(path)
    bad = violations(module, _imports(path))
    assert not bad, f"{module} imports {bad}; allowed: {ALLOWED[_layer(module) or '']}"


PHYSICS = [p for p in MODULES if _layer(_module_name(p)) == "physics"]


@pytest.mark.parametrize("path", PHYSICS, ids=_module_name)
def test_physics_uses_numerics_libraries_only(path: Path) -> None:
    third_party = {
        name.split(".")[0] for name in _imports(path) if name and not name.startswith("cwrend_cli")
    } - set(sys.stdlib_module_names)
    assert third_party <= PHYSICS_THIRD_PARTY, f"{_module_name(path)} imports {third_party}"


def test_an_upward_import_inside_a_function_is_a_violation() -> None:
    source = "def f():\n    from cwrend_cli.config import CwrendConfig\n"
    imported = imports_of(source, "cwrend_cli.physics")
    assert violations("cwrend_cli.physics.simulation", imported) == ["cwrend_cli.config"]


def test_a_relative_import_is_resolved() -> None:
    imported = imports_of("from ..campaign import executors\n", "cwrend_cli.report")
    assert violations("cwrend_cli.report.load", imported) == [
        "cwrend_cli.campaign",
        "cwrend_cli.campaign.executors",
    ]
