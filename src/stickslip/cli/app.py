"""The Typer app and its global options; the command modules add their commands to it."""

from __future__ import annotations

import typer

from stickslip._version import __version__
from stickslip.cli.common import set_verbosity, warnings_as_status_lines

app = typer.Typer(
    name="stickslip",
    help=(
        "Prandtl-Tomlinson parameters (U0, K, mean friction, eta, regime) from atomic-scale "
        "stick-slip friction traces. Conventions: ../shared/PHYSICS.md, summarised in README."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"stickslip {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    ctx: typer.Context,
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version."
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Only errors (no status lines, "
                               "tables or progress bars)."),
    verbose: bool = typer.Option(False, "--verbose", "-v", help="More status lines."),
) -> None:
    """stickslip command line."""
    set_verbosity(0 if quiet else 2 if verbose else 1)
    # for the whole command: warnings become -v status lines, never terminal noise
    ctx.with_resource(warnings_as_status_lines())
