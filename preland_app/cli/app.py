"""The `preland` application object, its shared helpers and the console entry point.

Every user mistake ends in one line on stderr naming what is wrong and a
non-zero exit (2 for bad input, 1 for a failed run); never a traceback.
"""

from __future__ import annotations

import enum
import sys
from collections.abc import Callable, Iterable
from pathlib import Path

import typer
from typer._click import exceptions as click_errors  # typer 0.29's own click: the `click` package's are others
from typer.core import TyperGroup

from ..version import __version__
from ..errors import PrelandError

DPI = 300  # --dpi of every command that draws: figures, a trial's path, printable boards and pads

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
        if self.type_descriptor.is_choice:  # the values as typed: png|pdf|svg; a long list wraps between values
            return label if len(label) <= 24 else label.replace("|", " | ")
        return names.get(label.lower(), label.upper())

    def option_type(self, ctx):
        if self.metavar is not None:
            return self.metavar
        return None if self.is_flag else plain(self, ctx)  # a flag takes no value

    core.TyperOption.display_type_rich = option_type
    core.TyperArgument.display_type_rich = plain  # an argument's metavar is its name column already


_plain_help_types()


class _Choices(enum.EnumMeta):
    """The metaclass of `choices`: iterating the class gives the values its function returns now."""

    def __iter__(cls):
        return iter(cls._values())

    def __len__(cls):
        return len(cls._values())

    def __contains__(cls, value):
        return value in cls._values()


def _values_of(reference: str) -> Callable[[], Iterable[str]]:
    """`"package.module:NAME"` as a function giving its values, imported on first use: a constant's items
    (a mapping's keys), an Enum's values, or what a function returns."""
    def values() -> Iterable[str]:
        import importlib

        module, _, name = reference.partition(":")
        found = getattr(importlib.import_module(module), name)
        if isinstance(found, type) and issubclass(found, enum.Enum):
            return [member.value for member in found]
        return found() if callable(found) else found

    return values


def choices(values: Callable[[], Iterable[str]] | str) -> type:
    """The type of an option or argument that takes one of `values()`, e.g. `choices(lambda: FORMATS)`, or of
    the values a reference names, e.g. `choices("preland_app.campaign.export:FORMATS")`: `--help`
    shows them (png|pdf|svg) and any other value is refused before the command runs, in one line naming the
    option and the values (exit 2).

    typer 0.29 shows and checks choices only for an Enum or Literal annotation, both fixed when the module is
    imported. This Enum reads its values from `values()` whenever typer asks, so they come from where the code
    defines them (a constant, an enum, a registry) without importing that module before it is needed (the pad
    renderer's paper sizes would bring matplotlib into every `preland` command) and with what a registry holds
    then (an executor registered before the app runs is a choice). The command receives the value as a str."""

    if isinstance(values, str):
        values = _values_of(values)

    class Choices(enum.Enum, metaclass=_Choices):
        _values = staticmethod(lambda: tuple(str(value) for value in values()))

    return Choices


def _hint(param) -> str:
    """How the user names a parameter: its long option (--format), or an argument's metavar (KIND)."""
    if param.param_type_name == "option":
        return next((name for name in param.opts if name.startswith("--")), param.opts[0])
    return param.metavar or (param.name or "").upper()


def _allowed(param) -> list[str]:
    descriptor = getattr(param, "type_descriptor", None)
    if descriptor is None or not descriptor.is_choice:
        return []
    return [str(c.value) if isinstance(c, enum.Enum) else str(c) for c in descriptor.choices]


def usage_line(error) -> str:
    """A click usage error as one line: `--format: unknown format 'gif' (expected one of: png, pdf, svg)`,
    `missing argument DB; see 'preland campaign report --help'`."""
    param = getattr(error, "param", None)
    see = f"; see '{error.ctx.command_path} --help'" if error.ctx is not None else ""
    flat = " ".join(error.format_message().split()).rstrip(".")
    if isinstance(error, click_errors.MissingParameter) and param is not None:
        allowed = _allowed(param)
        return (f"missing {error.param_type or param.param_type_name} {_hint(param)}"
                + (f" (expected one of: {', '.join(allowed)})" if allowed else see))
    if isinstance(error, click_errors.BadParameter) and param is not None:
        message = error.message.removeprefix("Value error, ")  # pydantic's prefix on typer's checks
        allowed = _allowed(param)
        if allowed:
            value, known, _ = message.rpartition(" is not one of ")  # typer's wording: 'gif' is not one of ...
            noun = _hint(param).lstrip("-").replace("-", " ").lower()
            said = f"unknown {noun} {value}" if known else message.rstrip(".")
            return f"{_hint(param)}: {said} (expected one of: {', '.join(allowed)})"
        return f"{_hint(param)}: {message}"
    return flat + see


class PrelandGroup(TyperGroup):
    """The root command: a usage error (unknown option, missing argument, a value not among the choices) ends,
    as every other bad input does, in one line `preland: error: ...` and exit 2, not click's usage block and
    error box. CliRunner and the console entry point both come through here."""

    def main(self, *args, standalone_mode: bool = True, **kwargs):
        if not standalone_mode:
            return super().main(*args, standalone_mode=False, **kwargs)
        try:
            code = super().main(*args, standalone_mode=False, **kwargs)
        except click_errors.NoArgsIsHelpError as error:  # the help is printed already
            sys.exit(error.exit_code)
        except click_errors.UsageError as error:
            typer.echo(f"preland: error: {usage_line(error)}", err=True)
            sys.exit(error.exit_code)
        except click_errors.ClickException as error:
            typer.echo(f"preland: error: {' '.join(error.format_message().split())}", err=True)
            sys.exit(error.exit_code)
        except typer.Abort:  # end of input at a prompt
            from typer import rich_utils

            rich_utils.rich_abort_error()
            sys.exit(1)
        sys.exit(code if isinstance(code, int) else 0)


app = typer.Typer(
    name="preland",
    cls=PrelandGroup,
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

