"""The shooting re-solves inside the compiled loop (issue 17 item 2).

The compiled loop (:func:`cwrend_cli.physics._loop_kernels.resolve_loop`)
makes each re-solve's warm attempt and, when it succeeds, the plan; a
re-solve whose warm attempt does not succeed ends in Python
(:func:`cwrend_cli.physics.guidance.after_warm`, as ``solve_state`` ends
one). The reference for the compiled path is therefore the Python path
itself: with a re-solve observer (``simulate(observe=…)``) every re-solve
returns to Python and is ended there, which is the loop as it was before
issue 17. Both must give the same run,
bit for bit, on any platform: the same arithmetic runs in the same order
(``np.dot`` in compiled code calls the BLAS routine numpy's ``@`` calls).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from cwrend_cli import campaign
from cwrend_cli.config import ARCHITECTURES, CwrendConfig, config_from_dict
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.physics import _clock, guidance, simulation

SHOOTING = [s for s in ARCHITECTURES if not s.endswith("_socp")]
#: Settings whose re-solves take other branches of the loop: the authors' timing (guess not
#: propagated, the plan's costate propagated), the step-mean hold, and minimum-miss controls
#: held after an infeasible re-solve (Python-only, after a compiled warm attempt).
VARIANTS: dict[str, dict[str, Any]] = {
    "paper": {},
    "reference_timing": {"guidance": {"resolve_timing": "reference"}},
    "mean_hold": {"guidance": {"hold": "mean"}},
    "min_miss": {"solver": {"on_infeasible": "min_miss"}},
}


def _simulate(
    cfg: CwrendConfig, slug: str, seed: int, observe: simulation.ResolveObserver | None = None
) -> simulation.RunResult:
    problem = problem_of(cfg)
    refs = simulation.open_loop_references(problem)
    noise = campaign.standard_normal_for(cfg, seed)
    return simulation.simulate(
        problem, ARCHITECTURES[slug], noise, refs, seed=seed, observe=observe
    )


def _same_run(a: simulation.RunResult, b: simulation.RunResult) -> None:
    for f in dataclasses.fields(simulation.RunResult):
        if f.name == "solves":
            continue
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            np.testing.assert_array_equal(x, y, err_msg=f.name)
        else:
            assert x == y, f.name

    def untimed(run: simulation.RunResult) -> list[simulation.SolveRecord]:
        return [dataclasses.replace(s, wall_time_ms=0.0) for s in run.solves]

    assert untimed(a) == untimed(b)


@pytest.mark.parametrize("variant", list(VARIANTS))
@pytest.mark.parametrize("slug", SHOOTING)
def test_compiled_resolves_equal_the_python_path(
    slug: str, variant: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every history, Δv, miss and solve record (wall times aside) bit for bit."""
    cfg = config_from_dict(VARIANTS[variant])
    compiled = _simulate(cfg, slug, seed=1)
    calls = _count_calls(monkeypatch)
    seen: list[simulation.ResolveInput] = []
    python = _simulate(cfg, slug, seed=1, observe=seen.append)
    assert calls[0] == len(seen) == len(python.resolves)  # every re-solve ended in Python
    _same_run(compiled, python)


def _count_calls(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Count the re-solves that end in Python (calls of ``guidance.after_warm``)."""
    calls = [0]
    real: Callable[..., guidance.SolveResult] = guidance.after_warm

    def counted(*args: Any, **kwargs: Any) -> guidance.SolveResult:
        calls[0] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(guidance, "after_warm", counted)
    return calls


@pytest.mark.parametrize("slug", ["plain_adaptive", "mtf_adaptive"])
def test_a_run_whose_warm_attempts_succeed_stays_compiled(
    slug: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The common case: no re-solve of an adaptive paper run returns to Python."""
    calls = _count_calls(monkeypatch)
    run = _simulate(CwrendConfig(), slug, seed=0)
    assert all(s.success for s in run.resolves)
    assert calls[0] == 0


@pytest.mark.parametrize("slug", ["plain_fixed", "mtf_fixed"])
def test_only_unsuccessful_warm_attempts_return_to_python(
    slug: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A fixed-ε run's infeasible re-solves (the final braking burn) end in Python; no other."""
    calls = _count_calls(monkeypatch)
    run = _simulate(CwrendConfig(), slug, seed=0)
    unsuccessful = [s for s in run.resolves if not s.success]
    assert unsuccessful, "the paper's fixed-ε runs have infeasible late re-solves"
    assert calls[0] == len(unsuccessful)
    assert {s.status for s in unsuccessful} == {"infeasible"}


def test_compiled_resolves_record_their_wall_time() -> None:
    """Each compiled re-solve's wall time is positive and together they fit inside the run."""
    start = time.perf_counter()
    run = _simulate(CwrendConfig(), "mtf_adaptive", seed=0)
    elapsed_ms = (time.perf_counter() - start) * 1e3
    times = np.array([s.wall_time_ms for s in run.resolves])
    assert np.all(times > 0.0) and np.all(np.isfinite(times))
    assert times.sum() < elapsed_ms


@pytest.mark.parametrize("clock", [_clock.monotonic_s, _clock._perf_counter_objmode])
def test_the_compiled_clock_measures_seconds(clock: Callable[[], float]) -> None:
    """Both clocks advance with Python's: a 20 ms sleep reads as 20 ms (± scheduling: +50 ms)."""
    python_clock = time.monotonic if clock is _clock.monotonic_s else time.perf_counter
    a, pa = clock(), python_clock()
    time.sleep(0.02)
    b, pb = clock(), python_clock()
    assert 0.02 <= b - a < 0.07
    assert abs((b - a) - (pb - pa)) < 1e-3  # the same clock, read microseconds apart


@pytest.mark.skipif(_clock.CLOCK_ID is None, reason="no clock_gettime on this platform")
def test_posix_platforms_use_the_direct_clock() -> None:
    """Where ``clock_gettime`` exists the compiled code calls it (no object-mode round trip)."""
    assert _clock.HAVE_CLOCK_GETTIME
    assert _clock.monotonic_s is _clock._clock_gettime_s
