"""Shared helpers for CLI commands: one-line errors and exit codes."""

from __future__ import annotations

import contextlib
import os
import sys
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NoReturn

import typer

EXIT_OK = 0
EXIT_FAILED_INPUT = 1  # some input could not be processed; the rest was
EXIT_USAGE = 2  # bad arguments or parameters


# verbosity of the status lines: 0 quiet (-q), 1 normal, 2 verbose (-v); errors always show
VERBOSITY = {"level": 1}


def set_verbosity(level: int) -> None:
    """Set the verbosity of status lines (``-q``: 0, default 1, ``-v``: 2)."""
    VERBOSITY["level"] = level


def error(message: str) -> None:
    """Print one error line to stderr."""
    typer.echo(f"stickslip: error: {message}", err=True)


def debug(message: str) -> None:
    """A status line shown only with ``-v``."""
    if VERBOSITY["level"] >= 2:
        typer.echo(message, err=True)


def show_progress() -> bool:
    """Progress bars: on a terminal, not under ``-q``."""
    return VERBOSITY["level"] >= 1 and sys.stderr.isatty()


@contextlib.contextmanager
def progress_bar(total: int, desc: str, unit: str = "trace"
                 ) -> Iterator[Callable[[int], None] | None]:  # fmt: skip
    """A progress bar on stderr, fed by a callback that takes the count done so far.

    Yields None (no bar) unless :func:`show_progress` (a terminal, not ``-q``); pass the
    callback to the library's ``progress=`` arguments.
    """
    if not show_progress() or total <= 0:
        yield None
        return
    from tqdm.auto import tqdm

    bar = tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, dynamic_ncols=True)

    def update(done: int) -> None:
        bar.update(max(0, done - bar.n))

    try:
        yield update
    finally:
        bar.close()


def usage_error(message: str) -> NoReturn:
    """Print one line and exit with the usage-error code."""
    error(message)
    raise typer.Exit(EXIT_USAGE)


#: Image formats a plot option accepts (matplotlib writes each from the suffix).
PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def check_output_file(option: str, path: Path) -> None:
    """A usage error, before any work, unless ``path`` can take an output file: it is
    not a folder, and it lies in a folder that exists (a mistyped folder name is refused,
    not made) and that this tool can write in."""
    if path.is_dir():
        usage_error(f"{option} {path} is a directory (it needs a file name)")
    folder = path.parent
    if not folder.is_dir():
        what = "is a file, not a folder" if folder.exists() else "does not exist"
        usage_error(f"{option} {path}: the folder {folder} {what}")
    if not os.access(folder, os.W_OK | os.X_OK):
        usage_error(f"{option} {path}: cannot write in the folder {folder}")


def check_table_path(option: str, path: Path) -> None:
    """A usage error, before any work, unless ``path`` names a result table this tool
    writes (its suffix: :func:`~stickslip.estimators.table.table_format`) where it can
    write it (:func:`check_output_file`)."""
    # imported here: every command imports this module, few write a table
    from stickslip.estimators.table import TableFormatError, table_format

    try:
        table_format(path)
    except TableFormatError as e:
        usage_error(str(e))
    check_output_file(option, path)


def check_plot_path(option: str, path: Path) -> None:
    """A usage error, before any work, unless ``path`` names an image file this tool
    writes (:data:`PLOT_SUFFIXES`) where it can write it (:func:`check_output_file`)."""
    if path.suffix.lower() not in PLOT_SUFFIXES:
        usage_error(f"{option} {path}: a plot is written as one of {', '.join(PLOT_SUFFIXES)} "
                    "(the suffix says which)")  # fmt: skip
    check_output_file(option, path)


def info(message: str) -> None:
    """Print a status line to stderr (stdout is kept for tables); quiet under ``-q``."""
    if VERBOSITY["level"] >= 1:
        typer.echo(message, err=True)


def echo(message: str) -> None:
    """Print a result (a table) to stdout; quiet under ``-q``."""
    if VERBOSITY["level"] >= 1:
        typer.echo(message)


@contextlib.contextmanager
def warnings_as_status_lines() -> Iterator[None]:
    """Route Python warnings raised while a command runs to ``-v`` status lines.

    A library's warning (numpy's ``RuntimeWarning: overflow``, a reader's deprecation)
    is no message for the user: what it means for a result is in the result (a refused
    row says why). Each distinct warning is still shown, once, with ``-v``; errors are
    untouched, and ``python -W error`` still turns warnings into errors.
    """
    seen: set[str] = set()

    def show(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ARG001
        text = f"warning: {category.__name__}: {message} ({Path(filename).name}:{lineno})"
        if text not in seen:
            seen.add(text)
            debug(text)

    with warnings.catch_warnings():
        warnings.showwarning = show
        yield


def is_interactive() -> bool:
    return sys.stderr.isatty()


# Reading options shared by every command that reads vendor maps.
CALIBRATION_HELP = ("Lateral calibration in nN/V, for force channels in volts (wins over a "
                    "calibration stored in the file); for a MATLAB signal without a unit, "
                    "its nN per unit.")
LPL_HELP = "Consecutive scan lines recorded at one load (groups lines by load)."
LOADS_HELP = "Comma-separated loads/setpoints of the line groups (with --lines-per-load)."


def parse_loads_arg(text: str | None) -> list[float] | None:
    """``--loads`` as a list of floats, or a usage error."""
    from stickslip.traces.formats.maps import parse_loads

    try:
        return parse_loads(text)
    except ValueError as e:
        usage_error(str(e))


def reading_options(
    calibration: float | None,
    lines_per_load: int | None,
    loads: list[float] | None,
    scan_size_nm: float | None = None,
    load_unit: str = "nN",
    velocity_nm_per_s: float | None = None,
) -> dict[str, Any]:
    """Reader ``**options`` for :func:`stickslip.traces.collect_traces`, or a usage error."""
    from stickslip.traces.formats.maps import reader_options

    try:
        return reader_options(calibration, lines_per_load, loads, load_unit=load_unit,
                              scan_size_nm=scan_size_nm,
                              velocity_nm_per_s=velocity_nm_per_s)  # fmt: skip
    except ValueError as e:
        usage_error(str(e))
