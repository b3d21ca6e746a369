"""Help texts (issue #29): what `--help` shows is what the user may type, and what they mistype is refused in
one line."""

from __future__ import annotations

import importlib
import re
import subprocess
import sys

import pytest
import typer
from rich.text import Text
from typer.testing import CliRunner

from preland_app.campaign import browse, compare, export
from preland_app.campaign.catalog import SOURCES
from preland_app.campaign.executors import executor_names, registry
from preland_app.cli import app
from preland_app.cli.app import DPI
from preland_app.cli.campaign_results import FIGURE_FORMATS
from preland_app.config import schema
from preland_app.landing.registry import PRECISION_SENSORS
from preland_app.outcome import Outcome
from preland_app.sensing.faults import FaultTarget
from preland_app.sensing.pad import DICTIONARIES, PAD_PRESETS

WIDE = {"COLUMNS": "200"}  # one help row per line, so that texts are not wrapped


def _help(*path: str) -> str:
    result = CliRunner().invoke(app, [*path, "--help"], env=WIDE)
    assert result.exit_code == 0, (path, result.output)
    return result.stdout


def _flat(text: str) -> str:
    """The help as one line of words, without the panels' borders."""
    return " ".join(re.sub(r"[│╭╮╰╯─]", " ", text).split())


def _option_rows(help_text: str, option: str) -> str:
    """The rows of one option in `--help`: its own and the wrapped ones below it."""
    lines = help_text.splitlines()
    start = next(i for i, line in enumerate(lines) if f" {option} " in line)
    rows = [lines[start]]
    for line in lines[start + 1:]:
        if line.lstrip("│").lstrip().startswith(("-", "*", "╰")):
            break
        rows.append(line)
    return "\n".join(rows)


def _tree():
    """(path, click command) of every command and group under `preland`, the root first."""
    def walk(command, path):
        yield path, command
        for name, sub in getattr(command, "commands", {}).items():
            yield from walk(sub, [*path, name])

    yield from walk(typer.main.get_command(app), [])


def _one_error_line(result) -> str:
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("preland: error: "), result.stderr
    assert "Usage:" not in result.output and "╭" not in result.output
    return lines[0].removeprefix("preland: error: ")


# 1. The extras' names.

def test_the_extras_names_print_in_help():
    assert "pip install 'preland[parquet]'" in _flat(_help("campaign", "export"))
    assert "pip install 'preland[browse]'" in _flat(_help("campaign", "browse"))


def test_a_missing_extra_names_it_in_its_one_line(tmp_path, monkeypatch):
    from preland_app.campaign.store import ResultsStore

    db = tmp_path / "r.db"
    ResultsStore(db).close()
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # `import pyarrow` now raises ImportError
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    result = CliRunner().invoke(app, ["campaign", "export", str(db), "--format", "parquet",
                                      "--out", str(tmp_path / "t.parquet")])
    assert "pip install 'preland[parquet]'" in _one_error_line(result)
    monkeypatch.setattr(browse, "datasette_available", lambda: False)
    result = CliRunner().invoke(app, ["campaign", "browse", str(db)])
    assert "pip install 'preland[browse]'" in _one_error_line(result)


def test_every_help_renders_and_keeps_its_brackets():
    commands, bracketed_seen = 0, set()
    for path, command in _tree():
        shown = _flat(_help(*path))
        texts = [command.help or ""] + [getattr(param, "help", None) or "" for param in command.params]
        for text in texts:
            plain = Text.from_markup(text).plain  # what Rich prints of it
            assert plain.count("[") == text.count("["), (path, text)  # no "[...]" read as markup
            for bracketed in re.findall(r"\S*\[[^\]\s]*\]\S*", " ".join(plain.split())):
                assert bracketed in shown, (path, bracketed)
                bracketed_seen.add(bracketed)
        commands += 1
    assert commands >= 25
    assert {"'preland[parquet]'.", "'preland[browse]'),"} <= bracketed_seen


# 2. Fixed choices.

CHOICES = [  # (command, option, the values where the code defines them, the other arguments it needs)
    (["campaign", "report"], "--format", FIGURE_FORMATS, ["r.db"]),
    (["campaign", "export"], "--format", export.FORMATS, ["r.db"]),
    (["campaign", "export"], "--table", export.TABLES, ["r.db"]),
    (["campaign", "compare"], "--measure", tuple(compare.MEASURES), ["a.db", "b.db"]),
    (["campaign", "run"], "--executor", tuple(executor_names()), ["c.yaml"]),
    (["trial", "show"], "--source", SOURCES, ["r.db", "c", "s", "0"]),
    (["trial", "record"], "--outcome", tuple(o.value for o in Outcome), ["r.db", "c", "s"]),
    (["trial", "amend"], "--outcome", tuple(o.value for o in Outcome), ["r.db", "c", "s", "0"]),
    (["pad", "render"], "--preset", tuple(PAD_PRESETS), ["--out", "pad.png"]),
    # Read when the test runs: the pad renderer imports matplotlib, which collection need not.
    (["pad", "render"], "--paper", lambda: tuple(importlib.import_module("preland_app.sensing.pad_render")
                                                 .PAPER_SIZES_M), ["--out", "pad.pdf", "--preset", "thesis"]),
    (["camera", "board"], "--dictionary", tuple(DICTIONARIES), ["--out", "board.png"]),
    (["camera", "calibrate"], "--dictionary", tuple(DICTIONARIES), ["--out", "camera.yaml"]),
    (["fault", "send"], "--target", tuple(t.name.lower() for t in FaultTarget), ["--connect", "udp://:14560"]),
    (["fly"], "--sensor", PRECISION_SENSORS, ["mission.yaml"]),
]


@pytest.mark.parametrize("command, option, values, others", CHOICES, ids=lambda v: " ".join(v) if
                         isinstance(v, list) else None)
def test_a_fixed_choice_shows_its_values_and_refuses_a_typo_in_one_line(tmp_path, command, option, values,
                                                                         others):
    values = values() if callable(values) else values
    rows = _option_rows(_help(*command), option)
    assert "TEXT" not in rows and all(re.search(rf"(^|[ |]){value}( |\||$)", rows, re.M) for value in values), rows
    if len("|".join(values)) <= 24:
        assert "|".join(values) in rows
    result = CliRunner().invoke(app, [*command, *[str(tmp_path / o) if "." in o and "/" not in o else o
                                                  for o in others], option, "typo"])
    noun = option.removeprefix("--")
    assert _one_error_line(result) == f"{option}: unknown {noun} 'typo' (expected one of: {', '.join(values)})"


def test_the_schema_kinds_are_the_schema_modules_own(monkeypatch):
    rows = _option_rows(_help("schema"), "KIND")
    assert all(kind in rows for kind in schema.SCHEMA_KINDS) and "TEXT" not in rows
    result = CliRunner().invoke(app, ["schema", "missions"])
    assert _one_error_line(result) == (f"KIND: unknown kind 'missions' (expected one of: "
                                       f"{', '.join(schema.SCHEMA_KINDS)})")
    monkeypatch.setattr(schema, "SCHEMA_KINDS", (*schema.SCHEMA_KINDS, "later"))  # one more kind: no other list
    assert " later " in _option_rows(_help("schema"), "KIND")


def test_an_executor_registered_before_the_app_runs_is_a_choice(monkeypatch, tmp_path):
    monkeypatch.setattr(registry, "_EXECUTORS", dict(registry._EXECUTORS))
    registry.register_executor("threads", lambda options: None)
    assert "local|ray|threads" in _option_rows(_help("campaign", "run"), "--executor")
    result = CliRunner().invoke(app, ["campaign", "run", str(tmp_path / "c.yaml"), "--executor", "dask"])
    assert _one_error_line(result).endswith("(expected one of: local, ray, threads)")


def test_a_missing_choice_names_its_values():
    result = CliRunner().invoke(app, ["fault", "send", "--connect", "udp://:14560"])
    assert _one_error_line(result) == "missing option --target (expected one of: irlock, marker, both)"


def test_usage_errors_are_one_line_too():
    runner = CliRunner()
    assert _one_error_line(runner.invoke(app, ["campaign", "report"])) == (
        "missing argument DB; see 'preland campaign report --help'")
    assert _one_error_line(runner.invoke(app, ["pad", "render", "--out", "x.png", "--colour"])).startswith(
        "No such option: --colour")
    assert _one_error_line(runner.invoke(app, ["flies"])).startswith("No such command 'flies'")
    assert _one_error_line(runner.invoke(app, ["trial", "show", "r.db", "c", "s", "first"])).startswith("INDEX: ")


def test_the_console_entry_point_prints_usage_errors_in_one_line():
    result = subprocess.run([sys.executable, "-m", "preland_app.cli", "schema", "missions"], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.splitlines() == [f"preland: error: KIND: unknown kind 'missions' (expected one of: "
                                          f"{', '.join(schema.SCHEMA_KINDS)})"]


# 3. Groups name their commands.

def test_every_group_names_its_commands_in_its_help():
    groups = [(path, command) for path, command in _tree() if path and hasattr(command, "commands")]
    assert {" ".join(path) for path, _ in groups} >= {"campaign", "trial", "pad", "camera", "sim", "fault"}
    for path, group in groups:
        words = set(re.findall(r"[a-z]+", group.help.lower()))
        missing = [name for name in group.commands if name not in words]
        assert not missing, (path, group.help, missing)


# 4. --dpi.

def test_every_dpi_option_defaults_to_the_one_constant():
    seen = {}
    for path, command in _tree():
        for param in command.params:
            if "--dpi" in getattr(param, "opts", ()):
                seen[" ".join(path)] = param.default
                assert f"[default: {param.default}]" in _option_rows(_help(*path), "--dpi")
    assert seen == {"campaign report": DPI, "trial show": DPI, "camera board": DPI, "pad render": DPI}
    assert DPI == 300


# 5. trial's arguments.

def test_every_trial_command_takes_the_trials_place_as_arguments():
    commands = {tuple(path): command for path, command in _tree()}
    for name in ("record", "show", "amend", "delete"):
        arguments = [p.metavar for p in commands[("trial", name)].params if p.param_type_name == "argument"]
        assert arguments[:3] == ["DB", "CAMPAIGN", "SCENARIO"], name
        assert arguments[3:] == ([] if name == "record" else ["INDEX"]), name
        options = {o for p in commands[("trial", name)].params for o in getattr(p, "opts", ())
                   if p.param_type_name == "option"}
        assert not options & {"--db", "--campaign", "--scenario"}, name


def test_trial_record_takes_db_campaign_scenario_and_refuses_the_old_options_in_one_line(tmp_path):
    db = tmp_path / "r.db"
    runner = CliRunner()
    result = runner.invoke(app, ["trial", "record", "--db", str(db), "--campaign", "day1", "--scenario", "hover",
                                 "--error-cm", "4", "--new"])
    line = _one_error_line(result)
    assert line.startswith("--db: ") and "preland trial record DB CAMPAIGN SCENARIO [OPTIONS]" in line
    assert not db.exists()
    result = runner.invoke(app, ["trial", "record", str(db), "day1", "hover", "--error-cm", "4", "--new"])
    assert result.exit_code == 0, result.output
    assert result.stdout.strip() == "recorded field trial 0 of day1 / hover: landed, 4 cm"
    result = runner.invoke(app, ["trial", "show", str(db), "day1", "hover", "0", "--source", "field"])
    assert result.exit_code == 0 and "landing error      4.00 cm" in result.stdout
    result = runner.invoke(app, ["trial", "record", str(db), "day2", "hover", "--error-cm", "4"])
    assert _one_error_line(result).startswith("CAMPAIGN: no campaign 'day2'")  # names the argument, not --campaign
