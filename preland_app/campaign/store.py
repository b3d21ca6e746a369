"""The results store: one SQLite file, one row per finished trial, committed as each trial ends.

Tables:

* `campaigns`: name, the spec's hash and text, when it was first run;
* `trials`: one row per trial: campaign, scenario (label and index), trial
  index, seed, every outcome field, the scenario's spec hash, the software
  version, the runtime (embedded, sitl, field), the source (sim, sitl, field),
  the wall time it took; unique per (campaign, scenario, trial index, source),
  so a resumed campaign can never record a trial twice, and field trials
  recorded by hand sit beside simulated ones of the same scenario;
* `events`: the mission's event log per trial;
* `trajectories`: the trial's downsampled trajectory (JSON rows, see
  `outcome.TRAJECTORY_COLUMNS`).

WAL journaling and one transaction per trial mean a killed campaign loses only
the trials in flight.
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..version import __version__
from ..errors import PrelandError
from .migrations import migrate

SCHEMA = """
CREATE TABLE IF NOT EXISTS campaigns (
    name TEXT PRIMARY KEY,
    spec_hash TEXT NOT NULL,
    spec_text TEXT NOT NULL,
    source_path TEXT NOT NULL DEFAULT '',
    created_at TEXT NOT NULL DEFAULT (datetime('now'))
);
CREATE TABLE IF NOT EXISTS trials (
    id INTEGER PRIMARY KEY,
    campaign TEXT NOT NULL,
    scenario TEXT NOT NULL,
    scenario_index INTEGER NOT NULL,
    trial_index INTEGER NOT NULL,
    seed INTEGER NOT NULL,
    outcome TEXT NOT NULL,
    message TEXT NOT NULL,
    mission TEXT,
    land_mode TEXT,
    sensor TEXT,
    faults TEXT,
    takeoff_altitude_m REAL,
    scoring_reference TEXT,
    landing_error_cm REAL,
    offset_north_cm REAL,
    offset_east_cm REAL,
    landing_time_s REAL,
    flight_time_s REAL,
    touchdown_speed_m_s REAL,
    details TEXT NOT NULL DEFAULT '{}',
    spec_hash TEXT NOT NULL,
    software_version TEXT NOT NULL,
    runtime TEXT NOT NULL,
    source TEXT NOT NULL DEFAULT 'sim',
    wall_time_s REAL,
    finished_at TEXT NOT NULL DEFAULT (datetime('now')),
    UNIQUE (campaign, scenario, trial_index, source)
);
CREATE TABLE IF NOT EXISTS events (
    trial_id INTEGER NOT NULL REFERENCES trials(id) ON DELETE CASCADE,
    time_s REAL NOT NULL,
    kind TEXT NOT NULL,
    message TEXT NOT NULL,
    data TEXT NOT NULL DEFAULT '{}'
);
CREATE TABLE IF NOT EXISTS trajectories (
    trial_id INTEGER PRIMARY KEY REFERENCES trials(id) ON DELETE CASCADE,
    columns TEXT NOT NULL,
    rows TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS trials_by_campaign ON trials (campaign, scenario_index, trial_index);
CREATE INDEX IF NOT EXISTS events_by_trial ON events (trial_id);
"""

OUTCOME_COLUMNS = ("outcome", "message", "mission", "land_mode", "sensor", "faults", "takeoff_altitude_m",
                   "scoring_reference", "landing_error_cm", "offset_north_cm", "offset_east_cm", "landing_time_s",
                   "flight_time_s", "touchdown_speed_m_s")


class StoreError(PrelandError):
    """The results store cannot be used as asked."""


class DuplicateTrial(StoreError):
    """The store already holds this trial (campaign, scenario, trial index, source)."""


@dataclass(frozen=True, kw_only=True)
class TrialRecord:
    """Everything one trial stores. `result` holds the outcome fields (see OUTCOME_COLUMNS) and `details`."""

    campaign: str
    scenario: str
    scenario_index: int
    trial_index: int
    seed: int
    result: dict[str, Any]
    spec_hash: str
    runtime: str = "embedded"
    source: str = "sim"
    wall_time_s: float | None = None
    events: tuple[dict[str, Any], ...] = ()
    trajectory_columns: tuple[str, ...] = ()
    trajectory_rows: tuple[tuple[float, ...], ...] = ()


class ResultsStore:
    """A SQLite results store. Use `ResultsStore(":memory:")` in tests."""

    def __init__(self, path: str | Path) -> None:
        self.path = str(path)
        try:
            self.db = sqlite3.connect(self.path)
            self.db.row_factory = sqlite3.Row
            self.db.execute("PRAGMA foreign_keys = ON")
            if self.path != ":memory:":
                self.db.execute("PRAGMA journal_mode = WAL")
                self.db.execute("PRAGMA synchronous = NORMAL")
            self.db.executescript(SCHEMA)
            migrate(self.db)
        except sqlite3.DatabaseError as error:
            raise StoreError(f"{self.path}: not a usable results database ({error})") from None

    def close(self) -> None:
        self.db.close()

    def __enter__(self) -> "ResultsStore":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        with self.db:  # commits, or rolls back on an exception
            yield self.db

    # ---------------------------------------------------------------- campaigns

    def register_campaign(self, *, name: str, spec_hash: str, spec_text: str, source_path: str = "") -> None:
        with self._transaction() as db:
            db.execute("INSERT OR IGNORE INTO campaigns (name, spec_hash, spec_text, source_path) VALUES (?, ?, ?, ?)",
                       (name, spec_hash, spec_text, source_path))
            db.execute("UPDATE campaigns SET spec_hash = ?, spec_text = ?, source_path = ? WHERE name = ?",
                       (spec_hash, spec_text, source_path, name))

    def campaigns(self) -> list[str]:
        return [row["name"] for row in self.db.execute(
            "SELECT name FROM campaigns UNION SELECT DISTINCT campaign FROM trials ORDER BY 1")]

    def campaign_text(self, name: str) -> tuple[str, str] | None:
        """The campaign file's text and path as they were when it ran, or None."""
        row = self.db.execute("SELECT spec_text, source_path FROM campaigns WHERE name = ?", (name,)).fetchone()
        return (row["spec_text"], row["source_path"]) if row else None

    # ---------------------------------------------------------------- trials

    def add_trial(self, record: TrialRecord) -> int:
        """Store one finished trial with its events and trajectory, in one transaction."""
        result = record.result
        values = [result.get(column) for column in OUTCOME_COLUMNS]
        try:
            return self._insert_trial(record, values)
        except sqlite3.IntegrityError as error:
            if "UNIQUE" not in str(error):
                raise
            raise DuplicateTrial(f"campaign {record.campaign!r}, scenario {record.scenario!r}, trial "
                                 f"{record.trial_index} ({record.source}) is already in {self.path}") from None

    def _insert_trial(self, record: TrialRecord, values: list[Any]) -> int:
        result = record.result
        with self._transaction() as db:
            cursor = db.execute(
                f"""INSERT INTO trials (campaign, scenario, scenario_index, trial_index, seed,
                    {", ".join(OUTCOME_COLUMNS)}, details, spec_hash, software_version, runtime, source, wall_time_s)
                    VALUES ({", ".join("?" * (5 + len(OUTCOME_COLUMNS) + 6))})""",
                (record.campaign, record.scenario, record.scenario_index, record.trial_index, record.seed, *values,
                 json.dumps(result.get("details", {}), sort_keys=True, default=str), record.spec_hash, __version__,
                 record.runtime, record.source, record.wall_time_s),
            )
            trial_id = int(cursor.lastrowid)
            db.executemany(
                "INSERT INTO events (trial_id, time_s, kind, message, data) VALUES (?, ?, ?, ?, ?)",
                [(trial_id, e["time_s"], e["kind"], e["message"],
                  json.dumps({k: v for k, v in e.items() if k not in ("time_s", "kind", "message")}, default=str))
                 for e in record.events],
            )
            if record.trajectory_rows:
                db.execute("INSERT INTO trajectories (trial_id, columns, rows) VALUES (?, ?, ?)",
                           (trial_id, json.dumps(record.trajectory_columns), json.dumps(record.trajectory_rows)))
        return trial_id

    def done_keys(self, campaign: str, source: str = "sim") -> set[tuple[str, int]]:
        """(scenario, trial_index) of every stored trial of a campaign from one source."""
        return {(row["scenario"], row["trial_index"]) for row in self.db.execute(
            "SELECT scenario, trial_index FROM trials WHERE campaign = ? AND source = ?", (campaign, source))}

    def next_trial_index(self, campaign: str, scenario: str, source: str) -> int:
        row = self.db.execute("SELECT MAX(trial_index) AS m FROM trials WHERE campaign = ? AND scenario = ? "
                              "AND source = ?", (campaign, scenario, source)).fetchone()
        return 0 if row["m"] is None else int(row["m"]) + 1

    def scenario_index(self, campaign: str, scenario: str) -> int:
        row = self.db.execute("SELECT MIN(scenario_index) AS i FROM trials WHERE campaign = ? AND scenario = ?",
                              (campaign, scenario)).fetchone()
        if row["i"] is not None:
            return int(row["i"])
        row = self.db.execute("SELECT MAX(scenario_index) AS m FROM trials WHERE campaign = ?", (campaign,)).fetchone()
        return 0 if row["m"] is None else int(row["m"]) + 1

    def trial_hashes(self, campaign: str, source: str = "sim") -> dict[str, set[str]]:
        hashes: dict[str, set[str]] = {}
        for row in self.db.execute("SELECT scenario, spec_hash FROM trials WHERE campaign = ? AND source = ?",
                                   (campaign, source)):
            hashes.setdefault(row["scenario"], set()).add(row["spec_hash"])
        return hashes

    def trials(self, campaign: str | None = None) -> list[dict[str, Any]]:
        query = "SELECT * FROM trials"
        args: tuple = ()
        if campaign is not None:
            query += " WHERE campaign = ?"
            args = (campaign,)
        rows = []
        for row in self.db.execute(query + " ORDER BY campaign, scenario_index, source DESC, trial_index", args):
            data = dict(row)
            data["details"] = json.loads(data["details"] or "{}")
            data["audit"] = json.loads(data.get("audit") or "[]")
            rows.append(data)
        return rows

    # ---------------------------------------------------------------- field campaigns

    def log_field(self, campaign: str, kind: str, *, scenario: str | None = None, trial_index: int | None = None,
                  data: dict[str, Any] | None = None) -> None:
        """Append one entry to a field campaign's journal (`field_log`), committed at once."""
        with self._transaction() as db:
            db.execute("INSERT INTO field_log (campaign, kind, scenario, trial_index, data) VALUES (?, ?, ?, ?, ?)",
                       (campaign, kind, scenario, trial_index, json.dumps(data or {}, sort_keys=True, default=str)))

    def field_log(self, campaign: str) -> list[dict[str, Any]]:
        """A field campaign's journal, oldest first: kind, scenario, trial_index, at (UTC), data."""
        return [{**dict(row), "data": json.loads(row["data"])} for row in self.db.execute(
            "SELECT kind, scenario, trial_index, at, data FROM field_log WHERE campaign = ? ORDER BY id",
            (campaign,))]

    def events(self, trial_id: int) -> list[dict[str, Any]]:
        return [{**dict(row), "data": json.loads(row["data"])} for row in self.db.execute(
            "SELECT time_s, kind, message, data FROM events WHERE trial_id = ? ORDER BY rowid", (trial_id,))]

    def trajectory(self, trial_id: int) -> tuple[list[str], list[list[float]]] | None:
        row = self.db.execute("SELECT columns, rows FROM trajectories WHERE trial_id = ?", (trial_id,)).fetchone()
        if row is None:
            return None
        return json.loads(row["columns"]), json.loads(row["rows"])
