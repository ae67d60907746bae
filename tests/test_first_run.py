"""The first run after an install (issue 37, item 12).

A command whose kernels are not in numba's cache says so before it compiles
(``compiling kernels (first run only, about N s)…``), with the same check for
``cwrend run`` and the campaigns; with the cache warm it says nothing. The
kernels are compiled once per signature: no literal-argument specialisation,
and the closed loop of the CW truth with the ideal actuator does not compile
the nonlinear truth's or the actuator's kernels.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numba.core import compiler
from numba.core.compiler import CompilerBase, DefaultPassBuilder, _EarlyPipelineCompletion
from numba.core.compiler_machinery import FunctionPass, register_pass
from numba.core.typed_passes import NopythonTypeInference
from rich.console import Console
from typer.testing import CliRunner

from cwrend_cli import campaign
from cwrend_cli.cli import app
from cwrend_cli.config import ALL_ARCHITECTURES, ARCHITECTURES, config_from_dict
from cwrend_cli.console import RichProgress
from cwrend_cli.physics import compiled

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "campaigns" / "paper.toml"
NOTICE = "compiling kernels (first run only, about"

runner = CliRunner()


def _in_empty_cache(code: str, cache: Path) -> list[str]:
    """The lines ``python -c code`` prints with numba's cache in ``cache`` (empty: a first run)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    return subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    ).stdout.splitlines()


def test_cwrend_processes_collect_less_often_and_build_plain_numba_messages() -> None:
    # numba's compiler allocates millions of objects: at Python's default thresholds the
    # collector took 1.7 of the references' 21 CPU s; and each message numba builds for an
    # overload it rejects re-initialised colorama with highlighting on
    code = (
        "from cwrend_cli.physics.compiled import tune_for_compiling; tune_for_compiling(); "
        "import gc; from numba.core import errors; "
        "print(gc.get_threshold(), type(errors.termcolor()).__name__)"
    )
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING"}
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    ).stdout.split()
    assert out == ["(50000,", "20,", "20)", "NOPColorScheme"]


def test_an_empty_cache_announces_the_first_compile(tmp_path: Path) -> None:
    code = (
        "from cwrend_cli.physics import compiled; "
        "print(compiled.compiling_notice({'shooting'})); "
        "print(compiled.compiling_notice({'shooting', 'socp'}))"
    )
    out = _in_empty_cache(code, tmp_path)  # nothing compiled there yet
    assert all(line.startswith(NOTICE) and line.endswith(" s)…") for line in out)
    assert not [f for f in tmp_path.rglob("*") if f.is_file()]  # asking compiles nothing


def test_a_campaign_on_two_workers_announces_the_step_loop_compiled_meanwhile(
    tmp_path: Path,
) -> None:
    code = (
        "from cwrend_cli.physics import compiled; "
        "print(compiled.compile_seconds({'shooting'}), "
        "compiled.compile_seconds({'shooting'}, fan_out=True))"
    )
    alone, fanned_out = (float(s) for s in _in_empty_cache(code, tmp_path)[0].split())
    assert 0.0 < fanned_out < alone  # a worker compiles the step loop while the solver compiles


def test_compiled_kernels_announce_nothing() -> None:
    # one closed loop compiles (or loads) what the shooting architectures need
    campaign.run_case(config_from_dict({}), (ARCHITECTURES["mtf_adaptive"],), 0)
    assert compiled.compiling_notice({"shooting"}) is None


def _j2(guidance: str) -> dict[str, Any]:
    """campaigns/paper_j2.toml's J2 truth, with the re-solves' design model ``guidance``."""
    truth = {"model": "j2", "inclination_deg": 51.6}
    return {"truth": truth, "model": {"guidance": guidance}}


@pytest.mark.parametrize("guidance", ["cw", "ss"])
@pytest.mark.parametrize("arch", ["mtf_adaptive", "mtf_adaptive_socp"])
def test_a_campaign_whose_step_loop_is_not_cached_announces_the_compile(
    arch: str, guidance: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The first ablate of a J2 (or ``ss``) config compiled its own step loop for two minutes
    without a word: the entry points held the paper's compile, and any compile counted."""
    from cwrend_cli.campaign.plan import plan
    from cwrend_cli.cli import _first_run_notice

    # the cache holds a compile of every entry point, none of this configuration's loop
    monkeypatch.setattr(compiled, "_cached", lambda dispatcher, signature=None: signature is None)
    campaign_plan = plan(config_from_dict(_j2(guidance)), [arch], [0])
    notice = _first_run_notice(campaign_plan, fan_out=False)
    assert notice is not None and notice.startswith(NOTICE)


@pytest.mark.parametrize("arch", ["mtf_adaptive", "mtf_adaptive_socp"])
def test_a_step_loop_once_run_is_cached_for_its_configuration(arch: str) -> None:
    """The types asked about are those a run compiles: after a run, its loop is not cold."""
    from cwrend_cli.campaign.worker import cold_loops_of_case

    cfg = config_from_dict(_j2("ss"))
    campaign.run_case(cfg, (ALL_ARCHITECTURES[arch],), 0)
    assert cold_loops_of_case(cfg, (ALL_ARCHITECTURES[arch],), 0) == set()


@pytest.mark.parametrize("arch", ["mtf_adaptive", "mtf_adaptive_socp"])
def test_a_campaign_prints_the_notice_before_its_runs(
    arch: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # every architecture, the cone-program ones too (a lookup among the paper's four alone
    # ended `ablate --arch all_socp` with a KeyError)
    monkeypatch.setattr(compiled, "compile_seconds", lambda methods, *_, **__: 24.0)
    out = f"output.dir={json.dumps(str(tmp_path))}"
    args = ["ablate", str(PAPER), "--arch", arch, "-w", "1", "--no-rrd", "--set", out]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    # once: the references' check printed it, the runs' bar does not print it again
    assert result.output.count("compiling kernels (first run only, about 25 s)…") == 1


def test_the_notice_is_not_printed_when_nothing_is_left_to_compute() -> None:
    buf = io.StringIO()
    progress = RichProgress(Console(file=buf, width=80), "ablate p", notice="compiling…")
    progress.start(total=0, skipped=4)
    assert "compiling" not in buf.getvalue()
    progress.start(total=4, skipped=0)
    assert "compiling…" in buf.getvalue()


#: Compiles, in an empty cache, the kernels that called others with literal arguments
#: (the derivative orders of find_switches, want_hess of burn_integral), then prints
#: every signature their callees were compiled for.
_LITERALS = """
import numpy as np
from cwrend_cli.physics.guidance import _kernels as k, _switching_kernels as s
lam = np.array([1e-3, 2e-4, 0.0, 0.9, 0.4, 0.1])
ws = k.workspace()
k.find_switches(1e-3, lam, 0.0, 800.0, 0.0, 20, np.empty(64), np.empty(64), ws)
x, w = np.polynomial.legendre.leggauss(12)
s.burn_integral(1e-3, lam, 0.0, 30.0, 8e-4, x, w, np.zeros(6), np.zeros((6, 6)),
                np.empty((6, 3)), np.empty(6))
for f in (k._bracketed_root, k._g, k._primer, k.add_control_node):
    print(f.py_func.__name__, len(f.signatures), any("Literal" in str(t) for t in f.signatures))
"""


def test_no_kernel_is_compiled_once_per_literal_argument(
    compiled_in_empty_cache: dict[str, list[str]],
) -> None:
    out = " ".join(compiled_in_empty_cache["literals"]).split()
    assert out == [
        "_bracketed_root", "1", "False", "_g", "1", "False",
        "_primer", "1", "False", "add_control_node", "1", "False",
    ]  # fmt: skip


def test_the_paper_loop_passes_no_truth_or_actuator_model_to_compile() -> None:
    from cwrend_cli.physics import _loop_kernels

    campaign.run_case(config_from_dict({}), (ARCHITECTURES["plain_adaptive"],), 0)
    # arguments 6 and 7 (after the step loop and the solver): the CW truth and the ideal
    # actuator cross as None (pruned)
    paper = [(str(sig[6]), str(sig[7])) for sig in _loop_kernels._resolve_loop.signatures]
    assert ("none", "none") in paper


# ---------------------------------------------------------------------------
# The first run's compile fanned out over the campaign process and two workers
# ---------------------------------------------------------------------------


@register_pass(mutates_CFG=False, analysis_only=True)
class _StopAfterTyping(FunctionPass):  # type: ignore[misc]
    """The last pass of :class:`_TypeOnly`: the pipeline ends with the types, no code."""

    _name = "cwrend_tests_stop_after_typing"

    def __init__(self) -> None:
        FunctionPass.__init__(self)

    def run_pass(self, state: Any) -> bool:
        raise _EarlyPipelineCompletion(state.typemap)


class _TypeOnly(CompilerBase):  # type: ignore[misc]
    """numba's nopython pipeline up to type inference (its untyped passes, the dead-branch
    pruning of ``None`` arguments included), then :class:`_StopAfterTyping`."""

    def define_pipelines(self) -> list[Any]:
        pm = DefaultPassBuilder.define_nopython_pipeline(self.state)
        pm.passes = pm.passes[: [p for p, _ in pm.passes].index(NopythonTypeInference) + 1]
        pm.add_pass(_StopAfterTyping, "end after type inference")
        pm.finalize()
        return [pm]


def _type_calls(kernel: Any, sig: tuple[Any, ...]) -> None:
    """Types ``kernel``'s Python function for ``sig`` with the kernel's own flags, generating
    no code: typing a call of another kernel compiles that kernel (or loads it from numba's
    cache) for the call's argument types, as compiling the caller would (an uncached copy of
    the step loop's caller compiled in 11-45 s, this types it in about 1 s)."""
    flags = compiler.Flags()
    kernel.targetdescr.options.parse_as_flags(flags, kernel.targetoptions)
    target = kernel.targetdescr
    contexts = (target.typing_context, target.target_context)
    args = (kernel.py_func, tuple(sig), None, flags, kernel.locals)
    compiler.compile_extra(*contexts, *args, pipeline_class=_TypeOnly)


@pytest.mark.parametrize(
    "tree",
    [{}, {"sensor": {"model": "range_bearing"}}, {"truth": {"model": "two_body"}}],
    ids=["paper", "range_bearing", "two_body"],
)
def test_compile_loop_ahead_gives_the_step_loop_the_signature_the_runs_use(
    tree: dict[str, Any],
) -> None:
    from cwrend_cli.campaign import worker
    from cwrend_cli.config.adapt import problem_of
    from cwrend_cli.physics import _loop_kernels, simulation

    # the paper's loop; a nonlinear sensor (its EKF update); a nonlinear truth
    cfg = config_from_dict(tree)
    campaign.run_case(cfg, (ARCHITECTURES["mtf_adaptive"],), 0)
    # the compiled loop types its call of the step loop here, whatever numba's cache holds:
    # typed again for each signature the runs gave it
    for sig in _loop_kernels._resolve_loop.signatures:
        _type_calls(_loop_kernels._resolve_loop, sig)
    before = _loop_kernels._steps.signatures
    simulation.compile_loop(
        problem_of(cfg), ARCHITECTURES["mtf_adaptive"], worker.standard_normal_for(cfg, 0)
    )
    assert _loop_kernels._steps.signatures == before  # compiled ahead: no signature of its own


@pytest.mark.parametrize(
    "tree",
    [{}, {"sensor": {"model": "range_bearing"}}, {"truth": {"model": "two_body"}}],
    ids=["paper", "range_bearing", "two_body"],
)
def test_the_loop_top_compiled_ahead_is_the_one_the_runs_call(tree: dict[str, Any]) -> None:
    from cwrend_cli.campaign import worker
    from cwrend_cli.config.adapt import problem_of
    from cwrend_cli.physics import _loop_kernels, simulation

    cfg = config_from_dict(tree)
    campaign.run_case(cfg, (ARCHITECTURES["mtf_adaptive"],), 0)
    before = _loop_kernels._resolve_loop.signatures
    simulation.compile_loop(
        problem_of(cfg), ARCHITECTURES["mtf_adaptive"], worker.standard_normal_for(cfg, 0), top=True
    )
    assert _loop_kernels._resolve_loop.signatures == before  # no signature of its own


#: Compiles (or loads) the paper loop's top as a second process does on a first run, then
#: prints how many signatures of the step loop and of the solver's kernels this process
#: compiled or loaded on the way, and of the loop's top.
_TOP_ALONE = """
from cwrend_cli.campaign import worker
from cwrend_cli.config import ARCHITECTURES, config_from_dict
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.physics import _loop_kernels as lk, simulation
from cwrend_cli.physics.guidance import _kernels as k, _switching_kernels as s
cfg = config_from_dict({})
simulation.compile_loop(
    problem_of(cfg), ARCHITECTURES["mtf_fixed"], worker.standard_normal_for(cfg, 0), top=True
)
print(len(lk._steps.signatures), len(s.bang_bang_ascent.signatures),
      len(s.switching_newton.signatures), len(k.newton_ascent.signatures),
      len(lk._resolve_loop.signatures))
"""


def test_the_loop_top_compiles_without_the_step_loop_or_the_solver(tmp_path: Path) -> None:
    # the top calls them by their addresses: a second process compiles it while the
    # campaign process compiles the solver, and the top's code does not carry theirs
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    out = subprocess.run(
        [sys.executable, "-c", _TOP_ALONE], env=env, capture_output=True, text=True, check=True
    ).stdout.split()
    assert out == ["0", "0", "0", "0", "1"]


def test_a_second_call_of_the_compiled_loop_does_not_type_its_arguments_again(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from cwrend_cli.physics import _loop_kernels

    cfg = config_from_dict({})
    campaign.run_case(cfg, (ARCHITECTURES["mtf_fixed"],), 0)

    def typed(*args: object) -> None:
        raise AssertionError("typed again")  # milliseconds in Python, at every re-solve's return

    monkeypatch.setattr(_loop_kernels, "_steps_types", typed)
    campaign.run_case(cfg, (ARCHITECTURES["mtf_fixed"],), 1)  # the same types: looked up


class _Submitted:
    """An executor that records what is submitted and runs nothing."""

    def __init__(self) -> None:
        self.calls: list[tuple[object, ...]] = []

    def submit(self, fn: object, *args: object) -> object:
        from concurrent.futures import Future

        self.calls.append((fn, *args))
        future: Future[None] = Future()
        future.set_result(None)
        return future


class _References:
    def __init__(self, calls: list[tuple[object, ...]]) -> None:
        self.calls = calls

    def of(self, task: object) -> None:
        self.calls.append(("references", task))


def _solver_copy_typed() -> Any:
    """The switching kernels' module, after an uncached copy of the solver typed its calls."""
    from numba import njit

    from cwrend_cli.physics.guidance import _switching_kernels

    # an uncached copy of the solver types its calls of its two halves here
    copy = njit(_switching_kernels.bang_bang_ascent.py_func)
    campaign.run_case(config_from_dict({}), (ARCHITECTURES["mtf_fixed"],), 0)
    for sig in _switching_kernels.bang_bang_ascent.signatures:
        copy.compile(sig)
    return _switching_kernels


def test_the_switching_newton_compiled_ahead_is_the_one_the_solver_calls() -> None:
    switching = _solver_copy_typed()
    before = switching.switching_newton.signatures
    switching.compile_switching_newton()
    assert switching.switching_newton.signatures == before  # no signature of its own


def test_the_burn_prediction_compiled_first_is_the_one_the_newton_calls() -> None:
    from numba import njit

    switching = _solver_copy_typed()
    # an uncached copy of the Newton types its call of the burn prediction here
    copy = njit(switching.switching_newton.py_func)
    for sig in switching.switching_newton.signatures:
        copy.compile(sig)
    before = switching.predicted_length.signatures
    switching.compile_predicted_length()
    assert switching.predicted_length.signatures == before  # no signature of its own


def test_the_dual_ascent_compiled_first_is_the_one_the_solver_calls() -> None:
    from cwrend_cli.config.adapt import problem_of
    from cwrend_cli.physics.guidance import _kernels

    _solver_copy_typed()
    before = _kernels.newton_ascent.signatures
    compiled.compile_ascent(problem_of(config_from_dict({})))
    assert _kernels.newton_ascent.signatures == before  # no signature of its own


class _Task:
    problem = object()


_TASK = _Task()


def _first_run_calls(
    executor: _Submitted | None, cold: bool, monkeypatch: pytest.MonkeyPatch
) -> list[tuple[object, ...]]:
    """What a first campaign asks of ``executor`` (None: a helper process) and does itself."""
    from contextlib import contextmanager

    from cwrend_cli.campaign import driver

    monkeypatch.setattr(compiled, "references_cold", lambda: cold)
    helper = executor or _Submitted()
    monkeypatch.setattr(driver, "helper_process", contextmanager(lambda: iter([helper])))
    monkeypatch.setattr(
        compiled, "compile_ascent", lambda problem: helper.calls.append(("ascent", problem))
    )
    driver._compile_first_run(executor, [_TASK], _References(helper.calls))  # type: ignore[arg-type, list-item]
    return helper.calls


def _expected(cold: bool) -> list[tuple[object, ...]]:
    """Cold: the step loop, the switching-time Newton and the loop's top ahead; the ascent and
    the references."""
    from cwrend_cli.campaign import worker

    if not cold:
        return []
    return [
        (worker.compile_ahead, _TASK),
        (worker.compile_newton,),
        (worker.compile_top, _TASK),
        ("ascent", _TASK.problem),
        ("references", _TASK),
    ]


@pytest.mark.parametrize("cold", [True, False])
def test_a_one_task_campaign_compiles_ahead_in_a_helper_process(
    cold: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    # no pool (the task runs in this process): a helper process compiles ahead meanwhile
    assert _first_run_calls(None, cold, monkeypatch) == _expected(cold)


@pytest.mark.parametrize("cold", [True, False])
def test_a_first_campaign_compiles_the_step_loop_in_a_worker_while_it_computes_the_references(
    cold: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    # cold: a worker compiles the step loop and the Newton while this process compiles the
    # ascent and computes the references
    assert _first_run_calls(_Submitted(), cold, monkeypatch) == _expected(cold)


def test_a_cone_program_campaign_compiles_no_shooting_loop_ahead(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from cwrend_cli.config.adapt import problem_of
    from cwrend_cli.physics import simulation

    made: list[str] = []
    monkeypatch.setattr(
        simulation, "compile_loop", lambda problem, arch, *draws: made.append(arch.slug)
    )
    problem = problem_of(config_from_dict({}))
    archs = [ALL_ARCHITECTURES[a] for a in ("mtf_adaptive_socp", "plain_fixed_socp")]
    compiled.compile_ahead(problem, archs, np.zeros((problem.scenario.n_steps, 3)))
    assert made == ["mtf_adaptive_socp"]  # one step loop per method: the cone program's


def test_sort_prefix_orders_as_numpy_sorts() -> None:
    from cwrend_cli.physics.guidance import _kernels

    rng = np.random.default_rng(7)
    for count in (0, 1, 2, 5, 17, 40):
        a = rng.uniform(0.0, 800.0, 48)
        a[3:6] = a[10]  # ties
        a[[1, 20]] = np.nan  # NaN last, as np.sort puts it
        want = np.concatenate((np.sort(a[:count]), a[count:]))
        _kernels.sort_prefix(a, count)
        assert np.array_equal(a, want, equal_nan=True)  # the prefix sorted, the rest untouched


#: Compiles the solver's start selection (and the dual evaluation and breakpoints below it)
#: in an empty cache and prints whether its code holds numba's quicksort or the
#: shape-mismatch message of an array-to-array slice assignment, and its code's size.
_SHRUNK = """
import numpy as np
from cwrend_cli.physics.guidance import _kernels as k
x, w = np.polynomial.legendre.leggauss(12)
starts = np.array([[1e-3, 2e-4, 0.0, 0.9, 0.4, 0.1]])
k.best_start(1e-3, starts, np.full(6, 1e-2), 800.0, 0.0, 8e-4, x, w, 20, True,
             np.empty(6), np.empty((6, 6)), k.workspace())
ir = "".join(k.best_start.inspect_llvm().values())
print("quicksort" in ir, "raise_with_shape_context" in ir, len(ir) > 10_000)
"""


def test_the_solver_compiles_no_sort_or_slice_error_message(
    compiled_in_empty_cache: dict[str, list[str]],
) -> None:
    assert compiled_in_empty_cache["shrunk"] == ["False False True"]


@pytest.fixture(scope="module")
def compiled_in_empty_cache(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[str]]:
    """What :data:`_LITERALS`, then :data:`_SHRUNK`, print in one fresh interpreter with an
    empty numba cache (one compile of the kernels both reach; each was a process of its own).

    Order-proof for both: the literal check types the callees before anything else
    compiles them, and :data:`_SHRUNK` reads the code of the start selection with every
    callee linked in, whichever compile met the callee first."""
    marker = "--- shrunk ---"
    code = f"{_LITERALS}\nprint({marker!r})\n{_SHRUNK}"
    out = _in_empty_cache(code, tmp_path_factory.mktemp("numba-cache"))
    cut = out.index(marker)
    return {"literals": out[:cut], "shrunk": out[cut + 1 :]}
