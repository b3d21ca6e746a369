"""The async mission runner: the thesis' scripted mission, step by step, with timeouts.

Steps: set parameters; wait for a position estimate; GUIDED and arm; take off;
record the position; fly the path's waypoints; hand over to the land mode
(event `land_handover`, the start of the landing time on every runtime). Each
step has its own timeout (vehicle seconds) and raises a typed error; the land
mode gets `timeouts.land_s`, and one still running then is cancelled. A
watcher task checks telemetry concurrently and stops the mission if the vehicle
disarms in flight. Whatever happens, the `MissionReport` holds what was
reached; the caller turns it into a trial outcome.
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass, field

import numpy as np

from .clock import wait_until
from .config.mission import MissionSpec
from .errors import LandModeFailed, MissionAborted, PrelandError, WaitTimeout
from .field.takeover import GuardedVehicle, PilotTakeover
from .events import EventLog
from .landing.base import LandingContext, LandingReport, LandStrategy
from .landing.boundary import SensorFaults, as_sensor_view
from .landing.plugins import where
from .sensing.suite import SensorSuite
from .vehicle.protocol import Vehicle, arm_when_allowed
from .vehicle.types import FlightMode, PositionNed, Telemetry

POLL_PERIOD_S = 0.1


class GeofenceBreach(MissionAborted):
    """The vehicle left the geofence; the fence's action (LAND or RTL) has been commanded."""


TAKEOFF_REACHED_FRACTION = 0.95  # as DroneKit's example scripts (the thesis' tool) judge a take-off done


@dataclass
class MissionReport:
    """What the mission reached. Positions are estimated, NED from home, in m."""

    recorded_position_ned_m: PositionNed | None = None
    waypoints_reached: list[PositionNed] = field(default_factory=list)
    handover_time_s: float | None = None  # vehicle clock, when the land mode took over
    disarmed_time_s: float | None = None
    landing: LandingReport | None = None
    completed: bool = False


class MissionRunner:
    """Flies one mission on one vehicle with one land strategy."""

    def __init__(
        self,
        *,
        spec: MissionSpec,
        vehicle: Vehicle,
        strategy: LandStrategy,
        events: EventLog,
        rng: np.random.Generator,
        sensors: SensorSuite | None = None,
        takeoff_altitude_rel_m: float | None = None,
    ) -> None:
        self.spec = spec
        # Every command goes through the guard, so a pilot's mode change stops them all at once.
        self.guard = GuardedVehicle(vehicle)
        self.vehicle = self.guard
        self.clock = vehicle.clock
        self.strategy = strategy
        self.events = events
        self.rng = rng
        self.sensors = sensors
        # A plugin's readings carry the mission's faults; the built-in modes apply their own.
        faults = spec.land.sensor_faults()
        self.sensor_faults = SensorFaults(faults=faults, rng=rng.spawn(1)[0], clock=self.clock) if faults \
            else None
        self.takeoff_altitude_rel_m = (
            takeoff_altitude_rel_m if takeoff_altitude_rel_m is not None else spec.takeoff_altitude_rel_m()
        )
        self.report = MissionReport()
        self._airborne = False
        self._landing = False

    async def run(self) -> MissionReport:
        """Fly the mission. Raises the first error of a step or of the watcher."""
        steps = asyncio.ensure_future(self._steps())
        watcher = asyncio.ensure_future(self._watch())
        try:
            done, _ = await asyncio.wait({steps, watcher}, return_when=asyncio.FIRST_COMPLETED)
            if watcher in done and not steps.done():
                steps.cancel()
                await asyncio.gather(steps, return_exceptions=True)
                watcher.result()  # raises what the watcher found
            return steps.result()
        except WaitTimeout as error:
            # The log shows when and which step ran out of time, as it shows every other ending.
            self.events.add("timed_out", str(error), operation=error.operation, timeout_s=error.timeout_s)
            raise
        finally:
            for task in (steps, watcher):
                if not task.done():
                    task.cancel()
            await asyncio.gather(steps, watcher, return_exceptions=True)

    async def _telemetry(self) -> Telemetry:
        telemetry = await self.vehicle.telemetry()
        if self.sensor_faults is not None:
            self.sensor_faults.observe(telemetry)
        return telemetry

    async def _describe(self) -> str:
        t = await self._telemetry()
        p = t.position_ned_m
        return (f"mode {t.mode.name}, {t.landed_state.name}, position N {p.north_m:.2f} E {p.east_m:.2f} m, "
                f"altitude {t.altitude_rel_m:.2f} m")

    async def _watch(self) -> None:
        """Stop the mission if the vehicle disarms while it should be flying, if the pilot takes over,
        or if it leaves the geofence."""
        fence = self.spec.geofence
        while True:
            await self.clock.sleep(POLL_PERIOD_S)
            t = await self._telemetry()
            try:
                self.guard.check(t)
            except PilotTakeover as error:
                self.events.add("pilot_takeover", str(error), mode=t.mode.name)
                raise
            if self._airborne and not self._landing and not t.armed:
                self.events.add("aborted", "vehicle disarmed in flight")
                raise MissionAborted("vehicle disarmed in flight before landing")
            if fence is not None and t.armed:
                p = t.position_ned_m
                distance_m = math.hypot(p.north_m, p.east_m)
                if distance_m > fence.max_distance_m or -p.down_m > fence.max_height_m:
                    await self.guard.set_mode(FlightMode[fence.action])
                    message = (f"geofence: {distance_m:.1f} m from home at {-p.down_m:.1f} m "
                               f"(limits {fence.max_distance_m:g} m, {fence.max_height_m:g} m): {fence.action}")
                    self.events.add("geofence", message, action=fence.action)
                    raise GeofenceBreach(message)

    async def _steps(self) -> MissionReport:
        spec, vehicle, clock, timeouts = self.spec, self.vehicle, self.clock, self.spec.timeouts
        report = self.report
        for name, value in spec.params.items():
            await vehicle.set_param(name, value)
        if spec.params:
            self.events.add("params", f"set {len(spec.params)} parameter(s)", **spec.params)

        async def position_ok() -> bool:
            return (await self._telemetry()).position_ok

        await wait_until(position_ok, clock=clock, timeout_s=timeouts.position_fix_s, operation="wait for position",
                         poll_period_s=POLL_PERIOD_S, describe=self._describe)
        await vehicle.set_mode(FlightMode.GUIDED)
        await self._arm()
        self.events.add("armed", "armed in GUIDED")

        target_alt = self.takeoff_altitude_rel_m
        await vehicle.takeoff(altitude_rel_m=target_alt)
        self._airborne = True
        self.events.add("takeoff", f"take-off to {target_alt:g} m", altitude_rel_m=target_alt)

        async def at_altitude() -> bool:
            return (await self._telemetry()).altitude_rel_m >= TAKEOFF_REACHED_FRACTION * target_alt

        await wait_until(at_altitude, clock=clock, timeout_s=timeouts.takeoff_s, operation="take-off",
                         poll_period_s=POLL_PERIOD_S, describe=self._describe)
        recorded = (await self._telemetry()).position_ned_m
        report.recorded_position_ned_m = recorded
        self.events.add("recorded", "position recorded after take-off", north_m=recorded.north_m,
                        east_m=recorded.east_m, altitude_rel_m=-recorded.down_m)

        for index, (north_rel, east_rel) in enumerate(spec.path.waypoints_rel_ned_m, start=1):
            await self._fly_to_waypoint(index, PositionNed(recorded.north_m + north_rel,
                                                           recorded.east_m + east_rel, -target_alt))

        self._landing = True
        report.landing = await self._land()
        await self._wait_disarmed()
        report.disarmed_time_s = clock.now_s()
        report.completed = True
        return report

    async def _wait_disarmed(self) -> None:
        """A land mode may return while the autopilot is still landing (it handed over to LAND, say): the
        trial has landed only once the vehicle is disarmed, within what is left of the land timeout."""
        clock = self.clock
        left_s = self.spec.timeouts.land_s - (clock.now_s() - (self.report.handover_time_s or clock.now_s()))

        async def disarmed() -> bool:
            return not (await self._telemetry()).armed

        await wait_until(disarmed, clock=clock, timeout_s=max(left_s, 0.0), operation="land",
                         poll_period_s=POLL_PERIOD_S, describe=self._describe)

    async def _land(self) -> LandingReport:
        """Hand over to the land mode, with the mission's land timeout. Its own errors (not the vehicle's)
        become LandModeFailed naming the exception."""
        strategy, clock, timeout_s = self.strategy, self.clock, self.spec.timeouts.land_s
        sensors = None
        if self.sensors is not None:
            sensors = as_sensor_view(self.sensors, clock=clock, faults=self.sensor_faults)
        context = LandingContext(vehicle=self.guard, clock=clock, events=self.events, rng=self.rng,
                                 timeout_s=timeout_s, poll_period_s=POLL_PERIOD_S, sensors=sensors)
        self.report.handover_time_s = clock.now_s()
        self.events.add("land_handover", f"hand-over to land mode {strategy.name}", land_mode=strategy.name)
        if self.sensor_faults is not None:
            self.sensor_faults.landing = True
        # The land mode runs inline in this task (so it starts at the very moment of the hand-over); a
        # watchdog on the vehicle clock cancels it at the land timeout.
        task = asyncio.current_task()
        expired: list[bool] = []

        async def watchdog() -> None:
            await clock.sleep(timeout_s)
            expired.append(True)
            task.cancel()

        dog = asyncio.ensure_future(watchdog())
        try:
            result = await strategy.land(context)
            if expired:  # it swallowed the cancellation
                raise asyncio.CancelledError
        except asyncio.CancelledError:
            if not expired:
                raise  # the mission was stopped (watcher, Ctrl-C)
            task.uncancel()
            raise WaitTimeout(operation="land", timeout_s=timeout_s,
                              last_state=f"land mode {strategy.name} still running; {await self._describe()}") from None
        except PrelandError:
            raise  # the vehicle's errors and timeouts keep their meaning (timed_out, link_lost, ...)
        except Exception as error:
            raise LandModeFailed(f"land mode {strategy.name!r} raised {type(error).__name__}: {error}"
                                 f"{where(error)}") from error
        finally:
            dog.cancel()
        if not isinstance(result, LandingReport):
            raise LandModeFailed(f"land mode {strategy.name!r} returned {type(result).__name__}, not a LandingReport")
        if self.sensor_faults is not None:
            for key, value in self.sensor_faults.details().items():
                result.details.setdefault(key, value)
        return result

    async def _arm(self) -> None:
        await arm_when_allowed(self.vehicle, timeout_s=self.spec.timeouts.arm_s)

    async def _fly_to_waypoint(self, index: int, target: PositionNed) -> None:
        await self.vehicle.goto_ned(position_ned_m=target)
        radius_m = self.spec.path.acceptance_radius_m
        settle_m_s = self.spec.path.settle_speed_m_s
        reached: list[Telemetry] = []

        async def arrived() -> bool:
            t = await self._telemetry()
            if (t.position_ned_m.horizontal_distance_m(target) <= radius_m
                    and t.velocity_ned_m_s.horizontal_m_s <= settle_m_s):
                reached.append(t)
                return True
            return False

        await wait_until(arrived, clock=self.clock, timeout_s=self.spec.timeouts.waypoint_s,
                         operation=f"waypoint {index}", poll_period_s=POLL_PERIOD_S, describe=self._describe)
        position = reached[-1].position_ned_m
        self.report.waypoints_reached.append(position)
        self.events.add("waypoint", f"waypoint {index} reached", index=index, north_m=position.north_m,
                        east_m=position.east_m, target_north_m=target.north_m, target_east_m=target.east_m)
