"""One driver per campaign and store: a lease row that a second driver sees, and that outlives no driver.

The driver that runs a campaign holds a row in `campaign_drivers` (campaign, source, its pid, host, the
process's start time, the executor, since when, a heartbeat). A second driver on the same campaign is
refused with one line naming the first. A lease is stale, and taken over, when its driver is gone: on the
same host, when no process with its pid and start time runs (a SIGKILLed driver: `--resume` then simply
works); from another host, when its heartbeat is older than STALE_AFTER_S.
"""

from __future__ import annotations

import os
import socket
import sqlite3
import time
import uuid
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path

from .store import ResultsStore, StoreError

STALE_AFTER_S = 120.0  # a lease from another host without a heartbeat for this long is taken over
HEARTBEAT_PERIOD_S = 5.0  # how often the driver refreshes its heartbeat (at most)

LEASE_SCHEMA = """
CREATE TABLE IF NOT EXISTS campaign_drivers (
    campaign TEXT NOT NULL,
    source TEXT NOT NULL,
    token TEXT NOT NULL,
    pid INTEGER NOT NULL,
    host TEXT NOT NULL,
    process_start TEXT NOT NULL,
    executor TEXT NOT NULL,
    started_at TEXT NOT NULL,
    heartbeat_unix_s REAL NOT NULL,
    PRIMARY KEY (campaign, source)
);
"""


class CampaignBusy(StoreError):
    """Another driver is running this campaign on this store."""


def _stat_fields(pid: int) -> list[str] | None:
    """/proc/PID/stat's fields after the command (field 3, the state, first), None where it cannot be read.
    Split after the command's closing parenthesis, which may itself hold spaces."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None


def process_start(pid: int) -> str:
    """When process `pid` started (clock ticks since boot, from /proc), or '' where that cannot be read.
    With the pid it tells a driver apart from a later process that got the same pid."""
    fields = _stat_fields(pid)
    return "" if not fields or fields[0] == "Z" else fields[19]


def parent_pid(pid: int) -> int | None:
    """The parent of process `pid` (from /proc), None where that cannot be read."""
    fields = _stat_fields(pid)
    return int(fields[1]) if fields else None


def _running(pid: int, started: str) -> bool:
    if Path("/proc").is_dir():
        now = process_start(pid)
        return bool(now) and (not started or now == started)
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class DriverLease:
    """The lease of one driver on (campaign, source) in a store. `acquire` refuses with CampaignBusy when a
    live driver holds it; `refresh` keeps it (and raises CampaignBusy if another driver took it over);
    `release` gives it up. `now_s` is the wall clock (seconds since the epoch), injectable for tests."""

    def __init__(self, store: ResultsStore, *, campaign: str, source: str, executor: str,
                 now_s: Callable[[], float] = time.time) -> None:
        self.store = store
        self.campaign = campaign
        self.source = source
        self.executor = executor
        self.now_s = now_s
        self.token = uuid.uuid4().hex
        self.pid = os.getpid()
        self.host = socket.gethostname()
        self._refreshed_s = -float("inf")

    def _describe(self, row: sqlite3.Row) -> str:
        age_s = self.now_s() - row["heartbeat_unix_s"]
        return (f"pid {row['pid']} on host {row['host']}, {row['executor']} executor, since {row['started_at']} "
                f"UTC, last heard {age_s:.0f} s ago")

    def _stale(self, row: sqlite3.Row) -> bool:
        if row["host"] == self.host:
            return not _running(row["pid"], row["process_start"])
        return self.now_s() - row["heartbeat_unix_s"] > STALE_AFTER_S

    def acquire(self) -> None:
        db = self.store.db
        try:
            db.executescript(LEASE_SCHEMA)
            db.execute("BEGIN IMMEDIATE")  # one driver at a time reads and takes the lease
            try:
                row = db.execute("SELECT * FROM campaign_drivers WHERE campaign = ? AND source = ?",
                                 (self.campaign, self.source)).fetchone()
                if row is not None and row["token"] != self.token and not self._stale(row):
                    raise CampaignBusy(f"campaign {self.campaign!r} in {self.store.path} is being run by another "
                                       f"driver ({self._describe(row)}); wait for it to finish, or stop it and "
                                       "run again with --resume")
                now = self.now_s()
                started = datetime.fromtimestamp(now, timezone.utc).strftime("%Y-%m-%d %H:%M:%S")
                db.execute("INSERT OR REPLACE INTO campaign_drivers (campaign, source, token, pid, host, "
                           "process_start, executor, started_at, heartbeat_unix_s) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                           (self.campaign, self.source, self.token, self.pid, self.host, process_start(self.pid),
                            self.executor, started, now))
            except BaseException:
                db.rollback()
                raise
            db.commit()
        except sqlite3.OperationalError as error:  # locked for longer than the connection's timeout
            raise StoreError(f"{self.store.path}: cannot take the campaign's lease ({error})") from None
        self._refreshed_s = self.now_s()

    def refresh(self, *, force: bool = False) -> None:
        now = self.now_s()
        if not force and now - self._refreshed_s < HEARTBEAT_PERIOD_S:
            return
        with self.store.db as db:
            updated = db.execute("UPDATE campaign_drivers SET heartbeat_unix_s = ? WHERE campaign = ? AND source = ? "
                                 "AND token = ?", (now, self.campaign, self.source, self.token)).rowcount
        if not updated:
            row = self.store.db.execute("SELECT * FROM campaign_drivers WHERE campaign = ? AND source = ?",
                                        (self.campaign, self.source)).fetchone()
            holder = f" by another driver ({self._describe(row)})" if row is not None else ""
            raise CampaignBusy(f"campaign {self.campaign!r} in {self.store.path}: this driver's lease was taken "
                               f"over{holder}; it stops")
        self._refreshed_s = now

    def release(self) -> None:
        try:
            with self.store.db as db:
                db.execute("DELETE FROM campaign_drivers WHERE campaign = ? AND source = ? AND token = ?",
                           (self.campaign, self.source, self.token))
        except sqlite3.Error:
            pass  # a lease left behind is stale once this process has ended
