"""What a precision-landing sensor produces: the direction (and maybe the range) to the target."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from ..vehicle.types import LandingTarget


@dataclass(frozen=True, slots=True, kw_only=True)
class TargetReading:
    """One sensor value. Angles in rad off the downward camera axis, body FRD convention of
    LANDING_TARGET (angle_x > 0: target to the right; angle_y > 0: target behind);
    `distance_m` is the range to the target or None; `capture_time_s` is when the
    underlying image or sample was taken (vehicle clock); `sensor` names the source."""

    sensor: str
    capture_time_s: float
    angle_x_rad: float
    angle_y_rad: float
    distance_m: float | None = None
    marker_id: int | None = None

    def restamped(self, new: "TargetReading") -> "TargetReading":
        """This value, given again in `new`'s place: `new`'s capture time (a stale fault)."""
        return replace(self, capture_time_s=new.capture_time_s)

    def displaced(self, *, offset_cam_m: tuple[float, float], height_m: float | None) -> "TargetReading | None":
        """This reading as if it pointed at a spot `offset_cam_m` (x right, y back; m) from its target on the
        ground plane: the spot's range along the optical axis is the reading's (from `distance_m`) or, without
        one, `height_m`; None when neither is known."""
        tan_x, tan_y = math.tan(self.angle_x_rad), math.tan(self.angle_y_rad)
        if self.distance_m is not None and self.distance_m > 0:
            depth_m = self.distance_m / math.sqrt(tan_x * tan_x + tan_y * tan_y + 1.0)
        elif height_m is not None and height_m > 0:
            depth_m = height_m
        else:
            return None
        x_m, y_m = tan_x * depth_m + offset_cam_m[0], tan_y * depth_m + offset_cam_m[1]
        angle_x, angle_y = angles_from_camera_point(x_m, y_m, depth_m)
        distance = None if self.distance_m is None else math.sqrt(x_m * x_m + y_m * y_m + depth_m * depth_m)
        return replace(self, angle_x_rad=angle_x, angle_y_rad=angle_y, distance_m=distance)

    def to_landing_target(self) -> LandingTarget:
        return LandingTarget(timestamp_s=self.capture_time_s, angle_x_rad=self.angle_x_rad,
                             angle_y_rad=self.angle_y_rad, distance_m=self.distance_m,
                             target_num=self.marker_id or 0)


def angles_from_camera_point(x_m: float, y_m: float, z_m: float) -> tuple[float, float]:
    """LANDING_TARGET angles of a point in the (downward, nose-up-in-image) OpenCV camera frame."""
    return math.atan2(x_m, z_m), math.atan2(y_m, z_m)
