"""From the validated configuration to the physics core's typed parameters.

The one place where pydantic models become the frozen dataclasses of
:mod:`cwrend_cli.physics.params`. The two mirror each other field for field,
so this is a plain copy: no value is computed or changed here, and a dotted
key names the same value on both sides (which is how dispersions are applied
to typed parameters, :func:`with_values`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any, TypeVar

from pydantic import BaseModel

from cwrend_cli.config.schema import CwrendConfig
from cwrend_cli.physics import params

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

_Params = TypeVar("_Params", bound="DataclassInstance")


def _mirror(cls: type[_Params], section: BaseModel) -> _Params:
    """The physics dataclass ``cls`` holding the same-named fields of a config section.

    Every field of ``cls`` must exist on ``section`` (an AttributeError here
    means the two have drifted apart; ``tests/test_config.py`` compares them).
    """
    return cls(**{f.name: getattr(section, f.name) for f in dataclasses.fields(cls)})


def windows_of(cfg: CwrendConfig) -> tuple[params.Window, ...]:
    """The configured degradation windows, in order (later ones win where they overlap)."""
    return tuple(_mirror(params.Window, w) for w in cfg.degradation.windows)


def problem_of(cfg: CwrendConfig) -> params.Problem:
    """The closed-loop problem described by ``cfg`` (every section but noise and output)."""
    return params.Problem(
        scenario=_mirror(params.Scenario, cfg.scenario),
        estimator=_mirror(params.Estimator, cfg.estimator),
        schedule=_mirror(params.Schedule, cfg.schedule),
        guidance=_mirror(params.Guidance, cfg.guidance),
        solver=_mirror(params.Solver, cfg.solver),
        degradation=params.Degradation(windows=windows_of(cfg)),
        truth=_mirror(params.Truth, cfg.truth),
        actuator=_mirror(params.Actuator, cfg.actuator),
        constraints=constraints_of(cfg),
        model=_mirror(params.DesignModel, cfg.model),
        target=_mirror(params.Target, cfg.target),
        sensor=_mirror(params.Sensor, cfg.sensor),
    )


def constraints_of(cfg: CwrendConfig) -> params.Constraints | None:
    """The configured path constraints (issue 32); None without a keep-out zone or corridor."""
    c = cfg.constraints
    if c.keep_out is None and c.corridor is None:  # a margin alone constrains nothing
        return None
    return params.Constraints(
        keep_out=None
        if c.keep_out is None
        else params.KeepOut(
            c.keep_out.semi_axes_km,
            tuple(_mirror(params.KeepOutBody, b) for b in c.keep_out.bodies),
        ),
        corridor=None if c.corridor is None else _mirror(params.Corridor, c.corridor),
        sigma_margin=c.sigma_margin,
        abort_safe_s=c.abort_safe_s,
        enforce=c.enforce,
    )


def _replaced(node: Any, parts: list[str], value: Any) -> Any:
    """``node`` (a frozen dataclass or tuple) with the value at ``parts`` replaced."""
    head, rest = parts[0], parts[1:]
    if isinstance(node, tuple):
        index = int(head)
        item = value if not rest else _replaced(node[index], rest, value)
        return (*node[:index], item, *node[index + 1 :])
    child = value if not rest else _replaced(getattr(node, head), rest, value)
    return dataclasses.replace(node, **{head: child})


def with_values(problem: params.Problem, assignment: Iterable[tuple[str, Any]]) -> params.Problem:
    """``problem`` with each ``(dotted.key, value)`` set, e.g. ``("scenario.x0.2", 31.2)``.

    The keys are configuration keys; the values must already have been
    validated against the configuration model (the campaign plan does that
    once per run), so nothing is checked here.
    """
    for key, value in assignment:
        problem = _replaced(problem, key.split("."), value)
    return problem
