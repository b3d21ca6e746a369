"""The thesis' field scenarios (Tables 3, 4 and 5) on the embedded simulator, N seeds each,
beside the published figures (mean / max landing error in cm, mean landing time in s).

Weather as the thesis reports it, and as campaigns/thesis_table*.yaml set it: Table 3 flights in
practically calm air (0.5 m/s, light turbulence), Tables 4 and 5 with regular gusts (3 m/s wind,
W20 = 5 m/s turbulence).

Usage: python benchmarks/fault_scenarios_table.py [--seeds N] [--workers W] [--only LABEL,...]
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

# label: (land mode, sensor, faults, take-off m, thesis mean cm, thesis max cm, thesis mean s or None)
SCENARIOS = {
    "T3 none": ("normal", None, {}, 10, 67.15, 180.0, None),
    "T3 irlock": ("irlock", None, {}, 10, 5.79, 13.86, None),
    "T3 irlock random0.75": ("irlock", None, {"irlock": "random:0.75"}, 10, 21.86, 70.0, None),
    "T3 irlock below3": ("irlock", None, {"irlock": "below:3"}, 10, 47.10, 66.3, None),
    "T3 marker": ("marker", None, {}, 6, 8.51, 11.6, None),
    "T3 marker random0.5": ("marker", None, {"marker": "random:0.5"}, 6, 11.05, 16.5, None),
    "T3 marker below3": ("marker", None, {"marker": "below:3"}, 6, 39.32, 62.9, None),
    "T4 fused": ("fused", None, {}, 10, 13.62, 24.6, None),
    "T4 fused ir<3 mk>3": ("fused", None, {"irlock": "below:3", "marker": "above:3"}, 10, 14.66, 20.6, None),
    "T4 fused ir>3 mk<3": ("fused", None, {"irlock": "above:3", "marker": "below:3"}, 6, 13.74, 20.4, None),
    "T4 fused random": ("fused", None, {"irlock": "random:0.75", "marker": "random:0.5"}, 10, 29.40, 46.1, None),
    "T5 default": ("marker", None, {"marker": "below:3:first-attempt"}, 6, 39.32, 62.9, 17.43),
    "T5 cautious": ("cautious", "marker", {"marker": "below:3:first-attempt"}, 6, 14.37, 24.1, 41.46),
}


CALM = {"speed_m_s": 0.5, "turbulence_w20_m_s": 0.5}
GUSTY = {"speed_m_s": 3.0, "turbulence_w20_m_s": 5.0}


def _one(job: tuple[str, int]) -> tuple[str, int, str, float | None, float | None, int]:
    label, seed = job
    mode, sensor, faults, height, *_ = SCENARIOS[label]
    mission = load_mission(ROOT / "missions" / "thesis_square_land.yaml")
    wind = CALM if label.startswith("T3") else GUSTY
    environment = replace(mission.environment, wind=replace(mission.environment.wind, **wind))
    mission = replace(mission, environment=environment)
    o = run_trial(TrialRequest(mission=mission, seed=seed, land_mode=mode, sensor=sensor, faults=faults,
                               takeoff_altitude_rel_m=float(height), record_trajectory=False))
    return label, seed, o.outcome.value, o.landing_error_cm, o.landing_time_s, int(o.details.get("attempts", 1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--only", default="", help="comma-separated labels")
    args = parser.parse_args()
    labels = [label for label in SCENARIOS if not args.only or label in args.only.split(",")]
    started = time.perf_counter()
    jobs = [(label, seed) for label in labels for seed in range(args.seeds)]
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        results = list(pool.map(_one, jobs, chunksize=1))
    print(f"thesis scenarios on the embedded simulator, {args.seeds} seeds each; T3 near-calm, T4/T5 gusty")
    print(f"{'scenario':<22} {'h':>3} {'landed':>6} {'mean cm':>8} {'max cm':>7} {'mean s':>7} {'attempts':>8}"
          f"   {'thesis cm':>9} {'max':>6} {'s':>6}")
    for label in labels:
        mode, sensor, faults, height, ref_mean, ref_max, ref_time = SCENARIOS[label]
        rows = [r for r in results if r[0] == label]
        errors = [r[3] for r in rows if r[3] is not None]
        times = [r[4] for r in rows if r[4] is not None]
        landed = sum(r[2] == "landed" for r in rows)
        attempts = statistics.mean(r[5] for r in rows)
        print(f"{label:<22} {height:>3} {landed:>3}/{len(rows):<2} {statistics.mean(errors):8.1f} {max(errors):7.1f} "
              f"{statistics.mean(times):7.1f} {attempts:8.2f}   {ref_mean:9.2f} {ref_max:6.1f} "
              f"{'' if ref_time is None else f'{ref_time:6.1f}'}")
    print(f"wall time {time.perf_counter() - started:.1f} s with {args.workers} worker(s)")


if __name__ == "__main__":
    main()
