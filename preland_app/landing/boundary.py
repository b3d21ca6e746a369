"""The truth boundary: a land mode holds views, never the runtime's objects.

A `LandingContext` gives a land mode the Vehicle protocol, the clock, the event
log and the sensor suite as views. A view has no attributes of its own
(`__slots__` holds only its weak-reference slot); its methods forward through a
table private to this module, keyed by the view. So nothing reachable from a
context (attributes, properties, bound methods' `__self__`, closures) leads to
a Simulator, a vehicle backend, or the functions that give the virtual sensors
the true pose: the vehicle view offers exactly the Vehicle protocol, the sensor
views give images, detections and readings. (Python cannot wall off objects
from code that goes looking for them, e.g. through `gc`; a land mode that does
breaks the contract; see the docs, "Your own land mode".)

For a plugin, the sensor views also apply the mission's faults (`land.faults`)
to what they deliver; the built-in precision modes apply their own.
"""

from __future__ import annotations

import weakref
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from ..clock import Clock
from ..errors import PrelandError
from ..events import EventLog, MissionEvent
from ..sensing.camera import CameraModel, Frame
from ..sensing.faults import FaultSpec
from ..sensing.marker import MarkerDetection
from ..sensing.readings import TargetReading
from ..sensing.spec import SensorsSpec
from ..vehicle.protocol import Vehicle
from ..vehicle.types import FlightMode, LandingTarget, PositionNed, Telemetry, VelocityNed
from .attempts import AttemptTracker
from .fault_gate import FaultGate

V = TypeVar("V")

# view -> what it forwards to. Only this module reads it; a view holds no reference to its target.
_TARGETS: weakref.WeakKeyDictionary[object, Any] = weakref.WeakKeyDictionary()


class BoundaryError(PrelandError):
    """A land mode asked for something outside its contract (connecting or closing the vehicle)."""


class ClockView:
    """The vehicle's clock: `now_s()` and `sleep(duration_s)`, in vehicle seconds."""

    __slots__ = ("__weakref__",)

    def __init__(self, clock: Clock) -> None:
        _TARGETS[self] = clock

    def now_s(self) -> float:
        """Vehicle seconds since an arbitrary epoch (monotonic)."""
        return _TARGETS[self].now_s()

    async def sleep(self, duration_s: float) -> None:
        """Sleep `duration_s` vehicle seconds."""
        await _TARGETS[self].sleep(duration_s)


def as_clock_view(clock: Clock) -> ClockView:
    return clock if isinstance(clock, ClockView) else ClockView(clock)


class VehicleView:
    """The Vehicle protocol (vehicle/protocol.py) and nothing more. Commands go through the mission's
    pilot-takeover guard; `connect()` and `close()` are refused: the mission owns the link."""

    __slots__ = ("__weakref__",)

    def __init__(self, vehicle: Vehicle) -> None:
        _TARGETS[self] = (vehicle, as_clock_view(vehicle.clock))

    def _vehicle(self) -> Vehicle:
        return _TARGETS[self][0]

    @property
    def clock(self) -> ClockView:
        """The vehicle's clock."""
        return _TARGETS[self][1]

    async def connect(self) -> None:
        """Refused: the mission owns the link."""
        raise BoundaryError("a land mode may not connect the vehicle: the mission owns the link")

    async def close(self) -> None:
        """Refused: the mission owns the link."""
        raise BoundaryError("a land mode may not close the vehicle: the mission owns the link")

    async def arm(self) -> None:
        await self._vehicle().arm()

    async def disarm(self) -> None:
        await self._vehicle().disarm()

    async def takeoff(self, *, altitude_rel_m: float) -> None:
        await self._vehicle().takeoff(altitude_rel_m=altitude_rel_m)

    async def goto_ned(self, *, position_ned_m: PositionNed, yaw_deg: float | None = None) -> None:
        await self._vehicle().goto_ned(position_ned_m=position_ned_m, yaw_deg=yaw_deg)

    async def goto_global(self, *, latitude_deg: float, longitude_deg: float, altitude_rel_m: float) -> None:
        await self._vehicle().goto_global(latitude_deg=latitude_deg, longitude_deg=longitude_deg,
                                          altitude_rel_m=altitude_rel_m)

    async def set_velocity_ned(self, *, velocity_ned_m_s: VelocityNed, yaw_deg: float | None = None) -> None:
        await self._vehicle().set_velocity_ned(velocity_ned_m_s=velocity_ned_m_s, yaw_deg=yaw_deg)

    async def set_velocity_body(self, *, forward_m_s: float, right_m_s: float, down_m_s: float,
                                yaw_rate_deg_s: float = 0.0) -> None:
        await self._vehicle().set_velocity_body(forward_m_s=forward_m_s, right_m_s=right_m_s, down_m_s=down_m_s,
                                                yaw_rate_deg_s=yaw_rate_deg_s)

    async def hold(self) -> None:
        await self._vehicle().hold()

    async def set_mode(self, mode: FlightMode) -> None:
        await self._vehicle().set_mode(mode)

    async def get_param(self, name: str) -> float:
        return await self._vehicle().get_param(name)

    async def set_param(self, name: str, value: float) -> None:
        await self._vehicle().set_param(name, value)

    async def telemetry(self) -> Telemetry:
        return await self._vehicle().telemetry()

    async def send_landing_target(self, target: LandingTarget) -> None:
        await self._vehicle().send_landing_target(target)


def as_vehicle_view(vehicle: Vehicle) -> VehicleView:
    return vehicle if isinstance(vehicle, VehicleView) else VehicleView(vehicle)


class EventView:
    """The trial's event log: `add(kind, message, **data)` stamps an event with the vehicle clock."""

    __slots__ = ("__weakref__",)

    def __init__(self, events: EventLog) -> None:
        _TARGETS[self] = events

    def add(self, kind: str, message: str, **data: Any) -> MissionEvent:
        """Log an event; `data` values should carry their unit in their name (altitude_rel_m=...)."""
        return _TARGETS[self].add(kind, message, **data)

    def first(self, kind: str) -> MissionEvent | None:
        return _TARGETS[self].first(kind)

    def all(self, kind: str) -> list[MissionEvent]:
        return _TARGETS[self].all(kind)

    @property
    def events(self) -> tuple[MissionEvent, ...]:
        """Every event so far, oldest first."""
        return tuple(_TARGETS[self].events)


def as_event_view(events: EventLog) -> EventView:
    return events if isinstance(events, EventView) else EventView(events)


class SensorFaults:
    """The mission's faults (`land.faults`) applied to the readings a plugin gets, as the built-in modes
    apply them to theirs: per sensor, on each new value, gated on the height above ground the vehicle
    reports and on the landing attempt (a climb of 0.5 m after the hand-over starts a new one); a delayed
    value reaches the plugin at the first of its reads at or after its arrival on `clock`."""

    def __init__(self, *, faults: Mapping[str, FaultSpec], rng: np.random.Generator, clock: Clock) -> None:
        self.gate = FaultGate(faults=faults, sensors=sorted(faults), rng=rng,
                              streams=("irlock", "marker") if faults else ())
        self.clock = clock
        self.attempts = AttemptTracker()
        self.height_m: float | None = None
        self.landing = False

    def observe(self, telemetry: Telemetry) -> None:
        """Feed every telemetry snapshot the mission reads."""
        self.height_m = telemetry.height_above_ground_m
        if self.landing:
            self.attempts.update(telemetry.altitude_rel_m)

    def apply(self, sensor: str, value: V | None) -> V | None:
        """A read of `sensor` with its new value (None: it has none): what the plugin gets (None: nothing, as
        when the value was dropped; see `FaultGate.take`)."""
        return self.gate.take(sensor, value, now_s=self.clock.now_s(), height_m=self.height_m,
                              attempt=self.attempts.attempt)

    def details(self) -> dict[str, Any]:
        """Per sensor: the fault, the values produced and the values dropped (as the built-in modes report)."""
        return self.gate.details()


class CameraView:
    """The companion's camera: `next_frame()` waits for the next frame (image, capture time); `camera` is
    its model (intrinsics in px, frame rate in Hz, mount offset in m, body FRD)."""

    __slots__ = ("__weakref__",)

    def __init__(self, source: Any) -> None:
        _TARGETS[self] = source

    @property
    def camera(self) -> CameraModel:
        return _TARGETS[self].camera

    async def next_frame(self) -> Frame | None:
        """The next frame on the vehicle clock, or None when the camera has stopped."""
        return await _TARGETS[self].next_frame()


class DetectorView:
    """The pad's marker detector: `detect(image)` gives the pad's markers in an image, with poses (camera
    frame: x right, y down in the image = body backward, z along the optical axis = body down; metres).
    For a plugin, a fault that drops this value gives no detections."""

    __slots__ = ("__weakref__",)

    def __init__(self, detector: Any, faults: SensorFaults | None) -> None:
        _TARGETS[self] = (detector, faults)

    def detect(self, image: np.ndarray) -> list[MarkerDetection]:
        detector, faults = _TARGETS[self]
        return self._admitted(detector.detect(image), faults)

    def detect_frame(self, frame: Frame) -> list[MarkerDetection]:
        """`detect` on a camera frame: a virtual camera then draws only the part the detector reads."""
        detector, faults = _TARGETS[self]
        return self._admitted(detector.detect_frame(frame), faults)

    @staticmethod
    def _admitted(detections: list[MarkerDetection], faults: SensorFaults | None) -> list[MarkerDetection]:
        if faults is not None:
            return faults.apply("marker", detections or None) or []
        return detections


class IrLockView:
    """The IR-LOCK: `next_reading()` waits for the next sample (angles to the beacon in rad, body FRD, as
    LANDING_TARGET; no distance); None when the beacon is not seen or a fault dropped the value."""

    __slots__ = ("__weakref__",)

    def __init__(self, source: Any, faults: SensorFaults | None) -> None:
        _TARGETS[self] = (source, faults)

    async def next_reading(self) -> TargetReading | None:
        source, faults = _TARGETS[self]
        reading = await source.next_reading()
        if faults is not None:
            return faults.apply("irlock", reading)
        return reading


@dataclass(frozen=True, slots=True, kw_only=True)
class MarkerFrame:
    """One processed camera frame: when it was captured (vehicle s), its index, and the pad's markers found
    in it (empty when none was seen, or a fault dropped the value)."""

    capture_time_s: float
    frame_index: int
    detections: tuple[MarkerDetection, ...]


class SensorView:
    """The companion's sensors, as readings. `camera` / `marker_detector` / `irlock` are None where the
    land mode did not ask for them (`uses_marker`, `uses_irlock`) or the vehicle has none; `spec` is the
    mission's `sensors:` section."""

    __slots__ = ("__weakref__",)

    def __init__(self, *, spec: SensorsSpec, camera: Any = None, marker_detector: Any = None, irlock: Any = None,
                 clock: Clock, faults: SensorFaults | None = None) -> None:
        _TARGETS[self] = (
            spec,
            CameraView(camera) if camera is not None else None,
            DetectorView(marker_detector, faults) if marker_detector is not None else None,
            IrLockView(irlock, faults) if irlock is not None else None,
            as_clock_view(clock),
        )

    @property
    def spec(self) -> SensorsSpec:
        return _TARGETS[self][0]

    @property
    def camera(self) -> CameraView | None:
        return _TARGETS[self][1]

    @property
    def marker_detector(self) -> DetectorView | None:
        return _TARGETS[self][2]

    @property
    def irlock(self) -> IrLockView | None:
        return _TARGETS[self][3]

    async def next_markers(self) -> MarkerFrame | None:
        """The next frame's marker detections, ready once the companion has processed it (after
        `sensors.marker.processing_latency_s`, as the built-in modes); None when the camera has stopped."""
        _, camera, detector, _, clock = _TARGETS[self]
        if camera is None or detector is None:
            raise BoundaryError("no camera: a land mode that reads markers must set uses_marker = True")
        frame = await camera.next_frame()
        if frame is None:
            return None
        detections = detector.detect_frame(frame)
        latency_s = self.spec.marker.processing_latency_s
        if latency_s > 0:
            await clock.sleep(latency_s)
        return MarkerFrame(capture_time_s=frame.capture_time_s, frame_index=frame.index,
                           detections=tuple(detections))


def as_sensor_view(suite: Any, *, clock: Clock, faults: SensorFaults | None = None) -> SensorView:
    """A readings-only view of a SensorSuite (`faults`: applied to the readings, for plugins)."""
    if isinstance(suite, SensorView):
        return suite
    return SensorView(spec=suite.spec, camera=suite.camera, marker_detector=suite.marker_detector,
                      irlock=suite.irlock, clock=clock, faults=faults)
