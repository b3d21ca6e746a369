#!/usr/bin/env python3
"""A stand-in for ArduPilot's `arducopter` SITL binary, for tests: it takes SITL's command line and serves
preland's embedded simulator over MAVLink to the --serial0 udpclient address. It writes its pid, the tick it
started at and its arguments to $FAKE_SITL_LOG_DIR (when set) so tests can check what was launched and that
it is gone (tests/procs.py), and a PID.airborne file there once the vehicle is in the air.

With `--model JSON:HOST` it also acts as SITL on its JSON interface: servo packets (a constant PWM just
below the quad X's hover, so the physics stays on the ground) to HOST at `--sim-port-out` (else 9002 +
10 x instance) at FRAME_RATE_HZ of its scaled clock, each waited for as SITL waits: for ever, resent after
each wall second without an answer. It writes the answers it got to PID.json_answers (a count). Its flight
stays the embedded simulator's, served over MAVLink as without JSON, but on SITL's clock in lock-step: the
physics' time (answers / FRAME_RATE_HZ); the next servo packet leaves only once the face has served the
time of the last answer (SITL runs its loop, MAVLink included, before it asks for the next step). As SITL
(HAL_SITL's SIGTERM handler), on JSON it takes a SIGTERM only at its next step: while the physics does not
answer, it runs no step and does not exit; once it does, it writes PID.exit ("SIGTERM") and exits 0."""

import argparse
import asyncio
import json
import os
import signal
import socket
import sys
import threading
import time
from pathlib import Path


def _arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    parser.add_argument("--model")
    parser.add_argument("--speedup", type=float, default=1.0)
    parser.add_argument("--defaults", default="")
    parser.add_argument("-I", dest="instance", type=int, default=0)
    parser.add_argument("--home")
    parser.add_argument("--serial0")
    parser.add_argument("--sim-port-out", type=int, default=None)
    return parser.parse_args()


if __name__ == "__main__":
    # Read before the simulator is imported: preland asks every binary for its --help before it launches it,
    # and arducopter answers at once.
    ARGUMENTS = _arguments()

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from preland_app.clock_scaled import ScaledWallClock  # noqa: E402
from preland_app.geo import GeoPoint  # noqa: E402
from preland_app.sim.mavlink_face import MavlinkFace  # noqa: E402
from preland_app.errors import CommandDenied  # noqa: E402
from preland_app.runtime.sitl_parm import read_parm_file  # noqa: E402
from preland_app.sim.params import ARDUCOPTER_PARAMS  # noqa: E402
from preland_app.sim.simulator import Simulator  # noqa: E402
from preland_app.sim.multirotor import QuadXFrame  # noqa: E402
from preland_app.sim.sitl_json import DEFAULT_PORT, build_servo_packet  # noqa: E402
from tests.procs import started_ticks  # noqa: E402


# SITL's own parameters that preland writes during a flight (libraries/SITL/SITL.cpp, 4.6: AP_Vector3f,
# served as three REAL32). The stand-in serves and stores them; its GPS error stays the simulator's own.
SITL_FLOAT_PARAMS = ("SIM_GPS_GLITCH_X", "SIM_GPS_GLITCH_Y", "SIM_GPS_GLITCH_Z")


FRAME_RATE_HZ = 100  # physics steps per scaled second: a few hundred packets per wall s, cheap for CI
RESEND_S = 1.0  # SIM_JSON::recv_fdm resends the servos after 1 wall s without an answer
SERVED_TIMEOUT_S = 60.0  # wall s for the face (this process) to serve a physics time before giving up
_SAME_S = 1e-6  # two times closer than this are one (the face's steps add up 1 / FRAME_RATE_HZ)


def _write_whole(path: Path, text: str) -> None:
    """Write `text` to `path` by a rename, so a test polling the file never reads it empty or half written."""
    partial = path.with_name(path.name + ".partial")
    partial.write_text(text)
    os.replace(partial, path)


class PhysicsTime:
    """SITL's clock on its JSON interface: the physics' time, which moves only with an answer. The face sleeps
    on it (one task: its step loop); the JSON side moves it, then waits until the face sleeps past it."""

    def __init__(self) -> None:
        self._answers = 0
        self._changed = threading.Condition()
        self._sleeper: tuple[float, asyncio.Future, asyncio.AbstractEventLoop] | None = None

    def now_s(self) -> float:
        return self._answers / FRAME_RATE_HZ

    async def sleep(self, duration_s: float) -> None:
        loop = asyncio.get_running_loop()
        future = loop.create_future()
        with self._changed:
            deadline_s = self.now_s() + max(0.0, duration_s)
            if deadline_s <= self.now_s() + _SAME_S:
                return
            self._sleeper = (deadline_s, future, loop)
            self._changed.notify_all()
        await future

    def answered(self) -> None:
        """The physics answered a servo packet: its time moves one frame on (the JSON side's thread)."""
        with self._changed:
            self._answers += 1
            if self._sleeper is not None and self._sleeper[0] <= self.now_s() + _SAME_S:
                _, future, loop = self._sleeper
                self._sleeper = None
                loop.call_soon_threadsafe(lambda: future.done() or future.set_result(None))

    def wait_served(self, timeout_s: float) -> bool:
        """Until the face sleeps past the physics' time (it has stepped and served up to it); False after
        `timeout_s` wall s."""
        with self._changed:
            return self._changed.wait_for(
                lambda: self._sleeper is not None and self._sleeper[0] > self.now_s() + _SAME_S, timeout=timeout_s)


_SHOULD_EXIT = threading.Event()  # set by SIGTERM on JSON, read after each answered step (see the module)


def serve_json_physics(*, host: str, port: int, speedup: float, log_dir: str | None,
                       physics_time: PhysicsTime) -> None:
    """SITL's side of the JSON interface, in lock-step: send a servo packet, wait for its answer, let the face
    serve the new time, next frame."""
    pwm = [round(QuadXFrame().hover_pwm_us()) - 50] * 4 + [0] * 12
    answers_file = Path(log_dir, f"{os.getpid()}.json_answers") if log_dir else None
    answers, noted_at = 0, 0.0
    frame_wall_s = 1.0 / (FRAME_RATE_HZ * speedup)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.settimeout(RESEND_S)
        if not physics_time.wait_served(SERVED_TIMEOUT_S):  # the face runs from time 0, as SITL on the physics
            print(f"fake SITL: the face did not start within {SERVED_TIMEOUT_S:g} s", file=sys.stderr, flush=True)
            os._exit(3)
        next_at = time.monotonic()
        for frame_count in range(2**32):
            packet = build_servo_packet(frame_rate_hz=FRAME_RATE_HZ, frame_count=frame_count, pwm_us=pwm)
            sent_at = time.monotonic()
            sock.sendto(packet, (host, port))
            while True:
                try:
                    sock.recv(4096)
                    break
                except socket.timeout:
                    print("No JSON sensor message received, resending servos", flush=True)  # as SITL says it
                    sock.sendto(packet, (host, port))  # the same frame_count again, as SITL resends
            answers += 1
            if _SHOULD_EXIT.is_set():
                if log_dir:
                    _write_whole(Path(log_dir, f"{os.getpid()}.exit"), "SIGTERM\n")
                os._exit(0)
            physics_time.answered()
            if not physics_time.wait_served(SERVED_TIMEOUT_S):
                print(f"fake SITL: the face did not serve physics time {physics_time.now_s():.2f} s within "
                      f"{SERVED_TIMEOUT_S:g} s", file=sys.stderr, flush=True)
                os._exit(3)
            if answers_file is not None and (answers == 1 or sent_at - noted_at > 0.2):
                _write_whole(answers_file, f"{answers}\n")
                noted_at = sent_at
            # at the frame rate, without a burst to catch up after a stall (a loaded machine, a long wait)
            next_at = max(next_at + frame_wall_s, time.monotonic() - frame_wall_s)
            time.sleep(max(0.0, next_at - time.monotonic()))


class SitlFace(MavlinkFace):
    """The face plus SITL's own SIM_* parameters, as a SITL build has them (REAL32)."""

    def __init__(self, *, sim_values: dict[str, float], heartbeat_log: Path | None = None, **kwargs) -> None:
        super().__init__(**kwargs)
        self.sim_values = {name: sim_values.get(name, 0.0) for name in SITL_FLOAT_PARAMS}
        self.heartbeat_log = heartbeat_log

    def _on_heartbeat(self, message) -> None:
        """Note the physics time each ground station's HEARTBEAT is read at (a test checks when they come)."""
        if self.heartbeat_log is not None:
            with self.heartbeat_log.open("a", encoding="ascii") as log:
                log.write(f"{self.simulator.time_s:.4f} {message.get_srcComponent()}\n")

    def _sim_value(self, name: str) -> None:
        self.mav.param_value_send(name.encode("ascii"), self.sim_values[name], 9, len(self._param_names), 65535)

    def _on_param_request_read(self, message) -> None:
        name = self._param_id(message)
        if message.param_index == -1 and name in self.sim_values:
            self._sim_value(name)
        else:
            super()._on_param_request_read(message)

    def _on_param_set(self, message) -> None:
        name = self._param_id(message)
        if name in self.sim_values:
            self.sim_values[name] = float(message.param_value)
            self._sim_value(name)
        else:
            super()._on_param_set(message)


def main(args: argparse.Namespace) -> None:
    log_dir = os.environ.get("FAKE_SITL_LOG_DIR")
    if log_dir:
        launch = {"pid": os.getpid(), "started": started_ticks(), "argv": sys.argv[1:]}
        _write_whole(Path(log_dir, f"{os.getpid()}.json"), json.dumps(launch))
    # ArduPilot reads every defaults file, later ones winning; the simulator models only some parameters,
    # the others (compass offsets, RC calibration, SIM_*) are taken and ignored, as SITL would use them.
    given = {}
    for path in filter(None, args.defaults.split(",")):
        given.update(read_parm_file(Path(path)))
    params = {name: value for name, value in given.items() if name in ARDUCOPTER_PARAMS}
    lat, lon, alt, heading = (float(v) for v in args.home.split(","))
    simulator = Simulator(seed=args.instance, origin=GeoPoint(lat, lon, alt), params=params, initial_yaw_deg=heading)
    if not given.get("FRAME_CLASS"):
        # ArduCopter's default FRAME_CLASS is 0 (undefined): its motors refuse to arm, as without copter.parm.
        def refuse(*_args, **_kwargs):
            raise CommandDenied(operation="arm", reason="Arm: Motors: Check frame class and type")

        simulator.autopilot.arm = refuse
    else:
        # SITL writes its dataflash log from arming (LOG_DISARMED 0) to logs/00000001.BIN in its folder.
        arm = simulator.autopilot.arm

        def arm_and_log(*arm_args, **arm_kwargs):
            result = arm(*arm_args, **arm_kwargs)
            Path("logs").mkdir(exist_ok=True)
            _write_whole(Path("logs", "00000001.BIN"), f"stand-in dataflash log of instance {args.instance}\n")
            return result

        simulator.autopilot.arm = arm_and_log
    if log_dir:
        # Tests that stop SITL in flight wait for this file instead of guessing a wall time.
        step, airborne = simulator.step, Path(log_dir, f"{os.getpid()}.airborne")
        noted = False

        def step_and_note() -> None:
            nonlocal noted
            step()
            if not noted and simulator.autopilot.landed_state().name == "IN_AIR":
                _write_whole(airborne, f"{simulator.time_s:.2f}\n")
                noted = True

        simulator.step = step_and_note
    on_json = bool(args.model and args.model.startswith("JSON"))
    clock = PhysicsTime() if on_json else ScaledWallClock(speedup=args.speedup)
    if on_json:
        host = args.model.partition(":")[2] or "127.0.0.1"
        port = args.sim_port_out if args.sim_port_out is not None else DEFAULT_PORT + 10 * args.instance
        signal.signal(signal.SIGTERM, lambda *_: _SHOULD_EXIT.set())
        threading.Thread(target=serve_json_physics, daemon=True,
                         kwargs={"host": host, "port": port, "speedup": args.speedup, "log_dir": log_dir,
                                 "physics_time": clock}).start()
    face = SitlFace(simulator=simulator, clock=clock, listen=args.serial0, sim_values=given,
                    heartbeat_log=Path(log_dir, f"{os.getpid()}.heartbeats") if log_dir else None)
    asyncio.run(face.run())


if __name__ == "__main__":
    main(ARGUMENTS)
