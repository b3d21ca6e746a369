"""The virtual camera draws only the tracking window, and the detections are those of the whole frame.

A frame from the virtual camera is drawn only when read, and then only the part
read: the window the tracker searches, warped with the homographies shifted by
the window's origin and with the same sensor-noise field at the same offsets.
Over flown descents, frame by frame, the window path must give the markers the
whole-frame path gives (same ids, corners within 0.1 px).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import preland_app.runtime.embedded as embedded
from preland_app.config.mission import load_mission
from preland_app.runtime.embedded import TrialRequest, run_trial
from preland_app.sensing.camera import RPI_CAMERA_V2_640X480, Frame
from preland_app.sensing.marker import MarkerDetector, TrackingMarkerDetector
from preland_app.sensing.pad import PAPER_PAD
from preland_app.sensing.virtual_camera import CameraPose, ImageEffects, RenderedFrame, VirtualCamera

ROOT = Path(__file__).resolve().parents[1]
DISTORTED = replace(RPI_CAMERA_V2_640X480, distortion=(-0.28, 0.09, 0.001, -0.0005, 0.0))


@pytest.mark.parametrize("camera", [RPI_CAMERA_V2_640X480, DISTORTED], ids=["pinhole", "distorted"])
@pytest.mark.parametrize("effects", [ImageEffects(), ImageEffects(blur_px=1.2, exposure_gain=1.3, noise_sigma=4.0)],
                         ids=["noise", "blur-exposure-noise"])
def test_a_region_is_the_whole_frame_cropped_there(camera, effects):
    renderer = VirtualCamera(camera=camera, pad=PAPER_PAD, pad_origin_ned_m=(0.3, -0.2),
                             rng=np.random.default_rng(5), effects=effects)
    regions = np.random.default_rng(1)
    differing = compared = 0
    for i in range(12):
        shot = renderer.capture(CameraPose(0.3 * math.sin(i), 0.2, -(12.0 - i), 0.05, 0.04, 0.3 + 0.2 * i))
        whole = renderer.render_shot(shot)
        for _ in range(4):
            x0, y0 = int(regions.integers(0, 600)), int(regions.integers(0, 440))
            x1, y1 = int(regions.integers(x0 + 1, 641)), int(regions.integers(y0 + 1, 481))
            part = renderer.render_shot(shot, (x0, y0, x1, y1)).astype(int)
            crop = whole[y0:y1, x0:x1].astype(int)
            assert part.shape == crop.shape
            # OpenCV's warp rounds its coordinates in single precision: a shifted homography may move a
            # rare pixel by one grey level (two after the exposure gain); misplaced noise, blur or lens
            # maps would change most of them.
            assert np.abs(part - crop).max() <= 2
            differing += np.count_nonzero(part != crop)
            compared += crop.size
    assert differing <= 0.002 * compared


def test_a_frame_is_drawn_only_when_read():
    renderer = VirtualCamera(camera=RPI_CAMERA_V2_640X480, pad=PAPER_PAD, pad_origin_ned_m=(0.0, 0.0),
                             rng=np.random.default_rng(2))
    drawn = []
    render_shot = renderer.render_shot
    renderer.render_shot = lambda shot, region=None: drawn.append(region) or render_shot(shot, region)
    frame = RenderedFrame(renderer=renderer, shot=renderer.capture(CameraPose(0, 0, -5, 0, 0, 0)),
                          capture_time_s=0.0, index=0)
    assert drawn == []
    assert frame.region(10, 20, 110, 70).shape == (50, 100)
    assert drawn == [(10, 20, 110, 70)]
    image = frame.image
    assert image is frame.image and drawn[-1] is None and len(drawn) == 2  # drawn once, then kept
    assert np.array_equal(frame.region(10, 20, 110, 70), image[20:70, 10:110])
    assert len(drawn) == 2


class _ComparingDetector:
    """The runtime's detector during a flight, checked frame by frame against the whole-frame paths: the
    same tracker on the whole drawn frame, and a plain MarkerDetector on the whole frame."""

    def __init__(self, *, pad, camera):
        self.window = TrackingMarkerDetector(pad=pad, camera=camera)
        self.whole = TrackingMarkerDetector(pad=pad, camera=camera)
        self.plain = MarkerDetector(pad=pad, camera=camera)
        self.pad, self.camera = pad, camera
        self.frames = self.windowed = 0
        self.id_mismatches: list[tuple[int, list[int], list[int]]] = []
        self.corner_errors_px: list[float] = []
        self.plain_extra_ids = self.plain_missed_ids = 0
        self.plain_corner_errors_px: list[float] = []

    def detect_frame(self, frame):
        assert isinstance(frame, RenderedFrame)
        searched_window = self.window._window is not None
        found = self.window.detect_frame(frame)  # first: only the window is drawn
        whole_image = frame.image
        reference = self.whole.detect_frame(Frame(whole_image, capture_time_s=frame.capture_time_s))
        self._compare(found, reference, self.id_mismatches, self.corner_errors_px)
        plain = {d.marker_id: d.corners_px for d in self.plain.detect(whole_image)}
        self.plain_extra_ids += sum(d.marker_id not in plain for d in found)
        self.plain_missed_ids += len(set(plain) - {d.marker_id for d in found})
        self.plain_corner_errors_px.extend(float(np.abs(d.corners_px - plain[d.marker_id]).max())
                                           for d in found if d.marker_id in plain)
        self.frames += 1
        self.windowed += searched_window and self.window.window_hits > 0
        return found

    def _compare(self, found, reference, mismatches, errors):
        a = {d.marker_id: d.corners_px for d in found}
        b = {d.marker_id: d.corners_px for d in reference}
        if sorted(a) != sorted(b):
            mismatches.append((self.frames, sorted(a), sorted(b)))
            return
        errors.extend(float(np.abs(a[k] - b[k]).max()) for k in a)


@pytest.mark.parametrize("mission_file, land, seed", [
    ("thesis_square_land.yaml", "marker", 11),
    ("paper_marker_land.yaml", "paper_adaptive", 4),
])
def test_window_detections_match_the_whole_frame_over_a_flown_descent(monkeypatch, mission_file, land, seed):
    detectors = []

    def comparing(*, pad, camera):
        detectors.append(_ComparingDetector(pad=pad, camera=camera))
        return detectors[-1]

    monkeypatch.setattr(embedded, "TrackingMarkerDetector", comparing)
    mission = load_mission(ROOT / "missions" / mission_file)
    outcome = run_trial(TrialRequest(mission=mission, seed=seed, land_mode=land, record_trajectory=False))
    assert outcome.outcome.value == "landed"
    (detector,) = detectors
    assert detector.frames > 200
    assert detector.window.window_hits > 0.5 * detector.frames  # most frames drew only the window
    assert detector.id_mismatches == []
    assert max(detector.corner_errors_px) <= 0.1
    # Against a plain whole-frame search: nothing it does not find (the window may miss a marker outside it
    # until the next whole-frame search, as the tracker always has).
    assert detector.plain_extra_ids == 0
    assert max(detector.plain_corner_errors_px) <= 0.1
