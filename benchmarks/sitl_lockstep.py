"""Lock-step SITL on preland's physics (`sitl:BIN?physics=preland`): every land mode over seeds, each seed
flown several times, optionally beside CPU-bound busy loops.

For each land mode and seed it prints the landing errors of the repeats (cm, to the micrometre), their
spread, whether the repeats are identical (error and flight time to the last digit), the speed (the
trial's vehicle seconds, from SITL's boot, per wall second), the camera frames read per vehicle second
while landing, and where the bridge's wall time went: stepping preland's physics, waiting for SITL (its
own step and the transport), and held for the companion (its readings, camera frames, the settle before
a wake; `settle` is the part of it spent on that settle), and `unset`, the wakes and exchanges of the
repeats that went on at a wall bound instead of at what they waited for (`lockstep_unsettled`: one such can
part the repeats of a seed). The summary gives the landings, the largest
spread, and the speeds of the camera land modes and of the others.

Usage: python benchmarks/sitl_lockstep.py [--binary PATH] [--seeds 1 2] [--repeats 3] [--workers 2]
       [--busy N] [--modes irlock marker ...]   (binary: $PRELAND_SITL_BINARY)
"""

from __future__ import annotations

import argparse
import concurrent.futures
import multiprocessing
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

THESIS = ROOT / "missions" / "thesis_square_land.yaml"
PAPER = ROOT / "missions" / "paper_marker_land.yaml"
# (name, land mode, sensor, mission): every land mode the issue names
MODES = [("normal", "normal", None, THESIS), ("irlock", "irlock", None, THESIS),
         ("marker", "marker", None, THESIS), ("fused", "fused", None, THESIS),
         ("cautious-irlock", "cautious", "irlock", THESIS), ("cautious-marker", "cautious", "marker", THESIS),
         ("cautious-fused", "cautious", "fused", THESIS),
         ("paper_static", "paper_static", None, PAPER), ("paper_adaptive", "paper_adaptive", None, PAPER)]
CAMERA_MODES = {"marker", "fused", "cautious-marker", "cautious-fused", "paper_static", "paper_adaptive"}
PRECISION_LIMIT_CM = 15.0
REPEAT_LIMIT_CM = 0.5


def _trial(binary: str, name: str, mode: str, sensor: str | None, mission: str, seed: int) -> dict:
    from preland_app.config.mission import load_mission
    from preland_app.runtime.embedded import TrialRequest
    from preland_app.runtime.sitl import SitlOptions, run_sitl_trial

    request = TrialRequest(mission=load_mission(mission), seed=seed, land_mode=mode, sensor=sensor)
    started = time.perf_counter()
    outcome = run_sitl_trial(request, options=SitlOptions(binary=Path(binary), physics="preland"))
    wall_s = time.perf_counter() - started
    d = outcome.details
    frames = d.get("marker_frames")
    return {"name": name, "seed": seed, "outcome": outcome.outcome.value, "message": outcome.message,
            "error_cm": outcome.landing_error_cm, "flight_time_s": outcome.flight_time_s, "wall_s": wall_s,
            "vehicle_s": d.get("bridge_vehicle_s"),
            "camera_hz": frames / outcome.landing_time_s if frames and outcome.landing_time_s else None,
            "physics_s": d.get("bridge_physics_wall_s"), "waiting_s": d.get("bridge_waiting_wall_s"),
            "held_s": d.get("lockstep_held_wall_s"), "settle_s": d.get("lockstep_settle_wall_s"),
            "unsettled": d.get("lockstep_unsettled") or 0}


def _busy() -> None:
    while True:
        pass


def _share(rows: list[dict], key: str) -> str:
    return f"{100.0 * sum(r[key] or 0.0 for r in rows) / sum(r['wall_s'] for r in rows):.0f}%"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--binary", default=os.environ.get("PRELAND_SITL_BINARY"))
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--busy", type=int, default=0, help="CPU-bound busy loops running beside the trials")
    parser.add_argument("--modes", nargs="+", choices=[m[0] for m in MODES], default=[m[0] for m in MODES])
    args = parser.parse_args()
    if not args.binary:
        print("set PRELAND_SITL_BINARY (or --binary) to an arducopter SITL binary")
        return 2
    modes = [m for m in MODES if m[0] in args.modes]
    jobs = [(args.binary, name, mode, sensor, str(mission), seed)
            for name, mode, sensor, mission in modes for seed in args.seeds for _ in range(args.repeats)]
    print(f"lock-step SITL on preland's physics: {len(modes)} land modes x seeds {args.seeds} x "
          f"{args.repeats} repeats, {args.workers} workers, {args.busy} busy loops beside, {os.cpu_count()} cores")
    busy = [multiprocessing.Process(target=_busy, daemon=True) for _ in range(args.busy)]
    for process in busy:
        process.start()
    started = time.perf_counter()
    try:
        with concurrent.futures.ProcessPoolExecutor(args.workers) as pool:
            rows = list(pool.map(_trial, *zip(*jobs)))
    finally:
        for process in busy:
            process.terminate()
    elapsed_s = time.perf_counter() - started
    print(f"  {'land mode':<16} {'seed':>4} {'errors cm':<32} {'spread':>7} {'same':>5} {'speed x':>8} "
          f"{'cam Hz':>7} {'physics':>8} {'SITL':>5} {'held':>5} {'settle':>7} {'unset':>6}")
    failures: list[str] = []
    spreads: list[float] = []
    for name, _, _, _ in modes:
        for seed in args.seeds:
            group = [r for r in rows if r["name"] == name and r["seed"] == seed]
            landed = [r for r in group if r["outcome"] == "landed"]
            errors = [r["error_cm"] for r in landed]
            for r in group:
                if r["outcome"] != "landed":
                    failures.append(f"{name} seed {seed}: {r['outcome']} ({r['message'][:100]})")
            spread = max(errors) - min(errors) if len(errors) == len(group) else float("nan")
            spreads.append(spread)
            same = len(landed) == len(group) and len({(r["error_cm"], r["flight_time_s"]) for r in group}) == 1
            speed = statistics.median(r["vehicle_s"] / r["wall_s"] for r in group if r["vehicle_s"])
            camera = [r["camera_hz"] for r in group if r["camera_hz"]]
            text = " ".join(f"{e:.4f}" for e in errors) if errors else "-"
            print(f"  {name:<16} {seed:>4} {text:<32} {spread:>7.3f} {'yes' if same else 'no':>5} {speed:>8.2f} "
                  f"{statistics.median(camera) if camera else float('nan'):>7.1f} {_share(group, 'physics_s'):>8} "
                  f"{_share(group, 'waiting_s'):>5} {_share(group, 'held_s'):>5} {_share(group, 'settle_s'):>7} "
                  f"{sum(r['unsettled'] for r in group):>6}")
    print()
    for line in failures:
        print(f"  not landed: {line}")
    precision = [r for r in rows if r["name"] != "normal" and r["outcome"] == "landed"]
    worst = max((r["error_cm"] for r in precision), default=float("nan"))
    print(f"  landed: {sum(r['outcome'] == 'landed' for r in rows)} of {len(rows)}; worst precision landing "
          f"{worst:.2f} cm (limit {PRECISION_LIMIT_CM:g})")
    print(f"  largest spread over repeats of a seed: {max(spreads):.4f} cm (limit {REPEAT_LIMIT_CM:g})")
    for label, names in (("camera land modes", CAMERA_MODES), ("IR-LOCK and normal", {"irlock", "normal",
                                                                                      "cautious-irlock"})):
        group = [r for r in rows if r["name"] in names and r["vehicle_s"]]
        if group:
            print(f"  {label}: median {statistics.median(r['vehicle_s'] / r['wall_s'] for r in group):.2f}x "
                  f"real time per trial; {60.0 * len(group) / sum(r['wall_s'] for r in group):.2f} trials a "
                  f"minute a trial process")
    print(f"  all {len(rows)} trials in {elapsed_s:.0f} wall s on {args.workers} workers: "
          f"{60.0 * len(rows) / elapsed_s / args.workers:.2f} trials a minute a worker")
    return 0


if __name__ == "__main__":
    sys.exit(main())
