"""The speed-up `preland sim serve` reaches against the one it is asked for: the simulator's MAVLink face
alone (no peer), stepped on a scaled wall clock for a few wall seconds at each speed-up, with the CPU it
took. The face's steps are due at fixed times of its clock, so a sleep that overshoots is made up by the
next steps; what it cannot reach is the machine's limit (the last column near 1 core).

Usage: python benchmarks/face_speed.py [--wall-s S] [--speedups 1 3 6 10 20 40]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import socket
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from preland_app.clock_scaled import ScaledWallClock  # noqa: E402
from preland_app.sim.mavlink_face import MavlinkFace  # noqa: E402
from preland_app.sim.simulator import Simulator  # noqa: E402


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


async def _serve(speedup: float, wall_s: float) -> tuple[float, float, float]:
    """Vehicle s served, wall s taken and CPU s used by one face at `speedup` for `wall_s` wall s."""
    face = MavlinkFace(simulator=Simulator(seed=1), clock=ScaledWallClock(speedup=speedup),
                       listen=f"udp:127.0.0.1:{_free_port()}")
    started_wall, started_cpu = time.perf_counter(), time.process_time()
    task = asyncio.ensure_future(face.run())
    await asyncio.sleep(wall_s)
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
    return face.simulator.time_s, time.perf_counter() - started_wall, time.process_time() - started_cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--wall-s", type=float, default=3.0)
    parser.add_argument("--speedups", type=float, nargs="+", default=[1.0, 3.0, 6.0, 10.0, 20.0, 40.0])
    args = parser.parse_args()
    print(f"{'asked':>7} {'reached':>8} {'vehicle s':>10} {'wall s':>7} {'CPU (cores)':>11}")
    for speedup in args.speedups:
        vehicle_s, wall_s, cpu_s = asyncio.run(_serve(speedup, args.wall_s))
        print(f"{speedup:6.1f}x {vehicle_s / wall_s:7.2f}x {vehicle_s:10.2f} {wall_s:7.2f} {cpu_s / wall_s:11.2f}")


if __name__ == "__main__":
    main()
