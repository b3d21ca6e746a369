"""How a campaign flies on one vehicle: the campaign file's `field:` block.

A field campaign (`campaign run FILE --runtime mavlink+...`) flies the
campaign's trials back to back on one vehicle. Between two trials the vehicle
goes back to where the campaign started (`between_trials`); after each landing
the battery is checked against `battery_swap_pct`. The block belongs to the
campaign, as its scenarios do: the same file runs on the embedded simulator
and SITL, where the block has nothing to do, so it never enters the
campaign's hash and a simulated run of the file does not read it.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from ..errors import require


class BetweenTrials(enum.Enum):
    """What brings the vehicle back to the campaign's start between two trials."""

    NONE = "none"  # the next trial takes off where the last one landed
    REPOSITION = "reposition"  # the vehicle hops back: low take-off, to the start by GPS, LAND, disarm
    OPERATOR = "operator"  # the operator carries it back and confirms


@dataclass(frozen=True)
class SurveyedPoint:
    """A surveyed position (WGS-84 degrees), such as the pad's centre measured with an RTK receiver."""

    latitude_deg: float
    longitude_deg: float

    def __post_init__(self) -> None:
        require(-90 <= self.latitude_deg <= 90, "latitude_deg", "must be within -90..90")
        require(-180 <= self.longitude_deg <= 180, "longitude_deg", "must be within -180..180")


@dataclass(frozen=True)
class FieldSpec:
    """`between_trials`: none, reposition or operator. `battery_swap_pct`: below this charge after a landing
    the campaign pauses for a battery swap (above the preflight's 30 % refusal, so a swap is asked for before
    a take-off is refused). `reposition_altitude_m`: the hop's height above the start; `reposition_tolerance_m`:
    a vehicle closer than this to the start (by its GPS) is not moved. `pad`: the pad centre's surveyed
    position, for `--measure vehicle`. `reconnect_timeout_s`: wall seconds to wait for the vehicle to come
    back after a swap."""

    between_trials: BetweenTrials = BetweenTrials.NONE
    battery_swap_pct: float = 35.0
    reposition_altitude_m: float = 3.0
    reposition_tolerance_m: float = 0.5
    pad: SurveyedPoint | None = None
    reconnect_timeout_s: float = 300.0

    def __post_init__(self) -> None:
        require(0 <= self.battery_swap_pct <= 100, "battery_swap_pct", "must be within 0..100 %")
        require(1.0 <= self.reposition_altitude_m <= 20.0, "reposition_altitude_m", "must be within 1..20 m")
        require(0 < self.reposition_tolerance_m <= 10.0, "reposition_tolerance_m", "must be > 0 and <= 10 m")
        require(self.reconnect_timeout_s > 0, "reconnect_timeout_s", "must be > 0 s")
