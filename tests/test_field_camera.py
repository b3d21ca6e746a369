"""Real-camera paths: replaying a recorded video, detection from the CLI, ChArUco calibration."""

import math

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from preland_app.cli import app
from preland_app.clock import LoopClock, run_virtual
from preland_app.sensing.calibration import CalibrationError, CharucoBoardSpec, calibrate
from preland_app.sensing.camera import RPI_CAMERA_V2_640X480, load_calibration
from preland_app.sensing.capture import CaptureError, VideoFileSource, VideoRecorder
from preland_app.sensing.marker import MarkerDetector
from preland_app.sensing.pad import THESIS_PAD
from preland_app.sensing.virtual_camera import CameraPose, VirtualCamera


def _descent_frames(count=40):
    renderer = VirtualCamera(camera=RPI_CAMERA_V2_640X480, pad=THESIS_PAD, pad_origin_ned_m=(0.0, 0.0),
                             rng=np.random.default_rng(3))
    for i in range(count):
        height = 8.0 - 7.5 * i / (count - 1)
        yield renderer.render(CameraPose(0.3 * math.sin(i / 5), 0.2, -height, 0.02, -0.01, 0.4))


def test_a_recorded_descent_replays_with_the_same_detections(tmp_path):
    detector = MarkerDetector(pad=THESIS_PAD, camera=RPI_CAMERA_V2_640X480)
    live, path = [], tmp_path / "descent.mkv"
    recorder = VideoRecorder(path=path, frame_rate_hz=30.0, size=(640, 480))
    for image in _descent_frames():
        live.append(detector.detect(image))
        recorder.write(image)
    recorder.close()

    async def replay():
        source = VideoFileSource(path=path, clock=LoopClock())
        found = []
        while (frame := await source.next_frame()) is not None:
            found.append((frame.capture_time_s, detector.detect(frame.image)))
        return found

    replayed = run_virtual(replay())
    assert len(replayed) == len(live) == 40
    assert replayed[1][0] == pytest.approx(1 / 30)
    for (_, again), first in zip(replayed, live):
        assert [d.marker_id for d in again] == [d.marker_id for d in first]
        for a, b in zip(again, first):
            assert np.allclose(a.corners_px, b.corners_px, atol=1e-6)
    assert sum(bool(d) for d in live) >= 35


def test_detect_command_on_a_video(tmp_path):
    path = tmp_path / "descent.mkv"
    recorder = VideoRecorder(path=path, frame_rate_hz=30.0, size=(640, 480))
    for image in _descent_frames(20):
        recorder.write(image)
    recorder.close()
    out = tmp_path / "annotated.mp4"
    result = CliRunner().invoke(app, ["detect", "--video", str(path), "--out", str(out)])
    assert result.exit_code == 0, result.output
    detector = MarkerDetector(pad=THESIS_PAD, camera=RPI_CAMERA_V2_640X480)
    expected = sum(bool(detector.detect(image)) for image in _descent_frames(20))
    assert f"frames 20, pad detected in {expected} (" in result.stdout and expected >= 17
    assert "median" in result.stdout and out.stat().st_size > 10_000
    result = CliRunner().invoke(app, ["detect", "--video", str(tmp_path / "none.mkv")])
    assert result.exit_code == 2 and "not found" in result.stderr


def _render_board_views(camera_matrix, size, views=14, seed=0):
    spec = CharucoBoardSpec()
    board_image = spec.board().generateImage((1400, 1000), marginSize=0)
    px_per_m = 1400 / (spec.squares_x * spec.square_m)
    rng = np.random.default_rng(seed)
    images = []
    for _ in range(views):
        rvec = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3)])
        rotation, _ = cv2.Rodrigues(rvec)
        centre = np.array([spec.squares_x * spec.square_m / 2, spec.squares_y * spec.square_m / 2, 0.0])
        tvec = np.array([rng.uniform(-0.05, 0.05), rng.uniform(-0.04, 0.04), rng.uniform(0.35, 0.55)]) - \
            rotation @ centre
        # Board texture pixel (u, v) -> board plane (u, v) / px_per_m -> image.
        plane_to_image = camera_matrix @ np.column_stack([rotation[:, 0], rotation[:, 1], tvec])
        texture_to_plane = np.diag([1 / px_per_m, 1 / px_per_m, 1.0])
        homography = plane_to_image @ texture_to_plane
        view = cv2.warpPerspective(board_image, homography, size, borderValue=200)
        images.append(view)
    return images


def test_calibration_recovers_the_focal_lengths_of_synthetic_views(tmp_path):
    known = np.array([[600.0, 0.0, 322.0], [0.0, 612.0, 236.0], [0.0, 0.0, 1.0]])
    images = _render_board_views(known, (640, 480))
    result = calibrate(images)
    assert result.views_used >= 10
    assert result.fx_px == pytest.approx(600.0, rel=0.02)
    assert result.fy_px == pytest.approx(612.0, rel=0.02)
    folder = tmp_path / "views"
    folder.mkdir()
    for index, image in enumerate(images):
        cv2.imwrite(str(folder / f"view{index:02d}.png"), image)
    out = tmp_path / "calibration.yaml"
    command = CliRunner().invoke(app, ["camera", "calibrate", "--images", str(folder), "--out", str(out)])
    assert command.exit_code == 0, command.output
    model = load_calibration(out)
    assert model.fx_px == pytest.approx(600.0, rel=0.02) and model.fy_px == pytest.approx(612.0, rel=0.02)


def test_calibration_needs_enough_views():
    with pytest.raises(CalibrationError, match="usable view"):
        calibrate([np.full((480, 640), 128, np.uint8)] * 5)
    with pytest.raises(CaptureError):
        run_virtual(_open_missing())


async def _open_missing():
    VideoFileSource(path="/nonexistent.mkv", clock=LoopClock())




def test_detect_writes_a_row_per_frame_and_warns_on_a_calibration_of_another_size(tmp_path):
    import csv

    path = tmp_path / "descent.mkv"
    recorder = VideoRecorder(path=path, frame_rate_hz=30.0, size=(640, 480))
    for image in _descent_frames(6):
        recorder.write(image)
    recorder.close()
    table = tmp_path / "frames.csv"
    result = CliRunner().invoke(app, ["detect", "--video", str(path), "--csv", str(table)])
    assert result.exit_code == 0, result.output
    assert "warning" not in result.stderr
    rows = list(csv.DictReader(table.open()))
    assert [int(r["frame"]) for r in rows] == list(range(6))
    detector = MarkerDetector(pad=THESIS_PAD, camera=RPI_CAMERA_V2_640X480)
    for row, image in zip(rows, _descent_frames(6)):
        found = detector.detect(image)
        assert int(row["markers"]) == len(found) and float(row["latency_ms"]) > 0
        if found:
            chosen = min(found, key=lambda d: d.side_m)
            assert int(row["chosen_id"]) == chosen.marker_id
            assert float(row["pad_z_m"]) == pytest.approx(chosen.pad_center_cam_m[2], abs=1e-3)
    calibration = tmp_path / "calib.yaml"
    calibration.write_text("camera_matrix: [[800, 0, 640], [0, 800, 360], [0, 0, 1]]\ndist_coeffs: [0, 0, 0, 0, 0]\n"
                           "image_width: 1280\nimage_height: 720\n")
    result = CliRunner().invoke(app, ["detect", "--video", str(path), "--calibration", str(calibration)])
    assert result.exit_code == 0, result.output
    assert "warning" in result.stderr and "1280x720" in result.stderr and "640x480" in result.stderr
