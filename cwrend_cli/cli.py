"""The ``cwrend`` command line (Typer). Thin: the logic lives in the modules.

Every command wraps its body in :func:`user_errors`, so a user mistake (bad
config, bad override, bad data file) prints ``error: ...`` on stderr and exits
with code 2, without a traceback. Typer's own usage errors also exit with 2.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer
from pydantic import ValidationError
from rich.console import Console

from cwrend_cli import __version__, campaign, storage
from cwrend_cli.config import (
    ARCHITECTURES,
    config_hash,
    format_validation_error,
    load_config,
    parse_arch,
    resolved_dict,
    to_json,
    to_toml,
)
from cwrend_cli.console import summary_console_table
from cwrend_cli.errors import ConfigError, CwrendError

app = typer.Typer(
    name="cwrend",
    help="Robust low-thrust rendezvous campaigns: CW dynamics, MTF Kalman filter, "
    "innovation-adaptive homotopy guidance (Candan & Servadio, AAS 26-893).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
)
config_app = typer.Typer(
    help="Inspect and check configuration files.", no_args_is_help=True, add_completion=False
)
app.add_typer(config_app, name="config")

USER_ERROR_EXIT = 2


def _stderr() -> Console:
    """A console on the current stderr (looked up at call time, so tests can capture it)."""
    return Console(stderr=True, highlight=False, soft_wrap=True)


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
    except ValidationError as exc:
        lines = "\n".join(f"  {line}" for line in format_validation_error(exc))
        _stderr().print("error: invalid values\n" + lines, markup=False)
        raise typer.Exit(code=USER_ERROR_EXIT) from None


# Shared option/argument declarations for commands that take a config file.
ConfigFile = Annotated[
    Path,
    typer.Argument(help="TOML config file (an empty file is the paper scenario)."),
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


class OutputFormat(StrEnum):
    """Formats for ``config show``."""

    toml = "toml"
    json = "json"


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


@config_app.command("show")
def config_show(
    file: ConfigFile,
    set_: SetOption = None,
    fmt: Annotated[
        OutputFormat, typer.Option("--format", "-f", help="Output format.")
    ] = OutputFormat.toml,
) -> None:
    """Print the resolved configuration (defaults and overrides applied) and its hash."""
    with user_errors():
        cfg = load_config(file, set_ or ())
        digest = config_hash(cfg)
        if fmt is OutputFormat.toml:
            typer.echo(f"# config_hash = {digest}\n")
            typer.echo(to_toml(cfg), nl=False)
        else:
            typer.echo(to_json(cfg))
            typer.echo(f"config_hash: {digest}", err=True)


@config_app.command("validate")
def config_validate(file: ConfigFile, set_: SetOption = None) -> None:
    """Check a configuration; print ``OK <hash>`` or the problems (exit code 2)."""
    with user_errors():
        cfg = load_config(file, set_ or ())
        typer.echo(f"OK {config_hash(cfg)}")


def _parse_archs(text: str) -> tuple:
    """``all`` or a comma-separated list of architecture slugs."""
    if text.strip() == "all":
        return tuple(ARCHITECTURES.values())
    archs = tuple(parse_arch(part) for part in text.split(",") if part.strip())
    if not archs:
        raise ConfigError(f"--arch {text!r}: name at least one of {', '.join(ARCHITECTURES)}")
    return archs


@app.command("run")
def run(
    file: ConfigFile,
    arch: Annotated[
        str,
        typer.Option(
            "--arch",
            "-a",
            help="Architecture slug(s), comma-separated, or 'all': "
            + ", ".join(ARCHITECTURES)
            + ".",
        ),
    ] = "mtf_adaptive",
    seed: Annotated[
        int | None,
        typer.Option("--seed", min=0, help="Noise realisation (default 0; root: noise.seed)."),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="Output directory (default: <output.dir>/<output.name>/run-<arch>-seed<N>).",
        ),
    ] = None,
    set_: SetOption = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No table on the console.")] = False,
) -> None:
    """Run closed-loop case(s) and the open-loop references; write Parquet results.

    Writes config.json, summary.parquet, steps.parquet, solves.parquet and
    references.parquet (each atomically) into the output directory.
    """
    with user_errors():
        cfg = load_config(file, set_ or ())
        archs = _parse_archs(arch)
        seed_ = 0 if seed is None else seed
        if out is None:
            slug = archs[0].slug if len(archs) == 1 else "multi"
            out = Path(cfg.output.dir) / (cfg.output.name or "run") / f"run-{slug}-seed{seed_}"
        console = Console(stderr=True, highlight=False)
        with console.status("compiling kernels and running…", spinner="dots"):
            case = campaign.run_case(cfg, archs, seed_)
        written = storage.write_run(
            out, resolved_dict(cfg), config_hash(cfg), case.runs, case.references
        )
        if not quiet:
            Console(highlight=False).print(
                summary_console_table(case, title=f"cwrend run · {file}")
            )
        console.print(f"results written to {written}")
