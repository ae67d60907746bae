"""Campaigns: what runs (a pure plan) and how one batch of runs is executed.

A campaign is a grid of parameter points × architectures × noise seeds, with
optional per-run dispersions. :func:`plan` turns a validated config into a
tuple of :class:`Task` (batches of :class:`RunSpec`) without side effects;
every run's resolved config is validated there, before anything runs.
:func:`execute_task` runs one batch in a worker and writes its per-run
Parquet files; :func:`run_campaign` drives the tasks through an executor and
keeps the journal.

Random streams are keyed by (noise.seed, realisation): the noise by
``(seed, 0)`` and the dispersion draws by ``(seed, 1)``, so every architecture
and grid point of a seed sees the same noise and the same dispersed values
(common random numbers), and the numbers do not depend on the worker count or
the executor.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import shutil
import time
import traceback
from collections.abc import Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from cwrend_cli import __version__
from cwrend_cli.campaign.executors import ExecutorKind, default_workers, open_executor
from cwrend_cli.config import (
    ARCHITECTURES,
    Architecture,
    CwrendConfig,
    Dispersion,
    config_from_dict,
    config_hash,
    resolved_dict,
)
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.config.io import load_noise_file
from cwrend_cli.config.overrides import apply, expand_grid, get_dotted
from cwrend_cli.errors import ConfigError, CwrendError
from cwrend_cli.output import recording
from cwrend_cli.output import tables as storage
from cwrend_cli.physics import sensors, simulation

BASE_POINT = "base"


@dataclass(frozen=True)
class CaseResult:
    """The closed-loop runs of one seed and the scenario's open-loop references."""

    runs: tuple[simulation.RunResult, ...]
    references: simulation.References


def standard_normal_for(cfg: CwrendConfig, seed: int) -> np.ndarray:
    """The standard-normal realisation (N, 3) of one seed.

    ``noise.file`` replays an external realisation (validated for length and
    finiteness); otherwise the stream ``SeedSequence(noise.seed,
    spawn_key=(seed, 0))``, so realisation ``seed`` is the same in a single
    run, an ablation and a sweep, whatever worker computes it. All
    architectures of a seed share it (SPEC §6).
    """
    n_steps = cfg.scenario.n_steps
    if cfg.noise.file is not None:
        return load_noise_file(cfg.noise.file, n_steps)
    return sensors.standard_normal_stream(noise_seed_sequence(cfg.noise.seed, seed), n_steps)


def noise_seed_sequence(root_seed: int, seed: int) -> np.random.SeedSequence:
    """Stream of the measurement noise of realisation ``seed``."""
    return np.random.SeedSequence(root_seed, spawn_key=(seed, 0))


def dispersion_seed_sequence(root_seed: int, seed: int) -> np.random.SeedSequence:
    """Stream of the dispersion draws of realisation ``seed`` (independent of the noise)."""
    return np.random.SeedSequence(root_seed, spawn_key=(seed, 1))


def run_case(
    cfg: CwrendConfig,
    archs: tuple[Architecture, ...],
    seed: int,
    refs: simulation.References | None = None,
) -> CaseResult:
    """Run ``archs`` on the noise of ``seed`` (references computed if not given)."""
    noise = standard_normal_for(cfg, seed)  # validate input before any computation
    refs = refs if refs is not None else simulation.open_loop_references(problem_of(cfg))
    runs = tuple(simulation.simulate(problem_of(cfg), a, noise, refs, seed=seed) for a in archs)
    return CaseResult(runs, refs)


# ---------------------------------------------------------------------------
# The plan (pure)
# ---------------------------------------------------------------------------

Assignment = tuple[tuple[str, Any], ...]


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
    """A batch of runs executed together (one grid point, a chunk of seeds, all archs)."""

    task_key: str
    runs: tuple[RunSpec, ...]


@dataclass(frozen=True)
class CampaignPlan:
    """Everything a campaign will run, decided before anything runs."""

    base: Mapping[str, Any]  # resolved base config (JSON tree)
    grid: tuple[tuple[str, tuple[Any, ...]], ...]
    seeds: tuple[int, ...]
    archs: tuple[str, ...]
    tasks: tuple[Task, ...]
    campaign_hash: str

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
    points = []
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
            draw = d.mean + d.std * rng.standard_normal()
        else:
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
    try:
        return config_from_dict(apply(base, assignment), source=what)
    except ConfigError as exc:
        values = ", ".join(f"{k} = {v!r}" for k, v in assignment)
        raise ConfigError(f"{what} ({values}) is invalid:", exc.problems or (str(exc),)) from None


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

    Raises :class:`ConfigError` naming the key and value of the first bad
    grid value or dispersion draw; nothing has run or been written then.
    """
    unknown = [a for a in archs if a not in ARCHITECTURES]
    if unknown:
        raise ConfigError(
            f"unknown architecture(s) {', '.join(unknown)} (allowed: {', '.join(ARCHITECTURES)})"
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
        for start in range(0, len(seeds), seeds_per_task):
            chunk = seeds[start : start + seeds_per_task]
            runs = []
            for seed in chunk:
                dispersed = draw_dispersions(cfg.dispersions, point_tree, root, seed)
                if dispersed:
                    _validated(base, params + dispersed, f"dispersed run (seed {seed})")
                runs.extend(
                    RunSpec(run_key(pid, a, seed), pid, a, seed, params, dispersed) for a in archs
                )
            tasks.append(Task(f"{pid}.s{chunk[0]:06d}-{chunk[-1]:06d}", tuple(runs)))
    base["sweep"] = {}
    base["dispersions"] = resolved_dict(cfg)["dispersions"]
    return CampaignPlan(
        base=base,
        grid=grid,
        seeds=tuple(seeds),
        archs=tuple(archs),
        tasks=tuple(tasks),
        campaign_hash=campaign_hash(base, grid),
    )


# ---------------------------------------------------------------------------
# Executing one task (in a worker process)
# ---------------------------------------------------------------------------

_REFERENCES_CACHE: dict[str, simulation.References] = {}
_CACHE_SIZE = 32


def _references(cfg: CwrendConfig) -> simulation.References:
    """Open-loop references, cached per worker by the sections they depend on."""
    key = json.dumps(
        [cfg.scenario.model_dump(mode="json"), cfg.solver.model_dump(mode="json")], sort_keys=True
    )
    if key not in _REFERENCES_CACHE:
        if len(_REFERENCES_CACHE) >= _CACHE_SIZE:
            _REFERENCES_CACHE.pop(next(iter(_REFERENCES_CACHE)))
        _REFERENCES_CACHE[key] = simulation.open_loop_references(problem_of(cfg))
    return _REFERENCES_CACHE[key]


@dataclass(frozen=True)
class RunOutcome:
    """What a worker returns for one run: small, whatever the run's length."""

    spec: RunSpec
    status: str  # "ok" or "failed"
    metrics: Mapping[str, Any]  # storage.summary_row fields (empty when failed)
    error: str
    started_at: float  # UNIX time
    duration_s: float


@dataclass(frozen=True)
class TaskOutcome:
    """A task's run outcomes and the files it wrote (relative to the campaign dir)."""

    execution: str  # task key and a digest of the runs executed
    outcomes: tuple[RunOutcome, ...]
    files: tuple[str, ...]
    warnings: tuple[str, ...] = ()  # e.g. a recording that could not be written


def execute_task(
    task: Task,
    base: Mapping[str, Any],
    out_dir: str,
    record_seeds: tuple[int, ...] = (),
) -> TaskOutcome:
    """Run a task's runs, write their steps/solves files and return their outcomes.

    A run that raises is returned as ``failed`` with its traceback; the other
    runs of the task go on. Files are written per task execution and
    architecture, as ``steps/arch=<slug>/<task_key>-<digest>.parquet`` (only
    seeds below ``output.steps_seeds`` when set), where the digest names the set
    of runs executed: rerunning the same runs
    overwrites the same files (atomically), so nothing is ever duplicated.

    For each seed of ``record_seeds`` (the driver passes only seeds whose
    every architecture runs in this task) a Rerun recording overlaying the
    architectures and the references is written to
    ``recordings/<point>.s<seed>.rrd``. A recording that cannot be written is
    reported in the outcome's ``warnings``; the runs stay valid.
    """
    outcomes: list[RunOutcome] = []
    results: dict[str, list[tuple[RunSpec, simulation.RunResult]]] = {}
    by_seed: dict[int, list[tuple[CwrendConfig, simulation.RunResult]]] = {}
    configs: dict[Assignment, CwrendConfig] = {}
    noises: dict[tuple[Assignment, int], np.ndarray] = {}  # shared by the archs of a seed
    for spec in task.runs:
        started = time.time()
        t0 = time.perf_counter()
        try:
            cfg = configs.get(spec.overrides)
            if cfg is None:
                cfg = configs[spec.overrides] = config_from_dict(apply(base, spec.overrides))
            refs = _references(cfg)
            noise = noises.get((spec.overrides, spec.seed))
            if noise is None:
                noise = noises[spec.overrides, spec.seed] = standard_normal_for(cfg, spec.seed)
            result = simulation.simulate(
                problem_of(cfg), ARCHITECTURES[spec.arch], noise, refs, spec.seed
            )
            metrics = storage.summary_row(result, refs.fuel.delta_v_km_s)
            results.setdefault(spec.arch, []).append((spec, result))
            by_seed.setdefault(spec.seed, []).append((cfg, result))
            outcomes.append(RunOutcome(spec, "ok", metrics, "", started, time.perf_counter() - t0))
        except Exception as exc:  # failure isolation: the campaign goes on
            kind = "error" if isinstance(exc, CwrendError) else type(exc).__name__
            text = f"{kind}: {exc}\n{traceback.format_exc(limit=8)}"
            outcomes.append(RunOutcome(spec, "failed", {}, text, started, time.perf_counter() - t0))
    files: list[str] = []
    digest = hashlib.sha256(" ".join(r.run_key for r in task.runs).encode()).hexdigest()[:8]
    limit = base["output"].get("steps_seeds")
    for arch, items in sorted(results.items()):
        kept = [(s, r) for s, r in items if limit is None or s.seed < limit]
        for kind, chosen, build in (
            ("solves", items, storage.campaign_solves_table),
            ("steps", kept, storage.campaign_steps_table),
        ):
            if not chosen:
                continue
            extra = {
                "run_key": [s.run_key for s, _ in chosen],
                "point": [s.point for s, _ in chosen],
            }
            rel = f"{kind}/arch={arch}/{task.task_key}-{digest}.parquet"
            storage.write_parquet(build([r for _, r in chosen], extra), Path(out_dir) / rel)
            files.append(rel)
    warnings: list[str] = []
    point = task.runs[0].point if task.runs else BASE_POINT
    for seed in record_seeds:
        cases = by_seed.get(seed, [])
        if not cases:
            continue
        rel = recording_path(point, seed)
        cfg = cases[0][0]
        try:
            recording.record_case(
                Path(out_dir) / rel,
                [r for _, r in cases],
                _references(cfg),
                cfg.degradation.windows,
                u_max_km_s2=cfg.scenario.u_max_km_s2,
                recording_name=f"cwrend {point} seed {seed}",
            )
            files.append(rel)
        except Exception as exc:  # a recording never costs the runs
            warnings.append(f"{rel}: recording not written ({type(exc).__name__}: {exc})")
    return TaskOutcome(f"{task.task_key}-{digest}", tuple(outcomes), tuple(files), tuple(warnings))


def recording_path(point: str, seed: int) -> str:
    """Where a campaign's recording of ``seed`` at grid point ``point`` goes (relative)."""
    return f"{storage.RECORDINGS}/{point}.s{seed:06d}.rrd"


def seeds_to_record(task: Task, archs: Sequence[str], limit: int | None) -> tuple[int, ...]:
    """Seeds of ``task`` below ``limit`` (None = all) whose every architecture runs in it.

    A resumed or retried task that reruns only some architectures of a seed
    leaves that seed's existing recording alone rather than overwrite it with
    a partial one.
    """
    counts: dict[int, int] = {}
    for r in task.runs:
        counts[r.seed] = counts.get(r.seed, 0) + 1
    return tuple(s for s, n in counts.items() if n == len(archs) and (limit is None or s < limit))


# ---------------------------------------------------------------------------
# Driving a campaign: resume, fan-out, journal
# ---------------------------------------------------------------------------


class Progress(Protocol):
    """What the driver reports while it works (the CLI draws it; tests may ignore it)."""

    def start(self, total: int, skipped: int) -> None:
        """``total`` runs to execute now; ``skipped`` already done."""

    def advance(self, ok: int, failed: int) -> None:
        """Runs just completed."""

    def close(self) -> None:
        """The campaign stopped."""


class _NoProgress:
    def start(self, total: int, skipped: int) -> None:
        pass

    def advance(self, ok: int, failed: int) -> None:
        pass

    def close(self) -> None:
        pass


@dataclass(frozen=True)
class CampaignSummary:
    """Outcome of one invocation of a campaign."""

    out_dir: Path
    executed: int
    skipped: int
    ok: int  # in the whole campaign directory
    failed: int  # in the whole campaign directory
    interrupted: bool


def _wipe(out_dir: Path) -> None:
    """Remove what a campaign writes (``--force``), nothing else."""
    for name in (storage.MANIFEST, storage.RUNS, storage.EVENTS, *STATS_FILES):
        (out_dir / name).unlink(missing_ok=True)
    for dataset in storage.DATASETS:
        if (out_dir / dataset).exists():
            shutil.rmtree(out_dir / dataset)


STATS_FILES = ("ablation.parquet", "sweep.parquet")


def _check_same_campaign(out_dir: Path, plan_: CampaignPlan) -> None:
    manifest = out_dir / storage.MANIFEST
    if not manifest.exists():
        return
    try:
        previous = json.loads(manifest.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        raise ConfigError(
            f"{manifest}: unreadable manifest; use --force to start the campaign over"
        ) from None
    if previous.get("campaign_hash") != plan_.campaign_hash:
        raise ConfigError(
            f"{out_dir} holds a campaign with a different configuration or grid "
            f"(hash {str(previous.get('campaign_hash'))[:12]}… vs {plan_.campaign_hash[:12]}…); "
            "use --force to start over, or another output.name"
        )


def _events_of(outcome: TaskOutcome, campaign: str) -> list[dict[str, Any]]:
    events: list[dict[str, Any]] = []
    for o in outcome.outcomes:
        s = o.spec
        common = {
            "run_key": s.run_key,
            "execution": outcome.execution,
            "campaign_hash": campaign,
        }
        events.append({"event": "run_started", "time": _iso(o.started_at), **common})
        events.append(
            {
                "event": "run_finished" if o.status == "ok" else "run_failed",
                "time": _iso(o.started_at + o.duration_s),
                **common,
                "point": s.point,
                "arch": s.arch,
                "seed": s.seed,
                "params": dict(s.params),
                "dispersed": dict(s.dispersed),
                "status": o.status,
                "metrics": dict(o.metrics),
                "error": o.error,
                "duration_s": o.duration_s,
            }
        )
    events.extend(
        {"event": "recording_failed", "time": _iso(time.time()), "error": w}
        for w in outcome.warnings
    )
    events.append(
        {
            "event": "task_done",
            "time": _iso(time.time()),
            "execution": outcome.execution,
            "files": list(outcome.files),
            "campaign_hash": campaign,
        }
    )
    return events


def _failed_outcome(task: Task, exc: BaseException) -> TaskOutcome:
    text = f"{type(exc).__name__}: {exc}"
    now = time.time()
    return TaskOutcome(
        f"{task.task_key}-lost",
        tuple(RunOutcome(r, "failed", {}, text, now, 0.0) for r in task.runs),
        (),
    )


def _iso(unix: float) -> str:
    return datetime.fromtimestamp(unix, tz=UTC).isoformat(timespec="milliseconds")


def run_campaign(
    plan_: CampaignPlan,
    out_dir: Path,
    *,
    command: str,
    executor_kind: ExecutorKind = "local",
    workers: int | None = None,
    address: str | None = None,
    force: bool = False,
    retry_failed: bool = False,
    progress: Progress | None = None,
) -> CampaignSummary:
    """Execute the runs of ``plan_`` not yet in ``out_dir``; keep everything computed.

    Completed runs (same campaign hash) are skipped, failed ones too unless
    ``retry_failed``; a changed configuration is refused unless ``force``,
    which starts over. Each finished task appends its run events and a
    ``task_done`` record to ``events.jsonl`` in one write, so an interrupted
    campaign (Ctrl-C or ``kill -9``) keeps every completed task and leaves no
    partial data: files of unfinished executions are removed on resume.
    """
    progress = progress or _NoProgress()
    out_dir.mkdir(parents=True, exist_ok=True)
    if force:
        _wipe(out_dir)
    _check_same_campaign(out_dir, plan_)
    journal = storage.load_journal(out_dir / storage.EVENTS)
    storage.remove_orphan_files(out_dir, journal.files)
    done = {k for k, e in journal.runs.items() if e["status"] == "ok" or not retry_failed}
    tasks = [
        Task(t.task_key, tuple(r for r in t.runs if r.run_key not in done)) for t in plan_.tasks
    ]
    tasks = [t for t in tasks if t.runs]
    total = sum(len(t.runs) for t in tasks)
    skipped = len(plan_.runs) - total
    started = time.time()
    manifest = {
        "cwrend_version": __version__,
        "command": command,
        "campaign_hash": plan_.campaign_hash,
        "config": plan_.base,
        "config_hash": config_hash(config_from_dict(plan_.base)),
        "grid": {k: list(v) for k, v in plan_.grid},
        "seeds": list(plan_.seeds),
        "root_seed": plan_.base["noise"]["seed"],
        "archs": list(plan_.archs),
        "executor": {"kind": executor_kind, "workers": workers, "address": address},
        "started_at": _iso(started),
        "status": "running",
    }
    storage.write_json(manifest, out_dir / storage.MANIFEST)
    interrupted = False
    progress.start(total, skipped)
    try:
        if tasks:
            if executor_kind == "local":  # no pool larger than the work (one task: in-process)
                workers = min(workers or default_workers(), len(tasks))
            with open_executor(executor_kind, workers, address) as (executor, parallel):
                _drive(executor, parallel, tasks, plan_, out_dir, progress)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        progress.close()
        journal = storage.load_journal(out_dir / storage.EVENTS)
        records = list(journal.runs.values())
        ok = sum(r["status"] == "ok" for r in records)
        failed = len(records) - ok
        storage.write_parquet(
            storage.runs_table(records, {"campaign_hash": plan_.campaign_hash}),
            out_dir / storage.RUNS,
        )
        manifest.update(
            finished_at=_iso(time.time()),
            status="interrupted" if interrupted else "complete",
            counts={"ok": ok, "failed": failed, "runs": len(records)},
        )
        storage.write_json(manifest, out_dir / storage.MANIFEST)
    return CampaignSummary(out_dir, total, skipped, ok, failed, interrupted)


def _drive(
    executor: Executor,
    parallel: int,
    tasks: Sequence[Task],
    plan_: CampaignPlan,
    out_dir: Path,
    progress: Progress,
) -> None:
    """Submit tasks with a bounded number in flight; journal each as it completes."""
    queue = iter(tasks)
    in_flight: dict[Future, Task] = {}
    limit = 2 * parallel
    events_path = out_dir / storage.EVENTS
    rrd_limit = plan_.base["output"].get("rrd_seeds")
    try:
        while True:
            while len(in_flight) < limit:
                task = next(queue, None)
                if task is None:
                    break
                record = seeds_to_record(task, plan_.archs, rrd_limit)
                future = executor.submit(execute_task, task, plan_.base, str(out_dir), record)
                in_flight[future] = task
            if not in_flight:
                return
            finished, _ = wait(in_flight, return_when=FIRST_COMPLETED)
            for future in finished:
                task = in_flight.pop(future)
                try:
                    outcome = future.result()
                except Exception as exc:  # the worker itself died or the task failed to run
                    outcome = _failed_outcome(task, exc)
                storage.append_events(events_path, _events_of(outcome, plan_.campaign_hash))
                n_ok = sum(o.status == "ok" for o in outcome.outcomes)
                progress.advance(n_ok, len(outcome.outcomes) - n_ok)
    except KeyboardInterrupt:
        for future in in_flight:
            future.cancel()
        raise
