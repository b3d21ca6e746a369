"""Fault injection: sensor values dropped on purpose (thesis Chapter 7 and Section 8.2.3).

Faults drop values, give an old one again in a new one's place, deliver them
late, or put a false target in a value's place (never noise on a value), and
apply per sensor before fusion. Kinds:

* `none`; `random:P` (drop each new value with probability P);
* `periodic:KEEP:DROP` (keep KEEP values, drop DROP, repeat);
* `permanent` (drop everything);
* `below:H` / `above:H` (drop while the height above the target, as the vehicle
  knows it, is <= H or >= H metres);
* `burst:LOSS:LENGTH` (drops in bursts: a two-state Gilbert channel, the
  loss-free/all-lost case of Gilbert-Elliott, whose long-run share of dropped
  values is LOSS and whose bursts last LENGTH values on average);
* `stale:P` (each new value is, with probability P, replaced by the value the
  sensor gave last, sent again as new: a frozen frame or reading);
* `stalestamp:P` (each new value is, with probability P, given the capture time
  of the value given before it: a new reading with an old timestamp, as from a
  driver whose frame time does not advance; for readings that carry a time);
* `delay:MS` / `delay:MS:JITTER` (each value arrives MS milliseconds after it
  was ready, plus a uniform draw in -JITTER..JITTER ms as Linux netem's
  `delay TIME JITTER`; in order: a value never arrives before the one ahead of it);
* `false:P:OFFSET` (each new value is, with probability P, replaced by a
  detection of a false target OFFSET metres from the real one on the ground, in
  a direction drawn once a trial: a reflection, a sunlit object, a look-alike);

each optionally suffixed `:first-attempt` to apply during the first landing
attempt only (the thesis' Table 5 removes the failure on the second attempt).
Faults combine with `+`, applied to each value in the order written
(`random:0.75+delay:50`: three in four readings dropped, the rest 50 ms late);
at most one of them a delay, none of them `none`.

`FaultCommand` is the thesis' fault-injection message (its Table 1) with its
documented rules; it converts to per-sensor `FaultSpec`s.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, replace

import numpy as np

from .readings import TargetReading

SENSORS = ("irlock", "marker")
FIRST_ATTEMPT_SUFFIX = "first-attempt"


class FaultKind(enum.Enum):
    NONE = "none"
    RANDOM = "random"
    PERIODIC = "periodic"
    PERMANENT = "permanent"
    BELOW = "below"
    ABOVE = "above"
    BURST = "burst"
    STALE = "stale"
    STALESTAMP = "stalestamp"
    DELAY = "delay"
    FALSE = "false"


class FaultSyntaxError(ValueError):
    """A fault string that does not parse; the message says what is expected."""


FAULT_SYNTAX = ("none, random:P, periodic:KEEP:DROP, permanent, below:H, above:H, burst:LOSS:LENGTH, stale:P, "
                "stalestamp:P, delay:MS[:JITTER] or false:P:OFFSET, optionally with :first-attempt, "
                "several joined by +")
# A delay beyond this is no longer a late value but a lost one (ArduPilot drops a LANDING_TARGET older than 1 s).
DELAY_MAX_MS = 5000.0
FALSE_OFFSET_MAX_M = 50.0  # farther, and a downward camera at landing heights would not see it


@dataclass(frozen=True)
class FaultSpec:
    """One sensor's fault. `probability` for random, stale and stalestamp, and the long-run share of values
    dropped for burst; `keep`/`drop` counts for periodic; `height_m` for below/above; `burst_length` (values)
    for burst; `delay_ms` and `jitter_ms` (milliseconds) for delay; `probability` and `offset_m` for false."""

    kind: FaultKind = FaultKind.NONE
    probability: float = 0.0
    keep: int = 0
    drop: int = 0
    height_m: float = 0.0
    burst_length: float = 0.0
    delay_ms: float = 0.0
    jitter_ms: float = 0.0
    offset_m: float = 0.0
    first_attempt_only: bool = False
    then: "FaultSpec | None" = None  # the next fault of a combined one (A+B), applied after this one

    def __post_init__(self) -> None:
        if not 0.0 <= self.probability <= 1.0:
            raise FaultSyntaxError(f"probability must be within 0..1, got {self.probability:g}")
        if self.keep < 0 or self.drop < 0:
            raise FaultSyntaxError("periodic counts must be >= 0")
        if self.kind is FaultKind.PERIODIC and self.keep == 0 and self.drop == 0:
            raise FaultSyntaxError("periodic needs KEEP or DROP > 0")
        if self.kind in (FaultKind.BELOW, FaultKind.ABOVE) and self.height_m < 0:
            raise FaultSyntaxError(f"height must be >= 0 m, got {self.height_m:g}")
        if self.kind is FaultKind.BURST:
            if not (math.isfinite(self.burst_length) and self.burst_length >= 1.0):
                raise FaultSyntaxError(f"burst length must be >= 1 value, got {self.burst_length:g}")
            # A burst ends after each value with probability 1/LENGTH; one starts with the probability that
            # makes LOSS the stationary share of the lost state, which must be a probability.
            most = self.burst_length / (1.0 + self.burst_length)
            if self.probability > most:
                raise FaultSyntaxError(f"burst loss {self.probability:g} cannot last {self.burst_length:g} values "
                                       f"on average: at most {most:.3g} (LENGTH / (1 + LENGTH))")

        if self.kind is FaultKind.DELAY:
            if not (math.isfinite(self.delay_ms) and 0.0 < self.delay_ms <= DELAY_MAX_MS):
                raise FaultSyntaxError(f"delay must be within 0..{DELAY_MAX_MS:g} ms and above 0, got {self.delay_ms:g}")
            if not (math.isfinite(self.jitter_ms) and 0.0 <= self.jitter_ms <= self.delay_ms):
                raise FaultSyntaxError(f"jitter must be within 0..{self.delay_ms:g} ms (the delay), "
                                       f"got {self.jitter_ms:g}")

        if self.then is not None:
            kinds = [part.kind for part in self.parts()]
            if FaultKind.NONE in kinds:
                raise FaultSyntaxError("none cannot be combined with another fault")
            if kinds.count(FaultKind.DELAY) > 1:
                raise FaultSyntaxError("a combined fault takes at most one delay")

        if self.kind is FaultKind.FALSE and not (math.isfinite(self.offset_m) and
                                                 0.0 < self.offset_m <= FALSE_OFFSET_MAX_M):
            raise FaultSyntaxError(f"false target offset must be within 0..{FALSE_OFFSET_MAX_M:g} m and above 0, "
                                   f"got {self.offset_m:g}")

    @classmethod
    def parse(cls, text: str) -> "FaultSpec":
        """Parse the CLI/spec syntax (see FAULT_SYNTAX); `A+B` is A with B as its `then`."""
        pieces = str(text).split("+")
        if len(pieces) == 1:
            return cls._parse_one(text)
        if any(not piece.strip() for piece in pieces):
            raise FaultSyntaxError(f"fault {text!r}: an empty part around + (expected {FAULT_SYNTAX})")
        combined = None
        for piece in reversed(pieces):
            combined = replace(cls._parse_one(piece), then=combined)
        return combined

    @classmethod
    def _parse_one(cls, text: str) -> "FaultSpec":
        parts = [p.strip() for p in str(text).strip().lower().split(":")]
        first_attempt = False
        if len(parts) > 1 and parts[-1] == FIRST_ATTEMPT_SUFFIX:
            first_attempt = True
            parts = parts[:-1]
        name, args = parts[0], parts[1:]
        try:
            kind = FaultKind(name)
        except ValueError:
            raise FaultSyntaxError(f"unknown fault {text!r} (expected {FAULT_SYNTAX})") from None
        expected = {FaultKind.NONE: (0,), FaultKind.PERMANENT: (0,), FaultKind.RANDOM: (1,), FaultKind.PERIODIC: (2,),
                    FaultKind.BELOW: (1,), FaultKind.ABOVE: (1,), FaultKind.BURST: (2,), FaultKind.STALE: (1,),
                    FaultKind.STALESTAMP: (1,), FaultKind.DELAY: (1, 2), FaultKind.FALSE: (2,)}[kind]
        if len(args) not in expected:
            counts = " or ".join(map(str, expected))
            raise FaultSyntaxError(f"fault {text!r}: {kind.value} takes {counts} value(s) (expected {FAULT_SYNTAX})")
        try:
            if kind in (FaultKind.RANDOM, FaultKind.STALE, FaultKind.STALESTAMP):
                return cls(kind, probability=float(args[0]), first_attempt_only=first_attempt)
            if kind is FaultKind.PERIODIC:
                return cls(kind, keep=int(args[0]), drop=int(args[1]), first_attempt_only=first_attempt)
            if kind in (FaultKind.BELOW, FaultKind.ABOVE):
                return cls(kind, height_m=float(args[0]), first_attempt_only=first_attempt)
            if kind is FaultKind.BURST:
                return cls(kind, probability=float(args[0]), burst_length=float(args[1]),
                           first_attempt_only=first_attempt)
            if kind is FaultKind.FALSE:
                return cls(kind, probability=float(args[0]), offset_m=float(args[1]), first_attempt_only=first_attempt)
            if kind is FaultKind.DELAY:
                return cls(kind, delay_ms=float(args[0]), jitter_ms=float(args[1]) if len(args) > 1 else 0.0,
                           first_attempt_only=first_attempt)
        except ValueError as error:
            if isinstance(error, FaultSyntaxError):
                raise
            raise FaultSyntaxError(f"fault {text!r}: {error}") from None
        return cls(kind, first_attempt_only=first_attempt)

    def __str__(self) -> str:
        text = {
            FaultKind.NONE: "none",
            FaultKind.PERMANENT: "permanent",
            FaultKind.RANDOM: f"random:{self.probability:g}",
            FaultKind.PERIODIC: f"periodic:{self.keep}:{self.drop}",
            FaultKind.BELOW: f"below:{self.height_m:g}",
            FaultKind.ABOVE: f"above:{self.height_m:g}",
            FaultKind.BURST: f"burst:{self.probability:g}:{self.burst_length:g}",
            FaultKind.STALE: f"stale:{self.probability:g}",
            FaultKind.STALESTAMP: f"stalestamp:{self.probability:g}",
            FaultKind.FALSE: f"false:{self.probability:g}:{self.offset_m:g}",
            FaultKind.DELAY: f"delay:{self.delay_ms:g}" + (f":{self.jitter_ms:g}" if self.jitter_ms else ""),
        }[self.kind]
        text += f":{FIRST_ATTEMPT_SUFFIX}" if self.first_attempt_only else ""
        return text if self.then is None else f"{text}+{self.then}"

    def parts(self) -> tuple["FaultSpec", ...]:
        """This fault and those combined after it, in order (each with no `then`)."""
        return (replace(self, then=None),) + (self.then.parts() if self.then is not None else ())

    @property
    def active(self) -> bool:
        return self.kind is not FaultKind.NONE


class FaultTarget(enum.IntEnum):
    """The fault command's `target` field (thesis Table 1)."""

    IRLOCK = 1
    MARKER = 2
    BOTH = 3


@dataclass(frozen=True)
class FaultCommand:
    """The thesis' fault-injection message: target (1 IR-LOCK, 2 marker, 3 both), r_drop, p_keep, p_drop.

    Rules (thesis Section 7.2): r_drop > 0 selects random drops with that
    probability and the other fields are ignored (so r_drop = 1.0 is a
    permanent failure); r_drop = 0 selects periodic drops with p_keep/p_drop
    (p_keep = 0 with p_drop > 0 is a permanent failure); all fields zero turn
    fault injection off for the target.
    """

    target: FaultTarget
    r_drop: float = 0.0
    p_keep: int = 0
    p_drop: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.target, FaultTarget):
            object.__setattr__(self, "target", FaultTarget(int(self.target)))
        if not 0.0 <= self.r_drop <= 1.0:
            raise FaultSyntaxError(f"r_drop must be within 0..1, got {self.r_drop:g}")
        if not (0 <= self.p_keep <= 65535 and 0 <= self.p_drop <= 65535):
            raise FaultSyntaxError("p_keep and p_drop are uint16 (0..65535)")

    def fault(self) -> FaultSpec:
        if self.r_drop >= 1.0:
            return FaultSpec(FaultKind.PERMANENT)
        if self.r_drop > 0.0:
            return FaultSpec(FaultKind.RANDOM, probability=self.r_drop)
        if self.p_keep == 0 and self.p_drop == 0:
            return FaultSpec(FaultKind.NONE)
        if self.p_keep == 0:
            return FaultSpec(FaultKind.PERMANENT)
        if self.p_drop == 0:
            return FaultSpec(FaultKind.NONE)
        return FaultSpec(FaultKind.PERIODIC, keep=self.p_keep, drop=self.p_drop)

    def targets(self) -> tuple[str, ...]:
        return {FaultTarget.IRLOCK: ("irlock",), FaultTarget.MARKER: ("marker",),
                FaultTarget.BOTH: ("irlock", "marker")}[self.target]

    def faults(self) -> dict[str, FaultSpec]:
        """The per-sensor faults this command sets."""
        return {sensor: self.fault() for sensor in self.targets()}


class FaultInjector:
    """Applies one FaultSpec to a stream of new values from one sensor; counts what it keeps, drops, gives
    again (stale), gives an old time (stalestamp), delays (delay) and replaces with a false target (false)."""

    def __init__(self, *, sensor: str, spec: FaultSpec, rng: np.random.Generator) -> None:
        self.sensor = sensor
        self._rng = rng
        self.set_spec(spec)
        self.produced = 0
        self.dropped = 0
        self.repeated = 0
        self.delayed = 0
        self.delay_total_s = 0.0
        self.falsified = 0
        self.old_stamped = 0
        self._false_direction_rad: float | None = None  # where the false target lies (drawn once)

    def set_spec(self, spec: FaultSpec) -> None:
        """Set the fault (and change it at runtime: the fault command); the periodic phase restarts."""
        self.spec = spec
        # A combined fault's next part, on a stream of its own (spawning leaves this one's draws as they were).
        self._next = FaultInjector(sensor=self.sensor, spec=spec.then, rng=self._rng.spawn(1)[0]) if spec.then else None
        self._phase = 0
        self._in_burst: bool | None = None  # the burst channel's state (None: not drawn yet)
        self._last: object | None = None  # the value given out last (a stale fault gives it again)
        self._last_arrival_s = -math.inf  # when the value ahead arrives (a delay fault keeps the order)

    def admit(self, *, height_m: float | None, attempt: int = 1) -> bool:
        """One new value: True to use it, False where the fault drops it or gives an older one instead.
        `height_m`: height above the target as the vehicle knows it (None when unknown: height faults then
        keep the value)."""
        new = object()
        return self.apply(new, height_m=height_m, attempt=attempt) is new

    def chain(self) -> tuple["FaultInjector", ...]:
        """This injector and those of the parts combined after it, in order."""
        return (self,) + (self._next.chain() if self._next is not None else ())

    def apply(self, value: object, *, height_m: float | None, attempt: int = 1) -> object | None:
        """One new value: what to use in its place, after this fault and then each combined after it (see
        `_apply_own`). `height_m` and `attempt` as in `admit`."""
        value = self._apply_own(value, height_m=height_m, attempt=attempt)
        if value is not None and self._next is not None:
            value = self._next.apply(value, height_m=height_m, attempt=attempt)
        return value

    def _apply_own(self, value: object, *, height_m: float | None, attempt: int = 1) -> object | None:
        """One new value: what to use in its place. None where the fault drops it; the value given out last
        where a stale fault gives that again (a `TargetReading` with the new one's capture time); else
        `value` itself, or under a stalestamp fault, with its probability, `value` with the capture time of the
        reading given last (a value that carries no time passes as it is); under a false fault, with its
        probability, the value pointing at the false target instead (a `TargetReading`, or a sequence of
        `MarkerDetection`s; a reading without a range is kept while the height is unknown)."""
        self.produced += 1
        spec = self.spec
        active = spec.active and not (spec.first_attempt_only and attempt > 1)
        if active and spec.kind is FaultKind.STALE:
            if self._last is not None and self._rng.random() < spec.probability:
                self.repeated += 1
                old = self._last
                both_readings = isinstance(old, TargetReading) and isinstance(value, TargetReading)
                return old.restamped(value) if both_readings else old
        elif active and spec.kind is FaultKind.STALESTAMP:
            if self._rng.random() < spec.probability and isinstance(value, TargetReading) \
                    and isinstance(self._last, TargetReading):
                self.old_stamped += 1
                value = replace(value, capture_time_s=self._last.capture_time_s)
        elif active and spec.kind is FaultKind.FALSE:
            if self._rng.random() < spec.probability:
                false = self._false_target(value, spec.offset_m, height_m)
                if false is not None:
                    self.falsified += 1
                    self._last = false
                    return false
        elif active and self._should_drop(spec, height_m):
            self.dropped += 1
            return None
        self._last = value
        return value

    def _false_target(self, value: object, offset_m: float, height_m: float | None) -> object | None:
        """`value` pointing at the false target: `offset_m` from the real one, in the sensor's frame, in a
        direction drawn the first time (a false target stays where it is while the vehicle descends)."""
        if self._false_direction_rad is None:
            self._false_direction_rad = float(self._rng.uniform(0.0, 2.0 * math.pi))
        offset = (offset_m * math.cos(self._false_direction_rad), offset_m * math.sin(self._false_direction_rad))
        if isinstance(value, TargetReading):
            return value.displaced(offset_cam_m=offset, height_m=height_m)
        if isinstance(value, (list, tuple)) and all(hasattr(item, "displaced") for item in value):
            return type(value)(item.displaced(offset_cam_m=offset, height_m=height_m) for item in value)
        raise TypeError(f"a false-target fault cannot displace a {type(value).__name__} of sensor {self.sensor!r}")

    def arrival_s(self, ready_s: float, *, attempt: int = 1) -> float:
        """When a value kept by `apply` and ready at `ready_s` (s, the clock's) arrives: `ready_s` itself
        unless a delay fault holds it back, then after its drawn delay and never before the value ahead."""
        spec = self.spec
        if spec.kind is not FaultKind.DELAY and self._next is not None:
            return self._next.arrival_s(ready_s, attempt=attempt)
        if spec.kind is not FaultKind.DELAY or (spec.first_attempt_only and attempt > 1):
            return max(ready_s, self._last_arrival_s)
        delay_ms = spec.delay_ms
        if spec.jitter_ms:
            delay_ms += float(self._rng.uniform(-spec.jitter_ms, spec.jitter_ms))
        arrival_s = max(ready_s + delay_ms / 1000.0, self._last_arrival_s)
        self._last_arrival_s = arrival_s
        self.delayed += 1
        self.delay_total_s += arrival_s - ready_s
        return arrival_s

    def _should_drop(self, spec: FaultSpec, height_m: float | None) -> bool:
        kind = spec.kind
        if kind is FaultKind.RANDOM:
            return bool(self._rng.random() < spec.probability)
        if kind is FaultKind.PERMANENT:
            return True
        if kind is FaultKind.PERIODIC:
            cycle = spec.keep + spec.drop
            position = self._phase % cycle
            self._phase += 1
            return position >= spec.keep
        if kind is FaultKind.BELOW:
            return height_m is not None and height_m <= spec.height_m
        if kind is FaultKind.ABOVE:
            return height_m is not None and height_m >= spec.height_m
        if kind is FaultKind.BURST:
            return self._burst_drops(spec)
        return False

    def _burst_drops(self, spec: FaultSpec) -> bool:
        """Gilbert's channel, one step a value: the first value finds it in its stationary state (lost with
        probability LOSS); after each value a burst ends with probability 1/LENGTH, and a run of kept values
        ends with probability LOSS / (LENGTH * (1 - LOSS))."""
        if self._in_burst is None:
            self._in_burst = bool(self._rng.random() < spec.probability)
            return self._in_burst
        ends = 1.0 / spec.burst_length
        starts = ends * spec.probability / (1.0 - spec.probability)  # LOSS < 1: checked with the spec
        self._in_burst = bool(self._rng.random() >= ends) if self._in_burst else bool(self._rng.random() < starts)
        return self._in_burst
