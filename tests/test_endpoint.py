"""MAVLink addresses: one parser for preland's, MAVSDK's, pymavlink's and ArduPilot's forms."""

import pytest

from preland_app.mavlink.endpoint import Endpoint, EndpointError, parse_endpoint


@pytest.mark.parametrize("text, expected", [
    ("mavlink+udp://:14550", Endpoint(kind="udp", port=14550)),
    ("udp://:14550", Endpoint(kind="udp", port=14550)),
    ("udp:127.0.0.1:14550", Endpoint(kind="udp", host="127.0.0.1", port=14550)),
    ("udpin:127.0.0.1:14550", Endpoint(kind="udp", host="127.0.0.1", port=14550)),
    ("mavlink+udpout://127.0.0.1:14550", Endpoint(kind="udpout", host="127.0.0.1", port=14550)),
    ("udpclient:127.0.0.1:14550", Endpoint(kind="udpout", host="127.0.0.1", port=14550)),
    ("mavlink+tcp://127.0.0.1:5760", Endpoint(kind="tcp", host="127.0.0.1", port=5760)),
    ("tcpout://10.0.0.2:5760", Endpoint(kind="tcp", host="10.0.0.2", port=5760)),
    ("tcpin://0.0.0.0:5760", Endpoint(kind="tcpin", host="0.0.0.0", port=5760)),
    ("mavlink+serial:///dev/ttyAMA0?baud=921600", Endpoint(kind="serial", device="/dev/ttyAMA0", baud=921600)),
    ("serial:///dev/ttyAMA0:921600", Endpoint(kind="serial", device="/dev/ttyAMA0", baud=921600)),
    ("serial:///dev/ttyUSB0", Endpoint(kind="serial", device="/dev/ttyUSB0", baud=57600)),
])
def test_every_form_reads_to_one_endpoint(text, expected):
    assert parse_endpoint(text) == expected
    assert parse_endpoint(expected.url) == expected  # preland's own form reads back


def test_each_library_gets_its_own_form():
    assert parse_endpoint("tcp://127.0.0.1:5760").mavsdk_url() == "tcpout://127.0.0.1:5760"
    assert parse_endpoint("mavlink+udp://:14550").mavsdk_url() == "udpin://0.0.0.0:14550"
    assert parse_endpoint("udpin://127.0.0.1:14550").mavsdk_url() == "udpin://127.0.0.1:14550"
    assert parse_endpoint("mavlink+serial:///dev/ttyAMA0?baud=921600").mavsdk_url() == "serial:///dev/ttyAMA0:921600"
    assert parse_endpoint("udpclient:127.0.0.1:14550").pymavlink_address() == "udpout:127.0.0.1:14550"
    assert parse_endpoint("mavlink+udp://127.0.0.1:14551").pymavlink_address() == "udpin:127.0.0.1:14551"


@pytest.mark.parametrize("text, problem", [
    ("http://127.0.0.1:80", "not a MAVLink address"),
    ("mavlink+udp://127.0.0.1", "needs a port"),
    ("mavlink+udpout://:14550", "needs the host"),
    ("mavlink+udp://:70000", "needs a port"),
    ("mavlink+serial:///dev/ttyAMA0?speed=9600", "unknown option 'speed'"),
    ("mavlink+serial:///dev/ttyAMA0?baud=fast", "baud must be"),
    ("mavlink+serial://ttyAMA0", "needs a device path"),
    ("mavlink+udp://:14550?rate=4", "takes no options"),
])
def test_a_bad_address_names_its_problem(text, problem):
    with pytest.raises(EndpointError, match=problem):
        parse_endpoint(text)
