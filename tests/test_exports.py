"""Exports round-trip: what CSV, JSON Lines and Parquet read back equals what the store holds."""

import csv
import io
import json

import pytest
from typer.testing import CliRunner

from preland_app.campaign.export import export, rows, schema
from preland_app.campaign.store import ResultsStore
from preland_app.cli import app

from .test_field_records import seeded_store
from .test_store_reading import add_events_and_path

JSON_COLUMNS = ("details", "audit", "data")


@pytest.fixture
def db(tmp_path):
    path = seeded_store(tmp_path / "r.db")
    add_events_and_path(path)
    runner = CliRunner()
    assert runner.invoke(app, ["trial", "record", str(path), "thesis_table3", "IRLock / none",
                               "--error-cm", "5", "--x-cm", "3", "--y-cm", "4", "--note",
                               "a, \"quoted\"\nnote"]).exit_code == 0
    assert runner.invoke(app, ["trial", "amend", str(path), "thesis_table3", "IRLock / none", "0",
                               "--landing-time-s", "19.5"]).exit_code == 0
    return path


def expected(store, table):
    """The store's rows as the export promises them: trials as `store.trials()` gives them (id as trial_id)."""
    if table == "trials":
        return [{"trial_id": t["id"], **{k: v for k, v in t.items() if k != "id"}} for t in store.trials()]
    return list(rows(store, table))


def typed_csv(text, columns):
    converters = {"INTEGER": int, "REAL": float, "TEXT": str}
    result = []
    for record in csv.DictReader(io.StringIO(text)):
        row = {}
        for name, kind in columns:
            cell = record[name]
            if name in JSON_COLUMNS:
                row[name] = json.loads(cell)
            else:
                row[name] = None if cell == "" and kind != "TEXT" else converters.get(kind, str)(cell)
        result.append(row)
    return result


def text_none_as_empty(row_list, columns):
    """CSV has no null: a missing text value reads back as an empty cell."""
    text = {name for name, kind in columns if kind == "TEXT" and name not in JSON_COLUMNS}
    return [{k: ("" if v is None and k in text else v) for k, v in row.items()} for row in row_list]


@pytest.mark.parametrize("table", ["trials", "events", "trajectories"])
def test_csv_and_json_lines_round_trip(db, table):
    with ResultsStore(db) as store:
        columns = schema(store, table)
        want = expected(store, table)
        assert want, "the fixture has rows in every table"
        csv_text = export(store, table=table, export_format="csv")
        jsonl_text = export(store, table=table, export_format="jsonl")
    assert typed_csv(csv_text, columns) == text_none_as_empty(want, columns)
    assert [json.loads(line) for line in jsonl_text.splitlines()] == want


@pytest.mark.parametrize("table", ["trials", "events", "trajectories"])
def test_parquet_round_trips_with_typed_columns(db, tmp_path, table):
    pq = pytest.importorskip("pyarrow.parquet", reason="the parquet extra (pyarrow) is not installed")
    out = tmp_path / f"{table}.parquet"
    result = CliRunner().invoke(app, ["campaign", "export", str(db), "--format", "parquet", "--table", table,
                                      "--out", str(out)])
    assert result.exit_code == 0, result.output
    read = pq.read_table(out)
    with ResultsStore(db) as store:
        columns = schema(store, table)
        want = expected(store, table)
    assert [(f.name, str(f.type)) for f in read.schema] == [
        (name, {"INTEGER": "int64", "REAL": "double", "TEXT": "string"}[kind]) for name, kind in columns]
    back = [{k: (json.loads(v) if k in JSON_COLUMNS else v) for k, v in row.items()} for row in read.to_pylist()]
    assert back == want


def test_export_cli_options(db, tmp_path):
    runner = CliRunner()
    result = runner.invoke(app, ["campaign", "export", str(db), "--format", "jsonl", "--table", "events",
                                 "--campaign", "thesis_table3"])
    assert result.exit_code == 0 and len(result.stdout.splitlines()) == 3
    assert json.loads(result.stdout.splitlines()[0])["kind"] == "armed"
    result = runner.invoke(app, ["campaign", "export", str(db), "--format", "xlsx"])
    assert result.exit_code == 2 and "--format" in result.stderr and "parquet" in result.stderr
    result = runner.invoke(app, ["campaign", "export", str(db), "--table", "wind"])
    assert result.exit_code == 2 and "--table" in result.stderr
    result = runner.invoke(app, ["campaign", "export", str(db), "--format", "parquet"])
    assert result.exit_code == 2 and "--out" in result.stderr
    out = tmp_path / "t.csv"
    result = runner.invoke(app, ["campaign", "export", str(db), "--out", str(out)])
    assert result.exit_code == 0 and out.read_text().startswith("trial_id,campaign,scenario")
