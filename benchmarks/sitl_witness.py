"""ArduPilot SITL as the second witness on the thesis' Table 3: the report's fidelity section for the embedded
simulator and for SITL on preland's world, side by side.

Flies `campaigns/thesis_table3.yaml` on the embedded simulator (`--sim-trials` a scenario, default 100, so the
simulated side's own spread does not decide a verdict) and on the SITL binary in lock-step on preland's
physics (`sitl:BIN?physics=preland`, `--sitl-trials` a scenario, default 20) into one store, then prints the
campaign report's fidelity section: each witness's rows against the field trials, the tests per scenario
(Mann-Whitney U, Holm-corrected over each witness's scenarios), the area metric beside its sampling floor and
Spearman beside its noise ceiling. `--db` keeps the store (and resumes it when the run was cut short).

Usage: python benchmarks/sitl_witness.py --sitl PATH [--sim-trials 100] [--sitl-trials 20] [--workers 2]
       [--db PATH]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import preland_app as preland  # noqa: E402
from preland_app.campaign.spec import load_campaign  # noqa: E402

CAMPAIGN = ROOT / "campaigns" / "thesis_table3.yaml"
FIDELITY_HEADING = "## Fidelity to the field"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sitl", required=True, help="the arducopter SITL binary")
    parser.add_argument("--sim-trials", type=int, default=100)
    parser.add_argument("--sitl-trials", type=int, default=20)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--db", type=Path, default=None)
    args = parser.parse_args()
    campaign = load_campaign(CAMPAIGN)
    with tempfile.TemporaryDirectory() as folder:
        db = args.db or Path(folder) / "witness.db"
        for label, trials, runtime in (("embedded", args.sim_trials, "sim:"),
                                       (f"ArduPilot SITL ({args.sitl})", args.sitl_trials,
                                        f"sitl:{args.sitl}?physics=preland")):
            started = time.perf_counter()
            run = preland.run_campaign(replace(campaign, trials=trials), db=db, workers=args.workers,
                                       runtime=runtime, resume=True)
            rows = [r for r in preland.read_results(db, campaign=campaign.name)
                    if r["source"] == ("sim" if runtime == "sim:" else "sitl")]
            landed = sum(r["outcome"] == "landed" for r in rows)
            print(f"{label}: {run.ran} trials flown now, {len(rows)} stored ({landed} landed), "
                  f"{time.perf_counter() - started:.0f} s wall on {args.workers} workers", flush=True)
        written = preland.write_campaign_report(db, campaign.name, Path(folder) / "report", figure_format="svg")
        text = written[0].read_text(encoding="utf-8")
    section = text[text.index(FIDELITY_HEADING):] if FIDELITY_HEADING in text else "(no fidelity section)"
    print()
    print("\n".join(line for line in section.splitlines() if not line.startswith("![")).rstrip())
    return 0


if __name__ == "__main__":
    sys.exit(main())
