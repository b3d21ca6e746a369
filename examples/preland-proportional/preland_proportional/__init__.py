"""An example land mode for preland: centre on the marker with GUIDED body-frame velocities, descend at a
rate scaled by height, hand over to LAND near the ground. Companion-side only: no precision landing on
the autopilot, so it flies the same on the embedded simulator, SITL and a real ArduCopter."""

from __future__ import annotations

import math

from preland_app.clock import wait_until
from preland_app.landing import LandingContext, LandingReport, ScoringReference
from preland_app.vehicle.types import FlightMode


def level_offset_m(camera_xyz_m, roll_deg: float, pitch_deg: float) -> tuple[float, float]:
    """A point seen by the downward camera (x right, y down in the image = body backward, z down), as
    (forward, right) in metres in the yaw-rotated level frame that set_velocity_body uses."""
    x, y, z = camera_xyz_m
    f, r, d = -y, x, z  # body FRD
    roll, pitch = math.radians(roll_deg), math.radians(pitch_deg)
    r, d = r * math.cos(roll) - d * math.sin(roll), r * math.sin(roll) + d * math.cos(roll)  # undo the roll
    return f * math.cos(pitch) + d * math.sin(pitch), r  # undo the pitch


class ProportionalLanding:
    """Proportional centring on the pad's smallest visible marker; descent rate scaled by height."""

    name = "proportional"
    scoring_reference = ScoringReference.PAD  # scored from the pad's centre
    uses_irlock = False
    uses_marker = True  # the runtime gives it the camera and the marker detector

    def __init__(self, *, gain_per_s: float = 0.5, max_speed_m_s: float = 1.0, descent_per_s: float = 0.2,
                 min_descent_m_s: float = 0.2, centred_fraction: float = 0.15, land_below_m: float = 0.4) -> None:
        if gain_per_s <= 0 or max_speed_m_s <= 0:
            raise ValueError("gain_per_s and max_speed_m_s must be > 0")
        self.gain_per_s, self.max_speed_m_s = gain_per_s, max_speed_m_s
        self.descent_per_s, self.min_descent_m_s = descent_per_s, min_descent_m_s
        self.centred_fraction, self.land_below_m = centred_fraction, land_below_m

    async def land(self, context: LandingContext) -> LandingReport:
        vehicle, sensors = context.vehicle, context.sensors
        frames = seen = 0
        while (telemetry := await vehicle.telemetry()).height_above_ground_m > self.land_below_m:
            markers = await sensors.next_markers()  # after the processing latency, faults applied
            frames += 1
            if not markers.detections:
                await vehicle.hold()  # lost: stop and wait for it
                continue
            seen += 1
            chosen = min(markers.detections, key=lambda d: d.side_m)  # the smallest: the most precise
            attitude = (await vehicle.telemetry()).attitude
            forward_m, right_m = level_offset_m(chosen.pad_center_cam_m, attitude.roll_deg, attitude.pitch_deg)
            offset_m, height_m = math.hypot(forward_m, right_m), telemetry.height_above_ground_m
            scale = min(self.gain_per_s, self.max_speed_m_s / offset_m) if offset_m > 0 else 0.0
            centred = offset_m <= self.centred_fraction * height_m + 0.05
            down_m_s = max(self.min_descent_m_s, self.descent_per_s * height_m) if centred else 0.0
            await vehicle.set_velocity_body(forward_m_s=forward_m * scale, right_m_s=right_m * scale,
                                            down_m_s=down_m_s)
        await vehicle.set_mode(FlightMode.LAND)  # the last decimetres: the autopilot lands and disarms

        async def disarmed() -> bool:
            return not (await vehicle.telemetry()).armed

        await wait_until(disarmed, clock=context.clock, timeout_s=context.timeout_s, operation="land")
        return LandingReport(details={"frames": frames, "frames_with_marker": seen})
