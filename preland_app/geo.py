"""Frames and conversions.

Frames used across preland:

* NED: north, east, down in metres, relative to a named origin (`_ned_m`);
* FRD: the body frame, forward, right, down (`_frd`), angles in radians;
* geodetic: WGS-84 latitude/longitude in degrees and altitude AMSL in metres.

Geodesy is pymap3d's; this module only names the frames.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pymap3d


@dataclass(frozen=True, slots=True)
class GeoPoint:
    """A WGS-84 point: latitude/longitude in degrees, altitude above mean sea level in m."""

    latitude_deg: float
    longitude_deg: float
    altitude_amsl_m: float


def ned_to_geodetic(*, north_m: float, east_m: float, down_m: float, origin: GeoPoint) -> GeoPoint:
    """The geodetic point at `north_m, east_m, down_m` (NED) from `origin`."""
    lat, lon, alt = pymap3d.ned2geodetic(
        north_m, east_m, down_m, origin.latitude_deg, origin.longitude_deg, origin.altitude_amsl_m
    )
    return GeoPoint(float(lat), float(lon), float(alt))


def geodetic_to_ned(point: GeoPoint, *, origin: GeoPoint) -> tuple[float, float, float]:
    """NED offset (north_m, east_m, down_m) of `point` from `origin`."""
    n, e, d = pymap3d.geodetic2ned(
        point.latitude_deg,
        point.longitude_deg,
        point.altitude_amsl_m,
        origin.latitude_deg,
        origin.longitude_deg,
        origin.altitude_amsl_m,
    )
    return float(n), float(e), float(d)


def frd_to_ned_xy(forward: float, right: float, yaw_rad: float) -> tuple[float, float]:
    """Rotate a horizontal body (forward, right) vector to (north, east) by yaw."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return forward * c - right * s, forward * s + right * c


def ned_to_frd_xy(north: float, east: float, yaw_rad: float) -> tuple[float, float]:
    """Rotate a horizontal (north, east) vector to body (forward, right) by yaw."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return north * c + east * s, -north * s + east * c


def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


class LocalTangentPlane:
    """Fast NED <-> geodetic around a fixed origin, linearised with pymap3d at construction.

    Within a few hundred metres of the origin the linearisation error is well
    under a millimetre, which is why simulator telemetry (polled many times
    per simulated second) uses it instead of a full conversion per call.
    """

    def __init__(self, origin: GeoPoint) -> None:
        self.origin = origin
        step_m = 100.0
        north = ned_to_geodetic(north_m=step_m, east_m=0.0, down_m=0.0, origin=origin)
        east = ned_to_geodetic(north_m=0.0, east_m=step_m, down_m=0.0, origin=origin)
        self._deg_lat_per_m = (north.latitude_deg - origin.latitude_deg) / step_m
        self._deg_lon_per_m = (east.longitude_deg - origin.longitude_deg) / step_m

    def to_geodetic(self, *, north_m: float, east_m: float, down_m: float) -> GeoPoint:
        return GeoPoint(
            self.origin.latitude_deg + north_m * self._deg_lat_per_m,
            self.origin.longitude_deg + east_m * self._deg_lon_per_m,
            self.origin.altitude_amsl_m - down_m,
        )

    def to_ned(self, point: GeoPoint) -> tuple[float, float, float]:
        return (
            (point.latitude_deg - self.origin.latitude_deg) / self._deg_lat_per_m,
            (point.longitude_deg - self.origin.longitude_deg) / self._deg_lon_per_m,
            self.origin.altitude_amsl_m - point.altitude_amsl_m,
        )


def ned_from_body_rows(roll_rad: float, pitch_rad: float, yaw_rad: float) -> tuple[tuple[float, float, float], ...]:
    """ZYX Euler rotation taking body FRD vectors to NED, as three rows of floats (plain arithmetic: the sensors
    and the precision-landing model use it many times a second, where numpy's overhead on a 3-vector costs more
    than the arithmetic)."""
    cr, sr = math.cos(roll_rad), math.sin(roll_rad)
    cp, sp = math.cos(pitch_rad), math.sin(pitch_rad)
    cy, sy = math.cos(yaw_rad), math.sin(yaw_rad)
    return ((cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy),
            (cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy),
            (-sp, sr * cp, cr * cp))


def body_to_ned(rows: tuple[tuple[float, float, float], ...],
                vector_frd: tuple[float, float, float]) -> tuple[float, float, float]:
    """A body FRD vector rotated to NED by `rows` (`ned_from_body_rows`)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rows
    x, y, z = vector_frd
    return r00 * x + r01 * y + r02 * z, r10 * x + r11 * y + r12 * z, r20 * x + r21 * y + r22 * z
