"""Cautious landing parameters (thesis Section 6.2), named after ArduPilot's precision-landing retry parameters.

On the embedded simulator the autopilot runs the thesis' variant of the retry
logic (see `sim/precland_retry.py`); on ArduPilot (SITL or a real drone) the
PLND_* values configure ArduPilot's own retry state machine and the PRL_*
values, which ArduPilot does not have, are left out.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import require


@dataclass(frozen=True)
class CautiousSpec:
    """Defaults: the thesis' behaviour. PLND_STRICT 1 retries; PLND_RET_MAX retries before the blind descent;
    PLND_TIMEOUT s waiting for the target after it is lost; PLND_RET_BEHAVE 0 goes back to where the target was
    last seen; PLND_ALT_MIN / PLND_ALT_MAX bound the heights (m) at which a loss triggers retries;
    PRL_LOST_HOLD 1 holds position while waiting (ArduPilot keeps descending); PRL_RET_ALT is the default
    height (m above home) when going back does not find the target; PRL_FS_HOLD s of hover before the
    blind descent."""

    PLND_STRICT: int = 1
    PLND_RET_MAX: int = 4
    PLND_TIMEOUT: float = 4.0
    PLND_RET_BEHAVE: int = 0
    PLND_ALT_MIN: float = 0.75
    PLND_ALT_MAX: float = 8.0
    PRL_LOST_HOLD: int = 1
    PRL_RET_ALT: float = 6.0
    PRL_FS_HOLD: float = 0.0

    def __post_init__(self) -> None:
        require(self.PLND_STRICT in (0, 1, 2), "PLND_STRICT", "must be 0, 1 or 2")
        require(0 <= self.PLND_RET_MAX <= 10, "PLND_RET_MAX", "must be within 0..10")
        require(0 <= self.PLND_TIMEOUT <= 20, "PLND_TIMEOUT", "must be within 0..20 s")
        require(self.PLND_RET_BEHAVE in (0, 1), "PLND_RET_BEHAVE", "must be 0 or 1")
        require(0 <= self.PLND_ALT_MIN <= 5, "PLND_ALT_MIN", "must be within 0..5 m")
        require(0 <= self.PLND_ALT_MAX <= 50, "PLND_ALT_MAX", "must be within 0..50 m")
        require(self.PRL_LOST_HOLD in (0, 1), "PRL_LOST_HOLD", "must be 0 or 1")
        require(0 <= self.PRL_RET_ALT <= 100, "PRL_RET_ALT", "must be within 0..100 m")
        require(0 <= self.PRL_FS_HOLD <= 60, "PRL_FS_HOLD", "must be within 0..60 s")

    def ardupilot_params(self) -> dict[str, float]:
        return {name: float(getattr(self, name)) for name in
                ("PLND_STRICT", "PLND_RET_MAX", "PLND_TIMEOUT", "PLND_RET_BEHAVE", "PLND_ALT_MIN", "PLND_ALT_MAX")}

    def embedded_params(self) -> dict[str, float]:
        return {name: float(getattr(self, name)) for name in ("PRL_LOST_HOLD", "PRL_RET_ALT", "PRL_FS_HOLD")}
