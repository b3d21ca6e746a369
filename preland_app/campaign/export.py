"""Exports of the results store, for pandas, R and polars: trials, events and trajectories.

Formats: CSV (an empty cell is no value), JSON Lines (one object per line;
`details`, `audit` and `data` as nested objects) and Parquet (typed columns,
through the optional `pyarrow`: `pip install 'preland[parquet]'`). Tables:

* `trials`: one row per trial, `trial_id` first, then every trials column;
* `events`: one row per event: `trial_id`, the trial's campaign, scenario,
  trial index and source, `time_s`, `kind`, `message`, `data`;
* `trajectories`: one row per stored sample (2 Hz): `trial_id`, campaign,
  scenario, trial index, source, then the trajectory columns (`time_s`,
  `est_north_m`, ..., see `outcome.TRAJECTORY_COLUMNS`).

`trial_id` joins the three. In CSV and Parquet, `details`, `audit` and `data`
are JSON text.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..errors import PrelandError
from .store import ResultsStore

FORMATS = ("csv", "jsonl", "parquet")
TABLES = ("trials", "events", "trajectories")
JSON_COLUMNS = ("details", "audit", "data")
KEY_COLUMNS = (("trial_id", "INTEGER"), ("campaign", "TEXT"), ("scenario", "TEXT"), ("trial_index", "INTEGER"),
               ("source", "TEXT"))

class ExportError(PrelandError):
    """An export cannot be written as asked."""


def _declared(store: ResultsStore, table: str) -> list[tuple[str, str]]:
    return [(row[1], (row[2] or "TEXT").upper()) for row in store.db.execute(f"PRAGMA table_info({table})")]


def schema(store: ResultsStore, table: str) -> list[tuple[str, str]]:
    """The exported table's columns with their SQLite types (INTEGER, REAL, TEXT)."""
    if table == "trials":
        return [("trial_id", "INTEGER")] + [c for c in _declared(store, "trials") if c[0] != "id"]
    if table == "events":
        return list(KEY_COLUMNS) + [c for c in _declared(store, "events") if c[0] != "trial_id"]
    if table == "trajectories":
        columns: list[str] = []
        for row in store.db.execute("SELECT DISTINCT columns FROM trajectories"):
            columns += [c for c in json.loads(row["columns"]) if c not in columns]
        return list(KEY_COLUMNS) + [(c, "REAL") for c in columns]
    raise ExportError(f"--table: unknown table {table!r} (expected one of: {', '.join(TABLES)})")


def rows(store: ResultsStore, table: str, campaign: str | None = None) -> Iterator[dict[str, Any]]:
    """The table's rows as dicts (JSON columns parsed), in the store's trial order."""
    trials = store.trials(campaign)
    if table == "trials":
        for trial in trials:
            yield {"trial_id": trial["id"], **{k: v for k, v in trial.items() if k != "id"}}
        return
    for trial in trials:
        key = {"trial_id": trial["id"], "campaign": trial["campaign"], "scenario": trial["scenario"],
               "trial_index": trial["trial_index"], "source": trial["source"]}
        if table == "events":
            for event in store.events(trial["id"]):
                yield {**key, **event}
        elif table == "trajectories":
            stored = store.trajectory(trial["id"])
            if stored is not None:
                columns, samples = stored
                for sample in samples:
                    yield {**key, **dict(zip(columns, sample))}
        else:
            raise ExportError(f"--table: unknown table {table!r} (expected one of: {', '.join(TABLES)})")


def _flat(value: Any, column: str) -> Any:
    return json.dumps(value, sort_keys=True) if column in JSON_COLUMNS else value


def to_csv(store: ResultsStore, table: str = "trials", campaign: str | None = None) -> str:
    columns = [name for name, _ in schema(store, table)]
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows(store, table, campaign):
        writer.writerow(["" if row.get(c) is None else _flat(row.get(c), c) for c in columns])
    return buffer.getvalue()


def to_jsonl(store: ResultsStore, table: str = "trials", campaign: str | None = None) -> str:
    columns = [name for name, _ in schema(store, table)]
    return "".join(json.dumps({c: row.get(c) for c in columns}, default=str) + "\n"
                   for row in rows(store, table, campaign))


def write_parquet(store: ResultsStore, path: Path, table: str = "trials", campaign: str | None = None) -> int:
    """Write the table as Parquet with typed columns; returns the rows written."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise ExportError("--format parquet needs pyarrow: pip install 'preland[parquet]'") from None
    types = {"INTEGER": pa.int64(), "REAL": pa.float64(), "TEXT": pa.string()}
    declared = schema(store, table)
    arrow_schema = pa.schema([(name, types.get(kind, pa.string())) for name, kind in declared])
    data: dict[str, list[Any]] = {name: [] for name, _ in declared}
    for row in rows(store, table, campaign):
        for name, _ in declared:
            value = row.get(name)
            data[name].append(None if value is None else _flat(value, name))
    pq.write_table(pa.table(data, schema=arrow_schema), path)
    return len(data[declared[0][0]]) if declared else 0


def export(store: ResultsStore, *, table: str = "trials", export_format: str = "csv", campaign: str | None = None,
           out: Path | None = None) -> str | None:
    """Export a table: the text (CSV, JSON Lines) when `out` is None, else write `out` and return None."""
    if export_format not in FORMATS:
        raise ExportError(f"--format: unknown format {export_format!r} (expected one of: {', '.join(FORMATS)})")
    if table not in TABLES:
        raise ExportError(f"--table: unknown table {table!r} (expected one of: {', '.join(TABLES)})")
    if export_format == "parquet":
        if out is None:
            raise ExportError("--format parquet: give --out FILE (Parquet is binary)")
        write_parquet(store, out, table, campaign)
        return None
    text = to_csv(store, table, campaign) if export_format == "csv" else to_jsonl(store, table, campaign)
    if out is None:
        return text
    out.write_text(text, encoding="utf-8")
    return None


def export_csv(store: ResultsStore, campaign: str | None = None) -> str:
    """Every stored trial (of one campaign, or all) as CSV, one row per trial (the `trials` table)."""
    return to_csv(store, "trials", campaign)
