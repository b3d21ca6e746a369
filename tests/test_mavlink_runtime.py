"""The whole mission over MAVLink (MAVSDK) against the simulator's MAVLink face on localhost."""

import asyncio
import re
import threading
import time

import pytest

from preland_app.clock_scaled import ScaledWallClock
from preland_app.outcome import Outcome
from preland_app.runtime.embedded import TrialRequest
from preland_app.runtime.mavlink import fly_mavlink
from preland_app.sim.mavlink_face import MavlinkFace
from preland_app.sim.params import ARDUCOPTER_PARAMS
from preland_app.sim.simulator import Simulator
from preland_app.vehicle.mavlink_backend import MavlinkVehicle
from preland_app.vehicle.types import FlightMode

from .ports import free_udp_port as free_port
from .waiting import until, until_async

SPEEDUP = 8.0
# Wall seconds a test waits for a served simulator to get somewhere: far above what it takes.
PATIENCE_S = 120.0


class ServedSimulator:
    """A MavlinkFace in a background thread with its own event loop."""

    def __init__(self, mission, seed: int, speedup: float = SPEEDUP, paced: bool = False) -> None:
        self.speedup = speedup
        self.paced = paced
        self.port = free_port()
        self.simulator = Simulator(seed=seed, environment=mission.environment, params=dict(mission.params),
                                   initial_yaw_deg=mission.initial_yaw_deg)
        self.loop = asyncio.new_event_loop()
        self.face = None
        self._task = None
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        until(lambda: self.face is not None, timeout_s=PATIENCE_S, what="the MAVLink face to start")

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.face = MavlinkFace(simulator=self.simulator, clock=ScaledWallClock(speedup=self.speedup),
                                listen=f"udp:127.0.0.1:{self.port}", paced=self.paced)
        self._task = self.loop.create_task(self.face.run())
        try:
            self.loop.run_until_complete(self._task)
        except asyncio.CancelledError:
            pass

    @property
    def url(self) -> str:
        return f"udpout://127.0.0.1:{self.port}"

    def stop(self) -> None:
        if self._task is not None:
            self.loop.call_soon_threadsafe(self._task.cancel)
        self._thread.join(timeout=5)


@pytest.mark.parametrize("mode, paced, faults", [("normal", False, {}), ("irlock", True, {"irlock": "burst:0.3:10"}),
                                                 ("irlock", True, {"irlock": "stale:0.3"}),
                                                 ("irlock", True, {"irlock": "delay:100:40"}),
                                                 ("irlock", True, {"irlock": "false:0.1:3"}),
                                                 ("irlock", True, {"irlock": "stalestamp:0.3"})])
def test_thesis_mission_over_mavlink(thesis_mission, short_mission, mode, paced, faults):
    # GPS alone follows the vehicle's clock, as on SITL and a drone; the IR-LOCK's 50 Hz readings fly in
    # lock-step, each at its vehicle time however loaded the machine is, and lose some in bursts on the way,
    # are given again, reach the vehicle late, point 3 m off the beacon, or carry the time of the one before.
    # The fault cases fly the thesis mission made short (from 5 m): what they check happens while landing.
    mission = thesis_mission if mode == "normal" else short_mission
    served = ServedSimulator(mission, seed=4, paced=paced)
    try:
        request = TrialRequest(mission=mission, seed=4, land_mode=mode, faults=faults)
        outcome = asyncio.run(fly_mavlink(request, url=served.url, paced=paced))
    finally:
        served.stop()
    assert outcome.outcome is Outcome.LANDED, outcome.message
    assert outcome.details["runtime"] == "mavlink"
    if not paced:
        assert outcome.details["clock_rate"] > 2.0  # the clock follows the served 8x
    kinds = [e.kind for e in outcome.events]
    assert kinds.count("waypoint") == 4 and "disarmed" in kinds
    # Scored from the simulator's truth (SIM_STATE), as in-process runs are.
    truth = served.simulator.touchdowns()[-1]
    reference = (2.0, 0.0) if mode == "irlock" else (0.0, 0.0)
    expected_cm = 100 * ((truth.north_m - reference[0]) ** 2 + (truth.east_m - reference[1]) ** 2) ** 0.5
    assert outcome.landing_error_cm == pytest.approx(expected_cm, abs=3.0)
    if mode == "irlock":
        assert outcome.landing_error_cm < 15.0 and served.face.landing_targets > 100
        details = outcome.details
        assert details["irlock_fault"] == faults["irlock"]
        if "delay" in faults["irlock"]:
            # Every reading reaches the vehicle, 60 to 140 ms late (in order, so a little more on average),
            # but those still on their way at touchdown (at most 140 ms of them, 7 readings).
            assert details["irlock_dropped"] == 0 and 100.0 <= details["irlock_delay_mean_ms"] < 115.0
            assert served.face.landing_targets == details["landing_targets_sent"]
            assert 0 <= details["irlock_produced"] - served.face.landing_targets <= 7
        elif "stalestamp" in faults["irlock"]:
            # Every reading is sent, about 3 in 10 with the time of the one before.
            assert details["irlock_dropped"] == 0
            assert 0.2 < details["irlock_old_stamp"] / details["irlock_produced"] < 0.4
            assert served.face.landing_targets == details["irlock_produced"]
        elif "false" in faults["irlock"]:
            # Every reading is sent, a tenth of them pointing 3 m off; the autopilot refuses those.
            assert details["irlock_dropped"] == 0 and 0.05 < details["irlock_false"] / details["irlock_produced"] < 0.15
            assert served.face.landing_targets == details["irlock_produced"]
        else:
            changed = details["irlock_repeated"] if "stale" in faults["irlock"] else details["irlock_dropped"]
            assert 0.15 < changed / details["irlock_produced"] < 0.45
            # Every reading kept or given again, and none dropped, reaches the vehicle as a LANDING_TARGET.
            assert served.face.landing_targets == details["irlock_produced"] - details["irlock_dropped"]
    else:
        assert 5.0 < outcome.landing_error_cm < 300.0
    # From 0.75 to 2 times the descent at LAND_SPEED (50 cm/s): 15 to 40 s from the thesis mission's 10 m.
    nominal_s = mission.takeoff.altitude_rel_m / (ARDUCOPTER_PARAMS["LAND_SPEED"].default / 100.0)
    assert 0.75 * nominal_s < outcome.landing_time_s < 2.0 * nominal_s


class _PhysicsBeside:
    """A physics in the companion's process that the sensors see the world from (as SITL's JSON bridge is): here
    the served simulator's own state, shifted 0.37 m north so that a score read from it is told from one read
    from SIM_STATE."""

    SHIFT_NORTH_M = 0.37

    def __init__(self, simulator: Simulator) -> None:
        self.simulator = simulator

    def pose(self):
        raise AssertionError("the normal land mode reads no sensor")

    def time_s(self) -> float:
        return self.simulator.true_pose().time_s

    def ned(self) -> tuple[float, float, float]:
        pose = self.simulator.true_pose()
        return pose.north_m + self.SHIFT_NORTH_M, pose.east_m, -pose.down_m


def test_a_physics_beside_the_companion_is_the_truth_the_landing_is_scored_by(thesis_mission):
    served = ServedSimulator(thesis_mission, seed=6)
    try:
        outcome = asyncio.run(fly_mavlink(TrialRequest(mission=thesis_mission, seed=6, land_mode="normal"),
                                          url=served.url, sensor_truth=_PhysicsBeside(served.simulator)))
    finally:
        served.stop()
    assert outcome.outcome is Outcome.LANDED, outcome.message
    rest = served.simulator.true_pose()
    assert rest.on_ground
    # Exact (not SIM_STATE's rounding of about a centimetre): the trajectory's last truth row is the state the
    # vehicle came to rest in, shifted.
    expected_cm = 100 * ((rest.north_m + _PhysicsBeside.SHIFT_NORTH_M) ** 2 + rest.east_m ** 2) ** 0.5
    assert outcome.landing_error_cm == pytest.approx(expected_cm, abs=1e-6)


def _fly_irlock_paced_then_stop(served, mission, *, seed: int):
    """One IR-LOCK trial of `mission` paced against `served`, which is stopped after it."""
    try:
        return asyncio.run(fly_mavlink(TrialRequest(mission=mission, seed=seed, land_mode="irlock"), url=served.url,
                                       paced=True))
    finally:
        served.stop()


def test_a_stalled_truth_stream_blinds_the_sensors_instead_of_showing_old_views(short_mission):
    # SIM_STATE stops for 2.5 vehicle s, half a second into LAND, while the rest of the telemetry goes on (a
    # stalled link or process). Readings of the last pose stamped with the present had the autopilot chase a
    # target that was not there: 25 m off; stamped with the pose's time and sent for 0.25 s, 5 to 19 m off.
    # In lock-step the SIM_STATE that should come with each held time is the one left out.
    served = ServedSimulator(short_mission, seed=4, paced=True)
    send_sim_state, stall = served.face._send_sim_state, {"land_s": None, "skipped": 0}

    def stalled_sim_state() -> None:
        simulator = served.simulator
        if simulator.autopilot.mode is FlightMode.LAND:
            stall["land_s"] = simulator.time_s if stall["land_s"] is None else stall["land_s"]
            if 0.5 <= simulator.time_s - stall["land_s"] < 3.0:
                stall["skipped"] += 1
                return
        send_sim_state()

    served.face._send_sim_state = stalled_sim_state
    outcome = _fly_irlock_paced_then_stop(served, short_mission, seed=4)
    assert stall["skipped"] >= 40, (outcome.outcome, outcome.message)  # SIM_STATE at 50 Hz for 2.5 s: about 125
    assert outcome.outcome is Outcome.LANDED, outcome.message
    assert outcome.landing_error_cm < 15.0
    # The IR-LOCK's 50 Hz ticks in the stall gave nothing (and a few outside it, between two SIM_STATEs).
    assert outcome.details["ticks_without_new_truth"] >= 120


def fly_paced(mission, *, seed: int, **request) -> tuple:
    """One trial in lock-step with a paced face: (outcome, the served simulator)."""
    served = ServedSimulator(mission, seed=seed, paced=True)
    try:
        outcome = asyncio.run(fly_mavlink(TrialRequest(mission=mission, seed=seed, **request), url=served.url,
                                          paced=True))
    finally:
        served.stop()
    return outcome, served


def _silence_heartbeats_in_flight(mission, *, seed: int, paced: bool, speedup: float = SPEEDUP) -> tuple:
    """Fly `mission` and silence the face's HEARTBEAT once the vehicle is in the air: (outcome, vehicle time
    of the silence, vehicle time the trial ended at). Paced, the trial ends where the companion lets the face
    go (its PRELAND_PACE 0): the face then runs free, so its time when the trial's result is in is later.
    Free, the face runs on while the companion closes the link, for as long as a loaded machine makes that
    take: the trial ends where the companion's link check finds the link lost (the face's time then)."""
    from preland_app.errors import LinkLost
    from preland_app.vehicle.mavlink_backend import MavlinkVehicle

    served = ServedSimulator(mission, seed=seed, speedup=speedup, paced=paced)
    released_at, lost_at = [], []
    release = served.face._release_pace
    check_link = MavlinkVehicle._check_link

    def recording_release():  # on the face's own loop
        if not released_at:
            released_at.append(served.simulator.time_s)
        release()

    def recording_check_link(self, operation):
        try:
            check_link(self, operation)
        except LinkLost:
            if not lost_at:
                lost_at.append(served.simulator.time_s)
            raise

    served.face._release_pace = recording_release
    MavlinkVehicle._check_link = recording_check_link

    async def main():
        trial = asyncio.ensure_future(fly_mavlink(TrialRequest(mission=mission, seed=seed), url=served.url,
                                                  paced=paced))
        await until_async(lambda: served.simulator.autopilot.landed_state().name == "IN_AIR" or trial.done(),
                          timeout_s=PATIENCE_S, what="the vehicle to take off")
        silenced = asyncio.get_running_loop().create_future()

        def silence():  # on the face's own loop, between two of its steps
            served.face.heartbeats_enabled = False
            silenced.get_loop().call_soon_threadsafe(silenced.set_result, served.simulator.time_s)

        served.loop.call_soon_threadsafe(silence)
        silenced_at = await asyncio.wait_for(silenced, timeout=PATIENCE_S)
        outcome = await asyncio.wait_for(trial, timeout=PATIENCE_S)
        if paced:  # the companion's PRELAND_PACE 0 may reach the face after the trial's result is in here
            await until_async(lambda: bool(released_at), timeout_s=PATIENCE_S,
                              what="the companion to let the face go at the trial's end")
            return outcome, silenced_at, released_at[0]
        return outcome, silenced_at, lost_at[0] if lost_at else served.simulator.time_s

    try:
        return asyncio.run(main())
    finally:
        MavlinkVehicle._check_link = check_link
        served.stop()


def test_lost_heartbeat_ends_the_trial_as_link_lost(thesis_mission):
    # Heartbeats: wall-clock bound.
    outcome, silenced_at, ended_at = _silence_heartbeats_in_flight(thesis_mission, seed=5, paced=False, speedup=6.0)
    # The vehicle's other messages go on coming: their stamps count the silence, not the wall clock.
    assert outcome.outcome is Outcome.LINK_LOST and "by the stamps of its other messages" in outcome.message
    # The last heartbeat came up to 1 s before the silence; the link counts as lost after 5 vehicle seconds.
    assert ended_at - silenced_at <= 5.0 + 1.0, (silenced_at, ended_at)
    assert ended_at - silenced_at >= 3.5


def test_parameters_are_read_and_written_with_ardupilots_types(thesis_mission):
    """ArduPilot declares PLND_ENABLED INT8 and PLND_TIMEOUT REAL32 (the face too); a float-only client
    failed on real ArduPilot with WRONG_TYPE, so the backend reads and writes each with its own type."""
    from preland_app.errors import CommandDenied
    from preland_app.vehicle.mavlink_backend import MavlinkVehicle

    served = ServedSimulator(thesis_mission, seed=1, speedup=SPEEDUP)

    async def main():
        vehicle = MavlinkVehicle(url=served.url)
        await vehicle.connect()
        try:
            await vehicle.set_param("PLND_ENABLED", 1)
            await vehicle.set_param("PLND_TIMEOUT", 2.5)
            types = vehicle.param_type("PLND_ENABLED"), vehicle.param_type("PLND_TIMEOUT")
            values = await vehicle.get_param("PLND_ENABLED"), await vehicle.get_param("PLND_TIMEOUT")
            with pytest.raises(CommandDenied, match="integer parameter"):
                await vehicle.set_param("PLND_STRICT", 1.5)
            with pytest.raises(CommandDenied, match="no PARAM_VALUE"):
                await vehicle.get_param("PRL_RET_ALT")  # not an ArduPilot parameter: no answer, as ArduPilot
            return types, values
        finally:
            await vehicle.close()

    try:
        types, values = asyncio.run(main())
    finally:
        served.stop()
    assert types == ("int", "float") and values == (1.0, 2.5)
    assert served.simulator.params.value("PLND_ENABLED") == 1 and served.simulator.params.value("PLND_TIMEOUT") == 2.5


def test_urls_reach_mavsdk_in_its_own_spelling():
    """ArduPilot documents SITL and telemetry servers as tcp://host:port; MAVSDK 3 deprecates that spelling
    for tcpout://."""
    from preland_app.vehicle.mavsdk_support import mavsdk_connection_url

    assert mavsdk_connection_url("tcp://127.0.0.1:5760") == "tcpout://127.0.0.1:5760"
    assert mavsdk_connection_url("udp://:14550") == "udpin://0.0.0.0:14550"  # MAVSDK 3 deprecates udp://
    for url in ("tcpout://10.0.0.2:5760", "tcpin://0.0.0.0:5760", "udpin://127.0.0.1:14550",
                "udpout://127.0.0.1:14550", "serial:///dev/ttyAMA0:921600"):
        assert mavsdk_connection_url(url) == url


def test_a_mavsdk_call_that_never_returns_does_not_hold_the_trial_at_its_end():
    """MAVSDK's asyncio plugins run calls on the loop's default executor; a command that got
    MAV_RESULT_IN_PROGRESS from an autopilot that then went away blocks for good. With the default
    ThreadPoolExecutor, asyncio.run joined that thread when the trial ended, and campaign workers on SITL
    hung there. The backend's executor never joins it."""
    import asyncio
    import threading
    import time

    from preland_app.vehicle.mavsdk_support import DaemonCallExecutor

    never = threading.Event()

    async def trial() -> str:
        loop = asyncio.get_running_loop()
        loop.set_default_executor(DaemonCallExecutor())
        assert await loop.run_in_executor(None, lambda: 6 * 7) == 42
        try:
            await asyncio.wait_for(loop.run_in_executor(None, never.wait), timeout=0.2)
        except asyncio.TimeoutError:
            return "timed out"
        return "returned"

    started = time.perf_counter()
    result = []
    runner = threading.Thread(target=lambda: result.append(asyncio.run(trial())), daemon=True)
    runner.start()
    runner.join(timeout=10.0)
    assert not runner.is_alive(), "asyncio.run waited for the blocked call"
    assert result == ["timed out"] and time.perf_counter() - started < 10.0
    blocked = [t for t in threading.enumerate() if t.name == "preland-mavsdk-call"]
    assert blocked and all(t.daemon for t in blocked)
    never.set()


def test_a_paced_flight_against_a_vehicle_that_does_not_pace_is_refused_at_connect(thesis_mission):
    from preland_app.errors import VehicleError

    served = ServedSimulator(thesis_mission, seed=1)
    served.face._on_preland_pace = lambda message: None  # as ArduPilot: the message is not known
    try:
        with pytest.raises(VehicleError, match="does not answer PRELAND_PACE"):
            asyncio.run(fly_mavlink(TrialRequest(mission=thesis_mission, seed=1), url=served.url, paced=True))
    finally:
        served.stop()


def test_in_lock_step_a_lost_heartbeat_is_reckoned_in_vehicle_seconds(thesis_mission):
    outcome, silenced_at, ended_at = _silence_heartbeats_in_flight(thesis_mission, seed=5, paced=True)
    assert outcome.outcome is Outcome.LINK_LOST and "vehicle s in lock-step" in outcome.message
    # The message says when the last HEARTBEAT was read and how many were: a failure names its timeline.
    assert re.search(r"the last read at \d+\.\d\d s, \d+ read\)", outcome.message), outcome.message
    # HEARTBEATs came at 10 Hz of vehicle time: lost 5 vehicle s after the last, give or take a grant.
    assert 4.8 <= ended_at - silenced_at <= 5.5, (silenced_at, ended_at)


def test_a_grant_longer_than_the_link_timeout_counts_its_heartbeats_and_the_next_companion_goes_on(short_mission):
    """Paced, the face steps through a whole grant, sending its HEARTBEATs, before its answer moves the
    companion's clock: those HEARTBEATs count at the vehicle times they were sent, so one grant longer than the
    link's 5 vehicle s is no lost link. The face then holds between companions (a campaign's next trial, a
    resumed one), and the next one paces on from where the first left it."""
    served = ServedSimulator(short_mission, seed=3, paced=True)

    async def first() -> float:
        vehicle = MavlinkVehicle(url=served.url, paced=True)
        await vehicle.connect()
        try:
            await vehicle.clock.sleep(8.0)  # one grant, past the link's 5 vehicle s without a HEARTBEAT
            await vehicle.telemetry()
            return vehicle.clock.now_s()
        finally:
            await vehicle.close()

    async def second() -> tuple[float, float]:
        vehicle = MavlinkVehicle(url=served.url, paced=True)
        await vehicle.connect()
        try:
            started_s = vehicle.clock.now_s()
            await vehicle.telemetry()
            return started_s, vehicle.link_timeout_s
        finally:
            await vehicle.close()

    try:
        left_s = asyncio.run(first())
        started_s, link_timeout_s = asyncio.run(second())
    finally:
        served.stop()
    assert left_s >= 8.0 > link_timeout_s
    assert started_s == pytest.approx(left_s, abs=0.02), (started_s, left_s)


def test_a_paced_command_answered_late_in_wall_time_reaches_the_vehicle_once(short_mission):
    """MAVSDK resends a command whose COMMAND_ACK is late in wall time; paced, a late answer only means a busy
    machine, and a copy of GUIDED carried out after LAND read as a pilot takeover. The face answers the
    first DO_SET_MODE a wall second late: the vehicle still gets each mode change once, in order."""
    served = ServedSimulator(short_mission, seed=3, paced=True)
    modes_received = []
    handle = served.face._on_command_long

    def answering_the_first_mode_change_late(message):  # on the face's loop: nothing else runs meanwhile
        if message.command == 176:  # MAV_CMD_DO_SET_MODE
            modes_received.append(FlightMode(int(message.param2)))
            if len(modes_received) == 1:
                time.sleep(1.0)  # not a wait: the late answer itself, twice MAVSDK's default resend time
        handle(message)

    served.face._on_command_long = answering_the_first_mode_change_late
    outcome = _fly_irlock_paced_then_stop(served, short_mission, seed=3)
    assert outcome.outcome is Outcome.LANDED, outcome.message
    assert modes_received == [FlightMode.GUIDED, FlightMode.LAND]


def test_every_ack_a_command_call_returns_is_read_on_the_message_stream_too(thesis_mission, monkeypatch):
    """MAVSDK's message stream goes live some time after it is subscribed to (seconds, on a loaded machine).
    A command sent before then has its ACK returned to the call but never shown on the stream; in lock-step
    every later command of that kind then waited in vain for its ACK there while SITL's time ran on (a trial
    lost its link). Here the stream misses the first messages after subscribing: the connection sends no
    request until the stream delivers, so each ACK returned is read on the stream as well."""
    from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync

    from preland_app.vehicle.mavlink_backend import MavlinkVehicle

    missed_first = 3
    subscribe = MavlinkDirectAsync.subscribe_message

    async def live_late(self, name):
        seen = 0
        async for message in subscribe(self, name):
            seen += 1
            if seen > missed_first:
                yield message

    monkeypatch.setattr(MavlinkDirectAsync, "subscribe_message", live_late)
    served = ServedSimulator(thesis_mission, seed=1, speedup=SPEEDUP)

    async def main():
        vehicle = MavlinkVehicle(url=served.url)
        await vehicle.connect()
        try:
            await until_async(lambda: vehicle._final_acks_read == vehicle._acks_returned, timeout_s=PATIENCE_S,
                              what="the stream to show every ACK the command calls returned")
            return dict(vehicle._acks_returned)
        finally:
            await vehicle.close()

    try:
        returned = asyncio.run(main())
    finally:
        served.stop()
    assert returned.get(511, 0) >= 9  # every stream asked for, each ACK seen on both
