"""The thesis' random-drop cost on every witness: a scenario with drops against the same scenario without, on
the embedded simulator and on each ArduPilot SITL binary given, beside the field trials.

The thesis' Table 3 measured IR-LOCK landings with 75 % of the readings dropped at random 16.1 cm worse than
without (21.86 against 5.79 cm; Mann-Whitney p 0.004 over its 10 + 10 field trials). This flies the pair on
the same seeds, in Table 3's near-calm air, on the embedded autopilot and on each SITL binary in lock-step
on preland's physics (`sitl:BIN?physics=preland`: the same vehicle, wind, sensors and faults; only the
autopilot differs), and prints per witness: each scenario's landings, mean, median and sd of the landing
error (cm), the cost (difference of means, cm) with a 95 % bootstrap interval (10,000 seeded resamples), and
a two-sided Mann-Whitney U test of the errors with drops against those without.

Usage: python benchmarks/drop_cost_witnesses.py [--seeds 20] [--workers 2]
       [--sitl LABEL=PATH ...] [--pair "T3 irlock,T3 irlock random0.75"]
(--sitl is repeatable, e.g. --sitl 4.6.3=/path/arducopter --sitl 2020-10-15=/path/arducopter.)
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import numpy as np  # noqa: E402
from fault_scenarios_table import FIELD_TABLE, SCENARIOS, field_trials, scenario_request  # noqa: E402
from scipy.stats import mannwhitneyu  # noqa: E402

from preland_app.runtime.embedded import run_trial  # noqa: E402
from preland_app.runtime.sitl import SitlOptions, run_sitl_trial  # noqa: E402

EMBEDDED = "embedded"


def _one(job: tuple[str, str | None, str, int]) -> tuple[str, str, int, str, float | None, str]:
    """(witness, scenario, seed, outcome, landing error cm, message)"""
    witness, binary, label, seed = job
    request = scenario_request(label, seed)
    if binary is None:
        outcome = run_trial(request)
    else:
        outcome = run_sitl_trial(request, options=SitlOptions(binary=Path(binary), physics="preland"))
    return witness, label, seed, outcome.outcome.value, outcome.landing_error_cm, outcome.message or ""


def _init_worker() -> None:
    import cv2

    cv2.setNumThreads(1)


def bootstrap_cost_ci(with_drops: list[float], without: list[float], *, resamples: int = 10_000,
                      seed: int = 0) -> tuple[float, float]:
    """95 % percentile interval of mean(with_drops) - mean(without), each resampled with replacement."""
    rng = np.random.default_rng(seed)
    a, b = np.asarray(with_drops), np.asarray(without)
    costs = (rng.choice(a, (resamples, a.size)).mean(axis=1) - rng.choice(b, (resamples, b.size)).mean(axis=1))
    low, high = np.percentile(costs, [2.5, 97.5])
    return float(low), float(high)


def pair_lines(name: str, pair: tuple[str, str], errors: dict[str, list[float]], counts: dict[str, str]) -> list[str]:
    """The two scenarios' rows and the cost line of one witness."""
    out = []
    for label in pair:
        values = errors[label]
        out.append(f"{name:<22} {label:<24} {counts[label]:>7} {statistics.mean(values):>7.2f} "
                   f"{statistics.median(values):>7.2f} {statistics.stdev(values):>7.2f}")
    without, with_drops = errors[pair[0]], errors[pair[1]]
    low, high = bootstrap_cost_ci(with_drops, without)
    p = float(mannwhitneyu(with_drops, without, alternative="two-sided").pvalue)
    out.append(f"{name:<22} {'cost':<24} {'':>7} {statistics.mean(with_drops) - statistics.mean(without):>+7.2f} "
               f"95% CI {low:+.2f}..{high:+.2f}  Mann-Whitney p {p:.3f}")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--sitl", action="append", default=[], metavar="LABEL=PATH")
    parser.add_argument("--pair", default="T3 irlock,T3 irlock random0.75")
    args = parser.parse_args()
    pair = tuple(label.strip() for label in args.pair.split(","))
    if len(pair) != 2 or any(label not in SCENARIOS for label in pair):
        parser.error(f"--pair: two scenarios of benchmarks/fault_scenarios_table.py, got {args.pair!r}")
    witnesses: list[tuple[str, str | None]] = [(EMBEDDED, None)]
    for item in args.sitl:
        label, _, path = item.partition("=")
        if not path or not Path(path).is_file():
            parser.error(f"--sitl {item!r}: expected LABEL=PATH to an arducopter SITL binary")
        witnesses.append((f"SITL {label}", path))
    jobs = [(name, binary, label, seed) for name, binary in witnesses for label in pair
            for seed in range(1, args.seeds + 1)]
    started = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers, initializer=_init_worker) as pool:
        results = list(pool.map(_one, jobs, chunksize=1))

    print(f"the random-drop cost on each witness: {pair[1]!r} against {pair[0]!r}, seeds 1..{args.seeds}, "
          "Table 3's near-calm air")
    print(f"{'witness':<22} {'scenario':<24} {'landed':>7} {'mean':>7} {'median':>7} {'sd':>7}")
    field = field_trials()
    field_errors = {label: [error for error, _ in field[FIELD_TABLE[label]]] for label in pair}
    print("\n".join(pair_lines("field (thesis)", pair, field_errors,
                               {label: f"{len(field_errors[label])}" for label in pair})))
    for name, _ in witnesses:
        rows = {label: [r for r in results if r[0] == name and r[1] == label] for label in pair}
        errors = {label: [r[4] for r in rows[label] if r[3] == "landed" and r[4] is not None] for label in pair}
        counts = {label: f"{len(errors[label])}/{len(rows[label])}" for label in pair}
        if all(len(values) >= 2 for values in errors.values()):
            print("\n".join(pair_lines(name, pair, errors, counts)))
        for row in (r for label in pair for r in rows[label] if r[3] != "landed"):
            print(f"{name:<22} {row[1]:<24} seed {row[2]}: {row[3]} ({row[5]})")
    print(f"wall time {time.perf_counter() - started:.1f} s with {args.workers} worker(s), {len(jobs)} trials")


if __name__ == "__main__":
    main()
