"""ArduPilot SITL's JSON physics interface, on the wire (`arducopter --model JSON:HOST`).

Each physics step SITL sends one binary servo packet over UDP to port 9002 (+10 per instance) of the
physics host (libraries/SITL/SIM_JSON.h):

    uint16 magic = 18458 | 29569   (16 or 32 channels; 32 with SERVO_32_ENABLE = 1)
    uint16 frame_rate              (Hz: the step the physics should take is 1 / frame_rate s)
    uint32 frame_count             (one more per accepted reply; the same again when SITL resends)
    uint16 pwm[16 | 32]            (us)

little-endian, no padding (40 or 72 bytes). The physics answers with one line of JSON text, preceded
and followed by a newline. SIM_JSON::parse_sensors reads it with `strstr` and `sscanf`, not a JSON
parser, which constrains the text:

- required: `timestamp` (s), `imu` with `gyro` (rad/s, body FRD) and `accel_body` (m/s^2, body FRD,
  specific force), `position` (m, NED), `velocity` (m/s, NED); and `attitude` (roll, pitch, yaw in rad)
  or `quaternion` (w, x, y, z; used when both are sent);
- a value must follow its key's colon at once (`"key":value`, no space): the parser skips
  `strlen(key) + 2` characters and vectors are read with `sscanf("[%f, %f, %f]")`;
- a key must not occur inside an earlier key (`velocity` would match `velocity_wind` first), so
  optional keys that contain a required one come after it;
- SIM_JSON takes the last complete line between two newlines; a reply without all required keys is
  dropped and SITL resends the same frame_count after 1 s without a reply;
- a timestamp lower than the previous one is taken as a physics reset.

`build_reply` writes such text; `parse_reply_like_sim_json` reads it the way SIM_JSON does (for tests).
"""

from __future__ import annotations

import functools
import math
import re
import struct
from dataclasses import dataclass
from typing import Sequence

from ..errors import PrelandError
from .multirotor import MultirotorState

MAGIC_16 = 18458  # SIM_JSON.h servo_packet_16
MAGIC_32 = 29569  # SIM_JSON.h servo_packet_32
_HEADER = struct.Struct("<HHI")
_CHANNELS_BY_MAGIC = {MAGIC_16: 16, MAGIC_32: 32}
# By a packet's size in bytes: its magic, and the whole packet read in one unpack.
_PACKET_BY_SIZE = {_HEADER.size + 2 * channels: (magic, struct.Struct(f"<HHI{channels}H"))
                   for magic, channels in _CHANNELS_BY_MAGIC.items()}
DEFAULT_PORT = 9002  # SITL_cmdline.cpp SIM_OUT_PORT; instance N uses 9002 + 10 N

# SIM_JSON.h keytable: (section, key, required)
REQUIRED_KEYS: tuple[tuple[str, str], ...] = (
    ("", "timestamp"), ("imu", "gyro"), ("imu", "accel_body"), ("", "position"), ("", "velocity"))
ATTITUDE_KEYS: tuple[str, ...] = ("attitude", "quaternion")


class SitlJsonError(PrelandError):
    """A servo packet or a reply that ArduPilot's JSON interface would not accept."""


@dataclass(frozen=True, kw_only=True)
class ServoPacket:
    """One servo packet from SITL: `frame_rate_hz` (the step is 1/frame_rate_hz s), `frame_count`,
    `pwm_us` (16 or 32 channels, us; channel i+1 at index i)."""

    magic: int
    frame_rate_hz: int
    frame_count: int
    pwm_us: tuple[int, ...]

    @property
    def dt_s(self) -> float:
        """The physics step SITL asks for (s)."""
        return 1.0 / self.frame_rate_hz


def parse_servo_packet(data: bytes) -> ServoPacket:
    """Decode one servo packet (either magic); SitlJsonError when it is not one."""
    magic, frame_rate_hz, frame_count, pwm = unpack_servo_packet(data)
    return ServoPacket(magic=magic, frame_rate_hz=frame_rate_hz, frame_count=frame_count, pwm_us=pwm)


def unpack_servo_packet(data: bytes) -> tuple[int, int, int, tuple[int, ...]]:
    """(magic, frame_rate_hz, frame_count, pwm_us) of one servo packet, as `parse_servo_packet` reads it,
    without building a `ServoPacket` (the bridge reads one per physics step); SitlJsonError when it is not
    one."""
    sized = _PACKET_BY_SIZE.get(len(data))
    if sized is not None:
        magic, frame_rate_hz, frame_count, *pwm = sized[1].unpack(data)
        if magic == sized[0] and frame_rate_hz != 0:
            return magic, frame_rate_hz, frame_count, tuple(pwm)
    # Not a well-formed packet of either size: say what is wrong with it.
    if len(data) < _HEADER.size:
        raise SitlJsonError(f"servo packet of {len(data)} bytes is shorter than its header")
    magic, frame_rate_hz, frame_count = _HEADER.unpack_from(data)
    channels = _CHANNELS_BY_MAGIC.get(magic)
    if channels is None:
        raise SitlJsonError(f"servo packet magic {magic} is neither {MAGIC_16} nor {MAGIC_32}")
    expected = _HEADER.size + 2 * channels
    if len(data) != expected:
        raise SitlJsonError(f"servo packet with magic {magic} has {len(data)} bytes, not {expected}")
    raise SitlJsonError("servo packet with frame rate 0")


def build_servo_packet(*, frame_rate_hz: int, frame_count: int, pwm_us: Sequence[int]) -> bytes:
    """Encode a servo packet as SIM_JSON::output_servos does: 16 channels, or 32 when more are given."""
    channels = 16 if len(pwm_us) <= 16 else 32
    if len(pwm_us) > 32:
        raise SitlJsonError(f"{len(pwm_us)} channels: at most 32")
    magic = MAGIC_16 if channels == 16 else MAGIC_32
    values = list(pwm_us) + [0] * (channels - len(pwm_us))
    return _HEADER.pack(magic, frame_rate_hz, frame_count & 0xFFFFFFFF) + struct.pack(f"<{channels}H", *values)


def _check_finite(values: Sequence[float], name: str) -> None:
    """SitlJsonError when one of `values` is not finite."""
    if not all(map(math.isfinite, values)):
        raise SitlJsonError(f"{name} is not finite: {[float(v) for v in values]}")


def build_reply(state: MultirotorState, *, include_euler: bool = False, include_rangefinder: bool = True,
                battery_voltage_v: float | None = None,
                wind_ned_m_s: tuple[float, float, float] | None = None) -> str:
    """The reply text for `state`: newline, one JSON object without spaces, newline.

    Sends `quaternion` (w, x, y, z; body FRD to NED), and `attitude` too when `include_euler`; `rng_1`
    is the downward rangefinder's distance (m) when `include_rangefinder`; `battery.voltage` (V) when
    given; `velocity_wind` (NED, m/s: SITL's wind estimate's truth, for its logs and an airspeed sensor)
    when `wind_ned_m_s` is given, last, since SIM_JSON finds keys by substring and `velocity` must match
    first. The timestamp is the model's simulated time (s).

    Written directly, not through json.dumps: the same text (json.dumps writes a float as its repr, as
    `%r` does), in a fraction of the time, once per physics step.
    """
    values = [state.time_s, *state.gyro_frd_rad_s, *state.accel_frd_m_s2, *state.position_ned_m,
              *state.velocity_ned_m_s, *state.quaternion_wxyz]
    if include_euler:
        values += state.euler_rad
    if include_rangefinder:
        values.append(state.rangefinder_down_m)
    if battery_voltage_v is not None:
        values.append(battery_voltage_v)
    if wind_ned_m_s is not None:
        values += wind_ned_m_s
    numbers = tuple(map(float, values))
    if not all(map(math.isfinite, numbers)):
        _refuse_not_finite(state, include_euler=include_euler, include_rangefinder=include_rangefinder,
                           battery_voltage_v=battery_voltage_v, wind_ned_m_s=wind_ned_m_s)
    return _reply_format(include_euler, include_rangefinder, battery_voltage_v is not None,
                         wind_ned_m_s is not None) % numbers


@functools.lru_cache(maxsize=None)
def _reply_format(euler: bool, rangefinder: bool, battery: bool, wind: bool) -> str:
    """The reply's text with a `%r` for each number, in `build_reply`'s order."""
    return "".join([
        '\n{"timestamp":%r,"imu":{"gyro":[%r,%r,%r],"accel_body":[%r,%r,%r]}',
        ',"position":[%r,%r,%r],"velocity":[%r,%r,%r],"quaternion":[%r,%r,%r,%r]',
        ',"attitude":[%r,%r,%r]' if euler else "",
        ',"rng_1":%r' if rangefinder else "",
        ',"battery":{"voltage":%r}' if battery else "",
        ',"velocity_wind":[%r,%r,%r]' if wind else "",
        "}\n"])


def _refuse_not_finite(state: MultirotorState, *, include_euler: bool, include_rangefinder: bool,
                       battery_voltage_v: float | None, wind_ned_m_s: tuple[float, float, float] | None) -> None:
    """SitlJsonError naming the first value of a reply that is not finite."""
    for name, values in (("timestamp", (state.time_s,)), ("gyro", state.gyro_frd_rad_s),
                         ("accel_body", state.accel_frd_m_s2), ("position", state.position_ned_m),
                         ("velocity", state.velocity_ned_m_s), ("quaternion", state.quaternion_wxyz),
                         ("attitude", state.euler_rad if include_euler else ()),
                         ("rng_1", (state.rangefinder_down_m,) if include_rangefinder else ()),
                         ("battery voltage", () if battery_voltage_v is None else (battery_voltage_v,)),
                         ("velocity_wind", wind_ned_m_s or ())):
        _check_finite(values, name)


_FLOAT = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def parse_reply_like_sim_json(text: str) -> dict[str, object]:
    """Read reply text the way SIM_JSON::recv_fdm and parse_sensors do; SitlJsonError on what they reject.

    Takes the last line between two newlines, looks each key up with a plain substring search (within
    its section), skips `len(key) + 2` characters and reads a number or `[a, b, c(, d)]`. Returns
    {"timestamp": float, "gyro": [...], "accel_body": [...], "position": [...], "velocity": [...],
    "attitude" or "quaternion": [...], optional "rng_1": float, ...}.
    """
    lines = text.split("\n")
    if len(lines) < 3:
        raise SitlJsonError("reply is not preceded and followed by a newline")
    line = lines[-2]  # between the last two newlines
    found: dict[str, object] = {}
    keys = [(s, k, True) for s, k in REQUIRED_KEYS] + [("", k, False) for k in ATTITUDE_KEYS] + [
        ("", f"rng_{i}", False) for i in range(1, 7)] + [("battery", "voltage", False), ("", "velocity_wind", False)]
    for section, key, required in keys:
        start = line.find(section)
        if start < 0 or not line:
            if required:
                raise SitlJsonError(f"no section {section!r}")
            continue
        start += len(section) + 1
        at = line.find(key, start)
        if at < 0:
            if required:
                raise SitlJsonError(f"no key {section}/{key}")
            continue
        value = line[at + len(key) + 2:]
        if key in ("gyro", "accel_body", "position", "velocity", "attitude", "quaternion", "velocity_wind"):
            n = 4 if key == "quaternion" else 3
            pattern = r"\[" + r",\s*".join([f"({_FLOAT})"] * n) + r"\]"
            match = re.match(pattern, value)
            if match is None:
                raise SitlJsonError(f"{key}: sscanf would not read {value[:40]!r}")
            found[key] = [float(g) for g in match.groups()]
        else:
            match = re.match(r"\s*" + _FLOAT, value)
            if match is None:
                raise SitlJsonError(f"{key}: atof would not read {value[:40]!r}")
            found[key] = float(match.group(0))
    if not any(k in found for k in ATTITUDE_KEYS):
        raise SitlJsonError("neither attitude nor quaternion")
    return found
