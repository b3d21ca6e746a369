"""The paper's companion-side marker landing: static Algorithm 1 and adaptive Algorithm 2.

The companion reads marker detections and telemetry and steers the vehicle with
GUIDED velocity setpoints (body frame), never through the autopilot's precision
landing. Per processed frame:

* no marker: Algorithm 1 holds position (the paper's "loiter"); Algorithm 2
  holds too, and once the marker has been out of view for `recovery_after_s`
  (1 s) recovers by climbing 1 m (once per loss) to widen the view. After 30 s
  without a detection the landing is aborted to a plain GPS landing (LAND);
* a marker: Algorithm 1 takes the highest id in view. Algorithm 2 records the
  altitude at which each id is first seen (its activation level) and switches
  to a higher id only below half of that level; a frame without its chosen
  marker counts as a frame without a detection, so it never glitches back;
* beta_x = |atan(x/z)|, beta_y = |atan(y/z)| from the chosen marker's position
  in the camera frame; alpha = 20 deg above z2 = 13 m, else 10 deg; beyond the
  border the vehicle moves horizontally towards the marker, first along the
  roll axis then along the pitch axis (as ArduSim's channel overrides do),
  else it descends;
* below z1 = 0.3 m the autopilot's LAND takes over and disarms.

Speeds are the paper's stick and throttle fractions times full-scale speeds
(see `PaperSpec`): Algorithm 1 moves at 5 % and descends at 10 %; Algorithm 2
moves at v1 = 15 % farther than 1 m from the marker and v2 = 5 % nearer, and
descends at min(60 %, altitude x 2 %) above 6 m, else v3 = 10 % (Equation 1).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

from ..clock import wait_until
from ..errors import WaitTimeout, require
from ..sensing.faults import FaultSpec
from .fault_gate import FaultGate
from ..sensing.marker import MarkerDetection
from ..vehicle.types import FlightMode
from .base import LandingContext, LandingReport, ScoringReference


@dataclass(frozen=True)
class PaperSpec:
    """The paper's parameters (Tables 1 and 2, Equation 1) and the full-scale speeds the percentages map to.

    The paper commands ArduSim with stick and throttle fractions. Vertically,
    full throttle travel asks ArduCopter for PILOT_SPEED_UP (2.5 m/s), so
    Algorithm 1's 10 % is 0.25 m/s, close to the 0.3 m/s the paper measured,
    and Equation 1's 60 % cap is 1.5 m/s. Horizontally the paper reports no
    speed; full stick is taken as 5 m/s, ArduCopter's navigation speed at the
    time (WPNAV_SPEED = 500 cm/s in Copter 3.6), which makes v1 0.75 m/s and
    v2 0.25 m/s. With LOIT_SPEED's 12.5 m/s instead, the 5 % correction
    overshoots the 10 deg border near the ground and the landing oscillates.
    """

    z1_m: float = 0.30
    z2_m: float = 13.0
    recovery_after_s: float = 1.0
    alpha_high_deg: float = 20.0
    alpha_low_deg: float = 10.0
    abort_after_s: float = 30.0
    recovery_climb_m: float = 1.0
    near_m: float = 1.0
    v1_pct: float = 15.0
    v2_pct: float = 5.0
    v3_pct: float = 10.0
    static_move_pct: float = 5.0
    static_descend_pct: float = 10.0
    descent_cap_pct: float = 60.0
    descent_pct_per_m: float = 2.0
    fast_descent_above_m: float = 6.0
    horizontal_full_scale_m_s: float = 5.0
    vertical_full_scale_m_s: float = 2.5

    def __post_init__(self) -> None:
        require(0 < self.z1_m < self.z2_m, "z1_m", "must be > 0 and below z2_m")
        require(0 < self.alpha_low_deg <= self.alpha_high_deg < 60, "alpha_low_deg", "must be within 0..alpha_high_deg")
        require(self.abort_after_s > 0, "abort_after_s", "must be > 0 s")
        require(self.horizontal_full_scale_m_s > 0 and self.vertical_full_scale_m_s > 0, "horizontal_full_scale_m_s",
                "full-scale speeds must be > 0")
        for name in ("v1_pct", "v2_pct", "v3_pct", "static_move_pct", "static_descend_pct", "descent_cap_pct"):
            require(0 < getattr(self, name) <= 100, name, "must be within 0..100 %")


class Action(enum.Enum):
    HOLD = "hold"  # Algorithm 1: no marker, loiter in place
    RECOVER = "recover"  # Algorithm 2: no marker, climb to widen the view
    MOVE = "move"
    DESCEND = "descend"


@dataclass(frozen=True, slots=True)
class Command:
    """What to do this frame: body-frame velocity in m/s (forward, right, down) and why."""

    action: Action
    forward_m_s: float = 0.0
    right_m_s: float = 0.0
    down_m_s: float = 0.0
    marker_id: int | None = None
    alpha_deg: float | None = None


@dataclass
class PaperPolicy:
    """The decision part of Algorithms 1 and 2, free of I/O (so it can be tested frame by frame)."""

    adaptive: bool
    spec: PaperSpec = field(default_factory=PaperSpec)
    selected_id: int | None = None
    activation_m: dict[int, float] = field(default_factory=dict)
    switches: list[tuple[float, int | None, int, float]] = field(default_factory=list)
    recovery_climbs: int = 0
    recovery_target_m: float | None = None
    _last_seen_s: float | None = None

    def _percent(self, pct: float, full_scale: float) -> float:
        return pct / 100.0 * full_scale

    def descent_speed_m_s(self, altitude_m: float) -> float:
        s = self.spec
        if not self.adaptive:
            return self._percent(s.static_descend_pct, s.vertical_full_scale_m_s)
        if altitude_m > s.fast_descent_above_m:
            pct = min(s.descent_cap_pct, altitude_m * s.descent_pct_per_m)
        else:
            pct = s.v3_pct
        return self._percent(pct, s.vertical_full_scale_m_s)

    def horizontal_speed_m_s(self, distance_m: float) -> float:
        s = self.spec
        if not self.adaptive:
            pct = s.static_move_pct
        else:
            pct = s.v1_pct if distance_m > s.near_m else s.v2_pct
        return self._percent(pct, s.horizontal_full_scale_m_s)

    def choose(self, detections: list[MarkerDetection], *, altitude_m: float,
               time_s: float) -> MarkerDetection | None:
        """The marker to steer by this frame, or None (Algorithm 2, when its marker is not in view)."""
        by_id = {d.marker_id: d for d in detections}
        if not self.adaptive:
            chosen = max(by_id)  # Algorithm 1: the highest id in view, whatever it was a frame ago
        else:
            for marker_id in sorted(by_id):
                self.activation_m.setdefault(marker_id, altitude_m)
            if self.selected_id is None:
                chosen = min(by_id)  # start from the largest marker, as the paper's flights did
            else:
                # Switch only to a smaller (higher-id) marker, and only below half its activation level;
                # a frame without the chosen marker is a frame without a detection (no glitching back).
                eligible = [i for i in sorted(by_id) if i > self.selected_id
                            and altitude_m < self.activation_m[i] / 2.0]
                chosen = eligible[-1] if eligible else self.selected_id
                if chosen not in by_id:
                    return None
        if chosen != self.selected_id:
            self.switches.append((time_s, self.selected_id, chosen, altitude_m))
            self.selected_id = chosen
        return by_id[chosen]

    def step(self, detections: list[MarkerDetection], *, altitude_m: float, time_s: float) -> Command:
        """One frame's decision. `detections` are the pad's markers found in it."""
        s = self.spec
        marker = self.choose(detections, altitude_m=altitude_m, time_s=time_s) if detections else None
        if marker is None:
            if self._last_seen_s is None:
                self._last_seen_s = time_s
            if not self.adaptive or time_s - self._last_seen_s < s.recovery_after_s:
                return Command(Action.HOLD)
            if self.recovery_target_m is None:
                self.recovery_target_m = altitude_m + s.recovery_climb_m
                self.recovery_climbs += 1
            if altitude_m < self.recovery_target_m:
                return Command(Action.RECOVER, down_m_s=-self._percent(s.v3_pct, s.vertical_full_scale_m_s))
            return Command(Action.HOLD)
        self._last_seen_s = time_s
        self.recovery_target_m = None
        x, y, z = (float(v) for v in marker.tvec)
        alpha_deg = s.alpha_high_deg if z > s.z2_m else s.alpha_low_deg
        beta_x = math.degrees(abs(math.atan2(x, z)))
        beta_y = math.degrees(abs(math.atan2(y, z)))
        if beta_x > alpha_deg or beta_y > alpha_deg:
            speed = self.horizontal_speed_m_s(math.hypot(x, y))
            # One axis at a time: roll (camera x = body right) first, then pitch (camera y = body backward).
            if beta_x > alpha_deg:
                return Command(Action.MOVE, right_m_s=math.copysign(speed, x), marker_id=marker.marker_id,
                               alpha_deg=alpha_deg)
            return Command(Action.MOVE, forward_m_s=-math.copysign(speed, y), marker_id=marker.marker_id,
                           alpha_deg=alpha_deg)
        return Command(Action.DESCEND, down_m_s=self.descent_speed_m_s(altitude_m), marker_id=marker.marker_id,
                       alpha_deg=alpha_deg)


class PaperLanding:
    """The paper's Algorithm 1 (static) or 2 (adaptive), flown by the companion in GUIDED."""

    scoring_reference = ScoringReference.PAD
    uses_irlock = False
    uses_marker = True

    def __init__(self, *, adaptive: bool, spec: PaperSpec | None = None,
                 marker_fault: FaultSpec | None = None) -> None:
        self.adaptive = adaptive
        self.marker_fault = marker_fault or FaultSpec()
        self.gate: FaultGate | None = None
        self.name = "paper_adaptive" if adaptive else "paper_static"
        self.policy = PaperPolicy(adaptive=adaptive, spec=spec or PaperSpec())
        self.aborted_to_gps = False
        self.frames = 0
        self.frames_with_marker = 0
        self.first_detection_altitude_m: float | None = None

    async def land(self, context: LandingContext) -> LandingReport:
        from .precision import MissingSensor

        sensors = context.sensors
        if sensors is None or sensors.camera is None or sensors.marker_detector is None:
            raise MissingSensor(f"land mode {self.name!r} needs a camera")
        vehicle, clock, spec = context.vehicle, context.clock, self.policy.spec
        camera, detector = sensors.camera, sensors.marker_detector
        latency_s = sensors.spec.marker.processing_latency_s
        self.gate = FaultGate(faults={"marker": self.marker_fault}, sensors=("marker",), rng=context.rng,
                              streams=("marker",))
        context.events.add("land_command", f"{self.name}: the companion takes over the landing")
        started_s = clock.now_s()
        last_detection_s = started_s
        deadline_s = started_s + context.timeout_s
        while True:
            frame = await camera.next_frame()
            if frame is None:
                raise MissingSensor(f"{self.name}: the camera stopped delivering frames")
            detections = detector.detect_frame(frame)
            if latency_s > 0:
                await clock.sleep(latency_s)
            self.frames += 1
            telemetry = await vehicle.telemetry()
            # The algorithm's "altitude": height above the ground (rangefinder when in range, else barometer).
            altitude_m = telemetry.height_above_ground_m
            now_s = clock.now_s()
            # A frame with markers is a value: the fault may drop it, give an older one or hold it back.
            detections = self.gate.take("marker", detections or None, now_s=now_s,
                                        height_m=telemetry.height_above_ground_m) or []
            if altitude_m <= spec.z1_m:
                context.events.add("handover", f"below z1 ({spec.z1_m:g} m): LAND", altitude_rel_m=altitude_m)
                break
            if detections:
                self.frames_with_marker += 1
                last_detection_s = now_s
                if self.first_detection_altitude_m is None:
                    self.first_detection_altitude_m = altitude_m
                    context.events.add("detected", "first marker detection", altitude_rel_m=round(altitude_m, 2))
            elif now_s - last_detection_s >= spec.abort_after_s:
                self.aborted_to_gps = True
                context.events.add("aborted_to_gps",
                                   f"no marker for {spec.abort_after_s:g} s: plain GPS landing")
                break
            if now_s >= deadline_s:
                raise WaitTimeout(operation="land", timeout_s=context.timeout_s,
                                  last_state=f"land mode {self.name} still running at {altitude_m:.2f} m")
            switches_before = len(self.policy.switches)
            climbs_before = self.policy.recovery_climbs
            command = self.policy.step(detections, altitude_m=altitude_m, time_s=now_s)
            for time_s, previous, chosen, altitude in self.policy.switches[switches_before:]:
                context.events.add("marker_switch", f"marker {previous} -> {chosen}", from_id=previous,
                                   to_id=chosen, altitude_rel_m=round(altitude, 2))
            if self.policy.recovery_climbs > climbs_before:
                context.events.add("recovery", "marker lost: climbing to widen the view",
                                   altitude_rel_m=round(altitude_m, 2))
            if command.action is Action.HOLD:
                await vehicle.hold()
            else:
                await vehicle.set_velocity_body(forward_m_s=command.forward_m_s, right_m_s=command.right_m_s,
                                                down_m_s=command.down_m_s)
        await vehicle.set_mode(FlightMode.LAND)

        async def disarmed() -> bool:
            return not (await vehicle.telemetry()).armed

        # What is left of the land timeout; a timeout names the whole of it, not the remainder.
        remaining_s = max(0.0, deadline_s - clock.now_s())
        try:
            await wait_until(disarmed, clock=clock, timeout_s=remaining_s, operation="land",
                             poll_period_s=context.poll_period_s)
        except WaitTimeout:
            raise WaitTimeout(operation="land", timeout_s=context.timeout_s,
                              last_state="LAND commanded, not yet disarmed") from None
        context.events.add("disarmed", "landed and disarmed")
        return LandingReport(details={
            "marker_switches": len(self.policy.switches),
            "switch_altitudes_m": [round(s[3], 2) for s in self.policy.switches],
            "recovery_climbs": self.policy.recovery_climbs,
            "aborted_to_gps": self.aborted_to_gps,
            "marker_frames": self.frames,
            "frames_with_marker": self.frames_with_marker,
            "first_detection_altitude_m": None if self.first_detection_altitude_m is None
            else round(self.first_detection_altitude_m, 2),
            **self.gate.details(),
        })
