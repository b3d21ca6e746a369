"""The `preland` application object, its shared helpers and the console entry point.

Every user mistake ends in one line on stderr naming what is wrong and a
non-zero exit (2 for bad input, 1 for a failed run); never a traceback.
"""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from .. import __version__
from ..errors import PrelandError

def _plain_help_types() -> None:
    """Help shows each option's value as click names it (PATH, INTEGER, FLOAT, TEXT) and nothing for a flag:
    typer 0.29 shows Python annotations instead (`<bool>` for a flag, `<list[Path]>` for a repeatable
    option), which read as code, not as what to type."""
    from typer import core

    names = {"path": "PATH", "int": "INTEGER", "float": "FLOAT", "str": "TEXT", "bool": "BOOLEAN"}

    def plain(self, ctx):
        label = self.display_type(ctx).strip("<>")
        if label.startswith("list[") and label.endswith("]"):
            label = label[5:-1]
        return names.get(label.lower(), label.upper())

    def option_type(self, ctx):
        if self.metavar is not None:
            return self.metavar
        return None if self.is_flag else plain(self, ctx)  # a flag takes no value

    core.TyperOption.display_type_rich = option_type
    core.TyperArgument.display_type_rich = plain  # an argument's metavar is its name column already


_plain_help_types()

app = typer.Typer(
    name="preland",
    help="Automated precision-landing missions for multirotor drones: fly, inject faults, measure.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1


def fail(message: str, *, code: int = EXIT_BAD_INPUT) -> typer.Exit:
    typer.echo(f"preland: error: {message}", err=True)
    return typer.Exit(code)


def _version_callback(value: bool) -> None:
    if value:
        typer.echo(f"preland {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version_callback, is_eager=True,
                                 help="Print the version and exit."),
) -> None:
    """Automated precision-landing missions for multirotor drones."""

def check_sitl_speedup(sitl_speedup: float | None) -> None:
    """--sitl-speedup: None (preland's choice) or within 0.1..1000."""
    if sitl_speedup is not None and not 0.1 <= sitl_speedup <= 1000:
        raise fail(f"--sitl-speedup: must be within 0.1..1000, got {sitl_speedup:g}")


def open_store(db: Path, *, must_exist: bool):
    from ..campaign.store import ResultsStore

    if must_exist and not db.exists():
        raise fail(f"{db}: no such results database")
    try:
        return ResultsStore(db)
    except PrelandError as error:
        raise fail(str(error)) from None


def progress_bar(*, enabled: bool):
    """A progress bar with ETA on stderr (a no-op when disabled), shown from the first `advance` on, so that
    a run refused before its first trial prints its one error line alone."""
    from contextlib import contextmanager

    @contextmanager
    def bar():
        if not enabled:
            yield lambda done, total: None
            return
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
        from rich.progress import TimeRemainingColumn

        shown: list = []

        def advance(done: int, total: int) -> None:
            if not shown:
                progress = Progress(TextColumn("trials"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                                    TextColumn("ETA"), TimeRemainingColumn(), console=Console(stderr=True),
                                    transient=False)
                progress.start()
                shown.extend((progress, progress.add_task("trials", total=None)))
            shown[0].update(shown[1], completed=done, total=total)

        try:
            yield advance
        finally:
            if shown:
                shown[0].stop()

    return bar()


def columns(header: tuple[str, ...], rows: list[tuple[str, ...]]) -> str:
    """Rows as text columns, each as wide as its widest cell (the last one left ragged)."""
    widths = [max(len(row[i]) for row in (header, *rows)) for i in range(len(header) - 1)]
    return "\n".join("  ".join([*(cell.ljust(w) for cell, w in zip(row, widths)), row[-1]]).rstrip()
                     for row in (header, *rows))


def main() -> None:
    """Console entry point."""
    try:
        app()
    except PrelandError as error:  # anything a command did not catch itself
        typer.echo(f"preland: error: {error}", err=True)
        sys.exit(EXIT_FAILED)

