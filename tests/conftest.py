"""Shared fixtures of the numerics tests: the paper scenario and its references.

The session-scoped fixtures are computed once per test process: the paper
configuration (paper Table 1 plus the settings of the authors' code:
docs/method.md), its open-loop references (paper Sec. "Numerical Results and Discussion",
~0.5 s once the kernels are compiled) and the shooting costates of the paper
problem at the homotopy parameters the guidance tests use, obtained by
ε-continuation from the energy-optimal costate (docs/method.md).
"""

from __future__ import annotations

import concurrent.futures
import fcntl
import os
import signal
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from cwrend_cli.config import CwrendConfig
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.physics import guidance, simulation


@pytest.fixture(scope="session", autouse=True)
def stop_signals_delivered() -> Iterator[None]:
    """Ctrl-C (SIGINT) and a hang-up (SIGHUP) reach the tests' campaigns, however the suite
    was started.

    A shell without job control starts a background job (``pytest … &``, a
    script's ``cmd &``) with SIGINT ignored, ``nohup`` with SIGHUP ignored,
    and cwrend keeps a signal ignored at its start ignored
    (:func:`cwrend_cli.teardown.stop_on_signals`), so the interruption tests
    failed there (seen: every run of
    ``test_a_ctrl_c_a_library_turns_into_an_error_drops_the_run`` started with
    ``&``, of ``test_sigterm_and_sighup_stop_a_campaign_as_ctrl_c_does[SIGHUP-129]``
    with ``nohup``). Python's own handling here; the campaigns the tests start
    inherit the default actions (a handler is reset on ``exec``, an ignored
    signal is not).
    """
    before = {
        signal.SIGINT: signal.signal(signal.SIGINT, signal.default_int_handler),
        signal.SIGHUP: signal.signal(signal.SIGHUP, signal.SIG_DFL),
    }
    yield
    for signum, handler in before.items():
        signal.signal(signum, handler)


#: Set on the controller of a whole-suite run on xdist workers (:func:`pytest_cmdline_main`).
_DISTRIBUTED = pytest.StashKey[bool]()

#: The groups of a whole-suite run on xdist workers, in the order they start: the test
#: modules whose tests take longest first (so that no long one is left for the end of the
#: run; their cold-cache times: docs/development.md), and modules that compile the same
#: step-loop specialisations together, one after the other on one worker, so that the
#: second loads from numba's cache what the first compiled instead of compiling it at the
#: same time on the other worker. Every other module is a group of its own, after these,
#: in file order. A group's tests run on one worker in file order, as in one process.
GROUPS: dict[str, tuple[str, ...]] = {
    name: (name,)
    for name in (
        # the second compiles no step loop for its first ~25 CPU s, while the first compiles
        # the paper's (both workers compiled it at once when both began with a campaign)
        "test_report", "test_tumbling_guidance", "test_first_run", "test_interrupt",
        "test_distributed", "test_ekf", "test_abort_safety", "test_campaign", "test_report_safety",
        "test_ss_shooting", "test_startup", "test_report_tumbling", "test_table",
        "test_process_noise", "test_constrained_guidance", "test_compare", "test_progress",
    )
}  # fmt: skip
_GROUP_OF = {module: group for group, modules in GROUPS.items() for module in modules}
_ORDER = {group: i for i, group in enumerate(GROUPS)}


def _group(path: str) -> str:
    """The group of a test module (its path or node id, ``tests/test_x.py::…``)."""
    module = Path(path.split("::", 1)[0]).stem
    return _GROUP_OF.get(module, module)


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config: pytest.Config) -> None:
    """The whole suite (``pytest`` with no paths: the ``testpaths``) runs on one pytest-xdist
    worker per usable CPU, each of :data:`GROUPS` on one worker; a run given paths
    (``pytest tests/test_x.py``) stays in one process, as does a run given ``-n`` (``-n 0``:
    in one process), ``--pdb`` or ``-p no:xdist``. Most of a cold run is numba compiling
    the step loop once per feature combination, on one core: two workers compile two at
    once (docs/development.md)."""
    opt = config.option
    if (
        hasattr(config, "workerinput")  # an xdist worker
        or getattr(opt, "numprocesses", 0) is not None  # no xdist, or -n given
        or config.args_source is not pytest.Config.ArgsSource.TESTPATHS
        or opt.usepdb
        or opt.collectonly
    ):
        return
    cpus = len(os.sched_getaffinity(0))
    if cpus > 1 and opt.dist == "no":
        opt.numprocesses = cpus
        opt.dist = "loadscope"  # scheduled by pytest_xdist_make_scheduler
        opt.loadscopereorder = False  # in the order of pytest_collection_modifyitems
        config.stash[_DISTRIBUTED] = True


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """xdist's scheduler of whole work units (``--dist loadscope``) with :data:`GROUPS` as
    the units: a unit starts on the first worker free, its tests in order."""
    if not config.stash.get(_DISTRIBUTED, False):
        return None
    from xdist.scheduler import LoadScopeScheduling

    class ModuleGroups(LoadScopeScheduling):  # type: ignore[misc]
        def _split_scope(self, nodeid: str) -> str:
            return _group(nodeid)

    return ModuleGroups(config, log)


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node: Any) -> None:
    """Tells each xdist worker of a whole-suite run to order its tests by :data:`GROUPS`."""
    if node.config.stash.get(_DISTRIBUTED, False):
        node.workerinput["cwrend_groups"] = True


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """On an xdist worker of a whole-suite run: the tests in the order of :data:`GROUPS`
    (each module's in file order), which the scheduler starts the groups in."""
    if getattr(config, "workerinput", {}).get("cwrend_groups"):
        items.sort(key=lambda item: _ORDER.get(_group(item.nodeid), len(_ORDER)))


def _lock_numba_cache_saves() -> None:
    """Serialise numba's cache writes across the test processes (xdist workers).

    Numba saves a specialisation by reading a function's cache index, adding the entry
    (with the first data-file number the index does not use) and writing index and data
    back, with no lock: two processes saving two specialisations of one function at once
    can pick the same data file, so one index entry may name the other's code. Each save
    here holds an exclusive ``flock`` on a file in that cache directory.
    """
    from numba.core import caching

    save = caching.IndexDataCacheFile.save

    def locked_save(self: Any, key: Any, data: Any) -> None:
        with open(os.path.join(self._cache_path, "cwrend-tests.lock"), "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            save(self, key, data)

    caching.IndexDataCacheFile.save = locked_save


if os.environ.get("PYTEST_XDIST_WORKER"):
    _lock_numba_cache_saves()

#: Homotopy parameters of the guidance tests, in continuation order (1 → 0).
EPS_CONTINUATION = (1.0, 0.3, 0.05, 0.0)


def spec_cw_matrices(n: float) -> tuple[np.ndarray, np.ndarray]:
    """``A`` (6×6) and ``B`` (6×3) written out from paper Eq. 4.

    Built here independently of :func:`cwrend_cli.dynamics.cw_system` so that
    reference computations (matrix exponentials, brute-force integration) do
    not share code with the package.
    """
    a = np.array(
        [
            [0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
            [3.0 * n * n, 0.0, 0.0, 0.0, 2.0 * n, 0.0],
            [0.0, 0.0, 0.0, -2.0 * n, 0.0, 0.0],
            [0.0, 0.0, -n * n, 0.0, 0.0, 0.0],
        ]
    )
    b = np.vstack([np.zeros((3, 3)), np.eye(3)])
    return a, b


@pytest.fixture(scope="session")
def cw_matrices() -> Callable[[float], tuple[np.ndarray, np.ndarray]]:
    """Factory ``n ↦ (A, B)`` of paper Eq. 4, independent of the package."""
    return spec_cw_matrices


@pytest.fixture(scope="session")
def paper_cfg() -> CwrendConfig:
    """The paper scenario: every default of the config (paper Table 1; docs/method.md)."""
    return CwrendConfig()


@pytest.fixture(scope="session")
def paper_refs(paper_cfg: CwrendConfig) -> simulation.References:
    """Open-loop energy- and fuel-optimal references of the paper scenario.

    The references of paper Sec. "Numerical Results and Discussion".
    """
    return simulation.open_loop_references(problem_of(paper_cfg))


@pytest.fixture(scope="session")
def paper_problem(
    paper_cfg: CwrendConfig,
) -> Callable[..., guidance.ShootingProblem]:
    """Factory of shooting problems of the paper scenario (x0, T = 800 s, x_f = 0 by default)."""
    sc = paper_cfg.scenario

    def make(
        eps: float, x0: np.ndarray | None = None, horizon_s: float | None = None
    ) -> guidance.ShootingProblem:
        return guidance.ShootingProblem(
            np.array(sc.x0 if x0 is None else x0, dtype=float),
            float(sc.horizon_s if horizon_s is None else horizon_s),
            float(eps),
            sc.mean_motion_rad_s,
            sc.u_max_km_s2,
            np.array(sc.xf, dtype=float),
        )

    return make


@pytest.fixture(scope="session")
def paper_costates(
    paper_problem: Callable[..., guidance.ShootingProblem],
) -> dict[float, np.ndarray]:
    """``λ(0)`` solving the paper problem at each ε of :data:`EPS_CONTINUATION`.

    ε-continuation 1 → 0.3 → 0.05 → 0 with :func:`guidance.solve`, the first
    solve warm-started from the closed-form energy-optimal costate (docs/method.md).
    """
    lam = guidance.energy_optimal_costate(paper_problem(EPS_CONTINUATION[0]))
    out: dict[float, np.ndarray] = {}
    for eps in EPS_CONTINUATION:
        result = guidance.solve(paper_problem(eps), lam)
        assert result.converged, f"continuation failed at eps = {eps}: {result.status}"
        lam = result.costate
        out[eps] = lam.copy()
    return out


@pytest.fixture(scope="session")
def refused_override() -> Callable[..., str]:
    """``cwrend config validate`` of the paper scenario with ``--set`` overrides (one or
    more) that must be refused.

    Checks what every refusal must do (exit code 2, no traceback) and returns
    stderr, for the test to check the message names the field.
    """
    from typer.testing import CliRunner

    from cwrend_cli.cli import app

    paper = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"

    def validate(*overrides: str) -> str:
        sets = [arg for override in overrides for arg in ("--set", override)]
        result = CliRunner().invoke(app, ["config", "validate", str(paper), *sets])
        assert result.exit_code == 2, result.output
        assert "Traceback" not in result.output
        return result.stderr

    return validate


@pytest.fixture(scope="session")
def mtf_sweep() -> Callable[..., pd.DataFrame]:
    """``cwrend sweep`` of a campaign file, ``mtf_adaptive`` only: its ``runs.parquet``.

    ``run(tmp_path, name, body, seeds=2)`` writes ``body`` (TOML after an
    ``[output]`` table without recordings) to ``tmp_path/<name>.toml``, sweeps
    it with one worker into ``tmp_path/<name>/`` (exit code 0 checked) and
    returns the runs sorted by point and seed. The dispersion and sweep tests
    of the actuator, the sensor faults and the truth model check each run
    against a single run of its own configuration
    (:func:`cwrend_cli.campaign.run_case`).
    """
    from typer.testing import CliRunner

    from cwrend_cli.cli import app

    def run(tmp_path: Path, name: str, body: str, seeds: int = 2) -> pd.DataFrame:
        path = tmp_path / f"{name}.toml"
        path.write_text("[output]\nrrd_seeds = 0\n" + body)
        args = ["sweep", str(path), "--seeds", str(seeds), "--workers", "1", "--no-rrd", "-q",
                "--arch", "mtf_adaptive", "--set", f"output.dir={str(tmp_path)!r}"]  # fmt: skip
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 0, result.output
        runs = pd.read_parquet(tmp_path / name / "runs.parquet")
        return runs.sort_values(["point", "seed"]).reset_index(drop=True)

    return run


class RecordingProgress:
    """A :class:`~cwrend_cli.campaign.Progress` that keeps every advance (runs, signed)."""

    def __init__(self) -> None:
        self.advances: list[int] = []
        self.total = 0

    def start(self, total: int, skipped: int) -> None:
        self.total = total

    def advance(self, ok: int, failed: int) -> None:
        self.advances.append(ok + failed)

    def close(self) -> None:
        pass


@pytest.fixture
def recording_progress() -> type[RecordingProgress]:
    """The class of a progress object that records each advance (one per campaign run)."""
    return RecordingProgress


def two_architecture_runs(n: int, points: int = 1) -> pd.DataFrame:
    """Hand-made ``runs.parquet`` rows: ``n`` ok seeds of mtf_adaptive and plain_adaptive
    at each of ``points`` grid points (``schedule.beta`` 0.25, 0.5, …).

    Misses about 1 and 2 m with 30 % noise, Δv 0.14 km/s ± 1e-4, drawn from
    ``default_rng(1)`` in row order (point, seed, architecture).
    """
    rng = np.random.default_rng(1)
    rows = []
    for point in range(points):
        for seed in range(n):
            for arch, scale in (("mtf_adaptive", 1.0), ("plain_adaptive", 2.0)):
                rows.append(
                    {"point": f"p{point}", "param.schedule.beta": 0.25 * (point + 1),
                     "seed": seed, "arch": arch, "status": "ok",
                     "miss_km": scale * 1e-3 * (1 + 0.3 * rng.standard_normal()),
                     "delta_v_km_s": 0.14 + 1e-4 * rng.standard_normal(),
                     "fuel_penalty_pct": 25.0, "solve_success_pct": 100.0,
                     "solve_mean_ms": 1.0, "solve_max_ms": 2.0, "n_infeasible": 0}
                )  # fmt: skip
    return pd.DataFrame(rows)


@pytest.fixture(scope="session")
def synthetic_runs() -> Callable[..., pd.DataFrame]:
    """Factory ``(n, points=1) ↦ runs`` of :func:`two_architecture_runs` (no campaign run)."""
    return two_architecture_runs


class _NeverRuns(concurrent.futures.Executor):
    """An executor whose futures never complete; ``_client`` as a Dask ClientExecutor's."""

    def __init__(self, client: object) -> None:
        self._client = client

    def submit(self, fn: Any, /, *args: Any, **kwargs: Any) -> concurrent.futures.Future[Any]:
        return concurrent.futures.Future()  # never runs


@pytest.fixture(scope="session")
def bounded_wait() -> Callable[[int, str], Callable[..., Any]]:
    """Factory ``(polls, what) ↦ wait``: ``concurrent.futures.wait`` that fails the test with
    ``what`` after ``polls`` calls. A guard against a hang only, for a driver whose wait is
    patched (``driver.wait``): it counts the driver's polls, not the time they take."""

    def factory(polls: int, what: str) -> Callable[..., Any]:
        seen = {"n": 0}

        def wait(*args: Any, **kwargs: Any) -> Any:
            seen["n"] += 1
            assert seen["n"] < polls, what
            return concurrent.futures.wait(*args, **kwargs)

        return wait

    return factory


@pytest.fixture(scope="session")
def stalled_executor() -> Callable[[object], Callable[..., Any]]:
    """Factory ``client ↦ open_executor``: a stand-in for the driver's ``open_executor``
    that opens one worker whose tasks never run, on a Dask ``client`` stand-in (its
    ``status`` and ``_scheduler_identity`` are what the driver asks of a cluster)."""

    def opener(client: object) -> Callable[..., Any]:
        @contextmanager
        def open_executor(*args: Any, **kwargs: Any) -> Iterator[tuple[_NeverRuns, int]]:
            yield _NeverRuns(client), 1

        return open_executor

    return opener
