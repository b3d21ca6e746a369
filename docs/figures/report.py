"""figures/report-errors.png, figures/report-positions.png, figures/report-trajectory.png: the report's
figures of the thesis' Table 3 campaign, as `make campaign` writes them, at web resolution.

The campaign really runs (70 trials on the embedded simulator, one worker: under a minute) into a
temporary store, and the report writer draws its figures from it; nothing is drawn here.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import sys
import tempfile
from pathlib import Path

if __name__ == "__main__":  # run alone: no __pycache__ in docs/, the site's source
    sys.dont_write_bytecode = True
import _figkit  # noqa: E402

from preland_app.api import load_campaign, run_campaign, write_campaign_report  # noqa: E402

CAMPAIGN = _figkit.ROOT / "campaigns" / "thesis_table3.yaml"
WORKERS = 1  # one core: the test suite builds the docs beside its real-time MAVLink tests
KINDS = ("errors", "positions", "trajectory")  # the report writer's figures, as `CAMPAIGN_KIND.png`
# A preview build (`PRELAND_DOCS_TRIALS=2 mkdocs serve`, and the test suite's build) runs the campaign with this
# many trials a scenario instead of its own: the same figures, drawn from fewer trials, in a few seconds.
PREVIEW_TRIALS_ENV = "PRELAND_DOCS_TRIALS"


def preview_trials() -> int | None:
    """Trials a scenario for a preview build ($PRELAND_DOCS_TRIALS), or None for the campaign's own."""
    text = os.environ.get(PREVIEW_TRIALS_ENV, "").strip()
    if not text:
        return None
    if not text.isdigit() or int(text) < 1:
        raise ValueError(f"{PREVIEW_TRIALS_ENV}: must be a whole number of trials >= 1, got {text!r}")
    return int(text)


def site_name(path: Path, campaign: str) -> str | None:
    """`report-KIND.png` for the report writer's `CAMPAIGN_KIND.png`; None for its other files."""
    prefix = f"{campaign}_"
    if path.suffix != ".png" or not path.stem.startswith(prefix):
        return None
    return f"report-{path.stem[len(prefix):]}.png"


def make(out_dir: Path, campaign_file: Path = CAMPAIGN, workers: int = WORKERS,
         trials: int | None = None) -> list[Path]:
    """The report's figures of `campaign_file`, each scenario with `trials` trials (default: the campaign's
    own, or $PRELAND_DOCS_TRIALS in a preview build)."""
    campaign = load_campaign(campaign_file)
    name = campaign.name
    trials = trials if trials is not None else preview_trials()
    if trials is not None:
        campaign = dataclasses.replace(campaign, trials=trials, scenarios=tuple(
            dataclasses.replace(scenario, trials=None) for scenario in campaign.scenarios))
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as folder:
        db = Path(folder) / "results.db"
        run_campaign(campaign, db=db, workers=workers)
        written = write_campaign_report(db, name, Path(folder) / "report", figure_format="png", dpi=_figkit.DPI)
        published = []
        for path in written:
            site = site_name(path, name)
            if site is not None:
                published.append(Path(shutil.copyfile(path, out_dir / site)))
    missing = {f"report-{kind}.png" for kind in KINDS} - {p.name for p in published}
    if missing:  # the trajectory figure needs a landed trial: a campaign that has none is not the thesis'
        raise RuntimeError(f"{campaign_file.name}: the report wrote no {', '.join(sorted(missing))}")
    return sorted(_figkit.fit(path) for path in published)


if __name__ == "__main__":
    _figkit.run_alone(make)
