"""What each compiled kernel costs to compile on a first run (issue 37 item 12).

    python -m benchmarks.compile_costs [CWREND ARGS…]

Runs one cwrend command in this process (default: the paper ablation with
``--workers 1 --no-rrd`` into a temporary directory) with numba's cache in a
new empty directory, and prints, per compiled function and signature, the CPU
seconds numba spent compiling it *exclusive* of the functions it compiled
on the way (its callees), and of those how many inside LLVM (numba's
``numba:llvm_lock`` events: optimising and emitting machine code, with the
callees' code linked in), from numba's own ``numba:compile`` events. The
inclusive figure of a top-level kernel is the whole cost of its first call.

By hand only, never in CI. CPU seconds (``time.process_time``) of this
process: other load on the machine moves them far less than wall time.

Measured (AMD EPYC znver4, 2 vCPU, 2026-12-02, load average 10 from other
jobs; docs/performance.md, "The first run"): 29.4 CPU s compiling (16.7 in
LLVM), 31.2 CPU s the command, against 35.5 and 37.6 before issue 37 item
12's fourth step (``compiled.tune_for_compiling``, the solver's two halves
in two processes); the solver 16.7 CPU s with its callees (the dual ascent
10.0, the switching-time Newton 4.6), the compiled loop's top 11.3 (its step
loop 6.1). Since the loop's top calls the step loop and the solver by address
(issue 37 item 12's fifth step; load average 3): compiling 21.7 and 24.6 CPU s against
23.6 and 25.4 before, in two interleaved pairs; the loop's top 2.6 CPU s with its callees
(9.9 before, the step loop compiled inside it). ``COMPILE_TREE=1`` prints the call tree
too. For the two processes of a real campaign, log numba's ``numba:compile`` events in each
(a listener installed before the command starts, e.g. from a
``sitecustomize`` module on ``PYTHONPATH``) with the process's CPU time.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import time
from collections import defaultdict
from typing import Any


def main(argv: list[str]) -> None:
    """Profile the compile of one cwrend command (module docstring)."""
    if "NUMBA_CACHE_DIR" not in os.environ or os.listdir(os.environ["NUMBA_CACHE_DIR"]):
        os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="cwrend-compile-costs-")
    from cwrend_cli.physics.compiled import tune_for_compiling

    tune_for_compiling()  # as the command's main() does, before numba is imported
    import numba.core.event as ev

    own: dict[str, float] = defaultdict(float)
    llvm: dict[str, float] = defaultdict(float)
    total: dict[str, float] = defaultdict(float)
    count: dict[str, int] = defaultdict(int)
    stack: list[list[Any]] = []  # [name, started, callees' seconds, llvm seconds]
    tree: list[tuple[int, str, float]] = []  # (depth, name, inclusive CPU s), in finishing order
    llvm_start: list[float] = []

    def name_of(data: dict[str, Any]) -> str:
        disp = data["dispatcher"]
        func = getattr(disp, "py_func", None)
        qual = f"{func.__module__.rsplit('.', 1)[-1]}.{func.__qualname__}" if func else str(disp)
        args = ", ".join(str(a) for a in data["args"])
        short = args if len(args) <= 60 else f"{args[:57]}…"
        return f"{qual}({short})"

    class Compiles(ev.Listener):  # type: ignore[misc]
        def on_start(self, event: Any) -> None:
            stack.append([name_of(event.data), time.process_time(), 0.0, 0.0])

        def on_end(self, event: Any) -> None:
            name, started, inner, in_llvm = stack.pop()
            spent = time.process_time() - started
            own[name] += spent - inner
            llvm[name] += in_llvm
            total[name] += spent
            count[name] += 1
            tree.append((len(stack), name, spent))
            if stack:
                stack[-1][2] += spent

    class Llvm(ev.Listener):  # type: ignore[misc]
        def on_start(self, event: Any) -> None:
            llvm_start.append(time.process_time())

        def on_end(self, event: Any) -> None:
            spent = time.process_time() - llvm_start.pop()
            if stack and not llvm_start:
                stack[-1][3] += spent

    from cwrend_cli.cli import app

    args = argv or ["ablate", "campaigns/paper.toml", "--no-rrd", "--workers", "1"]
    if not any(a.startswith("output.dir=") for a in args):
        out = tempfile.mkdtemp(prefix="cwrend-compile-costs-out-")
        args = [*args, "--set", f"output.dir={out}"]
    start_cpu = time.process_time()
    start_wall = time.perf_counter()
    with (
        ev.install_listener("numba:compile", Compiles()),
        ev.install_listener("numba:llvm_lock", Llvm()),
        contextlib.suppress(SystemExit),
    ):
        app(args, standalone_mode=False)
    cpu = time.process_time() - start_cpu
    wall = time.perf_counter() - start_wall
    if os.environ.get("COMPILE_TREE"):
        print("\n".join(_preorder(tree)))
    rows = sorted(own, key=own.__getitem__, reverse=True)
    print(f"{'own CPU s':>9} {'of it LLVM':>10} {'with callees':>12} {'n':>3}  function(signature)")
    for name in rows:
        print(f"{own[name]:9.2f} {llvm[name]:10.2f} {total[name]:12.2f} {count[name]:3d}  {name}")
    print(
        f"{sum(own.values()):9.2f} {sum(llvm.values()):10.2f} {'':>12} {sum(count.values()):3d}"
        f"  compiling, in all ({len(own)} signatures); the command: {cpu:.1f} CPU s, {wall:.1f} s"
    )


def _preorder(tree: list[tuple[int, str, float]]) -> list[str]:
    """The compile tree as indented lines, each caller above its callees (the last first).

    A function finishes compiling after its callees: the finishing order read
    backwards lists every caller before its callees.
    """
    out = []
    for depth, name, spent in reversed(tree):
        if spent >= 0.2:
            out.append(f"{'  ' * depth}{spent:6.2f}  {name}")
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
