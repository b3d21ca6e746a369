"""preland sim and preland fault: the embedded simulator as a MAVLink vehicle, and the fault command."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from ..errors import PrelandError
from .app import EXIT_FAILED, app, choices, fail


sim_app = typer.Typer(help="The embedded simulator: serve it as a MAVLink vehicle, calibrate its parameters to "
                           "field trials, list the calibratable params.", no_args_is_help=True)
app.add_typer(sim_app, name="sim")


@sim_app.command("serve")
def sim_serve(
    listen: list[str] = typer.Option(["udp:127.0.0.1:14550"], "--listen", metavar="UDP:HOST:PORT",
                                     help="UDP address to serve on (localhost unless told otherwise). Repeat it "
                                          "for more channels, as ArduPilot's serial ports: one for preland, "
                                          "one for a ground station."),
    speedup: float = typer.Option(1.0, "--speedup", help="Simulated seconds per wall second (while no companion "
                                                         "paces it)."),
    paced: bool = typer.Option(False, "--paced", help="Hold at time 0 until a companion flying with --paced "
                                                      "paces it (PRELAND_PACE), and between companions: the same "
                                                      "seed flies the same trial."),
    seed: int = typer.Option(1, "--seed", help="Simulator seed (wind, GPS error, noise)."),
    mission_file: Optional[Path] = typer.Option(None, "--mission",
                                                help="Take the environment and parameters from this mission."),
    param_values: list[str] = typer.Option([], "--param", metavar="NAME=VALUE",
                                           help="Set an ArduPilot parameter at start (repeatable; after the "
                                                "mission's), as a defaults file does: e.g. --param PLND_ENABLED=1 "
                                                "--param PLND_TYPE=1 for the precision land modes."),
) -> None:
    """Serve the embedded simulator over MAVLink, behaving like ArduCopter (Ctrl-C stops it)."""
    import asyncio
    import math

    from ..clock_scaled import ScaledWallClock
    from ..sim.mavlink_face import MavlinkFace
    from ..sim.params import ARDUCOPTER_PARAMS, ParameterTable
    from ..sim.simulator import Simulator

    if not 0.1 <= speedup <= 1000:
        raise fail(f"--speedup: must be within 0.1..1000, got {speedup:g}")
    environment, params, yaw = None, {}, 0.0
    if mission_file is not None:
        from ..config.mission import load_mission

        try:
            mission = load_mission(mission_file)
        except PrelandError as error:
            raise fail(str(error)) from None
        environment, params, yaw = mission.environment, dict(mission.params), mission.initial_yaw_deg
    check = ParameterTable()
    for text in param_values:
        name, sep, value_text = text.partition("=")
        name = name.strip().upper()
        info = ARDUCOPTER_PARAMS.get(name)
        if not sep or not name:
            raise fail(f"--param {text!r}: expected NAME=VALUE, e.g. PLND_ENABLED=1")
        if info is None or not info.ardupilot:
            raise fail(f"--param {text!r}: {name} is not an ArduCopter parameter the simulator models")
        try:
            value = float(value_text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise fail(f"--param {text!r}: {value_text.strip()!r} is not a number")
        try:
            check.set(name, value)
        except ValueError as error:
            raise fail(f"--param {text!r}: {error}") from None
        params[name] = value

    async def main() -> None:
        simulator = Simulator(seed=seed, environment=environment, params=params, initial_yaw_deg=yaw)
        face = MavlinkFace(simulator=simulator, clock=ScaledWallClock(speedup=speedup), listen=listen, paced=paced)
        pace = "paced by its companion" if paced else f"at {speedup:g}x"
        typer.echo(f"serving the embedded simulator on {', '.join(listen)} {pace} (Ctrl-C to stop)")
        await face.run()

    try:
        asyncio.run(main())
    except PrelandError as error:
        raise fail(str(error)) from None
    except KeyboardInterrupt:
        typer.echo("stopped")


def _fault_targets() -> list[str]:
    from ..sensing.faults import FaultTarget

    return [target.name.lower() for target in FaultTarget]


FaultTargetName = choices(_fault_targets)

fault_app = typer.Typer(help="The thesis' fault command: send it to a companion as a MAVLink message.",
                        no_args_is_help=True)
app.add_typer(fault_app, name="fault")


@fault_app.command("send")
def fault_send(
    connect: str = typer.Option(..., "--connect", metavar="URL",
                                help="Where the companion takes fault commands (its --fault-listen), "
                                     "e.g. udp://127.0.0.1:14560."),
    target: FaultTargetName = typer.Option(..., "--target", help="Sensor subsystem."),
    r_drop: float = typer.Option(0.0, "--r-drop", help="Drop probability (random mode; 1.0: permanent)."),
    p_keep: int = typer.Option(0, "--p-keep", help="Values to keep (periodic mode)."),
    p_drop: int = typer.Option(0, "--p-drop", help="Values to drop (periodic mode)."),
    ack_timeout_s: float = typer.Option(1.0, "--ack-timeout-s",
                                        help="Wait this long (wall s) for the companion's PRELAND_FAULT_ACK; "
                                             "0: send without waiting (nothing then tells whether it arrived)."),
) -> None:
    """Send a PRELAND_FAULT_INJECTION command (all zero: injection off for the target) and wait for the
    companion's acknowledgement (exit 1 when none comes)."""
    from ..mavlink.fault_message import ACK_IGNORED, FaultMessageError, send
    from ..sensing.faults import FaultCommand, FaultSyntaxError, FaultTarget

    if not 0.0 <= ack_timeout_s <= 60.0:
        raise fail(f"--ack-timeout-s: must be within 0..60 s, got {ack_timeout_s:g}")
    try:
        command = FaultCommand(target=FaultTarget[target.upper()], r_drop=r_drop, p_keep=p_keep, p_drop=p_drop)
    except FaultSyntaxError as error:
        raise fail(str(error)) from None
    try:
        result = send(command, url=connect, ack_timeout_s=ack_timeout_s or None)
    except FaultMessageError as error:
        raise fail(f"--connect {error}", code=EXIT_FAILED) from None
    except PrelandError as error:
        raise fail(str(error)) from None
    faults = ", ".join(f"{sensor} {fault}" for sensor, fault in command.faults().items())
    answer = {None: "not acknowledged (not waited for)", ACK_IGNORED: "the companion ignored it (its land mode "
              "takes no faults)"}.get(result, "the companion applied it")
    typer.echo(f"sent PRELAND_FAULT_INJECTION to {connect}: {faults}; {answer}")
