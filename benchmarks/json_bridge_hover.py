"""ArduCopter SITL flown on preland's motor-level quad X (JSON physics) beside ArduPilot's own `--model quad`.

For each physics: start `arducopter` in a temporary folder (`-w`, copter.parm as defaults), wait for a
position estimate, GUIDED, arm, take off to 5 m, hold 10 s, step the GUIDED altitude target up to 10 m and
back down to 5 m (12 vehicle s each), LAND; print whether it armed, took off and landed, the hover throttle
(MOT_THST_HOVER as learned, and the mean motor output (PWM - 1000) / 1000 in the hold), the largest
altitude error in the hold, each step's response (10-90 % rise time, overshoot, the time it settles within
0.1 m, its fastest vertical speed) and vehicle seconds per wall second. The JSON
physics is served by `JsonBridge` from a thread of this process. Every process started is stopped on
every path.

Then the GPS-only landing distribution on both physics: the thesis' Table 3 scenario without a precision
sensor (`T3 none` of fault_scenarios_table.py: land mode normal, its weather, the same seeds 0..N-1 on both,
flown through preland's SITL runtime: `physics=preland` in lock-step, `physics=ardupilot` at preland's
speed-up for it), its landing errors' mean, standard deviation, quartiles and maximum side by side, and two
two-sample tests of "the same distribution" (Mann-Whitney U and Kolmogorov-Smirnov, two-sided).

Usage: python benchmarks/json_bridge_hover.py [--binary PATH] [--speedup N] [--landings N] [--workers N]
       (binary: $PRELAND_SITL_BINARY; copter.parm from the binary's ArduPilot tree, else preland's copy;
       --landings 0 skips the landings)
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pymavlink import mavutil  # noqa: E402
from scipy import stats  # noqa: E402
from sitl_vs_embedded import Trial, fly_one  # noqa: E402

from preland_app.runtime.sitl import JSON_QUADX_DEFAULTS, PACKAGED_DEFAULTS, find_copter_defaults  # noqa: E402
from preland_app.runtime.sitl_parm import read_parm_file  # noqa: E402
from preland_app.sim.json_bridge import JsonBridge  # noqa: E402
from preland_app.sim.multirotor import QuadXFrame, QuadXMultirotor  # noqa: E402

HOME = "-35.363261,149.165230,584,353"  # ArduPilot's CMAC test site, SITL's usual home
MAVLINK_PORT = 14571
TAKEOFF_ALT_M = 5.0
HOLD_S = 10.0
STEP_ALT_M = 10.0  # the climb step's target; the descent step returns to TAKEOFF_ALT_M
STEP_S = 12.0  # vehicle seconds each step is watched
SETTLED_M = 0.1
GPS_ONLY_LABEL = "T3 none"  # fault_scenarios_table.py's Table 3 scenario flown with land mode normal
LANDING_RUNTIMES = (("sitl-preland", "JSON (preland quad X)"), ("sitl", "built-in --model + (ArduPilot's)"))
POSITION_ONLY_MASK = 0b0000_1111_1111_1000  # SET_POSITION_TARGET_*: position only, no yaw
# Parameters the JSON frame adds to copter.parm: the SITL runtime's own file for preland's physics (the quad X
# frame, SIM_RATE_HZ, ARMING_CHECK), so the frame flown here is the one trials fly.
JSON_EXTRA_PARAMS: dict[str, float] = read_parm_file(JSON_QUADX_DEFAULTS)


@dataclass
class FlightReport:
    physics: str
    armed: bool = False
    took_off: bool = False
    landed: bool = False
    hover_learned: float | None = None
    hover_motor_output: float | None = None
    hover_model_command: float | None = None
    motor_spread: float | None = None
    max_alt_error_m: float | None = None
    vehicle_s_per_wall_s: float | None = None
    steps: dict[str, "StepResponse"] = field(default_factory=dict)
    failure: str = ""
    statustexts: list[str] = field(default_factory=list)


@dataclass
class StepResponse:
    """An altitude step's response: from `start_m` to `target_m` (relative altitude, m), seen over STEP_S."""

    start_m: float
    target_m: float
    trace: list[tuple[float, float]]  # (vehicle s since the step, relative altitude m)

    def _crossing_s(self, share: float) -> float | None:
        level = self.start_m + share * (self.target_m - self.start_m)
        up = self.target_m > self.start_m
        return next((t for t, alt in self.trace if (alt >= level if up else alt <= level)), None)

    @property
    def rise_s(self) -> float | None:
        """10 to 90 % of the step (vehicle s)."""
        t10, t90 = self._crossing_s(0.1), self._crossing_s(0.9)
        return None if t10 is None or t90 is None else t90 - t10

    @property
    def overshoot_m(self) -> float | None:
        if not self.trace:
            return None
        sign = 1.0 if self.target_m > self.start_m else -1.0
        return max(0.0, max(sign * (alt - self.target_m) for _, alt in self.trace))

    @property
    def settled_s(self) -> float | None:
        """From the step until the altitude stays within SETTLED_M of the target (vehicle s); None if it does
        not within the watch."""
        outside = [t for t, alt in self.trace if abs(alt - self.target_m) > SETTLED_M]
        if not self.trace or (outside and outside[-1] >= self.trace[-1][0]):
            return None
        return outside[-1] if outside else 0.0

    @property
    def fastest_m_s(self) -> float | None:
        """The fastest vertical speed over 5 samples (GLOBAL_POSITION_INT at about 10 Hz) at least 0.3 vehicle s
        apart (m/s)."""
        window = [(self.trace[i], self.trace[i + 5]) for i in range(len(self.trace) - 5)]
        rates = [abs(a1 - a0) / (t1 - t0) for (t0, a0), (t1, a1) in window if t1 - t0 >= 0.3]
        return max(rates) if rates else None


class Link:
    """A MAVLink connection that keeps the latest message of each type and every STATUSTEXT."""

    def __init__(self, port: int, report: FlightReport) -> None:
        self.mav = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=250)
        self.report = report
        self.latest: dict[str, object] = {}

    def pump(self, wall_timeout_s: float, until=None) -> bool:
        """Read messages until `until(self)` holds (True) or `wall_timeout_s` passes (False)."""
        deadline = time.monotonic() + wall_timeout_s
        while time.monotonic() < deadline:
            msg = self.mav.recv_match(blocking=True, timeout=0.2)
            if msg is not None:
                kind = msg.get_type()
                self.latest[kind] = msg
                if kind == "STATUSTEXT":
                    self.report.statustexts.append(msg.text)
            if until is not None and until(self):
                return True
        return until is None

    def boot_s(self) -> float:
        msg = self.latest.get("GLOBAL_POSITION_INT")
        return msg.time_boot_ms / 1000.0 if msg is not None else 0.0

    def rel_alt_m(self) -> float:
        msg = self.latest.get("GLOBAL_POSITION_INT")
        return msg.relative_alt / 1000.0 if msg is not None else 0.0

    def armed(self) -> bool:
        hb = self.latest.get("HEARTBEAT")
        return hb is not None and bool(hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)

    def param(self, name: str, wall_timeout_s: float = 10.0) -> float | None:
        self.latest.pop("PARAM_VALUE", None)
        self.mav.mav.param_request_read_send(self.mav.target_system, self.mav.target_component, name.encode(), -1)
        ok = self.pump(wall_timeout_s, lambda s: "PARAM_VALUE" in s.latest and s.latest["PARAM_VALUE"].param_id == name)
        return float(self.latest["PARAM_VALUE"].param_value) if ok else None


def copter_parm(binary: str) -> Path:
    """ArduPilot's copter.parm of the binary's tree, else the copy preland packages (as the SITL runtime)."""
    return find_copter_defaults(Path(binary)) or PACKAGED_DEFAULTS


def write_defaults(folder: Path, extra: dict[str, float], *, binary: str) -> Path:
    path = folder / "defaults.parm"
    text = copter_parm(binary).read_text() + "".join(f"\n{k} {v}" for k, v in extra.items()) + "\n"
    path.write_text(text)
    return path


def fly(link: Link, report: FlightReport, speedup: float, bridge: JsonBridge | None) -> None:
    mav = link.mav
    if mav.wait_heartbeat(timeout=60) is None:
        report.failure = "no heartbeat"
        return
    mav.mav.request_data_stream_send(mav.target_system, mav.target_component,
                                     mavutil.mavlink.MAV_DATA_STREAM_ALL, 10, 1)
    wall = lambda vehicle_s: vehicle_s / speedup + 30.0  # noqa: E731  a bounded wall wait for a vehicle time

    def has_position(s: Link) -> bool:
        ekf = s.latest.get("EKF_STATUS_REPORT")
        gps = s.latest.get("GPS_RAW_INT")
        wanted = mavutil.mavlink.EKF_POS_HORIZ_ABS | mavutil.mavlink.EKF_PRED_POS_HORIZ_ABS
        return ekf is not None and gps is not None and gps.fix_type >= 3 and (ekf.flags & wanted) == wanted
    if not link.pump(wall(120), has_position):
        report.failure = "no position estimate"
        return
    started_wall, started_vehicle = time.monotonic(), link.boot_s()

    mav.set_mode("GUIDED")
    deadline = time.monotonic() + wall(90)
    while not link.armed() and time.monotonic() < deadline:
        mav.arducopter_arm()
        link.pump(3.0, Link.armed)
    report.armed = link.armed()
    if not report.armed:
        report.failure = "did not arm"
        return
    mav.mav.command_long_send(mav.target_system, mav.target_component, mavutil.mavlink.MAV_CMD_NAV_TAKEOFF,
                              0, 0, 0, 0, 0, 0, 0, TAKEOFF_ALT_M)
    report.took_off = link.pump(wall(40), lambda s: s.rel_alt_m() >= TAKEOFF_ALT_M - 0.25)
    if not report.took_off:
        report.failure = f"did not reach {TAKEOFF_ALT_M - 0.25} m (at {link.rel_alt_m():.2f} m)"
        return
    settle_until = link.boot_s() + 3.0  # let the climb settle for 3 vehicle s
    link.pump(wall(3), lambda s: s.boot_s() >= settle_until)
    hold_start = link.boot_s()
    errors, outputs, commands, spreads = [], [], [], []
    deadline = time.monotonic() + wall(HOLD_S)
    while link.boot_s() - hold_start < HOLD_S and time.monotonic() < deadline:
        msg = mav.recv_match(blocking=True, timeout=0.2)
        if msg is None:
            continue
        link.latest[msg.get_type()] = msg
        if msg.get_type() == "GLOBAL_POSITION_INT":
            errors.append(abs(msg.relative_alt / 1000.0 - TAKEOFF_ALT_M))
            if bridge is not None:
                commands.append(sum(bridge.latest_state.motor_commands) / 4)
        elif msg.get_type() == "SERVO_OUTPUT_RAW":
            pwm = (msg.servo1_raw, msg.servo2_raw, msg.servo3_raw, msg.servo4_raw)
            outputs.append(sum((p - 1000) / 1000.0 for p in pwm) / 4)
            spreads.append((max(pwm) - min(pwm)) / 1000.0)
        elif msg.get_type() == "STATUSTEXT":
            report.statustexts.append(msg.text)
    report.max_alt_error_m = max(errors) if errors else None
    report.hover_motor_output = sum(outputs) / len(outputs) if outputs else None
    report.motor_spread = sum(spreads) / len(spreads) if spreads else None
    report.hover_model_command = sum(commands) / len(commands) if commands else None
    report.hover_learned = link.param("MOT_THST_HOVER")
    for name, target_m in (("climb", STEP_ALT_M), ("descent", TAKEOFF_ALT_M)):
        report.steps[name] = altitude_step(link, target_m, wall)
    mav.set_mode("LAND")
    report.landed = link.pump(wall(60), lambda s: not s.armed() and s.rel_alt_m() < 0.5)
    if not report.landed:
        report.failure = f"did not land and disarm (at {link.rel_alt_m():.2f} m, armed {link.armed()})"
    wall_s = time.monotonic() - started_wall
    report.vehicle_s_per_wall_s = (link.boot_s() - started_vehicle) / wall_s if wall_s > 0 else None


def altitude_step(link: Link, target_m: float, wall) -> StepResponse:
    """Send a GUIDED position target at the vehicle's latitude and longitude and `target_m` above home, and
    record the relative altitude for STEP_S vehicle seconds."""
    mav = link.mav
    here = link.latest["GLOBAL_POSITION_INT"]
    step = StepResponse(start_m=link.rel_alt_m(), target_m=target_m, trace=[])
    started_s = link.boot_s()
    mav.mav.set_position_target_global_int_send(
        0, mav.target_system, mav.target_component, mavutil.mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        POSITION_ONLY_MASK, here.lat, here.lon, target_m, 0, 0, 0, 0, 0, 0, 0, 0)
    last = [here]

    def record(s: Link) -> bool:  # each new GLOBAL_POSITION_INT: one sample, until STEP_S have passed
        msg = s.latest["GLOBAL_POSITION_INT"]
        if msg is last[0]:
            return False
        last[0] = msg
        elapsed_s = msg.time_boot_ms / 1000.0 - started_s
        if elapsed_s <= STEP_S:
            step.trace.append((elapsed_s, msg.relative_alt / 1000.0))
        return elapsed_s > STEP_S

    link.pump(wall(STEP_S), record)
    return step


def run_one(binary: str, physics: str, speedup: float) -> FlightReport:
    report = FlightReport(physics=physics)
    bridge: JsonBridge | None = None
    process: subprocess.Popen | None = None
    with tempfile.TemporaryDirectory(prefix=f"preland-{physics}-") as tmp:
        folder = Path(tmp)
        try:
            if physics == "json":
                bridge = JsonBridge(model=QuadXMultirotor(frame=QuadXFrame()), packet_timeout_s=60.0).start()
                model = ["--model", "JSON:127.0.0.1"]
                defaults = write_defaults(folder, JSON_EXTRA_PARAMS, binary=binary)
            else:
                model = ["--model", "quad"]
                defaults = write_defaults(folder, {}, binary=binary)
            command = [binary, *model, "-w", "--defaults", str(defaults), "--speedup", str(speedup), "-I", "0",
                       "--home", HOME, "--serial0", f"udpclient:127.0.0.1:{MAVLINK_PORT}"]
            log = open(folder / "sitl.log", "wb")
            process = subprocess.Popen(command, cwd=folder, stdout=log, stderr=subprocess.STDOUT,
                                       stdin=subprocess.DEVNULL, start_new_session=True)
            link = Link(MAVLINK_PORT, report)
            try:
                fly(link, report, speedup, bridge)
            finally:
                link.mav.close()
            if bridge is not None and bridge.error is not None:
                report.failure += f" bridge: {bridge.error}"
        except Exception as error:  # reported, not raised: the other physics still flies
            report.failure += f" {type(error).__name__}: {error}"
        finally:
            if process is not None:
                stop_process_group(process)
            if bridge is not None:
                bridge.stop()
            if report.failure and (folder / "sitl.log").exists():
                tail = (folder / "sitl.log").read_text(errors="replace").splitlines()[-15:]
                report.statustexts.extend(f"[sitl stdout] {line}" for line in tail)
    return report


def stop_process_group(process: subprocess.Popen) -> None:
    """SIGTERM the process group, SIGKILL it after 5 s, and check nothing of it is left."""
    for sig, wait_s in ((signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(process.pid, sig)
        except ProcessLookupError:
            break
        try:
            process.wait(wait_s)
            break
        except subprocess.TimeoutExpired:
            continue
    left = subprocess.run(["pgrep", "-g", str(process.pid)], capture_output=True, text=True).stdout.split()
    if left:
        raise RuntimeError(f"processes left in group {process.pid}: {left}")


def fmt(value: float | None, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def landings(binary: str, seeds: int, workers: int) -> None:
    """The GPS-only landing distribution on both physics, side by side (see the module)."""
    jobs = [Trial(runtime, GPS_ONLY_LABEL, seed, binary) for seed in range(seeds) for runtime, _ in LANDING_RUNTIMES]
    started = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers) as pool:
        results = list(pool.map(fly_one, jobs, chunksize=1))
    errors = {runtime: [r[4] for r in results if r[0] == runtime and r[3] == "landed" and r[4] is not None]
              for runtime, _ in LANDING_RUNTIMES}

    def quartile(values: list[float], which: int) -> float | None:
        """The lower (which 0) or upper (which 2) quartile."""
        return statistics.quantiles(values, n=4, method="inclusive")[which] if len(values) > 1 else None

    rows = [("landed", lambda runtime, e: f"{len(e)}/{seeds}"),
            ("mean error (cm)", lambda runtime, e: fmt(statistics.mean(e) if e else None, ".1f")),
            ("standard deviation (cm)", lambda runtime, e: fmt(statistics.stdev(e) if len(e) > 1 else None, ".1f")),
            ("lower quartile (cm)", lambda runtime, e: fmt(quartile(e, 0), ".1f")),
            ("median (cm)", lambda runtime, e: fmt(statistics.median(e) if e else None, ".1f")),
            ("upper quartile (cm)", lambda runtime, e: fmt(quartile(e, 2), ".1f")),
            ("max (cm)", lambda runtime, e: fmt(max(e) if e else None, ".1f"))]
    print(f"\nGPS-only landings ({GPS_ONLY_LABEL}: land mode normal), seeds 0..{seeds - 1} on both physics, "
          "landing error from the pad")
    print(f"{'physics':46s}" + "".join(f"{title:>34s}" for _, title in LANDING_RUNTIMES))
    for label, value in rows:
        print(f"{label:46s}" + "".join(f"{value(runtime, errors[runtime]):>34s}" for runtime, _ in LANDING_RUNTIMES))
    for r in results:
        if r[3] != "landed":
            print(f"  {r[0]} seed {r[2]}: {r[3]} {r[8]}")
    first, second = (errors[runtime] for runtime, _ in LANDING_RUNTIMES)
    if len(first) > 1 and len(second) > 1:
        print(f"same distribution? Mann-Whitney U two-sided p = "
              f"{stats.mannwhitneyu(first, second, alternative='two-sided').pvalue:.3f}, "
              f"Kolmogorov-Smirnov two-sided p = {stats.ks_2samp(first, second).pvalue:.3f}")
    print(f"landings: wall time {time.perf_counter() - started:.0f} s with {workers} worker(s)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--binary", default=os.environ.get("PRELAND_SITL_BINARY"))
    parser.add_argument("--speedup", type=float, default=5.0)
    parser.add_argument("--only", choices=("json", "quad"), default=None)
    parser.add_argument("--landings", type=int, default=10, help="GPS-only landings on each physics (0: none)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="processes flying the landings")
    args = parser.parse_args()
    if not args.binary:
        parser.error("give --binary or set PRELAND_SITL_BINARY to an arducopter SITL binary")
    physics = [args.only] if args.only else ["json", "quad"]
    reports = [run_one(args.binary, p, args.speedup) for p in physics]
    rows = [("physics", lambda r: "JSON (preland quad X)" if r.physics == "json" else "built-in --model quad (+)"),
            ("armed", lambda r: str(r.armed)), ("took off to 5 m", lambda r: str(r.took_off)),
            ("landed", lambda r: str(r.landed)),
            ("MOT_THST_HOVER learned", lambda r: fmt(r.hover_learned, ".4f")),
            ("mean motor output in hold", lambda r: fmt(r.hover_motor_output, ".3f")),
            ("motor output spread in hold", lambda r: fmt(r.motor_spread, ".3f")),
            ("model motor command in hold", lambda r: fmt(r.hover_model_command, ".3f")),
            ("max altitude error in hold (m)", lambda r: fmt(r.max_alt_error_m, ".3f")),
            *[(f"{name} {start_m:g}->{target_m:g} m: {what}",
               (lambda r, name=name, attribute=attribute, spec=spec:
                fmt(getattr(r.steps[name], attribute), spec) if name in r.steps else "-"))
              for name, start_m, target_m in (("climb", TAKEOFF_ALT_M, STEP_ALT_M),
                                              ("descent", STEP_ALT_M, TAKEOFF_ALT_M))
              for what, attribute, spec in (("10-90 % rise (s)", "rise_s", ".2f"),
                                            ("overshoot (m)", "overshoot_m", ".3f"),
                                            ("settled within 0.1 m (s)", "settled_s", ".2f"),
                                            ("fastest vertical speed (m/s)", "fastest_m_s", ".2f"))],
            ("vehicle s per wall s", lambda r: fmt(r.vehicle_s_per_wall_s, ".2f")),
            ("failure", lambda r: r.failure.strip() or "-")]
    print(f"binary {args.binary}, --speedup {args.speedup:g}")
    for label, value in rows:
        print(f"{label:46s}" + "".join(f"{value(r):>26s}" for r in reports))
    for r in reports:
        if r.failure:
            print(f"STATUSTEXT ({r.physics}):")
            for text in r.statustexts:
                print("  " + text)
    if args.landings > 0:
        landings(args.binary, args.landings, args.workers)
    own = subprocess.run(["pgrep", "-P", str(os.getpid())], capture_output=True, text=True).stdout.split()
    print(f"child processes left: {len(own)}")


if __name__ == "__main__":
    main()
