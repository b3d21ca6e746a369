"""The Vehicle protocol, its value types, and its backends."""

from .protocol import Vehicle
from .types import (
    Attitude,
    Battery,
    FlightMode,
    GlobalPosition,
    LandedState,
    LandingTarget,
    LandingTargetFrame,
    PositionNed,
    Telemetry,
    VelocityNed,
)

__all__ = [
    "Attitude",
    "Battery",
    "FlightMode",
    "GlobalPosition",
    "LandedState",
    "LandingTarget",
    "LandingTargetFrame",
    "PositionNed",
    "Telemetry",
    "Vehicle",
    "VelocityNed",
]
