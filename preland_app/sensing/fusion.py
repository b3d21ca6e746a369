"""The fused sensor of the thesis (Section 5.2): IR-LOCK and marker combined.

Each poll looks at what is *new* since the previous poll:

* both sensors new: weighted average of the horizontal values (the angles);
  distance from the marker;
* only one new: that value alone (no mixing with the other's older value);
* none new: the stored value while it is fresher than `freshness_s` (1 s, as
  in the IR-LOCK and marker subsystems), else no valid value.

Distance comes from the marker when it has one; otherwise the value has none
and the autopilot uses its rangefinder or barometer.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import require
from .readings import TargetReading


@dataclass(frozen=True)
class FusionSpec:
    """Weights of the weighted average (normalised), freshness in s, and the front-end's poll rate in Hz.

    ArduPilot polls its precision-landing front-end at 400 Hz; at that rate the
    two sensors are almost never new in the same poll. The default 50 Hz (the
    IR-LOCK's own rate) makes every marker value meet an IR-LOCK value, so the
    weighted average applies whenever both see the target.
    """

    weight_irlock: float = 0.5
    weight_marker: float = 0.5
    freshness_s: float = 1.0
    poll_rate_hz: float = 50.0

    def __post_init__(self) -> None:
        require(self.weight_irlock >= 0 and self.weight_marker >= 0, "weight_irlock", "weights must be >= 0")
        require(self.weight_irlock + self.weight_marker > 0, "weight_marker", "weights must not both be 0")
        require(self.freshness_s > 0, "freshness_s", "must be > 0 s")
        require(0 < self.poll_rate_hz <= 1000, "poll_rate_hz", "must be within 0..1000 Hz")


@dataclass(frozen=True, slots=True)
class FusedValue:
    """A fused value and whether it is new in this poll (`source`: both, irlock, marker, stored)."""

    reading: TargetReading
    is_new: bool
    source: str


class FusedSensor:
    """The fusion front-end. Feed it new readings with `offer`, then `poll`."""

    def __init__(self, spec: FusionSpec = FusionSpec()) -> None:
        self.spec = spec
        self._new_irlock: TargetReading | None = None
        self._new_marker: TargetReading | None = None
        self._stored: TargetReading | None = None
        self._stored_time_s = 0.0
        self.counts = {"both": 0, "irlock": 0, "marker": 0, "stored": 0, "invalid": 0}

    def offer(self, reading: TargetReading) -> None:
        """A new value from a back-end (IR-LOCK or marker). The latest one per sensor wins."""
        if reading.sensor == "irlock":
            self._new_irlock = reading
        elif reading.sensor == "marker":
            self._new_marker = reading
        else:
            raise ValueError(f"fused sensor takes irlock or marker readings, not {reading.sensor!r}")

    def poll(self, now_s: float) -> FusedValue | None:
        """The value to hand to the autopilot now, or None when there is no valid value."""
        irlock, marker = self._new_irlock, self._new_marker
        self._new_irlock = self._new_marker = None
        if irlock is not None and marker is not None:
            w_i, w_m = self.spec.weight_irlock, self.spec.weight_marker
            total = w_i + w_m
            fused = TargetReading(
                sensor="fused",
                capture_time_s=max(irlock.capture_time_s, marker.capture_time_s),
                angle_x_rad=(w_i * irlock.angle_x_rad + w_m * marker.angle_x_rad) / total,
                angle_y_rad=(w_i * irlock.angle_y_rad + w_m * marker.angle_y_rad) / total,
                distance_m=marker.distance_m,
                marker_id=marker.marker_id,
            )
            return self._store(fused, now_s, "both")
        if irlock is not None or marker is not None:
            single = irlock if irlock is not None else marker
            source = single.sensor
            fused = TargetReading(sensor="fused", capture_time_s=single.capture_time_s,
                                  angle_x_rad=single.angle_x_rad, angle_y_rad=single.angle_y_rad,
                                  distance_m=single.distance_m, marker_id=single.marker_id)
            return self._store(fused, now_s, source)
        if self._stored is not None and now_s - self._stored_time_s <= self.spec.freshness_s:
            self.counts["stored"] += 1
            return FusedValue(self._stored, is_new=False, source="stored")
        self.counts["invalid"] += 1
        return None

    def _store(self, reading: TargetReading, now_s: float, source: str) -> FusedValue:
        self._stored = reading
        self._stored_time_s = now_s
        self.counts[source] += 1
        return FusedValue(reading, is_new=True, source=source)
