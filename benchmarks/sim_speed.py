"""Real-time factor of the embedded simulator on the thesis mission (simulated s per wall s, one core).

Usage: python benchmarks/sim_speed.py [--trials N]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from preland_app.clock import LoopClock, run_virtual  # noqa: E402
from preland_app.config.mission import load_mission  # noqa: E402
from preland_app.runtime.embedded import TrialRequest, fly_embedded  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--trials", type=int, default=20)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core, as the target says
    mission = load_mission(ROOT / "missions" / "thesis_square_land.yaml")

    async def timed(seed: int) -> tuple[float, float]:
        clock = LoopClock()
        started = time.perf_counter()
        await fly_embedded(TrialRequest(mission=mission, seed=seed, record_trajectory=False))
        return clock.now_s(), time.perf_counter() - started

    run_virtual(timed(999))  # warm-up: imports and caches
    simulated, wall = [], []
    for seed in range(args.trials):
        sim_s, wall_s = run_virtual(timed(seed))
        simulated.append(sim_s)
        wall.append(wall_s)
    factors = [s / w for s, w in zip(simulated, wall)]
    print(f"embedded simulator, thesis mission (normal land), {args.trials} trials, one core")
    print(f"  simulated time per trial : {statistics.mean(simulated):7.1f} s")
    print(f"  wall time per trial      : {statistics.mean(wall) * 1000:7.1f} ms")
    print(f"  real-time factor         : {sum(simulated) / sum(wall):7.0f}x  "
          f"(per trial: min {min(factors):.0f}x, median {statistics.median(factors):.0f}x)")


if __name__ == "__main__":
    main()
