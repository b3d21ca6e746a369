"""The truth boundary holds by construction: nothing reachable from a LandingContext leads to ground truth."""

import asyncio
import collections
import functools
import inspect
import types

import numpy as np
import pytest

from preland_app.clock import LoopClock, run_virtual, wait_until
from preland_app.events import EventLog
from preland_app.field.takeover import GuardedVehicle
from preland_app.landing import LandingContext, LandingReport, ScoringReference
from preland_app.landing.boundary import BoundaryError, VehicleView
from preland_app.outcome import Outcome
from preland_app.runtime.embedded import TrialRequest, build_sensor_suite, run_trial
from preland_app.runtime.recorder import TrajectoryRecorder
from preland_app.sensing.irlock import IrLockModel
from preland_app.sensing.sources import IrLockSource, VirtualFrameSource
from preland_app.sensing.virtual_camera import CameraPose, VirtualCamera
from preland_app.sim.simulator import Simulator
from preland_app.vehicle.protocol import Vehicle
from preland_app.vehicle.sim_backend import SimVehicle
from preland_app.vehicle.types import FlightMode

_LEAVES = (str, bytes, int, float, complex, bool, type(None), np.ndarray, np.generic, np.random.BitGenerator,
           type, types.ModuleType)
# The runtime's objects that hold or compute the truth, and the loop that runs them all.
FORBIDDEN_TYPES = (Simulator, SimVehicle, GuardedVehicle, VirtualFrameSource, IrLockSource, IrLockModel, VirtualCamera,
                   TrajectoryRecorder, EventLog, LoopClock, asyncio.AbstractEventLoop, asyncio.Task)
TRUTH_FUNCTIONS = {"true_pose", "touchdowns", "truth", "sim_state", "ned", "pose"}


def _children(obj):
    """Everything an object leads to: container items, __dict__ and __slots__ values, every attribute
    `dir()` shows (properties evaluated, methods bound), bound methods' __self__ and __func__, functions'
    closure cells and defaults, partials' parts."""
    out = []
    if isinstance(obj, dict):
        out += [*obj.keys(), *obj.values()]
    elif isinstance(obj, (list, tuple, set, frozenset, collections.deque)):
        out += list(obj)
    if isinstance(obj, types.MethodType):
        out += [obj.__self__, obj.__func__]
    elif isinstance(obj, types.BuiltinMethodType):
        out.append(obj.__self__)
    if isinstance(obj, types.FunctionType):
        out += [cell.cell_contents for cell in obj.__closure__ or () if cell.cell_contents is not None]
        out += [*(obj.__defaults__ or ()), *(obj.__kwdefaults__ or {}).values()]
        return out
    if isinstance(obj, functools.partial):
        out += [obj.func, *obj.args, *obj.keywords.values()]
    try:
        state = object.__getattribute__(obj, "__dict__")
    except AttributeError:
        state = None
    if isinstance(state, dict):
        out += list(state.values())
    for cls in type(obj).__mro__:
        slots = cls.__dict__.get("__slots__", ())
        for name in [slots] if isinstance(slots, str) else slots:
            try:
                out.append(getattr(obj, name))
            except AttributeError:
                pass
    if not isinstance(obj, (types.MethodType, types.BuiltinMethodType)):
        for name in dir(obj):
            if name.startswith("__"):
                continue
            try:
                out.append(getattr(obj, name))
            except Exception:  # a property that cannot be evaluated here
                pass
    return out


def reachable(root) -> list:
    seen: dict[int, object] = {}
    stack = [root]
    while stack:
        obj = stack.pop()
        if id(obj) in seen:
            continue
        seen[id(obj)] = obj
        if not isinstance(obj, _LEAVES):
            stack.extend(_children(obj))
    return list(seen.values())


def truth_in(objects) -> list[str]:
    found = [type(o).__name__ for o in objects if isinstance(o, FORBIDDEN_TYPES)]
    found += [f"function {o.__qualname__}" for o in objects
              if isinstance(o, (types.FunctionType, types.MethodType, types.BuiltinMethodType))
              and o.__name__ in TRUTH_FUNCTIONS]
    return found


WALKS: list[dict] = []


class WalkingLanding:
    """A plugin (named by import path) that walks its context while it flies, reads every sensor, then lands."""

    name = "walker"
    scoring_reference = ScoringReference.PAD
    uses_irlock = True
    uses_marker = True

    async def land(self, context: LandingContext) -> LandingReport:
        objects = reachable(context)
        frame = await context.sensors.camera.next_frame()
        reading = await context.sensors.irlock.next_reading()
        markers = await context.sensors.next_markers()
        misuse = []
        for attempt in (lambda: context.vehicle.simulator, lambda: context.vehicle._vehicle,
                        lambda: context.sensors.camera._pose):
            try:
                attempt()
            except AttributeError as error:
                misuse.append(type(error).__name__)
        try:
            await context.vehicle.close()
        except BoundaryError:
            misuse.append("close refused")
        WALKS.append({"count": len(objects), "truth": truth_in(objects), "frame": frame, "reading": reading,
                      "markers": markers, "misuse": misuse})
        await context.vehicle.set_mode(FlightMode.LAND)

        async def disarmed() -> bool:
            return not (await context.vehicle.telemetry()).armed

        await wait_until(disarmed, clock=context.clock, timeout_s=context.timeout_s, operation="land")
        return LandingReport(details={"objects_walked": len(objects)})


def test_nothing_reachable_from_a_live_landing_context_is_truth(thesis_mission):
    WALKS.clear()
    outcome = run_trial(TrialRequest(mission=thesis_mission, seed=3, land_mode=f"{__name__}:WalkingLanding"))
    assert outcome.outcome is Outcome.LANDED, outcome.message
    (walk,) = WALKS
    assert walk["count"] > 100  # it did walk: the views, the generator, the specs, the camera model...
    assert walk["truth"] == []
    # The sensors give readings: a frame, an IR-LOCK value, the markers seen in the next frame.
    assert walk["frame"].image.shape == (480, 640) and walk["reading"] is not None
    assert {d.marker_id for d in walk["markers"].detections} & {0, 16}
    # `_vehicle` is the view's forwarding method (a bound method: no attribute holds the vehicle).
    assert walk["misuse"] == ["AttributeError", "AttributeError", "close refused"]


def test_the_walk_finds_truth_where_there_is_some(thesis_mission):
    """The walker is strong enough: from the runtime's own sensor suite and vehicle, it finds the truth."""

    async def main():
        clock = LoopClock()
        simulator = Simulator(seed=1)

        def true_pose() -> CameraPose:
            pose = simulator.true_pose()
            return CameraPose(pose.north_m, pose.east_m, pose.down_m, pose.roll_rad, pose.pitch_rad, pose.yaw_rad)

        suite = build_sensor_suite(mission=thesis_mission, seed=1, true_pose=true_pose, clock=clock, camera=True,
                                   irlock=True)
        vehicle = SimVehicle(simulator=simulator, clock=clock)
        context = LandingContext(vehicle=GuardedVehicle(vehicle), clock=clock, events=EventLog(clock),
                                 rng=np.random.default_rng(0), timeout_s=10.0, sensors=suite)
        return (truth_in(reachable(suite)), truth_in(reachable(GuardedVehicle(vehicle))),
                truth_in(reachable(context)))

    raw_suite, raw_vehicle, context = run_virtual(main())
    assert "Simulator" in raw_suite and any(found.endswith("<locals>.true_pose") for found in raw_suite)
    assert "Simulator" in raw_vehicle
    assert context == []  # the same objects, behind a LandingContext


def test_the_vehicle_view_is_the_protocol_and_nothing_more():
    protocol = {name for name in dir(Vehicle) if not name.startswith("_")}
    view = {name for name in dir(VehicleView) if not name.startswith("_")}
    assert view == protocol
    for name in protocol - {"clock"}:
        assert inspect.signature(getattr(VehicleView, name)).parameters.keys() == \
            inspect.signature(getattr(Vehicle, name)).parameters.keys(), name
    with pytest.raises(AttributeError):
        VehicleView.__new__(VehicleView).stash = 1  # no __dict__: nothing can be hung on a view
