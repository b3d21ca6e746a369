"""Cautious landing parameters (thesis Section 6.2).

The PLND_* fields are ArduPilot's precision-landing retry parameters: the land
mode sets them on the autopilot, which runs its own retry state machine
(AC_PrecLand_StateMachine) with them. Where the thesis' cautious landing
differs from ArduPilot's retry, the companion computer does the difference
through the Vehicle protocol (see `cautious_retry.py`); its options are the
lower-case fields, and no autopilot parameter carries them, so the same land
mode runs on ArduPilot, SITL and the embedded simulator alike.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import require


@dataclass(frozen=True)
class CautiousSpec:
    """Defaults: the thesis' behaviour.

    ArduPilot parameters: PLND_STRICT 0 lands without retrying, 1 retries, 2 never lands without the target
    (hovers); PLND_RET_MAX retries before the blind descent; PLND_TIMEOUT s waiting for the target after it is
    lost (the thesis' pause); PLND_RET_BEHAVE 0 goes back to where the target was last seen (1: above its last
    estimated position, ArduPilot's own retry only); PLND_ALT_MIN / PLND_ALT_MAX bound the rangefinder heights
    (m) at which a loss starts the cautious sequence.

    Companion (thesis) options: `lost_after_s` without a new sensor value counts as lost (the thesis' 1 s
    freshness); `hold_while_waiting` stops the descent and holds in GUIDED while waiting (ArduPilot keeps
    descending); `retry_height_m` (m above home) is the default height to go to when going back does not find
    the target, from where a new attempt starts; `failsafe_hold_s` of hover before the blind descent once the
    retries are spent (ArduPilot waits 7 s; the thesis none)."""

    PLND_STRICT: int = 1
    PLND_RET_MAX: int = 4
    PLND_TIMEOUT: float = 4.0
    PLND_RET_BEHAVE: int = 0
    PLND_ALT_MIN: float = 0.75
    PLND_ALT_MAX: float = 8.0
    lost_after_s: float = 1.0
    hold_while_waiting: bool = True
    retry_height_m: float = 6.0
    failsafe_hold_s: float = 0.0

    def __post_init__(self) -> None:
        require(self.PLND_STRICT in (0, 1, 2), "PLND_STRICT", "must be 0, 1 or 2")
        require(0 <= self.PLND_RET_MAX <= 10, "PLND_RET_MAX", "must be within 0..10")
        require(0 <= self.PLND_TIMEOUT <= 20, "PLND_TIMEOUT", "must be within 0..20 s")
        require(self.PLND_RET_BEHAVE in (0, 1), "PLND_RET_BEHAVE", "must be 0 or 1")
        require(0 <= self.PLND_ALT_MIN <= 5, "PLND_ALT_MIN", "must be within 0..5 m")
        require(0 <= self.PLND_ALT_MAX <= 50, "PLND_ALT_MAX", "must be within 0..50 m")
        require(0.1 <= self.lost_after_s <= 10, "lost_after_s", "must be within 0.1..10 s")
        require(isinstance(self.hold_while_waiting, bool), "hold_while_waiting", "must be true or false")
        require(0 <= self.retry_height_m <= 100, "retry_height_m", "must be within 0..100 m (0: none)")
        require(0 <= self.failsafe_hold_s <= 60, "failsafe_hold_s", "must be within 0..60 s")

    def ardupilot_params(self) -> dict[str, float]:
        """The ArduPilot parameters this spec sets (all exist on ArduCopter 4.6)."""
        return {name: float(getattr(self, name)) for name in
                ("PLND_STRICT", "PLND_RET_MAX", "PLND_TIMEOUT", "PLND_RET_BEHAVE", "PLND_ALT_MIN", "PLND_ALT_MAX")}
