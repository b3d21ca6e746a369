"""Per-frame cost of the virtual camera and the marker detector at 640x480, beside raw
`cv2.aruco.ArucoDetector.detectMarkers` on the same frames; and the simulator's real-time factor
with the camera in the loop at 30 fps (marker land mode, thesis mission), on one core.

Usage: python benchmarks/vision_speed.py [--frames N] [--trials N]
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from preland_app.clock import LoopClock, run_virtual  # noqa: E402
from preland_app.config.mission import load_mission  # noqa: E402
from preland_app.runtime.embedded import TrialRequest, fly_embedded  # noqa: E402
from preland_app.sensing.camera import RPI_CAMERA_V2_640X480  # noqa: E402
from preland_app.sensing.marker import MarkerDetector, TrackingMarkerDetector  # noqa: E402
from preland_app.sensing.pad import THESIS_PAD  # noqa: E402
from preland_app.sensing.virtual_camera import CameraPose, VirtualCamera  # noqa: E402


def _ms(values: list[float]) -> str:
    return f"median {statistics.median(values) * 1e3:6.2f} ms   p95 {np.percentile(values, 95) * 1e3:6.2f} ms"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--trials", type=int, default=5)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    camera = RPI_CAMERA_V2_640X480
    renderer = VirtualCamera(camera=camera, pad=THESIS_PAD, pad_origin_ned_m=(0.0, 0.0), rng=np.random.default_rng(0))
    detector = MarkerDetector(pad=THESIS_PAD, camera=camera)
    tracker = TrackingMarkerDetector(pad=THESIS_PAD, camera=camera)
    render_s, detect_s, raw_s, track_s = [], [], [], []
    found = agree = 0
    for i in range(args.frames):  # a descent from 10 m to 0.3 m with some sway
        height = 10.0 - 9.7 * i / max(1, args.frames - 1)
        pose = CameraPose(0.3 * math.sin(i / 17), 0.2 * math.cos(i / 23), -height, 0.03 * math.sin(i / 5),
                          0.03 * math.cos(i / 7), 0.2)
        t0 = time.perf_counter()
        frame = renderer.render(pose)
        t1 = time.perf_counter()
        found += bool(detector.detect(frame))
        t2 = time.perf_counter()
        detector.detector.detectMarkers(frame)
        t3 = time.perf_counter()
        tracked = tracker.detect(frame)
        t4 = time.perf_counter()
        render_s.append(t1 - t0)
        detect_s.append(t2 - t1)
        raw_s.append(t3 - t2)
        track_s.append(t4 - t3)
        same = sorted(d.marker_id for d in tracked) == sorted(d.marker_id for d in detector.detect(frame))
        agree += same
    print(f"640x480 frames over a 10 m -> 0.3 m descent ({args.frames} frames, one core; pad found in {found})")
    print(f"  render (virtual camera)          : {_ms(render_s)}")
    print(f"  detect (MarkerDetector + pose)   : {_ms(detect_s)}")
    print(f"  raw ArucoDetector.detectMarkers  : {_ms(raw_s)}")
    print(f"  detect with tracking window      : {_ms(track_s)}  (same markers as full-frame in "
          f"{agree}/{args.frames} frames)")

    mission = load_mission(ROOT / "missions" / "thesis_square_land.yaml")

    async def timed(seed: int) -> tuple[float, float]:
        clock = LoopClock()
        started = time.perf_counter()
        await fly_embedded(TrialRequest(mission=mission, seed=seed, land_mode="marker", record_trajectory=False))
        return clock.now_s(), time.perf_counter() - started

    simulated = wall = 0.0
    for seed in range(args.trials):
        sim_s, wall_s = run_virtual(timed(seed))
        simulated += sim_s
        wall += wall_s
    print(f"marker land mode, camera at {camera.frame_rate_hz:g} fps during the landing, {args.trials} trials:")
    print(f"  real-time factor                 : {simulated / wall:6.1f}x  ({simulated / args.trials:.1f} simulated s "
          f"in {wall / args.trials:.2f} s per trial)")


if __name__ == "__main__":
    main()
