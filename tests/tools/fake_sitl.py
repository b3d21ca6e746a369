#!/usr/bin/env python3
"""A stand-in for ArduPilot's `arducopter` SITL binary, for tests: it takes SITL's command line and serves
preland's embedded simulator over MAVLink to the --serial0 udpclient address. It writes its pid and
arguments to $FAKE_SITL_LOG_DIR (when set) so tests can check what was launched and that it is gone, and a
PID.airborne file there once the vehicle is in the air."""

import argparse
import asyncio
import json
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from preland_app.clock_scaled import ScaledWallClock  # noqa: E402
from preland_app.geo import GeoPoint  # noqa: E402
from preland_app.sim.mavlink_face import MavlinkFace  # noqa: E402
from preland_app.errors import CommandDenied  # noqa: E402
from preland_app.sim.params import ARDUCOPTER_PARAMS  # noqa: E402
from preland_app.sim.simulator import Simulator  # noqa: E402


# SITL's own parameters that preland writes during a flight (libraries/SITL/SITL.cpp, 4.6: AP_Vector3f,
# served as three REAL32). The stand-in serves and stores them; its GPS error stays the simulator's own.
SITL_FLOAT_PARAMS = ("SIM_GPS_GLITCH_X", "SIM_GPS_GLITCH_Y", "SIM_GPS_GLITCH_Z")


class SitlFace(MavlinkFace):
    """The face plus SITL's own SIM_* parameters, as a SITL build has them (REAL32)."""

    def __init__(self, *, sim_values: dict[str, float], **kwargs) -> None:
        super().__init__(**kwargs)
        self.sim_values = {name: sim_values.get(name, 0.0) for name in SITL_FLOAT_PARAMS}

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


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--model")
    parser.add_argument("--speedup", type=float, default=1.0)
    parser.add_argument("--defaults", default="")
    parser.add_argument("-I", dest="instance", type=int, default=0)
    parser.add_argument("--home")
    parser.add_argument("--serial0")
    args = parser.parse_args()
    log_dir = os.environ.get("FAKE_SITL_LOG_DIR")
    if log_dir:
        Path(log_dir, f"{os.getpid()}.json").write_text(json.dumps({"pid": os.getpid(), "argv": sys.argv[1:]}))
    # ArduPilot reads every defaults file, later ones winning; the simulator models only some parameters,
    # the others (compass offsets, RC calibration, SIM_*) are taken and ignored, as SITL would use them.
    given = {}
    for path in filter(None, args.defaults.split(",")):
        for line in Path(path).read_text().splitlines():
            fields = line.split()
            if len(fields) >= 2 and not fields[0].startswith("#"):
                given[fields[0]] = float(fields[1])
    params = {name: value for name, value in given.items() if name in ARDUCOPTER_PARAMS}
    lat, lon, alt, heading = (float(v) for v in args.home.split(","))
    simulator = Simulator(seed=args.instance, origin=GeoPoint(lat, lon, alt), params=params, initial_yaw_deg=heading)
    if not given.get("FRAME_CLASS"):
        # ArduCopter's default FRAME_CLASS is 0 (undefined): its motors refuse to arm, as without copter.parm.
        def refuse(*_args, **_kwargs):
            raise CommandDenied(operation="arm", reason="Arm: Motors: Check frame class and type")

        simulator.autopilot.arm = refuse
    if log_dir:
        # Tests that stop SITL in flight wait for this file instead of guessing a wall time.
        step, airborne = simulator.step, Path(log_dir, f"{os.getpid()}.airborne")

        def step_and_note() -> None:
            step()
            if not airborne.exists() and simulator.autopilot.landed_state().name == "IN_AIR":
                airborne.write_text(f"{simulator.time_s:.2f}\n")

        simulator.step = step_and_note
    face = SitlFace(simulator=simulator, clock=ScaledWallClock(speedup=args.speedup), listen=args.serial0,
                    sim_values=given)
    asyncio.run(face.run())


if __name__ == "__main__":
    main()
