"""The ``cwrend`` command line (Typer). Thin: the logic lives in the modules.

Every command wraps its body in :func:`user_errors`, so a user mistake (bad
config, bad override, bad data file) prints ``error: ...`` on stderr and exits
with code 2, without a traceback. Typer's own usage errors also exit with 2.

Start-up (issue 17): this module imports only what every command needs —
Typer — so that ``cwrend --help``, ``cwrend <command> --help`` and ``cwrend
config validate`` answer at once; Rich's console is imported when a command
prints through it (:func:`_console`). Each command imports what it computes
with (configuration, campaign, tables, recordings: numba, scipy, pandas,
pyarrow, rerun, matplotlib) at the top of its own body; names needed only in
annotations are imported under ``TYPE_CHECKING`` below. The architecture
names of the help text are written out here (:data:`ARCH_SLUGS`), so that
the help imports no physics; ``tests/test_startup.py`` checks they are the
physics' names and that ``--help`` loads none of the heavy libraries, nor
pydantic (see :class:`_Group`), and ``config validate`` no numpy nor Rich.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, replace
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

import typer
from typer.core import TyperCommand, TyperGroup

from cwrend_cli import __version__, limits
from cwrend_cli.errors import ConfigError, CwrendError
from cwrend_cli.output.layout import (
    ABLATION_STATS,
    COMPARE_FIGURE,
    COMPARE_STATS,
    MANIFEST,
    RUN_RECORDING,
    RUNS_DIR,
    SWEEP_STATS,
    compare_dir,
    run_dir,
)
from cwrend_cli.output.manifest import pairs_recorded_at

if TYPE_CHECKING:  # annotations only; the commands import these when they run
    import pandas as pd
    from rich.console import Console

    from cwrend_cli import campaign
    from cwrend_cli.campaign import ExecutorKind, sequential
    from cwrend_cli.config import Architecture, CwrendConfig
    from cwrend_cli.report.table import Source

#: The architectures of ``--arch all`` and ``all_socp`` and the single-factor ones
#: (the keys of ``physics.params.ARCHITECTURES``, ``SOCP_ARCHITECTURES`` and
#: ``STF_ARCHITECTURES``, checked by a test).
ARCH_SLUGS = ("plain_fixed", "mtf_fixed", "plain_adaptive", "mtf_adaptive")
SOCP_ARCH_SLUGS = tuple(f"{a}_socp" for a in ARCH_SLUGS)
STF_ARCH_SLUGS = ("stf_fixed", "stf_adaptive", "stf_fixed_socp", "stf_adaptive_socp")


def _help_flag_off(option: typer.core.TyperOption | None) -> typer.core.TyperOption | None:
    """``--help`` unset is ``False``, not ``None``.

    Typer 0.29 coerces a flag's ``None`` through a pydantic ``TypeAdapter``,
    so every ``cwrend <command>`` imported pydantic (about 80 ms) just to find
    that the group's ``--help`` was not given; a ``bool`` is left as it is.
    Older Typer versions have ``False`` already.
    """
    if option is not None and option.default is None:
        option.default = False
    return option


class _Group(TyperGroup):
    """A command group whose unset ``--help`` costs no import (:func:`_help_flag_off`)."""

    def get_help_option(self, ctx: typer.Context) -> typer.core.TyperOption | None:  # type: ignore[override]
        return _help_flag_off(super().get_help_option(ctx))


class _Command(TyperCommand):
    """A command whose unset ``--help`` costs no import (:func:`_help_flag_off`)."""

    def get_help_option(self, ctx: typer.Context) -> typer.core.TyperOption | None:  # type: ignore[override]
        return _help_flag_off(super().get_help_option(ctx))


app = typer.Typer(
    cls=_Group,
    name="cwrend",
    help="Robust low-thrust rendezvous campaigns: CW dynamics, MTF Kalman filter, "
    "innovation-adaptive homotopy guidance (Candan & Servadio, AAS 26-893).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
    # plain help: Rich's help panels took "[sweep]" for markup and cut option help with "…"
    rich_markup_mode=None,
)
config_app = typer.Typer(
    cls=_Group,
    help="Inspect and check configuration files.",
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode=None,
)
app.add_typer(config_app, name="config")

USER_ERROR_EXIT = 2


def _console(*, stderr: bool = False, soft_wrap: bool = False) -> Console:
    """A Rich console without highlighting or emoji codes, on stdout or the current stderr.

    Rich is imported here, when a command prints through it, not with this
    module: ``cwrend --help`` and ``cwrend config validate`` print plain text
    and load no Rich (about 20 ms).
    """
    from rich.console import Console

    # emoji=False: text the user wrote (--range schedule.beta=1:-1:) is never an emoji code
    return Console(stderr=stderr, highlight=False, soft_wrap=soft_wrap, emoji=False)


def _stderr() -> Console:
    """A console on the current stderr (looked up at call time, so tests can capture it)."""
    return _console(stderr=True, soft_wrap=True)


@contextmanager
def user_errors() -> Iterator[None]:
    """Turn user-facing errors into ``error: <message>`` on stderr and exit code 2.

    Use as ``with user_errors(): ...`` inside a command (or as a decorator).
    Catches :class:`~cwrend_cli.errors.CwrendError` and, as a safety net,
    :class:`pydantic.ValidationError`; anything else propagates (it is a bug).
    """
    try:
        yield
    except CwrendError as exc:
        _stderr().print("error:", str(exc), markup=False)
        raise typer.Exit(code=exc.exit_code) from None
    except Exception as exc:
        from pydantic import ValidationError  # loaded already if it was raised

        from cwrend_cli.config import format_validation_error

        if not isinstance(exc, ValidationError):
            raise
        lines = "\n".join(f"  {line}" for line in format_validation_error(exc))
        _stderr().print("error: invalid values\n" + lines, markup=False)
        raise typer.Exit(code=USER_ERROR_EXIT) from None


# Shared option/argument declarations for commands that take a config file.
ConfigFile = Annotated[
    Path,
    typer.Argument(
        help="TOML config file (an empty file is the paper scenario).", metavar="CONFIG"
    ),
]
SetOption = Annotated[
    list[str] | None,
    typer.Option(
        "--set",
        "-s",
        help="Override a value: dotted.key=value, the value read as TOML "
        "(e.g. --set schedule.beta=0.5, --set degradation.windows.1.bias_km=[0,0,0]). "
        "Repeatable.",
        metavar="KEY=VALUE",
    ),
]

RrdOption = Annotated[
    bool,
    typer.Option(
        "--rrd/--no-rrd",
        help="Write Rerun recordings (.rrd) of the trajectories; open with `rerun FILE`.",
    ),
]


class OutputFormat(StrEnum):
    """Formats for ``config show``."""

    toml = "toml"
    json = "json"


class TableFormat(StrEnum):
    """Formats of a command's table for scripts (``--format``)."""

    md = "md"
    csv = "csv"
    json = "json"


TableFormatOption = Annotated[
    TableFormat | None,
    typer.Option(
        "--format",
        help="Print the command's table for scripts on stdout instead of the console tables: "
        "md (GitHub markdown), csv or json (records), every value unrounded, no progress.",
        metavar="md|csv|json",
    ),
]


def _version_callback(value: bool) -> None:
    if value:
        typer.echo(f"cwrend {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_version_callback, is_eager=True, help="Show the version."
        ),
    ] = False,
) -> None:
    """cwrend: batch campaigns for robust low-thrust rendezvous."""


@config_app.command(
    "show", cls=_Command, short_help="Print the resolved configuration and its hash."
)
def config_show(
    file: ConfigFile,
    set_: SetOption = None,
    fmt: Annotated[
        OutputFormat,
        typer.Option(
            "--format",
            "-f",
            help="Output format. TOML lists unset optional fields as comments "
            "('# key = (unset)'); JSON as null.",
        ),
    ] = OutputFormat.toml,
) -> None:
    """Print the resolved configuration (defaults and overrides applied) and its hash.

    Every field is listed, unset optional ones too.
    """
    from cwrend_cli.config import config_hash, load_config, to_json, to_toml

    with user_errors():
        cfg = load_config(file, set_ or ())
        digest = config_hash(cfg)
        if fmt is OutputFormat.toml:
            typer.echo(f"# config_hash = {digest}\n")
            typer.echo(to_toml(cfg, show_unset=True), nl=False)
        else:
            typer.echo(to_json(cfg))
            typer.echo(f"config_hash: {digest}", err=True)


@config_app.command(
    "validate", cls=_Command, short_help="Check a configuration: 'OK <hash>' or the errors."
)
def config_validate(file: ConfigFile, set_: SetOption = None) -> None:
    """Check a configuration; print 'OK <hash>' or the problems (exit code 2).

    Checked: the values and the rules between them; the [dispersions] keys (each
    names a number) and their draws for seed 0 on the base configuration (the
    draws of a one-seed campaign); the noise file (its columns and rows); [sweep]
    as sweep checks it: its keys, and every grid point (or each range's ends).

    Not checked: the draws of other seeds (a normal draw is unbounded; a uniform one
    spans low to high) or on grid points, and what the command line adds (--param,
    --range, --arch, the size limits). ablate and sweep check every run's draws
    before anything runs: a value a key does not take exits 2 naming the seed or
    point ('dispersed run (seed 3) (schedule.beta = -0.13) is invalid'), nothing
    written.
    """
    from cwrend_cli.config import config_hash, load_config

    with user_errors():
        cfg = load_config(file, set_ or ())
        if cfg.dispersions or cfg.noise.file is not None or cfg.sweep:  # else no numpy
            from cwrend_cli.campaign.plan import check_inputs, check_sweep

            check_sweep(cfg)  # the grid's checks first, as a campaign's plan makes them
            check_inputs(cfg)
        typer.echo(f"OK {config_hash(cfg)}")


def _parse_archs(text: str) -> tuple[Architecture, ...]:
    """``all``, ``all_socp``, ``everything`` or a comma-separated list of architecture slugs."""
    from cwrend_cli.config import parse_archs

    return parse_archs(text)


ARCH_HELP = (
    "Architecture slug(s), comma-separated, or a group: 'all' (the paper's four, shooting: "
    + ", ".join(ARCH_SLUGS)
    + "), 'all_socp' (the same with the cone-program re-solve: "
    + ", ".join(SOCP_ARCH_SLUGS)
    + "), 'everything' (both); the single-factor baseline ("
    + ", ".join(STF_ARCH_SLUGS)
    + ") only by name or in 'with_stf', 'with_stf_socp', 'everything_with_stf' (each group "
    "with the single-factor ones appended)."
)


@app.command(
    "run", cls=_Command, short_help="One seed of the chosen architectures and the references."
)
def run(
    file: ConfigFile,
    arch: Annotated[
        str,
        typer.Option(
            "--arch",
            "-a",
            help=ARCH_HELP,
            metavar="ARCHS",
        ),
    ] = "mtf_adaptive",
    seed: Annotated[
        int | None,
        typer.Option(
            "--seed",
            min=0,
            max=limits.MAX_SEED,
            help="Noise realisation (default 0; root: noise.seed).",
            metavar="N",
        ),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="Output directory (default: <output.dir>/runs/<name>-<arch>-seed<N>, <name> "
            "being output.name, the config file's stem unless set, and <arch> 'multi' for "
            "several architectures; never inside a campaign's directory).",
            metavar="DIR",
        ),
    ] = None,
    set_: SetOption = None,
    quiet: Annotated[
        bool, typer.Option("--quiet", "-q", help="Print nothing but warnings and errors.")
    ] = False,
    rrd: RrdOption = True,
    spawn: Annotated[
        bool,
        typer.Option("--spawn", help="Open the recording in the Rerun viewer (needs a display)."),
    ] = False,
    fmt: TableFormatOption = None,
) -> None:
    """Run closed-loop case(s) and the open-loop references; write Parquet results.

    Writes config.json, summary.parquet, steps.parquet, solves.parquet and
    references.parquet (each atomically) into the output directory, and
    recording.rrd unless --no-rrd.
    """
    from cwrend_cli import campaign
    from cwrend_cli.campaign.plan import check_design_models
    from cwrend_cli.campaign.worker import cold_loops_of_case
    from cwrend_cli.config import config_hash, load_config, resolved_dict
    from cwrend_cli.config.adapt import problem_of, windows_of
    from cwrend_cli.console import script_table, summary_console_table, summary_frame
    from cwrend_cli.output import recording
    from cwrend_cli.output.files import check_output_dir, check_run_dir, write_run
    from cwrend_cli.physics.compiled import compiling_notice
    from cwrend_cli.physics.params import arch_order

    with user_errors():
        cfg = load_config(file, set_ or ())
        archs = _parse_archs(arch)
        seed_ = 0 if seed is None else seed
        if spawn and not rrd:
            raise ConfigError("--spawn opens the recording: drop --no-rrd")
        if rrd:  # refuse before computing, so an error never leaves half the files
            recording.check_enabled()
        if out is None:
            slug = archs[0].slug if len(archs) == 1 else "multi"
            runs_root = Path(cfg.output.dir) / RUNS_DIR
            if (runs_root / MANIFEST).exists():  # cwrend's own directory: a manifest will do
                raise ConfigError(
                    f"{runs_root} is a campaign directory (a campaign named {RUNS_DIR!r}); "
                    "name the run's directory with --out"
                )
            out = Path(cfg.output.dir) / run_dir(cfg.output.name or "run", slug, seed_)
        check_output_dir(out, "choose another --out or output.dir")  # before computing
        check_run_dir(out, "choose another --out")  # never in a campaign's tree
        console = _console(stderr=True)
        ignored = [name for name in ("sweep", "dispersions") if getattr(cfg, name)]
        if ignored:  # a run is the base config's case: say so, with -q too
            tables = " and ".join(f"[{name}]" for name in ignored)
            console.print(
                f"warning: cwrend run flies the base configuration; its {tables} "
                f"{'is' if len(ignored) == 1 else 'are'} not applied (cwrend sweep applies "
                "them: a campaign's seed 0 is not this run)",
                markup=False,
                soft_wrap=True,
            )
        problem = problem_of(cfg)
        check_design_models(problem, archs)  # a refusal comes before any compile notice
        if quiet:
            case = campaign.run_case(cfg, archs, seed_)
        else:
            guidance = problem.guidance
            loops = cold_loops_of_case(cfg, archs, seed_)
            notice = compiling_notice({a.resolved_method(guidance) for a in archs}, loops=loops)
            if notice is not None and not console.is_terminal:  # no spinner to show it in
                console.print(notice, markup=False)
            with console.status(notice or "running…", spinner="dots"):
                case = campaign.run_case(cfg, archs, seed_)
        # computed in --arch order; shown and written in the one order of every table
        order = arch_order(r.arch for r in case.runs)
        case = replace(case, runs=tuple(sorted(case.runs, key=lambda r: order.index(r.arch))))
        written = write_run(out, resolved_dict(cfg), config_hash(cfg), case.runs, case.references)
        if rrd:
            rrd_path = recording.record_case(
                Path(written) / RUN_RECORDING, case.runs, case.references,
                windows_of(cfg), u_max_km_s2=cfg.scenario.u_max_km_s2,
                recording_name=f"cwrend run · {Path(written).name}",
            )  # fmt: skip
            if spawn and not recording.open_in_viewer(rrd_path):
                console.print(
                    f"warning: no Rerun viewer could be started (no `rerun` executable or no "
                    f"display); open the file elsewhere with `rerun {rrd_path}`"
                )
        if fmt is not None:  # the rows of the console table, for scripts
            sys.stdout.write(script_table(summary_frame(case), fmt.value))
        elif not quiet:
            from cwrend_cli.physics.params import Sensor  # the run loaded physics already

            dof = Sensor(model=cfg.sensor.model).dimension  # the NIS of a consistent filter
            _console().print(summary_console_table(case, f"cwrend run · {file}", dof))
            console.print(f"results written to {written}", soft_wrap=True, markup=False)


# ---------------------------------------------------------------------------
# Campaigns: ablate and sweep
# ---------------------------------------------------------------------------

SeedsOption = Annotated[
    int | None,
    typer.Option("--seeds", "-n", min=1, help="Seeds 0 to N−1 (default 1).", metavar="N"),
]
SeedListOption = Annotated[
    str | None,
    typer.Option("--seed-list", help="Explicit seeds, e.g. 0,5,9.", metavar="LIST"),
]
ArchsOption = Annotated[
    str,
    typer.Option(
        "--arch",
        "-a",
        help=ARCH_HELP,
        metavar="ARCHS",
    ),
]
PairOption = Annotated[
    list[str] | None,
    typer.Option(
        "--pair",
        help="Also compare A with B seed by seed (A:B, two architectures of the campaign; "
        "repeatable). By default: MTF vs plain and adaptive vs fixed within each re-solve "
        "method, and cone program vs shooting (with the single-factor baseline: MTF vs STF "
        "and STF vs plain too).",
        metavar="A:B",
    ),
]
WorkersOption = Annotated[
    int | None,
    typer.Option(
        "--workers",
        "-w",
        min=1,
        help="Parallel workers (default: all cores; 1 = in-process).",
        metavar="N",
    ),
]
ExecutorOption = Annotated[
    str,
    typer.Option("--executor", help="'local' (process pool) or 'dask'.", metavar="local|dask"),
]
AddressOption = Annotated[
    str | None,
    typer.Option(
        "--address", help="Dask scheduler, e.g. tcp://host:8786 (dask only).", metavar="URL"
    ),
]
NameOption = Annotated[
    str | None,
    typer.Option(
        "--name",
        help="Campaign name: results go to <output.dir>/<name> (default output.name).",
        metavar="NAME",
    ),
]
ForceOption = Annotated[
    bool, typer.Option("--force", help="Start over: discard what the campaign directory holds.")
]
RetryOption = Annotated[bool, typer.Option("--retry-failed", help="Rerun the failed runs.")]
VersionChangeOption = Annotated[
    bool,
    typer.Option(
        "--allow-version-change",
        help="Resume a campaign computed with other versions of cwrend or its numerics "
        "(refused by default: its numbers could differ in the last bits).",
    ),
]
RepairManifestOption = Annotated[
    bool,
    typer.Option(
        "--repair-manifest",
        help="Rebuild a damaged manifest.json from the journal and this configuration (the "
        "journal's runs must be this campaign's; they are kept).",
    ),
]
LargeOption = Annotated[
    bool,
    typer.Option("--yes-large", help=f"Allow more than {limits.MAX_POINTS:,} grid points."),
]
QuietOption = Annotated[
    bool,
    typer.Option(
        "--quiet", "-q", help="Print nothing but errors (no progress, tables or summary)."
    ),
]
RrdSeedsOption = Annotated[
    int | None,
    typer.Option(
        "--rrd-seeds",
        min=0,
        help="Record seeds below K only (one .rrd per seed and grid point, all architectures; "
        "default output.rrd_seeds = 3).",
        metavar="K",
    ),
]


def _seeds(seeds: int | None, seed_list: str | None) -> list[int]:
    if seeds is not None and seed_list is not None:
        raise ConfigError("use either --seeds or --seed-list, not both")
    if seed_list is None:
        if seeds is not None and seeds > limits.MAX_RUNS:
            raise ConfigError(f"--seeds {seeds}: at most {limits.MAX_RUNS:,} seeds per campaign")
        return list(range(seeds or 1))
    if len(seed_list) > 20 * limits.MAX_RUNS:
        raise ConfigError(f"--seed-list: too long (at most {limits.MAX_RUNS:,} seeds)")
    try:
        values = [int(v) for v in seed_list.split(",") if v.strip()]
    except ValueError:
        raise ConfigError(
            f"--seed-list {seed_list[:40]!r}: comma-separated integers, e.g. 0,5,9"
        ) from None
    if not values or len(set(values)) != len(values):
        raise ConfigError(f"--seed-list {seed_list[:40]!r}: distinct integers required")
    bad = [v for v in values if not 0 <= v <= limits.MAX_SEED]
    if bad:
        raise ConfigError(
            f"--seed-list: seed {bad[0]} is out of range; seeds are integers in "
            f"[0, {limits.MAX_SEED}] (2**63 − 1)"
        )
    return values


#: ``ablate --until``: seeds per batch, and the seed count it stops at, unless given.
DEFAULT_BATCH = 50
DEFAULT_MAX_SEEDS = 1000


@dataclass(frozen=True)
class CampaignOptions:
    """The command-line options shared by ``ablate`` and ``sweep``."""

    seeds: int | None
    seed_list: str | None
    arch: str
    workers: int | None
    executor: str
    address: str | None
    name: str | None
    force: bool
    retry_failed: bool
    quiet: bool
    rrd: bool
    rrd_seeds: int | None
    allow_version_change: bool
    yes_large: bool
    design: str | None = None  # sweep: a sampled design instead of a grid
    samples: int | None = None
    ranges: tuple[str, ...] = ()  # sweep --design: --range KEY=LOW:HIGH…
    second_order: bool = False  # sweep --design sobol: second-order indices
    until: str | None = None  # ablate: sequential Monte Carlo target
    batch: int | None = None  # ablate --until (None: not given, DEFAULT_BATCH)
    max_seeds: int | None = None  # ablate --until (None: not given, DEFAULT_MAX_SEEDS)
    strict: bool = False  # ablate --until: exit 1 when the target is not met
    pairs: tuple[str, ...] = ()  # --pair A:B, compared besides statistics.DEFAULT_PAIRS
    repair_manifest: bool = False  # rebuild a damaged manifest.json from the journal
    table_format: str | None = None  # --format: the statistics for scripts on stdout


def command_line() -> list[str]:
    """This process's command line as a shell would run it again (``sys.argv``).

    ``python -m cwrend_cli …`` has the module's ``__main__.py`` as ``argv[0]``:
    it is given back as the interpreter and ``-m cwrend_cli``.
    """
    argv = list(sys.argv)
    if argv and Path(argv[0]).name == "__main__.py":
        return [sys.executable, "-m", "cwrend_cli", *argv[1:]]
    return argv


def _shown(path: Path) -> str:
    """``path`` as a command prints where it wrote: relative to the working directory when
    inside it (``results/tour``, as given in the tour), else absolute."""
    absolute = Path(path).absolute()
    try:
        return str(absolute.relative_to(Path.cwd()))
    except ValueError:
        return str(absolute)


def _campaign_dir(cfg: CwrendConfig, name: str | None) -> Path:
    base = Path(cfg.output.dir)
    out = (base / (cfg.output.name or "campaign")).resolve()
    if not out.is_relative_to(base.resolve()) or out == base.resolve():
        raise ConfigError(f"output.name = {cfg.output.name!r}: must stay inside output.dir")
    return out


def _announce(err: Console, plan: campaign.CampaignPlan) -> None:
    """Say how many runs and roughly how much disk a large campaign will take."""
    from cwrend_cli.output.files import estimated_bytes

    runs = len(plan.runs)
    if runs <= limits.ANNOUNCE_RUNS:
        return
    seeds, points = len(plan.seeds), max(len({r.point for r in plan.runs}), 1)
    kept = seeds if plan.steps_seeds is None else min(seeds, plan.steps_seeds)
    recorded = seeds if plan.rrd_seeds is None else min(seeds, plan.rrd_seeds)
    stepped = points if plan.steps_points is None else len(plan.steps_points)
    size = estimated_bytes(runs, runs * kept * stepped // (seeds * points), stepped * recorded)
    where = "" if plan.steps_points is None else f", {stepped:,} point(s): design_steps_points"
    err.print(
        f"plan: {runs:,} runs ({points:,} point(s) × {seeds:,} seeds × {len(plan.archs)} "
        f"architectures), about {size / 1e9:.1f} GB of results (per-step data for "
        f"{kept:,} seeds: output.steps_seeds{where})",
        markup=False,
    )


def _first_run_notice(plan: campaign.CampaignPlan, fan_out: bool) -> str | None:
    """``compiling kernels (first run only, about N s)…`` when the plan's kernels are not cached.

    The same check as ``cwrend run`` (:func:`cwrend_cli.physics.compiled.compiling_notice`),
    for the guidance methods the plan's runs use and the step loops of their configurations
    (a J2 truth, an ``ss`` design model: :func:`cwrend_cli.campaign.worker.cold_loops`);
    ``fan_out``: a local campaign given two
    workers or more (a pool, or a helper process beside a campaign of one task), which
    compile part of the kernels at the same time.
    """
    from cwrend_cli.campaign.worker import cold_loops
    from cwrend_cli.config import ALL_ARCHITECTURES
    from cwrend_cli.physics.compiled import compiling_notice

    methods = {
        ALL_ARCHITECTURES[r.arch].resolved_method(task.problem.guidance)
        for task in plan.tasks
        for r in task.runs
    }
    return compiling_notice(methods, fan_out, loops=cold_loops(plan.tasks))


@contextmanager
def _second_ctrl_c_exits_130(err: Console) -> Iterator[None]:
    """A Ctrl-C that reaches the command (a second one, while results are summarised): 130."""
    try:
        yield
    except KeyboardInterrupt:
        err.print("interrupted: completed runs are kept; run the same command to resume")
        raise typer.Exit(code=130) from None


def _campaign(
    command: Literal["ablate", "sweep"],
    file: Path,
    set_: list[str] | None,
    params: list[str],
    opts: CampaignOptions,
) -> None:
    err = _console(stderr=True)
    # the campaign's lock, taken by its first run and held until everything is written
    with user_errors(), _second_ctrl_c_exits_130(err), ExitStack() as hold:
        from cwrend_cli.config import load_config

        # The config, the architectures and the plain option rules first: a typo exits 2
        # before the campaign package and its numerics are imported (about 0.6 s).
        overrides = list(set_ or [])
        if opts.name is not None:
            overrides.append(f"output.name={json.dumps(opts.name)}")
        if opts.rrd_seeds is not None and not opts.rrd:
            raise ConfigError("--rrd-seeds sets how many seeds are recorded: drop --no-rrd")
        if not opts.rrd or opts.rrd_seeds is not None:
            overrides.append(f"output.rrd_seeds={0 if not opts.rrd else opts.rrd_seeds}")
        cfg = load_config(file, overrides)
        if opts.executor not in ("local", "dask"):
            raise ConfigError(f"--executor {opts.executor!r}: must be 'local' or 'dask'")
        if opts.address and opts.executor != "dask":
            raise ConfigError("--address needs --executor dask")
        if opts.samples is not None and opts.design is None:
            raise ConfigError("--samples sets the size of a --design")
        archs = [a.slug for a in _parse_archs(opts.arch)]

        from cwrend_cli import campaign
        from cwrend_cli.campaign import design, sequential
        from cwrend_cli.campaign.statistics import campaign_pairs
        from cwrend_cli.console import phase, until_console_table
        from cwrend_cli.output import recording

        if cfg.output.rrd_seeds != 0:
            recording.check_enabled()
        if opts.design is not None and opts.design not in design.DESIGNS:
            raise ConfigError(f"--design {opts.design!r}: one of {', '.join(design.DESIGNS)}")
        pairs = campaign_pairs(opts.pairs, archs)
        out = _campaign_dir(cfg, opts.name)
        batch = opts.batch or DEFAULT_BATCH
        max_seeds = opts.max_seeds or DEFAULT_MAX_SEEDS
        target: sequential.Target | None = None  # --until's
        named: campaign.CampaignStatistics | None = None  # of the runs named, if computed
        # the most seeds a campaign of these points and architectures accepts (--until:
        # never run nor advised beyond; the plan refuses more than limits.MAX_RUNS runs)
        limit = sequential.seeds_limit()
        if opts.until is None:
            if opts.strict:
                raise ConfigError("--strict: applies to --until only; add --until TARGET")
            for option, value in (("--batch", opts.batch), ("--max-seeds", opts.max_seeds)):
                if value is not None:  # else accepted and ignored: a fixed --seeds campaign
                    raise ConfigError(
                        f"{option}: applies to --until only; add --until TARGET or drop {option}"
                    )
            seeds = _seeds(opts.seeds, opts.seed_list)
            plan, summary, statistics = _campaign_step(
                command, cfg, archs, seeds, params, opts, out, err, pairs, hold
            )
            achieved: list[sequential.Achieved] = []
            n = len(seeds)
        else:
            if opts.seeds is not None or opts.seed_list is not None:
                raise ConfigError("--until chooses the seed count: drop --seeds / --seed-list")
            # a pair added by an earlier command (--pair A:B, in the manifest) is compared
            # again by this one (when both its architectures run, without --force, which
            # forgets it): it may be the target
            recorded = () if opts.force else pairs_recorded_at(out / MANIFEST)
            remembered = [p for p in recorded if p not in pairs and set(p) <= set(archs)]
            target = sequential.parse_until(opts.until, [*pairs, *remembered], archs, recorded)
            if max_seeds > limits.MAX_RUNS:
                raise ConfigError(f"--max-seeds: at most {limits.MAX_RUNS:,}")
            # the runs a seed (points × architectures) bound the seeds: refused before any
            # run, not at the batch that would cross limits.MAX_RUNS
            first = _plan(cfg, archs, [0], params, opts)
            limit = sequential.seeds_limit(len(first.runs))
            if max_seeds > limit:
                raise ConfigError(
                    f"--max-seeds {max_seeds:,}: at most {limit:,} here ({len(first.runs):,} runs "
                    f"a seed: points × architectures; a campaign runs at most "
                    f"{limits.MAX_RUNS:,}); lower --max-seeds"
                )
            achieved = []
            n = 0
            label = f"{command} {out.name}: computing statistics"
            quiet = opts.quiet or opts.table_format is not None
            whole = True  # whether the last batch's statistics are those of every run held
            for n in sequential.seed_counts(batch, max_seeds):
                plan, summary, statistics = _campaign_step(
                    command, cfg, archs, list(range(n)), params, opts, out, err, pairs, hold,
                    write=False,
                )  # fmt: skip
                if summary.interrupted:  # no statistics computed: stop at once
                    break
                # the rule reads the intervals of this step's seeds, not of every seed the
                # directory holds: a rerun of a finished campaign decides as it did, and
                # computes only those at each batch (the file is written once, below)
                with phase(err, label, quiet=quiet):
                    named, whole = _batch_statistics(command, plan, summary, out)
                statistics = named
                achieved = sequential.achieved(named.frame, target, archs)
                if sequential.ready(n, batch) and all(a.met for a in achieved):
                    break
                if not opts.quiet and n < max_seeds:
                    err.print(sequential.next_batch_message(n, batch, achieved), markup=False)
            if not summary.interrupted and not whole:  # the file covers every run held
                with phase(err, label, quiet=quiet):
                    statistics = campaign.write_statistics(
                        out, command, plan.root_seed, summary.pairs
                    )
        _report_campaign(command, plan, summary, statistics, out, opts, err, named)
        # widths are checked only from sequential.checked_from(batch) seeds: a --max-seeds
        # below that stops with none checked
        checked = opts.until is None or sequential.ready(n, batch)
        if achieved and not opts.quiet:  # on stderr when stdout is a --format table
            shown = _console() if opts.table_format is None else err
            unit = None if target is None else target.unit
            shown.print(until_console_table(achieved, opts.until or "", checked, unit))
        unchecked = bool(achieved) and not checked  # met or not: not known (--strict: exit 1)
        unmet = opts.until is not None and achieved and not all(a.met for a in achieved)
        said = not summary.interrupted and (opts.strict or not opts.quiet)
        if unchecked and said:  # the one verdict: not checked, however wide the intervals
            err.print(sequential.unchecked_message(n, batch, achieved, limit), markup=False)
        elif unmet and said:
            err.print(sequential.unmet_message(achieved, max_seeds, limit), markup=False)
        if summary.interrupted:
            asked = {r.run_key for r in plan.runs}
            done = len(asked & campaign.held_run_keys(out))
            err.print(
                f"interrupted: {done} of {len(asked)} runs done ({summary.executed} computed now), "
                f"{summary.failed} failed; run the same command to resume (and to write the "
                f"statistics) → {_shown(out)}",
                soft_wrap=True,
                markup=False,
            )
            raise typer.Exit(code=130)
        if summary.failed:
            err.print(
                "some runs failed (see events.jsonl / runs.parquet); --retry-failed reruns them"
            )
            raise typer.Exit(code=1)
        if (unmet or unchecked) and opts.strict:
            raise typer.Exit(code=1)


def _workers(opts: CampaignOptions) -> int | None:
    """The campaign's worker count: ``--workers``, else the machine's for the local executor;
    None for a Dask cluster of unknown size (it sizes the tasks when
    ``output.seeds_per_task`` is unset: 16 seeds a task)."""
    from cwrend_cli.campaign.executors import default_workers

    return opts.workers or (default_workers() if opts.executor != "dask" else None)


def _plan(
    cfg: CwrendConfig,
    archs: list[str],
    seeds: list[int],
    params: list[str],
    opts: CampaignOptions,
) -> campaign.CampaignPlan:
    """The campaign's plan of ``seeds`` (:func:`.campaign.plan`, with the command's options)."""
    from cwrend_cli import campaign
    from cwrend_cli.campaign import design

    design_kind: design.Design | None = opts.design  # type: ignore[assignment]
    return campaign.plan(
        cfg, archs, seeds, params, allow_large=opts.yes_large, design_kind=design_kind,
        samples=opts.samples, workers=_workers(opts), ranges=opts.ranges,
        second_order=opts.second_order,
    )  # fmt: skip


def _campaign_step(
    command: Literal["ablate", "sweep"],
    cfg: CwrendConfig,
    archs: list[str],
    seeds: list[int],
    params: list[str],
    opts: CampaignOptions,
    out: Path,
    err: Console,
    pairs: Sequence[tuple[str, str]],
    hold: ExitStack,
    write: bool = True,
) -> tuple[campaign.CampaignPlan, campaign.CampaignSummary, campaign.CampaignStatistics]:
    """Plan, run (resuming) and compute the statistics (with ``pairs``) of one invocation.

    The campaign's lock is entered into ``hold`` (the command's): kept until the
    command has written everything, never released between the runs and the
    statistics (issue 36 item 2). ``write`` false: no statistics computed (a batch
    of ``ablate --until``, which computes those it needs: :func:`_batch_statistics`).
    """
    from cwrend_cli import campaign
    from cwrend_cli.console import RichProgress, phase

    executor_kind: ExecutorKind = "dask" if opts.executor == "dask" else "local"
    workers = _workers(opts)
    plan = _plan(cfg, archs, seeds, params, opts)
    if not opts.quiet:
        from cwrend_cli.config import replaced_sweep_keys

        swept = dict(plan.grid)
        for key in replaced_sweep_keys(cfg.sweep, params):  # the documented override, said
            table = cfg.sweep[key]
            written = list(table) if isinstance(table, tuple) else table  # as in the file
            err.print(
                f"note: --param {key} replaces the config's [sweep] values of {key} "
                f"({written!r}); the grid sweeps {key} = {list(swept[key])!r}",
                soft_wrap=True,
                markup=False,
            )
        _announce(err, plan)
    fan_out = executor_kind == "local" and (workers or 1) > 1
    notice = _first_run_notice(plan, fan_out)
    quiet = opts.quiet or opts.table_format is not None
    # cwrend run's check of each scenario, before anything is written: an unreachable
    # target (a port in metres) exits 2 instead of a campaign of failed runs. On a first
    # run it compiles the references' kernels (and, fanned out, a helper the step loop's)
    with phase(err, (notice or "").removesuffix("…"), quiet=quiet or notice is None):
        checked_before = None if opts.force else out  # --force starts over: every point
        references = campaign.check_references(plan, beside=fan_out, out_dir=checked_before)
    # one process: the step loop compiles with the runs; said again only where the line
    # above was a spinner (a terminal), not printed twice into a log
    left = None if fan_out or not err.is_terminal else notice
    progress = RichProgress(err, f"{command} {out.name}", quiet=quiet, notice=left)
    summary = campaign.run_campaign(
        plan, out, command=command, executor_kind=executor_kind, workers=opts.workers,
        address=opts.address, force=opts.force, retry_failed=opts.retry_failed,
        allow_version_change=opts.allow_version_change, progress=progress,
        argv=command_line(), hold=hold, repair_manifest=opts.repair_manifest, pairs=pairs,
        references=references,
    )  # fmt: skip
    if summary.set_aside:  # said even with -q: runs were computed again
        err.print(_set_aside_line(summary.set_aside), soft_wrap=True, markup=False)
    if summary.interrupted:  # out at once (the bootstrap of 12,000 runs takes 1.5-4 s on two
        # cores): the statistics are written, with everything, when the campaign completes
        return plan, summary, campaign.no_statistics(command)
    if not write:
        return plan, summary, campaign.no_statistics(command)
    with progress.phase("computing statistics"):
        # the pairs asked for and those earlier commands added (the manifest records them)
        statistics = campaign.write_statistics(out, command, plan.root_seed, summary.pairs)
    return plan, summary, statistics


def _set_aside_line(set_aside: Mapping[str, int]) -> str:
    """The console line of the journal's run records that were not reused (issue 36 item 4)."""
    reasons = ", ".join(f"{why}: {n}" for why, n in sorted(set_aside.items()))
    return (
        f"journal: {sum(set_aside.values())} run record(s) set aside ({reasons}): they do not "
        "prove they are this campaign's and these versions', so their runs are computed again"
    )


def _batch_statistics(
    command: Literal["ablate", "sweep"],
    plan: campaign.CampaignPlan,
    summary: campaign.CampaignSummary,
    out: Path,
) -> tuple[campaign.CampaignStatistics, bool]:
    """The statistics of the runs ``plan`` names (a batch of ``ablate --until``) and whether
    they are those of every run the directory holds: then written to the statistics file
    (:func:`campaign.write_statistics`), else computed on the runs named only, nothing
    written (:func:`campaign.subset_statistics`, as :func:`_report_campaign` does)."""
    from cwrend_cli import campaign

    asked = {r.run_key for r in plan.runs}
    if campaign.held_run_keys(out) - asked:
        return campaign.subset_statistics(out, command, plan.root_seed, asked, summary.pairs), False
    return campaign.write_statistics(out, command, plan.root_seed, summary.pairs), True


def _report_campaign(
    command: Literal["ablate", "sweep"],
    plan: campaign.CampaignPlan,
    summary: campaign.CampaignSummary,
    statistics: campaign.CampaignStatistics,
    out: Path,
    opts: CampaignOptions,
    err: Console,
    named: campaign.CampaignStatistics | None = None,
) -> None:
    """The console tables and summary line of a finished (or interrupted) campaign.

    ``named``: the statistics of the runs ``plan`` names, when computed already
    (:func:`_batch_statistics`: ``ablate --until`` reads its target from them).
    """
    from cwrend_cli import campaign
    from cwrend_cli.campaign import design
    from cwrend_cli.console import (
        ablation_console_table,
        applied_console_table,
        consistency_console_table,
        paired_console_table,
        phase,
        script_table,
        sensitivity_console_table,
        sweep_console_table,
    )

    if summary.interrupted:  # no statistics computed (see _campaign_step)
        return
    label = f"{command} {out.name}"
    designed = plan.design is not None
    with phase(err, f"{label}: computing sensitivity indices", quiet=opts.quiet or not designed):
        sensitivity = campaign.write_sensitivity(out, plan)
    asked = {r.run_key for r in plan.runs}
    held = campaign.held_run_keys(out)
    if held - asked and (not opts.quiet or opts.table_format is not None):
        # a re-run naming fewer seeds, architectures or points than the directory holds:
        # report on exactly the runs asked for, in the console and the script table alike;
        # the statistics file covers them all
        if named is None:
            with phase(err, f"{label}: computing statistics of the runs named", opts.quiet):
                named = campaign.subset_statistics(
                    out, command, plan.root_seed, asked, summary.pairs
                )
        statistics = named
        stats_file = ABLATION_STATS if command == "ablate" else SWEEP_STATS
        if not opts.quiet:
            err.print(
                f"note: the tables cover the {len(asked & held)} run(s) this command names; "
                f"the directory holds {len(held)} and {stats_file} covers them all",
                markup=False,
            )
    if opts.table_format is not None:  # the statistics of the runs named, for scripts
        sys.stdout.write(script_table(statistics.frame, opts.table_format))
    if opts.quiet or opts.table_format is not None:
        return
    stats = statistics.frame
    stdout = _console()
    if not stats.empty:
        if command == "ablate":
            stdout.print(ablation_console_table(stats, f"cwrend ablate · {out.name}"))
            applied = applied_console_table(stats)
            if applied is not None:
                stdout.print(applied)
            paired = paired_console_table(stats)
            if paired is not None:
                stdout.print(paired)
        elif plan.design is not None:  # hundreds of sampled points: no per-point table
            err.print(
                f"{len({r.point for r in plan.runs})} design points: the statistics of each "
                f"are in {SWEEP_STATS}",
                markup=False,
            )
        else:
            title = f"cwrend sweep · {out.name}"
            stdout.print(sweep_console_table(stats, list(statistics.groups), title))
            applied = applied_console_table(stats, list(statistics.groups))
            if applied is not None:
                stdout.print(applied)
        if plan.design is None:  # filter consistency against its χ² bands (issue 33)
            table = consistency_console_table(
                stats, list(statistics.groups), f"filter consistency · {out.name}"
            )
            if table is not None:
                stdout.print(table)
    if not sensitivity.empty:
        stdout.print(sensitivity_console_table(sensitivity, f"sensitivity · {out.name}"))
    if plan.design is not None:
        note = design.sensitivity_note(plan.design.kind, plan.design.samples, len(plan.design.rows))
        if note is not None:
            err.print(note, markup=False)
    if not summary.interrupted:
        err.print(
            f"{summary.executed} run(s) computed, {summary.skipped} already done; campaign "
            f"holds {summary.ok} ok, {summary.failed} failed → {_shown(out)}",
            soft_wrap=True,  # a path must stay copyable
            markup=False,
        )


@app.command(
    "ablate", cls=_Command, short_help="Compare the architectures on the same noise per seed."
)
def ablate(
    file: ConfigFile,
    seeds: SeedsOption = None,
    seed_list: SeedListOption = None,
    arch: ArchsOption = "all",
    workers: WorkersOption = None,
    executor: ExecutorOption = "local",
    address: AddressOption = None,
    name: NameOption = None,
    force: ForceOption = False,
    retry_failed: RetryOption = False,
    allow_version_change: VersionChangeOption = False,
    repair_manifest: RepairManifestOption = False,
    quiet: QuietOption = False,
    rrd: RrdOption = True,
    rrd_seeds: RrdSeedsOption = None,
    yes_large: LargeOption = False,
    fmt: TableFormatOption = None,
    until: Annotated[
        str | None,
        typer.Option(
            "--until",
            help="Run seeds in batches until the 95 % interval half-width of a metric is at "
            "most a target: [STATISTIC.]METRIC[@A-B]:WIDTH[%], e.g. miss_km:0.0005 (every "
            "architecture), median.miss_km:5% or miss_km@mtf_adaptive-plain_adaptive:0.001.",
            metavar="TARGET",
        ),
    ] = None,
    batch: Annotated[
        int | None,
        typer.Option(
            "--batch",
            min=1,
            max=limits.MAX_RUNS,
            help=f"Seeds per batch with --until (default {DEFAULT_BATCH}).",
            metavar="N",
        ),
    ] = None,
    max_seeds: Annotated[
        int | None,
        typer.Option(
            "--max-seeds",
            min=1,
            help=f"Stop --until at this many seeds (default {DEFAULT_MAX_SEEDS}).",
            metavar="N",
        ),
    ] = None,
    strict: Annotated[
        bool,
        typer.Option(
            "--strict",
            help="With --until: exit 1 when --max-seeds is reached with the target not met "
            "(or not checked: widths are checked from 2 batches and 20 seeds).",
        ),
    ] = False,
    pair: PairOption = None,
    set_: SetOption = None,
) -> None:
    """Compare the architectures on the same noise per seed (plus open-loop references).

    Results: <output.dir>/<name>/ with manifest.json, runs.parquet, steps/ and
    solves/ datasets, events.jsonl, ablation.parquet (statistics with 95 %
    bootstrap intervals and paired comparisons) and recordings/ (one Rerun
    .rrd per recorded seed). Rerunning resumes.
    Exit code 1 if any run failed (or, with --strict, the --until target was not met
    or not checked within --max-seeds), 2 for bad input, 3 if the machine failed (disk full,
    lost workers: nothing recorded, rerun to resume), 130 if interrupted.
    """
    opts = CampaignOptions(seeds, seed_list, arch, workers, executor, address, name, force,
                           retry_failed, quiet, rrd, rrd_seeds, allow_version_change,
                           yes_large, until=until, batch=batch, max_seeds=max_seeds,
                           strict=strict, pairs=tuple(pair or ()),
                           repair_manifest=repair_manifest,
                           table_format=fmt.value if fmt else None)  # fmt: skip
    _campaign("ablate", file, set_, [], opts)


@app.command(
    "sweep", cls=_Command, short_help="Grid × architectures × seeds, [dispersions] per run."
)
def sweep(
    file: ConfigFile,
    param: Annotated[
        list[str] | None,
        typer.Option(
            "--param",
            "-p",
            help="Swept key: dotted.key=v1,v2,v3, dotted.key=start:stop:num or a TOML array "
            "'dotted.key=[[1, 2, 3], [4, 5, 6]]' or 'dotted.key=[1, 2, 3],[4, 5, 6]' (vectors) "
            "(repeatable, one per key; adds "
            "a key to the config's [sweep] table or replaces its values, with a note).",
            metavar="KEY=VALUES",
        ),
    ] = None,
    seeds: SeedsOption = None,
    seed_list: SeedListOption = None,
    arch: ArchsOption = "all",
    workers: WorkersOption = None,
    executor: ExecutorOption = "local",
    address: AddressOption = None,
    name: NameOption = None,
    force: ForceOption = False,
    retry_failed: RetryOption = False,
    allow_version_change: VersionChangeOption = False,
    repair_manifest: RepairManifestOption = False,
    quiet: QuietOption = False,
    rrd: RrdOption = True,
    rrd_seeds: RrdSeedsOption = None,
    yes_large: LargeOption = False,
    fmt: TableFormatOption = None,
    design_: Annotated[
        str | None,
        typer.Option(
            "--design",
            help="Sample the ranges of [sweep] ({ low = L, high = H }, log = true, int = true, "
            "or { values = [V1, V2] }) instead of a grid: lhs, sobol (with Sobol sensitivity "
            "indices) or random.",
            metavar="lhs|sobol|random",
        ),
    ] = None,
    samples: Annotated[
        int | None,
        typer.Option(
            "--samples",
            min=1,
            max=limits.MAX_RUNS,
            help="Design size: points (lhs, random) or base points, a power of two (sobol: "
            "samples × (parameters + 2) points).",
            metavar="N",
        ),
    ] = None,
    range_: Annotated[
        list[str] | None,
        typer.Option(
            "--range",
            help="A --design range: KEY=LOW:HIGH (uniform), KEY=LOW:HIGH:log, KEY=LOW:HIGH:int "
            "or KEY=V1,V2 (categories); repeatable, adds to / replaces [sweep]'s ranges.",
            metavar="KEY=LOW:HIGH",
        ),
    ] = None,
    second_order: Annotated[
        bool,
        typer.Option(
            "--second-order",
            help="--design sobol: second-order Sobol indices too (samples × (2 × parameters "
            "+ 2) points; extends the first-order design of the same samples).",
        ),
    ] = False,
    pair: PairOption = None,
    set_: SetOption = None,
) -> None:
    """Grid (cartesian product) × architectures × seeds, with [dispersions] per run.

    Every run's config is validated before anything runs. Results as for
    ablate, with sweep.parquet holding the statistics per grid point.
    """
    opts = CampaignOptions(seeds, seed_list, arch, workers, executor, address, name, force,
                           retry_failed, quiet, rrd, rrd_seeds, allow_version_change,
                           yes_large, design=design_, samples=samples,
                           ranges=tuple(range_ or ()), second_order=second_order,
                           pairs=tuple(pair or ()), repair_manifest=repair_manifest,
                           table_format=fmt.value if fmt else None)  # fmt: skip
    _campaign("sweep", file, set_, list(param or []), opts)


# ---------------------------------------------------------------------------
# Report
# ---------------------------------------------------------------------------


@app.command(
    "report",
    cls=_Command,
    short_help="Figures, report.md and report.html into RESULTS_DIR/report/.",
)
def report(
    results_dir: Annotated[
        Path,
        typer.Argument(
            help="Output of `cwrend run` or a campaign directory (ablate/sweep).",
            metavar="RESULTS_DIR",
        ),
    ],
    seed: Annotated[
        int | None,
        typer.Option(
            "--seed",
            min=0,
            max=limits.MAX_SEED,
            help="Noise seed of the per-seed figures 1–5 (default: the first).",
            metavar="N",
        ),
    ] = None,
    point: Annotated[
        str | None,
        typer.Option(
            "--point",
            help="Grid point of figures 1–5 and the per-point tables: its id, or its "
            "swept values (beta=0.5, or 0.5; comma-separated for several keys). "
            "Default: the point at the config's values, else the first id in sorted order. "
            "A bad one lists the points.",
            metavar="KEY",
        ),
    ] = None,
    quiet: Annotated[
        bool,
        typer.Option("--quiet", "-q", help="Print nothing but errors (no file list or notes)."),
    ] = False,
) -> None:
    """Write the paper's figures (PNG), report.md and report.html into RESULTS_DIR/report/.

    report.html is self-contained (figures embedded, the tables, the config
    and its hash).

    Figures 1–6 (trajectories, control, ε and score, NIS and MTF ratio,
    errors, Δv vs miss); for several seeds the miss and Δv distributions and
    the paired comparison; for a sweep one figure per swept parameter.
    """
    with user_errors(), ExitStack() as hold:
        from cwrend_cli.report import write_report

        if results_dir.is_dir():  # no campaign writes in it meanwhile (issue 36 item 2)
            from cwrend_cli.campaign.journal import campaign_lock

            hold.enter_context(campaign_lock(results_dir))
        summary = write_report(results_dir, seed=seed, point=point)
        if quiet:
            return
        for path in summary.files:
            typer.echo(str(path))
        for note in summary.notes:
            _stderr().print(f"note: {note}", markup=False)


# ---------------------------------------------------------------------------
# Compare two campaigns
# ---------------------------------------------------------------------------


@app.command(
    "compare", cls=_Command, short_help="Paired differences A − B of two campaigns' shared runs."
)
def compare(
    a: Annotated[Path, typer.Argument(help="Campaign directory A (ablate or sweep).", metavar="A")],
    b: Annotated[
        Path, typer.Argument(help="Campaign directory B, on the same noise.", metavar="B")
    ],
    metric: Annotated[
        str,
        typer.Option(
            "--metric",
            "-m",
            help="Metrics, comma-separated: miss, dv, fuel (the paper's trapezoid Δv and its "
            "penalty), dv_applied, fuel_applied (the applied impulse and its penalty against "
            "the exact fuel optimum), or their column names.",
            metavar="LIST",
        ),
    ] = "miss,dv",
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="Directory for compare.parquet and compare.png (default: beside A, "
            "<A's parent>/compare-<A>-vs-<B>).",
            metavar="DIR",
        ),
    ] = None,
    quiet: Annotated[
        bool, typer.Option("--quiet", "-q", help="Print nothing but errors (no tables).")
    ] = False,
    fmt: TableFormatOption = None,
) -> None:
    """Compare two campaigns seed by seed on the runs they share.

    Runs match on architecture, seed and grid point; grid points match by
    their swept values (equal on every key both campaigns sweep; a key swept
    by one campaign only becomes a column of the result). Refused (exit 2)
    when the campaigns do not share noise (another noise.seed or noise file)
    or share no run. Per architecture: mean and median of the per-seed
    differences A − B with 95 % bootstrap intervals, and the share of seeds
    where A is lower (better), with its Wilson interval. First, what differs
    between the two configurations (dotted keys with A's and B's values,
    [output] aside), also in the figure's title and compare.parquet's
    metadata (config_diff). Writes compare.parquet and compare.png; never
    into A or B unless --out says so.
    """
    with user_errors():
        from cwrend_cli.campaign import compare as cmp
        from cwrend_cli.console import (
            compare_console_tables,
            config_diff_console_table,
            script_table,
        )
        from cwrend_cli.output.files import make_output_dir, write_parquet
        from cwrend_cli.report import write_compare_figure

        metrics = cmp.parse_metrics(metric)
        result = cmp.compare(cmp.load_campaign(a), cmp.load_campaign(b), metrics)
        if out is None:
            out = a.resolve().parent / compare_dir(a.resolve().name, b.resolve().name)
            if (out / MANIFEST).exists():
                raise ConfigError(f"{out} is a campaign directory: name another with --out")
        make_output_dir(out, "name another directory with --out")
        write_parquet(cmp.compare_table(result), out / COMPARE_STATS)
        differences = [(d.key, d.a, d.b) for d in cmp.config_diff(result.a, result.b)]
        write_compare_figure(
            result.frame, a.name, b.name, out / COMPARE_FIGURE, dirs=(a, b),
            differences=differences,
        )  # fmt: skip
        if fmt is not None:  # the paired differences as computed, for scripts
            sys.stdout.write(script_table(result.frame, fmt.value))
        elif not quiet:
            stdout = _console()
            stdout.print(
                f"cwrend compare: {result.compared} run pair(s) on the same noise\n"
                f"A = {a}\nB = {b}",
                markup=False,
                soft_wrap=True,  # paths must stay copyable
            )
            stdout.print(config_diff_console_table(differences))
            tables = compare_console_tables(result.frame, list(result.groups), "A − B")
            for table in tables:
                stdout.print(table)
        if not quiet:  # the notes on stderr, with --format too (stdout holds the table)
            err = _stderr()
            for note in result.notes:
                err.print(f"note: {note}", markup=False)
            if fmt is None:
                err.print(f"results written to {_shown(out)}", soft_wrap=True, markup=False)


# ---------------------------------------------------------------------------
# Tables for a paper
# ---------------------------------------------------------------------------


@app.command(
    "table",
    cls=_Command,
    short_help="A table of stored statistics across campaigns (md, LaTeX, CSV).",
)
def table(
    results: Annotated[
        list[str],
        typer.Argument(
            help="Campaign directories (ablate or sweep), each DIR or LABEL=DIR (the label names "
            "the campaign in the table).",
            metavar="DIR",
        ),
    ],
    rows: Annotated[
        str | None,
        typer.Option(
            "--rows",
            help="Fields whose values make the rows, comma-separated, each FIELD or "
            "FIELD=HEADER: campaign, arch, other (B of a pair), point, metric, or a "
            "configuration key (its swept value, else the campaign's base value). Default: "
            "campaign (several), the swept keys, arch (and other for a paired value).",
            metavar="FIELDS",
        ),
    ] = None,
    cols: Annotated[
        str | None,
        typer.Option(
            "--cols",
            help="Fields whose values make the columns (as --rows), each with every value; "
            "default: one column per value of --metric.",
            metavar="FIELDS",
        ),
    ] = None,
    metric: Annotated[
        str,
        typer.Option(
            "--metric",
            "-m",
            help="Values, comma-separated, each [STATISTIC.]METRIC[@A-B][:bare][:DIGITS]: "
            "mean|median|p95 of miss, dv, fuel (the paper's 1 s trapezoid), dv_applied, "
            "fuel_applied (Σ‖u_k‖Δt, vs the exact fuel optimum) (95 % bootstrap interval); "
            "solve_mean_ms, "
            "solve_max_ms, solve_success_pct; paired frac_less.miss (Wilson), median_diff.miss, "
            "mean_diff.dv, @A-B for one pair; n (ok runs; seed pairs beside paired values "
            "only). From runs.parquet: infeasible_pct, failed_pct (share of re-solves), "
            "infeasible_solves, failed_solves (their number), max.miss|dv|fuel; "
            ":with=STEP / :without=STEP keep the runs whose re-solves used / never used that "
            "fallback step (n:with=socp_plan counts them). :bare drops the interval, :3 shows "
            "3 decimals. mean.nees, mean.nis: the runs' mean NEES and NIS with the χ² 95 % band "
            "of a consistent filter. Safety (a campaign with [constraints]): violated_pct, "
            "abort_pct (share of runs, % with Wilson), median|p1.min_distance, "
            "median|p1.abort_distance (m), mean.unsafe_time (s) (bootstrap); from the runs: "
            "min.min_distance (m, the worst run), median|max.dock_position (m), "
            "median|max.dock_velocity (mm/s); from solves/ (re-solves of the ok runs): "
            "mean|max.scp_iterations, mean|p95|max.resolve_ms, slack_pct, abort_slack_pct "
            "(share needing a slack, %).",
            metavar="LIST",
        ),
    ] = "n,mean.miss,median.miss,mean.dv",
    where: Annotated[
        list[str] | None,
        typer.Option(
            "--where",
            help="Keep entries whose field has one of the values, in that order: "
            "[CAMPAIGN:]FIELD=V1,V2 (CAMPAIGN: only that campaign's entries). Repeatable.",
            metavar="FILTER",
        ),
    ] = None,
    versus: Annotated[
        list[str] | None,
        typer.Option(
            "--versus",
            help="Pair across campaigns: the paired values also compare A of each other "
            "campaign with B of this one (its label), seed by seed on matching grid points, "
            "as within a campaign; other_campaign is B's campaign. The campaigns must share "
            "noise and seeds. Repeatable.",
            metavar="CAMPAIGN",
        ),
    ] = None,
    fmt: Annotated[
        str,
        typer.Option(
            "--format",
            "-f",
            help="md (GitHub markdown), latex (booktabs) or csv.",
            metavar="md|latex|csv",
        ),
    ] = "md",
    title: Annotated[
        str | None, typer.Option("--title", help="A line above the table.", metavar="TEXT")
    ] = None,
) -> None:
    """Print a table of the statistics campaigns stored, for a paper or a script.

    Reads each campaign's ablation.parquet or sweep.parquet (values with their 95 %
    intervals, never recomputed) and, for the values computed from the runs, its
    runs.parquet (and solves/ for :with= / :without= and the re-solve values); --versus
    pairs the runs of two campaigns.
    Each cell must be one stored value: a cell that two campaigns, grid points or pairs
    fill is refused naming the field that tells them apart (exit 2), as is an unknown
    field or value, and a value no campaign holds (a safety value without [constraints]).
    Misses and distances in m, Δv in km/s, docking speed in mm/s, shares and fuel penalty
    in %; a bootstrap interval
    from fewer than 10 seeds is marked *. Example (a sweep over guidance.hold):

    cwrend table results/paper-1000 --rows guidance.hold,arch --metric n,mean.miss,p95.miss:bare
    """
    with user_errors():
        from cwrend_cli.report import table as tables

        if fmt not in tables.FORMATS:
            raise ConfigError(f"--format {fmt!r}: one of {', '.join(tables.FORMATS)}")
        values = [tables.parse_value(t) for t in metric.split(",") if t.strip()]
        sources = [tables.load_source(r) for r in results]
        built = tables.build_table(
            sources, values, rows, cols, where or (), title, versus or (), _pair_across
        )
        typer.echo(tables.render(built, fmt))


def _pair_across(
    a: Source, b: Source, extra: Sequence[tuple[str, str]], keep: Callable[[tuple[str, str]], bool]
) -> pd.DataFrame:
    """The pairs of ``cwrend table --versus`` (:data:`cwrend_cli.report.table.PairAcross`)."""
    from cwrend_cli.campaign import compare

    a_runs, b_runs = a.runs, b.runs
    assert a_runs is not None and b_runs is not None  # read by build_table for --versus
    campaigns = (
        compare.Campaign(a.path, a.manifest, a_runs),
        compare.Campaign(b.path, b.manifest, b_runs),
    )
    return compare.paired_across(*campaigns, extra, keep)
