"""Every error preland raises, written out in one place.

User mistakes (bad specs) and runtime failures (a refused command, a wait that
timed out) are all `PrelandError`s, so the CLI can print one readable line for
any of them and exit non-zero instead of showing a traceback.
"""

from __future__ import annotations


class PrelandError(Exception):
    """Base class of every error preland raises on purpose."""


# --- specs (user input) -----------------------------------------------------


class SpecError(PrelandError):
    """A spec file (mission, campaign, pad...) is malformed or invalid.

    The message always names the file, the field (dotted path) and the problem.
    """

    def __init__(self, *, path: str, field: str, problem: str) -> None:
        self.path = path
        self.field = field
        self.problem = problem
        where = f"{path}: {field}" if field else path
        super().__init__(f"{where}: {problem}")


class SpecValueError(PrelandError, ValueError):
    """Raised by a spec dataclass's own validation; the loader adds file and path.

    `field` is relative to the dataclass that raised it.
    """

    def __init__(self, field_name: str, problem: str) -> None:
        self.field = field_name
        self.problem = problem
        super().__init__(f"{field_name}: {problem}")


def require(condition: bool, field_name: str, problem: str) -> None:
    """Validation helper for spec dataclasses' __post_init__."""
    if not condition:
        raise SpecValueError(field_name, problem)


# --- vehicle and mission (runtime) ------------------------------------------


class VehicleError(PrelandError):
    """A vehicle operation failed. Carries the operation's name."""

    def __init__(self, *, operation: str, reason: str) -> None:
        self.operation = operation
        self.reason = reason
        super().__init__(f"{operation}: {reason}")


class CommandDenied(VehicleError):
    """The autopilot refused a command (like a MAVLink COMMAND_ACK 'denied')."""


class WaitTimeout(VehicleError):
    """A wait for a vehicle state did not complete within its timeout."""

    def __init__(self, *, operation: str, timeout_s: float, last_state: str = "") -> None:
        self.timeout_s = timeout_s
        self.last_state = last_state
        reason = f"not done after {timeout_s:g} s"
        if last_state:
            reason += f" ({last_state})"
        super().__init__(operation=operation, reason=reason)


class LinkLost(VehicleError):
    """The link to the vehicle was lost (no heartbeat within the allowed time)."""


class VehicleCrashed(VehicleError):
    """The vehicle hit the ground or fell in a way no landing explains."""


class MissionAborted(PrelandError):
    """The mission stopped on purpose before it finished (for example a disarm in flight)."""


class LandModeFailed(PrelandError):
    """The land mode raised an exception of its own (not a vehicle error or a timeout): the message names
    the land mode, the exception's type and message, and where it was raised."""
