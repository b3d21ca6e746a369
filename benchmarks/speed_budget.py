"""Where a camera trial's CPU goes, and what the speed targets would ask of each part: the marker land
mode (thesis mission), the paper mission (`paper_adaptive`) and the thesis' Tables 3 to 5, each flown in
this process on one core (OpenCV on one thread, as a campaign's workers run it).

Each workload is flown twice with the same seeds: once as it is, for its speed (simulated s per CPU s),
and once with the parts below timed (CPU time of this thread), which costs a few per cent more:

  detectMarkers   OpenCV's ArUco detection (cv2.aruco.ArucoDetector.detectMarkers)
  frame drawing   the virtual camera's pixels (VirtualCamera.render_shot)
  frame capture   a frame's geometry and noise draw (VirtualCamera.capture)
  poses           sub-pixel corners and solvePnP (MarkerDetector._poses)
  simulator       physics, navigation errors and the autopilot (Simulator.step)
  the rest        mission runner, land mode, IR-LOCK, telemetry, the event loop, the store's record

For each target it prints the speed each part's removal alone would give (that part at no cost at all),
and by how much everything else would have to shrink to meet the target with detection as it is.

Usage: python benchmarks/speed_budget.py [--trials N] [--table-trials N]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from preland_app.campaign.spec import load_campaign, resolve_scenarios  # noqa: E402
from preland_app.campaign.trials import plan_trials, run_job  # noqa: E402
from preland_app.config.mission import load_mission  # noqa: E402
from preland_app.runtime.embedded import TrialRequest, run_trial  # noqa: E402
from preland_app.sensing import marker as marker_module  # noqa: E402
from preland_app.sensing.virtual_camera import VirtualCamera  # noqa: E402
from preland_app.sim.simulator import Simulator  # noqa: E402

PARTS = ("detectMarkers", "frame drawing", "frame capture", "poses", "simulator")
# Issue #16's goals, simulated s per wall s per core.
GOALS = {"marker": 100.0, "paper": 60.0, "tables": 120.0}
_spent = dict.fromkeys(PARTS, 0.0)


class _TimedArucoDetector:
    """cv2.aruco.ArucoDetector with its detectMarkers timed; everything else passed through."""

    def __init__(self, *args) -> None:
        self._detector = _ARUCO_DETECTOR(*args)

    def detectMarkers(self, image, *args):  # noqa: N802 - OpenCV's name
        started = time.thread_time()
        try:
            return self._detector.detectMarkers(image, *args)
        finally:
            _spent["detectMarkers"] += time.thread_time() - started

    def __getattr__(self, name):
        return getattr(self._detector, name)


_ARUCO_DETECTOR = cv2.aruco.ArucoDetector


def _timed(part: str, function: Callable) -> Callable:
    def timed(*args, **kwargs):
        started = time.thread_time()
        try:
            return function(*args, **kwargs)
        finally:
            _spent[part] += time.thread_time() - started

    return timed


def _install_timers() -> None:
    marker_module.cv2.aruco.ArucoDetector = _TimedArucoDetector
    VirtualCamera.render_shot = _timed("frame drawing", VirtualCamera.render_shot)
    VirtualCamera.capture = _timed("frame capture", VirtualCamera.capture)
    marker_module.MarkerDetector._poses = _timed("poses", marker_module.MarkerDetector._poses)
    Simulator.step = _timed("simulator", Simulator.step)


def _single(mission_file: str, land: str, trials: int) -> Callable[[], float]:
    mission = load_mission(ROOT / "missions" / mission_file)

    def fly() -> float:
        return sum(run_trial(TrialRequest(mission=mission, seed=seed, land_mode=land, record_trajectory=True))
                   .flight_time_s or 0.0 for seed in range(trials))
    return fly


def _tables(trials_per_scenario: int) -> Callable[[], float]:
    jobs = []
    for name in ("thesis_table3.yaml", "thesis_table4.yaml", "thesis_table5.yaml"):
        campaign = load_campaign(ROOT / "campaigns" / name)
        jobs += [job for job in plan_trials(campaign, resolve_scenarios(campaign))
                 if job.trial_index < trials_per_scenario]

    def fly() -> float:
        return sum(run_job(job).result.get("flight_time_s") or 0.0 for job in jobs)
    return fly


def _cpu(fly: Callable[[], float]) -> tuple[float, float]:
    started = time.thread_time()
    flown = fly()
    return flown, time.thread_time() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--trials", type=int, default=8, help="marker-mode trials (half as many paper trials)")
    parser.add_argument("--table-trials", type=int, default=3, help="trials per Tables 3 to 5 scenario")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    cv2.setNumThreads(1)
    workloads = {
        "marker": ("marker land mode, thesis mission", _single("thesis_square_land.yaml", "marker", args.trials)),
        "paper": ("paper mission (paper_adaptive)",
                  _single("paper_marker_land.yaml", "paper_adaptive", max(1, args.trials // 2))),
        "tables": (f"thesis Tables 3 to 5 ({args.table_trials} per scenario)", _tables(args.table_trials)),
    }
    _single("thesis_square_land.yaml", "marker", 1)()  # imports, caches, the pad textures
    plain = {key: _cpu(fly) for key, (_, fly) in workloads.items()}
    _install_timers()
    print(f"CPU time of one core (load average {os.getloadavg()[0]:.1f} at the start); shares from a second, "
          "timed pass with the same seeds")
    for key, (label, fly) in workloads.items():
        for part in PARTS:
            _spent[part] = 0.0
        flown, cpu_s = _cpu(fly)
        plain_flown, plain_cpu_s = plain[key]
        speed = plain_flown / plain_cpu_s
        detect_s = _spent["detectMarkers"] * plain_cpu_s / cpu_s  # the timed pass's share, on the plain time
        rest_s = plain_cpu_s - detect_s
        goal = GOALS[key]
        needed_rest_s = plain_flown / goal - detect_s
        shares = "  ".join(f"{part} {100 * _spent[part] / cpu_s:4.1f} %" for part in PARTS)
        other = 100 * (cpu_s - sum(_spent.values())) / cpu_s
        print(f"{label}: {speed:6.1f}x per CPU s ({plain_flown:.0f} s flown in {plain_cpu_s:.2f} CPU s); goal {goal:g}x")
        print(f"  {shares}  the rest {other:4.1f} %")
        free = "  ".join(f"{part} {plain_flown / (plain_cpu_s * (1 - _spent[part] / cpu_s)):5.1f}x"
                         for part in PARTS)
        print(f"  one part at no cost: {free}")
        print(f"  to reach {goal:g}x with detection as it is, everything else would have to shrink by "
              + (f"{100 * (1 - needed_rest_s / rest_s):.0f} %" if needed_rest_s > 0
                 else "more than all of it (detection alone is over the budget)"))


if __name__ == "__main__":
    main()
