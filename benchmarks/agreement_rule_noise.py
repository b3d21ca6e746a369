"""How often `sitl_vs_embedded.py`'s agreement rule (means within 30 % or 3 cm) calls one model apart from
itself, on the thesis' Tables 3 to 5: what an agreement count from 10 or 20 seeds a scenario can tell.

The model is the embedded simulator as `sitl_vs_embedded.py` flies it beside SITL on preland's physics
(`copter-4.6` at SITL's physics step, with the EKF errors of that benchmark's latest record).

- **Other seeds:** the same model on seeds 0..N-1, in blocks of each size in `--blocks` (10 and 20 seeds a
  scenario, the comparison's former and present default); the rule between every ordered pair of blocks
  of a size (nothing differs but the seeds).
- **The same seeds, a nudged estimate:** seeds 0..B-1 (B the first block size) again with every EKF error
  `--nudge` larger and smaller (as two records' pooled EKF errors differ); the rule and the paired
  signed-rank test (Holm over the scenarios) of each beside the unchanged model. The seeds are shared, as
  SITL's and the embedded simulator's are in the comparison.

Usage: python benchmarks/agreement_rule_noise.py [--seeds 40] [--blocks 10,20] [--nudge 0.035] [--workers W]
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import re
import statistics
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from fault_scenarios_table import SCENARIOS, scenario_request  # noqa: E402
from sitl_vs_embedded import PAIRED_ALPHA, as_copter_4_6, signed_rank_p  # noqa: E402

from preland_app.campaign.fidelity_tests import holm  # noqa: E402
from preland_app.runtime.embedded import run_trial  # noqa: E402

RECORD = ROOT / "benchmarks" / "results" / "sitl_vs_embedded.json"
EKF_LINE = re.compile(r"roll and pitch error rms ([\d.]+) deg, horizontal velocity error rms ([\d.]+) m/s, "
                      r"position error \(high-passed over [\d.]+ s\) as position_noise_sigma_m ([\d.]+) m")
JUDGED = [label for label in SCENARIOS if SCENARIOS[label][0] != "normal"]


def recorded_navigation() -> dict[str, float]:
    """The EKF errors `sitl_vs_embedded.py` printed in its latest record."""
    found = EKF_LINE.search(json.loads(RECORD.read_text())["output"])
    if found is None:
        raise SystemExit(f"{RECORD}: no line with ArduCopter's EKF errors (run sitl_vs_embedded.py's record first)")
    attitude, velocity, position = (float(value) for value in found.groups())
    return {"attitude_noise_sigma_deg": attitude, "velocity_noise_sigma_m_s": velocity,
            "position_noise_sigma_m": position}


def fly(job: tuple[str, int, dict[str, float]]) -> tuple[str, int, float | None]:
    label, seed, navigation = job
    outcome = run_trial(as_copter_4_6(scenario_request(label, seed), navigation=navigation))
    return label, seed, outcome.landing_error_cm if outcome.outcome.value == "landed" else None


def agrees(a: float, b: float) -> bool:
    """`sitl_vs_embedded.py`'s rule, `b` in the embedded simulator's place."""
    return abs(a - b) <= max(0.3 * b, 3.0)


def _mean(errors: dict[int, float | None], seeds: range) -> float:
    return statistics.mean(errors[seed] for seed in seeds if errors[seed] is not None)


def _between_blocks(base: dict[str, dict[int, float | None]], size: int, seeds: int) -> None:
    blocks = [range(start, start + size) for start in range(0, seeds - size + 1, size)]
    print(f"\nmean landing error (cm) of each block of {size} seeds; lost: landings over 1 m")
    print(f"{'scenario':<22} " + " ".join(f"{f'{b.start}..{b.stop - 1}':>8}" for b in blocks) + "   lost")
    for label in JUDGED:
        lost = sum(e is not None and e > 100 for e in base[label].values())
        print(f"{label:<22} " + " ".join(f"{_mean(base[label], b):8.1f}" for b in blocks) + f"   {lost}/{seeds}")
    counts = []
    print(f"the rule between blocks of {size} (first in SITL's place): scenarios that agree, of {len(JUDGED)}")
    for first, second in itertools.permutations(range(len(blocks)), 2):
        a, b = blocks[first], blocks[second]
        apart = [label for label in JUDGED if not agrees(_mean(base[label], a), _mean(base[label], b))]
        counts.append(len(JUDGED) - len(apart))
        print(f"  {a.start}..{a.stop - 1} beside {b.start}..{b.stop - 1}: {counts[-1]}"
              + (f" (apart: {', '.join(apart)})" if apart else ""))
    print(f"blocks of {size}, agree over {len(counts)} ordered pairs: min {min(counts)}, median "
          f"{statistics.median(counts):g}, max {max(counts)}; at least 11 in {sum(c >= 11 for c in counts)} "
          f"of {len(counts)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=40)
    parser.add_argument("--blocks", default="10,20", help="comma-separated block sizes (seeds)")
    parser.add_argument("--nudge", type=float, default=0.035, help="relative change of each EKF error")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    args = parser.parse_args()
    sizes = [int(size) for size in args.blocks.split(",")]
    if min(sizes) < 1 or args.seeds < 2 * max(sizes):
        parser.error("--seeds: at least two blocks of each size")
    block = sizes[0]
    navigation = recorded_navigation()
    nudged = {f"{sign:+.1%}": {name: value * (1 + sign) for name, value in navigation.items()}
              for sign in (args.nudge, -args.nudge)}
    jobs = [(label, seed, navigation) for label in JUDGED for seed in range(args.seeds)]
    jobs += [(label, seed, each) for each in nudged.values() for label in JUDGED for seed in range(block)]
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        results = list(pool.map(fly, jobs, chunksize=2))
    base = {label: {} for label in JUDGED}
    for (label, seed, _), (_, _, error) in zip(jobs[:len(JUDGED) * args.seeds], results):
        base[label][seed] = error
    print(f"EKF errors (sitl_vs_embedded.py's record): roll and pitch {navigation['attitude_noise_sigma_deg']:g} "
          f"deg, velocity {navigation['velocity_noise_sigma_m_s']:g} m/s, "
          f"position {navigation['position_noise_sigma_m']:g} m")

    for size in sizes:
        _between_blocks(base, size, args.seeds)

    print(f"\nthe same seeds 0..{block - 1}, every EKF error nudged, beside the model unchanged")
    offset = len(JUDGED) * args.seeds
    for index, name in enumerate(nudged):
        chunk = results[offset + index * len(JUDGED) * block: offset + (index + 1) * len(JUDGED) * block]
        errors = {label: {} for label in JUDGED}
        for label, seed, error in chunk:
            errors[label][seed] = error
        seeds = range(block)
        apart, pvalues = [], {}
        for label in JUDGED:
            if not agrees(_mean(errors[label], seeds), _mean(base[label], seeds)):
                apart.append(f"{label} {_mean(errors[label], seeds):.1f}/{_mean(base[label], seeds):.1f}")
            shared = [s for s in seeds if errors[label][s] is not None and base[label][s] is not None]
            pvalues[label] = signed_rank_p([errors[label][s] - base[label][s] for s in shared])
        adjusted = holm({label: p for label, p in pvalues.items() if p is not None})
        differ = sum(p < PAIRED_ALPHA for p in adjusted.values())
        print(f"  {name}: the rule {len(JUDGED) - len(apart)} of {len(JUDGED)} agree"
              + (f" (apart, nudged/unchanged cm: {'; '.join(apart)})" if apart else "")
              + f"; paired test, Holm: {differ} differ at {PAIRED_ALPHA:g}")


if __name__ == "__main__":
    main()
