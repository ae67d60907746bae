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
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cwrend_cli.campaign.design import (
    RANGE_SYNTAX,
    TABLE_RANGE_SYNTAX,
    Design,
    ParameterRange,
    parse_cli_range,
    parse_range,
    range_ends,
    unit_samples,
)
from cwrend_cli.campaign.design import design_points as sample_design
from cwrend_cli.config import (
    ALL_ARCHITECTURES,
    CwrendConfig,
    Dispersion,
    config_from_dict,
    config_hash,
    resolved_dict,
)
from cwrend_cli.config.adapt import problem_of, with_values
from cwrend_cli.config.io import file_digest, load_noise_file
from cwrend_cli.config.messages import did_you_mean
from cwrend_cli.config.overrides import (
    CORRIDOR_PORT,
    check_given_once,
    check_swept,
    expand_grid,
    get_dotted,
    is_range,
    missing_key_hint,
    mixed_sweep_problem,
    moves_port,
    point_tree,
)
from cwrend_cli.config.schema import end_in_keep_out, nis_offset_given, xf_given
from cwrend_cli.errors import ConfigError
from cwrend_cli.limits import MAX_POINTS, MAX_RUNS, MAX_SEED
from cwrend_cli.physics.params import Architecture, DesignModel, Problem

__all__ = [
    "BASE_POINT",
    "Assignment",
    "CampaignPlan",
    "Grid",
    "NoiseSource",
    "RunSpec",
    "Task",
    "assignment_text",
    "campaign_hash",
    "check_inputs",
    "default_seeds_per_task",
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
    digest: str | None = None  # SHA-256 of the file's bytes when the campaign was planned


def noise_source(cfg: CwrendConfig) -> NoiseSource:
    """The noise source of a validated configuration (a noise file identified by its content)."""
    file = cfg.noise.file
    return NoiseSource(cfg.noise.seed, file, file_digest(file) if file is not None else None)


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
    #: Only to write the recordings of its seeds again (runs done already, journaled again
    #: never): what a resume owes for recordings a campaign lost (issue 36, item 1).
    record_only: bool = False


@dataclass(frozen=True)
class DesignSpec:
    """A campaign's sampled design (:mod:`cwrend_cli.campaign.design`) and its points' order."""

    kind: Design
    samples: int  # points (lhs, random) or base points (sobol)
    ranges: tuple[ParameterRange, ...]
    rows: tuple[str, ...]  # the point id of each design row, in design order
    #: sobol: second-order indices, the Saltelli scheme with the B_A^(i) rows as well
    second_order: bool = False

    def identity(self) -> dict[str, Any]:
        """What identifies the design's points (the sample count only where a larger design
        is not an extension of a smaller one: lhs; not ``second_order``, whose design
        contains the first-order one of the same samples)."""
        ident: dict[str, Any] = {
            "design": self.kind,
            "ranges": [[r.key, r.kind, r.low, r.high, r.log, list(r.values)] for r in self.ranges],
        }
        if self.kind == "lhs":
            ident["samples"] = self.samples
        return ident

    def unit(self, root_seed: int) -> np.ndarray:
        """The design's rows in the unit cube, in :attr:`rows` order (SALib's row order)."""
        kind, n, dims = self.kind, self.samples, len(self.ranges)
        return unit_samples(kind, n, dims, root_seed, self.second_order)


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
    run_timeout_s: float | None = None  # output.run_timeout_s (None: guards.run_timeout_s default)
    #: output.dask_no_worker_timeout_s [s]: a Dask cluster without workers this long stops it
    no_worker_timeout_s: float | None = None
    design: DesignSpec | None = None  # a sampled design instead of a grid (``grid`` is then empty)
    #: output.design_steps_points: the points with per-step data and recordings (None: all)
    steps_points: frozenset[str] | None = None
    #: the base's schedule.nis_offset was given (else each point's sensor fills it in; the
    #: resolved ``base`` has lost that: the manifest records it, outside the hashed config)
    nis_offset_given: bool = True
    #: the base's scenario.xf was given (else a point that introduces a corridor has its
    #: port at rest; recorded in the manifest as the offset's flag is)
    xf_given: bool = True

    @property
    def runs(self) -> tuple[RunSpec, ...]:
        """All runs, in plan order."""
        return tuple(r for t in self.tasks for r in t.runs)

    def steps_seeds_of(self, point: str) -> int | None:
        """Per-step data of ``point``'s runs below this seed (None: every seed; 0: none)."""
        return self.steps_seeds if self.steps_points is None or point in self.steps_points else 0

    def rrd_seeds_of(self, point: str) -> int | None:
        """Recordings of ``point``'s seeds below this seed (None: every seed; 0: none)."""
        return self.rrd_seeds if self.steps_points is None or point in self.steps_points else 0


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


def design_points(
    sweep: Mapping[str, Any],
    cli_params: Sequence[str],
    kind: Design,
    samples: int | None,
    root_seed: int,
    cli_ranges: Sequence[str] = (),
    second_order: bool = False,
    base: Mapping[str, Any] | None = None,
) -> tuple[DesignSpec, tuple[tuple[str, Assignment], ...]]:
    """The sampled points of a design over the ranges of ``[sweep]``, each point once.

    ``cli_ranges`` (``--range KEY=LOW:HIGH…``, :func:`~cwrend_cli.campaign.design.parse_cli_range`)
    add to or replace the ranges of ``[sweep]``; each of their keys must be a
    value of ``base`` (the resolved configuration). Rows of a design that
    sample identical values (integer or categorical ranges) are one point;
    :attr:`DesignSpec.rows` keeps each row's point.
    """
    if cli_params:
        raise ConfigError("--param gives grid values; a --design samples the ranges of [sweep]")
    if second_order and kind != "sobol":
        raise ConfigError(f"--second-order: second-order indices need --design sobol, not {kind}")
    if samples is None:
        raise ConfigError(f"--design {kind} needs --samples N")
    mixed = mixed_sweep_problem(sweep)
    if mixed is not None:
        raise ConfigError(mixed)
    by_key: dict[str, ParameterRange] = {}
    for key, spec in sweep.items():
        if not isinstance(spec, Mapping):
            raise ConfigError(
                f"[sweep] {key}: a --design samples ranges ({{ low = …, high = … }} or "
                "{ values = […] }), not a list of grid values"
            )
        by_key[key] = parse_range(key, spec)
    given: dict[str, str] = {}  # --range key -> its range as typed
    for text in cli_ranges:
        parsed = parse_cli_range(text)
        raw = text.split("=", 1)[1].strip()
        check_given_once(
            "--range", parsed.key, given, raw,
            f"give one range per key: --range {parsed.key}=LOW:HIGH or "
            f"--range {parsed.key}=V1,V2,… (a design samples each key once)",
        )  # fmt: skip
        given[parsed.key] = raw
        if base is not None:
            _check_range(base, parsed, f"--range {text}")
        by_key[parsed.key] = parsed
    if base is not None:  # the config's ranges a --range does not replace, as --range's
        for key in sweep:
            if key not in given:
                _check_range(base, by_key[key], f"[sweep] {key}", table=True)
    for parsed in by_key.values():  # what no swept key may be, as --param's (expand_grid)
        check_swept(parsed.key, parsed.values if parsed.kind == "choice" else None)
    if not by_key:
        raise ConfigError(
            f"--design {kind}: no ranges; give --range KEY=LOW:HIGH (e.g. --range "
            'schedule.beta=0.05:1.0) or a [sweep] range such as "schedule.beta" = '
            "{ low = 0.05, high = 1.0 }"
        )
    ranges = list(by_key.values())
    rows: list[str] = []
    points: dict[str, Assignment] = {}
    for assignment in sample_design(kind, ranges, samples, root_seed, second_order):
        pid = point_id(assignment)
        rows.append(pid)
        points.setdefault(pid, assignment)
    spec = DesignSpec(kind, samples, tuple(ranges), tuple(rows), second_order)
    return spec, tuple(points.items())


def _check_range(
    base: Mapping[str, Any], parsed: ParameterRange, where: str, table: bool = False
) -> None:
    """Refuse a design's range whose key is not a value of ``base`` (the resolved
    configuration) or whose bounds (or a choice's values) its key does not take, naming
    ``where`` (a ``--range`` option, or ``[sweep] KEY``: ``table``) and its syntax: else
    the first sampled point was refused as an invalid grid point, the range unnamed."""
    syntax = TABLE_RANGE_SYNTAX if table else RANGE_SYNTAX
    try:
        get_dotted(base, parsed.key)
    except (KeyError, IndexError, ValueError, TypeError):
        raise ConfigError(
            f"{where}: {parsed.key} is not a configuration value (a dotted key "
            f"such as schedule.beta or scenario.u_max_km_s2){_key_meant(base, parsed.key)}"
        ) from None
    for end, value in range_ends(parsed, table):
        try:
            _validated(base, ((parsed.key, value),), where)
        except ConfigError as exc:
            why = "; ".join(exc.problems) or str(exc)
            raise ConfigError(
                f"{where}: {end} = {value!r} is not a value {parsed.key} takes ({why}); "
                f"expected {syntax}"
            ) from None


def _key_meant(base: Mapping[str, Any], key: str) -> str:
    """``; did you mean 'schedule.beta'?`` for a dotted key that is not in ``base`` (the
    resolved configuration): the closest of its dotted keys."""

    def keys(node: Mapping[str, Any], prefix: str) -> list[str]:
        out = []
        for name, value in node.items():
            out.append(f"{prefix}{name}")
            if isinstance(value, Mapping):
                out.extend(keys(value, f"{prefix}{name}."))
        return out

    return did_you_mean(key, keys(base, ""))


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
        if key.startswith(CORRIDOR_PORT) and moves_port([key]):  # the port or an entry
            raise ConfigError(
                f"dispersions.{key}: the corridor's port cannot be dispersed: it is also the "
                "terminal state of every run of a grid point (scenario.xf, the port at rest), "
                "which a dispersed value does not move; sweep the port instead, each point "
                f"ending at its own, e.g. --param '{CORRIDOR_PORT}=[[0, 0, -0.25], "
                "[0, 0, -0.3]]', and drop it from [dispersions]"
            )
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
                hint = missing_key_hint(point_tree, key)
                raise ConfigError(
                    f"dispersions.{key}: no such config value to disperse "
                    f"(use a dotted key such as scenario.x0.2 or scenario.u_max_km_s2){hint}"
                ) from None
            if not isinstance(base, (int, float)) or isinstance(base, bool):
                raise ConfigError(
                    f"dispersions.{key}: the base value {base!r} is not a number "
                    "(point at a single number, e.g. scenario.x0.0)"
                )
            draw = base + draw
        out.append((key, float(draw)))
    return tuple(out)


#: Values of a grid point or dispersed run named in its error (the rest are counted).
_LISTED_VALUES = 5


def _validated(
    base: Mapping[str, Any],
    assignment: Assignment,
    what: str,
    offset_given: bool = True,
    xf_given_: bool = True,
) -> CwrendConfig:
    """The config ``base`` + ``assignment``, validated; errors name ``what`` and the values.

    ``offset_given``, ``xf_given_``: the base's ``schedule.nis_offset``, ``scenario.xf``
    was given by the user (:func:`~cwrend_cli.config.overrides.point_tree`).
    """
    tree = point_tree(base, assignment, offset_given, xf_given_)
    try:
        return config_from_dict(tree, source=what)
    except ConfigError as exc:
        values = assignment_text(assignment)
        raise ConfigError(f"{what} ({values}) is invalid:", exc.problems or (str(exc),)) from None


def assignment_text(assignment: Assignment) -> str:
    """``key = value, …`` of a grid point or dispersed run, as its errors name it."""
    values = ", ".join(f"{k} = {v!r}" for k, v in assignment[:_LISTED_VALUES])
    if len(assignment) > _LISTED_VALUES:  # a [sweep] of thousands of keys: the first few
        values += f", … {len(assignment):,} values in all"
    return values


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


def check_inputs(cfg: CwrendConfig) -> None:
    """Refuse the inputs of ``cfg`` that every campaign of it would refuse before running.

    The checks :func:`plan` makes of each point, made of the base configuration
    (``cwrend config validate``): the ``[dispersions]`` keys, drawn for seed 0 on
    top of the base (a key that names no number, a dispersed value that is invalid
    or cannot be applied to the physics parameters), and the noise file
    (:func:`~cwrend_cli.config.io.load_noise_file`: its columns and rows). Raises
    :class:`ConfigError` (or :class:`~cwrend_cli.errors.InputDataError`) with the
    message :func:`plan` gives.
    """
    if cfg.noise.file is not None:
        load_noise_file(cfg.noise.file, cfg.scenario.n_steps)
    if not cfg.dispersions:
        return
    base = _base_tree(cfg)
    dispersed = draw_dispersions(cfg.dispersions, base, cfg.noise.seed, 0)
    run_cfg = _validated(
        base, dispersed, "dispersed run (seed 0)", nis_offset_given(cfg), xf_given(cfg)
    )
    _check_typed(problem_of(cfg), dispersed, run_cfg, 0)


def check_sweep(cfg: CwrendConfig) -> None:
    """Refuse the ``[sweep]`` of ``cfg`` as every campaign of it would before running.

    The checks :func:`plan` makes of ``[sweep]`` (``cwrend config validate``), with its
    messages: a grid (lists, ``start:stop:num``) is expanded by
    :func:`~cwrend_cli.config.overrides.expand_grid` (its keys and values) and every grid
    point validated by :func:`grid_point_config`; a table of ranges is checked as
    ``sweep --design`` checks it (:func:`design_points`: each key a configuration value,
    each end one its key takes). Not checked: what depends on the command line (the
    size limits, ``--param``, ``--arch``). Raises :class:`ConfigError`.
    """
    if not cfg.sweep:
        return
    base = _base_tree(cfg)
    if any(is_range(v) for v in cfg.sweep.values()):
        # a design's ranges: checked as sweep --design checks them, one point sampled
        design_points(cfg.sweep, (), "random", 1, cfg.noise.seed, base=base)
        return
    offset_given, xf_set = nis_offset_given(cfg), xf_given(cfg)
    for pid, params in grid_points(expand_grid(cfg.sweep)):
        grid_point_config(base, pid, params, offset_given, xf_set)


def grid_point_config(
    base: Mapping[str, Any],
    pid: str,
    params: Assignment,
    offset_given: bool = True,
    xf_given_: bool = True,
) -> CwrendConfig:
    """The validated config of grid point ``pid`` (``base`` + ``params``): errors name the
    point and its values (:func:`_validated`)."""
    return _validated(base, params, f"grid point {pid}", offset_given, xf_given_)


def _base_tree(cfg: CwrendConfig) -> dict[str, Any]:
    """The resolved config of ``cfg`` without ``[sweep]`` and ``[dispersions]``: what every
    grid point and dispersed run starts from."""
    base = resolved_dict(cfg)
    base.pop("sweep", None)
    base.pop("dispersions", None)
    return base


def campaign_hash(
    base: Mapping[str, Any],
    grid: Sequence[tuple[str, Sequence[Any]]],
    input_digests: Sequence[str] = (),
    design: Mapping[str, Any] | None = None,
) -> str:
    """Hash of what determines a campaign's numbers (not where it is written).

    The resolved config (without ``[output]``), the grid, and the content
    digests of the input files (noise files): the same path with other
    content is another campaign (issue 20).
    """
    tree = {k: v for k, v in base.items() if k != "output"}
    identity: dict[str, Any] = {"config": tree, "grid": [[k, list(v)] for k, v in grid]}
    if input_digests:
        identity["inputs"] = sorted(set(input_digests))
    if design is not None:
        identity["design"] = dict(design)
    text = json.dumps(identity, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def _check_size(n_points: int, n_seeds: int, n_archs: int, allow_large: bool) -> None:
    """Refuse a plan beyond :mod:`cwrend_cli.limits` before it is expanded."""
    if n_points > MAX_POINTS and not allow_large:
        raise ConfigError(
            f"the sweep has {n_points:,} grid points (more than {MAX_POINTS:,}); "
            "pass --yes-large if you mean it"
        )
    runs = n_points * n_seeds * n_archs
    if runs > MAX_RUNS:
        raise ConfigError(
            f"{runs:,} runs ({n_points:,} points × {n_seeds:,} seeds × {n_archs} "
            f"architectures): at most {MAX_RUNS:,} per campaign; split it (e.g. by --seed-list)"
        )


#: At most this many seeds to a task when ``output.seeds_per_task`` is unset.
MAX_SEEDS_PER_TASK = 16
#: Tasks per worker wanted when ``output.seeds_per_task`` is unset (progress and balance).
TASKS_PER_WORKER = 4


def default_seeds_per_task(n_seeds: int, n_points: int, workers: int | None) -> int:
    """Seeds to a task when ``output.seeds_per_task`` is unset.

    As many as leave at least :data:`TASKS_PER_WORKER` tasks per worker (so
    the progress bar moves and no worker idles at the end), at most
    :data:`MAX_SEEDS_PER_TASK` (files and journal writes per run) and at
    least 1; ``workers=None`` (unknown) gives the maximum. The chunking never
    changes a number: a run's key and random streams depend on its seed, not
    on its task, and a resumed campaign skips its done runs whatever the
    chunking was.
    """
    if workers is None:
        return MAX_SEEDS_PER_TASK
    per_task = n_seeds * max(n_points, 1) // (TASKS_PER_WORKER * max(workers, 1))
    return max(1, min(MAX_SEEDS_PER_TASK, per_task))


def check_design_models(problem: Problem, archs: Sequence[Architecture]) -> None:
    """Refuse an architecture that cannot fly the configured design model (issue 33).

    Raises :class:`ConfigError` naming ``model.guidance`` and the architecture
    (:func:`cwrend_cli.physics.design_models.unsupported`); nothing runs.
    """
    if problem.model == DesignModel():
        return  # CW: every architecture (and no physics import on this path)
    from cwrend_cli.physics.design_models import unsupported

    for arch in archs:
        constrained = problem.constraints is not None and problem.constraints.enforce
        reason = unsupported(problem.model, arch, problem.guidance, constrained)
        if reason is not None:
            raise ConfigError(reason)


def check_terminal_state(
    cfg: CwrendConfig, problem: Problem, archs: Sequence[Architecture]
) -> None:
    """Refuse a cone-program architecture that would plan into the keep-out zone.

    With the constraints enforced and no corridor, a ``scenario.xf`` inside the zone
    leaves no safe plan: every re-solve would end softened by the zone's depth. Raises
    :class:`ConfigError` naming ``scenario.xf`` (:func:`~cwrend_cli.config.schema.
    end_in_keep_out`); the shooting architectures and ``constraints.enforce = false`` only
    measure the zone and may end there.
    """
    if problem.constraints is None or not problem.constraints.enforce:
        return
    planned = [a.slug for a in archs if a.resolved_method(problem.guidance) == "socp"]
    reason = end_in_keep_out(cfg) if planned else None
    if reason is not None:
        xf = ", ".join(str(v) for v in cfg.scenario.xf)
        raise ConfigError(
            "invalid configuration",
            [f"scenario.xf = [{xf}]: {reason} (planned with the constraints by "
             f"{', '.join(planned)})"],
        )  # fmt: skip


def plan(
    cfg: CwrendConfig,
    archs: Sequence[str],
    seeds: Sequence[int],
    cli_params: Sequence[str] = (),
    seeds_per_task: int | None = None,
    allow_large: bool = False,
    design_kind: Design | None = None,
    samples: int | None = None,
    workers: int | None = None,
    ranges: Sequence[str] = (),
    second_order: bool = False,
) -> CampaignPlan:
    """Expand a campaign into tasks, validating every run's resolved config first.

    Each grid point's config is validated once and converted into the typed
    problem its tasks carry; each dispersed run's config is validated once.
    Raises :class:`ConfigError` naming the key and value of the first bad
    grid value or dispersion draw, or a plan beyond :mod:`cwrend_cli.limits`
    (more than ``MAX_POINTS`` points unless ``allow_large``); a noise file is
    read and checked once here. Nothing has run or been written then.

    With ``design_kind`` the points are sampled from the ranges of
    ``[sweep]`` and ``ranges`` (``--range`` options; :func:`design_points`)
    instead of forming a grid; ``second_order`` asks a ``sobol`` design for
    second-order indices.

    Seeds per task: ``seeds_per_task``, else ``output.seeds_per_task``, else
    :func:`default_seeds_per_task` for ``workers`` (the executor's worker
    count; ``None``: at most 16 seeds a task).
    """
    unknown = [a for a in archs if a not in ALL_ARCHITECTURES]
    if unknown:
        raise ConfigError(
            f"unknown architecture(s) {', '.join(unknown)} "
            f"(allowed: {', '.join(ALL_ARCHITECTURES)})"
            f"{did_you_mean(unknown[0], list(ALL_ARCHITECTURES))}"
        )
    if len(set(seeds)) != len(seeds) or any(not 0 <= s <= MAX_SEED for s in seeds):
        raise ConfigError(f"seeds must be distinct integers in [0, {MAX_SEED}] (2**63 − 1)")
    base = _base_tree(cfg)
    root = cfg.noise.seed
    offset_given = nis_offset_given(cfg)  # else each point's sensor fills it in (issue 35)
    xf_set = xf_given(cfg)  # else a point that introduces a corridor ends at its port
    spec: DesignSpec | None = None
    if design_kind is None:
        if ranges or second_order:
            option = "--range" if ranges else "--second-order"
            raise ConfigError(f"{option} defines a sampled design: add --design lhs|sobol|random")
        grid = expand_grid(cfg.sweep, cli_params)
        _check_size(math.prod(len(v) for _, v in grid), len(seeds), len(archs), allow_large)
        points = grid_points(grid)
    else:
        grid = ()
        spec, points = design_points(
            cfg.sweep, cli_params, design_kind, samples, root, ranges, second_order, base
        )
        _check_size(len(spec.rows), len(seeds), len(archs), allow_large)
    seeds_per_task = (
        seeds_per_task
        or cfg.output.seeds_per_task
        or default_seeds_per_task(len(seeds), len(points), workers)
    )
    tasks = []
    digests: list[str] = []
    noises: dict[tuple[int, str | None, int], NoiseSource] = {}
    for pid, params in points:
        point_cfg = grid_point_config(base, pid, params, offset_given, xf_set)
        point_tree = resolved_dict(point_cfg)
        problem = problem_of(point_cfg)
        check_design_models(problem, [ALL_ARCHITECTURES[a] for a in archs])
        check_terminal_state(point_cfg, problem, [ALL_ARCHITECTURES[a] for a in archs])
        noise_key = (point_cfg.noise.seed, point_cfg.noise.file, problem.scenario.n_steps)
        noise = noises.get(noise_key)
        if noise is None:  # a noise file is hashed and checked once, not once per point
            noise = noises[noise_key] = noise_source(point_cfg)
            if noise.file is not None and noise.digest is not None:
                load_noise_file(noise.file, problem.scenario.n_steps)  # refused before any run
                digests.append(noise.digest)
        for start in range(0, len(seeds), seeds_per_task):
            chunk = seeds[start : start + seeds_per_task]
            runs: list[RunSpec] = []
            for seed in chunk:
                dispersed = draw_dispersions(cfg.dispersions, point_tree, root, seed)
                if dispersed:
                    run_cfg = _validated(
                        base,
                        params + dispersed,
                        f"dispersed run (seed {seed})",
                        offset_given,
                        xf_set,
                    )
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
        campaign_hash=campaign_hash(base, grid, digests, spec.identity() if spec else None),
        # the hash of ``base`` as a config, without validating it again
        config_hash=config_hash(cfg.model_copy(update={"sweep": {}})),
        root_seed=root,
        steps_seeds=cfg.output.steps_seeds,
        rrd_seeds=cfg.output.rrd_seeds,
        run_timeout_s=cfg.output.run_timeout_s,
        no_worker_timeout_s=cfg.output.dask_no_worker_timeout_s,
        design=spec,
        steps_points=_steps_points(spec, cfg.output.design_steps_points),
        nis_offset_given=offset_given,
        xf_given=xf_set,
    )


def _steps_points(spec: DesignSpec | None, first: int) -> frozenset[str] | None:
    """The first ``first`` distinct points of a design in design order (None: not a design)."""
    if spec is None:
        return None
    return frozenset(list(dict.fromkeys(spec.rows))[:first])
