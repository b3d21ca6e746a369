"""The embedded simulator's MAVLink face, driven by a plain pymavlink client on localhost."""

import asyncio
import contextlib
import errno
import socket
import threading
import time

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from preland_app.clock_scaled import ScaledWallClock
from preland_app.mavlink.dialect import decode_frame, encode_frame
from preland_app.sim import mavlink_face
from preland_app.sim.mavlink_face import MavlinkFace, MavlinkFaceError, parse_listen
from preland_app.sim.params import ARDUPILOT_PARAM_NAMES
from preland_app.sim.simulator import Simulator
from preland_app.sim.spec import EnvironmentSpec, WindSpec

from .ports import free_udp_port as free_port
from .waiting import until

# 8x: what these tests reached when they asked 10x, before the face kept to its clock; a true 10x
# beside the real-time field flight left its camera behind its frame rate.
SPEEDUP = 8.0


def pace(client, time_ms: int) -> None:
    """A companion's PRELAND_PACE grant, sent raw (pymavlink's compiled dialect does not know it)."""
    client.write(encode_frame("PRELAND_PACE", {"target_system": 1, "target_component": 1, "time_boot_ms": time_ms},
                              system_id=client.mav.srcSystem, component_id=190))


def held_at_ms(client, *, timeout_s: float = 10.0) -> tuple[int, object]:
    """The face's PRELAND_PACE answer (the time it holds at, ms) and the SIM_STATE sent just before it."""
    deadline = time.monotonic() + timeout_s
    sim_state = None
    while time.monotonic() < deadline:
        message = client.recv_match(blocking=True, timeout=0.2)
        if message is None:
            continue
        if message.get_type() == "SIM_STATE":
            sim_state = message
        elif message.get_type().startswith("UNKNOWN_"):
            fields = decode_frame("PRELAND_PACE", bytes(message.get_msgbuf()))
            if fields is not None:
                return fields["time_boot_ms"], sim_state
    raise AssertionError(f"no PRELAND_PACE answer within {timeout_s} s")


@contextlib.contextmanager
def serving(channels: int, *, speedup: float = SPEEDUP, params: dict[str, float] | None = None,
            paced: bool = False):
    """A face on `channels` free localhost ports, run in a thread with its own event loop; yields one
    pymavlink client per port, the simulator and the face."""
    ports = [free_port() for _ in range(channels)]
    simulator = Simulator(seed=3, environment=EnvironmentSpec(wind=WindSpec(speed_m_s=0.0, turbulence_w20_m_s=0.0)),
                          params=params)
    loop = asyncio.new_event_loop()
    face_box = {}
    started = threading.Event()

    def run():
        asyncio.set_event_loop(loop)
        face = MavlinkFace(simulator=simulator, clock=ScaledWallClock(speedup=speedup),
                           listen=[f"udp:127.0.0.1:{port}" for port in ports], paced=paced)
        face_box["face"] = face
        face_box["task"] = loop.create_task(face.run())
        started.set()
        try:
            loop.run_until_complete(face_box["task"])
        except asyncio.CancelledError:
            pass

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    assert started.wait(timeout=10)
    clients = [mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255 - i,
                                          dialect="ardupilotmega") for i, port in enumerate(ports)]
    try:
        yield clients, simulator, face_box
    finally:
        loop.call_soon_threadsafe(face_box["task"].cancel)
        thread.join(timeout=5)
        for client in clients:
            client.close()


@pytest.fixture()
def served():
    """A face on one free localhost port."""
    with serving(1) as (clients, simulator, face_box):
        yield clients[0], simulator, face_box


def wait_for(client, message_type, *, timeout_s=10.0, condition=lambda m: True):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        client.mav.heartbeat_send(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        message = client.recv_match(type=message_type, blocking=True, timeout=0.2)
        if message is not None and condition(message):
            return message
    raise AssertionError(f"no {message_type} within {timeout_s} s")


def position_estimate_ready(simulator) -> bool:
    """Whether the served autopilot will take GUIDED or arm: it checks against the estimate of its last control
    cycle, which takes the simulator's newest estimate (`simulator.nav`) one physics step later."""
    nav = simulator.autopilot.nav
    return nav is not None and nav.position_ok


def command(client, command_id, *params, texts=None):
    """Send COMMAND_LONG and wait for its ACK; STATUSTEXTs that arrive meanwhile go to `texts`."""
    params = list(params) + [0.0] * (7 - len(params))
    client.mav.command_long_send(1, 1, command_id, 0, *params)
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        message = client.recv_match(type=["COMMAND_ACK", "STATUSTEXT"], blocking=True, timeout=0.2)
        if message is None:
            continue
        if message.get_type() == "STATUSTEXT":
            if texts is not None:
                texts.append(message.text)
        elif message.command == command_id:
            return message
    raise AssertionError(f"no COMMAND_ACK for {command_id}")


def test_heartbeat_says_ardupilot_copter(served):
    client, _, _ = served
    heartbeat = wait_for(client, "HEARTBEAT")
    assert heartbeat.autopilot == mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert heartbeat.type == mavlink2.MAV_TYPE_QUADROTOR
    assert heartbeat.custom_mode == 0 and not heartbeat.base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED


def test_nothing_streams_until_asked(served):
    client, _, _ = served
    wait_for(client, "HEARTBEAT")
    assert client.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=0.5) is None
    ack = command(client, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 1e5)
    assert ack.result == mavlink2.MAV_RESULT_ACCEPTED
    position = wait_for(client, "GLOBAL_POSITION_INT")
    assert abs(position.lat / 1e7 - (-35.363261)) < 1e-4


def test_param_protocol(served):
    client, simulator, _ = served
    wait_for(client, "HEARTBEAT")
    client.mav.param_request_read_send(1, 1, b"LAND_SPEED", -1)
    value = wait_for(client, "PARAM_VALUE", condition=lambda m: m.param_id == "LAND_SPEED")
    # LAND_SPEED is an AP_Int16 on ArduCopter; only ArduPilot's parameters are counted.
    assert value.param_value == 50.0 and value.param_type == mavlink2.MAV_PARAM_TYPE_INT16
    assert value.param_count == len(ARDUPILOT_PARAM_NAMES)
    client.mav.param_set_send(1, 1, b"LAND_SPEED", 35.0, mavlink2.MAV_PARAM_TYPE_INT16)
    value = wait_for(client, "PARAM_VALUE", condition=lambda m: m.param_id == "LAND_SPEED")
    assert value.param_value == 35.0 and simulator.params.get("LAND_SPEED") == 35.0
    client.mav.param_set_send(1, 1, b"LAND_SPEED", 9999.0, mavlink2.MAV_PARAM_TYPE_INT16)
    value = wait_for(client, "PARAM_VALUE", condition=lambda m: m.param_id == "LAND_SPEED")
    assert value.param_value == 35.0  # out of range: refused, the value in force comes back


def test_arm_take_off_and_land_over_mavlink(served):
    client, simulator, face_box = served
    wait_for(client, "HEARTBEAT")
    texts = []
    denied = command(client, mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1, texts=texts)
    assert denied.result == mavlink2.MAV_RESULT_DENIED  # no position estimate yet
    assert any("Need Position Estimate" in text for text in texts)
    until(lambda: position_estimate_ready(simulator), timeout_s=60, what="the autopilot's position estimate")
    assert command(client, mavlink2.MAV_CMD_DO_SET_MODE, 1, 4).result == mavlink2.MAV_RESULT_ACCEPTED
    assert command(client, mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink2.MAV_RESULT_ACCEPTED
    assert command(client, mavlink2.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5).result == mavlink2.MAV_RESULT_ACCEPTED
    command(client, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 1e5)
    wait_for(client, "GLOBAL_POSITION_INT", condition=lambda m: m.relative_alt > 4800, timeout_s=15)
    client.mav.landing_target_send(0, 0, mavlink2.MAV_FRAME_BODY_FRD, 0.01, -0.02, 5.0, 0.0, 0.0)
    assert command(client, mavlink2.MAV_CMD_DO_SET_MODE, 1, 9).result == mavlink2.MAV_RESULT_ACCEPTED
    heartbeat = wait_for(client, "HEARTBEAT", timeout_s=20,
                         condition=lambda m: not m.base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED)
    assert heartbeat.custom_mode == 9
    assert simulator.touchdowns() and simulator.true_pose().on_ground
    assert face_box["face"].landing_targets == 1
    command(client, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink2.MAVLINK_MSG_ID_SIMSTATE, 1e5)
    truth = wait_for(client, "SIMSTATE")
    assert abs(truth.lat / 1e7 - (-35.363261)) < 1e-4


def test_unknown_commands_and_bad_addresses(served):
    client, _, _ = served
    wait_for(client, "HEARTBEAT")
    assert command(client, mavlink2.MAV_CMD_DO_FLIGHTTERMINATION, 1).result == mavlink2.MAV_RESULT_UNSUPPORTED
    with pytest.raises(MavlinkFaceError, match="udp:HOST:PORT"):
        parse_listen("tcp:localhost")


def test_a_ground_station_watches_on_its_own_channel_while_the_companion_flies():
    with serving(2) as ((companion, gcs), simulator, _):
        wait_for(companion, "HEARTBEAT")
        wait_for(gcs, "HEARTBEAT")
        # A refusal the companion provokes (no position estimate yet) is told on every channel.
        assert command(companion, mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink2.MAV_RESULT_DENIED
        wait_for(gcs, "STATUSTEXT", condition=lambda m: "Need Position Estimate" in m.text)
        # Stream rates are per channel, as ArduPilot's SRn_ parameters are per serial port.
        command(companion, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 1e5)
        wait_for(companion, "GLOBAL_POSITION_INT")
        command(gcs, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink2.MAVLINK_MSG_ID_ATTITUDE, 1e5)
        wait_for(gcs, "ATTITUDE")
        assert gcs.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=0.5) is None
        # A parameter the ground station sets comes back on the companion's channel too.
        gcs.mav.param_set_send(1, 1, b"LAND_SPEED", 35.0, mavlink2.MAV_PARAM_TYPE_REAL32)
        wait_for(companion, "PARAM_VALUE", condition=lambda m: m.param_id == "LAND_SPEED" and m.param_value == 35.0)
        # The companion flies; the ground station sees it armed in GUIDED, then climbing.
        until(lambda: position_estimate_ready(simulator), timeout_s=60, what="the autopilot's position estimate")
        assert command(companion, mavlink2.MAV_CMD_DO_SET_MODE, 1, 4).result == mavlink2.MAV_RESULT_ACCEPTED
        assert command(companion, mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink2.MAV_RESULT_ACCEPTED
        assert command(companion, mavlink2.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5).result == \
            mavlink2.MAV_RESULT_ACCEPTED
        heartbeat = wait_for(gcs, "HEARTBEAT", condition=lambda m: m.base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED)
        assert heartbeat.custom_mode == 4
        command(gcs, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 1e5)
        climbed = wait_for(gcs, "GLOBAL_POSITION_INT", condition=lambda m: m.relative_alt > 3000, timeout_s=15)
        assert abs(climbed.relative_alt / 1000 + simulator.nav.down_m - simulator.autopilot.home_down_m) < 1.0


def test_the_same_address_twice_is_refused():
    port = free_port()
    simulator = Simulator(seed=3)
    with pytest.raises(MavlinkFaceError, match="the same address twice"):
        MavlinkFace(simulator=simulator, clock=ScaledWallClock(speedup=1.0),
                    listen=[f"udp:127.0.0.1:{port}", f"udp:127.0.0.1:{port}"])


class OvershootingClock:
    """A clock whose every sleep overshoots by half again, as short asyncio sleeps do; vehicle s."""

    def __init__(self) -> None:
        self.time_s = 0.0

    def now_s(self) -> float:
        return self.time_s

    async def sleep(self, duration_s: float) -> None:
        self.time_s += 1.5 * max(0.0, duration_s)
        await asyncio.sleep(0)


def test_the_face_keeps_to_its_clock_when_sleeps_overshoot():
    clock = OvershootingClock()
    face = MavlinkFace(simulator=Simulator(seed=1), clock=clock, listen=f"udp:127.0.0.1:{free_port()}")

    async def serve_until(vehicle_s: float) -> None:
        task = asyncio.ensure_future(face.run())
        deadline = time.monotonic() + 20.0
        while face.simulator.time_s < vehicle_s and time.monotonic() < deadline:
            await asyncio.sleep(0.001)
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task

    asyncio.run(serve_until(5.0))
    # Sleeping a step after every step ran 1.5x slower than the clock; steps due at fixed times keep up.
    assert face.simulator.time_s >= 5.0
    assert abs(face.simulator.time_s - clock.now_s()) <= 2 * face.simulator.dt_s


def test_a_paced_face_holds_at_time_zero_steps_to_each_grant_and_answers_with_the_truth_of_that_time():
    with serving(1, paced=True) as ((client,), simulator, face_box):
        wait_for(client, "HEARTBEAT")  # sent while it holds, a wall half second apart
        assert simulator.time_s == 0.0
        pace(client, 250)
        held_ms, sim_state = held_at_ms(client)
        assert held_ms == 250 and simulator.time_s == pytest.approx(0.25)
        assert sim_state is not None and sim_state.lat == pytest.approx(simulator.origin.latitude_deg)
        pace(client, 1255)  # between two physics steps: the first step at or after it
        assert held_at_ms(client)[0] == 1260
        until(lambda: face_box["face"].pace_holds == 2, timeout_s=10, what="the second hold")
        assert simulator.time_s == pytest.approx(1.26)  # and no further, however long we look
        pace(client, 0)  # let go: a paced face holds where it is until the next companion
        wait_for(client, "HEARTBEAT")
        assert simulator.time_s == pytest.approx(1.26)


def test_a_free_face_runs_on_its_clock_until_paced_and_again_when_let_go():
    with serving(1) as ((client,), simulator, face_box):
        wait_for(client, "HEARTBEAT", condition=lambda m: simulator.time_s > 0.5)
        pace(client, 1)  # behind the face: it holds at once, where it is
        held_ms, _ = held_at_ms(client)
        assert held_ms / 1000 == pytest.approx(simulator.time_s, abs=1e-3) and held_ms > 500
        pace(client, 0)
        until(lambda: simulator.time_s > held_ms / 1000 + 0.5, timeout_s=30, what="the face to run free again")


def test_a_face_whose_companion_has_gone_runs_free_after_the_wall_bound(monkeypatch):
    monkeypatch.setattr(mavlink_face, "PACE_RELEASE_WALL_S", 0.3)
    with serving(1) as ((client,), simulator, face_box):
        wait_for(client, "HEARTBEAT")
        pace(client, 1)
        held_ms, _ = held_at_ms(client)
        texts = []
        deadline = time.monotonic() + 30
        while not any("pacing released" in t for t in texts) and time.monotonic() < deadline:
            message = client.recv_match(type="STATUSTEXT", blocking=True, timeout=0.2)
            if message is not None:
                texts.append(message.text)  # and nothing sent meanwhile: the companion is silent
        assert any("pacing released" in t for t in texts)
        until(lambda: simulator.time_s > held_ms / 1000 + 0.5, timeout_s=30, what="the face to run free")


def test_what_a_step_writes_leaves_in_datagrams_of_whole_frames_below_the_mtu():
    """Several messages of one step share a datagram (so a reader is woken once a step, not once a message);
    a burst larger than MAX_DATAGRAM_BYTES (the whole parameter list) is split between whole frames, and
    every frame arrives."""
    with serving(1) as (clients, _, _):
        client = clients[0]
        client.mav.request_data_stream_send(1, 1, mavlink2.MAV_DATA_STREAM_ALL, 50, 1)
        client.mav.param_request_list_send(1, 1)
        parser = mavlink2.MAVLink(None)
        parser.robust_parsing = False
        frames_per_datagram, sizes, names = [], [], set()
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline and (len(names) < len(ARDUPILOT_PARAM_NAMES) or len(sizes) < 200):
            client.mav.heartbeat_send(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            client.port.settimeout(0.2)
            try:
                datagram = client.port.recv(65535)
            except socket.timeout:
                continue
            messages = parser.parse_buffer(datagram) or []
            assert parser.buf_len() == 0, "a datagram ends with a whole frame"
            frames_per_datagram.append(len(messages))
            sizes.append(len(datagram))
            names.update(m.param_id for m in messages if m.get_type() == "PARAM_VALUE")
    assert names == set(ARDUPILOT_PARAM_NAMES), "the whole list arrived"
    assert max(sizes) <= mavlink_face.MAX_DATAGRAM_BYTES
    assert max(sizes) > mavlink_face.MAX_DATAGRAM_BYTES - 280, "the list burst filled datagrams to the bound"
    assert min(frames_per_datagram) >= 1 and max(frames_per_datagram) > 3


class _AttitudeReader:
    """A free face (at 1x) with one pymavlink client that asked for ATTITUDE at 10 Hz, stepped by hand."""

    def __init__(self) -> None:
        self.port = free_port()
        self.simulator = Simulator(seed=3, environment=EnvironmentSpec(wind=WindSpec(speed_m_s=0.0,
                                                                                     turbulence_w20_m_s=0.0)))
        self.face = MavlinkFace(simulator=self.simulator, clock=ScaledWallClock(speedup=1.0),
                                listen=f"udp:127.0.0.1:{self.port}")
        self.client = mavutil.mavlink_connection(f"udpout:127.0.0.1:{self.port}", source_system=255,
                                                 dialect="ardupilotmega")
        self.attitudes_ms: list[int] = []
        self.client.mav.command_long_send(1, 1, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                          mavlink2.MAVLINK_MSG_ID_ATTITUDE, 1e5, 0, 0, 0, 0, 0)
        self.step_until_an_attitude_after(-1, "the face to stream ATTITUDE to the client that asked")

    def step_until_an_attitude_after(self, time_ms: int, what: str) -> None:
        deadline = time.monotonic() + 30.0
        while not self.attitudes_ms or self.attitudes_ms[-1] <= time_ms:
            assert time.monotonic() < deadline, f"waited 30 s for {what}"
            self.face._step_and_serve()
            while (message := self.client.recv_match(type="ATTITUDE", blocking=False)) is not None:
                self.attitudes_ms.append(message.time_boot_ms)

    def a_second_unheard(self) -> tuple[int, int]:
        """Step one vehicle second, then speak and read on: (from, to) ms of the second stepped."""
        from_ms = self.face.time_boot_ms()
        for _ in range(round(1.0 / self.simulator.dt_s)):
            self.face._step_and_serve()
        to_ms = self.face.time_boot_ms()
        self.client.mav.heartbeat_send(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        self.step_until_an_attitude_after(to_ms, "the face to stream again to the client that spoke")
        return from_ms, to_ms

    def close(self) -> None:
        self.face._close()
        self.client.close()


def test_a_listening_port_sends_nothing_to_a_peer_gone_silent_until_it_speaks_again():
    """A companion's port, once closed, may be handed to another program, which would read this vehicle as its
    own: a peer that said nothing for PEER_SILENT_WALL_S gets no more streams, and gets them again when it
    speaks."""
    reader = _AttitudeReader()
    try:
        # The peer last spoke longer ago than the bound: a second of steps sends it nothing.
        reader.face.channels[0].heard_wall_s -= mavlink_face.PEER_SILENT_WALL_S + 1.0
        silent_from_ms, silent_to_ms = reader.a_second_unheard()
    finally:
        reader.close()
    assert silent_to_ms - silent_from_ms >= 990
    # Datagrams from one sender arrive in order: any sent in the silent second would be read before the later ones.
    assert [t for t in reader.attitudes_ms if silent_from_ms < t <= silent_to_ms] == []
    assert reader.attitudes_ms[-1] > silent_to_ms


def test_a_peer_that_lets_go_of_its_pacing_gets_nothing_more_until_it_speaks_again():
    """A companion's PRELAND_PACE 0 says it is leaving (it closes its port next): its port gets nothing more at
    once, not after PEER_SILENT_WALL_S, in which another program given the port would read this vehicle and
    fly it with its own grants and commands."""
    reader = _AttitudeReader()
    try:
        pace(reader.client, 0)
        gone_from_ms, gone_to_ms = reader.a_second_unheard()
    finally:
        reader.close()
    first_after = [t for t in reader.attitudes_ms if t > gone_from_ms][0]
    assert gone_to_ms - gone_from_ms >= 990
    # The release is read at the next step: at most one ATTITUDE (10 Hz) is sent before it.
    assert [t for t in reader.attitudes_ms if gone_from_ms + 100 < t <= gone_to_ms] == [], first_after
    assert reader.attitudes_ms[-1] > gone_to_ms


def test_no_socket_can_share_a_served_port():
    """pymavlink binds a listening port with SO_REUSEADDR, which lets any later socket with it share the port
    (one bound to port 0 may even be given it): the face clears it once bound."""
    reader = _AttitudeReader()
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other:
            other.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            with pytest.raises(OSError) as refused:
                other.bind(("127.0.0.1", reader.port))
    finally:
        reader.close()
    assert refused.value.errno == errno.EADDRINUSE
