"""preland pad, detect and camera: landing pads, live marker detection and camera calibration."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from ..errors import PrelandError
from .app import DPI, EXIT_FAILED, app, choices, fail

VIDEO_SUFFIXES = (".mkv", ".avi", ".mp4")  # the containers VideoRecorder writes (FFV1, mp4v)


PadPreset = choices("preland_app.sensing.pad:PAD_PRESETS")
PaperSize = choices("preland_app.sensing.pad_render:PAPER_SIZES_M")  # imported (with matplotlib) on use
Dictionary = choices("preland_app.sensing.pad:DICTIONARIES")


pad_app = typer.Typer(help="Landing pads: render printable pads.", no_args_is_help=True)
app.add_typer(pad_app, name="pad")


@pad_app.command("render")
def pad_render(
    out: Path = typer.Option(..., "--out", help="Output file: .png or .pdf."),
    preset: Optional[PadPreset] = typer.Option(None, "--preset", help="Pad preset."),
    pad_file: Optional[Path] = typer.Option(None, "--pad", help="A pad YAML file instead of a preset."),
    dpi: int = typer.Option(DPI, "--dpi", help="Print resolution in dots per inch."),
    paper: Optional[PaperSize] = typer.Option(None, "--paper", help="Tile the sheet onto pages of this size (one "
                                              "PDF page, or one PNG file, per tile), with crop marks to cut and "
                                              "join them."),
) -> None:
    """Render a printable landing pad at true scale, with its dimensions annotated, a sheet outline and crop
    marks."""
    from ..sensing.pad import load_pad
    from ..sensing.pad_render import render_printable_pad

    if (preset is None) == (pad_file is None):
        raise fail("give exactly one of --preset or --pad")
    if out.suffix.lower() not in (".png", ".pdf"):
        raise fail(f"--out: {out} must end in .png or .pdf")
    if not 20 <= dpi <= 600:
        raise fail(f"--dpi: must be within 20..600, got {dpi}")
    try:
        pad = load_pad(preset if preset is not None else str(pad_file))
    except PrelandError as error:
        raise fail(str(error)) from None
    paths = render_printable_pad(pad, out, dpi=dpi, paper=paper)
    written = str(paths[0]) if len(paths) == 1 else f"{len(paths)} {paper} pages, {paths[0]} to {paths[-1]}"
    typer.echo(f"wrote {written} ({pad.name}: {pad.size_m * 100:.0f} cm sheet, "
               + ", ".join(f"id {m.id} {m.side_m * 100:.0f} cm" for m in pad.markers) + ")")


@app.command("detect")
def detect(
    camera_source: Optional[str] = typer.Option(None, "--camera", metavar="SRC",
                                                help="Capture device: index (0), device path, or GStreamer pipeline."),
    video: Optional[Path] = typer.Option(None, "--video", help="A video file instead of a camera."),
    pad_name: str = typer.Option("thesis", "--pad", help="Pad preset (as pad render --preset) or pad YAML file."),
    calibration: Optional[Path] = typer.Option(None, "--calibration", help="OpenCV calibration file."),
    out: Optional[Path] = typer.Option(None, "--out", help="Write the annotated frames to this video."),
    frames: int = typer.Option(0, "--frames", help="Stop after this many frames (0: the whole video, or Ctrl-C)."),
    csv_path: Optional[Path] = typer.Option(None, "--csv", help="Write one row per frame: frame, capture time, "
                                            "markers seen, the smallest marker's pad-centre position in the "
                                            "camera frame (m), detection latency (ms)."),
) -> None:
    """Detect the pad's markers live or in a video: overlays, detection rate and per-frame latency."""
    import asyncio
    import statistics
    import time

    from ..clock import LoopClock
    from ..sensing.camera import RPI_CAMERA_V2_640X480, load_calibration
    from ..sensing.capture import CaptureDeviceSource, VideoFileSource, VideoRecorder
    from ..sensing.marker import MarkerDetector
    from ..sensing.overlay import draw_detections
    from ..sensing.pad import load_pad

    if (camera_source is None) == (video is None):
        raise fail("give exactly one of --camera or --video")
    if csv_path is not None and csv_path.suffix.lower() != ".csv":
        raise fail(f"--csv: {csv_path} must end in .csv")
    if out is not None and out.suffix.lower() not in VIDEO_SUFFIXES:
        raise fail(f"--out: {out} is not a video file OpenCV can write here (expected one of: "
                   f"{', '.join(VIDEO_SUFFIXES)})")
    try:
        pad = load_pad(pad_name)
        camera = load_calibration(calibration) if calibration else RPI_CAMERA_V2_640X480
    except PrelandError as error:
        raise fail(str(error)) from None
    detector = MarkerDetector(pad=pad, camera=camera)

    async def main() -> tuple[int, int, list[float]]:
        clock = LoopClock()
        source = (VideoFileSource(path=video, clock=clock, camera=camera) if video is not None
                  else CaptureDeviceSource(source=camera_source, clock=clock, camera=camera))
        recorder = None
        seen = total = 0
        latencies: list[float] = []
        table = _FrameTable(csv_path) if csv_path is not None else None
        try:
            while frames <= 0 or total < frames:
                frame = await source.next_frame()
                if frame is None:
                    break
                if total == 0:
                    _warn_on_size_mismatch(camera, frame.image, calibration)
                started = time.perf_counter()
                detections = detector.detect(frame.image)
                latencies.append(time.perf_counter() - started)
                if table is not None:
                    table.write(total, frame.capture_time_s, detections, latencies[-1])
                total += 1
                seen += bool(detections)
                if out is not None:
                    annotated = draw_detections(frame.image, detections, camera)
                    if recorder is None:
                        recorder = VideoRecorder(path=out, frame_rate_hz=camera.frame_rate_hz,
                                                 size=(annotated.shape[1], annotated.shape[0]), color=True)
                    recorder.write(annotated)
        finally:
            if recorder is not None:
                recorder.close()
            if table is not None:
                table.close()
        return seen, total, latencies

    try:
        seen, total, latencies = asyncio.run(main())
    except PrelandError as error:
        raise fail(str(error)) from None
    except KeyboardInterrupt:
        raise fail("interrupted", code=130) from None
    if total == 0:
        raise fail("no frames")
    latencies_ms = sorted(1000 * v for v in latencies)
    typer.echo(f"frames {total}, pad detected in {seen} ({100 * seen / total:.1f} %)")
    typer.echo(f"detection latency per frame: median {statistics.median(latencies_ms):.2f} ms, "
               f"p95 {latencies_ms[int(0.95 * (len(latencies_ms) - 1))]:.2f} ms")
    if out is not None:
        if not _readable_video(out):
            raise fail(f"--out: {out} was not written as a readable video", code=EXIT_FAILED)
        typer.echo(f"wrote {out}")
    if csv_path is not None:
        typer.echo(f"wrote {csv_path}")


class _FrameTable:
    """detect --csv: one row per frame."""

    HEADER = ("frame", "capture_time_s", "markers", "marker_ids", "chosen_id", "pad_x_m", "pad_y_m", "pad_z_m",
              "latency_ms")

    def __init__(self, path: Path) -> None:
        import csv

        self.handle = path.open("w", newline="", encoding="utf-8")
        self.writer = csv.writer(self.handle)
        self.writer.writerow(self.HEADER)

    def write(self, index: int, time_s: float, detections, latency_s: float) -> None:
        chosen = min(detections, key=lambda d: d.side_m) if detections else None
        position = [f"{v:.4f}" for v in chosen.pad_center_cam_m] if chosen is not None else ["", "", ""]
        self.writer.writerow([index, f"{time_s:.4f}", len(detections),
                              " ".join(str(d.marker_id) for d in detections),
                              "" if chosen is None else chosen.marker_id, *position, f"{1000 * latency_s:.3f}"])

    def close(self) -> None:
        self.handle.close()


def _warn_on_size_mismatch(camera, image, calibration: Path | None) -> None:
    """A calibration made at another resolution gives wrong angles and distances: say so once."""
    height, width = image.shape[:2]
    if (width, height) != (camera.width_px, camera.height_px):
        where = f"--calibration {calibration}" if calibration else "the default camera model"
        typer.echo(f"preland: warning: {where} is for {camera.width_px}x{camera.height_px} frames, the video's are "
                   f"{width}x{height}: marker angles and distances will be wrong (calibrate at this size)", err=True)


def _readable_video(path: Path) -> bool:
    """Whether OpenCV reads a frame back from a video it wrote (a codec failure leaves an unreadable file)."""
    import cv2

    if not path.exists() or path.stat().st_size == 0:
        return False
    capture = cv2.VideoCapture(str(path))
    try:
        ok, _ = capture.read()
        return bool(ok)
    finally:
        capture.release()


camera_app = typer.Typer(help="Cameras: render a printable ChArUco board, calibrate a camera from views of it.",
                         no_args_is_help=True)
app.add_typer(camera_app, name="camera")


@camera_app.command("board")
def camera_board(
    out: Path = typer.Option(..., "--out", help="Output file: .png or .pdf."),
    squares_x: int = typer.Option(7, "--squares-x", help="Board squares across."),
    squares_y: int = typer.Option(5, "--squares-y", help="Board squares down."),
    square_m: float = typer.Option(0.04, "--square-m", help="Square side in m."),
    marker_m: float = typer.Option(0.03, "--marker-m", help="Marker side in m."),
    dictionary: Dictionary = typer.Option("DICT_4X4_50", "--dictionary", help="ArUco dictionary of the board."),
    dpi: int = typer.Option(DPI, "--dpi", help="Print resolution in dots per inch."),
) -> None:
    """Render a printable ChArUco board at true scale for camera calibrate (same options)."""
    from ..sensing.board_render import render_charuco_board

    if out.suffix.lower() not in (".png", ".pdf"):
        raise fail(f"--out: {out} must end in .png or .pdf")
    if not 50 <= dpi <= 1200:
        raise fail(f"--dpi: must be within 50..1200, got {dpi}")
    spec = _board_spec(squares_x=squares_x, squares_y=squares_y, square_m=square_m, marker_m=marker_m,
                       dictionary=dictionary)
    path = render_charuco_board(spec, out, dpi=dpi)
    typer.echo(f"wrote {path} ({squares_x} x {squares_y} squares of {square_m * 100:g} cm, markers "
               f"{marker_m * 100:g} cm, {dictionary})")


@camera_app.command("calibrate")
def camera_calibrate(
    images: Optional[Path] = typer.Option(None, "--images", help="Folder of ChArUco board images (png, jpg)."),
    video: Optional[Path] = typer.Option(None, "--video", help="A video of the board (every 10th frame is used)."),
    out: Path = typer.Option(..., "--out", help="OpenCV calibration file to write (.yaml)."),
    squares_x: int = typer.Option(7, "--squares-x", help="Board squares across."),
    squares_y: int = typer.Option(5, "--squares-y", help="Board squares down."),
    square_m: float = typer.Option(0.04, "--square-m", help="Square side in m."),
    marker_m: float = typer.Option(0.03, "--marker-m", help="Marker side in m."),
    dictionary: Dictionary = typer.Option("DICT_4X4_50", "--dictionary", help="ArUco dictionary of the board."),
) -> None:
    """Calibrate a camera from views of a ChArUco board; writes a file the marker sensor reads."""
    from ..sensing.calibration import calibrate, read_images

    if images is None and video is None:
        raise fail("give --images or --video")
    board_spec = _board_spec(squares_x=squares_x, squares_y=squares_y, square_m=square_m, marker_m=marker_m,
                             dictionary=dictionary)
    try:
        result = calibrate(read_images(folder=images, video=video), board_spec=board_spec)
    except PrelandError as error:
        raise fail(str(error)) from None
    result.write(out)
    typer.echo(f"wrote {out}: fx {result.fx_px:.1f} px, fy {result.fy_px:.1f} px, "
               f"{result.views_used} views, RMS reprojection error {result.rms_error_px:.3f} px")


def _board_spec(**fields):
    """The board the options describe; a bad value fails naming its option (`--square-m`...)."""
    from ..errors import SpecValueError
    from ..sensing.calibration import CharucoBoardSpec

    try:
        return CharucoBoardSpec(**fields)
    except SpecValueError as error:
        raise fail(f"--{error.field.replace('_', '-')}: {error.problem}") from None
