"""The faults of a landing applied to each new sensor value: one mechanism for every land mode.

The built-in precision modes, the paper's algorithms and a plugin's sensor views all pass their values
through a `FaultGate`, which drops a value or gives the sensor's last value again in its place: one
`FaultInjector` per sensor the mode uses, each drawing from a random stream of its own (spawned from the
landing's generator in the order `streams` gives, so a mode's draws do not depend on the other sensor's),
gated on the height above ground the vehicle reports and on the landing attempt.
"""

from __future__ import annotations

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

    def apply(self, sensor: str, value: V, *, height_m: float | None, attempt: int = 1) -> V | None:
        """One new value of `sensor`: what to use in its place (None: dropped; see `FaultInjector.apply`).
        `height_m`: above the ground as the vehicle knows it (None: unknown); `attempt`: the landing attempt
        under way (1 first)."""
        injector = self.injectors.get(sensor)
        if injector is None:
            return value
        return injector.apply(value, height_m=height_m, attempt=attempt)

    def set_spec(self, sensor: str, spec: FaultSpec) -> None:
        """A new fault for a gated sensor (the thesis' fault command during the flight)."""
        if sensor in self.injectors:
            self.injectors[sensor].set_spec(spec)

    def details(self) -> dict[str, Any]:
        """Per sensor: its fault, the values produced, the values dropped, and under a stale fault the values
        given again."""
        details: dict[str, Any] = {}
        for sensor, injector in sorted(self.injectors.items()):
            details[f"{sensor}_fault"] = str(injector.spec)
            details[f"{sensor}_produced"] = injector.produced
            details[f"{sensor}_dropped"] = injector.dropped
            if injector.repeated or injector.spec.kind is FaultKind.STALE:
                details[f"{sensor}_repeated"] = injector.repeated
        return details
