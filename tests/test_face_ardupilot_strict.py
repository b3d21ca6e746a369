"""The MAVLink face is as strict as ArduCopter 4.6 where a client could tell: typed parameters (MAVSDK refuses a
float read of an integer), no parameters ArduPilot lacks, SYS_STATUS without a fence breach, FTP refused at
once, POSHOLD, the mission protocol's home item, a busy port refused, and `sim serve --param`."""

import asyncio
import socket
import time

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from typer.testing import CliRunner

from preland_app.cli import app
from preland_app.clock_scaled import ScaledWallClock
from preland_app.sim.mavlink_face import MavlinkFace, MavlinkFaceError
from preland_app.sim.mavlink_face_gcs import FTP_ERR_UNKNOWN_COMMAND, FTP_NAK, ftp_reply
from preland_app.sim.params import ARDUCOPTER_PARAMS, ARDUPILOT_PARAM_NAMES, ParamKind, ParameterTable
from preland_app.sim.simulator import Simulator

from .conftest import THESIS_MISSION
from .ports import free_udp_port as free_port
from .test_mavlink_face import command, position_estimate_ready, serving, wait_for
from .waiting import until

EMBEDDED_ONLY = ("PRL_LOST_HOLD", "PRL_RET_ALT", "PRL_FS_HOLD")


def port_of(face) -> int:
    return int(face.channels[0].listen.rsplit(":", 1)[1])


def replies(client, wanted, *, until, timeout_s=5.0):
    """Every message of the types in `wanted` up to and including the first one `until` accepts."""
    seen = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        message = client.recv_match(type=wanted, blocking=True, timeout=0.2)
        if message is None:
            continue
        seen.append(message)
        if until(message):
            return seen
    raise AssertionError(f"no closing message among {[m.get_type() for m in seen]}")


# ------------------------------------------------------------------------------------------- parameters


def test_every_parameter_has_an_ardupilot_type_and_a_range_its_type_holds():
    for name, info in ARDUCOPTER_PARAMS.items():
        low, high = info.kind.limits
        assert low <= info.minimum <= info.default <= info.maximum <= high, name
        assert info.kind.stored(info.default) == info.default, name
    assert not set(EMBEDDED_ONLY) & set(ARDUPILOT_PARAM_NAMES)
    assert ARDUCOPTER_PARAMS["RTL_ALT"].kind is ParamKind.INT32
    assert ARDUCOPTER_PARAMS["PLND_TYPE"].kind is ParamKind.INT8  # an AP_Enum, stored as AP_Int8
    assert ARDUCOPTER_PARAMS["WPNAV_SPEED"].kind is ParamKind.REAL32


def test_an_integer_parameter_keeps_what_ap_param_set_float_keeps():
    table = ParameterTable()
    for given, kept in ((35.7, 35.0), (35.995, 36.0), (30.5, 30.0)):
        table.set("LAND_SPEED", given)
        assert table.get("LAND_SPEED") == kept
    table.set("PLND_LAG", 0.05)
    assert table.get("PLND_LAG") == 0.05  # a float stays a float
    with pytest.raises(ValueError, match="outside 0..127"):
        table.set("DISARM_DELAY", 300)  # refused, not clamped to the 127 an AP_Int8 would hold
    assert ParamKind.INT8.stored(300) == 127 and ParamKind.INT16.stored(-2.995) == -3


def test_param_list_is_typed_and_counts_only_ardupilot_parameters():
    with serving(1) as ((client,), _, _):
        wait_for(client, "HEARTBEAT")
        client.mav.param_request_list_send(1, 1)
        values = {}
        deadline = time.monotonic() + 5
        while len(values) < len(ARDUPILOT_PARAM_NAMES) and time.monotonic() < deadline:
            message = client.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.2)
            if message is not None:
                values[message.param_id] = message
    assert set(values) == set(ARDUPILOT_PARAM_NAMES)
    assert sorted(m.param_index for m in values.values()) == list(range(len(ARDUPILOT_PARAM_NAMES)))
    assert {m.param_count for m in values.values()} == {len(ARDUPILOT_PARAM_NAMES)}
    for name, message in values.items():
        assert message.param_type == ARDUCOPTER_PARAMS[name].kind.mav_param_type, name
    assert values["LAND_SPEED"].param_type == mavlink2.MAV_PARAM_TYPE_INT16
    assert values["DISARM_DELAY"].param_type == mavlink2.MAV_PARAM_TYPE_INT8
    assert values["RTL_ALT"].param_type == mavlink2.MAV_PARAM_TYPE_INT32
    assert values["PLND_LAG"].param_type == mavlink2.MAV_PARAM_TYPE_REAL32
    # "Cast" encoding: the integer's value as a float, not its bytes.
    assert values["RTL_ALT"].param_value == 1500.0 and values["PLND_LAG"].param_value == pytest.approx(0.02)


def test_param_set_replies_with_the_typed_value_kept():
    with serving(1) as ((client,), simulator, _):
        wait_for(client, "HEARTBEAT")
        # A client may send an integer's value with any declared type: ArduPilot uses the parameter's own.
        client.mav.param_set_send(1, 1, b"LAND_SPEED", 35.7, mavlink2.MAV_PARAM_TYPE_REAL32)
        value = wait_for(client, "PARAM_VALUE", condition=lambda m: m.param_id == "LAND_SPEED")
        assert value.param_value == 35.0 and value.param_type == mavlink2.MAV_PARAM_TYPE_INT16
        assert value.param_index == 65535  # ArduPilot's -1: a set's reply names no index
        assert simulator.params.get("LAND_SPEED") == 35.0
        client.mav.param_set_send(1, 1, b"PLND_RET_MAX", 2.5, mavlink2.MAV_PARAM_TYPE_INT8)
        value = wait_for(client, "PARAM_VALUE", condition=lambda m: m.param_id == "PLND_RET_MAX")
        assert value.param_value == 2.0 and value.param_type == mavlink2.MAV_PARAM_TYPE_INT8


def test_parameters_ardupilot_lacks_are_neither_served_nor_accepted():
    with serving(1) as ((client,), simulator, _):
        wait_for(client, "HEARTBEAT")
        # ArduPilot sends nothing for an unknown name or index: the read that follows is the first answer.
        client.mav.param_request_read_send(1, 1, b"PRL_FS_HOLD", -1)
        client.mav.param_request_read_send(1, 1, b"", len(ARDUPILOT_PARAM_NAMES))
        client.mav.param_set_send(1, 1, b"PRL_FS_HOLD", 3.0, mavlink2.MAV_PARAM_TYPE_REAL32)
        client.mav.param_request_read_send(1, 1, b"LAND_SPEED", -1)
        seen = replies(client, ["PARAM_VALUE", "STATUSTEXT"],
                       until=lambda m: getattr(m, "param_id", "") == "LAND_SPEED")
        assert [m.get_type() for m in seen] == ["PARAM_VALUE"]
        assert simulator.params.get("PRL_FS_HOLD") == 7.0  # the set was ignored


def test_mavsdk_reads_an_integer_parameter_only_as_an_integer():
    from mavsdk.asyncio.mavsdk import Configuration, Mavsdk
    from mavsdk.asyncio.plugins.param import ParamAsync
    from mavsdk.component_type import ComponentType
    from mavsdk.plugins.param import ParamError, ParamResult

    async def check(port: int) -> None:
        sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.COMPANION_COMPUTER))
        try:
            await sdk.add_any_connection(f"udpout://127.0.0.1:{port}")
            system = await sdk.first_autopilot(timeout_s=10)
            assert system is not None
            param = ParamAsync(system)
            with pytest.raises(ParamError) as refused:
                await param.get_param_float("LAND_SPEED")
            assert refused.value.result == ParamResult.WRONG_TYPE
            assert await param.get_param_int("LAND_SPEED") == 50
            assert await param.get_param_int("RTL_ALT") == 1500
            assert await param.get_param_float("PLND_LAG") == pytest.approx(0.02)
            with pytest.raises(ParamError) as refused:
                await param.get_param_int("PLND_LAG")
            assert refused.value.result == ParamResult.WRONG_TYPE
            await param.set_param_int("LAND_SPEED", 35)
            assert await param.get_param_int("LAND_SPEED") == 35
        finally:
            sdk.destroy()

    with serving(1) as ((client,), simulator, face_box):
        client.close()  # MAVSDK is the only client
        asyncio.run(check(port_of(face_box["face"])))
        assert simulator.params.get("LAND_SPEED") == 35.0


# ------------------------------------------------------------------------------------------- ground station


def test_sys_status_shows_no_fence_and_no_breach_as_arducopter():
    with serving(1) as ((client,), _, _):
        wait_for(client, "HEARTBEAT")
        command(client, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink2.MAVLINK_MSG_ID_SYS_STATUS, 1e5)
        status = wait_for(client, "SYS_STATUS", condition=lambda m: m.onboard_control_sensors_health
                          & mavlink2.MAV_SYS_STATUS_AHRS)
    fence = mavlink2.MAV_SYS_STATUS_GEOFENCE
    # No fence: not present, not enabled, and healthy, which is what keeps MAVProxy from saying "fence breach".
    assert not status.onboard_control_sensors_present & fence
    assert not status.onboard_control_sensors_enabled & fence
    assert status.onboard_control_sensors_health & fence
    wanted = (mavlink2.MAV_SYS_STATUS_SENSOR_GPS | mavlink2.MAV_SYS_STATUS_SENSOR_3D_GYRO
              | mavlink2.MAV_SYS_STATUS_PREARM_CHECK | mavlink2.MAV_SYS_STATUS_SENSOR_LASER_POSITION)
    assert status.onboard_control_sensors_present & wanted == wanted
    assert status.onboard_control_sensors_health & wanted == wanted
    # Disarmed: the position controller is present but not running.
    assert not status.onboard_control_sensors_enabled & mavlink2.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL


def test_ftp_is_refused_at_once_with_a_nak():
    with serving(1) as ((client,), _, _):
        wait_for(client, "HEARTBEAT")
        path = b"@PARAM/param.pck"
        request = bytes([7, 0, 3, 4, len(path), 0, 0, 0, 0, 0, 0, 0]) + path  # seq 7, session 3, OpenFileRO
        client.mav.file_transfer_protocol_send(0, 1, 1, list(request.ljust(251, b"\0")))
        reply = wait_for(client, "FILE_TRANSFER_PROTOCOL", timeout_s=2.0)
    payload = bytes(reply.payload)
    assert reply.target_system == client.mav.srcSystem
    assert int.from_bytes(payload[0:2], "little") == 8 and payload[2] == 3  # seq + 1, same session
    assert payload[3] == FTP_NAK and payload[5] == 4 and payload[4] == 1  # NAK of OpenFileRO, one byte
    assert payload[12] == 10  # FileNotFound
    terminate = ftp_reply(bytes([9, 0, 3, 1]))
    assert terminate[3] == 128 and terminate[5] == 1  # TerminateSession is ACKed
    unknown = ftp_reply(bytes([1, 0, 0, 99]))
    assert unknown[3] == FTP_NAK and unknown[12] == FTP_ERR_UNKNOWN_COMMAND


def test_poshold_is_accepted_and_holds_position():
    with serving(1, speedup=25.0) as ((client,), simulator, _):
        wait_for(client, "HEARTBEAT")
        wait_for(client, "HEARTBEAT", condition=lambda m: position_estimate_ready(simulator))
        assert command(client, mavlink2.MAV_CMD_DO_SET_MODE, 1, 4).result == mavlink2.MAV_RESULT_ACCEPTED
        assert command(client, mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink2.MAV_RESULT_ACCEPTED
        assert command(client, mavlink2.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5).result == \
            mavlink2.MAV_RESULT_ACCEPTED
        command(client, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 1e5)
        wait_for(client, "GLOBAL_POSITION_INT", condition=lambda m: m.relative_alt > 4900)
        assert command(client, mavlink2.MAV_CMD_DO_SET_MODE, 1, 16).result == mavlink2.MAV_RESULT_ACCEPTED
        heartbeat = wait_for(client, "HEARTBEAT", condition=lambda m: m.custom_mode == 16)
        assert heartbeat.base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
        start = simulator.true_pose()
        start_s = simulator.time_s
        until(lambda: simulator.time_s >= start_s + 10.0, timeout_s=120, what="ten simulated seconds")
        end = simulator.true_pose()
    assert ((end.north_m - start.north_m) ** 2 + (end.east_m - start.east_m) ** 2) ** 0.5 < 0.5
    assert abs(end.down_m - start.down_m) < 0.5 and not end.on_ground


def test_mission_protocol_serves_home_as_item_zero():
    with serving(1) as ((client,), simulator, _):
        wait_for(client, "HEARTBEAT")
        client.mav.mission_request_list_send(1, 1, mavlink2.MAV_MISSION_TYPE_MISSION)
        count = wait_for(client, "MISSION_COUNT")
        assert count.count == 1 and count.mission_type == mavlink2.MAV_MISSION_TYPE_MISSION
        client.mav.mission_request_int_send(1, 1, 0, mavlink2.MAV_MISSION_TYPE_MISSION)
        home = wait_for(client, "MISSION_ITEM_INT")
        assert (home.seq, home.command, home.frame) == (0, mavlink2.MAV_CMD_NAV_WAYPOINT, mavlink2.MAV_FRAME_GLOBAL)
        assert abs(home.x / 1e7 - simulator.origin.latitude_deg) < 1e-6
        assert abs(home.y / 1e7 - simulator.origin.longitude_deg) < 1e-6
        assert home.z == pytest.approx(simulator.origin.altitude_amsl_m, abs=0.01)
        # The old MISSION_REQUEST gets a float MISSION_ITEM, with ArduPilot's warning.
        client.mav.mission_request_send(1, 1, 0, mavlink2.MAV_MISSION_TYPE_MISSION)
        seen = replies(client, ["MISSION_ITEM", "STATUSTEXT"], until=lambda m: m.get_type() == "MISSION_ITEM")
        assert any("use MISSION_REQUEST_INT" in m.text for m in seen[:-1])
        assert seen[-1].seq == 0 and abs(seen[-1].x - simulator.origin.latitude_deg) < 1e-5
        # Beyond home: ArduPilot says the real count, then refuses.
        client.mav.mission_request_int_send(1, 1, 1, mavlink2.MAV_MISSION_TYPE_MISSION)
        seen = replies(client, ["MISSION_COUNT", "MISSION_ACK"], until=lambda m: m.get_type() == "MISSION_ACK")
        assert [m.get_type() for m in seen] == ["MISSION_COUNT", "MISSION_ACK"]
        assert seen[-1].type == mavlink2.MAV_MISSION_ERROR
        # Fences and rally points: none. Other types: unsupported.
        client.mav.mission_request_list_send(1, 1, mavlink2.MAV_MISSION_TYPE_FENCE)
        fence = wait_for(client, "MISSION_COUNT")
        assert fence.count == 0 and fence.mission_type == mavlink2.MAV_MISSION_TYPE_FENCE
        client.mav.mission_request_list_send(1, 1, mavlink2.MAV_MISSION_TYPE_ALL)
        assert wait_for(client, "MISSION_ACK").type == mavlink2.MAV_MISSION_UNSUPPORTED
        client.mav.mission_clear_all_send(1, 1, mavlink2.MAV_MISSION_TYPE_MISSION)
        assert wait_for(client, "MISSION_ACK").type == mavlink2.MAV_MISSION_ACCEPTED
        client.mav.mission_count_send(1, 1, 3, mavlink2.MAV_MISSION_TYPE_MISSION)
        assert wait_for(client, "MISSION_ACK").type == mavlink2.MAV_MISSION_UNSUPPORTED


# ------------------------------------------------------------------------------------------- serving


def test_a_busy_port_is_refused():
    port = free_port()
    holder = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}")  # SO_REUSEADDR, as another face would
    try:
        with pytest.raises(MavlinkFaceError, match="address in use"):
            MavlinkFace(simulator=Simulator(seed=1), clock=ScaledWallClock(speedup=1.0),
                        listen=f"udp:127.0.0.1:{port}")
        result = CliRunner().invoke(app, ["sim", "serve", "--listen", f"udp:127.0.0.1:{port}"])
    finally:
        holder.close()
    assert result.exit_code == 2
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and "--listen" in lines[0] and "address in use" in lines[0]


def test_a_plain_socket_holding_the_port_is_refused_too():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other:
        other.bind(("127.0.0.1", 0))
        port = other.getsockname()[1]
        with pytest.raises(MavlinkFaceError, match="address in use"):
            MavlinkFace(simulator=Simulator(seed=1), clock=ScaledWallClock(speedup=1.0),
                        listen=f"udp:127.0.0.1:{port}")


@pytest.mark.parametrize("option, expected", [
    ("LAND_SPEEDX=40", "not an ArduCopter parameter"),
    ("PRL_FS_HOLD=3", "not an ArduCopter parameter"),
    ("LAND_SPEED=fast", "is not a number"),
    ("LAND_SPEED=nan", "is not a number"),
    ("LAND_SPEED=5", "outside 30..200"),
    ("LAND_SPEED", "expected NAME=VALUE"),
])
def test_sim_serve_param_is_validated(option, expected):
    result = CliRunner().invoke(app, ["sim", "serve", "--listen", f"udp:127.0.0.1:{free_port()}",
                                      "--param", option])
    assert result.exit_code == 2
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and "--param" in lines[0] and expected in lines[0], lines


def test_sim_serve_param_sets_parameters_at_start_after_the_missions(monkeypatch):
    served = {}

    async def record(face):
        served["params"] = face.simulator.params

    monkeypatch.setattr(MavlinkFace, "run", record)
    result = CliRunner().invoke(app, ["sim", "serve", "--listen", f"udp:127.0.0.1:{free_port()}",
                                      "--mission", str(THESIS_MISSION), "--param", "PLND_ENABLED=1",
                                      "--param", "plnd_type=1", "--param", "LAND_SPEED=35.7"])
    assert result.exit_code == 0, result.output
    params = served["params"]
    assert params.get("PLND_ENABLED") == 1 and params.get("PLND_TYPE") == 1
    assert params.get("LAND_SPEED") == 35.0  # an AP_Int16 keeps the whole part
