"""How the simulated precision landing degrades as random drops thin out the sensor values.

The thesis' field trials lost a lot to random drops (IR-LOCK random 0.75: 21.9 cm against 5.8 cm;
fused, IR-LOCK random 0.75 + marker random 0.5: 29.4 against 13.6 cm). This script sweeps the drop
probability and prints, for each level, the values per second that reach the autopilot and the
landing error over the same seeds, so the gap between the simulator and the field is a measured
figure: at which rate the simulated landing starts to suffer.

Sweeps: IR-LOCK alone in near-calm air (thesis Table 3 weather) and the fused sensor in gusts
(Table 4 weather), both sensors dropped at once.

Usage: python benchmarks/drop_rate_sensitivity.py [--seeds N] [--workers W]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from preland_app.config.mission import load_mission  # noqa: E402
from preland_app.runtime.embedded import TrialRequest, run_trial  # noqa: E402

CALM = {"speed_m_s": 0.5, "turbulence_w20_m_s": 0.5}
GUSTY = {"speed_m_s": 3.0, "turbulence_w20_m_s": 5.0}

# (sweep, land mode, faults, wind)
LEVELS = [
    ("irlock, calm", "irlock", {}, CALM),
    ("irlock, calm", "irlock", {"irlock": "random:0.75"}, CALM),
    ("irlock, calm", "irlock", {"irlock": "random:0.9"}, CALM),
    ("irlock, calm", "irlock", {"irlock": "random:0.95"}, CALM),
    ("irlock, calm", "irlock", {"irlock": "random:0.98"}, CALM),
    ("irlock, calm", "irlock", {"irlock": "random:0.99"}, CALM),
    ("fused, gusty", "fused", {}, GUSTY),
    ("fused, gusty", "fused", {"irlock": "random:0.75", "marker": "random:0.5"}, GUSTY),
    ("fused, gusty", "fused", {"irlock": "random:0.9", "marker": "random:0.8"}, GUSTY),
    ("fused, gusty", "fused", {"irlock": "random:0.95", "marker": "random:0.9"}, GUSTY),
    ("fused, gusty", "fused", {"irlock": "random:0.98", "marker": "random:0.95"}, GUSTY),
]


def _one(job: tuple[int, int]) -> tuple[int, float | None, float | None, float]:
    """One trial: (level index, landing error cm, landing time s, values/s sent during the landing)."""
    index, seed = job
    _, mode, faults, wind = LEVELS[index]
    mission = load_mission(ROOT / "missions" / "thesis_square_land.yaml")
    environment = replace(mission.environment, wind=replace(mission.environment.wind, **wind))
    mission = replace(mission, environment=environment)
    o = run_trial(TrialRequest(mission=mission, seed=seed, land_mode=mode, faults=faults,
                               takeoff_altitude_rel_m=10.0, record_trajectory=False))
    sent = float(o.details.get("landing_targets_sent", 0))
    rate = sent / o.landing_time_s if o.landing_time_s else 0.0
    return index, o.landing_error_cm, o.landing_time_s, rate


def _label(faults: dict[str, str]) -> str:
    return " + ".join(f"{sensor} {rule}" for sensor, rule in sorted(faults.items())) or "no faults"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    args = parser.parse_args()
    started = time.perf_counter()
    jobs = [(index, seed) for index in range(len(LEVELS)) for seed in range(args.seeds)]
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        results = list(pool.map(_one, jobs, chunksize=1))
    print(f"random drops against landing error, {args.seeds} seeds per level, same seeds at every level")
    print(f"{'sweep':<13} {'faults':<44} {'values/s':>8} {'mean cm':>8} {'max cm':>7} {'mean s':>7}")
    for index, (sweep, _, faults, _) in enumerate(LEVELS):
        rows = [r for r in results if r[0] == index]
        errors = [r[1] for r in rows if r[1] is not None]
        times = [r[2] for r in rows if r[2] is not None]
        rate = statistics.mean(r[3] for r in rows)
        print(f"{sweep:<13} {_label(faults):<44} {rate:8.1f} {statistics.mean(errors):8.1f} {max(errors):7.1f} "
              f"{statistics.mean(times):7.1f}")
    print(f"wall time {time.perf_counter() - started:.1f} s with {args.workers} worker(s)")


if __name__ == "__main__":
    main()
