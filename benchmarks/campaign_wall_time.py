"""Wall time of a whole campaign on the embedded simulator (default: campaigns/thesis_table3.yaml,
70 trials) with N worker processes, into a fresh results database.

With --scaling, the campaign runs on 1 worker and then on N, and beside it the machine's own ceiling is
measured in the same round: the same pure-Python loop alone, then N copies at once. `--rounds` repeats
that, alternated, and prints the median of the rounds' ratios: on a shared virtual machine one round's
ratio moves by a quarter from the next. On a virtual machine
whose cores share a physical core or a host, N busy cores are slower each than one, and no campaign can
scale past that. The campaign's per-trial wall times (from the store) show where the time went: the sum
over trials against the makespan.

Usage: python benchmarks/campaign_wall_time.py [--campaign FILE] [--workers N] [--scaling [--rounds R]]
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
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


def _run(campaign, workers: int) -> tuple[float, list[float], list[str]]:
    with tempfile.TemporaryDirectory() as folder:
        with ResultsStore(Path(folder) / "results.db") as store:
            started = time.perf_counter()
            run_campaign(campaign, store, workers=workers)
            elapsed = time.perf_counter() - started
            rows = store.trials(campaign.name)
    return elapsed, [r["wall_time_s"] for r in rows], [r["outcome"] for r in rows]


def _spin() -> float:
    started = time.perf_counter()
    total = 0
    for i in range(20_000_000):
        total += i
    return time.perf_counter() - started


def _spin_after(barrier, results) -> None:
    barrier.wait()
    results.put(_spin())


def _machine_ceiling(workers: int) -> float:
    """How much faster N copies of a pure-Python loop, started together, finish than N run one after
    another."""
    alone = _spin()
    context = multiprocessing.get_context("spawn")
    barrier, results = context.Barrier(workers), context.Queue()
    processes = [context.Process(target=_spin_after, args=(barrier, results)) for _ in range(workers)]
    for process in processes:
        process.start()
    together = max(results.get() for _ in processes)
    for process in processes:
        process.join()
    return workers * alone / together


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--campaign", default=str(ROOT / "campaigns" / "thesis_table3.yaml"))
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--scaling", action="store_true", help="1 worker against --workers, and the machine's ceiling")
    parser.add_argument("--rounds", type=int, default=3, help="with --scaling: rounds, alternated")
    args = parser.parse_args()
    campaign = load_campaign(args.campaign)
    runs = [1, args.workers] if args.scaling else [args.workers]
    ratios, ceilings = [], []
    for round_number in range(args.rounds if args.scaling else 1):
        walls = {}
        for workers in runs:
            elapsed, trial_walls, outcomes = _run(campaign, workers)
            walls[workers] = elapsed
            print(f"campaign {campaign.name}: {len(outcomes)} trials with {workers} worker(s) on {os.cpu_count()} "
                  f"core(s): {elapsed:.1f} s wall ({elapsed / max(1, len(outcomes)):.2f} s per trial); "
                  f"{outcomes.count('landed')} landed, {len(outcomes) - outcomes.count('landed')} other; "
                  f"trials' own wall times sum to {sum(trial_walls):.1f} s ({sum(trial_walls) / workers:.1f} s per "
                  "worker)", flush=True)
        if args.scaling:
            ratios.append(walls[1] / walls[args.workers])
            ceilings.append(_machine_ceiling(args.workers))
            print(f"round {round_number + 1}: 1 -> {args.workers} workers {ratios[-1]:.2f}x faster; this machine's "
                  f"ceiling (a pure-Python loop, {args.workers} copies at once against one) {ceilings[-1]:.2f}x",
                  flush=True)
    if args.scaling:
        print(f"1 -> {args.workers} workers, median of {len(ratios)} rounds: {statistics.median(ratios):.2f}x "
              f"(rounds {', '.join(f'{r:.2f}' for r in ratios)}); machine's ceiling, median "
              f"{statistics.median(ceilings):.2f}x (rounds {', '.join(f'{c:.2f}' for c in ceilings)})")


if __name__ == "__main__":
    main()
