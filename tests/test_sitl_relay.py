"""The UDP relay between SITL and MAVSDK (runtime/sitl_relay.py): frames passed both ways and counted by key."""

import socket

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from preland_app.runtime.sitl_relay import MavlinkRelay, frame_keys

from .waiting import until

NAMES = {message_id: cls.msgname for message_id, cls in mavlink2.mavlink_map.items()}


def _encoder(system_id: int = 1) -> mavlink2.MAVLink:
    return mavlink2.MAVLink(None, srcSystem=system_id, srcComponent=1)


def test_frame_keys_name_each_frame_and_a_command_by_its_number():
    mav = _encoder()
    heartbeat = mav.heartbeat_encode(2, 3, 0, 4, 0).pack(mav)
    # DO_SET_MODE's trailing zero bytes are trimmed by MAVLink 2: the command is still read.
    command = mav.command_long_encode(1, 1, 176, 0, 1, 4, 0, 0, 0, 0, 0).pack(mav)
    target = mav.landing_target_encode(0, 0, 8, 0.1, -0.2, 5.0, 0.0, 0.0).pack(mav)
    assert frame_keys(heartbeat + command + target, NAMES) == ["HEARTBEAT", "COMMAND_LONG:176", "LANDING_TARGET"]
    assert frame_keys(b"\x00\x01" + heartbeat, NAMES) == ["HEARTBEAT"]  # bytes before a frame are skipped
    zeros = mav.command_long_encode(0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav)
    assert zeros[1] == 1 and frame_keys(zeros, NAMES) == ["COMMAND_LONG:0"]  # all zeros: trimmed to one byte


def test_the_relay_passes_frames_both_ways_and_counts_them():
    mavsdk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # where MAVSDK would listen
    mavsdk.bind(("127.0.0.1", 0))
    mavsdk.settimeout(10.0)
    sitl = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # SITL's udpclient
    sitl.settimeout(10.0)
    relay = MavlinkRelay(mavsdk_port=mavsdk.getsockname()[1]).start()
    try:
        vehicle, companion = _encoder(1), _encoder(255)
        sent = vehicle.heartbeat_encode(2, 3, 0, 4, 0).pack(vehicle)
        sitl.sendto(sent, ("127.0.0.1", relay.sitl_port))
        received, relay_address = mavsdk.recvfrom(65536)
        assert received == sent
        until(lambda: relay.from_sitl["HEARTBEAT"] == 1, timeout_s=10.0, what="the relay to count SITL's frame")
        assert relay.idle()

        answer = companion.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(companion)
        mavsdk.sendto(answer, relay_address)  # MAVSDK answers where the frames came from
        assert sitl.recvfrom(65536)[0] == answer
        until(lambda: relay.to_sitl["COMMAND_LONG:400"] == 1, timeout_s=10.0, what="the relay to count the command")
        assert relay.from_sitl == {"HEARTBEAT": 1} and relay.to_sitl == {"COMMAND_LONG:400": 1}
    finally:
        relay.stop()
        mavsdk.close()
        sitl.close()


def test_a_gated_message_reaches_sitl_only_as_admitted():
    mavsdk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    mavsdk.bind(("127.0.0.1", 0))
    mavsdk.settimeout(10.0)
    sitl = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sitl.settimeout(10.0)
    relay = MavlinkRelay(mavsdk_port=mavsdk.getsockname()[1]).start()
    try:
        vehicle, companion = _encoder(1), _encoder(1)
        sitl.sendto(vehicle.heartbeat_encode(2, 3, 0, 4, 0).pack(vehicle), ("127.0.0.1", relay.sitl_port))
        _, relay_address = mavsdk.recvfrom(65536)

        def heartbeat() -> bytes:
            return companion.heartbeat_encode(18, 8, 0, 0, 0).pack(companion)

        mavsdk.sendto(heartbeat(), relay_address)  # not gated yet: passed
        assert frame_keys(sitl.recvfrom(65536)[0], NAMES) == ["HEARTBEAT"]
        until(lambda: relay.to_sitl["HEARTBEAT"] == 1, timeout_s=10.0, what="the relay to count the heartbeat")
        assert relay.gate("HEARTBEAT") == 1  # how many passed before
        target = companion.landing_target_encode(0, 0, 8, 0.1, -0.2, 5.0, 0.0, 0.0).pack(companion)
        mavsdk.sendto(heartbeat(), relay_address)  # MAVSDK's own: held back
        mavsdk.sendto(heartbeat() + target, relay_address)  # held back, the target in the same datagram passed
        assert sitl.recvfrom(65536)[0] == target
        relay.allow("HEARTBEAT")
        admitted = heartbeat()
        mavsdk.sendto(admitted, relay_address)
        assert sitl.recvfrom(65536)[0] == admitted
        until(lambda: relay.to_sitl["HEARTBEAT"] == 2, timeout_s=10.0, what="the relay to count the admitted one")
        relay.allow("LANDING_TARGET")  # not gated: nothing changes
        mavsdk.sendto(target, relay_address)
        assert sitl.recvfrom(65536)[0] == target
        until(lambda: relay.to_sitl["LANDING_TARGET"] == 2, timeout_s=10.0, what="the relay to count the target")
        mavsdk.sendto(b"\x00\x01\x02", relay_address)  # no frame at all: passed as it came, counted under none
        assert sitl.recvfrom(65536)[0] == b"\x00\x01\x02"
        assert relay.held_back == {"HEARTBEAT": 2} and relay.to_sitl == {"HEARTBEAT": 2, "LANDING_TARGET": 2}
    finally:
        relay.stop()
        mavsdk.close()
        sitl.close()
