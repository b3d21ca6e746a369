"""Landing error and time per land mode over N seeds on the thesis mission (no faults, default wind),
beside the thesis' field figures (Tables 3 and 4).

Usage: python benchmarks/land_modes_table.py [--seeds N] [--workers W] [--modes normal,irlock,...]
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

THESIS = {  # mean cm, max cm, initial height m (Tables 3 and 4, no failures)
    "normal": (67.15, 180.0, 10),
    "irlock": (5.79, 13.86, 10),
    "marker": (8.51, 11.60, 6),
    "fused": (13.62, 24.60, 10),
}


def _one(args: tuple[str, int]) -> tuple[str, int, str, float | None, float | None]:
    mode, seed = args
    mission = load_mission(ROOT / "missions" / "thesis_square_land.yaml")
    o = run_trial(TrialRequest(mission=mission, seed=seed, land_mode=mode, record_trajectory=False))
    return mode, seed, o.outcome.value, o.landing_error_cm, o.landing_time_s


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--modes", default="normal,irlock,marker,fused")
    args = parser.parse_args()
    modes = args.modes.split(",")
    started = time.perf_counter()
    jobs = [(mode, seed) for mode in modes for seed in range(args.seeds)]
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        results = list(pool.map(_one, jobs))
    print(f"thesis mission, {args.seeds} seeds per mode, default wind; simulated vs thesis field trials")
    print(f"{'mode':<8} {'height':>6} {'landed':>7} {'mean cm':>8} {'max cm':>7} {'mean s':>7}   "
          f"{'thesis mean':>11} {'thesis max':>10}")
    for mode in modes:
        rows = [r for r in results if r[0] == mode]
        errors = [r[3] for r in rows if r[3] is not None]
        times = [r[4] for r in rows if r[4] is not None]
        landed = sum(r[2] == "landed" for r in rows)
        ref = THESIS.get(mode, (float("nan"), float("nan"), 0))
        print(f"{mode:<8} {ref[2]:>5}m {landed:>4}/{len(rows):<2} {statistics.mean(errors):8.1f} {max(errors):7.1f} "
              f"{statistics.mean(times):7.1f}   {ref[0]:11.2f} {ref[1]:10.2f}")
    print(f"wall time {time.perf_counter() - started:.1f} s with {args.workers} worker(s)")


if __name__ == "__main__":
    main()
