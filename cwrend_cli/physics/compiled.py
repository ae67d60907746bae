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
from typing import Any

#: CPU seconds of the first compile of each entry point's kernels, with what it calls
#: (measured one after the other in one process on a 2-core Intel Xeon, Sapphire Rapids,
#: 2026-12-02, ``NUMBA_CACHE_DIR`` empty: the paper ablation compiled in 24-28 s).
#: An estimate for the notice only: the machine and the scenario (a nonlinear truth, an
#: actuator with errors) move it.
_COMPILE_CPU_S = {
    "references": 15.0,  # bang_bang_ascent: the open-loop references and every first plan
    "shooting": 9.0,  # _resolve_loop: the closed loop with its compiled re-solves
    "socp": 9.0,  # _advance and the cone program's grid kernels
}


def _entry_points(part: str) -> tuple[Any, ...]:
    """The dispatchers whose compile brings in the kernels of ``part`` (see _COMPILE_CPU_S)."""
    from cwrend_cli.physics import _loop_kernels
    from cwrend_cli.physics.guidance import _grid_kernels, _switching_kernels

    if part == "references":
        return (_switching_kernels.bang_bang_ascent,)
    if part == "shooting":
        return (_loop_kernels._resolve_loop,)
    return (_loop_kernels._advance, _grid_kernels.grid_dual_ascent)


def _cached(dispatcher: Any) -> bool:
    """Whether numba's cache holds a compile of ``dispatcher``'s current code for this CPU.

    Reads the cache index as the dispatcher itself does on its first call
    (numba's ``IndexDataCacheFile``: version, source stamp), then its keys
    (signature, CPU and features, bytecode hash); private numba API, so any
    surprise counts as cached (no notice rather than a wrong one).
    """
    try:
        cache = dispatcher._cache
        index = cache._cache_file._load_index()
        codegen = dispatcher.targetctx.codegen()
        return any(cache._index_key(key[0], codegen) == key for key in index)
    except Exception:  # a change of numba's internals must not break a command
        return True


def compile_seconds(methods: Iterable[str]) -> float:
    """About how many seconds the first closed loops with these guidance ``methods`` compile.

    ``methods``: ``"shooting"`` and/or ``"socp"``. 0 when every kernel they
    need is in numba's cache (the usual case: everything but the first run).
    """
    parts = ["references", *sorted(set(methods))]
    return sum(
        _COMPILE_CPU_S[part] for part in parts if not all(_cached(d) for d in _entry_points(part))
    )


def compiling_notice(methods: Iterable[str]) -> str | None:
    """``compiling kernels (first run only, about N s)…``, or ``None`` when all is cached."""
    seconds = compile_seconds(methods)
    if not seconds:
        return None
    return f"compiling kernels (first run only, about {5 * round(seconds / 5):.0f} s)…"
