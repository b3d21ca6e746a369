"""Per-frame cost of the virtual camera and the marker detector at 640x480, the whole-frame path beside
the tracking-window path on the same frames: render (whole frame / window only), detect (MarkerDetector
on the whole frame / the tracker), and both together (whole frame drawn then tracked / the frame drawn
only where the tracker reads it), with whether both paths found the same markers; then the simulator's
real-time factor with the camera in the loop at 30 fps (marker land mode, thesis mission), on one core.
Times are CPU time of this thread (time.thread_time), which other work on the machine does not inflate.

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
from preland_app.sensing.camera import Frame  # noqa: E402
from preland_app.sensing.virtual_camera import CameraPose, RenderedFrame, VirtualCamera  # noqa: E402


def _ms(values: list[float]) -> str:
    return f"median {statistics.median(values) * 1e3:5.2f} / p95 {np.percentile(values, 95) * 1e3:5.2f} ms"


def _replay(tracker: TrackingMarkerDetector, window, frames: int) -> TrackingMarkerDetector:
    """A tracker in the state `tracker` had before this frame (its window and frame count), to time the
    detection alone on the drawn frame."""
    replay = TrackingMarkerDetector(pad=tracker.pad, camera=tracker.camera)
    replay._window, replay._frames = window, frames
    return replay


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
    window_tracker = TrackingMarkerDetector(pad=THESIS_PAD, camera=camera)
    clock = time.thread_time
    times: dict[str, list[float]] = {key: [] for key in (
        "render_whole", "render_window", "detect_whole", "detect_window", "both_whole", "both_window")}
    found = same = windowed = 0
    worst_corner_px = 0.0
    render_shot = renderer.render_shot
    drawing = {"s": 0.0, "calls": 0}

    def timed_render_shot(shot, region=None):
        t0 = clock()
        try:
            return render_shot(shot, region)
        finally:
            drawing["s"] += clock() - t0
            drawing["calls"] += 1

    culled = 0
    for i in range(args.frames):  # a descent from 10 m to 0.3 m with some sway
        height = 10.0 - 9.7 * i / max(1, args.frames - 1)
        pose = CameraPose(0.3 * math.sin(i / 17), 0.2 * math.cos(i / 23), -height, 0.03 * math.sin(i / 5),
                          0.03 * math.cos(i / 7), 0.2)
        shot = renderer.capture(pose)
        window = window_tracker._window
        hits_before = window_tracker.window_hits
        # Window path: the frame is drawn only where the tracker reads it.
        renderer.render_shot = timed_render_shot
        drawing["s"], drawing["calls"] = 0.0, 0
        t0 = clock()
        tracked = window_tracker.detect_frame(RenderedFrame(renderer=renderer, shot=shot, capture_time_s=0.0, index=i))
        t1 = clock()
        renderer.render_shot = render_shot
        times["both_window"].append(t1 - t0)
        times["render_window"].append(drawing["s"])
        windowed += window_tracker.window_hits > hits_before
        culled += drawing["calls"] == 0
        # Whole-frame path: draw the whole frame, then detect in it.
        t0 = clock()
        image = renderer.render_shot(shot)
        t1 = clock()
        reference = detector.detect(image)
        t2 = clock()
        times["render_whole"].append(t1 - t0)
        times["detect_whole"].append(t2 - t1)
        times["both_whole"].append(t2 - t0)
        # The tracker's detection alone, on the same frame already drawn, from the state it had before it.
        drawn = RenderedFrame(renderer=renderer, shot=shot, capture_time_s=0.0, index=i)
        drawn.preset_image(image)
        replay = _replay(window_tracker, window, i)
        t0 = clock()
        replay.detect_frame(drawn)
        times["detect_window"].append(clock() - t0)
        found += bool(reference)
        a = {d.marker_id: d.corners_px for d in tracked}
        b = {d.marker_id: d.corners_px for d in reference}
        if sorted(a) == sorted(b):
            same += 1
            worst_corner_px = max([worst_corner_px] + [float(np.abs(a[k] - b[k]).max()) for k in a])
    print(f"640x480 frames over a 10 m -> 0.3 m descent ({args.frames} frames, CPU time per frame, one core; "
          f"pad found in {found}; {windowed} found in the tracking window; {culled} with no marker wholly in view, "
          f"so neither drawn nor searched)")
    print(f"  {'':38s}{'whole frame':>28s}   {'tracking window':>28s}")
    for label, key in (("render (virtual camera)", "render"), ("detect (with poses)", "detect"),
                       ("render + detect", "both")):
        print(f"  {label:38s}{_ms(times[key + '_whole']):>28s}   {_ms(times[key + '_window']):>28s}")
    print(f"  window path against a whole-frame MarkerDetector: same markers in {same}/{args.frames} frames, "
          f"corners within {worst_corner_px:.3f} px")

    mission = load_mission(ROOT / "missions" / "thesis_square_land.yaml")

    async def timed(seed: int) -> tuple[float, float]:
        clock = LoopClock()
        started = time.thread_time()
        await fly_embedded(TrialRequest(mission=mission, seed=seed, land_mode="marker", record_trajectory=False))
        return clock.now_s(), time.thread_time() - started

    simulated = wall = 0.0
    for seed in range(args.trials):
        sim_s, wall_s = run_virtual(timed(seed))
        simulated += sim_s
        wall += wall_s
    print(f"marker land mode, camera at {camera.frame_rate_hz:g} fps during the landing, {args.trials} trials:")
    print(f"  real-time factor (per CPU s)     : {simulated / wall:6.1f}x  ({simulated / args.trials:.1f} simulated s "
          f"in {wall / args.trials:.2f} CPU s per trial)")


if __name__ == "__main__":
    main()
