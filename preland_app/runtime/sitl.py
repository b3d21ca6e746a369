"""ArduPilot SITL binaries as a runtime: one fresh `arducopter` process per trial.

Each trial gets its own SITL instance number (`-I N`, so parallel workers never
share ports) held by a lock file, a temporary working folder (SITL writes its
EEPROM and logs there), `--speedup`, the mission's home, and `--defaults` in
this order: ArduPilot's copter defaults (Tools/autotest/default_params/copter.parm
of the build tree the binary sits in, else the small copy the package carries),
the user's `--sitl-defaults` files, then the trial's own parameters in a file of
their own: precision landing from a companion (PLND_TYPE=1) and the downward
rangefinder (RNGFND1_TYPE) take effect only after a reboot, so they go in at
launch; the scenario's wind as SIM_WIND_*; and the trial's GPS error as
SIM_GPS_GLITCH_*, which `GpsErrorDriver` then moves along during the flight. SITL sends MAVLink to a UDP port the trial listens on
(`--serial0 udpclient:127.0.0.1:PORT`). The process runs in its own process
group, dies with the process that launched it (PR_SET_PDEATHSIG), and is
stopped, group and all, when the trial ends, fails or is interrupted.

The physics is ArduPilot's own (`physics=ardupilot`, `--model +`) or preland's motor-level quad X
(`physics=preland`): SITL then runs `--model JSON:127.0.0.1` and sends its motors' PWM, each physics
step, to a `JsonBridge` serving from a thread of the trial's process on a port of its own
(`--sim-port-out`), which answers with the next state; the frame's parameters (packaged
sitl_json_quadx.parm) follow the copter defaults. On preland's physics the air is the embedded
simulator's (`sim/air.py`: the scenario's wind, Dryden gusts and rotor wash from the trial seed's
streams), sent to SITL as `velocity_wind`; SITL's own SIM_WIND_* blow only on its own physics and are
not set. With `gyro_error`, the body rates SITL's IMU reads carry a gyro error scaled from the mission's
attitude error (`sim/imu.py`). The bridge is stopped with its SITL.

On preland's physics the trial runs in lock-step with it (`vehicle.lockstep_clock`): the companion's
clock is the physics' time, each camera frame and IR-LOCK reading shows the physics' state at its own
vehicle time (not SIM_STATE, which comes later and at its stream's rate), and the physics does not step
past that time until the reading's LANDING_TARGET is sent. --speedup is then SPEEDUP_LOCKSTEP, more than
the two can reach, so SITL never sleeps: the pace is the physics' and the companion's.
"""

from __future__ import annotations

import asyncio
import ctypes
import fcntl
import functools
import logging
import math
import os
import shutil
import signal
import socket
import subprocess
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar
from pathlib import Path

from ..config.mission import MissionSpec
from ..errors import PrelandError
from ..outcome import TrialOutcome
from ..sim.navigation import GpsPositionError
from ..sim.noise import child_rng
from ..sim.air import AirAtVehicle
from ..sim.autopilot import ARMING_DELAY_S
from ..sim.imu import GyroError
from ..sim.json_bridge import JsonBridge, JsonBridgeTimeout
from ..sim.multirotor import QuadXFrame, QuadXMultirotor
from ..sim.spec import DEFAULT_HOME, EnvironmentSpec
from ..sensing.virtual_camera import CameraPose
from ..vehicle.lockstep_clock import LockstepClock, udp_receive_queue
from ..vehicle.mavlink_backend import MavlinkVehicle
from .base import RuntimeOptionError, TrialRequest, build_options
from .mavlink import fly_mavlink
from .sitl_relay import MavlinkRelay

logger = logging.getLogger(__name__)

SITL_ENV = "PRELAND_SITL_BINARY"
MAX_INSTANCES = 64
STOP_GRACE_S = 3.0


PACKAGED_DEFAULTS = Path(__file__).with_name("data") / "sitl_copter.parm"
# The quad X frame of preland's physics, after the copter defaults (which set SITL's plus frame).
JSON_QUADX_DEFAULTS = Path(__file__).with_name("data") / "sitl_json_quadx.parm"
PHYSICS = ("ardupilot", "preland")  # SitlOptions.physics: ArduPilot's own, or preland's over SITL's JSON
# How long the bridge waits for a servo packet before it stops (wall s). Only the bridge stops: a SITL
# that died or stalled is the trial's SITL-exit and link-lost handling's to judge, much sooner.
BRIDGE_PACKET_TIMEOUT_S = 60.0
COPTER_DEFAULTS_IN_TREE = Path("Tools") / "autotest" / "default_params" / "copter.parm"
# ArduPilot SITL's rangefinder type (AP_RangeFinder::Type::SIM) and downward orientation (ROTATION_PITCH_270).
RNGFND_TYPE_SIM = 100
RNGFND_ORIENT_DOWN = 25
SIM_WIND_T_NO_LIMIT = 1  # SITL's WindLimitType: the same mean wind at every height
# --speedup when none is given (benchmarks/sitl_vs_embedded.py): the companion runs in wall time while SITL
# runs SPEEDUP times faster, so a land mode that renders and reads camera frames processes fewer of them
# per vehicle second as the speedup grows (on 2 cores: 15.5 Hz at 2x as on the embedded simulator, 9.3 Hz
# at 10x), and with dropped values ArduPilot's 2 s precision-landing initialisation then fails; sensors
# without frames (IR-LOCK, GPS) keep their rate at 10x.
SPEEDUP_CAMERA = 2.0
SPEEDUP_NO_CAMERA = 10.0
# On preland's physics in lock-step, a ceiling SITL never reaches (it would sleep above it): the rate is
# what SITL, the physics and the companion together manage (benchmarks/sitl_lockstep.py).
SPEEDUP_LOCKSTEP = 1000.0
GPS_UPDATE_PERIOD_S = 0.5  # vehicle seconds between SIM_GPS_GLITCH updates (the drift moves ~1 cm in that time)
METRES_PER_DEG_LAT = 111_319.49  # WGS-84 equatorial, as ArduPilot's LATLON_TO_M


class SitlError(PrelandError):
    """The SITL binary is missing, not executable, or did not start."""


class SitlExited(PrelandError):
    """The SITL process ended while its trial was flying."""


class PhysicsBridgeFailed(PrelandError):
    """preland's physics (the JSON bridge) failed while its trial was flying."""


def resolve_sitl_binary(path: str | Path | None) -> Path:
    """The SITL binary from `path` or $PRELAND_SITL_BINARY; one clear error when it cannot be used."""
    chosen = path or os.environ.get(SITL_ENV)
    if not chosen:
        raise SitlError(f"no SITL binary: give --sitl PATH or set {SITL_ENV}")
    binary = Path(chosen).expanduser()
    if not binary.is_file():
        raise SitlError(f"SITL binary {binary} not found")
    if not os.access(binary, os.X_OK):
        raise SitlError(f"SITL binary {binary} is not executable")
    return binary


def find_copter_defaults(binary: Path) -> Path | None:
    """ArduPilot's copter.parm for a binary inside an ArduPilot tree (build/sitl/bin/arducopter), else None."""
    for folder in Path(binary).resolve().parents:
        candidate = folder / COPTER_DEFAULTS_IN_TREE
        if candidate.is_file():
            return candidate
    return None


@dataclass(frozen=True)
class SitlOptions:
    """How to run SITL: the binary (None: $PRELAND_SITL_BINARY of the machine a trial runs on, as cluster
    nodes each have their own), its --speedup (None: SPEEDUP_CAMERA for a land mode that reads camera
    frames, else SPEEDUP_NO_CAMERA), extra --defaults files (after the copter defaults), extra parameters,
    a folder for one .tlog per trial (None: no logs), a folder for SITL's own dataflash log of each trial
    (`log_dir`, a .BIN named as the trial's .tlog; None: not kept), a UDP address for the thesis' fault command
    (None: none), the physics: `ardupilot` (SITL's own) or `preland` (preland's quad X over SITL's
    JSON interface), and on preland's physics a gyro error (`gyro_error`, 1/s: the error's standard
    deviation in rad/s per radian of the mission's attitude error, `sim/imu.py`; 0: a true IMU)."""

    binary: Path | None
    speedup: float | None = None
    defaults: tuple[Path, ...] = ()
    extra_params: dict[str, float] = field(default_factory=dict)
    tlog_dir: Path | None = None
    log_dir: Path | None = None
    fault_listen: str | None = None
    physics: str = "ardupilot"
    gyro_error: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.gyro_error) and self.gyro_error >= 0):
            raise RuntimeOptionError(option="gyro_error", runtime="sitl:",
                                     problem=f"must be a number >= 0, got {self.gyro_error:g}")
        if self.gyro_error and self.physics != "preland":
            raise RuntimeOptionError(option="gyro_error", runtime="sitl:",
                                     problem="applies to preland's physics only (physics=preland)")

    def speedup_for(self, *, uses_camera: bool) -> float:
        """The --speedup of a trial whose land mode does (or does not) read camera frames; on preland's
        physics, in lock-step, SPEEDUP_LOCKSTEP whatever the land mode."""
        if self.speedup is not None:
            return self.speedup
        if self.physics == "preland":
            return SPEEDUP_LOCKSTEP
        return SPEEDUP_CAMERA if uses_camera else SPEEDUP_NO_CAMERA

    def defaults_files(self) -> tuple[Path, ...]:
        """copter.parm of the binary's ArduPilot tree (else the packaged copy), preland's frame with
        `physics=preland`, then the user's files (which win)."""
        frame = (JSON_QUADX_DEFAULTS,) if self.physics == "preland" else ()
        return (find_copter_defaults(self.binary) or PACKAGED_DEFAULTS, *frame, *self.defaults)

    def on_this_machine(self) -> "SitlOptions":
        """These options with the binary checked here: the one given, else this machine's
        $PRELAND_SITL_BINARY (SitlError when neither can be used)."""
        return replace(self, binary=resolve_sitl_binary(self.binary))


SPEEDUP_RANGE = (0.1, 1000.0)


_URL_OPTIONS: dict[str, Callable[[str], Any]] = {
    "speedup": float,
    "defaults": lambda text: tuple(Path(part) for part in text.split(",") if part),
    "physics": str,
    "gyro_error": float,
}
"""The query options of a `sitl:` URL and how each is read from its text (ValueError: not a number)."""


@dataclass(frozen=True)
class SitlRuntime:
    """ArduPilot SITL (`sitl:PATH`, `sitl:` for $PRELAND_SITL_BINARY; query `speedup=X`,
    `defaults=A.parm,B.parm`, `physics=ardupilot|preland`, `gyro_error=X` on preland's physics): a fresh
    `arducopter` process per trial, scored from its SIM_STATE."""

    scheme: ClassVar[str] = "sitl"
    name: ClassVar[str] = "sitl"
    source: ClassVar[str] = "sitl"
    simulated_world: ClassVar[bool] = True
    max_workers: ClassVar[int | None] = None
    cluster_resource: ClassVar[str | None] = "sitl"
    options: SitlOptions

    @property
    def url(self) -> str:
        return f"sitl:{self.options.binary or ''}"

    @classmethod
    def from_url(cls, *, target: str, query: dict[str, str], options: dict[str, Any]) -> "SitlRuntime":
        values: dict[str, Any] = {}
        for key, text in query.items():
            read = _URL_OPTIONS.get(key)
            if read is None:
                raise RuntimeOptionError(option=key, runtime="sitl:", takes=tuple(_URL_OPTIONS),
                                         problem="not an option of a sitl: URL")
            try:
                values[key] = read(text)
            except ValueError:
                raise RuntimeOptionError(option=key, runtime="sitl:",
                                         problem=f"must be a number, got {text!r}") from None
        values.update(options)
        if "binary" in values:
            raise RuntimeOptionError(option="binary", runtime="sitl:", problem="the binary is the URL's path "
                                                                               "(sitl:PATH)")
        chosen = build_options(SitlOptions, {"binary": Path(target).expanduser() if target else None, **values},
                               runtime="sitl:")
        if chosen.speedup is not None and not SPEEDUP_RANGE[0] <= chosen.speedup <= SPEEDUP_RANGE[1]:
            raise RuntimeOptionError(option="speedup", runtime="sitl:",
                                     problem=f"must be within 0.1..1000, got {chosen.speedup:g}")
        if chosen.physics not in PHYSICS:
            raise RuntimeOptionError(option="physics", runtime="sitl:",
                                     problem=f"must be one of {', '.join(PHYSICS)} on the sitl: runtime, "
                                             f"got {chosen.physics!r}")
        return cls(options=replace(chosen, defaults=tuple(Path(p).resolve() for p in chosen.defaults),
                                   tlog_dir=Path(chosen.tlog_dir).resolve() if chosen.tlog_dir else None,
                                   log_dir=Path(chosen.log_dir).resolve() if chosen.log_dir else None))

    def fly(self, request: TrialRequest, *, tlog_name: str | None = None) -> TrialOutcome:
        return run_sitl_trial(request, options=self.options.on_this_machine(), tlog_name=tlog_name)

    def on_this_machine(self) -> "SitlRuntime":
        return replace(self, options=self.options.on_this_machine())


def sim_params(mission: MissionSpec, seed: int) -> dict[str, float]:
    """The scenario's wind as ArduPilot SITL parameters: SIM_WIND_SPD (m/s), SIM_WIND_DIR (deg, from),
    SIM_WIND_T and SIM_WIND_TURB (m/s).

    SIM_WIND_T 1 (no height profile): SITL's default (0, square law) scales the mean wind by
    sqrt(height / SIM_WIND_T_ALT) below SIM_WIND_T_ALT (60 m), so at the thesis' 10 m it would blow at
    41 % of the scenario's speed and near the ground at about 13 %; the embedded model's steady wind is
    the same at every height, and so is the scenario's. A scenario without a direction gets the one the
    embedded simulator draws for the same seed (the first draw of the seed's `wind` stream).

    SITL's turbulence is a horizontal gust whose standard deviation is SIM_WIND_TURB (its IIR filter,
    coefficient 0.98, is scaled to match), at any height; preland passes the embedded model's horizontal
    gust standard deviation (Dryden sigma_u) at 10 m, the thesis' flight height. The two spectra differ:
    SITL's gust turns to a random direction at every physics step, so its push mostly averages out.
    """
    from ..sim.environment import WindModel, dryden_scales

    wind = mission.environment.wind
    direction = WindModel(spec=wind, rng=child_rng(seed, "wind")).direction_from_deg  # the seed's draw
    _, _, sigma_u_m_s, _ = dryden_scales(altitude_m=10.0, w20_m_s=wind.turbulence_w20_m_s)
    return {"SIM_WIND_SPD": wind.speed_m_s, "SIM_WIND_DIR": direction, "SIM_WIND_T": SIM_WIND_T_NO_LIMIT,
            "SIM_WIND_TURB": round(sigma_u_m_s, 3)}


def rangefinder_params(mission: MissionSpec) -> dict[str, float]:
    """SITL's simulated downward rangefinder (the thesis' drone had one), over the range the embedded
    simulator's rangefinder uses; none when the mission's vehicle has no rangefinder."""
    from ..sim.params import ARDUCOPTER_PARAMS

    if not mission.environment.navigation.rangefinder_present:
        return {}
    ranged = {name: float(mission.params.get(name, ARDUCOPTER_PARAMS[name].default))
              for name in ARDUCOPTER_PARAMS if name.startswith("RNGFND1_") and name != "RNGFND1_TYPE"}
    return {"RNGFND1_TYPE": RNGFND_TYPE_SIM, "RNGFND1_ORIENT": RNGFND_ORIENT_DOWN, **ranged}


def embedded_arming_s(environment: EnvironmentSpec) -> float:
    """When the embedded simulator arms, in its seconds from the start: when its position fix arrives (its
    mission arms at the next poll, 0.1 s later). SITL's world is aligned to it: the GPS drift at SITL's arming,
    the air when SITL's motors first turn."""
    return environment.navigation.gps_fix_delay_s


def embedded_motors_start_s(environment: EnvironmentSpec) -> float:
    """When the embedded simulator's motors first turn as `copter-4.6` flies, in its seconds from the start:
    ArduCopter's arming delay after its arming. SITL's air starts at this point of the seed's gust path."""
    return embedded_arming_s(environment) + ARMING_DELAY_S


class GpsErrorDriver:
    """The trial's GPS position error on SITL: the drift path the embedded simulator's estimate has for the same
    seed (`GpsPositionError` from the seed's `gps` stream, stepped at the mission's `physics_rate_hz` as the
    embedded simulator steps it), written into SITL's GPS glitch offsets, SIM_GPS_GLITCH_X/Y (degrees of
    latitude/longitude, added to every GPS fix). Only the drift is written: SITL's EKF has its own fast noise.

    The two paths are aligned at arming, since each runtime arms at its own time (the embedded simulator when
    its fix arrives, `gps_fix_delay_s`; SITL when its EKF is ready, some seconds later): until SITL arms it gets
    the drift of the embedded arming time, then the drift moves on with SITL's vehicle time, written every
    GPS_UPDATE_PERIOD_S vehicle seconds."""

    def __init__(self, *, environment: EnvironmentSpec, seed: int, latitude_deg: float) -> None:
        spec = environment.navigation
        self._error = GpsPositionError.for_seed(spec, seed)
        self._error.step(0.0)  # the embedded simulator's first estimate, before its first step
        self._dt_s = 1.0 / environment.physics_rate_hz
        self._steps = 0
        self._armed_path_s = embedded_arming_s(environment)
        self.path_s = 0.0  # the embedded simulator's time the drift has reached (s)
        self._advance_to(self._armed_path_s)
        self._metres_per_deg_lon = METRES_PER_DEG_LAT * max(math.cos(math.radians(latitude_deg)), 1e-6)
        self.updates = 0  # writes after arming
        self.armed_at_s: float | None = None  # SITL's vehicle time the drift started moving from (s)

    @property
    def error_ned_m(self) -> tuple[float, float]:
        return self._error.drift_ne_m

    def params(self) -> dict[str, float]:
        """The current error as SITL parameters."""
        north_m, east_m = self._error.drift_ne_m
        return {"SIM_GPS_GLITCH_X": north_m / METRES_PER_DEG_LAT, "SIM_GPS_GLITCH_Y": east_m / self._metres_per_deg_lon}

    def _advance_to(self, path_s: float) -> None:
        target = round(path_s / self._dt_s)
        while self._steps < target:
            self._error.step(self._dt_s)
            self._steps += 1
        self.path_s = self._steps * self._dt_s

    def at(self, since_armed_s: float) -> dict[str, float]:
        """The error `since_armed_s` vehicle seconds after arming, as SITL parameters (moves only forwards)."""
        self._advance_to(self._armed_path_s + since_armed_s)
        return self.params()

    async def run(self, vehicle: MavlinkVehicle) -> None:
        """Follow the trial in vehicle time: at every multiple of GPS_UPDATE_PERIOD_S, look whether the vehicle
        has armed; from the first tick that finds it armed on, write the error of the time since that tick. The
        ticks are in vehicle time, so in lock-step the error at a vehicle time does not depend on the machine."""
        while not vehicle.connected:
            await asyncio.sleep(0.05)
        clock = vehicle.clock
        period_s = GPS_UPDATE_PERIOD_S
        while True:
            now_s = clock.now_s()
            tick_s = (math.floor(now_s / period_s + 1e-9) + 1) * period_s
            await clock.sleep(tick_s - now_s)
            if self.armed_at_s is None:
                if not (await vehicle.telemetry()).armed:
                    continue
                self.armed_at_s = tick_s
            self.updates += 1
            for name, value in self.at(tick_s - self.armed_at_s).items():
                await vehicle.set_param(name, value)


@functools.lru_cache(maxsize=8)
def _serial0_flag(binary: str, modified_ns: int) -> str:
    """The binary's flag for its first serial port: `--serial0` (ArduPilot 4.5 and later) or `--uartA` (4.4 and
    earlier, such as a 2020 ArduCopter), read from its --help (`modified_ns` keys the cache)."""
    try:
        listed = subprocess.run([binary, "--help"], capture_output=True, text=True, errors="replace",
                                timeout=30, check=False)
    except (OSError, subprocess.TimeoutExpired) as error:
        raise SitlError(f"{binary} --help: {error}") from None
    usage = listed.stdout + listed.stderr
    return "--uartA" if "--uartA" in usage and "--serial0" not in usage else "--serial0"


def _hold_udp_port(port: int) -> socket.socket | None:
    """Bind 127.0.0.1:`port` (0: a free one the system picks; no SO_REUSEADDR, so nothing can share it) and
    return the socket, or None when the port is taken (the companion's MAVLink has not let it go)."""
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sink.bind(("127.0.0.1", port))
    except OSError:
        sink.close()
        return None
    return sink


def _die_with_parent() -> None:
    os.setsid()  # a process group of its own, so the whole group can be stopped
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except OSError:
        pass


class SitlInstance:
    """One running SITL process (use `async with`), with its JSON bridge when the physics is preland's."""

    def __init__(self, *, options: SitlOptions, params: dict[str, float], home=DEFAULT_HOME,
                 heading_deg: float = 0.0, air: AirAtVehicle | None = None,
                 gyro_error: GyroError | None = None) -> None:
        self.options = options
        self.air = air  # preland's physics only: the air it flies in (None: still air)
        self.gyro_error = gyro_error  # preland's physics only: the IMU's error (None: a true IMU)
        self.params = params
        self.home = home
        self.heading_deg = heading_deg
        self.instance: int | None = None
        # SITL sends to the companion's port from its start, before the companion binds it: held meanwhile, the
        # port cannot be handed to another program (another trial's companion), which would read this vehicle.
        self._port_hold = _hold_udp_port(0)
        if self._port_hold is None:
            raise SitlError("no free UDP port on 127.0.0.1 for the companion")
        self.port = self._port_hold.getsockname()[1]
        self.process: subprocess.Popen | None = None
        self.bridge: JsonBridge | None = None
        self.relay: MavlinkRelay | None = None  # on preland's physics: between SITL and MAVSDK (sitl_relay)
        self.log_path: Path | None = None  # where SITL's dataflash log is kept when the trial ends (None: not)
        self._lock_file = None
        self._folder: tempfile.TemporaryDirectory | None = None

    @property
    def url(self) -> str:
        return f"udpin://127.0.0.1:{self.port}"

    def _claim_instance(self) -> int:
        for number in range(MAX_INSTANCES):
            handle = open(Path(tempfile.gettempdir()) / f"preland-sitl-{number}.lock", "w")
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                handle.close()
                continue
            self._lock_file = handle
            return number
        raise SitlError(f"no free SITL instance number (all {MAX_INSTANCES} in use)")

    def command(self, folder: Path) -> list[str]:
        params_file = folder / "preland.parm"
        params_file.write_text("".join(f"{name} {value!r}\n" for name, value in sorted(self.params.items())))
        defaults = ",".join(str(p) for p in (*self.options.defaults_files(), params_file))
        home = f"{self.home.latitude_deg},{self.home.longitude_deg},{self.home.altitude_amsl_m},{self.heading_deg:g}"
        if self.bridge is not None:
            # SITL sends to 9002 + 10 x instance unless told: the bridge's own port keeps trials apart.
            model = ["--model", "JSON:127.0.0.1", "--sim-port-out", str(self.bridge.address[1])]
        else:
            model = ["--model", "+"]
        binary = str(self.options.binary)
        serial0 = _serial0_flag(binary, self.options.binary.stat().st_mtime_ns)
        return [binary, *model, "--speedup", f"{self.options.speedup:g}",
                "--defaults", defaults, "-I", str(self.instance), f"--home={home}",
                serial0, f"udpclient:127.0.0.1:{self.relay.sitl_port if self.relay is not None else self.port}"]

    def _start_bridge(self) -> None:
        # Bound (port 0: the system picks a free one) and serving before SITL starts, so no other trial
        # can take the port and SITL's first servo packet is answered. The model starts facing the
        # mission's heading, as SITL's own physics does from --home.
        model = QuadXMultirotor(frame=QuadXFrame(), yaw_rad=math.radians(self.heading_deg))
        try:
            self.bridge = JsonBridge(model=model, port=0, packet_timeout_s=BRIDGE_PACKET_TIMEOUT_S,
                                     air=self.air, gyro_error=self.gyro_error).start()
        except OSError as error:
            raise SitlError(f"cannot open the JSON physics port: {error.strerror or error}") from None
        try:
            self.relay = MavlinkRelay(mavsdk_port=self.port).start()
        except OSError as error:
            raise SitlError(f"cannot open the MAVLink relay's ports: {error.strerror or error}") from None

    async def __aenter__(self) -> "SitlInstance":
        self.instance = self._claim_instance()
        self._folder = tempfile.TemporaryDirectory(prefix=f"preland-sitl-{self.instance}-")
        folder = Path(self._folder.name)
        try:
            if self.options.physics == "preland":
                self._start_bridge()
            self.process = subprocess.Popen(self.command(folder), cwd=folder, stdin=subprocess.DEVNULL,
                                            stdout=subprocess.DEVNULL, stderr=open(folder / "stderr.txt", "wb"),
                                            preexec_fn=_die_with_parent)
        except OSError as error:
            self._release()
            raise SitlError(f"cannot start {self.options.binary}: {error.strerror or error}") from None
        except BaseException:
            self._release()
            raise
        try:
            await asyncio.sleep(0.2)
        except BaseException:  # interrupted while starting: nothing of the trial is left running
            self.stop()
            raise
        if self.process.poll() is not None:
            message = self._ended_before_answering()
            self._release()
            raise SitlError(message)
        return self

    def hand_port_to_companion(self) -> None:
        """Let the companion's port go, for the companion to bind it at once (`MavlinkVehicle(before_link=...)`)."""
        if self._port_hold is not None:
            self._port_hold.close()
            self._port_hold = None

    def _ended_before_answering(self) -> str:
        # Said the same whether the start check or the watch finds it: how soon a process that cannot start
        # exits depends on the machine's load.
        return f"{self.options.binary} {self.exit_description()} before its vehicle answered"

    def _stderr_tail(self) -> str:
        """The last line SITL wrote to its stderr ("" without one)."""
        if self._folder is None:
            return ""
        try:
            lines = Path(self._folder.name, "stderr.txt").read_text(errors="replace").strip().splitlines()
        except OSError:
            return ""
        return lines[-1].strip() if lines else ""

    async def __aexit__(self, *exc: object) -> None:
        self.stop()

    def exit_description(self) -> str | None:
        """None while SITL runs; else how it ended ("killed by SIGKILL", "exited with code 1")."""
        if self.process is None or self.process.poll() is None:
            return None
        code = self.process.returncode
        if code < 0:
            try:
                return f"killed by {signal.Signals(-code).name}"
            except ValueError:
                return f"killed by signal {-code}"
        tail = self._stderr_tail()
        return f"exited with code {code}" + (f" (its last line on stderr: {tail})" if tail else "")

    async def watch(self, vehicle: MavlinkVehicle) -> None:
        """Raise SitlExited as soon as the SITL process ends (its trial cannot go on; SitlError before the
        vehicle has answered, as a SITL that cannot start), and
        PhysicsBridgeFailed when the JSON bridge fails other than by its packet timeout (a bridge that
        timed out only stopped: SITL's exit or the lost link then ends the trial)."""
        while True:
            ended = self.exit_description()
            if ended is not None:
                if not vehicle.connected:
                    raise SitlError(self._ended_before_answering())
                raise SitlExited(f"{self.options.binary.name} (SITL instance {self.instance}) {ended} "
                                 "during the trial")
            failure = self.bridge.error if self.bridge is not None else None
            if failure is not None and not isinstance(failure, JsonBridgeTimeout):
                raise PhysicsBridgeFailed(f"preland's physics for SITL instance {self.instance} failed: "
                                          f"{type(failure).__name__}: {failure}")
            await asyncio.sleep(0.1)

    def stop(self) -> None:
        # SITL (or the relay) sends to the companion's port until it has stopped, and the companion has let the
        # port go: held meanwhile, it cannot be handed to another trial, whose companion would read this
        # vehicle's messages as its own (every vehicle is system 1).
        sink = _hold_udp_port(self.port)
        try:
            self._stop_process()
        finally:
            if sink is not None:
                sink.close()

    def _stop_process(self) -> None:
        process = self.process
        if process is not None and process.poll() is None:
            if self.bridge is not None:
                # SITL reads its SIGTERM in its main loop, which on preland's physics waits for the physics'
                # answer: a physics the companion's clock still holds would keep it there for the whole grace.
                self.bridge.gate.hold_at(None)
            try:
                os.killpg(process.pid, signal.SIGTERM)
                # A stopped SITL (SIGSTOP, a debugger) takes its SIGTERM only once continued, as `kill` and
                # systemd continue one: else the grace would pass with nothing to wait for.
                os.killpg(process.pid, signal.SIGCONT)
                process.wait(timeout=STOP_GRACE_S)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                try:
                    os.killpg(process.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                process.wait(timeout=STOP_GRACE_S)
        self._release()

    def _release(self) -> None:
        self.hand_port_to_companion()
        if self.bridge is not None:
            self.bridge.stop()  # joins its thread (bounded); safe to call again
        if self.relay is not None:
            self.relay.stop()
        if self._lock_file is not None:
            self._lock_file.close()
            self._lock_file = None
        if self._folder is not None:
            self._keep_log(Path(self._folder.name))
            self._folder.cleanup()
            self._folder = None


    def _keep_log(self, folder: Path) -> None:
        """Copy SITL's newest dataflash log (logs/*.BIN in its working folder) to `log_path`, if asked."""
        logs = sorted((folder / "logs").glob("*.BIN"))
        if self.log_path is None or not logs:
            return
        try:
            self.log_path.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(logs[-1], self.log_path)
        except OSError as error:  # the trial's outcome stands without its log
            logger.warning("cannot keep SITL's log %s: %s", self.log_path, error.strerror or error)


class BridgeTruth:
    """Where the simulated sensors see the world from on preland's physics: the JSON bridge's newest state
    (NED m from the model's origin, which is SITL's home and the trial's start; attitude in rad), exact
    at a reading's time since the physics holds there for it."""

    def __init__(self, bridge: JsonBridge) -> None:
        self.bridge = bridge

    def pose(self) -> CameraPose:
        state = self.bridge.latest_state
        north_m, east_m, down_m = state.position_ned_m
        return CameraPose(north_m, east_m, down_m, *state.euler_rad)

    def time_s(self) -> float:
        """The physics time (vehicle s) of that state."""
        return self.bridge.latest_state.time_s

    def ned(self) -> tuple[float, float, float]:
        """The true (north_m, east_m, altitude_m) from the start, as the physics has it: the trajectory and
        the score read it instead of SIM_STATE, whose 1e-7 degree integers round a position to about 1 cm."""
        north_m, east_m, down_m = self.bridge.latest_state.position_ned_m
        return north_m, east_m, -down_m


async def fly_sitl(request: TrialRequest, *, options: SitlOptions, tlog_name: str | None = None) -> TrialOutcome:
    """One trial on a fresh SITL process, scored from SITL's ground truth (SIM_STATE; on preland's physics,
    the physics' own state). SITL ending during the trial ends it with outcome `error` naming how SITL ended."""
    mission = request.resolved_mission()
    options = replace(options, speedup=options.speedup_for(uses_camera=mission.land.strategy().uses_marker))
    gps = GpsErrorDriver(environment=mission.environment, seed=request.seed, latitude_deg=DEFAULT_HOME.latitude_deg)
    on_preland_physics = options.physics == "preland"
    wind = {} if on_preland_physics else sim_params(mission, request.seed)
    params = {"PLND_ENABLED": 1, "PLND_TYPE": 1, **rangefinder_params(mission), **wind,
              **gps.params(), **mission.params, **options.extra_params}
    air = AirAtVehicle(environment=mission.environment, seed=request.seed,
                       lead_on_ground_s=embedded_motors_start_s(mission.environment)) if on_preland_physics else None
    gyro_error = GyroError.for_mission(mission.environment.navigation, seed=request.seed,
                                       per_attitude_error=options.gyro_error) if on_preland_physics else None
    async with SitlInstance(options=options, params=params, heading_deg=mission.initial_yaw_deg,
                            air=air, gyro_error=gyro_error) as sitl:
        tlog_path = None
        name = tlog_name or f"{mission.name}_seed{request.seed}.tlog"
        if options.tlog_dir is not None:
            tlog_path = str(Path(options.tlog_dir) / name)
        if options.log_dir is not None:
            sitl.log_path = Path(options.log_dir) / Path(name).with_suffix(".BIN").name
        lockstep = LockstepClock(gate=sitl.bridge.gate, unread=functools.partial(udp_receive_queue, sitl.port),
                                 relay=sitl.relay) if sitl.bridge is not None else None
        # On preland's physics the bridge's state is the truth: no SIM_STATE asked for (the 2020 ArduCopter
        # sends none, only SIMSTATE, which has no altitude).
        outcome = await fly_mavlink(request, url=sitl.url, truth=not on_preland_physics, tlog_path=tlog_path,
                                    fault_listen=options.fault_listen,
                                    companions=(sitl.watch, gps.run),
                                    lockstep=lockstep, before_link=sitl.hand_port_to_companion,
                                    sensor_truth=BridgeTruth(sitl.bridge) if sitl.bridge is not None else None)
    outcome.details["runtime"] = "sitl"
    outcome.details["sitl_instance"] = sitl.instance
    outcome.details["sitl_speedup"] = options.speedup
    outcome.details["sitl_physics"] = options.physics
    if air is not None:
        outcome.details["wind_from_deg"] = round(air.wind.direction_from_deg, 1)
    else:
        outcome.details["wind_from_deg"] = round(wind["SIM_WIND_DIR"], 1)
    if sitl.bridge is not None:
        counters = sitl.bridge.counters
        outcome.details["sitl_json_packets"] = counters.packets
        outcome.details["lockstep_holds"] = counters.holds
        outcome.details["lockstep_held_wall_s"] = round(counters.held_wall_s, 2)
        outcome.details["bridge_physics_wall_s"] = round(counters.physics_wall_s, 2)
        outcome.details["bridge_waiting_wall_s"] = round(counters.waiting_wall_s, 2)
        outcome.details["bridge_vehicle_s"] = round(sitl.bridge.latest_state.time_s, 2)  # from SITL's boot
    outcome.details["sitl_gps_error_cm"] = [round(v * 100.0, 1) for v in gps.error_ned_m]
    outcome.details["sitl_gps_armed_s"] = gps.armed_at_s
    return outcome


def run_sitl_trial(request: TrialRequest, *, options: SitlOptions, tlog_name: str | None = None) -> TrialOutcome:
    return asyncio.run(fly_sitl(request, options=options, tlog_name=tlog_name))
