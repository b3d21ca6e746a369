"""Simulated seconds per wall second per core, with the camera in the loop, from the trials' own flight
times (arming to disarming): the marker land mode and the paper mission on one worker (in this process,
pinned to one core), the thesis' Tables 3 to 5 on 2 worker processes, and `thesis_table3` on 1 against 2
workers. Beside each wall-clock figure, the same per CPU second (this process and its workers), which a
machine shared with other work does not inflate.

Usage: python benchmarks/loop_speed.py [--trials N] [--skip-campaigns] [--scaling-rounds R]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from preland_app.campaign.driver import run_campaign  # noqa: E402
from preland_app.campaign.spec import load_campaign  # noqa: E402
from preland_app.campaign.store import ResultsStore  # noqa: E402
from preland_app.config.mission import load_mission  # noqa: E402
from preland_app.runtime.embedded import TrialRequest, run_trial  # noqa: E402


def _cpu_s(*, children: bool = True) -> float:
    """CPU seconds of this process and (unless `children` is False) of its finished children."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    total = own.ru_utime + own.ru_stime
    if children:
        spawned = resource.getrusage(resource.RUSAGE_CHILDREN)
        total += spawned.ru_utime + spawned.ru_stime
    return total


def single(mission_file: str, land: str, trials: int) -> None:
    mission = load_mission(ROOT / "missions" / mission_file)
    run_trial(TrialRequest(mission=mission, seed=999, land_mode=land, record_trajectory=False))  # warm-up
    flown = 0.0
    # This process only: campaign workers reaped meanwhile must not count here.
    wall, cpu = time.perf_counter(), _cpu_s(children=False)
    for seed in range(trials):
        outcome = run_trial(TrialRequest(mission=mission, seed=seed, land_mode=land, record_trajectory=True))
        flown += outcome.flight_time_s or 0.0
    wall, cpu = time.perf_counter() - wall, _cpu_s(children=False) - cpu
    print(f"  {land:15s} {mission_file:24s} 1 worker : {flown / wall:6.1f}x per core (wall)   "
          f"{flown / cpu:6.1f}x per CPU s   ({trials} trials, {flown / trials:.1f} s flown, "
          f"{wall / trials:.2f} s wall each)")


def campaigns(files: list[str], workers: int) -> tuple[float, float, float]:
    """Runs each campaign into a fresh store; returns (flight s, wall s, CPU s) over all of them."""
    flown = wall = cpu = 0.0
    for name in files:
        campaign = load_campaign(ROOT / "campaigns" / name)
        with tempfile.TemporaryDirectory() as folder, ResultsStore(Path(folder) / "results.db") as store:
            started, cpu_started = time.perf_counter(), _cpu_s()
            run_campaign(campaign, store, workers=workers)
            wall += time.perf_counter() - started
            cpu += _cpu_s() - cpu_started
            flown += sum(t["flight_time_s"] or 0.0 for t in store.trials(campaign.name))
    return flown, wall, cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--trials", type=int, default=5)
    parser.add_argument("--skip-campaigns", action="store_true")
    parser.add_argument("--scaling-rounds", type=int, default=3, help="rounds of thesis_table3 on 1 then 2 workers")
    args = parser.parse_args()
    print(f"simulated s per wall s per core, and per CPU s ({os.cpu_count()} cores; load average "
          f"{os.getloadavg()[0]:.1f} at the start)")
    if not args.skip_campaigns:
        tables = ["thesis_table3.yaml", "thesis_table4.yaml", "thesis_table5.yaml"]
        flown, wall, cpu = campaigns(tables, workers=2)
        print(f"  thesis Tables 3 to 5, 2 workers            : {flown / wall / 2:6.1f}x per core (wall)   "
              f"{flown / cpu:6.1f}x per CPU s   ({wall:.1f} s wall, {flown:.0f} s flown)")
        # One round's ratio moves by a quarter from the next on a shared machine: rounds alternated, the median.
        ratios = []
        for _ in range(args.scaling_rounds):
            one = campaigns(["thesis_table3.yaml"], workers=1)
            two = campaigns(["thesis_table3.yaml"], workers=2)
            ratios.append(one[1] / two[1])
            print(f"  thesis_table3, 1 -> 2 workers              : {one[1]:.1f} s -> {two[1]:.1f} s wall, "
                  f"{ratios[-1]:.2f}x faster (CPU {one[2]:.1f} s -> {two[2]:.1f} s)", flush=True)
        print(f"  thesis_table3, 1 -> 2 workers, median of {len(ratios)} rounds: {statistics.median(ratios):.2f}x")
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    import cv2

    cv2.setNumThreads(1)  # one worker on one core, as a campaign's worker processes run OpenCV
    single("thesis_square_land.yaml", "marker", args.trials)
    single("paper_marker_land.yaml", "paper_adaptive", max(1, args.trials // 2))


if __name__ == "__main__":
    main()
