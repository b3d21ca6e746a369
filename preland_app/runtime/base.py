"""Where a trial runs: the `Runtime` interface, the trial it flies, and the registry that finds a runtime by
the scheme of its URL.

One object flies every trial of `preland fly`, `preland campaign run` and the Python API:

| URL | runtime |
|---|---|
| `sim:` (the default) | the embedded simulator, in virtual time |
| `sitl:PATH` (`sitl:` for `$PRELAND_SITL_BINARY`), `?speedup=X&defaults=A.parm,B.parm&physics=preland&gyro_error=X` | a fresh ArduPilot SITL process per trial |
| `mavlink+udp://[HOST]:PORT`, `mavlink+udpout://HOST:PORT`, `mavlink+tcp://HOST:PORT`, `mavlink+serial:///dev/DEVICE?baud=N` | a vehicle over MAVLink: `preland sim serve`, a SITL already running, a drone |

A runtime's options are one frozen dataclass of its own (`options_type`); an option that does not apply to
the chosen runtime is refused (`RuntimeOptionError` names it and the runtime), never ignored. An installed
package adds a runtime under the entry-point group `preland.runtimes` (name: the URL scheme; value: a class
with `from_url`), as land modes are added.
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.metadata
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, runtime_checkable
from urllib.parse import parse_qsl

from ..config.mission import MissionSpec
from ..errors import PrelandError
from ..outcome import TrialOutcome

ENTRY_POINT_GROUP = "preland.runtimes"
DEFAULT_URL = "sim:"
MAVLINK_PREFIX = "mavlink+"
# The forms MAVSDK writes a link in, read as a mavlink+ URL (`--connect udpout://...` as before).
_MAVLINK_SCHEMES = ("udp", "udpin", "udpout", "tcp", "tcpout", "tcpin", "serial")


class RuntimeUrlError(PrelandError):
    """A runtime URL that names no runtime or cannot be read."""


class RuntimeOptionError(PrelandError):
    """An option that the chosen runtime does not take, or a value it refuses: `option` names it."""

    def __init__(self, *, option: str, runtime: str, problem: str, takes: tuple[str, ...] | None = None) -> None:
        self.option, self.runtime, self.problem, self.takes = option, runtime, problem, takes
        listed = "" if takes is None else f" (it takes: {', '.join(takes) or 'no options'})"
        super().__init__(f"{option}: {problem}{listed}")


@dataclass(frozen=True, kw_only=True)
class TrialRequest:
    """One trial: a mission, a seed, and optional overrides of its land mode (a name or an import path),
    the plugin's options (`land_params`), sensor, faults (sensor -> fault syntax) and take-off altitude."""

    mission: MissionSpec
    seed: int
    land_mode: str | None = None
    sensor: str | None = None
    faults: dict[str, str] | None = None
    takeoff_altitude_rel_m: float | None = None
    record_trajectory: bool = True
    land_params: dict[str, Any] | None = None

    def resolved_mission(self) -> MissionSpec:
        if self.land_mode is None and self.sensor is None and self.faults is None and self.land_params is None:
            return self.mission
        return self.mission.with_land(mode=self.land_mode, sensor=self.sensor, faults=self.faults,
                                      params=self.land_params)


@runtime_checkable
class Runtime(Protocol):
    """Flies trials. Picklable (a campaign sends it to its workers), so it holds a URL and options only.

    `name`: stored with every trial (`trials.runtime`); `source`: what the trial's figures are (`sim`,
    `sitl`, `field`: measured on a vehicle without ground truth); `simulated_world`: whether the weather
    and the error model are preland's to set (mission overrides of the wind apply); `max_workers`: trials
    that may fly at once (None: any; 1: one vehicle); `cluster_resource`: the custom resource a cluster
    node must advertise to run it (None: any node)."""

    scheme: ClassVar[str]
    url: str
    name: str
    source: str
    simulated_world: bool
    max_workers: int | None
    cluster_resource: str | None

    def fly(self, request: TrialRequest, *, tlog_name: str | None = None) -> TrialOutcome:
        """Fly one trial and return its outcome; a failure in the trial is its outcome. `tlog_name`: the file
        name of the trial's MAVLink telemetry log, where the runtime keeps one (its `tlog_dir` option)."""

    def on_this_machine(self) -> "Runtime":
        """This runtime as the machine it now runs on resolves it (a cluster node's own SITL binary)."""


def split_url(url: str) -> tuple[str, str, dict[str, str]]:
    """`url` as (scheme, target, query options): `sim:` -> ("sim", "", {}); `sitl:PATH?speedup=5` ->
    ("sitl", "PATH", {"speedup": "5"}); `mavlink+udp://:14550` -> ("mavlink", "mavlink+udp://:14550", {})
    (a MAVLink link keeps its whole address, read by `preland_app.mavlink.endpoint`)."""
    text = url.strip()
    if not text:
        raise RuntimeUrlError("the runtime URL is empty (expected sim:, sitl:PATH or mavlink+udp://...)")
    if text.startswith(MAVLINK_PREFIX) or text.split("://", 1)[0] in _MAVLINK_SCHEMES:
        return "mavlink", text, {}
    scheme, sep, rest = text.partition(":")
    if not sep or not scheme.replace("_", "").replace("-", "").isalnum():
        raise RuntimeUrlError(f"{url!r}: expected SCHEME:..., e.g. sim:, sitl:PATH or mavlink+udp://:14550")
    target, _, query = rest.partition("?")
    try:
        options = dict(parse_qsl(query, keep_blank_values=True, strict_parsing=bool(query)))
    except ValueError:
        raise RuntimeUrlError(f"{url!r}: the options after ? must be NAME=VALUE joined by &") from None
    return scheme.lower(), target, options


def mavlink_url(address: str) -> str:
    """A MAVLink address in any form `preland_app.mavlink.endpoint` reads, as a runtime URL (`mavlink+...`)."""
    from ..mavlink.endpoint import parse_endpoint

    return parse_endpoint(address).url


_BUILT_IN = {"sim": "preland_app.runtime.embedded:EmbeddedRuntime",
             "sitl": "preland_app.runtime.sitl:SitlRuntime",
             "mavlink": "preland_app.runtime.mavlink:MavlinkRuntime"}
_REGISTERED: dict[str, type] = {}


def register_runtime(runtime_class: type) -> None:
    """Add (or replace) the runtime for URLs of `runtime_class.scheme`."""
    _REGISTERED[runtime_class.scheme] = runtime_class


def _load(reference: str, *, what: str) -> type:
    module_name, _, attribute = reference.partition(":")
    try:
        return getattr(importlib.import_module(module_name), attribute)
    except (ImportError, AttributeError) as error:
        raise RuntimeUrlError(f"{what}: cannot load {reference} ({type(error).__name__}: {error})") from None


def runtime_schemes() -> list[str]:
    """The URL schemes this installation can fly on: built-in, registered, installed."""
    names = [*_BUILT_IN, *_REGISTERED]
    names += [ep.name for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)]
    return list(dict.fromkeys(names))


def runtime_class(scheme: str) -> type:
    if scheme in _REGISTERED:
        return _REGISTERED[scheme]
    if scheme in _BUILT_IN:
        return _load(_BUILT_IN[scheme], what=f"runtime {scheme}:")
    for entry_point in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP, name=scheme):
        return _load(entry_point.value, what=f"runtime {scheme}: (entry point of {entry_point.dist.name})"
                     if entry_point.dist else f"runtime {scheme}:")
    known = ", ".join("mavlink+udp://..., mavlink+tcp://..." if s == "mavlink" else f"{s}:" for s in runtime_schemes())
    raise RuntimeUrlError(f"no runtime for {scheme}: URLs (known: {known})")


def open_runtime(url: str | None = None, options: Mapping[str, Any] | None = None) -> Runtime:
    """The runtime `url` names (default `sim:`), with `options` (names of its options dataclass, over
    what the URL's query gives). RuntimeUrlError for an unknown scheme; RuntimeOptionError for an option
    it does not take."""
    scheme, target, query = split_url(url or DEFAULT_URL)
    cls = runtime_class(scheme)
    return cls.from_url(target=target, query=query, options=dict(options or {}))


def build_options(options_type: type, values: Mapping[str, Any], *, runtime: str) -> Any:
    """`values` as `options_type` (a frozen dataclass): a name it does not have is refused, naming the
    runtime and what it does take."""
    names = tuple(f.name for f in dataclasses.fields(options_type))
    for name in values:
        if name not in names:
            raise RuntimeOptionError(option=name, runtime=runtime, takes=names,
                                     problem=f"does not apply to the {runtime} runtime")
    return options_type(**values)


def no_options(values: Mapping[str, Any], *, runtime: str) -> None:
    """For a runtime that takes none."""
    for name in values:
        raise RuntimeOptionError(option=name, runtime=runtime, takes=(),
                                 problem=f"does not apply to the {runtime} runtime")
