"""Precision land modes `irlock`, `marker`, `fused` and `cautious`: companion-side sensing, onboard landing.

The companion computer runs the sensors (IR-LOCK samples, camera frames through
the marker detector, or both through the thesis' fused sensor), drops values as
the trial's faults say, and sends every remaining new value as a LANDING_TARGET
through the Vehicle protocol. The autopilot's own precision landing
(PLND_ENABLED=1, PLND_TYPE=1: companion) steers the LAND descent onto the
target. The plain modes set PLND_STRICT=0 (the thesis' default operation: when
the target is lost the descent goes on); `cautious` sets ArduPilot's retry
parameters of its `CautiousSpec` and runs the thesis' cautious sequence on the
companion (`cautious_retry.py`).
"""

from __future__ import annotations

import asyncio
from collections import Counter, deque

from ..clock import join, wait_until
from ..errors import CommandDenied, PrelandError
from ..sensing.faults import FaultCommand, FaultSpec
from ..sensing.fusion import FusedSensor
from ..sensing.marker import choose_smallest, reading_from_detection
from ..sensing.readings import TargetReading
from ..vehicle.types import FlightMode
from .attempts import AttemptTracker
from .fault_gate import FaultGate
from .base import LandingContext, LandingReport, ScoringReference
from .cautious import CautiousSpec
from .cautious_retry import CompanionRetry

SENSORS = ("irlock", "marker", "fused")
TELEMETRY_PERIOD_S = 0.1


async def _has_param(vehicle, name: str) -> bool:
    """Whether the autopilot has parameter `name` (one that answers no read of it has not)."""
    try:
        await vehicle.get_param(name)
    except CommandDenied:
        return False
    return True


class MissingSensor(PrelandError):
    """A land mode needs a sensor the vehicle does not have."""


class PrecisionLanding:
    """LAND guided by the autopilot's precision landing, fed by `sensor` (irlock, marker or fused)."""

    scoring_reference = ScoringReference.PAD

    def __init__(self, sensor: str, *, faults: dict[str, FaultSpec] | None = None,
                 cautious: CautiousSpec | None = None) -> None:
        if sensor not in SENSORS:
            raise ValueError(f"unknown precision sensor {sensor!r} (expected one of: {', '.join(SENSORS)})")
        self.sensor = sensor
        self.name = "cautious" if cautious is not None else sensor
        self.cautious = cautious
        self.faults = dict(faults or {})
        self.counts: Counter[str] = Counter()
        self.gate: FaultGate | None = None
        self.attempts = AttemptTracker()
        self._fused: FusedSensor | None = None
        self._height_m: float | None = None
        self._retry: CompanionRetry | None = None
        self._outbox: deque[tuple[float, TargetReading]] = deque()  # delayed values on their way: (arrival s, value)
        self._courier: asyncio.Future | None = None

    @property
    def attempt(self) -> int:
        """The landing attempt now under way (1 first): the companion's count for the cautious mode, else
        counted from the autopilot's climbs in LAND."""
        return self._retry.attempt if self._retry is not None else self.attempts.attempt

    @property
    def uses_irlock(self) -> bool:
        return self.sensor in ("irlock", "fused")

    @property
    def uses_marker(self) -> bool:
        return self.sensor in ("marker", "fused")

    def apply_fault_command(self, command: FaultCommand) -> None:
        """The thesis' runtime fault command: change the faults of the targeted sensors this mode uses."""
        used = {"irlock": self.uses_irlock, "marker": self.uses_marker}
        for sensor, spec in command.faults().items():
            if not used[sensor]:
                continue  # as the thesis' front-ends ignore commands for another subsystem
            if self.gate is not None:
                self.gate.set_spec(sensor, spec)
            self.faults[sensor] = spec

    async def _configure(self, context: LandingContext) -> None:
        vehicle = context.vehicle
        params: dict[str, float] = {"PLND_ENABLED": 1, "PLND_TYPE": 1}
        if self.cautious is None:
            # ArduCopter before 4.1 has no PLND_STRICT: a lost target never held its descent, as 0 does not.
            if await _has_param(vehicle, "PLND_STRICT"):
                params["PLND_STRICT"] = 0
        else:
            params.update(self.cautious.ardupilot_params())
        for name, value in params.items():
            await vehicle.set_param(name, value)
        if self.cautious is not None:
            self._retry = CompanionRetry(spec=self.cautious, vehicle=vehicle, clock=context.clock,
                                         events=context.events)

    async def land(self, context: LandingContext) -> LandingReport:
        vehicle, clock = context.vehicle, context.clock
        sensors = context.sensors
        if sensors is None or (self.uses_irlock and sensors.irlock is None) or (
                self.uses_marker and (sensors.camera is None or sensors.marker_detector is None)):
            need = {"irlock": "an IR-LOCK", "marker": "a camera", "fused": "an IR-LOCK and a camera"}[self.sensor]
            raise MissingSensor(f"land mode {self.name!r} with sensor {self.sensor!r} needs {need}")
        await self._configure(context)
        used = [sensor for sensor in ("irlock", "marker") if getattr(self, f"uses_{sensor}")]
        self.gate = FaultGate(faults=self.faults, sensors=used, rng=context.rng, streams=("irlock", "marker"))
        if self.sensor == "fused":
            self._fused = FusedSensor(sensors.spec.fusion)
        self._height_m = (await vehicle.telemetry()).height_above_ground_m
        tasks = [asyncio.ensure_future(self._telemetry_loop(context))]
        if self.uses_irlock:
            tasks.append(asyncio.ensure_future(self._irlock_loop(context)))
        if self.uses_marker:
            tasks.append(asyncio.ensure_future(self._marker_loop(context)))
        if self._fused is not None:
            tasks.append(asyncio.ensure_future(self._fusion_loop(context)))
        try:
            await vehicle.set_mode(FlightMode.LAND)
            faults = ", ".join(f"{s} {f}" for s, f in sorted(self.faults.items()) if f.active) or "no faults"
            context.events.add("land_command", f"LAND with precision landing ({self.name}, {self.sensor}; {faults})")

            async def disarmed() -> bool:
                self._raise_if_failed([*tasks, *([self._courier] if self._courier is not None else [])])
                return not (await vehicle.telemetry()).armed

            async def describe() -> str:
                t = await vehicle.telemetry()
                return f"altitude {t.altitude_rel_m:.1f} m, {t.landed_state.name}, attempt {self.attempt}"

            await wait_until(disarmed, clock=clock, timeout_s=context.timeout_s, operation="land",
                             poll_period_s=context.poll_period_s, describe=describe)
        finally:
            carriers = [self._courier] if self._courier is not None else []
            for task in [*tasks, *carriers]:
                task.cancel()
            await asyncio.gather(*tasks, *carriers, return_exceptions=True)
        context.events.add("disarmed", "landed and disarmed")
        return LandingReport(details=self._details())

    def _details(self) -> dict:
        details: dict = {"sensor": self.sensor, "attempts": self.attempt}
        if self._retry is not None:
            details["cautious_pauses"] = self._retry.pauses
            details["cautious_retries"] = self._retry.retries
        details.update({key: value for key, value in sorted(self.counts.items())})
        if self.gate is not None:
            details.update(self.gate.details())
        if self._fused is not None:
            details.update({f"fused_{key}": value for key, value in self._fused.counts.items()})
        return details

    @staticmethod
    def _raise_if_failed(tasks: list[asyncio.Future]) -> None:
        for task in tasks:
            if task.done() and not task.cancelled() and task.exception() is not None:
                raise task.exception()

    async def _telemetry_loop(self, context: LandingContext) -> None:
        """Keep the height the faults gate on, and count attempts."""
        while True:
            t = await context.vehicle.telemetry()
            self._height_m = t.height_above_ground_m
            if self._retry is not None:
                await self._retry.step(t)
            elif t.mode is FlightMode.LAND and self.attempts.update(t.altitude_rel_m):
                context.events.add("attempt", f"landing attempt {self.attempts.attempt} started",
                                   attempt=self.attempts.attempt, altitude_rel_m=round(t.altitude_rel_m, 2))
            await context.clock.sleep(TELEMETRY_PERIOD_S)

    async def _deliver(self, context: LandingContext, reading: TargetReading) -> None:
        """A new sensor value: through the fault injector, then, when it arrives (a delay fault holds it
        back), to the fused sensor or the autopilot."""
        if self.gate is not None:
            reading = self.gate.apply(reading.sensor, reading, height_m=self._height_m, attempt=self.attempt)
            if reading is None:
                return
            now_s = context.clock.now_s()
            arrival_s = self.gate.arrival_s(reading.sensor, now_s, attempt=self.attempt)
            if arrival_s > now_s or self._outbox:
                self._outbox.append((arrival_s, reading))
                if self._courier is None or self._courier.done():
                    if self._courier is not None:
                        self._raise_if_failed([self._courier])  # not lost under the next courier
                    self._courier = asyncio.ensure_future(self._carry(context))
                return
        await self._hand_on(context, reading)

    async def _carry(self, context: LandingContext) -> None:
        """Hands the delayed values on at their arrival times, in order, until none is on its way (one task
        for them all, so two that arrive at the same time keep their order; it reads no sensor but hands
        values on, so on a lock-step clock time waits for it as for the sensor tasks)."""
        join(context.clock)
        while self._outbox:
            arrival_s, reading = self._outbox[0]
            wait_s = arrival_s - context.clock.now_s()
            if wait_s > 0:
                await context.clock.sleep(wait_s)
            self._outbox.popleft()
            await self._hand_on(context, reading)

    async def _hand_on(self, context: LandingContext, reading: TargetReading) -> None:
        if self._fused is not None:
            self._fused.offer(reading)
            return
        await context.vehicle.send_landing_target(reading.to_landing_target())
        self._sent()

    def _sent(self) -> None:
        self.counts["landing_targets_sent"] += 1
        if self._retry is not None:
            self._retry.note_target()

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
            detections = detector.detect_frame(frame)
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
                self._sent()
