"""The paper's mission (take off to 20 m, fly 14 m to the marker's GPS position, land) with GPS-only
landing, Algorithm 1 and Algorithm 2, N seeds each, beside the paper's figures.

Usage: python benchmarks/paper_table.py [--seeds N] [--workers W]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from preland_app.config.mission import load_mission  # noqa: E402
from preland_app.runtime.embedded import TrialRequest, run_trial  # noqa: E402

MODES = {  # mode: the paper's figures
    "normal": "GPS-only: mean 85 cm (51 to 144), 27 to 30 s",
    "paper_static": "Algorithm 1: mean 11 cm (3 to 18), mean 162 s, 3 of 10 stopped after the 30 s timeout",
    "paper_adaptive": "Algorithm 2: same accuracy as Algorithm 1, mean 55 s, landed on the marker every time",
}


def _one(job: tuple[str, int]) -> tuple:
    mode, seed = job
    mission = load_mission(ROOT / "missions" / "paper_marker_land.yaml")
    o = run_trial(TrialRequest(mission=mission, seed=seed, land_mode=mode, record_trajectory=False))
    return (mode, seed, o.outcome.value, o.landing_error_cm, o.landing_time_s, bool(o.details.get("aborted_to_gps")),
            o.details.get("marker_switches", 0), o.details.get("recovery_climbs", 0))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    args = parser.parse_args()
    started = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        results = list(pool.map(_one, [(m, s) for m in MODES for s in range(args.seeds)], chunksize=1))
    print(f"paper mission, {args.seeds} seeds per mode, default wind")
    print(f"{'mode':<15} {'landed':>7} {'aborted':>7} {'mean cm':>8} {'min':>6} {'max':>6} {'mean s':>7} "
          f"{'switches':>8} {'climbs':>6}")
    for mode, reference in MODES.items():
        rows = [r for r in results if r[0] == mode]
        errors = [r[3] for r in rows if r[3] is not None]
        times = [r[4] for r in rows if r[4] is not None]
        print(f"{mode:<15} {sum(r[2] == 'landed' for r in rows):>4}/{len(rows):<2} {sum(r[5] for r in rows):>7} "
              f"{statistics.mean(errors):8.1f} {min(errors):6.1f} {max(errors):6.1f} {statistics.mean(times):7.1f} "
              f"{statistics.mean(r[6] for r in rows):8.1f} {statistics.mean(r[7] for r in rows):6.1f}")
        print(f"{'':<15} paper: {reference}")
    print(f"wall time {time.perf_counter() - started:.1f} s with {args.workers} worker(s)")


if __name__ == "__main__":
    main()
