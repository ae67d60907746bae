"""A run that does not raise can still fail: non-finite results and time limits (issue 21)."""

from __future__ import annotations

import dataclasses
import signal
import sys
import threading
import time
from collections.abc import Callable

import numpy as np
import pytest

from cwrend_cli.campaign import guards
from cwrend_cli.config import CwrendConfig
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.physics import simulation
from cwrend_cli.physics.params import ARCHITECTURES


@pytest.fixture(scope="module")
def run(paper_refs: simulation.References) -> simulation.RunResult:
    noise = np.random.default_rng(0).standard_normal((800, 3))
    problem = problem_of(CwrendConfig())
    return simulation.simulate(problem, ARCHITECTURES["mtf_adaptive"], noise, paper_refs)


def test_a_finite_run_passes(run: simulation.RunResult) -> None:
    guards.check_finite(run)  # NaN rows of NIS and measurements are by design


def test_a_non_finite_estimate_is_named_with_its_first_step(run: simulation.RunResult) -> None:
    x_hat = run.x_hat.copy()
    x_hat[5:, 2] = np.inf
    with pytest.raises(
        guards.NonFiniteRunError,
        match=r"non-finite estimate \(x_hat\) from t = 5 s \(step 5, 796 of 801 rows\)",
    ):
        guards.check_finite(dataclasses.replace(run, x_hat=x_hat))


def test_a_non_finite_miss_is_named(run: simulation.RunResult) -> None:
    with pytest.raises(guards.NonFiniteRunError, match="non-finite miss_km"):
        guards.check_finite(dataclasses.replace(run, miss_km=float("nan")))


def test_an_infinite_nis_on_a_measured_row_is_named(run: simulation.RunResult) -> None:
    nis = run.nis.copy()
    nis[300] = np.inf  # issue 36 item 7: R x 1e308 recorded such runs ok
    with pytest.raises(guards.NonFiniteRunError, match=r"non-finite NIS \(nis\) from t = 300 s"):
        guards.check_finite(dataclasses.replace(run, nis=nis))


def test_a_nan_nis_on_a_measured_row_is_named(run: simulation.RunResult) -> None:
    nis = run.nis.copy()
    nis[12] = np.nan
    with pytest.raises(guards.NonFiniteRunError, match=r"non-finite NIS \(nis\) from t = 12 s"):
        guards.check_finite(dataclasses.replace(run, nis=nis))


def test_nan_measurement_rows_of_a_dropout_pass(run: simulation.RunResult) -> None:
    dropout = run.dropout.copy()
    dropout[100:110] = True
    quiet = {name: getattr(run, name).copy() for name in ("y", "nis", "mtf_ratio", "score")}
    for values in quiet.values():
        values[100:110] = np.nan  # no measurement on those rows: NaN by design
    guards.check_finite(dataclasses.replace(run, dropout=dropout, **quiet))


def test_a_nan_nees_is_named(run: simulation.RunResult) -> None:
    nees = run.nees.copy()
    nees[40:] = np.nan  # issue 36 item 7: initial_error = 1e308 recorded mean_nees = NaN ok
    with pytest.raises(guards.NonFiniteRunError, match=r"non-finite NEES \(nees\) from t = 40 s"):
        guards.check_finite(dataclasses.replace(run, nees=nees))


def test_a_mean_nis_that_overflows_is_named(run: simulation.RunResult) -> None:
    nis = run.nis.copy()
    nis[1:200] = 1e308  # finite rows whose mean is not: the logged metric would be inf
    with pytest.raises(guards.NonFiniteRunError, match="non-finite mean_nis_nominal"):
        guards.check_finite(dataclasses.replace(run, nis=nis))


def test_a_block_longer_than_its_limit_raises_a_timeout() -> None:
    started = time.monotonic()
    expected = r"timed out: the run took longer than 0\.2 s"
    with pytest.raises(guards.RunTimeoutError, match=expected), guards.time_limit(0.2):
        while time.monotonic() - started < 10.0:
            time.sleep(0.01)
    assert time.monotonic() - started < 5.0


def test_no_limit_and_a_finished_block_leave_no_alarm_behind() -> None:
    with guards.time_limit(None):
        time.sleep(0.05)
    with guards.time_limit(0.1):
        pass
    time.sleep(0.2)  # an alarm left armed would raise here


def test_the_time_numba_spends_compiling_does_not_count_against_the_limit() -> None:
    """A 2 s compile (numba's own ``numba:compile`` event, announced here as numba's
    dispatcher does) inside a 1 s limit does not time the block out; the clock goes on
    afterwards with the time it had left, so the block still times out once it runs long."""
    from numba.core import event

    started = time.monotonic()
    with pytest.raises(guards.RunTimeoutError), guards.time_limit(1.0):
        with event.trigger_event("numba:compile"):
            time.sleep(2.0)
        compiled = time.monotonic()
        while time.monotonic() - started < 30.0:
            time.sleep(0.01)
    assert compiled - started >= 2.0  # the compile ran to its end
    assert time.monotonic() - compiled >= 0.5  # the limit's remaining second, not 0


def _in_a_thread(block: Callable[[], None]) -> BaseException | None:
    """Run ``block`` in a thread that is not the main one (as a Dask worker runs a task);
    what it raised, if anything."""
    raised: list[BaseException] = []

    def target() -> None:
        try:
            block()
        except BaseException as exc:  # handed to the test
            raised.append(exc)

    thread = threading.Thread(target=target)
    thread.start()
    thread.join(timeout=120.0)
    assert not thread.is_alive()
    return raised[0] if raised else None


def test_a_block_longer_than_its_limit_times_out_outside_the_main_thread() -> None:
    """A Dask worker runs its tasks in threads, where SIGALRM never arrives: the limit
    is kept there too (before, the block ran unlimited)."""

    def block() -> None:
        started = time.monotonic()
        with guards.time_limit(0.2):
            while time.monotonic() - started < 60.0:
                time.sleep(0.01)

    raised = _in_a_thread(block)
    assert isinstance(raised, guards.RunTimeoutError)
    assert str(raised) == "timed out: the run took longer than 0.2 s"


def test_a_finished_block_outside_the_main_thread_leaves_no_alarm_behind() -> None:
    def block() -> None:
        with guards.time_limit(0.05):
            pass
        waited = time.monotonic()
        while time.monotonic() - waited < 0.5:  # an alarm left armed would raise here
            time.sleep(0.01)

    assert _in_a_thread(block) is None


def test_compiling_outside_the_main_thread_does_not_count_against_the_limit() -> None:
    from numba.core import event

    times: dict[str, float] = {}

    def block() -> None:
        times["started"] = time.monotonic()
        with guards.time_limit(1.0):
            with event.trigger_event("numba:compile"):
                time.sleep(2.0)
            times["compiled"] = time.monotonic()
            while time.monotonic() - times["started"] < 30.0:
                time.sleep(0.01)

    assert isinstance(_in_a_thread(block), guards.RunTimeoutError)
    assert times["compiled"] - times["started"] >= 2.0  # the compile ran to its end
    assert time.monotonic() - times["compiled"] >= 0.5  # the limit's remaining second, not 0


def test_another_threads_compile_stops_this_threads_clock_too() -> None:
    """numba's events are process-wide: on a Dask worker one task's compile stops every
    task's clock. Deliberate (docs/guide/integrity.md, "Time limits"): a thread meeting a
    kernel meanwhile waits for numba's process-wide compiler lock with no event of its own,
    so a per-thread pause would count another run's compile against it."""
    from numba.core import event

    inside, compiled = threading.Event(), threading.Event()

    def block() -> None:
        with guards.time_limit(3.0):
            inside.set()
            while not compiled.is_set():  # a task waiting on the lock another thread holds
                time.sleep(0.01)

    thread_result: list[BaseException | None] = []
    runner = threading.Thread(target=lambda: thread_result.append(_in_a_thread(block)))
    runner.start()
    assert inside.wait(timeout=60.0)
    with event.trigger_event("numba:compile"):  # this thread compiles for twice the limit
        time.sleep(6.0)
    compiled.set()
    runner.join(timeout=60.0)
    assert thread_result == [None]


class _RaisesTheAlarmWhenCollected:
    """Raises SIGALRM in its ``__del__``: the timeout falls due where Python swallows it."""

    def __del__(self) -> None:
        signal.raise_signal(signal.SIGALRM)


def test_a_timeout_due_in_a_del_is_raised_after_it_not_swallowed() -> None:
    """Python prints ("Exception ignored") and drops what escapes a ``__del__`` or a ctypes
    callback (llvmlite's, loading a kernel): the run went on unlimited, a traceback on
    stderr. The timeout waits for the block to leave such code, then is raised."""
    unraisable: list[object] = []
    previous = sys.unraisablehook
    sys.unraisablehook = unraisable.append
    try:
        with pytest.raises(guards.RunTimeoutError), guards.time_limit(1000.0):
            _RaisesTheAlarmWhenCollected()  # collected at once: its __del__ runs here
            for _ in range(10_000):  # the timeout, tried again a millisecond later, ends this
                time.sleep(0.001)
    finally:
        sys.unraisablehook = previous
    assert unraisable == []


def test_a_timeout_due_in_an_llvmlite_callback_is_raised_after_it_not_swallowed() -> None:
    """llvmlite calls numba's object cache through ctypes when it loads or emits a
    kernel (``ExecutionEngine._raw_object_cache_notify``): the timeout a limit of
    0.2 s had there was printed as "Exception ignored" and lost."""
    import llvmlite.binding as llvm

    llvm.initialize_native_target()
    llvm.initialize_native_asmprinter()
    module = llvm.parse_assembly("define i32 @f() {\n  ret i32 1\n}\n")
    engine = llvm.create_mcjit_compiler(
        llvm.parse_assembly(""), llvm.Target.from_default_triple().create_target_machine()
    )
    engine.set_object_cache(notify_func=lambda module, data: signal.raise_signal(signal.SIGALRM))
    unraisable: list[object] = []
    previous = sys.unraisablehook
    sys.unraisablehook = unraisable.append
    try:
        with pytest.raises(guards.RunTimeoutError), guards.time_limit(1000.0):
            engine.add_module(module)
            engine.finalize_object()  # emits the module: the callback runs here
            for _ in range(10_000):  # the timeout, tried again a millisecond later, ends this
                time.sleep(0.001)
    finally:
        sys.unraisablehook = previous
    assert unraisable == []


def test_the_clock_stops_while_numba_holds_its_compiler_lock() -> None:
    """numba takes its compiler lock to load a kernel from its cache, with no compile
    event: loading the references' kernels (about 1.5 s) counted against the limit."""
    from numba.core.compiler_lock import global_compiler_lock

    with guards.time_limit(1000.0):
        assert signal.getitimer(signal.ITIMER_REAL)[0] > 0.0
        with global_compiler_lock:
            stopped = signal.getitimer(signal.ITIMER_REAL)
        assert signal.getitimer(signal.ITIMER_REAL)[0] > 0.0  # set again afterwards
    assert stopped == (0.0, 0.0)
