"""The published figures a stored campaign names for its scenarios (`reference:`), read back from the store."""

from __future__ import annotations

from pathlib import Path

import yaml

from ..config.loader import build
from .spec import ReferenceSpec
from .store import ResultsStore


def stored_references(store: ResultsStore, campaign: str) -> tuple[dict[str, ReferenceSpec], Path | None]:
    """The published references of a stored campaign's scenarios (by label), read from the campaign text the
    store keeps, and the folder its relative paths start from (None when the store has no path)."""
    stored = store.campaign_text(campaign)
    if stored is None:
        return {}, None
    text, source_path = stored
    base = Path(source_path).parent if source_path else None
    try:
        data = yaml.safe_load(text) or {}
    except yaml.YAMLError:
        return {}, base
    references = {}
    for scenario in data.get("scenarios", []) or []:
        if isinstance(scenario, dict) and isinstance(scenario.get("reference"), dict):
            references[str(scenario.get("label"))] = build(ReferenceSpec, scenario["reference"],
                                                           path=source_path or campaign, field="reference")
    return references, base
