"""Normal land mode: the autopilot's own LAND on GPS, no precision sensor (thesis 'None')."""

from __future__ import annotations

from ..clock import wait_until
from ..vehicle.types import FlightMode
from .base import LandingContext, LandingReport, ScoringReference


class NormalLanding:
    """Switch to LAND and wait for the autopilot to touch down and disarm."""

    name = "normal"
    uses_irlock = False
    uses_marker = False

    def __init__(self, *, scoring_reference: ScoringReference = ScoringReference.TAKEOFF) -> None:
        # The thesis scores GPS landings from the take-off position; the paper from the target.
        self.scoring_reference = scoring_reference

    async def land(self, context: LandingContext) -> LandingReport:
        vehicle = context.vehicle
        await vehicle.set_mode(FlightMode.LAND)
        context.events.add("land_command", "LAND mode set (GPS only)")

        async def disarmed() -> bool:
            return not (await vehicle.telemetry()).armed

        async def describe() -> str:
            t = await vehicle.telemetry()
            return f"altitude {t.altitude_rel_m:.1f} m, {t.landed_state.name}"

        await wait_until(disarmed, clock=context.clock, timeout_s=context.timeout_s, operation="land",
                         poll_period_s=context.poll_period_s, describe=describe)
        context.events.add("disarmed", "landed and disarmed")
        return LandingReport()
