"""The campaign plan (pure): every run, decided and validated before anything runs.

A campaign is a grid of parameter points × architectures × noise seeds, with
optional per-run dispersions. :func:`plan` turns a validated config into a
:class:`CampaignPlan` of :class:`Task` (batches of :class:`RunSpec` of one
grid point) without side effects. Each grid point's config is validated once
and converted into the physics core's typed
:class:`~cwrend_cli.physics.params.Problem`, which its tasks carry; each
dispersed run's config is validated once as well, so every run is known to be
valid before anything runs, and the workers only apply a run's drawn values to
the point's typed parameters (:func:`~cwrend_cli.config.adapt.with_values`).

Here too: the grid points and their ids, run keys, the campaign hash and the
dispersion draws. Random streams are keyed by (noise.seed, realisation): the
dispersion draws by ``(seed, 1)`` (:func:`dispersion_seed_sequence`), the
noise by ``(seed, 0)`` and the per-step actuator errors by ``(seed, 2)``
(:mod:`cwrend_cli.campaign.worker`), so every
architecture and grid point of a seed sees the same noise and the same
dispersed values (common random numbers), and the numbers do not depend on
the worker count or the executor.
"""

from __future__ import annotations

import hashlib
import itertools
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cwrend_cli.config import (
    ALL_ARCHITECTURES,
    CwrendConfig,
    Dispersion,
    config_from_dict,
    config_hash,
    resolved_dict,
)
from cwrend_cli.config.adapt import problem_of, with_values
from cwrend_cli.config.overrides import apply, expand_grid, get_dotted
from cwrend_cli.errors import ConfigError
from cwrend_cli.physics.params import Problem

__all__ = [
    "BASE_POINT",
    "Assignment",
    "CampaignPlan",
    "Grid",
    "NoiseSource",
    "RunSpec",
    "Task",
    "campaign_hash",
    "dispersion_seed_sequence",
    "draw_dispersions",
    "grid_points",
    "noise_source",
    "plan",
    "point_id",
    "run_key",
]

#: Id of the only grid point of a campaign without a grid (an ablation).
BASE_POINT = "base"

#: ``(dotted.key, value)`` pairs applied on top of a configuration.
Assignment = tuple[tuple[str, Any], ...]
#: The swept keys and their values, in order.
Grid = tuple[tuple[str, tuple[Any, ...]], ...]


@dataclass(frozen=True)
class NoiseSource:
    """Where the measurement noise of a grid point comes from (its ``[noise]`` section).

    The stream of realisation ``seed`` of ``root_seed``, or the realisation
    replayed from ``file`` (an absolute path) when one is given.
    """

    root_seed: int
    file: str | None = None


def noise_source(cfg: CwrendConfig) -> NoiseSource:
    """The noise source of a validated configuration."""
    return NoiseSource(root_seed=cfg.noise.seed, file=cfg.noise.file)


@dataclass(frozen=True)
class RunSpec:
    """One run: a grid point, an architecture, a noise realisation, applied values."""

    run_key: str
    point: str
    arch: str
    seed: int
    params: Assignment  # grid values of the point
    dispersed: Assignment  # dispersion values drawn for this seed

    @property
    def overrides(self) -> Assignment:
        """Everything applied on top of the base config."""
        return self.params + self.dispersed


@dataclass(frozen=True)
class Task:
    """A batch of runs executed together (one grid point, a chunk of seeds, all archs).

    It carries what a worker needs besides the point's open-loop references:
    the point's typed problem (a run applies its ``dispersed`` values on top)
    and its noise source. No configuration tree travels to the workers.
    """

    task_key: str
    runs: tuple[RunSpec, ...]
    point: str
    problem: Problem
    noise: NoiseSource


@dataclass(frozen=True)
class CampaignPlan:
    """Everything a campaign will run, decided before anything runs."""

    base: Mapping[str, Any]  # resolved base config (JSON tree), as the manifest records it
    grid: Grid
    seeds: tuple[int, ...]
    archs: tuple[str, ...]
    tasks: tuple[Task, ...]
    campaign_hash: str
    config_hash: str  # of the base config (cwrend_cli.config.config_hash)
    root_seed: int  # noise.seed of the base config (also keys the dispersion draws)
    steps_seeds: int | None  # output.steps_seeds: per-step data only below this seed
    rrd_seeds: int | None  # output.rrd_seeds: recordings only below this seed

    @property
    def runs(self) -> tuple[RunSpec, ...]:
        """All runs, in plan order."""
        return tuple(r for t in self.tasks for r in t.runs)


def grid_points(grid: Sequence[tuple[str, Sequence[Any]]]) -> tuple[tuple[str, Assignment], ...]:
    """Cartesian product of the grid as ``(point_id, assignment)`` pairs.

    The id is a hash of the assignment, so it does not depend on the grid's
    order or on which other points exist (a campaign can be extended).
    """
    if not grid:
        return ((BASE_POINT, ()),)
    keys = [k for k, _ in grid]
    points: list[tuple[str, Assignment]] = []
    for combo in itertools.product(*(v for _, v in grid)):
        assignment = tuple(zip(keys, combo, strict=True))
        points.append((point_id(assignment), assignment))
    return tuple(points)


def point_id(assignment: Assignment) -> str:
    """Stable short id of a grid point."""
    if not assignment:
        return BASE_POINT
    text = json.dumps(sorted([k, v] for k, v in assignment), sort_keys=True)
    return "p" + hashlib.sha256(text.encode()).hexdigest()[:10]


def run_key(point: str, arch: str, seed: int) -> str:
    """Unique, stable key of a run."""
    return f"{point}.{arch}.s{seed:06d}"


def dispersion_seed_sequence(root_seed: int, seed: int) -> np.random.SeedSequence:
    """Stream of the dispersion draws of realisation ``seed`` (independent of the noise)."""
    return np.random.SeedSequence(root_seed, spawn_key=(seed, 1))


def draw_dispersions(
    dispersions: Mapping[str, Dispersion], point_tree: Mapping[str, Any], root_seed: int, seed: int
) -> Assignment:
    """Dispersed values of realisation ``seed`` on top of a grid point.

    Draws come from the realisation's dispersion stream in sorted key order,
    one draw per key, so they do not depend on the point, the architecture or
    the worker.
    """
    if not dispersions:
        return ()
    rng = np.random.Generator(np.random.PCG64(dispersion_seed_sequence(root_seed, seed)))
    out = []
    for key in sorted(dispersions):
        d = dispersions[key]
        if d.dist == "normal":
            assert d.std is not None  # the model requires std for dist = "normal"
            draw = d.mean + d.std * rng.standard_normal()
        else:
            assert d.low is not None and d.high is not None  # required for "uniform"
            draw = rng.uniform(d.low, d.high)
        if d.mode == "add":
            try:
                base = get_dotted(point_tree, key)
            except (KeyError, IndexError, ValueError, TypeError):
                raise ConfigError(
                    f"dispersions.{key}: no such config value to disperse "
                    "(use a dotted key such as scenario.x0.2 or scenario.u_max_km_s2)"
                ) from None
            if not isinstance(base, (int, float)) or isinstance(base, bool):
                raise ConfigError(
                    f"dispersions.{key}: the base value {base!r} is not a number "
                    "(point at a single number, e.g. scenario.x0.0)"
                )
            draw = base + draw
        out.append((key, float(draw)))
    return tuple(out)


def _validated(base: Mapping[str, Any], assignment: Assignment, what: str) -> CwrendConfig:
    """The config ``base`` + ``assignment``, validated; errors name ``what`` and the values."""
    try:
        return config_from_dict(apply(base, assignment), source=what)
    except ConfigError as exc:
        values = ", ".join(f"{k} = {v!r}" for k, v in assignment)
        raise ConfigError(f"{what} ({values}) is invalid:", exc.problems or (str(exc),)) from None


def _check_typed(problem: Problem, dispersed: Assignment, run_cfg: CwrendConfig, seed: int) -> None:
    """Refuse dispersed values that the worker could not apply exactly as validated.

    The worker applies ``dispersed`` to the point's typed problem without
    validation; this makes sure that gives the problem of the validated run
    config, value for value (it does for any single number of the physics
    sections, which validation stores unchanged).
    """
    try:
        typed: Problem | None = with_values(problem, dispersed)
    except (AttributeError, IndexError, KeyError, TypeError, ValueError):
        typed = None
    if typed != problem_of(run_cfg):
        keys = ", ".join(k for k, _ in dispersed)
        raise ConfigError(
            f"dispersed run (seed {seed}): {keys} cannot be applied to the physics "
            "parameters as drawn (disperse single numbers of the scenario, estimator, "
            "schedule, guidance, solver or degradation sections)"
        )


def campaign_hash(base: Mapping[str, Any], grid: Sequence[tuple[str, Sequence[Any]]]) -> str:
    """Hash of what determines a campaign's numbers (not where it is written)."""
    tree = {k: v for k, v in base.items() if k != "output"}
    text = json.dumps({"config": tree, "grid": [[k, list(v)] for k, v in grid]}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def plan(
    cfg: CwrendConfig,
    archs: Sequence[str],
    seeds: Sequence[int],
    cli_params: Sequence[str] = (),
    seeds_per_task: int | None = None,
) -> CampaignPlan:
    """Expand a campaign into tasks, validating every run's resolved config first.

    Each grid point's config is validated once and converted into the typed
    problem its tasks carry; each dispersed run's config is validated once.
    Raises :class:`ConfigError` naming the key and value of the first bad
    grid value or dispersion draw; nothing has run or been written then.
    """
    unknown = [a for a in archs if a not in ALL_ARCHITECTURES]
    if unknown:
        raise ConfigError(
            f"unknown architecture(s) {', '.join(unknown)} "
            f"(allowed: {', '.join(ALL_ARCHITECTURES)})"
        )
    if len(set(seeds)) != len(seeds) or any(s < 0 for s in seeds):
        raise ConfigError("seeds must be distinct non-negative integers")
    seeds_per_task = seeds_per_task or cfg.output.seeds_per_task
    base = resolved_dict(cfg)
    base.pop("sweep", None)
    base.pop("dispersions", None)
    grid = expand_grid(cfg.sweep, cli_params)
    root = cfg.noise.seed
    tasks = []
    for pid, params in grid_points(grid):
        point_cfg = _validated(base, params, f"grid point {pid}")
        point_tree = resolved_dict(point_cfg)
        problem = problem_of(point_cfg)
        noise = noise_source(point_cfg)
        for start in range(0, len(seeds), seeds_per_task):
            chunk = seeds[start : start + seeds_per_task]
            runs: list[RunSpec] = []
            for seed in chunk:
                dispersed = draw_dispersions(cfg.dispersions, point_tree, root, seed)
                if dispersed:
                    run_cfg = _validated(base, params + dispersed, f"dispersed run (seed {seed})")
                    _check_typed(problem, dispersed, run_cfg, seed)
                runs.extend(
                    RunSpec(run_key(pid, a, seed), pid, a, seed, params, dispersed) for a in archs
                )
            key = f"{pid}.s{chunk[0]:06d}-{chunk[-1]:06d}"
            tasks.append(Task(key, tuple(runs), pid, problem, noise))
    base["sweep"] = {}
    base["dispersions"] = resolved_dict(cfg)["dispersions"]
    return CampaignPlan(
        base=base,
        grid=grid,
        seeds=tuple(seeds),
        archs=tuple(archs),
        tasks=tuple(tasks),
        campaign_hash=campaign_hash(base, grid),
        # the hash of ``base`` as a config, without validating it again
        config_hash=config_hash(cfg.model_copy(update={"sweep": {}})),
        root_seed=root,
        steps_seeds=cfg.output.steps_seeds,
        rrd_seeds=cfg.output.rrd_seeds,
    )
