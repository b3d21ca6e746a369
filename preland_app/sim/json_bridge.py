"""The lock-step bridge between ArduPilot SITL's JSON interface and a `QuadXMultirotor`.

SITL sends a servo packet and waits for the state; the bridge answers each new packet with the state
after stepping the model by the packet's 1/frame_rate s. The model's time is the only clock of the
physics: wall time is used only to bound how long the bridge waits for a packet.

- a repeated frame_count (SITL resends after 1 s without a usable reply) is answered with the same
  reply again, without stepping;
- a higher frame_count than the next one (packets lost) is stepped once, as any new packet;
- a lower frame_count means SITL restarted: the model is reset and its time starts again from 0.

`gate` (a `StepGate`) lets the companion hold the physics at a vehicle time (a camera frame's, an
IR-LOCK reading's) until it has made that reading and sent its LANDING_TARGET: the packet that would step
past it waits. Datagrams SITL resent meanwhile (the same frame_count, after 1 s without an answer) are
dropped before the answer leaves, so SITL gets one answer per frame and never reads a stale one later; the
socket is looked at for them only after a held step or an answer late by half SITL's resend time.

SITL is told the model's state through `SensorSmoothing` (SITL's own smooth_sensors), its body rates
with `gyro_error` (`sim/imu.py`) when given; `latest_state` stays the model's true state.
"""

from __future__ import annotations

import select
import socket
import struct
import sys
import threading
import time
from dataclasses import dataclass

from ..errors import PrelandError
from .air import AirAtVehicle
from .imu import GyroError
from .multirotor import MultirotorState, QuadXMultirotor
from .sitl_json import DEFAULT_PORT, SitlJsonError, build_reply, unpack_servo_packet
from .sensor_smoothing import SensorSmoothing
from .step_gate import StepGate

_POLL_S = 0.05  # how often a waiting bridge looks at its stop flag (wall s)
_MAX_PACKET_BYTES = 2048
# SITL resends a servo packet only after waiting 1 s for its answer (SIM_JSON::recv_fdm: ten 100 ms waits), so
# an answer that leaves sooner than this after the one before, its physics not held, has no resend to drop
# before it and the socket is not looked at (wall s).
_RESEND_LOOK_WALL_S = 0.5


class JsonBridgeTimeout(PrelandError):
    """No servo packet arrived within the bridge's bounded wait."""

    def __init__(self, *, timeout_s: float, packets: int) -> None:
        self.timeout_s = timeout_s
        self.packets = packets
        super().__init__(f"JSON bridge: no servo packet for {timeout_s:g} wall s (after {packets} packets)")


@dataclass(frozen=True, kw_only=True)
class BridgeCounters:
    """What the bridge has done: packets received, steps taken, repeats answered, resets, bad packets; and
    where its wall time went: stepping the model and writing the replies (`physics_wall_s`), waiting for
    SITL's next packet (`waiting_wall_s`: SITL's own step and the transport), and held for the companion
    (`held_wall_s`: its readings, camera frames and the settle before a wake)."""

    packets: int
    steps: int
    repeats: int
    resets: int
    frames_skipped: int
    bad_packets: int
    last_frame_count: int | None
    holds: int
    held_wall_s: float
    resends_dropped: int
    physics_wall_s: float
    waiting_wall_s: float


class JsonBridge:
    """A UDP server answering SITL's servo packets with `model`'s state, in lock-step.

    Use `start()` / `stop()` (or `with JsonBridge(...)`) to serve from a thread, or `serve()` to serve in
    the calling thread until `stop()` or a timeout. `packet_timeout_s` bounds the wait for each packet
    (wall s); when it passes, `serve` raises JsonBridgeTimeout (kept in `error` when serving in a thread).
    """

    def __init__(self, *, model: QuadXMultirotor, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 packet_timeout_s: float = 30.0, send_rangefinder: bool = True,
                 battery_voltage_v: float | None = None, air: AirAtVehicle | None = None,
                 gyro_error: GyroError | None = None) -> None:
        if packet_timeout_s <= 0:
            raise ValueError("packet_timeout_s must be positive")
        self.model = model
        self.air = air  # None: still air
        self._motors_turned = False
        self._motor_idle_pwm_us = model.frame.pwm_min_us + 10.0  # disarmed and spooled down: MOT_PWM_MIN
        self.gyro_error = gyro_error  # None: SITL is told the true body rates
        self.packet_timeout_s = float(packet_timeout_s)
        self._send_rangefinder = send_rangefinder
        self._battery_voltage_v = battery_voltage_v
        # No SO_REUSEADDR: with it, Linux may give port 0 a port another such socket holds (a served vehicle's),
        # and the two would share its datagrams.
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind((host, port))
        if sys.platform == "linux":
            # A blocking socket whose receive gives up after _POLL_S: one system call a packet each way (a
            # Python timeout polls before each receive and send), and still a look at the stop flag.
            seconds, micros = divmod(round(_POLL_S * 1e6), 1_000_000)
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, struct.pack("@ll", seconds, micros))
        else:
            self._sock.settimeout(_POLL_S)
        self._readable = select.poll()
        self._readable.register(self._sock, select.POLLIN)
        self.address = self._sock.getsockname()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._last_frame: int | None = None
        self._last_reply: bytes = b""
        self._packets = self._steps = self._repeats = self._resets = self._skipped = self._bad = 0
        self._latest: MultirotorState = model.state
        self._dropped = 0
        self._physics_wall_s = self._waiting_wall_s = 0.0
        self._pending: tuple[bytes, object] | None = None  # a datagram read while dropping resends
        self._held = False  # the step just taken waited at the gate (SITL may have resent meanwhile)
        self.gate = StepGate()
        self._smoothing = SensorSmoothing()  # what SITL is told, as SITL's own physics tells it
        self.error: BaseException | None = None

    # --- life cycle -----------------------------------------------------------------------------

    def start(self) -> "JsonBridge":
        """Serve from a daemon thread; returns self."""
        if self._thread is not None:
            raise RuntimeError("bridge already started")
        self._thread = threading.Thread(target=self._serve_in_thread, name="sitl-json-bridge", daemon=True)
        self._thread.start()
        return self

    def stop(self, *, timeout_s: float = 5.0) -> None:
        """Stop serving, wait (bounded) for the thread, close the socket. Safe to call twice."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
        self._sock.close()

    def wait(self, timeout_s: float) -> bool:
        """Wait at most `timeout_s` wall s for the serving thread to end; True if it has ended."""
        if self._thread is not None:
            self._thread.join(timeout_s)
        return not self.running

    def __enter__(self) -> "JsonBridge":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        """True while the serving thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    def _serve_in_thread(self) -> None:
        try:
            self.serve()
        except BaseException as error:  # kept for the owner, who reads `error`
            self.error = error

    # --- serving --------------------------------------------------------------------------------

    def serve(self, *, max_packets: int | None = None) -> None:
        """Answer packets until `stop()`, `max_packets` packets, or JsonBridgeTimeout."""
        served = 0
        deadline = time.monotonic() + self.packet_timeout_s  # wall time bounds the wait only
        waiting_since = replied_at = time.perf_counter()
        while not self._stop.is_set() and (max_packets is None or served < max_packets):
            try:
                if self._pending is not None:
                    (data, sender), self._pending = self._pending, None
                else:
                    data, sender = self._sock.recvfrom(_MAX_PACKET_BYTES)
            except (socket.timeout, BlockingIOError):  # no packet within _POLL_S
                if time.monotonic() > deadline:
                    raise JsonBridgeTimeout(timeout_s=self.packet_timeout_s, packets=self._packets) from None
                continue
            except OSError:
                if self._stop.is_set():
                    return  # socket closed by stop()
                raise
            received_at = time.perf_counter()
            deadline = time.monotonic() + self.packet_timeout_s
            reply = self._handle(data, waited_wall_s=received_at - waiting_since)
            waiting_since = time.perf_counter()  # before the answer leaves: SITL's step starts with it
            if reply is not None:
                if self._held or waiting_since - replied_at >= _RESEND_LOOK_WALL_S:
                    self._drop_resends()
                self._sock.sendto(reply, sender)
                replied_at = waiting_since
            served += 1

    def _drop_resends(self) -> None:
        """Drop the resends of the frame about to be answered already waiting; keep anything else."""
        while self._readable.poll(0):  # only what is there now: no wait, no exception per answer
            data, sender = self._sock.recvfrom(_MAX_PACKET_BYTES)
            try:
                repeat = unpack_servo_packet(data)[2] == self._last_frame
            except SitlJsonError:
                repeat = False
            if not repeat:
                self._pending = (data, sender)
                return
            with self._lock:
                self._dropped += 1

    def handle(self, data: bytes) -> bytes | None:
        """The reply to one datagram (None for one that is not a servo packet); steps the model."""
        return self._handle(data, waited_wall_s=0.0)

    def _handle(self, data: bytes, *, waited_wall_s: float) -> bytes | None:
        """`handle`, counting `waited_wall_s` (the wall s the datagram was waited for) in `waiting_wall_s`."""
        try:
            _, frame_rate_hz, frame_count, pwm_us = unpack_servo_packet(data)
        except SitlJsonError:
            with self._lock:
                self._bad += 1
                self._waiting_wall_s += waited_wall_s
            return None
        with self._lock:
            self._waiting_wall_s += waited_wall_s
            self._packets += 1
            last = self._last_frame
            if last is not None and frame_count == last:
                self._repeats += 1
                return self._last_reply
            if last is not None and frame_count < last:
                self.model.reset()  # SITL restarted: so does the physics
                self._smoothing.reset()
                self._resets += 1
            elif last is not None and frame_count > last + 1:
                self._skipped += frame_count - last - 1
        if last is not None and frame_count < last:
            self.gate.reset()
        # Held for a reading at this time: SITL waits with us (and may resend meanwhile).
        self._held = self.gate.wait_to_step(stop=self._stop)
        stepping_at = time.perf_counter()
        dt_s = 1.0 / frame_rate_hz
        with self._lock:
            # The air moves from the first step the motors turn on (before, the vehicle rests on the ground,
            # still air): that is where the embedded simulator's flight starts, whenever SITL got ready.
            self._motors_turned = self._motors_turned or max(pwm_us[:4]) > self._motor_idle_pwm_us
            wind = None if self.air is None or not self._motors_turned else self.air.step(
                dt_s=dt_s, height_m=self.model.height_above_ground_m, velocity_ned_m_s=self.model.velocity_ned_m_s)
            state = self.model.step(pwm_us, dt_s, wind or (0.0, 0.0, 0.0))
            self._steps += 1
            self._last_frame = frame_count
            told = self._smoothing.smoothed(state)
            if self.gyro_error is not None:
                told = self.gyro_error.applied(told, dt_s)
            self._last_reply = build_reply(told, include_rangefinder=self._send_rangefinder,
                                           battery_voltage_v=self._battery_voltage_v, wind_ned_m_s=wind).encode()
            self._latest = state
            reply = self._last_reply
            self._physics_wall_s += time.perf_counter() - stepping_at
        self.gate.stepped(state.time_s)
        return reply

    # --- readings for other threads ---------------------------------------------------------------

    @property
    def latest_state(self) -> MultirotorState:
        """The state of the last reply (a frozen snapshot)."""
        return self._latest

    @property
    def counters(self) -> BridgeCounters:
        """A consistent snapshot of the bridge's counters."""
        with self._lock:
            return BridgeCounters(packets=self._packets, steps=self._steps, repeats=self._repeats,
                                  resets=self._resets, frames_skipped=self._skipped, bad_packets=self._bad,
                                  last_frame_count=self._last_frame, holds=self.gate.holds,
                                  held_wall_s=self.gate.held_wall_s, resends_dropped=self._dropped,
                                  physics_wall_s=self._physics_wall_s, waiting_wall_s=self._waiting_wall_s)
