"""ArduCopter's roll and pitch estimate error on preland's physics (`sitl:BIN?physics=preland`), with a true
IMU and with gyro errors (`preland_app/sim/imu.py`, the `sitl:` option `gyro_error`), side by side.

Flies thesis scenarios in their weather (`benchmarks/fault_scenarios_table.py`: Table 3's near-calm air,
Table 4's gusts) on SITL in lock-step, keeps each trial's dataflash log, and compares ArduCopter's estimate
(ATT) with the physics' truth SITL logs beside it (SIM, the same instant) while airborne (more than 1 m
above the ground). For each `--gyro-error` value (1/s: the gyro error's standard deviation in rad/s per
radian of the mission's attitude error; 0: a true IMU) it prints each trial's landing error and estimate
error (rms of roll and pitch together, degrees), each scenario's, and all of them beside the mission's
attitude error (`attitude_noise_sigma_deg`), which the embedded simulator gives its estimate.

Usage: python benchmarks/sitl_attitude_error.py [--binary PATH] [--seeds 4] [--workers 2]
       [--scenarios "T3 irlock,T4 fused"] [--gyro-error 0,0.43]   (binary: $PRELAND_SITL_BINARY)
"""

from __future__ import annotations

import argparse
import concurrent.futures
import os
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from fault_scenarios_table import scenario_request  # noqa: E402

from preland_app.runtime.sitl_log import attitude_estimate_errors_deg, rms  # noqa: E402


def _trial(job: tuple[str, str, int, str, float]) -> tuple[float, str, int, str, float | None, list[float]]:
    binary, label, seed, log_dir, gyro_error = job
    from preland_app.runtime.sitl import SitlOptions, run_sitl_trial

    name = f"{label.replace(' ', '_').replace('<', 'lt').replace('>', 'gt')}_seed{seed}_gyro{gyro_error:g}.tlog"
    options = SitlOptions(binary=Path(binary), physics="preland", log_dir=Path(log_dir), gyro_error=gyro_error)
    outcome = run_sitl_trial(scenario_request(label, seed), options=options, tlog_name=name)
    log = Path(log_dir) / Path(name).with_suffix(".BIN").name
    return (gyro_error, label, seed, outcome.outcome.value, outcome.landing_error_cm,
            attitude_estimate_errors_deg(log) if log.exists() else [])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--binary", default=os.environ.get("PRELAND_SITL_BINARY"))
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--scenarios", default="T3 irlock,T4 fused")
    parser.add_argument("--gyro-error", default="0,0.43", help="comma-separated gyro_error values (1/s)")
    args = parser.parse_args()
    if not args.binary:
        parser.error("give --binary or set PRELAND_SITL_BINARY")
    labels = [label.strip() for label in args.scenarios.split(",") if label.strip()]
    factors = [float(value) for value in args.gyro_error.split(",")]
    mission_sigma = scenario_request(labels[0], 0).mission.environment.navigation.attitude_noise_sigma_deg
    print(f"ArduCopter's roll and pitch estimate error on preland's physics, {args.seeds} seeds a scenario; "
          f"the mission's attitude error {mission_sigma:g} deg")
    with tempfile.TemporaryDirectory() as log_dir:
        jobs = [(args.binary, label, seed, log_dir, factor) for factor in factors for label in labels
                for seed in range(args.seeds)]
        with concurrent.futures.ProcessPoolExecutor(max_workers=args.workers) as pool:
            results = list(pool.map(_trial, jobs))
    for factor in factors:
        print(f"\ngyro_error {factor:g} (1/s): gyro error sigma {factor * mission_sigma:.3f} deg/s")
        everything: list[float] = []
        for label in labels:
            rows = [r for r in results if r[0] == factor and r[1] == label]
            pooled = [e for r in rows for e in r[5]]
            everything += pooled
            for _, _, seed, outcome, error_cm, errors in rows:
                landing = f"{error_cm:.1f} cm" if error_cm is not None else "-"
                print(f"  {label:<22} seed {seed}: {outcome:<8} {landing:>9}  estimate error rms "
                      f"{rms(errors):.3f} deg ({len(errors) // 2} instants)")
            landed = [r[4] for r in rows if r[4] is not None]
            mean_cm = f"{statistics.fmean(landed):.1f} cm" if landed else "-"
            print(f"{label:<24} landing error mean {mean_cm}, estimate error rms {rms(pooled):.3f} deg")
        print(f"all scenarios: estimate error rms {rms(everything):.3f} deg")


if __name__ == "__main__":
    main()
