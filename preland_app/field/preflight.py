"""Preflight checks: refuse take-off, one clear line per failed check.

Checks: the link (telemetry arrives), a 3D GPS fix with a healthy position
estimate, the battery above a threshold, precision-landing parameters set when
a precision land mode is chosen (PLND_TYPE takes effect only after a reboot on
ArduPilot, so it must be right before take-off), the camera delivering frames
at the expected rate, and, when the mission asks, the pad in view at the start.
"""

from __future__ import annotations

import asyncio

import time
from dataclasses import dataclass

from ..clock import Clock
from ..errors import PrelandError, require
from ..sensing.suite import SensorSuite
from ..vehicle.protocol import Vehicle


@dataclass(frozen=True)
class PreflightSpec:
    """`min_battery_pct`: refuse below this charge; `gps_wait_s`: how long (vehicle s) to wait for a 3D fix
    and a healthy estimate before refusing; `camera_min_rate_fraction`: refuse a camera slower than
    this fraction of its frame rate; `require_pad_visible`: refuse unless the pad is detected before take-off."""

    min_battery_pct: float = 30.0
    gps_wait_s: float = 30.0
    camera_min_rate_fraction: float = 0.8
    camera_check_frames: int = 15
    require_pad_visible: bool = False

    def __post_init__(self) -> None:
        require(0 <= self.min_battery_pct <= 100, "min_battery_pct", "must be within 0..100 %")
        require(0 < self.camera_min_rate_fraction <= 1, "camera_min_rate_fraction", "must be within 0..1")
        require(self.camera_check_frames >= 2, "camera_check_frames", "must be >= 2")
        require(self.gps_wait_s >= 0, "gps_wait_s", "must be >= 0 s")


class PreflightFailed(PrelandError):
    """Take-off refused: one line per failed check."""

    def __init__(self, failures: list[str]) -> None:
        self.failures = failures
        super().__init__("preflight failed: " + "; ".join(failures))


async def run_preflight(*, vehicle: Vehicle, clock: Clock, spec: PreflightSpec, precision: bool,
                        sensors: SensorSuite | None) -> list[str]:
    """Every check; returns the lines of those that passed, raises PreflightFailed listing those that failed."""
    failures, passed = [], []
    try:
        telemetry = await vehicle.telemetry()
    except PrelandError as error:
        raise PreflightFailed([f"link: {error}"]) from None
    passed.append("link: telemetry arriving")
    deadline_s = clock.now_s() + spec.gps_wait_s
    while not telemetry.position_ok and clock.now_s() < deadline_s:
        await clock.sleep(0.5)
        telemetry = await vehicle.telemetry()
    if telemetry.position_ok:
        passed.append("GPS: 3D fix, position estimate healthy")
    else:
        failures.append("GPS: no 3D fix / position estimate not healthy yet")
    if telemetry.battery.remaining_pct < 0:
        passed.append("battery: no charge reported, not checked")
    elif telemetry.battery.remaining_pct < spec.min_battery_pct:
        failures.append(f"battery: {telemetry.battery.remaining_pct:.0f} % is below {spec.min_battery_pct:.0f} %")
    else:
        passed.append(f"battery: {telemetry.battery.remaining_pct:.0f} %")
    if precision:
        for name, wanted in (("PLND_ENABLED", 1.0), ("PLND_TYPE", 1.0)):
            try:
                value = await vehicle.get_param(name)
            except PrelandError as error:
                failures.append(f"{name}: cannot read it ({error})")
                continue
            if value != wanted:
                failures.append(f"{name} is {value:g}, must be {wanted:g} for a precision landing from the companion"
                                + (" (then reboot the autopilot)" if name == "PLND_TYPE" else ""))
            else:
                passed.append(f"{name} = {value:g}")
    camera = sensors.camera if sensors is not None else None
    if camera is not None:
        started_wall = time.monotonic()
        started_s = clock.now_s()

        async def read_frames() -> list:
            frames = []
            for _ in range(spec.camera_check_frames):
                frame = await camera.next_frame()
                if frame is None:
                    break
                frames.append(frame)
            return frames

        # In a task of its own: a task that reads a camera holds a paced vehicle's time until it ends
        # (`preland_app.clock.join`), and this one goes on to wait for the whole mission.
        frames = await asyncio.ensure_future(read_frames())
        elapsed_s = max(clock.now_s() - started_s, 1e-6)
        rate_hz = (len(frames) - 1) / elapsed_s if len(frames) > 1 else 0.0
        expected_hz = camera.camera.frame_rate_hz
        if rate_hz < spec.camera_min_rate_fraction * expected_hz:
            failures.append(f"camera: {rate_hz:.1f} frames/s, expected {expected_hz:g}")
        else:
            passed.append(f"camera: {rate_hz:.1f} frames/s ({time.monotonic() - started_wall:.1f} s wall)")
        if spec.require_pad_visible:
            detector = sensors.marker_detector
            if detector is None or not any(detector.detect(frame.image) for frame in frames):
                failures.append("pad: not in view of the camera")
            else:
                passed.append("pad: in view")
    if failures:
        raise PreflightFailed(failures)
    return passed
