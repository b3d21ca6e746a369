"""What OpenCV detector settings (`sensors.marker.detector`) would buy in speed, and what they would change in
the results: the camera scenarios of the thesis' Tables 3 to 5 and the paper mission (`paper_adaptive`),
flown with the same seeds under the thesis' detector (OpenCV's defaults with sub-pixel corners) and under
each variant, in this process on one core. Per variant: simulated s per CPU s, and per scenario the mean
landing error beside the default's, the largest change of one trial's error, and the trials whose outcome
changed.

Usage: python benchmarks/detector_variants.py [--trials N] [--paper-trials N]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import cv2

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from preland_app.campaign.spec import load_campaign, resolve_scenarios  # noqa: E402
from preland_app.campaign.trials import plan_trials, run_job  # noqa: E402
from preland_app.config.mission import load_mission  # noqa: E402
from preland_app.runtime.embedded import TrialRequest, run_trial  # noqa: E402

VARIANTS = {
    "thesis (OpenCV defaults)": {},
    "thresholds 3, 13 (no 23)": {"adaptiveThreshWinSizeMax": 13},
    "thresholds 13, 23 (no 3)": {"adaptiveThreshWinSizeMin": 13},
    "ArUco3": {"useAruco3Detection": True},
}


def _with_detector(mission, detector: dict):
    marker = replace(mission.sensors.marker, detector=dict(detector))
    return replace(mission, sensors=replace(mission.sensors, marker=marker))


def _camera_jobs(trials: int) -> list:
    jobs = []
    for name in ("thesis_table3.yaml", "thesis_table4.yaml", "thesis_table5.yaml"):
        campaign = load_campaign(ROOT / "campaigns" / name)
        jobs += [job for job in plan_trials(campaign, resolve_scenarios(campaign))
                 if job.trial_index < trials and job.mission.land.precision_sensor in ("marker", "fused")]
    return jobs


def _fly(jobs, paper_mission, paper_trials: int, detector: dict) -> tuple[float, float, dict]:
    """(flight s, CPU s, {scenario: [(outcome, landing error cm), ...]})."""
    results: dict[str, list] = {}
    flown = 0.0
    started = time.thread_time()
    for job in jobs:
        record = run_job(replace(job, mission=_with_detector(job.mission, detector)))
        flown += record.result.get("flight_time_s") or 0.0
        results.setdefault(f"{job.campaign.removeprefix('thesis_')} {job.scenario}", []).append(
            (record.result.get("outcome"), record.result.get("landing_error_cm")))
    mission = _with_detector(paper_mission, detector)
    for seed in range(paper_trials):
        outcome = run_trial(TrialRequest(mission=mission, seed=seed, land_mode="paper_adaptive", record_trajectory=True))
        flown += outcome.flight_time_s or 0.0
        results.setdefault("paper mission, paper_adaptive", []).append(
            (outcome.outcome.value, outcome.landing_error_cm))
    return flown, time.thread_time() - started, results


def _mean(rows) -> str:
    errors = [error for _, error in rows if error is not None]
    return f"{statistics.fmean(errors):6.1f}" if errors else "   n/a"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--trials", type=int, default=5, help="trials per Tables 3 to 5 camera scenario")
    parser.add_argument("--paper-trials", type=int, default=3)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    cv2.setNumThreads(1)
    jobs = _camera_jobs(args.trials)
    paper = load_mission(ROOT / "missions" / "paper_marker_land.yaml")
    _fly(jobs[:1], paper, 0, {})  # imports, caches, the pad textures
    runs = {label: _fly(jobs, paper, args.paper_trials, detector) for label, detector in VARIANTS.items()}
    _, base_cpu, base = next(iter(runs.values()))
    print(f"{len(jobs)} Tables 3 to 5 camera trials ({args.trials} per scenario) and {args.paper_trials} paper "
          f"trials per variant, the same seeds, one core")
    for label, (flown, cpu_s, _) in runs.items():
        print(f"{label:28s} {flown / cpu_s:6.1f}x per CPU s ({cpu_s:5.1f} CPU s; {base_cpu / cpu_s:4.2f}x the "
              f"thesis detector's speed)")
    for label, (_, _, results) in list(runs.items())[1:]:
        print(f"\n{label}: mean landing error (cm), thesis detector -> this; largest change of one trial; "
              "outcomes changed")
        for scenario, rows in results.items():
            reference = base[scenario]
            changes = [abs(a[1] - b[1]) for a, b in zip(rows, reference) if a[1] is not None and b[1] is not None]
            flipped = sum(a[0] != b[0] for a, b in zip(rows, reference))
            print(f"  {scenario:58s} {_mean(reference)} -> {_mean(rows)}   max {max(changes, default=0.0):6.1f}   "
                  f"{flipped}/{len(rows)}")


if __name__ == "__main__":
    main()
