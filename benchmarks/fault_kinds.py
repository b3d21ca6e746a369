"""What the kind of a fault costs beside how much it takes: Table 3's drop scenarios flown with the thesis'
random drops, with burst drops of the same long-run share, with stale values in the same share, with new
values given old times, with every value delivered late, with false detections among the true ones, and with
the random drops combined with the sensor's own latency, on the same seeds.

The thesis drops each value on its own (random:P). A burst fault (burst:LOSS:LENGTH, Gilbert's two-state
channel) drops the same share in runs of LENGTH values on average, as a marker out of view for a few frames
would; a stale fault (stale:P) drops nothing but gives the last value again in place of a share P of the new
ones. A delay fault (delay:MS[:JITTER]) drops nothing but delivers each value MS ms late, with ArduPilot's
default PLND_LAG of 20 ms and, in the rows marked so, with PLND_LAG set to the delay, as ArduPilot's
precision-landing docs ask of a sensor with a known lag. A false fault (false:P:OFFSET) drops nothing but
points a share P of the values at a spot OFFSET metres off the target; a stalestamp fault (stalestamp:P) drops
nothing but gives a share P of the new values the time of the value before (the embedded autopilot, as
ArduCopter 3.6/4.0, times a value by its arrival). The combined rows add to the thesis' random drops the
latency its sensors had: the marker's frame processing on the Raspberry Pi, about 50 ms (thesis, Section
4.2), and one frame of the IR-LOCK's 50 Hz Pixy, 20 ms. Per fault: the landing error (mean, median, sd; cm), the
mean landing time (s), the share of values dropped, given again, given an old time and made false, the cost
against the same scenario without a fault (difference of means, cm) and a two-sided Mann-Whitney U test of
the errors (p) against the random fault's at the same share (burst, stale, combined) or against no fault
(stalestamp, delay, false), Holm-corrected over the rows of the table.

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

from preland_app.campaign.fidelity_tests import holm  # noqa: E402
from preland_app.config.mission import load_mission  # noqa: E402
from preland_app.runtime.embedded import TrialRequest, run_trial  # noqa: E402

CALM = {"speed_m_s": 0.5, "turbulence_w20_m_s": 0.5}

# (scenario, land mode, sensor, fault or None, take-off m, PLND_LAG s or None for the mission's); burst and
# stale faults are tested against the scenario's random one, old times, delays and false targets against no fault.
LEVELS = [
    ("T3 irlock", "irlock", "irlock", None, 10.0, None),
    ("T3 irlock", "irlock", "irlock", "random:0.75", 10.0, None),
    ("T3 irlock", "irlock", "irlock", "burst:0.75:5", 10.0, None),
    ("T3 irlock", "irlock", "irlock", "burst:0.75:25", 10.0, None),
    ("T3 irlock", "irlock", "irlock", "stale:0.75", 10.0, None),
    ("T3 irlock", "irlock", "irlock", "random:0.75+delay:20", 10.0, None),
    ("T3 irlock", "irlock", "irlock", "stalestamp:0.75", 10.0, None),
    ("T3 irlock", "irlock", "irlock", "delay:50", 10.0, None),
    ("T3 irlock", "irlock", "irlock", "delay:100", 10.0, None),
    ("T3 irlock", "irlock", "irlock", "delay:100:50", 10.0, None),
    ("T3 irlock", "irlock", "irlock", "delay:200", 10.0, None),
    ("T3 irlock", "irlock", "irlock", "delay:200", 10.0, 0.2),
    ("T3 irlock", "irlock", "irlock", "delay:300", 10.0, None),
    ("T3 irlock", "irlock", "irlock", "delay:400", 10.0, None),
    ("T3 irlock", "irlock", "irlock", "delay:400", 10.0, 0.25),
    ("T3 irlock", "irlock", "irlock", "false:0.1:1", 10.0, None),
    ("T3 irlock", "irlock", "irlock", "false:0.1:3", 10.0, None),
    ("T3 irlock", "irlock", "irlock", "false:0.3:3", 10.0, None),
    ("T3 marker", "marker", "marker", None, 6.0, None),
    ("T3 marker", "marker", "marker", "random:0.5", 6.0, None),
    ("T3 marker", "marker", "marker", "burst:0.5:3", 6.0, None),
    ("T3 marker", "marker", "marker", "burst:0.5:15", 6.0, None),
    ("T3 marker", "marker", "marker", "stale:0.5", 6.0, None),
    ("T3 marker", "marker", "marker", "random:0.5+delay:50", 6.0, None),
    ("T3 marker", "marker", "marker", "stalestamp:0.5", 6.0, None),
    ("T3 marker", "marker", "marker", "delay:50", 6.0, None),
    ("T3 marker", "marker", "marker", "delay:100", 6.0, None),
    ("T3 marker", "marker", "marker", "delay:100:50", 6.0, None),
    ("T3 marker", "marker", "marker", "delay:100", 6.0, 0.15),
    ("T3 marker", "marker", "marker", "delay:200", 6.0, None),
    ("T3 marker", "marker", "marker", "delay:200", 6.0, 0.25),
    ("T3 marker", "marker", "marker", "false:0.1:1", 6.0, None),
    ("T3 marker", "marker", "marker", "false:0.3:1", 6.0, None),
]


def _one(job: tuple[int, int]) -> tuple[int, str, float | None, float | None, float, float, float, float]:
    """One trial: (level, outcome, landing error cm, landing time s, share of the sensor's values dropped,
    share given again, share given an old time, share made false)."""
    index, seed = job
    _, mode, sensor, fault, height, lag_s = LEVELS[index]
    mission = load_mission(ROOT / "missions" / "thesis_square_land.yaml")
    environment = replace(mission.environment, wind=replace(mission.environment.wind, **CALM))
    mission = replace(mission, environment=environment)
    if lag_s is not None:
        mission = replace(mission, params={**mission.params, "PLND_LAG": lag_s})
    outcome = run_trial(TrialRequest(mission=mission, seed=seed, land_mode=mode,
                                     faults={sensor: fault} if fault else {}, takeoff_altitude_rel_m=height,
                                     record_trajectory=False))
    produced = outcome.details.get(f"{sensor}_produced", 0)
    dropped = outcome.details.get(f"{sensor}_dropped", 0)
    repeated = outcome.details.get(f"{sensor}_repeated", 0)
    old_stamp = outcome.details.get(f"{sensor}_old_stamp", 0)
    false = outcome.details.get(f"{sensor}_false", 0)
    return (index, outcome.outcome.value, outcome.landing_error_cm, outcome.landing_time_s,
            *(count / produced if produced else 0.0 for count in (dropped, repeated, old_stamp, false)))


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
           f"{'scenario':<10} {'fault':<26} {'landed':>6} {'mean':>6} {'median':>6} {'sd':>6} {'time s':>6} "
           f"{'dropped':>7} {'again':>6} {'old t':>6} {'false':>6} {'cost':>6} {'vs':>6} {'p':>7} {'Holm p':>7}"]
    errors = {index: [r[2] for r in results if r[0] == index and r[1] == "landed" and r[2] is not None]
              for index in range(len(LEVELS))}
    versus: dict[int, int] = {}
    pvalues: dict[str, float] = {}
    def plain_random(fault: str | None) -> bool:
        return bool(fault) and fault.startswith("random") and "+" not in fault

    for index, (scenario, _, _, fault, _, _) in enumerate(LEVELS):
        if not fault or plain_random(fault):
            continue
        kind = "none" if fault.startswith(("delay", "false", "stalestamp")) else "random"
        versus[index] = next(i for i, level in enumerate(LEVELS) if level[0] == scenario and (
            level[3] is None if kind == "none" else plain_random(level[3])))
        if errors[index] and errors[versus[index]]:
            pvalues[str(index)] = float(mannwhitneyu(errors[index], errors[versus[index]],
                                                     alternative="two-sided").pvalue)
    corrected = holm(pvalues)
    for index, (scenario, _, _, fault, _, lag_s) in enumerate(LEVELS):
        rows = [r for r in results if r[0] == index]
        times = [r[3] for r in rows if r[1] == "landed" and r[3] is not None]
        base = next(i for i, level in enumerate(LEVELS) if level[0] == scenario and level[3] is None)
        values = errors[index]
        mean = statistics.mean(values) if values else float("nan")
        cost = f"{mean - statistics.mean(errors[base]):>+6.1f}" if fault and errors[base] and values else f"{'':>6}"
        if str(index) in pvalues:
            against = "none" if LEVELS[versus[index]][3] is None else "random"
            tested = f"{against:>6} {pvalues[str(index)]:>7.3f} {corrected[str(index)]:>7.3f}"
        else:
            tested = f"{'':>6} {'':>7} {'':>7}"
        label = (fault or "none") + (f" (PLND_LAG {lag_s:g})" if lag_s is not None else "")
        out.append(f"{scenario:<10} {label:<26} {len(values):>3}/{len(rows):<2} {mean:>6.1f} "
                   f"{statistics.median(values) if values else float('nan'):>6.1f} "
                   f"{statistics.stdev(values) if len(values) > 1 else float('nan'):>6.1f} "
                   f"{statistics.mean(times) if times else float('nan'):>6.1f} "
                   f"{statistics.mean(r[4] for r in rows):>7.2f} {statistics.mean(r[5] for r in rows):>6.2f} "
                   f"{statistics.mean(r[6] for r in rows):>6.2f} {statistics.mean(r[7] for r in rows):>6.2f} "
                   f"{cost} {tested}")
    return out


if __name__ == "__main__":
    main()
