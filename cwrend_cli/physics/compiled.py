"""Whether the compiled kernels a command needs are in numba's cache (the first-run notice).

numba compiles a kernel on its first call and keeps it on disk (``cache=True``:
``__pycache__`` beside the source, or ``NUMBA_CACHE_DIR``); only the first
command after an install or an upgrade compiles, which takes tens of seconds
on a small machine, where a warm command starts in about a second. Every
command that runs closed loops asks :func:`compile_seconds` first and says
``compiling kernels (first run only, about N s)…`` when it is not zero
(issue 37 item 12), so a first run does not look hung.

The check reads numba's own cache index of each entry point (the kernels
called from Python, which compile every kernel below them): an entry point is
cold when the index is missing, stale (its source changed), made by another
numba version or for another CPU, or holds no entry for its bytecode.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from cwrend_cli.physics import actuator, sensors
    from cwrend_cli.physics.params import Architecture, FloatArray, Problem

#: CPU seconds of the first compile of each entry point's kernels, with what it calls.
#: Measured in one process (``python -m benchmarks.compile_costs``: the paper ablation with
#: ``--workers 1`` into an empty ``NUMBA_CACHE_DIR``) on a 2-core AMD EPYC (znver4,
#: 2026-12-02, load average 10 from other jobs): the solver 16.7 CPU s, 31.2 CPU s for the
#: whole command (37.6 s before issue 37 item 12's fourth step, :func:`tune_for_compiling`;
#: 47.8 s before the third). The compiled loop, since its top calls the step loop and the
#: solver by their addresses (the fifth step; load average 4-5): its step loop 5.7 CPU s,
#: its top 3.2 s (was 11.3 s with the step loop, the top carrying both).
#: Machines differ by about 2x: the notice is the slower machine's figure. The cone
#: program's part was not measured again (24 s before the fourth step, less the same 17 %).
#: An estimate for the notice only: the machine and the scenario (a nonlinear truth, an
#: actuator with errors, a nonlinear sensor, an EKF) move it.
_COMPILE_CPU_S = {
    "references": 17.0,  # bang_bang_ascent: the open-loop references and every first plan
    "shooting": 9.0,  # _steps and _resolve_loop: the closed loop with its compiled re-solves
    "socp": 20.0,  # _advance and the cone program's grid kernels
}
#: Of each part, the CPU seconds a second process compiles (the step loop below the
#: re-solves, :func:`compile_ahead`: 5.7 s; then the solver's switching-time Newton less
#: its burn prediction: 2.5 s; then the compiled loop's top: 3.2 s) while the campaign
#: process compiles the references' dual ascent (:func:`compile_ascent`); on 2 cores or more
#: they overlap it.
_AHEAD_CPU_S = {"references": 2.5, "shooting": 9.0, "socp": 4.0}


#: The cyclic garbage collector's thresholds in cwrend's processes (Python's default:
#: 700, 10, 10). numba's compiler allocates millions of objects; at the default it collected
#: the youngest generation about 1,200 times while compiling the references' solver, 1.7 of
#: its 21 CPU s, against 0.5 s at these (2-core AMD EPYC, 2026-12-02; gc.callbacks timing).
GC_THRESHOLDS = (50_000, 20, 20)


def tune_for_compiling() -> None:
    """Make this process's numba compiles cheaper, changing nothing they compute.

    Called first in every cwrend process that may compile (the command, pool
    workers). Sets :data:`GC_THRESHOLDS`, and, unless set already,
    ``NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING``: numba builds an error
    message for every overload it tries and rejects while typing a kernel,
    and with highlighting on each one re-initialises colorama on stdout and
    stderr (a few % of a first compile). Has to run before numba is imported
    for the second; processes spawned afterwards inherit it.
    """
    import gc
    import os

    gc.set_threshold(*GC_THRESHOLDS)
    os.environ.setdefault("NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING", "1")


def _entry_points(part: str) -> tuple[Any, ...]:
    """The dispatchers whose compile brings in the kernels of ``part`` (see _COMPILE_CPU_S)."""
    from cwrend_cli.physics import _loop_kernels
    from cwrend_cli.physics.guidance import _grid_kernels, _switching_kernels

    if part == "references":
        return (_switching_kernels.bang_bang_ascent,)
    if part == "shooting":  # the loop's top calls the step loop by its address: both
        return (_loop_kernels._resolve_loop, _loop_kernels._steps)
    return (_loop_kernels._advance, _grid_kernels.grid_dual_ascent)


def _cached(dispatcher: Any, signature: tuple[Any, ...] | None = None) -> bool:
    """Whether numba's cache holds a compile of ``dispatcher``'s current code for this CPU.

    Reads the cache index as the dispatcher itself does on its first call
    (numba's ``IndexDataCacheFile``: version, source stamp), then its keys
    (signature, CPU and features, bytecode hash); private numba API, so any
    surprise counts as cached (no notice rather than a wrong one). With
    ``signature`` (argument types), a compile for exactly those: the step
    loop's entry points hold one per specialisation (:func:`cold_loops`).
    """
    try:
        cache = dispatcher._cache
        index = cache._cache_file._load_index()
        codegen = dispatcher.targetctx.codegen()
        if signature is not None:
            return cache._index_key(tuple(signature), codegen) in index
        return any(cache._index_key(key[0], codegen) == key for key in index)
    except Exception:  # a change of numba's internals must not break a command
        return True


def cold_loops(
    problem: Problem,
    archs: Iterable[Architecture],
    standard_normal: FloatArray,
    actuator_draws: actuator.ActuatorDraws | None = None,
    fault_draws: sensors.FaultDraws | None = None,
) -> set[str]:
    """The guidance methods of ``archs`` whose step loop for ``problem`` is not in numba's cache.

    Each choice of truth model, actuator errors, sensor, filter, process noise,
    hold and design model (``ss``: the model enters the loop as a kernel tuple)
    compiles its own specialisation of the step loop on its first run, with
    the kernels below it (a J2 truth's RK8 step: a minute and more on a small
    machine), while the entry points hold the paper's: asked about any
    compile, they said cached. This asks for the argument types of a run of
    the first of ``archs`` of each method (:func:`~cwrend_cli.physics.simulation.loop_signature`,
    with the draws of that run, as :func:`compile_ahead`); any failure counts
    as cached.
    """
    from cwrend_cli.physics import simulation

    first: dict[str, Architecture] = {}
    for arch in archs:
        first.setdefault(arch.resolved_method(problem.guidance), arch)
    cold = set()
    for method, arch in first.items():
        try:
            dispatcher, signature = simulation.loop_signature(
                problem, arch, standard_normal, actuator_draws, fault_draws
            )
        except Exception:  # the notice must not break a command
            continue
        if not _cached(dispatcher, signature):
            cold.add(method)
    return cold


def compile_seconds(
    methods: Iterable[str], fan_out: bool = False, loops: Iterable[str] = ()
) -> float:
    """About how many seconds the first closed loops with these guidance ``methods`` compile.

    ``methods``: ``"shooting"`` and/or ``"socp"``. 0 when every kernel they
    need is in numba's cache (the usual case: everything but the first run).
    ``fan_out``: a local campaign given two workers or more (its pool, or a
    helper process beside a campaign of one task), whose second process
    compiles :data:`_AHEAD_CPU_S` while the campaign process compiles the
    references' dual ascent (:func:`compile_ascent`), so those seconds overlap.
    ``loops``: methods whose step loop is cold for the runs' own configuration
    (:func:`cold_loops`) although their entry points hold another's.
    """
    parts = ["references", *sorted(set(methods))]
    cold = [
        part
        for part in parts
        if part in set(loops) or not all(_cached(d) for d in _entry_points(part))
    ]
    seconds = sum(_COMPILE_CPU_S[part] for part in cold)
    if fan_out and "references" in cold:
        seconds -= sum(_AHEAD_CPU_S.get(part, 0.0) for part in cold)
    return seconds


def compiling_notice(
    methods: Iterable[str], fan_out: bool = False, loops: Iterable[str] = ()
) -> str | None:
    """``compiling kernels (first run only, about N s)…``, or ``None`` when all is cached.

    ``fan_out`` and ``loops``: as for :func:`compile_seconds`.
    """
    seconds = compile_seconds(methods, fan_out, loops)
    if not seconds:
        return None
    return f"compiling kernels (first run only, about {5 * round(seconds / 5):.0f} s)…"


def references_cold() -> bool:
    """Whether the references' kernels are missing from numba's cache: a first run."""
    return not all(_cached(d) for d in _entry_points("references"))


def compile_ascent(problem: Problem) -> None:
    """Compile (or load) the references' dual ascent, the longest chain of a first compile.

    On a first run the campaign process compiles the shooting solver
    (``bang_bang_ascent``, for the references: about half of a first
    compile) before any run can start. Its two halves are compiled in two
    processes at once (issue 37 item 12): here the dual ascent
    (:func:`~cwrend_cli.physics.guidance._switching_kernels.compile_newton_ascent`:
    the ascent, its start selection, the dual evaluation, its breakpoints and
    switching times, nine levels that compile one after the other), in the
    second process the switching-time Newton
    (:func:`~cwrend_cli.physics.guidance._switching_kernels.compile_switching_newton`),
    after :func:`compile_ahead`. The campaign process then waits for the
    Newton and loads it rather than compiling it a second time; the solver's
    top is all that is left of it. Before the ascent it compiles the
    Newton's burn prediction
    (:func:`~cwrend_cli.physics.guidance._switching_kernels.compile_predicted_length`,
    about 1.9 of the Newton's 4.6 CPU s), which the second process then
    loads: the second process starts later (its own start-up) and has the
    step loop to compile first, and without it the campaign process waited
    for the Newton. ``problem``: the campaign's first point (its solver
    settings' types).
    """
    from cwrend_cli.physics import simulation
    from cwrend_cli.physics.guidance import _switching_kernels

    _switching_kernels.compile_predicted_length()
    _switching_kernels.compile_newton_ascent(simulation.solver_settings(problem).newton_fields)


def compile_ahead(
    problem: Problem,
    archs: Iterable[Architecture],
    standard_normal: FloatArray,
    actuator_draws: actuator.ActuatorDraws | None = None,
    fault_draws: sensors.FaultDraws | None = None,
    top: bool = False,
) -> None:
    """Compile a first run's step loop in a second process (issue 37 item 12).

    The step loop of the first of ``archs`` of each guidance method
    (:func:`cwrend_cli.physics.simulation.compile_loop`), which does not
    depend on the solver, while the campaign process compiles the
    references' dual ascent (:func:`compile_ascent`); then the same process
    compiles the solver's switching-time Newton, which the campaign process
    waits for. The step loop first: the campaign process needs the Newton
    only after the ascent (about 10 CPU s), by when the step loop (about 7 s)
    is done, and the ascent's switching-time search, which the Newton calls
    too, is cached by then, so neither process compiles it a second time.
    Then the same process compiles the compiled loop's top (``top``: the
    top of the first shooting architecture's loop,
    ``_resolve_loop``, with ``simulation.compile_loop``'s ``top``), which
    calls the step loop and the solver by their addresses and so compiles
    without either; what is left for the runs is the cone program's grid
    kernels.
    ``problem`` and the draws: those of the campaign's first run, so that
    the argument types are the runs' own.
    """
    from cwrend_cli.physics import simulation

    first: dict[str, Architecture] = {}
    for arch in archs:
        first.setdefault(arch.resolved_method(problem.guidance), arch)
    methods = ["shooting"] if top and "shooting" in first else [] if top else sorted(first)
    for method in methods:  # shooting's step loop first: the cone program's links it
        simulation.compile_loop(
            problem, first[method], standard_normal, actuator_draws, fault_draws, top
        )
