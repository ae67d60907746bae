"""Executing runs: a campaign task in a worker process, and the single case of ``cwrend run``.

:func:`execute_task` receives a :class:`~cwrend_cli.campaign.plan.Task` (the
grid point's typed problem, its noise source and the runs) and the point's
open-loop references, computed once by the driver. For each run it applies
the run's dispersed values to the typed problem
(:func:`~cwrend_cli.config.adapt.with_values`), draws the seed's noise and
simulates; it never validates a configuration nor builds a pydantic model
(the plan validated every run). A dispersed run whose scenario or solver
differs from its point's computes its own references, kept in a dict local to
the task (there is no module-level cache). The worker writes the task's
per-architecture ``steps``/``solves`` Parquet files and the Rerun recordings
of the seeds it is asked to record, and returns small outcomes that the
driver journals.

The noise of realisation ``seed`` is the stream ``SeedSequence(noise.seed,
spawn_key=(seed, 0))`` (or ``noise.file`` replayed), so realisation ``seed``
is the same in a single run, an ablation and a sweep, whatever worker
computes it. All architectures of a seed share it (a fair comparison: a convention of cwrend;
not in the paper, see docs/method.md).

Every other random draw of a run has its own child of the realisation's
seed: ``(seed, 1)`` the dispersions (:mod:`cwrend_cli.campaign.plan`),
``(seed, 2)`` the per-step actuator errors (:func:`actuator_seed_sequence`;
magnitude and pointing from its children 0 and 1,
:func:`cwrend_cli.physics.actuator.draw`). They are drawn here, outside the
physics, and only when the run's actuator has per-step noise; switching one
on changes no other draw, and a run with the actuator ideal gets exactly the
numbers it had before actuators existed. ``(seed, 3)`` the sensor faults of
the degradation windows (:func:`fault_seed_sequence`; children 0 dropout,
1 outlier, 2 bias drift, :func:`cwrend_cli.physics.sensors.draw_faults`),
drawn only for the fault kinds some window of the run switches on.
"""

from __future__ import annotations

import functools
import hashlib
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cwrend_cli.campaign import guards
from cwrend_cli.campaign.plan import (
    Assignment,
    NoiseSource,
    RunSpec,
    Task,
    check_design_models,
    check_terminal_state,
    noise_source,
)
from cwrend_cli.config import CwrendConfig
from cwrend_cli.config.adapt import problem_of, with_values
from cwrend_cli.config.io import file_digest, load_noise_file
from cwrend_cli.errors import CwrendError, InputDataError
from cwrend_cli.output import recording
from cwrend_cli.output.files import write_parquet
from cwrend_cli.output.layout import SOLVES, STEPS, recording_path
from cwrend_cli.output.tables import campaign_solves_table, campaign_steps_table, summary_row
from cwrend_cli.physics import actuator, sensors, simulation
from cwrend_cli.physics.params import (
    ALL_ARCHITECTURES,
    Architecture,
    FloatArray,
    Problem,
    Scenario,
)
from cwrend_cli.physics.params import Solver as SolverParams
from cwrend_cli.teardown import (
    clear_stop,
    note_stop,
    on_stop,
    raise_stop,
    redeliver,
    redelivered,
    stop_asked,
    unraisable_stop,
)

__all__ = [
    "CaseResult",
    "InputChangedError",
    "ReferencesKey",
    "RunOutcome",
    "TaskInterrupted",
    "TaskOutcome",
    "actuator_draws",
    "actuator_seed_sequence",
    "attitude_draws",
    "execute_task",
    "fault_draws",
    "fault_seed_sequence",
    "noise_seed_sequence",
    "references_id",
    "references_key",
    "run_case",
    "seeds_to_record",
    "standard_normal",
    "standard_normal_for",
    "stop_task",
]

#: What the open-loop references of a problem depend on.
ReferencesKey = tuple[Scenario, SolverParams]


def references_key(problem: Problem) -> ReferencesKey:
    """The part of ``problem`` its open-loop references depend on: scenario and solver."""
    return (problem.scenario, problem.solver)


def references_id(key: ReferencesKey) -> str:
    """A stable name of the references of ``key``: ``r`` and 12 hex digits.

    The SHA-256 of the key's ``repr`` (the scenario's and the solver's
    fields: numbers, tuples of numbers and words), so every grid point with
    the same scenario and solver names one file, in any process.
    """
    return "r" + hashlib.sha256(repr(key).encode()).hexdigest()[:12]


# ---------------------------------------------------------------------------
# Noise and the single case
# ---------------------------------------------------------------------------


def noise_seed_sequence(root_seed: int, seed: int) -> np.random.SeedSequence:
    """Stream of the measurement noise of realisation ``seed``."""
    return np.random.SeedSequence(root_seed, spawn_key=(seed, 0))


def actuator_seed_sequence(root_seed: int, seed: int) -> np.random.SeedSequence:
    """Stream of the per-step actuator errors of realisation ``seed`` (independent of the noise)."""
    return np.random.SeedSequence(root_seed, spawn_key=(seed, 2))


def actuator_draws(problem: Problem, root_seed: int, seed: int) -> actuator.ActuatorDraws | None:
    """The actuator draws of realisation ``seed``, or ``None`` when ``problem`` needs none."""
    if not problem.actuator.noisy:
        return None
    return actuator.draw(actuator_seed_sequence(root_seed, seed), problem.scenario.n_steps)


def fault_seed_sequence(root_seed: int, seed: int) -> np.random.SeedSequence:
    """Stream of the sensor faults of realisation ``seed`` (independent of every other)."""
    return np.random.SeedSequence(root_seed, spawn_key=(seed, 3))


def fault_draws(problem: Problem, root_seed: int, seed: int) -> sensors.FaultDraws | None:
    """The sensor-fault draws of realisation ``seed``, or ``None`` when every fault is off."""
    if not sensors.fault_kinds(problem.degradation.windows).any:
        return None  # no stream to key (a SeedSequence costs more than the rest of the check)
    return sensors.draw_faults(
        fault_seed_sequence(root_seed, seed), problem.scenario.n_steps, problem.degradation.windows
    )


def attitude_seed_sequence(root_seed: int, seed: int) -> np.random.SeedSequence:
    """Stream of the attitude-knowledge error of realisation ``seed`` (issue 34; independent of
    every other)."""
    return np.random.SeedSequence(root_seed, spawn_key=(seed, 4))


def attitude_draws(problem: Problem, root_seed: int, seed: int) -> FloatArray | None:
    """The standard normals of realisation ``seed``'s attitude-knowledge error
    (:func:`cwrend_cli.physics.attitude.knowledge_error`), or ``None`` when it is off:
    6 for an error drawn once a run, (N steps, 6) for one drawn at every re-solve
    (``target.knowledge_draw = "resolve"``; the re-solve at step k takes row k, so the
    draws depend on the seed only, not on when or where the run is computed)."""
    target = problem.target
    if not target.knowledge_error:
        return None
    rng = np.random.default_rng(attitude_seed_sequence(root_seed, seed))
    if target.knowledge_draw == "resolve":
        return rng.standard_normal((problem.scenario.n_steps, 6))
    return rng.standard_normal(6)


def standard_normal(noise: NoiseSource, seed: int, n_steps: int) -> FloatArray:
    """The standard-normal realisation (N, 3) of ``seed`` from ``noise``.

    ``noise.file`` is replayed (validated for length and finiteness);
    otherwise the stream :func:`noise_seed_sequence` of the root seed.
    """
    if noise.file is not None:
        if noise.digest is None:
            return load_noise_file(noise.file, n_steps)
        try:  # planned: the file must still hold what was planned
            unchanged = file_digest(noise.file) == noise.digest
        except InputDataError as exc:  # deleted or unreadable since
            reason = f"unusable since the campaign was planned ({exc})"
        else:
            if unchanged:  # the file as planned: what is wrong with it was so from the start
                return load_noise_file(noise.file, n_steps)
            reason = "changed since the campaign was planned"
        raise InputChangedError(
            f"noise.file = {noise.file!r} {reason}; a campaign replays one realisation, so it "
            "stopped and recorded no run for it: restore the file and run the same command "
            "to resume, or start over with --force"
        )
    return sensors.standard_normal_stream(noise_seed_sequence(noise.root_seed, seed), n_steps)


class InputChangedError(InputDataError):
    """An input of a planned campaign (its noise file) changed while it ran (exit 2).

    Not a run's failure: it escapes :func:`execute_task`, and the driver
    stops the campaign at once without journaling the task (issue 36, item 5).
    """


def standard_normal_for(cfg: CwrendConfig, seed: int) -> FloatArray:
    """The standard-normal realisation (N, 3) of one seed of a validated config."""
    return standard_normal(noise_source(cfg), seed, cfg.scenario.n_steps)


@dataclass(frozen=True)
class CaseResult:
    """The closed-loop runs of one seed and the scenario's open-loop references."""

    runs: tuple[simulation.RunResult, ...]
    references: simulation.References


def run_case(
    cfg: CwrendConfig,
    archs: Sequence[Architecture],
    seed: int,
    refs: simulation.References | None = None,
) -> CaseResult:
    """Run ``archs`` on the noise of ``seed`` (references computed if not given)."""
    noise = standard_normal_for(cfg, seed)  # validate input before any computation
    problem = problem_of(cfg)
    check_design_models(problem, archs)
    check_terminal_state(cfg, problem, archs)
    refs = refs if refs is not None else simulation.open_loop_references(problem)
    draws = actuator_draws(problem, cfg.noise.seed, seed)
    faults = fault_draws(problem, cfg.noise.seed, seed)
    knowledge = attitude_draws(problem, cfg.noise.seed, seed)
    runs = tuple(
        simulation.simulate(
            problem,
            a,
            noise,
            refs,
            seed=seed,
            actuator_draws=draws,
            fault_draws=faults,
            attitude_draws=knowledge,
        )
        for a in archs
    )
    for run in runs:
        guards.check_finite(run)
    return CaseResult(runs, refs)


# ---------------------------------------------------------------------------
# Executing one task (in a worker process)
# ---------------------------------------------------------------------------


#: Compiled variants this process has started a run of (:func:`kernel_variant`): the first
#: run of each also loads (or compiles) its kernels, which its time limit allows for
#: (:func:`guards.run_timeout_s`).
_VARIANTS_RUN: set[tuple[object, ...]] = set()
#: The initial constrained plans this process made (:func:`.simulation.simulate`'s
#: ``initial_plans``): every seed of a campaign point starts from the same estimate, so a
#: worker plans that start once (issue 32's study: 0.25 of the 0.68 CPU s of a
#: constrained fixed-ε run, docs/performance.md).
_INITIAL_PLANS: simulation.InitialPlans = {}


def kernel_variant(
    problem: Problem, arch: str, draws: tuple[Any, ...] | None = None
) -> tuple[object, ...]:
    """What chooses the compiled code a run of ``arch`` on ``problem`` loads or compiles.

    The architecture and the step loop's entry point with the exact argument
    types of the run (:func:`cwrend_cli.physics.simulation.loop_signature`, what
    the first-run notice asks numba's cache about): each choice of truth,
    actuator, sensor, filter, process noise, hold and design model that types
    the loop differently is its own specialisation, 10-15 CPU s on a fresh
    install, so the first run of each gets the first-run allowance of its time
    limit, not only the first run of each architecture. ``draws``: the run's
    standard normals, actuator and fault draws; by default those of seed 0 (the
    types depend on the problem, not on the seed). Any failure to type the loop
    counts as one variant per architecture.
    """
    if draws is None:
        n_steps = problem.scenario.n_steps
        draws = (
            sensors.standard_normal_stream(noise_seed_sequence(0, 0), n_steps),
            actuator_draws(problem, 0, 0),
            fault_draws(problem, 0, 0),
        )
    try:
        dispatcher, signature = simulation.loop_signature(problem, ALL_ARCHITECTURES[arch], *draws)
    except Exception:  # the run itself reports what is wrong with its problem
        return (arch,)
    return (arch, dispatcher, signature)


def compile_ahead(task: Task) -> None:
    """Compile a first run's step loop for ``task``'s runs (in a pool worker).

    :func:`cwrend_cli.physics.compiled.compile_ahead` with the problem and
    draws of the task's first run and the architectures of its runs, while
    the campaign process compiles the references' solver (issue 37 item 12).
    Compiles into numba's cache and returns nothing; a failure here is only
    a lost head start (each run compiles what it needs), so it is swallowed.
    """
    from cwrend_cli.physics import compiled

    _compile_for(task, compiled.compile_ahead)


def compile_top(task: Task) -> None:
    """Compile a first run's compiled loop's top for ``task``'s runs (in a pool worker).

    :func:`cwrend_cli.physics.compiled.compile_ahead` of the loop's top, as :func:`compile_ahead`
    (after it and :func:`compile_newton`; issue 37 item 12).
    """
    from cwrend_cli.physics import compiled

    _compile_for(task, functools.partial(compiled.compile_ahead, top=True))


def _compile_for(task: Task, compile_: Any) -> None:
    """``compile_`` with the problem and draws of ``task``'s first run and its architectures;
    a failure swallowed (:func:`compile_ahead`)."""
    try:
        compile_(*_first_run(task))
    except Exception:  # the runs compile what they need themselves
        return


def _first_run(task: Task) -> tuple[Any, ...]:
    """The problem, architectures and draws of ``task``'s first run (:func:`compile_ahead`)."""
    spec = task.runs[0]
    problem = with_values(task.problem, spec.dispersed)
    return (
        problem,
        [ALL_ARCHITECTURES[r.arch] for r in task.runs],
        standard_normal(task.noise, spec.seed, problem.scenario.n_steps),
        actuator_draws(problem, task.noise.root_seed, spec.seed),
        fault_draws(problem, task.noise.root_seed, spec.seed),
    )


def cold_loops(tasks: Iterable[Task]) -> set[str]:
    """The guidance methods whose step loop some of ``tasks`` compiles on its first run.

    :func:`cwrend_cli.physics.compiled.cold_loops` of the first run of each
    task, once per kind of loop (:func:`kernel_variant` of one architecture per
    guidance method, as that function asks: a task's runs repeat their
    architectures once per seed, and typing a loop takes about a millisecond):
    for the first-run notice. Any failure counts as cached (no notice).
    """
    from cwrend_cli.physics import compiled

    cold: set[str] = set()
    seen: set[tuple[object, ...]] = set()
    for task in tasks:
        if not task.runs:
            continue
        problem = task.problem
        one_per_method: dict[str, str] = {}
        for run in task.runs:
            method = ALL_ARCHITECTURES[run.arch].resolved_method(problem.guidance)
            one_per_method.setdefault(method, run.arch)
        key = tuple(kernel_variant(problem, arch) for arch in one_per_method.values())
        if key in seen:
            continue
        seen.add(key)
        try:
            cold |= compiled.cold_loops(*_first_run(task))
        except Exception:  # the notice must not break a command
            continue
    return cold


def cold_loops_of_case(cfg: CwrendConfig, archs: Sequence[Architecture], seed: int) -> set[str]:
    """:func:`cold_loops` of the case ``cwrend run`` flies: ``archs`` on the base config."""
    from cwrend_cli.physics import compiled

    problem = problem_of(cfg)
    try:
        return compiled.cold_loops(
            problem, archs, standard_normal_for(cfg, seed),
            actuator_draws(problem, cfg.noise.seed, seed),
            fault_draws(problem, cfg.noise.seed, seed),
        )  # fmt: skip
    except Exception:  # the notice must not break a command
        return set()


def compile_newton() -> None:
    """Compile the shooting solver's switching-time Newton (in a pool worker; issue 37 item 12).

    :func:`~cwrend_cli.physics.guidance._switching_kernels.compile_switching_newton`,
    the half of the references' solver that the campaign process does not
    compile (:func:`cwrend_cli.physics.compiled.compile_ascent`). A failure is
    only a lost head start, as in :func:`compile_ahead`.
    """
    from cwrend_cli.physics.guidance import _switching_kernels

    try:
        _switching_kernels.compile_switching_newton()
    except Exception:  # the references compile it themselves
        return


@dataclass(frozen=True)
class RunOutcome:
    """What a worker returns for one run: small, whatever the run's length."""

    spec: RunSpec
    status: str  # "ok" or "failed"
    metrics: dict[str, Any]  # output.tables.summary_row fields (empty when failed)
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
    files_s: float = 0.0  # the worker's time writing ``files`` (steps/solves, recordings) [s]


class TaskInterrupted(KeyboardInterrupt):
    """A task stopped by Ctrl-C (or its pool's stop): ``outcome`` holds the runs it finished.

    Their steps/solves files are written; the driver journals them, so an
    interrupted campaign keeps every finished run, not only whole tasks
    (issue 37 item 2). A ``KeyboardInterrupt``: in-process it stops the
    campaign as Ctrl-C does.
    """

    def __init__(self, outcome: TaskOutcome) -> None:
        super().__init__(outcome)
        self.outcome = outcome


#: Whether this process's main thread is running a task's runs now (:func:`execute_task`).
_RUNNING = {"runs": False}
#: How long a pool worker asked to stop lets the run in progress end before it interrupts
#: it [s]. Most runs end sooner (5-100 ms) and are kept; the interrupt lands at the run's
#: next Python code, or, swallowed by a callback of numba's compiler, is raised again
#: (:func:`cwrend_cli.teardown.unraisable_stop`); the run is dropped, never recorded failed.
STOP_PATIENCE_S = 0.25


def stop_task(signum: int) -> None:
    """Stop this pool worker's task and keep its finished runs (its handler of ``signum``).

    The run in progress may end (within :data:`STOP_PATIENCE_S`, then it is
    interrupted: the stop is raised into it from this same handler, again
    until it lands) and the task returns (:class:`TaskInterrupted`) with the
    runs it finished; a task that starts later stops before its first run. A
    second signal (the terminal's Ctrl-C, then the driver's) changes nothing.
    """
    if redelivered():  # STOP_PATIENCE_S is over, or an interrupt was swallowed
        if _RUNNING["runs"]:
            raise_stop()
        return
    if not stop_asked():
        note_stop(signum)
        if _RUNNING["runs"]:
            later = threading.Timer(STOP_PATIENCE_S, _interrupt_run)
            later.daemon = True
            later.start()


def _interrupt_run() -> None:
    """Interrupt the run in progress, if any (:func:`stop_task` raises in the main thread)."""
    if _RUNNING["runs"]:
        redeliver()


def _ctrl_c_noted() -> Callable[[], None]:
    """In-process, make a Ctrl-C this task's stop, as ``cwrend`` does; what restores.

    ``cwrend`` handles Ctrl-C itself (:func:`cwrend_cli.teardown.stop_on_signals`);
    a library caller's Python raises ``KeyboardInterrupt`` without noting it,
    and there it may become an error of the run or be swallowed by a compiler
    callback. For the task, Ctrl-C gets cwrend's handler: noted, the run is
    dropped rather than recorded failed, a swallowed stop is raised again, and
    the task stops before its next run at the latest. A pool worker's handler
    (:func:`stop_task`) notes its stop itself.
    """
    in_main = threading.current_thread() is threading.main_thread()
    if not in_main or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        return lambda: None
    hook = sys.unraisablehook
    signal.signal(signal.SIGINT, on_stop)
    sys.unraisablehook = unraisable_stop

    def restore() -> None:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        sys.unraisablehook = hook
        clear_stop()

    return restore


def execute_task(
    task: Task,
    refs: simulation.References | None,
    out_dir: str,
    record_seeds: tuple[int, ...] = (),
    steps_seeds: int | None = None,
    metadata: Mapping[str, str] | None = None,
    run_timeout_s: float | None = None,
    on_run: Callable[[bool], None] | None = None,
) -> TaskOutcome:
    """Run a task's runs, write their steps/solves files and return their outcomes.

    ``refs`` are the open-loop references of the task's point (``None``: each
    run computes them, as when the driver could not). A run that raises is
    returned as ``failed`` with its traceback; the other runs of the task go
    on. Files are written per task execution and architecture, as
    ``steps/arch=<slug>/<task_key>-<digest>.parquet`` (only seeds below
    ``steps_seeds`` when set), where the digest names the set of runs
    executed: rerunning the same runs overwrites the same files (atomically),
    so nothing is ever duplicated.

    For each seed of ``record_seeds`` (the driver passes only seeds whose
    every architecture runs in this task) a Rerun recording overlaying the
    architectures and the references is written to
    ``recordings/<point>.s<seed>.rrd``. A recording that cannot be written is
    reported in the outcome's ``warnings``; the runs stay valid, except when
    it cannot be written to disk (an :class:`OSError`: disk full, permission),
    which is an infrastructure fault like a steps file that cannot be written.
    A ``record_only`` task (a recording a resumed campaign owes) writes only
    its recordings: no steps/solves files, no outcomes, no per-run signals.

    The steps/solves files are complete when this returns but not
    necessarily on disk: the driver's journal flushes them before it records
    the task (:func:`cwrend_cli.campaign.journal.append_events`), so a
    worker does not wait for the disk between its tasks.

    ``metadata`` goes into the schema metadata of the steps/solves files
    (the campaign's ``config_hash`` and ``campaign_hash``, issue 18 item 5).

    A run also fails when its results are not finite or it runs longer than
    ``run_timeout_s`` (:mod:`cwrend_cli.campaign.guards`; default from its
    number of steps). An exception that escapes this function (an I/O error
    writing the files) is an infrastructure fault: the driver retries or
    stops, and records nothing.

    ``on_run`` is called after each run with whether it was ok (the driver's
    per-run progress, :func:`cwrend_cli.campaign.executors.run_signals`); it
    only informs: the outcome returned is what counts.

    Ctrl-C in-process, or :func:`stop_task` in a pool worker, stops the task:
    the run in progress is dropped, the files of the runs finished are
    written (named by those runs, no recordings: a resume writes the ones it
    owes) and :class:`TaskInterrupted` carries their outcome.
    """
    outcomes: list[RunOutcome] = []
    results: dict[str, list[tuple[RunSpec, simulation.RunResult]]] = {}
    by_seed: dict[int, list[tuple[Problem, simulation.RunResult]]] = {}
    # What this task computes once: the problem of each set of dispersed values,
    # the references of each (scenario, solver), the noise of each seed.
    problems: dict[Assignment, Problem] = {}
    references: dict[ReferencesKey, simulation.References] = {}
    if refs is not None:
        references[references_key(task.problem)] = refs
    noises: dict[tuple[Assignment, int], FloatArray] = {}  # shared by the archs of a seed
    variants: dict[tuple[Assignment, str], tuple[object, ...]] = {}  # kernel_variant's
    stopped = False
    restore = _ctrl_c_noted()
    _RUNNING["runs"] = True
    try:
        for spec in task.runs:
            if stop_asked():  # told to stop: no new run (a stop swallowed meanwhile too)
                raise_stop()
            started = time.time()
            t0 = time.perf_counter()
            try:
                problem = problems.get(spec.dispersed)
                if problem is None:
                    problem = problems[spec.dispersed] = with_values(task.problem, spec.dispersed)
                noise = noises.get((spec.dispersed, spec.seed))
                if noise is None:
                    n_steps = problem.scenario.n_steps
                    noise = noises[spec.dispersed, spec.seed] = standard_normal(
                        task.noise, spec.seed, n_steps
                    )
                draws = (
                    noise,
                    actuator_draws(problem, task.noise.root_seed, spec.seed),
                    fault_draws(problem, task.noise.root_seed, spec.seed),
                )
                variant = variants.get((spec.dispersed, spec.arch))
                if variant is None:  # the types depend on the problem, not on the seed
                    variant = kernel_variant(problem, spec.arch, draws)
                    variants[spec.dispersed, spec.arch] = variant
                first = variant not in _VARIANTS_RUN
                _VARIANTS_RUN.add(variant)
                limit = guards.run_timeout_s(run_timeout_s, problem, first=first)
                with guards.time_limit(limit):  # the references too, when computed here
                    run_refs = _references(problem, references)
                    result = simulation.simulate(
                        problem,
                        ALL_ARCHITECTURES[spec.arch],
                        noise,
                        run_refs,
                        spec.seed,
                        actuator_draws=draws[1],
                        fault_draws=draws[2],
                        attitude_draws=attitude_draws(problem, task.noise.root_seed, spec.seed),
                        initial_plans=_INITIAL_PLANS,
                    )
                guards.check_finite(result)
                metrics = summary_row(result, run_refs.fuel)
                results.setdefault(spec.arch, []).append((spec, result))
                by_seed.setdefault(spec.seed, []).append((problem, result))
                outcomes.append(
                    RunOutcome(spec, "ok", metrics, "", started, time.perf_counter() - t0)
                )
            except InputChangedError:  # the campaign's input, not this run: it stops
                raise
            except Exception as exc:  # failure isolation: the campaign goes on
                if stop_asked():  # what the interrupt became (in a library): not a result
                    raise_stop()
                kind = "error" if isinstance(exc, CwrendError) else type(exc).__name__
                text = f"{kind}: {exc}\n{traceback.format_exc(limit=8)}"
                outcomes.append(
                    RunOutcome(spec, "failed", {}, text, started, time.perf_counter() - t0)
                )
            if on_run is not None and not task.record_only:
                on_run(outcomes[-1].status == "ok")
        _RUNNING["runs"] = False
    except KeyboardInterrupt:  # the runs finished so far are kept (TaskInterrupted below)
        stopped = True
    finally:
        _RUNNING["runs"] = False
        restore()
    files: list[str] = []
    writing = time.perf_counter()  # the task's files: part of its job (TaskOutcome.files_s)
    # the runs executed: the task's, or those finished before a stop
    digest = hashlib.sha256(" ".join(o.spec.run_key for o in outcomes).encode()).hexdigest()[:8]
    if stopped:  # a result of the dropped run's, if any, is in no outcome and no file
        executed = {o.spec.run_key for o in outcomes}
        results = {a: [(s, r) for s, r in rs if s.run_key in executed] for a, rs in results.items()}
        record_seeds = ()
    if task.record_only:  # its runs are journaled already: a name of its own, no outcomes
        digest, outcomes, results = f"{digest}-rrd", [], {}
    for arch, items in sorted(results.items()):
        kept = [(s, r) for s, r in items if steps_seeds is None or s.seed < steps_seeds]
        for kind, chosen, build in (
            (SOLVES, items, campaign_solves_table),
            (STEPS, kept, campaign_steps_table),
        ):
            if not chosen:
                continue
            extra = {
                "run_key": [s.run_key for s, _ in chosen],
                "point": [s.point for s, _ in chosen],
            }
            rel = f"{kind}/arch={arch}/{task.task_key}-{digest}.parquet"
            table = build([r for _, r in chosen], extra, metadata)
            # not waiting for the disk: the journal flushes the files before it records the task
            write_parquet(table, Path(out_dir) / rel, durable=False, root=Path(out_dir))
            files.append(rel)
    warnings: list[str] = []
    for seed in record_seeds:
        cases = by_seed.get(seed, [])
        if not cases:
            continue
        rel = recording_path(task.point, seed)
        problem = cases[0][0]
        try:
            recording.record_case(
                Path(out_dir) / rel,
                [r for _, r in cases],
                _references(problem, references),
                problem.degradation.windows,
                u_max_km_s2=problem.scenario.u_max_km_s2,
                recording_name=f"cwrend {task.point} seed {seed}",
                root=Path(out_dir),
            )
            files.append(rel)
        except OSError:  # cannot write results (disk full): a fault, as for the tables above
            raise
        except Exception as exc:  # a recording never costs the runs
            warnings.append(f"{rel}: recording not written ({type(exc).__name__}: {exc})")
    outcome = TaskOutcome(
        f"{task.task_key}-{digest}",
        tuple(outcomes),
        tuple(files),
        tuple(warnings),
        time.perf_counter() - writing,
    )
    if stopped:
        raise TaskInterrupted(outcome)
    return outcome


def _references(
    problem: Problem, known: dict[ReferencesKey, simulation.References]
) -> simulation.References:
    """The references of ``problem``: from ``known``, else computed and added to it."""
    key = references_key(problem)
    refs = known.get(key)
    if refs is None:
        refs = known[key] = simulation.open_loop_references(problem)
    return refs


def seeds_to_record(task: Task, archs: Sequence[str], limit: int | None) -> tuple[int, ...]:
    """Seeds of ``task`` below ``limit`` (None = all) whose every architecture runs in it.

    A resumed or retried task that reruns only some architectures of a seed
    leaves that seed's existing recording alone rather than overwrite it with
    a partial one. A ``record_only`` task records every seed it holds below
    ``limit`` (its runs are the seed's ok runs, as the lost recording had).
    """
    if task.record_only:
        return tuple(sorted({r.seed for r in task.runs if limit is None or r.seed < limit}))
    counts: dict[int, int] = {}
    for r in task.runs:
        counts[r.seed] = counts.get(r.seed, 0) + 1
    return tuple(s for s, n in counts.items() if n == len(archs) and (limit is None or s < limit))
