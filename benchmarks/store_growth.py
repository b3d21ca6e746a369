"""How fast the results store grows: bytes per 1,000 trials, with every trial's event log and trajectory
(at 2 Hz) and with `--outcomes-only`, on the same campaign (default: campaigns/thesis_table3.yaml, 70
trials), each into a fresh store. Prints the per-table share (SQLite's dbstat) and the file size, and
what the driver's commit of one trial costs (1,000 copies of a stored trial, each in its own transaction,
into a fresh file store: the ceiling on trials per second one driver can store).

Usage: python benchmarks/store_growth.py [--campaign FILE] [--workers N]
"""

from __future__ import annotations

import argparse
import os
import sqlite3
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from preland_app.campaign.driver import run_campaign  # noqa: E402
from preland_app.campaign.spec import load_campaign  # noqa: E402
from preland_app.campaign.store import ResultsStore, TrialRecord  # noqa: E402


def table_bytes(db: Path) -> dict[str, int]:
    with sqlite3.connect(db) as connection:
        connection.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        try:
            rows = connection.execute("SELECT name, SUM(pgsize) FROM dbstat GROUP BY name").fetchall()
        except sqlite3.OperationalError:  # SQLite built without dbstat
            rows = []
    groups = {"trials": 0, "events": 0, "trajectories": 0, "other": 0}
    for name, size in rows:
        key = next((g for g in ("trials", "events", "trajectories") if name.startswith(g)), "other")
        groups[key] += size
    return groups


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--campaign", default=str(ROOT / "campaigns" / "thesis_table3.yaml"))
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    args = parser.parse_args()
    campaign = load_campaign(args.campaign)
    with tempfile.TemporaryDirectory() as folder:
        empty = Path(folder) / "empty.db"
        with ResultsStore(empty) as store:  # the schema and the campaign's row, before any trial
            store.register_campaign(name=campaign.name, spec_hash="", spec_text=Path(args.campaign).read_text())
        table_bytes(empty)
        base = empty.stat().st_size
        for label, outcomes_only in (("with events and trajectories", False), ("--outcomes-only", True)):
            db = Path(folder) / f"{outcomes_only}.db"
            with ResultsStore(db) as store:
                ran, _ = run_campaign(campaign, store, workers=args.workers, outcomes_only=outcomes_only)
            groups = table_bytes(db)
            size = db.stat().st_size
            per_1000 = (size - base) / ran * 1000
            shares = ", ".join(f"{name} {value / ran * 1000 / 1e6:.2f} MB" for name, value in groups.items()
                               if value and name != "other")
            print(f"{campaign.name}, {ran} trials, {label}: {size / 1e6:.2f} MB file ({base / 1e3:.0f} kB of it "
                  f"before the first trial); {per_1000 / 1e6:.2f} MB per 1,000 trials (tables: {shares})")
            if not outcomes_only:
                commit_ms = commit_cost_ms(db, Path(folder) / "commits.db")
                print(f"one trial's commit (with its events and trajectory): {commit_ms:.2f} ms "
                      f"({1000 / commit_ms:.0f} trials/s for one driver)")


def commit_cost_ms(source: Path, target: Path, copies: int = 1000) -> float:
    import time

    with ResultsStore(source) as store:
        trial = store.trials()[0]
        events = [{"time_s": e["time_s"], "kind": e["kind"], "message": e["message"], **e["data"]}
                  for e in store.events(trial["id"])]
        columns, rows = store.trajectory(trial["id"])
    result = {key: trial[key] for key in trial if key not in ("id", "campaign", "scenario", "trial_index")}
    with ResultsStore(target) as store:
        started = time.perf_counter()
        for index in range(copies):
            store.add_trial(TrialRecord(campaign="commits", scenario="s", scenario_index=0, trial_index=index,
                                        seed=trial["seed"], result=result, spec_hash=trial["spec_hash"],
                                        events=tuple(events), trajectory_columns=tuple(columns),
                                        trajectory_rows=tuple(tuple(r) for r in rows)))
        return (time.perf_counter() - started) / copies * 1000


if __name__ == "__main__":
    main()
