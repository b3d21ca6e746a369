"""The faults of a landing applied to each new sensor value: one mechanism for every land mode.

The built-in precision modes, the paper's algorithms and a plugin's sensor views all drop values through a
`FaultGate`: one `FaultInjector` per sensor the mode uses, each drawing from a random stream of its own
(spawned from the landing's generator in the order `streams` gives, so a mode's draws do not depend on the
other sensor's), gated on the height above ground the vehicle reports and on the landing attempt.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..sensing.faults import FaultInjector, FaultSpec


class FaultGate:
    """`faults`: sensor -> fault (a sensor without one passes everything); `sensors`: the ones gated;
    `streams`: the sensors, in order, that each get a child of `rng` (a superset of `sensors`)."""

    def __init__(self, *, faults: Mapping[str, FaultSpec], sensors: Sequence[str], rng: np.random.Generator,
                 streams: Sequence[str]) -> None:
        children = dict(zip(streams, rng.spawn(len(streams)))) if streams else {}
        self.injectors = {sensor: FaultInjector(sensor=sensor, spec=faults.get(sensor, FaultSpec()),
                                                rng=children[sensor]) for sensor in sensors}

    def admit(self, sensor: str, *, height_m: float | None, attempt: int = 1) -> bool:
        """One new value of `sensor`: True to keep it. `height_m`: above the ground as the vehicle knows it
        (None: unknown); `attempt`: the landing attempt under way (1 first)."""
        injector = self.injectors.get(sensor)
        return injector is None or injector.admit(height_m=height_m, attempt=attempt)

    def set_spec(self, sensor: str, spec: FaultSpec) -> None:
        """A new fault for a gated sensor (the thesis' fault command during the flight)."""
        if sensor in self.injectors:
            self.injectors[sensor].set_spec(spec)

    def details(self) -> dict[str, Any]:
        """Per sensor: its fault, the values produced and the values dropped."""
        details: dict[str, Any] = {}
        for sensor, injector in sorted(self.injectors.items()):
            details[f"{sensor}_fault"] = str(injector.spec)
            details[f"{sensor}_produced"] = injector.produced
            details[f"{sensor}_dropped"] = injector.dropped
        return details
