"""What the kind of a fault costs beside how much it takes: Table 3's drop scenarios flown with the thesis'
random drops, with burst drops of the same long-run share and with stale values in the same share, on the
same seeds.

The thesis drops each value on its own (random:P). A burst fault (burst:LOSS:LENGTH, Gilbert's two-state
channel) drops the same share in runs of LENGTH values on average, as a marker out of view for a few frames
would; a stale fault (stale:P) drops nothing but gives the last value again in place of a share P of the new
ones. Per fault: the landing error (mean, median, sd; cm), the mean landing time (s), the share of values
dropped and the share given again, the cost against the same scenario without a fault (difference of means,
cm) and a two-sided Mann-Whitney U test of the errors against the random fault's at the same share (p).

IR-LOCK (50 Hz) at random 0.75 against bursts of 5 and 25 readings (0.1 and 0.5 s); the marker (about
15 frames a second) at random 0.5 against bursts of 3 and 15 frames (0.2 and 1 s). Weather and take-off
heights as the thesis' Table 3 (near-calm air; 10 m for IR-LOCK, 6 m for the marker).

Usage: python benchmarks/fault_kinds.py [--seeds N] [--workers W]
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

from scipy.stats import mannwhitneyu  # noqa: E402

from preland_app.config.mission import load_mission  # noqa: E402
from preland_app.runtime.embedded import TrialRequest, run_trial  # noqa: E402

CALM = {"speed_m_s": 0.5, "turbulence_w20_m_s": 0.5}

# (scenario, land mode, sensor, fault or None, take-off m); the first fault of a scenario after "none" is the
# thesis' random one, which the bursts are tested against.
LEVELS = [
    ("T3 irlock", "irlock", "irlock", None, 10.0),
    ("T3 irlock", "irlock", "irlock", "random:0.75", 10.0),
    ("T3 irlock", "irlock", "irlock", "burst:0.75:5", 10.0),
    ("T3 irlock", "irlock", "irlock", "burst:0.75:25", 10.0),
    ("T3 irlock", "irlock", "irlock", "stale:0.75", 10.0),
    ("T3 marker", "marker", "marker", None, 6.0),
    ("T3 marker", "marker", "marker", "random:0.5", 6.0),
    ("T3 marker", "marker", "marker", "burst:0.5:3", 6.0),
    ("T3 marker", "marker", "marker", "burst:0.5:15", 6.0),
    ("T3 marker", "marker", "marker", "stale:0.5", 6.0),
]


def _one(job: tuple[int, int]) -> tuple[int, str, float | None, float | None, float, float]:
    """One trial: (level, outcome, landing error cm, landing time s, share of the sensor's values dropped,
    share given again)."""
    index, seed = job
    _, mode, sensor, fault, height = LEVELS[index]
    mission = load_mission(ROOT / "missions" / "thesis_square_land.yaml")
    environment = replace(mission.environment, wind=replace(mission.environment.wind, **CALM))
    mission = replace(mission, environment=environment)
    outcome = run_trial(TrialRequest(mission=mission, seed=seed, land_mode=mode,
                                     faults={sensor: fault} if fault else {}, takeoff_altitude_rel_m=height,
                                     record_trajectory=False))
    produced = outcome.details.get(f"{sensor}_produced", 0)
    dropped = outcome.details.get(f"{sensor}_dropped", 0)
    repeated = outcome.details.get(f"{sensor}_repeated", 0)
    return (index, outcome.outcome.value, outcome.landing_error_cm, outcome.landing_time_s,
            dropped / produced if produced else 0.0, repeated / produced if produced else 0.0)


def _init_worker() -> None:
    import cv2

    cv2.setNumThreads(1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    args = parser.parse_args()
    jobs = [(index, seed) for index in range(len(LEVELS)) for seed in range(1, args.seeds + 1)]
    started = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers, initializer=_init_worker) as pool:
        results = list(pool.map(_one, jobs, chunksize=1))
    print("\n".join(report_lines(results, args.seeds)))
    print(f"wall time {time.perf_counter() - started:.1f} s with {args.workers} worker(s), {len(jobs)} trials")


def report_lines(results: list[tuple], seeds: int) -> list[str]:
    """The printed table: one row a fault."""
    out = [f"fault kinds on the thesis' Table 3 drop scenarios, {seeds} seeds each (the same seeds in every row)",
           f"{'scenario':<10} {'fault':<14} {'landed':>6} {'mean':>6} {'median':>6} {'sd':>6} {'time s':>6} "
           f"{'dropped':>7} {'again':>6} {'cost':>6} {'p vs random':>11}"]
    errors: dict[int, list[float]] = {}
    for index, (scenario, _, _, fault, _) in enumerate(LEVELS):
        rows = [r for r in results if r[0] == index]
        errors[index] = [r[2] for r in rows if r[1] == "landed" and r[2] is not None]
        times = [r[3] for r in rows if r[1] == "landed" and r[3] is not None]
        base = next(i for i, level in enumerate(LEVELS) if level[0] == scenario and level[3] is None)
        random_level = next(i for i, level in enumerate(LEVELS)
                            if level[0] == scenario and (level[3] or "").startswith("random"))
        values = errors[index]
        mean = statistics.mean(values) if values else float("nan")
        cost = f"{mean - statistics.mean(errors[base]):>+6.1f}" if fault and errors[base] and values else f"{'':>6}"
        if fault and not fault.startswith("random") and values and errors[random_level]:
            p = f"{mannwhitneyu(values, errors[random_level], alternative='two-sided').pvalue:>11.3f}"
        else:
            p = f"{'':>11}"
        out.append(f"{scenario:<10} {fault or 'none':<14} {len(values):>3}/{len(rows):<2} {mean:>6.1f} "
                   f"{statistics.median(values) if values else float('nan'):>6.1f} "
                   f"{statistics.stdev(values) if len(values) > 1 else float('nan'):>6.1f} "
                   f"{statistics.mean(times) if times else float('nan'):>6.1f} "
                   f"{statistics.mean(r[4] for r in rows):>7.2f} {statistics.mean(r[5] for r in rows):>6.2f} "
                   f"{cost} {p}")
    return out


if __name__ == "__main__":
    main()
