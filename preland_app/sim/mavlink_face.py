"""The embedded simulator as a MAVLink system that behaves like ArduCopter, for what preland and a
ground station use.

It speaks MAVLink 2 (the ardupilotmega dialect, through pymavlink) on one or
more UDP ports, bound to localhost unless told otherwise. Each port is a
channel, as an ArduPilot serial port is: it answers whoever talks to it there
and keeps its own stream rates, so preland can fly on one port while a ground
station watches on another. Like ArduPilot it streams nothing but HEARTBEAT
until asked (MAV_CMD_SET_MESSAGE_INTERVAL or REQUEST_DATA_STREAM) on that
channel; STATUSTEXT and changed parameters go to every channel. Unlike ArduPilot, a
listening port stops sending to a peer silent for PEER_SILENT_WALL_S, or one that
has let go of its pacing (PRELAND_PACE 0: it is leaving), until it speaks again:
its port, once closed, may be handed to another program, which would read this
vehicle and, answering, fly it. It handles COMMAND_LONG
(arm/disarm, take-off, land, RTL, set mode, message intervals, message
requests), SET_MODE, SET_POSITION_TARGET_LOCAL_NED (positions and velocities,
local and body frames), SET_POSITION_TARGET_GLOBAL_INT, LANDING_TARGET, the
PARAM protocol, and (mavlink_face_gcs.py) the mission protocol and MAVLink FTP;
it sends HEARTBEAT (ArduPilot autopilot, Copter custom modes), SYS_STATUS,
GPS_RAW_INT, GLOBAL_POSITION_INT, LOCAL_POSITION_NED, ATTITUDE, HOME_POSITION,
EXTENDED_SYS_STATE, DISTANCE_SENSOR, STATUSTEXT, COMMAND_ACK, PARAM_VALUE, and
SIMSTATE / SIM_STATE with the ground truth.

It is as strict as ArduCopter 4.6 where a client could tell the difference:
parameters carry ArduPilot's storage type (PARAM_VALUE's param_type INT8/16/32
or REAL32, the value cast to float), so a client reading an integer parameter
as a float fails as it would on ArduPilot; an integer parameter set keeps what
AP_Param::set_float keeps; parameters ArduPilot lacks are neither served nor
accepted; a read or set of an unknown name gets no answer; SYS_STATUS reports
sensors as ArduCopter does with no fence; and a UDP port another process
already holds is refused rather than silently shared, as is, once served, the
face's own port (pymavlink binds it with SO_REUSEADDR, which the face then
clears, so no later socket can share it).

What one step writes to a port leaves in one datagram (several if it passes
MAX_DATAGRAM_BYTES, split between frames), as a telemetry radio or
mavlink-router packs frames; ArduPilot SITL sends a datagram a frame. A reader
must take every frame of a datagram, as MAVSDK and pymavlink do.

Pacing: the face runs on its clock (wall time times a speed-up) until a preland
companion sends PRELAND_PACE. From then on the companion owns time: the face
steps, without waiting for its clock, until the simulated time reaches the
time granted, sends the SIM_STATE of that moment and a PRELAND_PACE saying
where it holds, and holds (serving messages, and a HEARTBEAT a wall second)
until a later grant comes. So a companion that renders and detects camera
frames in wall time sees each frame at its vehicle time however loaded the
machine is. A grant of 0, or PACE_RELEASE_WALL_S without a word from the
companion's port (it has gone), lets the face run free again; a face made
`paced` (`sim serve --paced`) holds instead, from time 0 until the first grant
and between companions, so the same seed flies the same trial.
"""

from __future__ import annotations

import asyncio
import errno
import math
import os
import socket
import time
from collections.abc import Sequence

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from ..clock import Clock
from ..mavlink.dialect import decode_frame, encode_frame, message_id
from ..mavlink.endpoint import EndpointError, parse_endpoint
from ..errors import CommandDenied, PrelandError
from ..geo import GeoPoint, LocalTangentPlane
from ..vehicle.types import FlightMode, LandedState, LandingTarget
from .mavlink_face_gcs import GroundStationServices
from .params import ARDUCOPTER_PARAMS, ARDUPILOT_PARAM_NAMES
from .simulator import Simulator

os.environ.setdefault("MAVLINK20", "1")

# Paced: the companion port has said nothing (MAVSDK alone sends a HEARTBEAT a second) for this long: it
# has gone, and the face runs free again.
PACE_RELEASE_WALL_S = 10.0
# A peer a listening port learned (it spoke first) that has said nothing for this long gets nothing more until
# it speaks again: its port, once closed, may be handed to another program, which would read this vehicle.
PEER_SILENT_WALL_S = 5.0
# Paced and holding: the face wakes when a datagram comes, or after this many wall seconds to look at the
# time (a HEARTBEAT each HOLD_HEARTBEAT_WALL_S, the release bound).
HOLD_WAIT_WALL_S = 0.1
HOLD_HEARTBEAT_WALL_S = 0.5
# Paced steps between two yields to the event loop (the face shares it with nothing in `sim serve`).
PACED_STEPS_PER_YIELD = 20
_PACE_TYPE = f"UNKNOWN_{message_id('PRELAND_PACE')}"  # pymavlink's compiled dialect does not know it
# Vehicle seconds the face may fall behind its clock and still make them up by stepping without sleeping.
MAX_BEHIND_S = 0.5
_STREAMS_DEFAULT_HZ = {mavlink2.MAVLINK_MSG_ID_HEARTBEAT: 1.0}
# REQUEST_DATA_STREAM groups, as ArduPilot maps them (SRx_POSITION, SRx_EXTRA1, SRx_EXTENDED_STATUS).
_DATA_STREAMS = {
    mavlink2.MAV_DATA_STREAM_POSITION: (mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
                                        mavlink2.MAVLINK_MSG_ID_LOCAL_POSITION_NED),
    mavlink2.MAV_DATA_STREAM_EXTRA1: (mavlink2.MAVLINK_MSG_ID_ATTITUDE, mavlink2.MAVLINK_MSG_ID_SIMSTATE),
    mavlink2.MAV_DATA_STREAM_EXTENDED_STATUS: (mavlink2.MAVLINK_MSG_ID_SYS_STATUS,
                                               mavlink2.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                                               mavlink2.MAVLINK_MSG_ID_GPS_RAW_INT),
}
_LANDED_STATE = {LandedState.ON_GROUND: 1, LandedState.IN_AIR: 2, LandedState.TAKING_OFF: 3,
                 LandedState.LANDING: 4, LandedState.UNDEFINED: 0}
_ACCEPTED = mavlink2.MAV_RESULT_ACCEPTED
_DENIED = mavlink2.MAV_RESULT_DENIED
_UNSUPPORTED = mavlink2.MAV_RESULT_UNSUPPORTED
_FAILED = mavlink2.MAV_RESULT_FAILED
# ArduPilot answers a read by name and a set with param_index -1, which the uint16 field carries as 65535.
_NO_PARAM_INDEX = 65535
# What ArduCopter reports (GCS::update_sensor_status_flags, GCS_Copter::update_vehicle_sensor_status_flags).
_SENSORS_ALWAYS = (mavlink2.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink2.MAV_SYS_STATUS_SENSOR_3D_ACCEL
                   | mavlink2.MAV_SYS_STATUS_SENSOR_3D_MAG | mavlink2.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
                   | mavlink2.MAV_SYS_STATUS_SENSOR_BATTERY | mavlink2.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
                   | mavlink2.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
                   | mavlink2.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
                   | mavlink2.MAV_SYS_STATUS_SENSOR_YAW_POSITION | mavlink2.MAV_SYS_STATUS_SENSOR_PROPULSION)
_SENSORS_NAVIGATION = (mavlink2.MAV_SYS_STATUS_AHRS | mavlink2.MAV_SYS_STATUS_SENSOR_GPS)
_SENSORS_POSITION_CONTROL = (mavlink2.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
                             | mavlink2.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL)
# ArduCopter 4.6.3, official release: FW_MAJOR << 24 | FW_MINOR << 16 | FW_PATCH << 8 | FW_TYPE.
_FLIGHT_SW_VERSION = (4 << 24) | (6 << 16) | (3 << 8) | mavlink2.FIRMWARE_VERSION_TYPE_OFFICIAL


class MavlinkFaceError(PrelandError):
    """The MAVLink face cannot start (for example: the address is in use)."""


def parse_listen(address: str) -> str:
    """A UDP address the face serves (any form `parse_endpoint` reads: `udp:HOST:PORT`,
    `mavlink+udp://HOST:PORT`; `udpclient:HOST:PORT` or `udpout:`, as SITL's --serial0 says it, sends
    first) as pymavlink's `udpin:HOST:PORT` or `udpout:HOST:PORT`."""
    try:
        endpoint = parse_endpoint(address)
        if endpoint.kind not in ("udp", "udpout") or not endpoint.host:
            raise EndpointError("only UDP with a host can be served")
        return endpoint.pymavlink_address()
    except EndpointError:
        raise MavlinkFaceError(f"--listen {address!r}: expected udp:HOST:PORT, e.g. udp:127.0.0.1:14550") from None


def _refuse_busy_port(listen: str, address: str) -> None:
    """pymavlink's udpin sets SO_REUSEADDR, so a second server on a port would share it without a word; a
    plain bind first (no SO_REUSEADDR) fails on a port anyone holds, which is then refused."""
    host, _, port = address.partition(":")[2].rpartition(":")
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        probe.bind((host, int(port)))
    except OSError as error:
        reason = "address in use" if error.errno == errno.EADDRINUSE else (error.strerror or str(error))
        raise MavlinkFaceError(f"--listen {listen!r}: {reason}") from None
    finally:
        probe.close()


# Datagrams of a step's frames (see the module): each datagram wakes its reader (MAVSDK's thread, then the
# companion's loop), and most steps that send anything send several messages. Below the Ethernet MTU, so a
# datagram crossing a network is never fragmented.
MAX_DATAGRAM_BYTES = 1400


class _Datagrams:
    """The channel's writer: frames queue until `flush` (the end of a step or of a hold's sending)."""

    def __init__(self, connection) -> None:
        self._connection = connection
        self._frames: list[bytes] = []
        self._size = 0

    def write(self, frame: bytes) -> None:
        if self._size + len(frame) > MAX_DATAGRAM_BYTES:
            self.flush()
        self._frames.append(frame)
        self._size += len(frame)

    def flush(self) -> None:
        if self._frames:
            datagram = b"".join(self._frames)
            self._frames.clear()
            self._size = 0
            self._connection.write(datagram)


class _Channel:
    """One MAVLink port, as an ArduPilot serial port: its own peer and its own stream rates."""

    def __init__(self, *, listen: str, system_id: int) -> None:
        self.listen = listen
        address = parse_listen(listen)
        if address.startswith("udpin:"):
            _refuse_busy_port(listen, address)
        try:
            self.connection = mavutil.mavlink_connection(address, source_system=system_id,
                                                         source_component=1, dialect="ardupilotmega")
        except OSError as error:
            raise MavlinkFaceError(f"--listen {listen!r}: {error.strerror or error}") from None
        if address.startswith("udpin:"):
            # Linux lets any later socket with SO_REUSEADDR share the port while this one has it set, even
            # one bound to port 0 (the system then may pick this port): that socket would take the datagrams
            # meant for this vehicle.
            self.connection.port.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 0)
        self.mav = self.connection.mav
        self.datagrams = _Datagrams(self.connection)
        self.mav.file = self.datagrams  # pymavlink's sender writes its frames here
        self.intervals_s: dict[int, float] = {k: 1.0 / v for k, v in _STREAMS_DEFAULT_HZ.items()}
        self.next_send_s: dict[int, float] = {}
        # Sending first (udpclient) needs no peer to have spoken; listening waits for one.
        self.sends_first = address.startswith("udpout")
        self.peer_seen = self.sends_first
        self.heard_wall_s = 0.0  # when its peer last spoke (monotonic wall s)

    def forget_silent_peer(self, now_wall_s: float) -> None:
        if self.peer_seen and not self.sends_first and now_wall_s - self.heard_wall_s > PEER_SILENT_WALL_S:
            self.peer_seen = False


class MavlinkFace(GroundStationServices):
    """Serves one `Simulator` over MAVLink on a clock (wall time times a speed-up in practice).

    `listen`: one address or several (one channel each), `udp:HOST:PORT` or `udpclient:HOST:PORT`.
    `paced`: hold at time 0 until a companion paces it, and hold again when one lets go (see the module).
    """

    def __init__(self, *, simulator: Simulator, clock: Clock, listen: str | Sequence[str] = "udp:127.0.0.1:14550",
                 system_id: int = 1, paced: bool = False) -> None:
        self.simulator = simulator
        self.clock = clock
        addresses = (listen,) if isinstance(listen, str) else tuple(listen)
        if not addresses:
            raise MavlinkFaceError("--listen: at least one address is needed")
        if len(set(addresses)) != len(addresses):
            raise MavlinkFaceError(f"--listen: the same address twice in {', '.join(addresses)}")
        self.channels: list[_Channel] = []
        try:
            for address in addresses:
                self.channels.append(_Channel(listen=address, system_id=system_id))
        except MavlinkFaceError:
            self._close()
            raise
        self._channel = self.channels[0]  # the channel being served: replies go back on it
        self.plane = LocalTangentPlane(simulator.origin)
        self.heartbeats_enabled = True  # a test can silence them to simulate a lost link
        self._messages_sent = 0
        self.landing_targets = 0
        self._param_names = ARDUPILOT_PARAM_NAMES
        self._status_sent = 0
        # Pacing (PRELAND_PACE): the time granted (s; None: free), the channel that grants it, whether the
        # face has said it holds there.
        self.paced = paced
        self.pace_until_s: float | None = simulator.time_s if paced else None
        self._pace_channel: _Channel | None = None
        self._pace_answered = True
        self._held_heartbeat_wall_s = 0.0
        self.pace_holds = 0  # how many times it held for a companion

    # ---------------------------------------------------------------- running

    @property
    def mav(self):
        """The pymavlink sender of the channel being served."""
        return self._channel.mav

    @property
    def intervals_s(self) -> dict[int, float]:
        """Stream intervals (s) by message id, of the channel being served."""
        return self._channel.intervals_s

    async def run(self) -> None:
        """Step the simulator and serve MAVLink until cancelled."""
        sim = self.simulator
        dt_s = sim.dt_s
        # Steps are due at fixed times of the clock, so the time lost to sleeping (an asyncio sleep of a
        # quarter millisecond takes more than that) is made up by the next steps: sleeping dt after every
        # step ran the face at 2.25x when asked for 3x, and at 8x whatever it was asked above that.
        due_s = self.clock.now_s()
        paced_steps = 0
        try:
            while True:
                if self.pace_until_s is not None:
                    if sim.time_s < self.pace_until_s - 1e-9:
                        paced_steps += 1
                        if paced_steps % PACED_STEPS_PER_YIELD == 0:
                            await asyncio.sleep(0)
                        self._step_and_serve()
                    else:
                        await self._hold()
                        due_s = self.clock.now_s()  # free again later: from then, not catching up
                    continue
                due_s += dt_s
                wait_s = due_s - self.clock.now_s()
                if wait_s > 0:
                    await self.clock.sleep(wait_s)
                else:
                    if wait_s < -MAX_BEHIND_S:
                        due_s = self.clock.now_s()  # far behind (a loaded machine): slow down, don't race
                    await asyncio.sleep(0)
                self._step_and_serve()
        finally:
            self._close()

    def _step_and_serve(self) -> None:
        self.simulator.step()
        self._receive_everywhere()
        self._flush_status_text()
        for channel in self.channels:
            if channel.peer_seen:
                self._channel = channel
                self._send_streams()
        self._send_written()

    def _send_written(self) -> None:
        for channel in self.channels:
            channel.datagrams.flush()

    def _receive_everywhere(self) -> None:
        now_wall_s = time.monotonic()
        for channel in self.channels:
            self._channel = channel
            self._receive_all()
            channel.forget_silent_peer(now_wall_s)

    async def _hold(self) -> None:
        """At the granted time: say so once (SIM_STATE, then PRELAND_PACE), then serve until a later grant."""
        channel = self._pace_channel
        if not self._pace_answered and channel is not None:
            self._pace_answered = True
            self.pace_holds += 1
            self._channel = channel
            self._send_sim_state()
            channel.datagrams.write(encode_frame(
                "PRELAND_PACE", {"target_system": 0, "target_component": 0, "time_boot_ms": self.time_boot_ms()},
                system_id=channel.mav.srcSystem, component_id=channel.mav.srcComponent))
        self._receive_everywhere()
        self._flush_status_text()
        try:
            if self.pace_until_s is None or not self._pace_answered or \
                    self.simulator.time_s < self.pace_until_s - 1e-9:
                return  # a grant (or a release) came: step, or answer it
            now_wall_s = time.monotonic()
            if channel is not None and now_wall_s - channel.heard_wall_s > PACE_RELEASE_WALL_S:
                self._release_pace()
                self._say(f"pacing released: the companion said nothing for {PACE_RELEASE_WALL_S:g} s")
                return
            if now_wall_s - self._held_heartbeat_wall_s >= HOLD_HEARTBEAT_WALL_S:
                self._held_heartbeat_wall_s = now_wall_s
                for each in self.channels:
                    if each.peer_seen:
                        self._channel = each
                        self._send_heartbeat()
        finally:
            self._send_written()
        await self._readable(HOLD_WAIT_WALL_S)

    async def _readable(self, timeout_s: float) -> None:
        """Until a datagram waits on any channel, or `timeout_s` wall seconds (no busy polling: in a test the
        face shares its process, and the interpreter, with the companion it holds for)."""
        loop = asyncio.get_running_loop()
        ready = loop.create_future()

        def on_ready() -> None:
            if not ready.done():
                ready.set_result(None)

        descriptors = [channel.connection.port.fileno() for channel in self.channels]
        for descriptor in descriptors:
            loop.add_reader(descriptor, on_ready)
        try:
            await asyncio.wait_for(ready, timeout_s)
        except TimeoutError:
            pass
        finally:
            for descriptor in descriptors:
                loop.remove_reader(descriptor)

    def _release_pace(self) -> None:
        self.pace_until_s = self.simulator.time_s if self.paced else None
        self._pace_channel = None
        self._pace_answered = True

    def _close(self) -> None:
        for channel in self.channels:
            channel.datagrams.flush()  # pymavlink's UDP write drops a socket error itself
            channel.connection.close()

    def time_boot_ms(self) -> int:
        # Rounded: the steps' float sum falls either side of a whole millisecond, and a paced hold must say
        # the millisecond it was granted.
        return int(round(self.simulator.time_s * 1000)) & 0xFFFFFFFF

    def _receive_all(self) -> None:
        while True:
            try:
                message = self._channel.connection.recv_match(blocking=False)
            except (OSError, ValueError):
                return
            if message is None:
                return
            self._channel.peer_seen = True
            self._channel.heard_wall_s = time.monotonic()
            if message.get_type() == _PACE_TYPE:
                self._on_preland_pace(message)
                continue
            handler = getattr(self, f"_on_{message.get_type().lower()}", None)
            if handler is not None:
                handler(message)

    # ---------------------------------------------------------------- outgoing

    def _send_streams(self) -> None:
        now = self.simulator.time_s
        next_send_s = self._channel.next_send_s
        for message_id, interval_s in list(self.intervals_s.items()):
            due_s = next_send_s.get(message_id, 0.0)
            if interval_s <= 0 or now < due_s - 1e-9:
                continue
            # On a fixed grid, so a stream keeps its rate when the interval is not a whole number of physics
            # steps (50 Hz asked of `now + interval` on 100 Hz steps gave 44 Hz); from now after a long gap.
            next_send_s[message_id] = due_s + interval_s if now - due_s < interval_s else now + interval_s
            self.send_message(message_id)

    def send_message(self, message_id: int) -> bool:
        """Send one message now; False for a message this face does not provide."""
        sender = {
            mavlink2.MAVLINK_MSG_ID_HEARTBEAT: self._send_heartbeat,
            mavlink2.MAVLINK_MSG_ID_SYS_STATUS: self._send_sys_status,
            mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self._send_global_position,
            mavlink2.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self._send_local_position,
            mavlink2.MAVLINK_MSG_ID_ATTITUDE: self._send_attitude,
            mavlink2.MAVLINK_MSG_ID_HOME_POSITION: self._send_home,
            mavlink2.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: self._send_extended_state,
            mavlink2.MAVLINK_MSG_ID_SIMSTATE: self._send_simstate,
            mavlink2.MAVLINK_MSG_ID_SIM_STATE: self._send_sim_state,
            mavlink2.MAVLINK_MSG_ID_AUTOPILOT_VERSION: self._send_autopilot_version,
            mavlink2.MAVLINK_MSG_ID_DISTANCE_SENSOR: self._send_distance_sensor,
            mavlink2.MAVLINK_MSG_ID_GPS_RAW_INT: self._send_gps_raw,
        }.get(message_id)
        if sender is None:
            return False
        sender()
        self._messages_sent += 1
        return True

    def _send_heartbeat(self) -> None:
        if not self.heartbeats_enabled:
            return
        autopilot = self.simulator.autopilot
        base_mode = mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink2.MAV_MODE_FLAG_STABILIZE_ENABLED
        if autopilot.armed:
            base_mode |= mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
        status = mavlink2.MAV_STATE_ACTIVE if autopilot.armed else mavlink2.MAV_STATE_STANDBY
        self.mav.heartbeat_send(mavlink2.MAV_TYPE_QUADROTOR, mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA, base_mode,
                                autopilot.mode.value, status)

    def sensor_flags(self) -> tuple[int, int, int]:
        """SYS_STATUS' present, enabled and health bitmasks as ArduCopter builds them. With no fence the
        geofence bit is in health only (AC_Fence::sys_status_failed is false when not present): a ground
        station such as MAVProxy reads a clear health bit as a fence breach."""
        sim = self.simulator
        autopilot = sim.autopilot
        params = sim.params
        nav = sim.nav
        present = (_SENSORS_ALWAYS | _SENSORS_NAVIGATION | _SENSORS_POSITION_CONTROL
                   | mavlink2.MAV_SYS_STATUS_PREARM_CHECK)
        enabled = _SENSORS_ALWAYS | _SENSORS_NAVIGATION
        health = _SENSORS_ALWAYS | mavlink2.MAV_SYS_STATUS_GEOFENCE
        if nav.position_ok:
            health |= _SENSORS_NAVIGATION
        if params.value("ARMING_CHECK") != 0:
            enabled |= mavlink2.MAV_SYS_STATUS_PREARM_CHECK
            if autopilot.armed or nav.position_ok:  # armed, or the pre-arm checks pass
                health |= mavlink2.MAV_SYS_STATUS_PREARM_CHECK
        if autopilot.armed and not autopilot.land_complete:  # the position controller runs
            enabled |= _SENSORS_POSITION_CONTROL
            health |= _SENSORS_POSITION_CONTROL
        if sim.environment.navigation.rangefinder_present:
            # Out of range (on the ground, say) is still data to ArduPilot (AP_RangeFinder_Backend::has_data).
            present |= mavlink2.MAV_SYS_STATUS_SENSOR_LASER_POSITION
            enabled |= mavlink2.MAV_SYS_STATUS_SENSOR_LASER_POSITION
            health |= mavlink2.MAV_SYS_STATUS_SENSOR_LASER_POSITION
        if params.value("PLND_ENABLED") == 1:
            present |= mavlink2.MAV_SYS_STATUS_SENSOR_VISION_POSITION
            enabled |= mavlink2.MAV_SYS_STATUS_SENSOR_VISION_POSITION
            if autopilot.precland_enabled():  # a companion backend is healthy once it exists
                health |= mavlink2.MAV_SYS_STATUS_SENSOR_VISION_POSITION
        if sim.battery_remaining_fraction() <= 0:
            health &= ~mavlink2.MAV_SYS_STATUS_SENSOR_BATTERY
        return present, enabled, health

    def _send_sys_status(self) -> None:
        sim = self.simulator
        present, enabled, health = self.sensor_flags()
        self.mav.sys_status_send(present, enabled, health, 200, int(sim.battery_voltage_v() * 1000), -1,
                                 int(100 * sim.battery_remaining_fraction()), 0, 0, 0, 0, 0, 0)

    def _estimate(self):
        sim = self.simulator
        autopilot = sim.autopilot
        nav = sim.nav
        here = self.plane.to_geodetic(north_m=nav.north_m, east_m=nav.east_m, down_m=nav.down_m)
        relative_m = -(nav.down_m - autopilot.home_down_m)
        return nav, here, relative_m

    def _send_global_position(self) -> None:
        nav, here, relative_m = self._estimate()
        body = self.simulator.dynamics.state
        heading_cdeg = int(math.degrees(body.yaw_rad) % 360 * 100)
        self.mav.global_position_int_send(self.time_boot_ms(), int(here.latitude_deg * 1e7),
                                          int(here.longitude_deg * 1e7), int(here.altitude_amsl_m * 1000),
                                          int(relative_m * 1000), int(nav.velocity_north_m_s * 100),
                                          int(nav.velocity_east_m_s * 100), int(nav.velocity_down_m_s * 100),
                                          heading_cdeg)

    def _send_local_position(self) -> None:
        nav = self.simulator.nav
        self.mav.local_position_ned_send(self.time_boot_ms(), nav.north_m, nav.east_m, nav.down_m,
                                         nav.velocity_north_m_s, nav.velocity_east_m_s, nav.velocity_down_m_s)

    def _send_attitude(self) -> None:
        body = self.simulator.dynamics.state
        self.mav.attitude_send(self.time_boot_ms(), body.roll_rad, body.pitch_rad,
                               (body.yaw_rad + math.pi) % (2 * math.pi) - math.pi, 0.0, 0.0, 0.0)

    def home_location(self) -> GeoPoint:
        """Home; before the first arming, the take-off spot, where ArduPilot would put home at its first fix."""
        autopilot = self.simulator.autopilot
        if not autopilot.home_set:
            return self.simulator.origin
        return self.plane.to_geodetic(north_m=autopilot.home_north_m, east_m=autopilot.home_east_m,
                                      down_m=autopilot.home_down_m)

    def _send_home(self) -> None:
        autopilot = self.simulator.autopilot
        if not autopilot.home_set:
            return
        home = self.home_location()
        self.mav.home_position_send(int(home.latitude_deg * 1e7), int(home.longitude_deg * 1e7),
                                    int(home.altitude_amsl_m * 1000), autopilot.home_north_m, autopilot.home_east_m,
                                    autopilot.home_down_m, (1.0, 0.0, 0.0, 0.0), 0.0, 0.0, 0.0)

    def _send_extended_state(self) -> None:
        landed = self.simulator.autopilot.landed_state()
        self.mav.extended_sys_state_send(mavlink2.MAV_VTOL_STATE_MC, _LANDED_STATE[landed])

    def _truth(self):
        pose = self.simulator.true_pose()
        here = self.plane.to_geodetic(north_m=pose.north_m, east_m=pose.east_m, down_m=pose.down_m)
        return pose, here

    def _send_simstate(self) -> None:
        pose, here = self._truth()
        self.mav.simstate_send(pose.roll_rad, pose.pitch_rad, pose.yaw_rad, 0.0, 0.0, -9.81, 0.0, 0.0, 0.0,
                               int(here.latitude_deg * 1e7), int(here.longitude_deg * 1e7))

    def _send_sim_state(self) -> None:
        pose, here = self._truth()
        body = self.simulator.dynamics.state
        self.mav.sim_state_send(1.0, 0.0, 0.0, 0.0, pose.roll_rad, pose.pitch_rad, pose.yaw_rad, 0.0, 0.0, -9.81,
                                0.0, 0.0, 0.0, here.latitude_deg, here.longitude_deg, here.altitude_amsl_m, 0.0, 0.0,
                                body.velocity_north_m_s, body.velocity_east_m_s, body.velocity_down_m_s,
                                int(here.latitude_deg * 1e7), int(here.longitude_deg * 1e7))

    def _send_distance_sensor(self) -> None:
        nav = self.simulator.nav
        params = self.simulator.params
        minimum, maximum = int(params.value("RNGFND1_MIN_CM")), int(params.value("RNGFND1_MAX_CM"))
        current = int(nav.rangefinder_m * 100) if nav.rangefinder_m is not None else maximum + 1
        self.mav.distance_sensor_send(self.time_boot_ms(), minimum, maximum, current,
                                      mavlink2.MAV_DISTANCE_SENSOR_LASER, 0, mavlink2.MAV_SENSOR_ROTATION_PITCH_270, 0)

    def _send_gps_raw(self) -> None:
        nav, here, _ = self._estimate()
        fix = mavlink2.GPS_FIX_TYPE_3D_FIX if nav.position_ok else mavlink2.GPS_FIX_TYPE_NO_FIX
        self.mav.gps_raw_int_send(int(self.simulator.time_s * 1e6), fix, int(here.latitude_deg * 1e7),
                                  int(here.longitude_deg * 1e7), int(here.altitude_amsl_m * 1000), 80, 120, 0, 0,
                                  14 if nav.position_ok else 0)

    def _send_autopilot_version(self) -> None:
        # No MAV_PROTOCOL_CAPABILITY_FTP: FTP requests are answered, but only with NAKs.
        capabilities = (mavlink2.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mavlink2.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
                        | mavlink2.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
                        | mavlink2.MAV_PROTOCOL_CAPABILITY_MISSION_INT
                        | mavlink2.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                        | mavlink2.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
                        | mavlink2.MAV_PROTOCOL_CAPABILITY_COMMAND_INT)
        self.mav.autopilot_version_send(capabilities, _FLIGHT_SW_VERSION, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8,
                                        0, 0, 0)

    def _flush_status_text(self) -> None:
        messages = self.simulator.autopilot.messages
        for status in messages[self._status_sent:]:
            self._say(status.text, mavlink2.MAV_SEVERITY_INFO)
        self._status_sent = len(messages)

    def _say(self, text: str, severity: int = mavlink2.MAV_SEVERITY_WARNING) -> None:
        """STATUSTEXT on every channel with a peer (ArduPilot's send_text goes to all)."""
        for channel in self.channels:
            if channel.peer_seen:
                channel.mav.statustext_send(severity, text.encode("ascii", "replace")[:50])

    def _ack(self, message, result: int) -> None:
        """COMMAND_ACK to `message`'s sender, addressed to it as ArduPilot's is (target_system/component)."""
        self.mav.command_ack_send(message.command, result, 0, 0, message.get_srcSystem(), message.get_srcComponent())

    # ---------------------------------------------------------------- incoming

    def _on_command_long(self, message) -> None:
        command = message.command
        autopilot = self.simulator.autopilot
        try:
            if command == mavlink2.MAV_CMD_COMPONENT_ARM_DISARM:
                if message.param1 >= 0.5:
                    autopilot.arm()
                else:
                    autopilot.disarm(force=int(message.param2) == 21196, reason="commanded")
            elif command == mavlink2.MAV_CMD_NAV_TAKEOFF:
                autopilot.takeoff(altitude_rel_m=message.param7)
            elif command == mavlink2.MAV_CMD_NAV_LAND:
                autopilot.set_mode(FlightMode.LAND)
            elif command == mavlink2.MAV_CMD_NAV_RETURN_TO_LAUNCH:
                autopilot.set_mode(FlightMode.RTL)
            elif command == mavlink2.MAV_CMD_DO_SET_MODE:
                autopilot.set_mode(self._mode(int(message.param2)))
            elif command == mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL:
                message_id, interval_us = int(message.param1), message.param2
                if interval_us < 0:
                    self.intervals_s.pop(message_id, None)
                elif interval_us == 0:
                    self.intervals_s[message_id] = 0.1
                else:
                    self.intervals_s[message_id] = interval_us / 1e6
            elif command == mavlink2.MAV_CMD_REQUEST_MESSAGE:
                if not self.send_message(int(message.param1)):
                    self._ack(message, _UNSUPPORTED)
                    return
            elif command == mavlink2.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
                self.send_message(mavlink2.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
            else:
                self._ack(message, _UNSUPPORTED)
                return
        except CommandDenied as error:
            self._say(error.reason)
            self._ack(message, _DENIED)
            return
        except (ValueError, KeyError) as error:
            self._say(str(error))
            self._ack(message, _FAILED)
            return
        self._ack(message, _ACCEPTED)

    @staticmethod
    def _mode(custom_mode: int) -> FlightMode:
        try:
            return FlightMode(custom_mode)
        except ValueError:
            raise CommandDenied(operation="set_mode", reason=f"mode {custom_mode} not supported") from None

    def _on_set_mode(self, message) -> None:
        try:
            self.simulator.autopilot.set_mode(self._mode(int(message.custom_mode)))
        except CommandDenied as error:
            self._say(error.reason)

    def _on_request_data_stream(self, message) -> None:
        ids = _DATA_STREAMS.get(message.req_stream_id, ())
        if message.req_stream_id == mavlink2.MAV_DATA_STREAM_ALL:
            ids = tuple(i for group in _DATA_STREAMS.values() for i in group)
        for message_id in ids:
            if message.start_stop and message.req_message_rate > 0:
                self.intervals_s[message_id] = 1.0 / message.req_message_rate
            else:
                self.intervals_s.pop(message_id, None)

    def _on_set_position_target_local_ned(self, message) -> None:
        autopilot = self.simulator.autopilot
        mask = message.type_mask
        position_ignored = mask & 0b111 == 0b111
        velocity_ignored = mask & 0b111000 == 0b111000
        yaw = None if mask & (1 << 10) else message.yaw
        yaw_rate = 0.0 if mask & (1 << 11) else message.yaw_rate
        try:
            if not position_ignored:
                # LOCAL_NED targets are relative to the EKF origin, as on ArduPilot; goto takes them from home.
                autopilot.goto(north_m=message.x - autopilot.home_north_m, east_m=message.y - autopilot.home_east_m,
                               down_m=message.z - autopilot.home_down_m, yaw_rad=yaw)
            elif not velocity_ignored:
                vn, ve, vd = message.vx, message.vy, message.vz
                if message.coordinate_frame in (mavlink2.MAV_FRAME_BODY_NED, mavlink2.MAV_FRAME_BODY_OFFSET_NED,
                                                mavlink2.MAV_FRAME_BODY_FRD):
                    yaw_now = autopilot.yaw_rad
                    vn, ve = (vn * math.cos(yaw_now) - ve * math.sin(yaw_now),
                              vn * math.sin(yaw_now) + ve * math.cos(yaw_now))
                autopilot.set_velocity(north_m_s=vn, east_m_s=ve, down_m_s=vd, yaw_rad=yaw, yaw_rate_rad_s=yaw_rate)
        except CommandDenied as error:
            self._say(error.reason)

    def _on_set_position_target_global_int(self, message) -> None:
        autopilot = self.simulator.autopilot
        north, east, _ = self.plane.to_ned(GeoPoint(message.lat_int / 1e7, message.lon_int / 1e7,
                                                    self.simulator.origin.altitude_amsl_m))
        try:
            autopilot.goto(north_m=north - autopilot.home_north_m, east_m=east - autopilot.home_east_m,
                           down_m=-message.alt, yaw_rad=None)
        except CommandDenied as error:
            self._say(error.reason)

    def _on_preland_pace(self, message) -> None:
        fields = decode_frame("PRELAND_PACE", bytes(message.get_msgbuf()))
        if fields is None:
            return
        if fields["time_boot_ms"] == 0:
            if self._channel is self._pace_channel:
                self._release_pace()
            # The companion is leaving: its port gets nothing more until it speaks again.
            self._channel.peer_seen = self._channel.sends_first
            return
        self.pace_until_s = fields["time_boot_ms"] / 1000.0
        self._pace_channel = self._channel
        self._pace_answered = False

    def _on_landing_target(self, message) -> None:
        now_s = self.simulator.time_s
        stamp_s = message.time_usec / 1e6
        # ArduPilot times a measurement by its arrival; a plausible vehicle-time stamp is used as is.
        capture_s = stamp_s if now_s - 2.0 <= stamp_s <= now_s else now_s
        self.landing_targets += 1
        self.simulator.autopilot.receive_landing_target(LandingTarget(
            timestamp_s=capture_s, angle_x_rad=message.angle_x, angle_y_rad=message.angle_y,
            distance_m=message.distance if message.distance > 0 else None, target_num=message.target_num))

    def _param_value(self, name: str, *, index: int = _NO_PARAM_INDEX, every_channel: bool = False) -> None:
        """PARAM_VALUE with ArduPilot's storage type and the value cast to float ("cast" encoding, as
        ArduPilot sends it, not the bytes of the integer)."""
        kind = ARDUCOPTER_PARAMS[name].kind
        value = self.simulator.params.get(name)
        channels = [c for c in self.channels if c.peer_seen] if every_channel else [self._channel]
        for channel in channels:
            channel.mav.param_value_send(name.encode("ascii"), value, kind.mav_param_type, len(self._param_names),
                                         index)

    @staticmethod
    def _param_id(message) -> str:
        name = message.param_id if isinstance(message.param_id, str) else message.param_id.decode()
        return name.rstrip("\x00")

    def _on_param_request_list(self, message) -> None:
        for index, name in enumerate(self._param_names):
            self._param_value(name, index=index)

    def _on_param_request_read(self, message) -> None:
        """By index when one is given (ArduPilot then ignores the name), else by name; nothing comes back
        for an index out of range or a name ArduPilot does not have (GCS_Param.cpp's param_io_timer)."""
        if message.param_index != -1:
            if 0 <= message.param_index < len(self._param_names):
                self._param_value(self._param_names[message.param_index], index=message.param_index)
            return
        name = self._param_id(message)
        if name in self._param_names:
            self._param_value(name)

    def _on_param_set(self, message) -> None:
        """An unknown name or a non-finite value is ignored without a word, as GCS_Param.cpp's
        handle_param_set does; an integer parameter keeps what AP_Param::set_float keeps. Unlike ArduPilot,
        which stores anything, a value outside the documented range is refused (the simulator's models
        assume sane values): the value in force comes back."""
        name = self._param_id(message)
        if name not in self._param_names or not math.isfinite(message.param_value):
            return
        try:
            self.simulator.params.set(name, message.param_value)
        except ValueError as error:
            self._say(str(error))
        self._param_value(name, every_channel=True)  # the value now in force, on every channel, as ArduPilot


async def serve(*, simulator: Simulator, clock: Clock, listen: str | Sequence[str], paced: bool = False) -> None:
    """Serve until cancelled."""
    await MavlinkFace(simulator=simulator, clock=clock, listen=listen, paced=paced).run()

