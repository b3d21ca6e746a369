"""Additive schema changes to the results store, applied when a store opens.

A results.db written by an earlier version still opens: columns and tables are
only ever added (never renamed or dropped), with defaults that describe the rows
that existed before them.

* `trials.audit`: JSON list of the changes made to a trial after it was stored
  (`[{"at": UTC time, "action": "amended", "changes": {field: [old, new]},
  "reason": text}]`); `[]` for a trial never changed.
* `deleted_trials`: every deleted trial's row as JSON, with when and why, so a
  deletion loses nothing that was recorded.
* `field_log`: a field campaign's journal, appended to and never changed: where
  the campaign started, each flight as it starts, flights interrupted (the
  laptop killed mid-flight) or flown again (`redo`, with the redone flight's
  record as JSON), pauses and what ended them.
"""

from __future__ import annotations

import sqlite3

ADDED_COLUMNS = {
    "trials": (("audit", "TEXT NOT NULL DEFAULT '[]'"),),
}

ADDED_TABLES = """
CREATE TABLE IF NOT EXISTS deleted_trials (
    campaign TEXT NOT NULL,
    scenario TEXT NOT NULL,
    trial_index INTEGER NOT NULL,
    source TEXT NOT NULL,
    deleted_at TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%SZ', 'now')),
    reason TEXT NOT NULL DEFAULT '',
    row TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS field_log (
    id INTEGER PRIMARY KEY,
    campaign TEXT NOT NULL,
    kind TEXT NOT NULL,
    scenario TEXT,
    trial_index INTEGER,
    at TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%SZ', 'now')),
    data TEXT NOT NULL DEFAULT '{}'
);
CREATE INDEX IF NOT EXISTS field_log_by_campaign ON field_log (campaign, id);
"""


def migrate(db: sqlite3.Connection) -> None:
    """Bring an open store's schema up to this version's (idempotent)."""
    with db:
        for table, columns in ADDED_COLUMNS.items():
            present = {row[1] for row in db.execute(f"PRAGMA table_info({table})")}
            for name, declaration in columns:
                if name not in present:
                    db.execute(f"ALTER TABLE {table} ADD COLUMN {name} {declaration}")
        db.executescript(ADDED_TABLES)
