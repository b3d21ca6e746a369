"""Ray against local worker processes: the same 40-trial campaign on 2 CPUs, run side by side.

Each run is a fresh `preland campaign run` process, as a user runs it, timed from start to exit, into a
fresh store:

* local: `--executor local --workers N` (N worker processes on this machine);
* ray, joined: `--executor ray --ray-address ADDR`, joining a local Ray instance of N CPUs that this script
  started beforehand (a running cluster, the case the executor is for);
* ray, own instance: `--executor ray --workers N`, which starts a local Ray instance and stops it again.

Rounds alternate the three so that load from elsewhere on the machine falls on all of them. Prints each
run's wall time, the wall-time ratios against local (of the summed rounds, and of the fastest rounds, the
least disturbed by other work), the overhead per trial ((ray - local) / trials), the time per trial spent
outside trials (wall - time in trials / CPUs), and checks that every run stored the same rows.

`--campaign FILE` runs a campaign file instead (for example campaigns/thesis_table3.yaml, to check that
its rows are the same on both executors).

Usage: python benchmarks/executor_overhead.py [--workers 2] [--rounds 2] [--trials-per-scenario 10]
                                              [--campaign FILE]
"""

from __future__ import annotations

import argparse
import logging
import os
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
MISSION = ROOT / "missions" / "thesis_square_land.yaml"
SCENARIOS = """scenarios:
  - {label: normal, land: normal, initial_height_m: 10}
  - {label: irlock, land: irlock, initial_height_m: 10}
  - {label: irlock random, land: irlock, faults: {irlock: "random:0.75"}, initial_height_m: 10}
  - {label: marker, land: marker, initial_height_m: 6}
"""
ROW = "scenario, trial_index, seed, outcome, message, landing_error_cm, landing_time_s"


def run(command: list[str], env: dict[str, str]) -> float:
    started = time.perf_counter()
    result = subprocess.run(command, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    elapsed = time.perf_counter() - started
    if result.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed ({result.returncode}): {result.stderr.strip()[-400:]}")
    return elapsed


def rows(db: Path) -> tuple[list[tuple], float]:
    with sqlite3.connect(db) as connection:
        stored = connection.execute(f"SELECT {ROW} FROM trials ORDER BY scenario_index, trial_index").fetchall()
        busy_s = connection.execute("SELECT SUM(wall_time_s) FROM trials").fetchone()[0]
    return stored, busy_s


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--trials-per-scenario", type=int, default=10)
    parser.add_argument("--campaign", default=None, help="a campaign file (default: the 40-trial one above)")
    args = parser.parse_args()

    import ray

    folder = Path(tempfile.mkdtemp(prefix="preland-executors-"))
    if args.campaign:
        campaign = Path(args.campaign).resolve()
    else:
        campaign = folder / "overhead.yaml"
        campaign.write_text(f"name: overhead\nmission: {MISSION}\ntrials: {args.trials_per_scenario}\n"
                            "base_seed: 40\n" + SCENARIOS)
    from preland_app.campaign.spec import load_campaign, resolve_scenarios

    trials = sum(s.trials for s in resolve_scenarios(load_campaign(campaign)))
    started = time.perf_counter()
    ray.init(address="local", num_cpus=args.workers, include_dashboard=False, logging_level=logging.WARNING,
             log_to_driver=False)
    print(f"local Ray instance of {args.workers} CPUs started in {time.perf_counter() - started:.1f} s "
          f"(Ray {ray.__version__}, {os.cpu_count()} cores on this machine)")
    address = ray.get_runtime_context().gcs_address
    env = {key: value for key, value in os.environ.items() if key != "RAY_ADDRESS"}
    base = [sys.executable, "-m", "preland_app.cli", "campaign", "run", str(campaign), "--quiet"]
    variants = {
        "local": ["--executor", "local", "--workers", str(args.workers)],
        "ray, joined": ["--executor", "ray", "--ray-address", address],
        "ray, own instance": ["--executor", "ray", "--workers", str(args.workers)],
    }
    times: dict[str, list[float]] = {name: [] for name in variants}
    busy: dict[str, list[float]] = {name: [] for name in variants}
    reference = None
    try:
        for round_index in range(args.rounds):
            for name, extra in variants.items():
                db = folder / f"{name.replace(', ', '_').replace(' ', '_')}_{round_index}.db"
                elapsed = run([*base, "--db", str(db), *extra], env)
                stored, busy_s = rows(db)
                if len(stored) != trials:
                    raise SystemExit(f"{name}: {len(stored)} trials stored, expected {trials}")
                reference = reference or stored
                if stored != reference:
                    raise SystemExit(f"{name}: rows differ from the first run's")
                times[name].append(elapsed)
                busy[name].append(busy_s)
                print(f"round {round_index + 1}  {name:18s} {elapsed:6.1f} s wall  "
                      f"({busy_s:.1f} s of trials in workers)")
    finally:
        ray.shutdown()
        shutil.rmtree(folder, ignore_errors=True)
    local = sum(times["local"])
    print(f"\n{campaign.stem}: {trials} trials, {args.workers} CPUs, {args.rounds} round(s); all runs stored "
          "identical rows")
    print("ratio: wall time against local, summed over rounds (and of the fastest rounds); overhead per trial: "
          "(wall - local wall) / trials; outside trials: (wall - time in trials / CPUs) / trials")
    print(f"{'executor':18s} {'mean s':>7s} {'fastest s':>9s} {'ratio':>6s} {'(fastest)':>9s} "
          f"{'overhead/trial':>14s} {'outside trials/trial':>20s}")
    for name in variants:
        total = sum(times[name])
        overhead_ms = (total - local) / args.rounds / trials * 1000
        outside_ms = sum(t - b / args.workers for t, b in zip(times[name], busy[name])) / args.rounds / trials * 1000
        print(f"{name:18s} {total / args.rounds:7.1f} {min(times[name]):9.1f} {total / local:6.2f} "
              f"{min(times[name]) / min(times['local']):9.2f} {overhead_ms:11.0f} ms {outside_ms:17.0f} ms")

if __name__ == "__main__":
    main()
