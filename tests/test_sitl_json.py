"""ArduPilot SITL's JSON interface: wire format, the quad X motor model, the lock-step bridge (no SITL binary)."""

from __future__ import annotations

import json
import math
import socket
import struct
import time

import pytest

from preland_app.errors import PrelandError
from preland_app.sim.json_bridge import JsonBridge, JsonBridgeTimeout
from preland_app.sim.multirotor import GRAVITY_M_S2, QuadXFrame, QuadXMultirotor
from preland_app.sim.sitl_json import (MAGIC_16, MAGIC_32, REQUIRED_KEYS, SitlJsonError, build_reply,
                                       build_servo_packet, parse_reply_like_sim_json, parse_servo_packet)

RATE_HZ = 1200  # SITL.cpp SIM_RATE_HZ_DEFAULT on SITL boards
DT_S = 1.0 / RATE_HZ


def airborne(frame: QuadXFrame | None = None, altitude_m: float = 5.0) -> QuadXMultirotor:
    """A vehicle at `altitude_m` with its motors already at the hover command."""
    frame = frame or QuadXFrame()
    hover = frame.pwm_to_command(frame.hover_pwm_us())
    return QuadXMultirotor(frame=frame, position_ned_m=(0.0, 0.0, -altitude_m), motor_commands=[hover] * 4)


# --- wire format ------------------------------------------------------------------------------------


def test_servo_packets_of_both_magics_parse():
    raw16 = struct.pack("<HHI16H", MAGIC_16, 1200, 77, *range(1000, 1016))
    packet = parse_servo_packet(raw16)
    assert (packet.magic, packet.frame_rate_hz, packet.frame_count) == (MAGIC_16, 1200, 77)
    assert packet.pwm_us == tuple(range(1000, 1016)) and packet.dt_s == pytest.approx(1 / 1200)
    raw32 = struct.pack("<HHI32H", MAGIC_32, 400, 2**32 - 1, *range(1100, 1132))
    packet = parse_servo_packet(raw32)
    assert (packet.magic, packet.frame_rate_hz, packet.frame_count) == (MAGIC_32, 400, 2**32 - 1)
    assert len(packet.pwm_us) == 32 and packet.pwm_us[31] == 1131
    assert len(raw16) == 40 and len(raw32) == 72  # SIM_JSON.h's structs, no padding
    assert build_servo_packet(frame_rate_hz=1200, frame_count=77, pwm_us=range(1000, 1016)) == raw16


@pytest.mark.parametrize("raw, why", [
    (b"", "0 bytes is shorter than its header"),
    (struct.pack("<HHI16H", 1234, 1200, 0, *[1000] * 16), "magic 1234 is neither"),
    (struct.pack("<HHI16H", MAGIC_32, 1200, 0, *[1000] * 16), f"magic {MAGIC_32} has 40 bytes, not 72"),
    (struct.pack("<HHI32H", MAGIC_16, 1200, 0, *[1000] * 32), f"magic {MAGIC_16} has 72 bytes, not 40"),
    (struct.pack("<HHI16H", MAGIC_16, 0, 0, *[1000] * 16), "frame rate 0")])
def test_what_is_not_a_servo_packet_is_refused(raw, why):
    with pytest.raises(SitlJsonError, match=why):
        parse_servo_packet(raw)
    assert issubclass(SitlJsonError, PrelandError)


def test_the_reply_is_one_json_line_that_sim_json_reads():
    state = airborne().step([1500] * 4, DT_S)
    text = build_reply(state, include_euler=True, battery_voltage_v=12.6)
    assert text.startswith("\n") and text.endswith("\n") and text.count("\n") == 2
    assert ": " not in text and ", " not in text  # SIM_JSON skips len(key)+2 and sscanf's "[%f, %f, %f]"
    data = json.loads(text)
    assert {k for s, k in REQUIRED_KEYS if s == ""} <= data.keys() and {"gyro", "accel_body"} <= data["imu"].keys()
    assert len(data["quaternion"]) == 4 and len(data["attitude"]) == 3 and data["battery"]["voltage"] == 12.6
    assert data["timestamp"] == pytest.approx(DT_S) and data["rng_1"] == pytest.approx(5.0, abs=1e-3)
    seen = parse_reply_like_sim_json(text)
    assert seen["position"] == pytest.approx(list(state.position_ned_m))
    assert seen["quaternion"] == pytest.approx(list(state.quaternion_wxyz))
    assert seen["accel_body"] == pytest.approx(list(state.accel_frd_m_s2))
    with pytest.raises(SitlJsonError):  # a space after the colon: SIM_JSON's sscanf reads nothing
        parse_reply_like_sim_json(text.replace('"position":', '"position": '))
    with pytest.raises(SitlJsonError):  # a required key missing
        parse_reply_like_sim_json(text.replace('"velocity"', '"speed"'))


# --- the motor model --------------------------------------------------------------------------------


def test_thrust_curve_matches_arducopter_hover():
    frame = QuadXFrame()
    # four motors at MOT_THST_HOVER's thrust lift the weight: thrust fraction 0.39 of maximum
    assert 4 * frame.max_thrust_per_motor_n * frame.thrust_fraction(
        frame.command_for_thrust_fraction(0.39)) == pytest.approx(frame.mass_kg * GRAVITY_M_S2)
    assert frame.hover_pwm_us() == pytest.approx(1590.66, abs=0.01)  # 1000 + (0.15 + 0.5508 * 0.8) * 1000
    assert frame.pwm_to_command(1150) == 0.0 and frame.pwm_to_command(1950) == 1.0
    assert frame.command_to_pwm_us(frame.pwm_to_command(1400)) == pytest.approx(1400)


def test_at_rest_on_the_ground_with_motors_at_pwm_min_it_stays_at_rest():
    model = QuadXMultirotor()
    for _ in range(10 * RATE_HZ):  # 10 simulated s
        state = model.step([1000] * 4, DT_S)
    assert state.time_s == pytest.approx(10.0)
    assert state.position_ned_m == (0.0, 0.0, 0.0) and state.velocity_ned_m_s == (0.0, 0.0, 0.0)
    assert state.on_ground and state.accel_frd_m_s2 == pytest.approx((0.0, 0.0, -GRAVITY_M_S2))
    assert state.gyro_frd_rad_s == (0.0, 0.0, 0.0) and state.rangefinder_down_m == 0.0


def test_at_the_hover_pwm_it_holds_altitude():
    frame = QuadXFrame()
    model = airborne(frame)
    hover_pwm = frame.hover_pwm_us()
    for _ in range(5 * RATE_HZ):
        state = model.step([hover_pwm] * 4, DT_S)
    assert abs(state.position_ned_m[2] + 5.0) < 0.03  # within 3 cm over 5 s
    assert max(abs(v) for v in state.velocity_ned_m_s) < 0.01
    assert state.accel_frd_m_s2[2] == pytest.approx(-GRAVITY_M_S2, abs=1e-3)


def test_it_takes_off_and_touches_down_without_bouncing():
    frame = QuadXFrame()
    model = QuadXMultirotor(frame=frame)
    for _ in range(RATE_HZ):  # 1 s at 60 us above hover
        state = model.step([frame.hover_pwm_us() + 60] * 4, DT_S)
    assert not state.on_ground and state.position_ned_m[2] < -0.1
    heights = []
    for _ in range(5 * RATE_HZ):  # motors to idle: it falls, touches down, stays
        state = model.step([1000] * 4, DT_S)
        heights.append(-state.position_ned_m[2])
    touchdown = next(i for i, h in enumerate(heights) if h <= 0.0)
    assert all(h == 0.0 for h in heights[touchdown:])  # no bounce, no sinking
    assert state.on_ground and state.velocity_ned_m_s == (0.0, 0.0, 0.0)


def test_more_thrust_on_motors_1_and_4_rolls_left_as_arducopter_mixes():
    # AP_MotorsMatrix: roll factor cos(angle + 90 deg) is negative for motors 1 (45 deg) and 4 (135 deg),
    # so ArduCopter lowers them to roll right: raised, they roll the vehicle left (negative roll).
    assert math.cos(math.radians(45 + 90)) < 0 and math.cos(math.radians(135 + 90)) < 0
    frame = QuadXFrame()
    model = airborne(frame)
    hover = frame.hover_pwm_us()
    for _ in range(RATE_HZ // 10):
        state = model.step([hover + 50, hover, hover, hover + 50], DT_S)
    roll, pitch, yaw = state.euler_rad
    assert roll < -0.05 and state.gyro_frd_rad_s[0] < -1.0
    assert abs(pitch) < 1e-9 and abs(yaw) < 1e-9
    model = airborne(frame)
    for _ in range(RATE_HZ // 10):  # front motors 1 and 3 raised: nose up (positive pitch)
        state = model.step([hover + 50, hover, hover + 50, hover], DT_S)
    assert state.euler_rad[1] > 0.05 and abs(state.euler_rad[0]) < 1e-9


def test_more_thrust_on_the_ccw_motors_yaws_right():
    # AP_MotorsMatrix.h: yaw factor CCW = +1 (motors 1, 2): ArduCopter raises them to yaw right (positive)
    frame = QuadXFrame()
    model = airborne(frame)
    hover = frame.hover_pwm_us()
    for _ in range(RATE_HZ // 2):
        state = model.step([hover + 50, hover + 50, hover - 50, hover - 50], DT_S)
    assert state.gyro_frd_rad_s[2] > 0.1 and state.euler_rad[2] > 0.01
    assert abs(state.euler_rad[0]) < 1e-9 and abs(state.euler_rad[1]) < 1e-9


# --- the lock-step bridge ---------------------------------------------------------------------------


class StandInSitl:
    """A UDP client that talks to the bridge as SIM_JSON does: a servo packet, then wait for the reply."""

    def __init__(self, address: tuple[str, int]) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.settimeout(5.0)  # every wait bounded
        self.address = address

    def exchange(self, frame_count: int, pwm_us: list[int]) -> dict:
        self.sock.sendto(build_servo_packet(frame_rate_hz=RATE_HZ, frame_count=frame_count, pwm_us=pwm_us),
                         self.address)
        text = self.sock.recvfrom(65000)[0].decode()
        parse_reply_like_sim_json(text)
        return json.loads(text)

    def close(self) -> None:
        self.sock.close()


def test_the_bridge_answers_1000_steps_in_lock_step():
    bridge = JsonBridge(model=QuadXMultirotor(), port=0, packet_timeout_s=10.0).start()
    sitl = StandInSitl(bridge.address)
    try:
        pwm = [1000] * 16
        replies = [sitl.exchange(frame, pwm) for frame in range(1000)]
        for i, reply in enumerate(replies):
            assert reply["timestamp"] == pytest.approx((i + 1) * DT_S, abs=1e-9)
        steps = [b["timestamp"] - a["timestamp"] for a, b in zip(replies, replies[1:])]
        assert min(steps) == pytest.approx(DT_S, abs=1e-12) and max(steps) == pytest.approx(DT_S, abs=1e-12)
        again = sitl.exchange(999, pwm)  # SITL resending a frame: the same answer, no step
        assert again == replies[-1]
        counters = bridge.counters
        assert (counters.packets, counters.steps, counters.repeats, counters.last_frame_count) == (1001, 1000, 1, 999)
        restarted = sitl.exchange(0, pwm)  # a lower frame count: SITL restarted, the physics too
        assert restarted["timestamp"] == pytest.approx(DT_S) and bridge.counters.resets == 1
        assert bridge.error is None and bridge.running
    finally:
        sitl.close()
        bridge.stop()
    assert not bridge.running


def test_resends_sitl_made_while_the_bridge_was_held_are_dropped_and_answered_once():
    from .waiting import until

    bridge = JsonBridge(model=QuadXMultirotor(), port=0, packet_timeout_s=10.0).start()
    sitl = StandInSitl(bridge.address)
    try:
        pwm = [1000] * 16
        sitl.exchange(0, pwm)
        bridge.gate.hold_at(bridge.gate.time_s)  # a reading is being made at this time: frame 1 waits
        packet = build_servo_packet(frame_rate_hz=RATE_HZ, frame_count=1, pwm_us=pwm)
        for _ in range(3):  # frame 1, then two resends (SITL resends after 1 s without an answer)
            sitl.sock.sendto(packet, bridge.address)
        until(lambda: bridge.counters.packets == 2, timeout_s=10.0, what="the bridge to read frame 1")
        bridge.gate.hold_at(None)
        first = json.loads(sitl.sock.recvfrom(65000)[0].decode())
        assert first["timestamp"] == pytest.approx(2 * DT_S, abs=1e-9)
        following = sitl.exchange(2, pwm)  # the next answer is frame 2's: no stale frame-1 answer between
        assert following["timestamp"] == pytest.approx(3 * DT_S, abs=1e-9)
        counters = bridge.counters
        assert counters.resends_dropped == 2 and counters.steps == 3 and counters.repeats == 0
    finally:
        sitl.close()
        bridge.stop()


def test_resends_sitl_made_while_a_step_was_late_are_dropped_too(monkeypatch):
    """Not held, but late (a stalled thread, a loaded machine): an answer that leaves _RESEND_LOOK_WALL_S or
    more after the one before looks for resends first, as one after a hold does."""
    import threading

    from preland_app.sim import json_bridge

    from .waiting import until

    monkeypatch.setattr(json_bridge, "_RESEND_LOOK_WALL_S", 0.2)
    bridge = JsonBridge(model=QuadXMultirotor(), port=0, packet_timeout_s=10.0).start()
    sitl = StandInSitl(bridge.address)
    stepping, go_on = threading.Event(), threading.Event()
    model_step = bridge.model.step

    def late_step(*args):
        if not go_on.is_set():  # frame 1: the step stands until the resends are in the bridge's socket
            stepping.set()
            assert go_on.wait(10.0), "the test to let the step go on"
        return model_step(*args)

    try:
        pwm = [1000] * 16
        sitl.exchange(0, pwm)
        replied = time.monotonic()
        bridge.model.step = late_step
        packet = build_servo_packet(frame_rate_hz=RATE_HZ, frame_count=1, pwm_us=pwm)
        sitl.sock.sendto(packet, bridge.address)
        assert stepping.wait(10.0), "the bridge to step frame 1"
        for _ in range(2):  # two resends, while the bridge steps frame 1 (in its socket once sent: loopback)
            sitl.sock.sendto(packet, bridge.address)
        until(lambda: time.monotonic() - replied >= 0.2, timeout_s=10.0, what="the answer to be late")
        go_on.set()
        first = json.loads(sitl.sock.recvfrom(65000)[0].decode())
        assert first["timestamp"] == pytest.approx(2 * DT_S, abs=1e-9)
        following = sitl.exchange(2, pwm)  # the next answer is frame 2's: no stale frame-1 answer between
        assert following["timestamp"] == pytest.approx(3 * DT_S, abs=1e-9)
        counters = bridge.counters
        assert counters.resends_dropped == 2 and counters.steps == 3 and counters.repeats == 0 and counters.holds == 0
    finally:
        go_on.set()
        sitl.close()
        bridge.stop()


def test_the_bridge_accounts_for_its_wall_time_between_physics_sitl_and_holds():
    bridge = JsonBridge(model=QuadXMultirotor(), port=0, packet_timeout_s=10.0).start()
    sitl = StandInSitl(bridge.address)
    try:
        started = time.perf_counter()
        sitl.exchange(0, [1000] * 16)
        slow_sitl_s = 0.05
        deadline = time.perf_counter() + slow_sitl_s  # SITL's own step, slow: the bridge is waiting for it
        while time.perf_counter() < deadline:
            pass
        for frame in range(1, 200):
            sitl.exchange(frame, [1000] * 16)
        elapsed_s = time.perf_counter() - started
        counters = bridge.counters
        assert counters.physics_wall_s > 0 and counters.held_wall_s == 0.0  # nothing held it
        assert counters.waiting_wall_s >= slow_sitl_s
        assert counters.physics_wall_s + counters.waiting_wall_s <= elapsed_s + 0.5  # the bridge started first
    finally:
        sitl.close()
        bridge.stop()


def test_the_bridge_gives_up_after_its_bounded_wait():
    bridge = JsonBridge(model=QuadXMultirotor(), port=0, packet_timeout_s=0.3).start()
    try:
        assert bridge.wait(5.0)  # bounded: the bridge's own 0.3 s wait ends its thread
        assert isinstance(bridge.error, JsonBridgeTimeout) and isinstance(bridge.error, PrelandError)
        assert bridge.error.packets == 0
    finally:
        bridge.stop()


# --- the air: the embedded simulator's wind, gusts and wash -----------------------------------------


def test_a_vehicle_held_level_drifts_with_the_wind_until_it_moves_with_the_air():
    # Level, at the hover PWM, in a steady 3 m/s wind towards the south: drag pushes it until its
    # velocity over the ground is the air's (within 5 %); in still air it does not move (test above).
    frame = QuadXFrame()
    model = airborne(frame, altitude_m=20.0)
    wind = (-3.0, 0.0, 0.0)
    for _ in range(60 * RATE_HZ):
        state = model.step([frame.hover_pwm_us()] * 4, DT_S, wind)
    vn, ve, vd = state.velocity_ned_m_s
    assert vn == pytest.approx(-3.0, rel=0.05) and abs(ve) < 1e-6
    assert state.position_ned_m[0] < -100.0  # carried south, about 3 m/s for most of the minute


def test_a_landed_vehicle_is_held_by_the_ground_not_blown_by_the_air():
    # 5 m/s across and 2 m/s up, motors at 90 % of the hover thrust: held, level, until the motors lift it.
    frame = QuadXFrame()
    model = QuadXMultirotor(frame=frame)
    below_hover = frame.command_to_pwm_us(frame.command_for_thrust_fraction(0.9 * frame.thrust_fraction(
        frame.pwm_to_command(frame.hover_pwm_us()))))
    for _ in range(2 * RATE_HZ):
        state = model.step([below_hover] * 4, DT_S, (5.0, 0.0, -2.0))
    assert state.on_ground and state.position_ned_m == (0.0, 0.0, 0.0) and state.velocity_ned_m_s == (0.0, 0.0, 0.0)
    for _ in range(RATE_HZ):
        state = model.step([frame.hover_pwm_us() + 100] * 4, DT_S, (5.0, 0.0, -2.0))
    assert not state.on_ground and state.position_ned_m[2] < -0.1 and state.velocity_ned_m_s[0] > 0.1


def test_the_bridge_flies_in_the_trial_seeds_air_and_tells_sitl_of_it():
    from preland_app.sim.air import AirAtVehicle
    from preland_app.sim.simulator import Simulator
    from preland_app.sim.spec import EnvironmentSpec, GroundEffectSpec, WindSpec

    # Steady wind only: what SITL is told is exactly the wind from the east, 2.5 m/s towards the west.
    steady = EnvironmentSpec(wind=WindSpec(speed_m_s=2.5, direction_from_deg=90.0, turbulence_w20_m_s=0.0),
                             ground_effect=GroundEffectSpec(sigma_m_s=0.0))
    bridge = JsonBridge(model=airborne(), port=0, packet_timeout_s=10.0,
                        air=AirAtVehicle(environment=steady, seed=3)).start()
    sitl = StandInSitl(bridge.address)
    try:
        hover = [int(QuadXFrame().hover_pwm_us())] * 4 + [1000] * 12
        replies = [sitl.exchange(frame, hover) for frame in range(2 * RATE_HZ)]
    finally:
        sitl.close()
        bridge.stop()
    for reply in replies:
        assert reply["velocity_wind"] == pytest.approx([0.0, -2.5, 0.0], abs=1e-9)
    assert replies[-1]["velocity"][1] < -0.05  # pushed west
    # A direction left to the seed: the embedded simulator's for the same seed; stepped alike, its very gusts.
    gusty = EnvironmentSpec(wind=WindSpec(speed_m_s=1.5, direction_from_deg=None, turbulence_w20_m_s=2.0))
    for seed in (1, 2):
        air, embedded = AirAtVehicle(environment=gusty, seed=seed), Simulator(seed=seed, environment=gusty).wind
        assert air.wind.direction_from_deg == embedded.direction_from_deg
        assert math.hypot(*air.wind.steady_ned_m_s) == pytest.approx(1.5)
        winds = [air.step(dt_s=DT_S, height_m=10.0, velocity_ned_m_s=(0.0, 0.0, 0.0)) for _ in range(10 * RATE_HZ)]
        assert winds == [embedded.step(dt_s=DT_S, altitude_m=10.0, airspeed_m_s=math.hypot(*embedded.current_ned_m_s[:2]))
                         for _ in range(10 * RATE_HZ)]
        assert max(abs(w[0] - winds[0][0]) for w in winds) > 0.05  # the gusts blow


def test_the_air_starts_when_the_motors_turn_after_the_embedded_simulators_time_on_the_ground():
    from preland_app.sim.air import AirAtVehicle
    from preland_app.sim.spec import EnvironmentSpec, WindSpec

    gusty = EnvironmentSpec(wind=WindSpec(speed_m_s=1.5, direction_from_deg=None, turbulence_w20_m_s=2.0))
    lead_s = 3.0
    bridge = JsonBridge(model=QuadXMultirotor(), port=0, packet_timeout_s=10.0,
                        air=AirAtVehicle(environment=gusty, seed=5, lead_on_ground_s=lead_s)).start()
    sitl = StandInSitl(bridge.address)
    try:
        # SITL booting and arming: motors at MOT_PWM_MIN, the vehicle on the ground in still air.
        idle = [sitl.exchange(frame, [1000] * 16) for frame in range(RATE_HZ)]
        turning = [sitl.exchange(frame, [1100] * 4 + [1000] * 12) for frame in range(RATE_HZ, RATE_HZ + 20)]
    finally:
        sitl.close()
        bridge.stop()
    assert all("velocity_wind" not in reply or reply["velocity_wind"] == [0.0, 0.0, 0.0] for reply in idle)
    # From the first step the motors turn: the air the embedded simulator has lead_s after its start, stepped
    # alike (at rest on the ground until then, at rest on the ground in these 20 steps too).
    embedded = AirAtVehicle(environment=gusty, seed=5)
    for _ in range(round(lead_s * RATE_HZ)):
        embedded.step(dt_s=DT_S, height_m=0.0, velocity_ned_m_s=(0.0, 0.0, 0.0))
    expected = [embedded.step(dt_s=DT_S, height_m=0.0, velocity_ned_m_s=(0.0, 0.0, 0.0)) for _ in range(20)]
    told = [value for reply in turning for value in reply["velocity_wind"]]
    assert told == pytest.approx([value for wind in expected for value in wind], abs=1e-9)
    assert math.hypot(*expected[0][:2]) > 0.5


def test_a_gyro_error_reaches_sitls_roll_and_pitch_rates_only_and_repeats_with_its_seed():
    from preland_app.sim.imu import GyroError
    from preland_app.sim.spec import NavigationSpec

    spec = NavigationSpec(attitude_noise_sigma_deg=0.7, attitude_noise_tau_s=0.5)
    hover = [int(QuadXFrame().hover_pwm_us())] * 4 + [1000] * 12
    flown = {}
    for name, error in (("true", None), ("seed 4", GyroError.for_mission(spec, seed=4, per_attitude_error=0.5)),
                        ("seed 4 again", GyroError.for_mission(spec, seed=4, per_attitude_error=0.5))):
        bridge = JsonBridge(model=airborne(), port=0, packet_timeout_s=10.0, gyro_error=error).start()
        sitl = StandInSitl(bridge.address)
        try:
            flown[name] = [sitl.exchange(frame, hover) for frame in range(RATE_HZ)]
        finally:
            sitl.close()
            bridge.stop()
    assert flown["seed 4"] == flown["seed 4 again"]
    expected = GyroError.for_mission(spec, seed=4, per_attitude_error=0.5)
    at_rest = airborne().state  # only the error added to its rates is read
    for true, erred in zip(flown["true"], flown["seed 4"]):
        # The physics flies the same: only the body rates SITL is told differ, by the error's own sequence.
        assert erred["position"] == true["position"] and erred["quaternion"] == true["quaternion"]
        assert erred["imu"]["accel_body"] == true["imu"]["accel_body"]
        assert erred["imu"]["gyro"][2] == true["imu"]["gyro"][2]
        stepped = expected.applied(at_rest, DT_S).gyro_frd_rad_s
        for axis in (0, 1):
            assert erred["imu"]["gyro"][axis] - true["imu"]["gyro"][axis] == pytest.approx(stepped[axis], abs=1e-12)
    assert max(abs(r["imu"]["gyro"][0] - t["imu"]["gyro"][0]) for r, t in zip(flown["seed 4"], flown["true"])) > 1e-4


def test_the_gyro_errors_spread_and_time_constant_are_the_missions_attitude_error_scaled():
    from preland_app.sim.imu import GyroError
    from preland_app.sim.multirotor import MultirotorState
    from preland_app.sim.spec import NavigationSpec

    spec = NavigationSpec(attitude_noise_sigma_deg=0.7, attitude_noise_tau_s=0.5)
    assert GyroError.for_mission(spec, seed=1, per_attitude_error=0.0) is None
    assert GyroError.for_mission(NavigationSpec(attitude_noise_sigma_deg=0.0), seed=1, per_attitude_error=0.5) is None
    error = GyroError.for_mission(spec, seed=1, per_attitude_error=0.5)
    rest = MultirotorState(time_s=0.0, position_ned_m=(0.0, 0.0, 0.0), velocity_ned_m_s=(0.0, 0.0, 0.0),
                           quaternion_wxyz=(1.0, 0.0, 0.0, 0.0), gyro_frd_rad_s=(0.0, 0.0, 0.0),
                           accel_frd_m_s2=(0.0, 0.0, -GRAVITY_M_S2), motor_commands=(0.0,) * 4, on_ground=True,
                           rangefinder_down_m=0.0)
    dt_s = 1.0 / 800
    rolls = [error.applied(rest, dt_s).gyro_frd_rad_s[0] for _ in range(800 * 600)]  # 600 vehicle s
    sigma = math.radians(0.7) * 0.5
    # 600 s hold about 600 independent values of a 0.5 s process: the spread within 10 %, the lag-tau
    # autocorrelation near 1/e.
    spread = math.sqrt(sum(r * r for r in rolls) / len(rolls))
    assert spread == pytest.approx(sigma, rel=0.1)
    lag = 400  # 0.5 s at 800 Hz
    correlation = sum(a * b for a, b in zip(rolls, rolls[lag:])) / (len(rolls) - lag) / spread ** 2
    assert correlation == pytest.approx(math.exp(-1.0), abs=0.1)


def test_the_high_pass_takes_off_what_moves_slowly_and_keeps_what_moves_fast():
    from preland_app.runtime.sitl_log import HIGH_PASS_S, high_passed, rms

    rows = [(0.04 * i, 5.0 + 0.01 * 0.04 * i + 0.1 * math.sin(2 * math.pi * 0.04 * i / 0.5), -3.0)
            for i in range(1500)]  # 60 s at 25 Hz: an offset, a slow drift, a 0.5 s wave of 0.1 m north
    out = high_passed(rows)
    north, east = out[0::2], out[1::2]
    # A centred average over whole periods of the wave: the offset and the drift go, the wave stays.
    assert rms(north) == pytest.approx(0.1 / math.sqrt(2), rel=0.02)
    assert max(abs(v) for v in east) < 1e-9
    # Rows within half the window of either end (less its 0.5 s slack) have no centred average.
    assert len(north) == sum(1 for t, *_ in rows if HIGH_PASS_S / 2 - 0.5 <= t <= 60 - 0.04 - HIGH_PASS_S / 2 + 0.5)
