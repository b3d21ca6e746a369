"""Wall time of a whole campaign on the embedded simulator (default: campaigns/thesis_table3.yaml,
70 trials) with N worker processes, into a fresh results database.

Usage: python benchmarks/campaign_wall_time.py [--campaign FILE] [--workers N]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from preland_app.campaign.driver import run_campaign  # noqa: E402
from preland_app.campaign.spec import load_campaign  # noqa: E402
from preland_app.campaign.store import ResultsStore  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--campaign", default=str(ROOT / "campaigns" / "thesis_table3.yaml"))
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    args = parser.parse_args()
    campaign = load_campaign(args.campaign)
    with tempfile.TemporaryDirectory() as folder:
        with ResultsStore(Path(folder) / "results.db") as store:
            started = time.perf_counter()
            ran, total = run_campaign(campaign, store, workers=args.workers)
            elapsed = time.perf_counter() - started
            outcomes = [t["outcome"] for t in store.trials(campaign.name)]
    print(f"campaign {campaign.name}: {ran} trials with {args.workers} worker(s) on {os.cpu_count()} core(s): "
          f"{elapsed:.1f} s wall ({elapsed / max(1, ran):.2f} s per trial); "
          f"{outcomes.count('landed')} landed, {len(outcomes) - outcomes.count('landed')} other")


if __name__ == "__main__":
    main()
