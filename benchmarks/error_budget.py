"""Error budget: what each modelled error source adds to the mean landing error in the thesis scenarios.

Every scenario is flown with all sources on, then once with each source switched off in turn, on the
same seeds (common random numbers: each source has its own random stream, so switching one off leaves
the others' draws as they were). A source's contribution is the all-on mean minus its switched-off mean
(cm; negative: the source happens to help on these seeds). The last rows fly with every source off, and
the seed-to-seed spread of the all-on mean. Each row names where the source's magnitude comes from.

Where each source's magnitude comes from is in `preland_app/sim/error_sources.py` (the docs' error-source
reference is generated from it).

Usage: python benchmarks/error_budget.py [--seeds N] [--workers W] [--only LABEL,...] [--out FILE]
(`--out` also writes the printed table to FILE.)
Default: 4 seeds of 3 scenarios (a few minutes on 2 cores); use --seeds 20 for figures to quote.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from fault_scenarios_table import CALM, GUSTY, SCENARIOS  # noqa: E402

from preland_app.config.mission import MissionSpec, load_mission  # noqa: E402
from preland_app.runtime.embedded import TrialRequest, run_trial  # noqa: E402
from preland_app.sim.error_sources import ERROR_SOURCES, switched_off  # noqa: E402

DEFAULT_SCENARIOS = ("T3 irlock", "T3 irlock below3", "T5 default")


# Every source the mission switches on by default (the rotor wash is off unless a profile sets it).
SOURCES = {source.name: source for source in ERROR_SOURCES if source.defaults() != source.off}


def _mission(label: str, off: tuple[str, ...]) -> MissionSpec:
    mission = load_mission(ROOT / "missions" / "thesis_square_land.yaml")
    wind = CALM if label.startswith("T3") else GUSTY
    mission = replace(mission, environment=replace(mission.environment, wind=replace(mission.environment.wind,
                                                                                     **wind)))
    return switched_off(mission, *(SOURCES[name] for name in off))


def _one(job: tuple[str, tuple[str, ...], int]) -> tuple[str, tuple[str, ...], int, float | None]:
    label, off, seed = job
    mode, sensor, faults, height, *_ = SCENARIOS[label]
    outcome = run_trial(TrialRequest(mission=_mission(label, off), seed=seed, land_mode=mode,
                                     sensor=sensor, faults=faults, takeoff_altitude_rel_m=float(height),
                                     record_trajectory=False))
    return label, off, seed, outcome.landing_error_cm


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--only", default=",".join(DEFAULT_SCENARIOS), help="comma-separated scenario labels")
    parser.add_argument("--out", default="", help="also write the table to this file")
    args = parser.parse_args()
    labels = [label for label in args.only.split(",") if label]
    unknown = [label for label in labels if label not in SCENARIOS]
    if unknown:
        print(f"error_budget.py: --only: unknown scenario {unknown[0]!r} (known: {', '.join(SCENARIOS)})",
              file=sys.stderr)
        raise SystemExit(2)
    variants: list[tuple[str, ...]] = [(), *[(name,) for name in SOURCES], tuple(SOURCES)]
    jobs = [(label, variant, seed) for variant in variants for label in labels for seed in range(args.seeds)]
    started = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        results = list(pool.map(_one, jobs, chunksize=1))

    lines = budget_lines(results, labels, args.seeds)
    lines.append(f"wall time {time.perf_counter() - started:.1f} s with {args.workers} worker(s), {len(jobs)} trials")
    print("\n".join(lines))
    if args.out:
        Path(args.out).write_text("\n".join(lines[:-1]) + "\n", encoding="utf-8")


def budget_lines(results: list[tuple], labels: list[str], seeds: int) -> list[str]:
    """The printed table, one row per source."""
    out: list[str] = []
    add = out.append

    def mean(label: str, variant: tuple[str, ...]) -> float:
        errors = [r[3] for r in results if r[0] == label and r[1] == variant and r[3] is not None]
        return statistics.mean(errors) if errors else float("nan")

    short = {label: label.replace("T3 ", "").replace("T5 ", "T5 ")[:12] for label in labels}
    add(f"error budget: contribution of each source to the mean landing error (cm), {seeds} seeds, "
          f"all-on mean minus the mean with that source off")
    header = f"{'source':<24}" + "".join(f"{short[label]:>13}" for label in labels) + f"{'mean':>8}"
    add(header)
    all_on = {label: mean(label, ()) for label in labels}
    for name in SOURCES:
        row = [all_on[label] - mean(label, (name,)) for label in labels]
        add(f"{name:<24}" + "".join(f"{value:>+13.1f}" for value in row) + f"{statistics.mean(row):>+8.1f}")
    add(f"{'all on (mean)':<24}" + "".join(f"{all_on[label]:>13.1f}" for label in labels))
    add(f"{'all off (mean)':<24}" + "".join(f"{mean(label, tuple(SOURCES)):>13.1f}" for label in labels))
    spreads = []
    for label in labels:
        errors = [r[3] for r in results if r[0] == label and r[1] == () and r[3] is not None]
        spreads.append(statistics.stdev(errors) / len(errors) ** 0.5 if len(errors) > 1 else float("nan"))
    add(f"{'all-on mean: std error':<24}" + "".join(f"{value:>13.1f}" for value in spreads))
    return out


if __name__ == "__main__":
    main()
