"""Wall time of one physics step of the JSON bridge (`sim/json_bridge.py`), the part of lock-step SITL on
preland's physics that runs once per servo packet (the runtime's SIM_RATE_HZ a vehicle second): parsing the
packet, the air (wind and gusts), the motor-level quad X, SITL's sensor smoothing and the reply's text.

No SITL is needed: the bridge answers a fixed sequence of servo packets (a climb on unequal motors, then a
wobble about hover) in the thesis mission's weather, on one core. Prints microseconds per step over
`--steps` steps (the median of `--runs` runs) and a hash of every reply, so a rewrite of the step can be
checked to answer SITL with the same text to the bit. Then the same packets served as in a trial: over UDP
from another process that sends each packet once the answer to the one before is in, as SITL does; the CPU
time of the serving thread per step (receiving, stepping, answering), and the hash of what that process read.

Usage: python benchmarks/bridge_step.py [--steps N] [--runs N]
"""

from __future__ import annotations

import argparse
import hashlib
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from preland_app.config.mission import load_mission  # noqa: E402
from preland_app.runtime.sitl import JSON_QUADX_DEFAULTS  # noqa: E402
from preland_app.runtime.sitl_parm import read_parm_file  # noqa: E402
from preland_app.sim.air import AirAtVehicle  # noqa: E402
from preland_app.sim.json_bridge import JsonBridge  # noqa: E402
from preland_app.sim.multirotor import QuadXFrame, QuadXMultirotor  # noqa: E402
from preland_app.sim.sitl_json import build_servo_packet  # noqa: E402

RATE_HZ = int(read_parm_file(JSON_QUADX_DEFAULTS)["SIM_RATE_HZ"])  # the packets a vehicle second in trials
CLIMB_STEPS = 2 * RATE_HZ  # 2 vehicle s of climb before the wobble


def packets(steps: int) -> list[bytes]:
    out = []
    for i in range(steps):
        base = 1700 if i < CLIMB_STEPS else 1560
        pwm = [base + int(30 * math.sin(i / 50.0 + k)) for k in range(4)]
        out.append(build_servo_packet(frame_rate_hz=RATE_HZ, frame_count=i, pwm_us=pwm))
    return out


def new_bridge() -> JsonBridge:
    """A bridge in the thesis mission's weather, its air from seed 1."""
    mission = load_mission(ROOT / "missions" / "thesis_square_land.yaml")
    return JsonBridge(model=QuadXMultirotor(frame=QuadXFrame()), port=0,
                      air=AirAtVehicle(environment=mission.environment, seed=1))


def run(steps: list[bytes]) -> tuple[float, str]:
    bridge = new_bridge()
    digest = hashlib.sha256()
    try:
        started = time.perf_counter()
        for packet in steps:
            digest.update(bridge.handle(packet))
        return (time.perf_counter() - started) / len(steps), digest.hexdigest()[:16]
    finally:
        bridge.stop()


# The stand-in SITL: builds the same packets, sends each once the answer to the one before is in, hashes the answers.
_CLIENT = """
import hashlib, socket, sys
sys.path.insert(0, sys.argv[1])
sys.path.insert(0, sys.argv[1] + '/benchmarks')
from bridge_step import packets
port, steps = int(sys.argv[2]), int(sys.argv[3])
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.settimeout(30)
digest = hashlib.sha256()
print('ready', flush=True)
for packet in packets(steps):
    sock.sendto(packet, ('127.0.0.1', port))
    digest.update(sock.recv(65536))
print(digest.hexdigest()[:16], flush=True)
"""


def served(steps: int) -> tuple[float, float, str]:
    """(CPU s and wall s of the serving thread per step, the hash of the answers the other process read)."""
    bridge = new_bridge()
    client = subprocess.Popen([sys.executable, "-c", _CLIENT, str(ROOT), str(bridge.address[1]), str(steps)],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert client.stdout is not None and client.stdout.readline().strip() == "ready"
        cpu0, wall0 = time.thread_time(), time.perf_counter()
        bridge.serve(max_packets=steps)
        cpu_s, wall_s = time.thread_time() - cpu0, time.perf_counter() - wall0
        digest = client.stdout.readline().strip()
        client.wait(timeout=30)
        return cpu_s / steps, wall_s / steps, digest
    finally:
        if client.poll() is None:
            client.kill()
        bridge.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=8000)
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    steps = packets(args.steps)
    results = [run(steps) for _ in range(args.runs)]
    hashes = {h for _, h in results}
    per_step_us = statistics.median(t for t, _ in results) * 1e6
    print(f"JSON bridge, {args.steps} steps at {RATE_HZ} Hz ({args.steps / RATE_HZ:g} vehicle s), "
          f"median of {args.runs} runs, one core")
    print(f"  {per_step_us:.1f} us per step: {per_step_us * RATE_HZ / 1e6:.3f} wall s per vehicle s "
          f"(the physics alone would run {1e6 / (per_step_us * RATE_HZ):.1f}x real time)")
    print(f"  replies' hash {', '.join(sorted(hashes))}")
    served_runs = [served(args.steps) for _ in range(args.runs)]
    cpu_us = statistics.median(c for c, _, _ in served_runs) * 1e6
    wall_us = statistics.median(w for _, w, _ in served_runs) * 1e6
    print(f"served over UDP to another process on the same core, median of {args.runs} runs")
    print(f"  {cpu_us:.1f} us of the serving thread's CPU per step ({cpu_us - per_step_us:.1f} more than the step "
          f"alone), {wall_us:.1f} us wall per exchange")
    print(f"  answers' hash {', '.join(sorted({h for _, _, h in served_runs}))}")


if __name__ == "__main__":
    main()
