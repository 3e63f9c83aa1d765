"""Shared helpers for CLI commands: one-line errors and exit codes."""

from __future__ import annotations

import sys
from typing import NoReturn

import typer

EXIT_OK = 0
EXIT_FAILED_INPUT = 1  # some input could not be processed; the rest was
EXIT_USAGE = 2  # bad arguments or parameters


def error(message: str) -> None:
    """Print one error line to stderr."""
    typer.echo(f"stickslip: error: {message}", err=True)


def usage_error(message: str) -> NoReturn:
    """Print one line and exit with the usage-error code."""
    error(message)
    raise typer.Exit(EXIT_USAGE)


def info(message: str) -> None:
    """Print a status line to stderr (stdout is kept for tables)."""
    typer.echo(message, err=True)


def is_interactive() -> bool:
    return sys.stderr.isatty()
