"""The thesis' scenarios (Tables 3 to 5) on ArduPilot SITL and on the embedded simulator, side by side,
and SITL's throughput and result stability across speedups.

Part 1: every scenario of benchmarks/fault_scenarios_table.py, the same seeds on both runtimes (same
weather, same faults, same mission): mean and maximum landing error (cm), mean landing time (s), and
SITL / embedded ratios of each, one table for each SITL physics asked for (`--physics`): `preland`,
ArduPilot flying preland's multirotor, wind, sensors and camera in lock-step over SITL's JSON interface (the
shared world: what differs from the embedded simulator is the autopilot), and `ardupilot`, SITL's own
physics and sensors. A precision scenario "agrees" when the means are within 30 % or 3 cm, whichever is
larger. Beside that rule, each precision scenario's per-seed differences (SITL minus embedded, the seeds
where both landed) get a two-sided Wilcoxon signed-rank test, Holm-corrected over the scenarios judged: a
scenario "differs" when its adjusted p is below 0.05. The rule judges means of heavy-tailed errors (one
lost pad among 10 seeds moves a mean by 25 cm); the paired test says which differences the seeds support.
20 seeds a scenario by default: on 10, the rule calls the embedded simulator apart from itself on other
seeds in most pairs of seed sets (`agreement_rule_noise.py`).

On preland's physics the embedded simulator is flown twice: as it is by default (ArduCopter 3.6/4.0's
precision landing and the mission's estimate errors, fitted to the field), and as the autopilot SITL runs:
`environment.autopilot.firmware: copter-4.6` at SITL's physics step (400 Hz, so that a seed's gusts take the
same path), with the estimate errors ArduCopter's EKF made in these SITL
trials (each SITL trial keeps its dataflash log, `preland_app/runtime/sitl_log.py`): its roll and pitch
error (`attitude_noise_sigma_deg`), its horizontal velocity error (`velocity_noise_sigma_m_s`) and how far
its position strays from its GPS (`position_noise_sigma_m`, scaled so that the embedded estimate's error,
high-passed the same way, has the same rms). The first comparison is the one that agrees or not.

Part 2: SITL trials per minute per core at several --speedup values (the marker scenario, the same seeds
at every speedup), and the landing errors' change against the lowest speedup: SITL is not bit-exact
across speedups, so this measures how far results move.

Needs an arducopter SITL binary: --sitl PATH or $PRELAND_SITL_BINARY.

Usage: python benchmarks/sitl_vs_embedded.py [--seeds 20] [--workers 2] [--only LABEL,...]
                                             [--physics preland,ardupilot]
                                             [--speedups 5,10,20,50] [--sweep-seeds 6] [--skip-compare]
                                             [--sweep-scenarios LABEL,...] [--skip-sweep]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from fault_scenarios_table import SCENARIOS, scenario_request  # noqa: E402
from scipy.stats import wilcoxon  # noqa: E402

from preland_app.campaign.fidelity_tests import holm  # noqa: E402
from preland_app.runtime.embedded import run_trial  # noqa: E402
from preland_app.runtime.sitl import JSON_QUADX_DEFAULTS, SitlOptions, resolve_sitl_binary, run_sitl_trial  # noqa: E402
from preland_app.runtime.sitl_parm import read_parm_file  # noqa: E402
from preland_app.runtime.sitl_log import (  # noqa: E402
    HIGH_PASS_S, attitude_estimate_errors_deg, high_passed, horizontal_estimate_errors, rms)
from preland_app.sim.navigation import NavigationModel  # noqa: E402
from preland_app.sim.spec import AutopilotSpec, Firmware  # noqa: E402

SWEEP_LABEL = "T3 marker"
# The camera's frames processed per vehicle second while landing: on SITL the companion runs in wall time,
# so at a high speedup it processes fewer frames per vehicle second than the camera's 30.


class Trial(NamedTuple):
    """One trial of a scenario on a runtime: `embedded`, `embedded-4.6` (flown with `navigation`, the estimate
    errors), `sitl` (ArduPilot's physics at `speedup`, None: preland's default) or `sitl-preland` (preland's, in
    lock-step; with `log_dir`, its dataflash log is kept there for its EKF errors)."""

    runtime: str
    label: str
    seed: int
    binary: str
    speedup: float | None = None
    log_dir: str | None = None
    navigation: dict[str, float] | None = None


def fly_one(trial: Trial) -> tuple:
    """(runtime, label, seed, outcome, error cm, landing time s, wall s, speedup, message, camera Hz, EKF errors);
    the EKF errors are (attitude deg, velocity m/s, position m) lists for a `sitl-preland` trial with a
    `log_dir`, else None."""
    runtime, label, seed, binary, speedup, log_dir, navigation = trial
    started = time.perf_counter()
    request = scenario_request(label, seed)
    ekf = None
    if runtime.startswith("sitl"):
        physics = "preland" if runtime == "sitl-preland" else "ardupilot"
        log_dir = Path(log_dir) if log_dir is not None else None
        name = f"{label.replace(' ', '_').replace('<', 'lt').replace('>', 'gt')}_seed{seed}.tlog"
        outcome = run_sitl_trial(request, options=SitlOptions(binary=Path(binary), speedup=speedup, physics=physics,
                                                              log_dir=log_dir), tlog_name=name)
        log = None if log_dir is None else log_dir / Path(name).with_suffix(".BIN").name
        if log is not None and log.exists():
            ekf = (attitude_estimate_errors_deg(log), *horizontal_estimate_errors(log))
            log.unlink()
            log.with_suffix(".tlog").unlink(missing_ok=True)
    else:
        if runtime == "embedded-4.6":
            request = as_copter_4_6(request, navigation=navigation)
        outcome = run_trial(request)
    frames = outcome.details.get("marker_frames")
    camera_hz = frames / outcome.landing_time_s if frames and outcome.landing_time_s else None
    return (runtime, label, seed, outcome.outcome.value, outcome.landing_error_cm, outcome.landing_time_s,
            time.perf_counter() - started, speedup, outcome.message, camera_hz, ekf)


# The step of SITL's JSON physics, as trials fly it: at the same step a seed's gusts take the same path on both
# from the start of the flight (sim/air.py).
SITL_PHYSICS_RATE_HZ = read_parm_file(JSON_QUADX_DEFAULTS)["SIM_RATE_HZ"]


def as_copter_4_6(request, *, navigation: dict[str, float]):
    environment = request.mission.environment
    environment = replace(environment, navigation=replace(environment.navigation, **navigation),
                          autopilot=AutopilotSpec(firmware=Firmware.COPTER_4_6),
                          physics_rate_hz=SITL_PHYSICS_RATE_HZ)
    return replace(request, mission=replace(request.mission, environment=environment))


def _high_passed_rms_per_metre(*, seconds: float = 600.0) -> float:
    """The rms of the embedded estimate's fast position error, sampled at 25 Hz like XKF1 and high-passed as
    `high_passed` does, per metre of `position_noise_sigma_m` (the GPS drift off: it is the world's, and SITL
    is given it)."""
    spec = replace(scenario_request(SWEEP_LABEL, 0).mission.environment.navigation, position_noise_sigma_m=1.0,
                   gps_drift_sigma_m=0.0)
    model = NavigationModel(spec=spec, rangefinder_min_m=0.2, rangefinder_max_m=10.0, seed=0)
    rows = []
    for step in range(int(seconds * 100)):
        estimate = model.step(dt_s=0.01, north_m=0.0, east_m=0.0, down_m=-5.0, velocity_ned_m_s=(0.0, 0.0, 0.0),
                              tilt_cos=1.0, yaw_rad=0.0)
        if step % 4 == 0:
            rows.append((step * 0.01, estimate.north_m, estimate.east_m))
    return rms(high_passed(rows))


def ekf_navigation(results: list[tuple]) -> dict[str, float]:
    """The navigation errors that give the embedded estimate ArduCopter's EKF errors of these SITL trials."""
    pooled = [[value for r in results if r[10] is not None for value in r[10][part]] for part in range(3)]
    return {"attitude_noise_sigma_deg": rms(pooled[0]), "velocity_noise_sigma_m_s": rms(pooled[1]),
            "position_noise_sigma_m": rms(pooled[2]) / _high_passed_rms_per_metre()}


PAIRED_ALPHA = 0.05  # family-wise, over the precision scenarios of one table


def signed_rank_p(differences: list[float]) -> float | None:
    """Two-sided Wilcoxon signed-rank p of paired differences (scipy's; exact for small samples without ties);
    1.0 when every difference is 0, None without any."""
    if not differences:
        return None
    if not any(differences):
        return 1.0
    return float(wilcoxon(differences, alternative="two-sided").pvalue)


def _mean(values: list[float]) -> float | None:
    return statistics.mean(values) if values else None


def _fmt(value: float | None, width: int, digits: int = 1) -> str:
    return f"{'-':>{width}}" if value is None else f"{value:{width}.{digits}f}"


def compare(*, binary: str, labels: list[str], seeds: int, workers: int, speedup: float | None,
            physics: list[str]) -> None:
    sitl_runtimes = ["sitl-preland" if p == "preland" else "sitl" for p in physics]
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as log_dir, ProcessPoolExecutor(max_workers=workers) as pool:
        jobs = [Trial(runtime, label, seed, binary, speedup if runtime == "sitl" else None,
                      log_dir if runtime == "sitl-preland" else None) for label in labels
                for seed in range(seeds) for runtime in (*sitl_runtimes, "embedded")]
        results = list(pool.map(fly_one, jobs, chunksize=1))
        if "sitl-preland" in sitl_runtimes:
            navigation = ekf_navigation([r for r in results if r[0] == "sitl-preland"])
            print("ArduCopter's EKF on preland's physics, pooled over its trials: roll and pitch error rms "
                  f"{navigation['attitude_noise_sigma_deg']:.3f} deg, horizontal velocity error rms "
                  f"{navigation['velocity_noise_sigma_m_s']:.3f} m/s, position error (high-passed over "
                  f"{HIGH_PASS_S:g} s) as position_noise_sigma_m {navigation['position_noise_sigma_m']:.3f} m")
            jobs = [Trial("embedded-4.6", label, seed, binary, navigation=navigation)
                    for label in labels for seed in range(seeds)]
            results += list(pool.map(fly_one, jobs, chunksize=1))
    for runtime in sitl_runtimes:
        if runtime == "sitl-preland":
            _table(results, runtime=runtime, embedded="embedded-4.6", labels=labels, seeds=seeds, speedup=speedup)
        _table(results, runtime=runtime, embedded="embedded", labels=labels, seeds=seeds, speedup=speedup)
    print(f"wall time {time.perf_counter() - started:.0f} s with {workers} worker(s)")


def _table(results: list[tuple], *, runtime: str, embedded: str, labels: list[str], seeds: int,
           speedup: float | None) -> None:
    if runtime == "sitl-preland":
        at = "on preland's physics in lock-step (the shared world)"
    else:
        at = "on ArduPilot's physics, " + ("at preland's default speedup (2x with a camera, else 10x)"
                                            if speedup is None else f"at {speedup:g}x")
    beside = ("the embedded simulator as ArduCopter 4.6 (copter-4.6, with the EKF errors above)"
              if embedded == "embedded-4.6" else "the embedded simulator as it is by default (copter-4.0)")
    print(f"\nthesis scenarios, {seeds} seeds each, SITL {at} beside {beside} (error cm, landing time s)")
    print(f"{'scenario':<22} {'SITL landed':>11} {'mean':>6} {'max':>6} {'time':>6}   {'emb landed':>10} {'mean':>6} "
          f"{'max':>6} {'time':>6}   {'mean x':>6} {'max x':>6} {'time x':>6}  agree  "
          f"{'SITL-emb':>7} {'p':>6} {'Holm p':>6}  cam Hz SITL/emb")
    agreed = judged = 0
    lines, pvalues, shifts, cameras = [], {}, {}, {}
    for label in labels:
        row, by_seed = {}, {}
        for name in (runtime, embedded):
            rows = [r for r in results if r[0] == name and r[1] == label]
            errors = [r[4] for r in rows if r[3] == "landed" and r[4] is not None]
            times = [r[5] for r in rows if r[3] == "landed" and r[5] is not None]
            row[name] = (sum(r[3] == "landed" for r in rows), len(rows), _mean(errors),
                         max(errors) if errors else None, _mean(times),
                         _mean([r[9] for r in rows if r[9] is not None]))
            by_seed[name] = {r[2]: r[4] for r in rows if r[3] == "landed" and r[4] is not None}
            for r in rows:
                if r[3] != "landed":
                    print(f"  {name} {label} seed {r[2]}: {r[3]} {r[8]}")
        s, e = row[runtime], row[embedded]

        def ratio(a, b):
            return None if a is None or not b else a / b

        cameras[label] = "" if s[5] is None else f"{s[5]:.1f}/{_fmt(e[5], 1)}"
        agree = ""
        if SCENARIOS[label][0] != "normal" and s[2] is not None and e[2] is not None:
            within = abs(s[2] - e[2]) <= max(0.3 * e[2], 3.0)
            judged, agreed, agree = judged + 1, agreed + within, "yes" if within else "NO"
            differences = [by_seed[runtime][seed] - by_seed[embedded][seed]
                           for seed in sorted(set(by_seed[runtime]) & set(by_seed[embedded]))]
            shifts[label], pvalues[label] = _mean(differences), signed_rank_p(differences)
        lines.append((label, f"{label:<22} {s[0]:>7}/{s[1]:<3} {_fmt(s[2], 6)} {_fmt(s[3], 6)} {_fmt(s[4], 6)}   "
                      f"{e[0]:>6}/{e[1]:<3} {_fmt(e[2], 6)} {_fmt(e[3], 6)} {_fmt(e[4], 6)}   "
                      f"{_fmt(ratio(s[2], e[2]), 6, 2)} {_fmt(ratio(s[3], e[3]), 6, 2)} "
                      f"{_fmt(ratio(s[4], e[4]), 6, 2)}  {agree:<5}  "))
    adjusted = holm({label: p for label, p in pvalues.items() if p is not None})
    for label, line in lines:
        paired = (f"{_fmt(shifts.get(label), 7)} {_fmt(pvalues.get(label), 6, 3)} {_fmt(adjusted.get(label), 6, 3)}"
                  if label in pvalues else f"{'':>7} {'':>6} {'':>6}")
        print(f"{line}{paired}  {cameras[label]}")
    print(f"{agreed} of {judged} precision scenarios agree")
    differ = sorted(label for label, p in adjusted.items() if p < PAIRED_ALPHA)
    print(f"paired signed-rank test, Holm over {len(adjusted)} scenarios: {len(differ)} differ at "
          f"{PAIRED_ALPHA:g}" + (f" ({', '.join(differ)})" if differ else ""))


def sweep(*, binary: str, speedups: list[float], seeds: int, workers: int, label: str = SWEEP_LABEL) -> None:
    print(f"\nSITL throughput and stability: {label}, seeds 0..{seeds - 1}, {workers} worker(s)")
    print(f"{'speedup':>7} {'landed':>6} {'trials/min/core':>15} {'wall s/trial':>12} {'mean cm':>8} "
          f"{'mean |change| cm vs first':>26} {'camera Hz':>9}")
    baseline: dict[int, float] | None = None
    for speedup in speedups:
        jobs = [Trial("sitl", label, seed, binary, speedup) for seed in range(seeds)]
        started = time.perf_counter()
        with ProcessPoolExecutor(max_workers=workers) as pool:
            results = list(pool.map(fly_one, jobs, chunksize=1))
        wall_s = time.perf_counter() - started
        errors = {r[2]: r[4] for r in results if r[3] == "landed" and r[4] is not None}
        change = None
        if baseline is None:
            baseline = errors
        else:
            shared = sorted(set(errors) & set(baseline))
            change = _mean([abs(errors[s] - baseline[s]) for s in shared])
        per_core = len(results) / (wall_s / 60.0) / workers
        print(f"{speedup:>7g} {len(errors):>3}/{len(results):<2} {per_core:15.2f} "
              f"{_mean([r[6] for r in results]):12.1f} "
              f"{_fmt(_mean(list(errors.values())), 8)} {_fmt(change, 26)} "
              f"{_fmt(_mean([r[9] for r in results if r[9] is not None]), 9)}")
        for r in results:
            if r[3] != "landed":
                print(f"    seed {r[2]}: {r[3]} {r[8]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sitl", default=None, help="arducopter binary (default $PRELAND_SITL_BINARY)")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--speedup", type=float, default=None,
                        help="SITL speedup of the comparison (default: preland's, 2x with a camera, else 10x)")
    parser.add_argument("--only", default="", help="comma-separated scenario labels")
    parser.add_argument("--physics", default="preland,ardupilot",
                        help="comma-separated SITL physics compared with the embedded simulator: preland, ardupilot")
    parser.add_argument("--speedups", default="5,10,20,50")
    parser.add_argument("--sweep-seeds", type=int, default=6)
    parser.add_argument("--sweep-scenarios", default=f"{SWEEP_LABEL},T3 marker random0.5",
                        help="comma-separated scenario labels swept over the speedups")
    parser.add_argument("--skip-compare", action="store_true")
    parser.add_argument("--skip-sweep", action="store_true")
    args = parser.parse_args()
    binary = str(resolve_sitl_binary(args.sitl))
    labels = [label for label in SCENARIOS if not args.only or label in args.only.split(",")]
    if not args.skip_compare:
        physics = args.physics.split(",")
        if not set(physics) <= {"preland", "ardupilot"}:
            parser.error(f"--physics: {args.physics!r}: each one of preland, ardupilot")
        compare(binary=binary, labels=labels, seeds=args.seeds, workers=args.workers, speedup=args.speedup,
                physics=physics)
    if not args.skip_sweep:
        for label in args.sweep_scenarios.split(","):
            sweep(binary=binary, speedups=[float(v) for v in args.speedups.split(",")], seeds=args.sweep_seeds,
                  workers=args.workers, label=label)


if __name__ == "__main__":
    main()
