"""Precision land modes `irlock`, `marker` and `fused`: companion-side sensing, onboard landing.

The companion computer runs the sensors (IR-LOCK samples, camera frames through
the marker detector, or both through the thesis' fused sensor) and sends every
new value as a LANDING_TARGET through the Vehicle protocol. The autopilot's own
precision landing (PLND_ENABLED=1, PLND_TYPE=1: companion) steers the LAND
descent onto the target. PLND_STRICT=0: when the target is lost the descent
goes on (the thesis' default operation, Section 6.1).
"""

from __future__ import annotations

import asyncio
from collections import Counter

from ..clock import wait_until
from ..errors import PrelandError
from ..sensing.fusion import FusedSensor
from ..sensing.marker import choose_smallest, reading_from_detection
from ..sensing.readings import TargetReading
from ..vehicle.types import FlightMode
from .base import LandingContext, LandingReport, ScoringReference

PRECLAND_PARAMS = {"PLND_ENABLED": 1, "PLND_TYPE": 1, "PLND_STRICT": 0}


class MissingSensor(PrelandError):
    """A land mode needs a sensor the vehicle does not have."""


class PrecisionLanding:
    """LAND guided by the autopilot's precision landing, fed by `sensor` (irlock, marker or fused)."""

    scoring_reference = ScoringReference.PAD

    def __init__(self, sensor: str) -> None:
        if sensor not in ("irlock", "marker", "fused"):
            raise ValueError(f"unknown precision sensor {sensor!r}")
        self.name = sensor
        self.sensor = sensor
        self.counts: Counter[str] = Counter()
        self._fused: FusedSensor | None = None

    @property
    def uses_irlock(self) -> bool:
        return self.sensor in ("irlock", "fused")

    @property
    def uses_marker(self) -> bool:
        return self.sensor in ("marker", "fused")

    async def land(self, context: LandingContext) -> LandingReport:
        vehicle, clock = context.vehicle, context.clock
        sensors = context.sensors
        if sensors is None or (self.uses_irlock and sensors.irlock is None) or (
                self.uses_marker and (sensors.camera is None or sensors.marker_detector is None)):
            raise MissingSensor(f"land mode {self.name!r} needs "
                                + {"irlock": "an IR-LOCK", "marker": "a camera", "fused": "an IR-LOCK and a camera"}[
                                    self.sensor])
        for name, value in PRECLAND_PARAMS.items():
            await vehicle.set_param(name, value)
        if self.sensor == "fused":
            self._fused = FusedSensor(sensors.spec.fusion)
        tasks = []
        if self.uses_irlock:
            tasks.append(asyncio.ensure_future(self._irlock_loop(context)))
        if self.uses_marker:
            tasks.append(asyncio.ensure_future(self._marker_loop(context)))
        if self._fused is not None:
            tasks.append(asyncio.ensure_future(self._fusion_loop(context)))
        try:
            await vehicle.set_mode(FlightMode.LAND)
            context.events.add("land_command", f"LAND mode set with precision landing ({self.sensor})")

            async def disarmed() -> bool:
                self._raise_if_failed(tasks)
                return not (await vehicle.telemetry()).armed

            async def describe() -> str:
                t = await vehicle.telemetry()
                return f"altitude {t.altitude_rel_m:.1f} m, {t.landed_state.name}"

            await wait_until(disarmed, clock=clock, timeout_s=context.timeout_s, operation="land",
                             poll_period_s=context.poll_period_s, describe=describe)
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
        context.events.add("disarmed", "landed and disarmed")
        details = {f"{key}": value for key, value in sorted(self.counts.items())}
        if self._fused is not None:
            details.update({f"fused_{key}": value for key, value in self._fused.counts.items()})
        return LandingReport(details=details)

    @staticmethod
    def _raise_if_failed(tasks: list[asyncio.Future]) -> None:
        for task in tasks:
            if task.done() and not task.cancelled() and task.exception() is not None:
                raise task.exception()

    async def _deliver(self, context: LandingContext, reading: TargetReading) -> None:
        """A new sensor value: to the fused sensor, or straight to the autopilot."""
        self.counts[f"{reading.sensor}_values"] += 1
        if self._fused is not None:
            self._fused.offer(reading)
            return
        await context.vehicle.send_landing_target(reading.to_landing_target())
        self.counts["landing_targets_sent"] += 1

    async def _irlock_loop(self, context: LandingContext) -> None:
        source = context.sensors.irlock
        while True:
            reading = await source.next_reading()
            self.counts["irlock_samples"] += 1
            if reading is not None:
                await self._deliver(context, reading)

    async def _marker_loop(self, context: LandingContext) -> None:
        camera, detector = context.sensors.camera, context.sensors.marker_detector
        latency_s = context.sensors.spec.marker.processing_latency_s
        while True:
            frame = await camera.next_frame()
            if frame is None:
                return
            detections = detector.detect(frame.image)
            # The reading is ready only after the companion has processed the frame.
            if latency_s > 0:
                await context.clock.sleep(latency_s)
            self.counts["marker_frames"] += 1
            chosen = choose_smallest(detections)
            if chosen is not None:
                await self._deliver(context, reading_from_detection(chosen, capture_time_s=frame.capture_time_s))

    async def _fusion_loop(self, context: LandingContext) -> None:
        period_s = 1.0 / context.sensors.spec.fusion.poll_rate_hz
        while True:
            await context.clock.sleep(period_s)
            value = self._fused.poll(context.clock.now_s())
            if value is not None and value.is_new:
                await context.vehicle.send_landing_target(value.reading.to_landing_target())
                self.counts["landing_targets_sent"] += 1
