"""The Vehicle protocol over MAVLink, for ArduPilot Copter (SITL or a real drone) and `preland sim serve`.

MAVSDK (the `mavsdk` 4.x package) does the link: connection URLs, system
discovery, and commands with their COMMAND_ACK retries
(MavlinkDirect.send_command). Everything else goes through MAVSDK's
MavlinkDirect plugin as plain MAVLink messages, because ArduPilot's GUIDED
mode, custom flight modes and LANDING_TARGET in MAV_FRAME_BODY_FRD have no
dedicated MAVSDK API, and reading the raw messages keeps the autopilot's own
timestamps (time_boot_ms), which the vehicle clock follows.

Parameters too go as plain PARAM_REQUEST_READ / PARAM_SET / PARAM_VALUE, with
ArduPilot's types: each PARAM_VALUE says INT8/16/32 or REAL32, integer
parameters are written as integers with their own type and read back exactly.
(MAVSDK's Param plugin caches a failed typed read against ArduPilot and then
refuses every write of that parameter with WRONG_TYPE.)

Positions: LOCAL_POSITION_NED is relative to the EKF origin; the protocol's
NED positions are relative to home (HOME_POSITION's x, y, z from the origin).
"""

from __future__ import annotations

import asyncio
import collections
import concurrent.futures
import contextlib
import json
import math
import time
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

from ..mavlink.dialect import xml_text
from ..errors import CommandDenied, LinkLost, VehicleError, WaitTimeout
from .commanded_state import Commanded, heartbeat_armed, heartbeat_mode
from .link_watch import LinkWatch
from .lockstep_clock import EXCHANGE_STEP_S, LockstepClock
from .mavsdk_support import (DaemonCallExecutor, mavsdk_connection_url, quiet_mavsdk_logs,
                             set_command_resend_wall_s)
from .paced_clock import PacedClock
from .tlog import TlogWriter
from .types import (
    Attitude,
    Battery,
    FlightMode,
    GlobalPosition,
    LandedState,
    LandingTarget,
    PositionNed,
    Telemetry,
    VelocityNed,
)
from .vehicle_time_clock import VehicleTimeClock

MAV_RESULT_IN_PROGRESS = 5  # a COMMAND_ACK that another, final one follows

MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_FRAME_LOCAL_NED = 1
MAV_FRAME_GLOBAL_RELATIVE_ALT_INT = 6
MAV_FRAME_BODY_NED = 8
MAV_FRAME_BODY_FRD = 12
POSITION_ONLY = 0b0000_1001_1111_1000  # position (and yaw when given) only
VELOCITY_ONLY = 0b0000_1001_1100_0111
YAW_IGNORED = 1 << 10
YAW_RATE_IGNORED = 1 << 11
_LANDED = {0: LandedState.UNDEFINED, 1: LandedState.ON_GROUND, 2: LandedState.IN_AIR, 3: LandedState.TAKING_OFF,
           4: LandedState.LANDING}
STREAMS_HZ = {"HEARTBEAT": 10, "GLOBAL_POSITION_INT": 10, "LOCAL_POSITION_NED": 10, "ATTITUDE": 10, "EXTENDED_SYS_STATE": 5,
              "SYS_STATUS": 2, "GPS_RAW_INT": 2, "HOME_POSITION": 1, "DISTANCE_SENSOR": 10}
# The HEARTBEAT MAVSDK sends as a companion computer (MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID), sent by
# the vehicle itself in lock-step (`keep_heartbeat_in_vehicle_time`).
COMPANION_HEARTBEAT = {"type": 18, "autopilot": 8, "base_mode": 0, "custom_mode": 0, "system_status": 0,
                       "mavlink_version": 3}
# What the vehicle reads of what the autopilot sends: its streams and the answers to requests (a lock-step clock
# counts these before a wake).
READ_MESSAGES = frozenset(STREAMS_HZ) | {"COMMAND_ACK", "PARAM_VALUE", "STATUSTEXT"}
# Ground truth for the simulated sensors: each of their readings needs a SIM_STATE of its own, and the
# IR-LOCK reads at 50 Hz.
SIM_STATE_HZ = 50
# Paced (PRELAND_PACE): a grant the simulator has not answered within this many wall seconds is sent again
# (UDP may drop it); the first answer is awaited this long before the vehicle counts as not pacing.
PACE_RESEND_WALL_S = 0.5
PACE_FIRST_ANSWER_WALL_S = 5.0
CLOSE_CALLS_WALL_S = 2.0  # at close, how long MAVSDK calls still running are waited for
PARAM_TRIES = 3
PARAM_TIMEOUT_S = 1.5  # wall seconds per try
FLOAT_PARAM_TYPES = (9, 10)  # MAV_PARAM_TYPE_REAL32, REAL64
# Paced and in lock-step, the vehicle answers a command within its own time, which this process grants: an
# answer is late in wall time only because this machine is busy. MAVSDK resends a command whose COMMAND_ACK
# is late (after 0.5 wall s by default), and the vehicle carries the copy out as a second command, maybe after
# a later one (a DO_SET_MODE GUIDED after LAND reads as a pilot takeover). Over this machine's own UDP nothing
# is lost, so there MAVSDK waits this long before a resend (wall s).
LOCAL_COMMAND_RESEND_WALL_S = 5.0
MESSAGE_IDS = {"HEARTBEAT": 0, "GLOBAL_POSITION_INT": 33, "LOCAL_POSITION_NED": 32, "ATTITUDE": 30, "EXTENDED_SYS_STATE": 245,
               "SYS_STATUS": 1, "GPS_RAW_INT": 24, "HOME_POSITION": 242, "DISTANCE_SENSOR": 132, "SIM_STATE": 108}
T = TypeVar("T")


class MavlinkVehicle:
    """A Vehicle over a MAVLink connection URL (udp://:14550, udpout://host:port, tcp://host:port,
    serial:///dev/ttyAMA0:921600), for ArduPilot Copter. `paced`: the vehicle is preland's simulator and
    runs in lock-step with this companion (PRELAND_PACE, see `paced_clock`); its clock is then a
    `PacedClock`, and the ground truth comes with each held time. `lockstep`: the vehicle is SITL on a
    physics in this process that owns time, and this is its clock (`lockstep_clock`). `before_link`: called
    just before MAVSDK opens the connection (binds its port), so whoever kept the port for it lets it go."""

    def __init__(self, *, url: str, connect_timeout_s: float = 30.0, link_timeout_s: float = 5.0,
                 want_truth: bool = False, tlog_path: str | None = None, paced: bool = False,
                 lockstep: LockstepClock | None = None, before_link: Callable[[], None] | None = None) -> None:
        if paced and lockstep is not None:
            raise ValueError("a vehicle is paced (PRELAND_PACE) or in lock-step with a local physics, not both")
        self.url = url
        self._before_link = before_link
        self.tlog = TlogWriter(tlog_path) if tlog_path else None
        self.connect_timeout_s = connect_timeout_s
        self.link_timeout_s = link_timeout_s
        self.want_truth = want_truth
        self._clock = VehicleTimeClock()
        self.paced = paced
        self._paced_clock = PacedClock(grant=self._want_grant, explain=self._pace_sends) if paced else None
        self._lockstep = lockstep
        self._listened: collections.Counter[str] = collections.Counter()  # messages read, by name
        self._received = 0  # messages taken in
        if lockstep is not None:
            lockstep.activity = self._activity
            lockstep.listened, lockstep.taken_in = self._listened, READ_MESSAGES
        self._pace_wanted_ms: int | None = None
        self._pace_changed = asyncio.Event()
        self._pace_sent = 0  # how many times the newest PRELAND_PACE grant was sent
        self._pace_send_failures = 0  # of those, sends MAVSDK refused
        self._pace_send_error = ""  # the last refusal
        self._failure: LinkLost | None = None  # a task that reads or writes the link stopped (see `_background`)
        self._last_heartbeat_vehicle_s = 0.0
        self._messages: dict[str, dict[str, Any]] = {}
        self._sim_state_time_s = 0.0
        self._sim_state_fresh = False
        self._status_texts: list[str] = []
        self._heartbeat_stamp_s: float | None = None  # the newest vehicle time read when a heartbeat came
        self._link = LinkWatch()  # what was heard, and when: whether a free-running vehicle's link is lost
        self._sdk = None
        self._direct = None
        self._sender = None  # the synchronous MavlinkDirect under `_direct`
        self._executor: DaemonCallExecutor | None = None
        self._param_types: dict[str, int] = {}  # name -> MAV_PARAM_TYPE, as the autopilot declares it
        self._param_values: dict[str, tuple[float, int, int]] = {}  # name -> (value, type, receipt number)
        self._param_receipts = 0
        self._tasks: list[asyncio.Task] = []
        self._closed = False
        self._connected = False
        self.system_id = 1
        # An accepted arm/disarm or mode change holds until a HEARTBEAT sent after it is read (see Commanded).
        self._commanded_armed: Commanded | None = None
        self._commanded_mode: Commanded | None = None
        self._acks_returned: dict[int, int] = {}  # MAV_CMD -> COMMAND_ACKs its calls have returned
        self._acks_streamed: dict[int, list[int]] = {}  # MAV_CMD -> per ACK on the message stream, HEARTBEATs before
        self._final_acks_read: dict[int, int] = {}  # MAV_CMD -> final COMMAND_ACKs read on the message stream
        self._heartbeats_read = 0

    @property
    def clock(self) -> VehicleTimeClock | PacedClock | LockstepClock:
        """The vehicle's time: followed (`VehicleTimeClock`), or in lock-step (`PacedClock`, `LockstepClock`)."""
        if self._lockstep is not None:
            return self._lockstep
        return self._paced_clock if self._paced_clock is not None else self._clock

    @property
    def connected(self) -> bool:
        """True from the end of `connect()` until `close()`."""
        return self._connected and not self._closed

    # ---------------------------------------------------------------- link

    async def connect(self) -> None:
        quiet_mavsdk_logs()
        from mavsdk.asyncio.mavsdk import Configuration, Mavsdk
        from mavsdk.component_type import ComponentType

        self._executor = DaemonCallExecutor()
        asyncio.get_running_loop().set_default_executor(self._executor)
        self._sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.COMPANION_COMPUTER))
        if self.paced or self._lockstep is not None:
            set_command_resend_wall_s(self._sdk, LOCAL_COMMAND_RESEND_WALL_S)
        try:
            await self._link_up()
        except BaseException:
            # Nothing is left to the garbage collector: it destroys MAVSDK in whatever thread collects, which
            # can abort the process (a caller that closes after a failed connect finds it closed).
            await self.close()
            raise

    async def _link_up(self) -> None:
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync

        if self._before_link is not None:
            self._before_link()
        try:
            await self._sdk.add_any_connection(mavsdk_connection_url(self.url))
        except Exception as error:
            raise VehicleError(operation="connect", reason=f"{self.url}: {error}") from None
        system = await self._sdk.first_autopilot(timeout_s=self.connect_timeout_s)
        if system is None:
            raise LinkLost(operation="connect", reason=f"no autopilot on {self.url} within "
                                                        f"{self.connect_timeout_s:g} s")
        self._direct = MavlinkDirectAsync(system)
        # Sends go straight to the plugin under the asyncio wrapper, from this thread: sending queues the
        # message and returns (no answer is awaited), where the wrapper starts a thread for each (a
        # LANDING_TARGET and a PRELAND_PACE grant every few vehicle ms). The ctypes call releases the GIL.
        self._sender = self._direct._plugin
        self._background(self._listen(), "listen")
        self._background(self._link.tick(), "tick")
        deadline = time.monotonic() + self.connect_timeout_s
        # No request before MAVSDK's message stream delivers: an answer sent before the subscription is live
        # (later than the call, on a loaded machine) is returned to its call but never read on the stream,
        # and the two counts of a command's ACKs would differ for the rest of the link (`_command`).
        while not self._received:
            if time.monotonic() > deadline:
                raise LinkLost(operation="connect", reason="MAVSDK's message stream delivered nothing")
            await asyncio.sleep(0.01)
        # Only a followed clock needs the link's rate measured. Paced, the simulator may hold at time 0 (sim serve
        # --paced): its HEARTBEAT is enough. In lock-step SITL runs free until the mission's start
        # (`LockstepClock.start_at`): each wall second spent here is vehicle seconds of that margin.
        followed = self.clock is self._clock
        while (followed and not self._clock.settled) or "HEARTBEAT" not in self._messages:
            if time.monotonic() > deadline:
                raise LinkLost(operation="connect", reason="no telemetry from the autopilot")
            await self._request_streams()
            await asyncio.sleep(0.2)
        await self._request_streams()
        if self._paced_clock is not None:
            await self._start_pacing()
        self._connected = True

    async def _start_pacing(self) -> None:
        try:
            await self._direct.load_custom_xml(xml_text())
        except Exception as error:
            raise VehicleError(operation="connect", reason=f"MAVSDK cannot load preland's dialect: {error}") from None
        self._background(self._pace_sender(), "pace")
        self._paced_clock.start(self._clock.now_s())
        deadline = time.monotonic() + PACE_FIRST_ANSWER_WALL_S
        while not self._paced_clock.answers:
            if time.monotonic() > deadline:
                raise VehicleError(operation="connect", reason=f"{self.url} does not answer PRELAND_PACE within "
                                                               f"{PACE_FIRST_ANSWER_WALL_S:g} s: paced flight needs "
                                                               "preland's simulator (preland sim serve)")
            await asyncio.sleep(0.01)

    def _background(self, coroutine, name: str) -> None:
        """A task that runs as long as the link. One that stops on an error takes the link with it, named:
        silently gone, it would leave the trial waiting for answers nobody reads or grants nobody sends."""
        task = asyncio.ensure_future(coroutine)
        task.set_name(f"mavlink-{name}")
        task.add_done_callback(self._background_done)
        self._tasks.append(task)

    def _background_done(self, task: asyncio.Task) -> None:
        if task.cancelled() or self._closed:
            return
        error = task.exception()
        reason = f"{task.get_name()} stopped: {type(error).__name__}: {error}" if error else \
            f"{task.get_name()} ended"
        self._failure = LinkLost(operation=task.get_name(), reason=reason)
        if self._paced_clock is not None:
            self._paced_clock.fail(operation=task.get_name(), reason=reason)

    def _pace_sends(self) -> str:
        failed = f", {self._pace_send_failures} failed ({self._pace_send_error})" if self._pace_send_failures else ""
        return f"that grant sent {self._pace_sent} times{failed}"

    def _want_grant(self, time_ms: int) -> None:
        """PacedClock's grant: the sender task sends the newest, one at a time, so grants leave in order."""
        self._pace_wanted_ms = time_ms
        self._pace_changed.set()

    async def _pace_sender(self) -> None:
        clock = self._paced_clock
        sent_ms, sent_wall_s = None, 0.0
        while True:
            wanted_ms = self._pace_wanted_ms
            # Unanswered until the simulator says it holds at or past the grant. Any answer is not enough: one
            # to an earlier grant, or a second answer to a grant sent twice, can come after this grant has
            # left, and this grant's own answer may be lost.
            unanswered = bool(sent_ms) and round(clock.now_s() * 1000) < sent_ms
            if wanted_ms is not None and (wanted_ms != sent_ms or (
                    unanswered and time.monotonic() - sent_wall_s > PACE_RESEND_WALL_S)):
                if wanted_ms != sent_ms:
                    self._pace_sent = self._pace_send_failures = 0
                sent_ms, sent_wall_s = wanted_ms, time.monotonic()
                self._pace_sent += 1
                try:
                    await self._send_now("PRELAND_PACE", {"time_boot_ms": wanted_ms})
                except Exception as error:  # MAVSDK could not send it now: sent again after PACE_RESEND_WALL_S
                    self._pace_send_failures += 1
                    self._pace_send_error = f"{type(error).__name__}: {error}"
                continue
            self._pace_changed.clear()
            try:
                await asyncio.wait_for(self._pace_changed.wait(), timeout=PACE_RESEND_WALL_S)
            except TimeoutError:
                pass

    async def restart_streams(self) -> None:
        """Stop every stream, then ask for each again. ArduPilot sets a stream's schedule when its interval is
        first set (GCS_MAVLINK::set_ap_message_interval), so its messages then come at vehicle times counted
        from now, not from when the connection's requests happened to arrive."""
        await self._request_streams(restart=True)

    def keep_heartbeat_in_vehicle_time(self) -> None:
        """In lock-step with SITL: from now on, the companion's HEARTBEAT reaches SITL at each whole vehicle
        second. MAVSDK sends its own each wall second, which reach SITL at whatever vehicle time this
        machine's speed gives (and the same seed then landed a few millimetres apart); the relay drops
        those (`LockstepClock.gate`). SITL still hears a ground station once a second, as a GCS failsafe
        (FS_GCS_ENABLE) needs."""
        if self._lockstep is not None and self._lockstep.gate("HEARTBEAT"):
            self._background(self._heartbeats(), "heartbeat")

    async def _heartbeats(self) -> None:
        clock = self._lockstep
        while True:
            now_s = clock.now_s()
            await clock.sleep(math.floor(now_s + 1e-9) + 1.0 - now_s)
            await self._send_now("HEARTBEAT", COMPANION_HEARTBEAT, targeted=False)

    async def _request_streams(self, *, restart: bool = False) -> None:
        streams = dict(STREAMS_HZ)
        if self.want_truth and not self.paced:  # paced: the simulator sends SIM_STATE with each held time
            streams["SIM_STATE"] = SIM_STATE_HZ
        for name in streams if restart else ():  # all stopped first: a stream sharing a schedule keeps it
            await self._command(MAV_CMD_SET_MESSAGE_INTERVAL, MESSAGE_IDS[name], -1, operation="set_message_interval",
                                check=False)
        for name, rate_hz in streams.items():
            await self._command(MAV_CMD_SET_MESSAGE_INTERVAL, MESSAGE_IDS[name], 1e6 / rate_hz,
                                operation="set_message_interval", check=False)

    async def _listen(self) -> None:
        async for message in self._direct.subscribe_message(""):
            try:
                fields = json.loads(message.fields_json)
            except ValueError:
                continue
            name = message.message_name
            self._received += 1
            self._listened[name] += 1
            if self._lockstep is not None:
                self._lockstep.nudge()  # its waits look again once this message is read (below)
            if self.tlog is not None:
                self.tlog.write(name=name, fields=fields, system_id=message.system_id,
                                component_id=message.component_id)
            if message.system_id != self.system_id:
                continue
            self._messages[name] = fields
            self._link.heard(heartbeat=name == "HEARTBEAT")
            if name == "HEARTBEAT":
                self._heartbeat_stamp_s = self._clock.newest_s
                self._last_heartbeat_vehicle_s = self.clock.now_s()
                if self._paced_clock is not None and self._clock.newest_s is not None:
                    # Paced, the simulator steps through a whole grant before its answer moves this clock: a
                    # HEARTBEAT read meanwhile was sent at the time of the stamped messages read before it.
                    self._last_heartbeat_vehicle_s = max(self._last_heartbeat_vehicle_s, self._clock.newest_s)
                self._heartbeats_read += 1
                self._heartbeat_confirms(fields)
            elif name == "COMMAND_ACK":
                acked = int(fields.get("command", -1))
                self._acks_streamed.setdefault(acked, []).append(self._heartbeats_read)
                if int(fields.get("result", 0)) != MAV_RESULT_IN_PROGRESS:
                    self._final_acks_read[acked] = self._final_acks_read.get(acked, 0) + 1
            elif name == "PARAM_VALUE":
                self._param_receipts += 1
                param_id = str(fields.get("param_id", "")).rstrip("\x00")
                self._param_values[param_id] = (float(fields.get("param_value", 0.0)),
                                                int(fields.get("param_type", 9)), self._param_receipts)
            elif name == "STATUSTEXT":
                self._status_texts.append(str(fields.get("text", "")))
            elif name == "PRELAND_PACE" and self._paced_clock is not None:
                held_s = int(fields.get("time_boot_ms", 0)) / 1000.0
                if not self._paced_clock.answers and "HEARTBEAT" in self._messages:
                    self._last_heartbeat_vehicle_s = held_s  # heard before time meant anything here
                if self._sim_state_fresh:
                    self._sim_state_time_s = held_s  # the SIM_STATE sent just before is of the held time
                    self._sim_state_fresh = False
                self._paced_clock.held(held_s)
            elif name == "SIM_STATE" and self._paced_clock is not None:
                self._sim_state_fresh = True  # stamped by the held time that follows it
            elif name == "SIM_STATE":
                # SIM_STATE has no timestamp: the clock when it is read. The clock runs from the wall time at
                # which the newest time_boot_ms was read, so a backlog read late still reads as old.
                self._sim_state_time_s = self._clock.now_s()
            if "time_boot_ms" in fields:
                stamp_s = fields["time_boot_ms"] / 1000.0
                self._link.heard_stamp(stamp_s)
                self._clock.observe(stamp_s)

    def _heartbeat_confirms(self, fields: dict[str, Any]) -> None:
        """Note a HEARTBEAT that reports a commanded state, so a later one reporting another counts at once."""
        if self._commanded_mode is not None:
            self._commanded_mode.confirm(heartbeat_mode(fields))
        if self._commanded_armed is not None:
            self._commanded_armed.confirm(heartbeat_armed(fields))

    def _check_link(self, operation: str) -> None:
        if self._closed or self._direct is None:
            raise VehicleError(operation=operation, reason="not connected")
        if self._failure is not None:
            raise LinkLost(operation=operation, reason=self._failure.reason)
        locked = self._lockstep or (self._paced_clock if self._paced_clock is not None and
                                    self._paced_clock.started else None)
        if locked is not None:
            # In lock-step the vehicle's time passes only with the companion's leave, so silence is vehicle
            # time; a vehicle that stops answering at all is the clock's to find (a wall bound).
            now_s = locked.now_s()
            silent_vehicle_s = now_s - self._last_heartbeat_vehicle_s
            if silent_vehicle_s > self.link_timeout_s:
                raise LinkLost(operation=operation, reason=f"no heartbeat for {silent_vehicle_s:.1f} vehicle s in "
                                                          f"lock-step (now {now_s:.2f} s, the last read at "
                                                          f"{self._last_heartbeat_vehicle_s:.2f} s, "
                                                          f"{self._heartbeats_read} read)")
        else:
            self._link.check(operation, link_timeout_s=self.link_timeout_s, rate=self._clock.rate)

    async def close(self) -> None:
        calls_waited = False
        try:
            if self._paced_clock is not None and self._paced_clock.started and self._sdk is not None:
                self._paced_clock.release()
                try:  # the simulator runs free again at once (else after its own wall bound)
                    await asyncio.wait_for(self._send_now("PRELAND_PACE", {"time_boot_ms": 0}), timeout=2.0)
                except Exception:  # closing must not fail a trial
                    pass
            self._closed = True
            for task in self._tasks:
                task.cancel()
            await asyncio.gather(*self._tasks, return_exceptions=True)
            if self.tlog is not None:
                self.tlog.close()
            if self._executor is not None:
                # Calls still on their threads (a send the cancelled tasks left) finish before MAVSDK is
                # destroyed; one blocked for good (a command whose final ACK never comes) is left after the bound.
                deadline = time.monotonic() + CLOSE_CALLS_WALL_S
                while self._executor.running and time.monotonic() < deadline:
                    await asyncio.sleep(0.005)
            calls_waited = True
        finally:
            self._closed = True
            self._destroy_sdk(calls_waited=calls_waited)

    def _destroy_sdk(self, *, calls_waited: bool) -> None:
        """Destroy MAVSDK now, also when closing was cancelled or failed: an instance left to the garbage
        collector is destroyed whenever a collection runs, in whatever then runs, and perhaps under a call
        still sending, which aborts the process."""
        sdk, self._sdk = self._sdk, None
        if sdk is None:
            return
        if not calls_waited and self._executor is not None and self._executor.running:
            # Cancelled or failed before the calls on threads were waited for: the same bound, here (MAVSDK must
            # not be destroyed under a call that is sending).
            concurrent.futures.wait(list(self._executor.running), timeout=CLOSE_CALLS_WALL_S)
        try:
            sdk.destroy()  # synchronous in MAVSDK-Python 4
        except Exception:  # closing must not fail a trial
            pass

    # ---------------------------------------------------------------- sending

    async def _poll_pause(self) -> None:
        """Between two looks for an answer: in lock-step, one step of vehicle time (so the answer is seen at
        the vehicle time it came, whatever the machine); else 10 wall ms."""
        if self._lockstep is not None:
            await self._lockstep.sleep(EXCHANGE_STEP_S)
        else:
            await asyncio.sleep(0.01)

    def _activity(self) -> tuple[int, int]:
        """How much has come in (messages, and MAVSDK calls still out), for a lock-step clock to wait until
        nothing more does."""
        return self._received, len(self._executor.running) if self._executor is not None else 0

    def _holding(self):
        """Paced, the vehicle's time stands still during an exchange with it (as in virtual time)."""
        return self._paced_clock.holding() if self._paced_clock is not None else contextlib.nullcontext()

    async def _exchange(self, request: Awaitable[T], *, answered: Callable[[], bool], sends: str | None = None) -> T:
        """Await `request`, an exchange that waits for the vehicle's answer: paced, time stands still (the
        simulator answers while it holds); in lock-step with SITL, time runs for it (SITL answers only as
        time passes) from when SITL has the request (`sends`, the relay's key) until `answered()`, the answer
        read off the link, and the task goes on once the clock has settled after it (`LockstepClock.answered`)."""
        if self._lockstep is None:
            with self._holding():
                return await request
        with self._lockstep.exchanging(answered=answered, sends=sends):
            result = await request
            await self._lockstep.answered(answered)
            return result

    async def _send(self, name: str, fields: dict[str, Any], *, targeted: bool = True) -> None:
        with self._holding():
            await self._send_now(name, fields, targeted=targeted)

    async def _send_now(self, name: str, fields: dict[str, Any], *, targeted: bool = True) -> None:
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        payload = {"target_system": self.system_id, "target_component": 1, **fields} if targeted else dict(fields)
        delivered = self._lockstep.handing(name) if self._lockstep is not None else None
        self._sender.send_message(MavlinkMessage(message_name=name, target_system_id=self.system_id,
                                                 target_component_id=1, fields_json=json.dumps(payload)))
        if self._lockstep is not None:
            await self._lockstep.sent(delivered)

    async def _command(self, command: int, *params: float, operation: str, check: bool = True) -> int | None:
        """Send COMMAND_LONG and await its COMMAND_ACK: which ACK of `command` it was on this link (1, 2, ...),
        or None without one (`check=False`)."""
        # The stream's ACKs can come after the calls' own: an earlier call of `command` returned already, its
        # ACK not yet read on the stream, must not pass for this call's answer.
        acks_before = max(self._final_acks_read.get(command, 0), self._acks_returned.get(command, 0))

        def answered() -> bool:
            return self._final_acks_read.get(command, 0) > acks_before

        texts_before = len(self._status_texts)
        acked = await self._exchange(self._command_now(command, *params, operation=operation, check=check),
                                     answered=answered, sends=f"COMMAND_LONG:{command}")
        if acked is None:
            return None
        number, result = acked
        if check and result != 0:
            if self._lockstep is None:
                # ArduPilot sends its reason as STATUSTEXT around the ACK (paced, still in the exchange's hold).
                # In lock-step the exchange ended with all SITL sent up to its answer taken in.
                with self._holding():
                    await asyncio.sleep(0.05)
            reasons = [t for t in self._status_texts[texts_before:] if t]
            raise CommandDenied(operation=operation,
                                reason=reasons[-1] if reasons else f"MAV_RESULT {result}")
        return number

    async def _command_now(self, command: int, *params: float, operation: str,
                           check: bool = True) -> tuple[int, int] | None:
        """Send COMMAND_LONG; (which ACK of `command` on this link, its MAV_RESULT), None without an ACK."""
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        values = list(params) + [0.0] * (7 - len(params))
        fields = {"target_system": self.system_id, "target_component": 1, "command": command, "confirmation": 0,
                  **{f"param{i + 1}": float(v) for i, v in enumerate(values)}}
        try:
            ack = await self._direct.send_command(MavlinkMessage(
                message_name="COMMAND_LONG", target_system_id=self.system_id, target_component_id=1,
                fields_json=json.dumps(fields)))
        except Exception as error:
            if check:
                raise LinkLost(operation=operation, reason=f"no COMMAND_ACK ({error})") from None
            return None
        self._acks_returned[command] = number = self._acks_returned.get(command, 0) + 1
        return number, int(json.loads(ack.fields_json or "{}").get("result", 0))

    # ---------------------------------------------------------------- the protocol

    async def arm(self) -> None:
        self._check_link("arm")
        number = await self._command(MAV_CMD_COMPONENT_ARM_DISARM, 1, operation="arm")
        self._commanded_armed = self._commanded(True, MAV_CMD_COMPONENT_ARM_DISARM, number)

    async def disarm(self) -> None:
        self._check_link("disarm")
        number = await self._command(MAV_CMD_COMPONENT_ARM_DISARM, 0, operation="disarm")
        self._commanded_armed = self._commanded(False, MAV_CMD_COMPONENT_ARM_DISARM, number)

    async def takeoff(self, *, altitude_rel_m: float) -> None:
        self._check_link("takeoff")
        await self._command(MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, altitude_rel_m, operation="takeoff")

    async def set_mode(self, mode: FlightMode) -> None:
        self._check_link("set_mode")
        number = await self._command(MAV_CMD_DO_SET_MODE, 1, mode.value, operation="set_mode")
        self._commanded_mode = self._commanded(mode, MAV_CMD_DO_SET_MODE, number)

    def _commanded(self, value: Any, command: int, number: int | None) -> Commanded:
        return Commanded(value, self.clock.now_s(), ack=None if number is None else (command, number))

    def _heartbeats_after_ack(self, commanded: Commanded) -> int | None:
        """HEARTBEATs read after `commanded`'s COMMAND_ACK on the message stream (0 before it is read there), or
        None where the stream has shown no COMMAND_ACK (a vehicle or a link that leaves it out)."""
        if commanded.ack is None or not self._acks_streamed:
            return None
        command, number = commanded.ack
        streamed = self._acks_streamed.get(command, [])
        return self._heartbeats_read - streamed[number - 1] if len(streamed) >= number else 0

    def _home_local(self) -> tuple[float, float, float]:
        home = self._messages.get("HOME_POSITION")
        return (home["x"], home["y"], home["z"]) if home else (0.0, 0.0, 0.0)

    async def goto_ned(self, *, position_ned_m: PositionNed, yaw_deg: float | None = None) -> None:
        self._check_link("goto_ned")
        hx, hy, hz = self._home_local()
        mask = POSITION_ONLY | (YAW_IGNORED if yaw_deg is None else 0)
        await self._send("SET_POSITION_TARGET_LOCAL_NED", {
            "time_boot_ms": int(self.clock.now_s() * 1000), "coordinate_frame": MAV_FRAME_LOCAL_NED,
            "type_mask": mask, "x": hx + position_ned_m.north_m, "y": hy + position_ned_m.east_m,
            "z": hz + position_ned_m.down_m, "yaw": math.radians(yaw_deg or 0.0)})

    async def goto_global(self, *, latitude_deg: float, longitude_deg: float, altitude_rel_m: float) -> None:
        self._check_link("goto_global")
        await self._send("SET_POSITION_TARGET_GLOBAL_INT", {
            "time_boot_ms": int(self.clock.now_s() * 1000), "coordinate_frame": MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
            "type_mask": POSITION_ONLY | YAW_IGNORED, "lat_int": int(latitude_deg * 1e7),
            "lon_int": int(longitude_deg * 1e7), "alt": altitude_rel_m})

    async def set_velocity_ned(self, *, velocity_ned_m_s: VelocityNed, yaw_deg: float | None = None) -> None:
        self._check_link("set_velocity_ned")
        mask = VELOCITY_ONLY | (YAW_IGNORED if yaw_deg is None else 0)
        await self._send("SET_POSITION_TARGET_LOCAL_NED", {
            "time_boot_ms": int(self.clock.now_s() * 1000), "coordinate_frame": MAV_FRAME_LOCAL_NED,
            "type_mask": mask, "vx": velocity_ned_m_s.north_m_s, "vy": velocity_ned_m_s.east_m_s,
            "vz": velocity_ned_m_s.down_m_s, "yaw": math.radians(yaw_deg or 0.0)})

    async def set_velocity_body(self, *, forward_m_s: float, right_m_s: float, down_m_s: float,
                                yaw_rate_deg_s: float = 0.0) -> None:
        self._check_link("set_velocity_body")
        mask = VELOCITY_ONLY & ~YAW_RATE_IGNORED
        await self._send("SET_POSITION_TARGET_LOCAL_NED", {
            "time_boot_ms": int(self.clock.now_s() * 1000), "coordinate_frame": MAV_FRAME_BODY_NED,
            "type_mask": mask, "vx": forward_m_s, "vy": right_m_s, "vz": down_m_s,
            "yaw_rate": math.radians(yaw_rate_deg_s)})

    async def hold(self) -> None:
        self._check_link("hold")
        local = self._messages.get("LOCAL_POSITION_NED")
        if local is None:
            raise VehicleError(operation="hold", reason="no position yet")
        hx, hy, hz = self._home_local()
        await self.goto_ned(position_ned_m=PositionNed(local["x"] - hx, local["y"] - hy, local["z"] - hz))

    async def _param_exchange(self, name: str, *, operation: str, send: dict[str, Any] | None) -> tuple[float, int]:
        """Send PARAM_SET (`send`) or PARAM_REQUEST_READ and wait for the PARAM_VALUE of `name` that answers it:
        (value, MAV_PARAM_TYPE). ArduPilot answers nothing for a name it lacks."""
        asked = [self._param_receipts]  # the PARAM_VALUEs received before the newest request

        def answered() -> bool:
            answer = self._param_values.get(name)
            return answer is not None and answer[2] > asked[0]

        return await self._exchange(self._param_exchange_now(name, operation=operation, send=send, asked=asked,
                                                             answered=answered), answered=answered)

    async def _param_exchange_now(self, name: str, *, operation: str, send: dict[str, Any] | None,
                                  asked: list[int], answered: Callable[[], bool]) -> tuple[float, int]:
        for _ in range(PARAM_TRIES):
            self._check_link(operation)
            asked[0] = self._param_receipts
            if send is None:
                await self._send("PARAM_REQUEST_READ", {"param_id": name, "param_index": -1})
            else:
                await self._send("PARAM_SET", {"param_id": name, **send})
            deadline = time.monotonic() + PARAM_TIMEOUT_S
            while time.monotonic() < deadline:
                if answered():
                    value, mav_type, _ = self._param_values[name]
                    return value, mav_type
                await self._poll_pause()
        raise CommandDenied(operation=operation, reason=f"{name}: no PARAM_VALUE after {PARAM_TRIES} tries "
                                                        "(no such parameter?)")

    def param_type(self, name: str) -> str | None:
        """'int' or 'float' once `name` has been read or written, else None."""
        mav_type = self._param_types.get(name)
        return None if mav_type is None else ("float" if mav_type in FLOAT_PARAM_TYPES else "int")

    async def get_param(self, name: str) -> float:
        value, mav_type = await self._param_exchange(name, operation="get_param", send=None)
        self._param_types[name] = mav_type
        return float(value)

    async def set_param(self, name: str, value: float) -> None:
        """Write `name` with its own type (read first when unknown); an integer parameter takes only a whole
        number, and the value ArduPilot answers with must equal it exactly (a float within 1e-4 relative)."""
        if name not in self._param_types:
            await self.get_param(name)
        mav_type = self._param_types[name]
        is_int = mav_type not in FLOAT_PARAM_TYPES
        if is_int and float(value) != round(float(value)):
            raise CommandDenied(operation="set_param", reason=f"{name} is an integer parameter: {value:g} is not whole")
        read, _ = await self._param_exchange(name, operation="set_param", send={
            "param_value": float(round(float(value)) if is_int else value), "param_type": mav_type})
        matches = read == round(float(value)) if is_int else \
            abs(read - float(value)) <= 1e-4 * max(1.0, abs(float(value)))
        if not matches:
            raise CommandDenied(operation="set_param", reason=f"{name} reads back {read:g}, not {value:g}")

    async def telemetry(self) -> Telemetry:
        self._check_link("telemetry")
        m = self._messages
        heartbeat = m.get("HEARTBEAT", {})
        glob = m.get("GLOBAL_POSITION_INT", {})
        local = m.get("LOCAL_POSITION_NED", {})
        attitude = m.get("ATTITUDE", {})
        status = m.get("SYS_STATUS", {})
        home = m.get("HOME_POSITION")
        gps = m.get("GPS_RAW_INT", {})
        distance = m.get("DISTANCE_SENSOR")
        hx, hy, hz = self._home_local()
        now_s = self.clock.now_s()
        mode, armed = heartbeat_mode(heartbeat), heartbeat_armed(heartbeat)
        # When the newest HEARTBEAT was sent, by the vehicle's clock: on a followed clock, the newest stamp read
        # before it on the same ordered stream (a backlog read late, on a loaded machine, is still early), else
        # the clock's own time.
        followed = self.clock is self._clock and self._heartbeat_stamp_s is not None
        heard_s = self._heartbeat_stamp_s if followed else now_s
        if self._commanded_armed is not None:
            armed = self._commanded_armed.reported(armed, heard_s, self._heartbeats_after_ack(self._commanded_armed))
        if self._commanded_mode is not None:
            mode = self._commanded_mode.reported(mode, heard_s, self._heartbeats_after_ack(self._commanded_mode))
        relative_m = glob.get("relative_alt", 0) / 1000.0
        rangefinder_valid = bool(distance) and distance["min_distance"] <= distance["current_distance"] <= \
            distance["max_distance"]
        height_m = distance["current_distance"] / 100.0 if rangefinder_valid else relative_m
        return Telemetry(
            time_s=now_s,
            armed=armed,
            mode=mode,
            landed_state=_LANDED.get(int(m.get("EXTENDED_SYS_STATE", {}).get("landed_state", 0)),
                                     LandedState.UNDEFINED),
            position_ok=int(gps.get("fix_type", 0)) >= 3,
            position_ned_m=PositionNed(local.get("x", 0.0) - hx, local.get("y", 0.0) - hy, local.get("z", 0.0) - hz),
            velocity_ned_m_s=VelocityNed(glob.get("vx", 0) / 100.0, glob.get("vy", 0) / 100.0,
                                         glob.get("vz", 0) / 100.0),
            global_position=GlobalPosition(glob.get("lat", 0) / 1e7, glob.get("lon", 0) / 1e7,
                                           glob.get("alt", 0) / 1000.0, relative_m),
            home=GlobalPosition(home["latitude"] / 1e7, home["longitude"] / 1e7, home["altitude"] / 1000.0, 0.0)
            if home else GlobalPosition(0.0, 0.0, 0.0, 0.0),
            attitude=Attitude(math.degrees(attitude.get("roll", 0.0)), math.degrees(attitude.get("pitch", 0.0)),
                              math.degrees(attitude.get("yaw", 0.0)) % 360.0),
            height_above_ground_m=height_m,
            rangefinder_valid=rangefinder_valid,
            battery=Battery(status.get("voltage_battery", 0) / 1000.0, float(status.get("battery_remaining", -1))),
        )

    async def send_landing_target(self, target: LandingTarget) -> None:
        self._check_link("send_landing_target")
        await self._send("LANDING_TARGET", targeted=False, fields={
            "time_usec": int(target.timestamp_s * 1e6), "target_num": target.target_num,
            "frame": MAV_FRAME_BODY_FRD, "angle_x": target.angle_x_rad, "angle_y": target.angle_y_rad,
            "distance": target.distance_m or 0.0, "size_x": target.size_x_rad, "size_y": target.size_y_rad})

    # ---------------------------------------------------------------- truth (SITL and the simulator's face)

    def sim_state(self) -> dict[str, Any] | None:
        """The latest SIM_STATE (ground truth from SITL or the simulator), if asked for and received."""
        return self._messages.get("SIM_STATE")

    def sim_state_time_s(self) -> float:
        """The vehicle time (s) of the latest SIM_STATE: the clock's reading when it was read."""
        return self._sim_state_time_s

    async def wait_for_truth(self, timeout_s: float = 10.0) -> dict[str, Any]:
        deadline = time.monotonic() + timeout_s
        while self.sim_state() is None:
            if time.monotonic() > deadline:
                raise WaitTimeout(operation="ground truth (SIM_STATE)", timeout_s=timeout_s)
            await asyncio.sleep(0.05)
        return self.sim_state()
