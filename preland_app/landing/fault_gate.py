"""The faults of a landing applied to each new sensor value: one mechanism for every land mode.

The built-in precision modes, the paper's algorithms and a plugin's sensor views all pass their values
through a `FaultGate`, which drops a value, gives the sensor's last value again in its place, gives it an old
time, puts a false target in its place, or holds it back until it arrives: one `FaultInjector` per sensor the
mode uses, each drawing from a random stream of its own (spawned from the landing's generator in the order
`streams` gives, so a mode's draws do not depend on the other sensor's), gated on the height above ground the
vehicle reports and on the landing attempt.

A delayed value reaches its reader in one of two ways. A mode that pushes values to the autopilot
(`apply`, then `arrival_s`) sends each at its own arrival time. One that reads its sensors at their ticks
(`take`, the paper's algorithms and a plugin's views) reads at each tick the newest value that has arrived
by then, as a program reading the latest result of a pipeline; an older one that arrived in the same
interval is passed over (counted as superseded).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from typing import Any, TypeVar

import numpy as np

from ..sensing.faults import FaultInjector, FaultKind, FaultSpec

V = TypeVar("V")


class FaultGate:
    """`faults`: sensor -> fault (a sensor without one passes everything); `sensors`: the ones gated;
    `streams`: the sensors, in order, that each get a child of `rng` (a superset of `sensors`)."""

    def __init__(self, *, faults: Mapping[str, FaultSpec], sensors: Sequence[str], rng: np.random.Generator,
                 streams: Sequence[str]) -> None:
        children = dict(zip(streams, rng.spawn(len(streams)))) if streams else {}
        self.injectors = {sensor: FaultInjector(sensor=sensor, spec=faults.get(sensor, FaultSpec()),
                                                rng=children[sensor]) for sensor in sensors}
        self._in_flight: dict[str, deque[tuple[float, object]]] = {sensor: deque() for sensor in sensors}
        self._superseded = dict.fromkeys(sensors, 0)

    def apply(self, sensor: str, value: V, *, height_m: float | None, attempt: int = 1) -> V | None:
        """One new value of `sensor`: what to use in its place (None: dropped; see `FaultInjector.apply`).
        `height_m`: above the ground as the vehicle knows it (None: unknown); `attempt`: the landing attempt
        under way (1 first)."""
        injector = self.injectors.get(sensor)
        if injector is None:
            return value
        return injector.apply(value, height_m=height_m, attempt=attempt)

    def arrival_s(self, sensor: str, ready_s: float, *, attempt: int = 1) -> float:
        """When a value `apply` kept, ready at `ready_s` (the clock's s), arrives: `ready_s` unless `sensor`'s
        fault delays it (see `FaultInjector.arrival_s`)."""
        injector = self.injectors.get(sensor)
        return ready_s if injector is None else injector.arrival_s(ready_s, attempt=attempt)

    def take(self, sensor: str, value: V | None, *, now_s: float, height_m: float | None,
             attempt: int = 1) -> V | None:
        """A sensor tick at `now_s` (the clock's s) with its new value (None: the tick brought none): the
        value the reader gets now, the newest that has arrived by `now_s` (None: none arrived). Without a
        delay fault, the new value after `apply`."""
        if value is not None:
            value = self.apply(sensor, value, height_m=height_m, attempt=attempt)
        in_flight = self._in_flight.get(sensor)
        if in_flight is None:
            return value
        if value is not None:
            in_flight.append((self.arrival_s(sensor, now_s, attempt=attempt), value))
        newest = None
        while in_flight and in_flight[0][0] <= now_s:
            if newest is not None:
                self._superseded[sensor] += 1
            newest = in_flight.popleft()[1]
        return newest

    def set_spec(self, sensor: str, spec: FaultSpec) -> None:
        """A new fault for a gated sensor (the thesis' fault command during the flight)."""
        if sensor in self.injectors:
            self.injectors[sensor].set_spec(spec)

    def details(self) -> dict[str, Any]:
        """Per sensor: its fault, the values produced, the values dropped; under a stale fault the values
        given again; under a stalestamp fault the values sent with an old time; under a false fault the values
        replaced by the false target; under a delay fault the values delayed, their mean delay (ms) and those a
        reader at its ticks passed over. A combined fault's parts count together."""
        details: dict[str, Any] = {}
        for sensor, injector in sorted(self.injectors.items()):
            chain = injector.chain()
            kinds = {part.spec.kind for part in chain}

            def total(counter: str) -> Any:
                return sum(getattr(part, counter) for part in chain)

            details[f"{sensor}_fault"] = str(injector.spec)
            details[f"{sensor}_produced"] = injector.produced
            details[f"{sensor}_dropped"] = total("dropped")
            for counter, kind, name in (("repeated", FaultKind.STALE, "repeated"),
                                        ("old_stamped", FaultKind.STALESTAMP, "old_stamp"),
                                        ("falsified", FaultKind.FALSE, "false")):
                if total(counter) or kind in kinds:
                    details[f"{sensor}_{name}"] = total(counter)
            delayed = total("delayed")
            if delayed or FaultKind.DELAY in kinds:
                details[f"{sensor}_delayed"] = delayed
                details[f"{sensor}_delay_mean_ms"] = round(1000.0 * total("delay_total_s") / delayed, 1) \
                    if delayed else None
                details[f"{sensor}_superseded"] = self._superseded[sensor]
        return details
