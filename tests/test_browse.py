"""The store in Datasette: metadata with units and descriptions, canned queries, and the page in a real
headless browser."""

import json
import re
import sqlite3

import pytest
from typer.testing import CliRunner

from preland_app.campaign import browse
from preland_app.cli import app

from .test_field_records import seeded_store
from .tools import browser


def test_metadata_gives_units_descriptions_and_canned_queries_that_run(tmp_path):
    db = seeded_store(tmp_path / "results.db")
    assert CliRunner().invoke(app, ["trial", "record", str(db), "thesis_table3", "IRLock / none",
                                    "--error-cm", "6"]).exit_code == 0
    out = tmp_path / "metadata.json"
    result = CliRunner().invoke(app, ["campaign", "browse", str(db), "--metadata", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    trials = data["databases"]["results"]["tables"]["trials"]
    assert trials["units"]["landing_error_cm"] == "cm" and trials["units"]["landing_time_s"] == "s"
    assert set(trials["columns"]) >= {"landing_error_cm", "source", "audit", "details"}
    queries = data["databases"]["results"]["queries"]
    with sqlite3.connect(db) as connection:
        connection.row_factory = sqlite3.Row
        rows = [dict(r) for r in connection.execute(queries["thesis_table"]["sql"], {"campaign": "thesis_table3"})]
        assert [(r["scenario"], r["source"], r["trials"]) for r in rows] == [
            ("None / none", "sim", 2), ("IRLock / none", "sim", 2), ("IRLock / none", "field", 1)]
        assert rows[1]["avg_error_cm"] == 3.5 and rows[2]["avg_error_cm"] == 6.0
        overview = [dict(r) for r in connection.execute(queries["campaigns_overview"]["sql"])]
        assert overview[0]["campaign"] == "thesis_table3" and overview[0]["sim"] == 4 and overview[0]["field"] == 1
        side = [dict(r) for r in connection.execute(queries["field_beside_simulated"]["sql"],
                                                    {"campaign": "thesis_table3"})]
        assert side[1]["field_avg_error_cm"] == 6.0 and side[1]["sim_avg_error_cm"] == 3.5
        assert list(connection.execute(queries["paper_measures"]["sql"], {"campaign": "thesis_table3"})) == []


def test_browse_without_datasette_says_how_to_install_it(tmp_path, monkeypatch):
    db = seeded_store(tmp_path / "results.db")
    monkeypatch.setattr(browse, "datasette_available", lambda: False)
    result = CliRunner().invoke(app, ["campaign", "browse", str(db)])
    assert result.exit_code == 2 and "pip install 'preland[browse]'" in result.stderr


@pytest.mark.skipif(not browse.datasette_available(), reason="Datasette is not installed (the browse extra)")
@pytest.mark.skipif(browser.chromium() is None, reason="no Chromium on this machine (apt-get install chromium)")
def test_the_datasette_page_lists_campaigns_and_runs_a_canned_query_in_headless_chromium(tmp_path):
    db = seeded_store(tmp_path / "results.db")
    assert CliRunner().invoke(app, ["trial", "record", str(db), "field_day", "hover", "--error-cm", "6",
                                    "--new"]).exit_code == 0
    port = browser.free_port()
    server = browse.start(db, tmp_path / "metadata.json", port=port)
    try:
        base = f"http://127.0.0.1:{port}/results"
        browser.wait_for_http(base + ".json", timeout_s=30, process=server)
        page = browser.dom(base + "/campaigns_overview")
        assert "Campaigns: scenarios and trials per source" in page
        assert "thesis_table3" in page and "field_day" in page
        page = browser.dom(base + "/thesis_table?campaign=thesis_table3")
        assert "Thesis table: per-scenario figures of a campaign" in page
        assert "IRLock / none" in page and "None / none" in page and ">3.5<" in page.replace(" ", "")
        page = browser.dom(base + "/trials?source=field")
        assert "field_day" in page
        # The unit from the metadata: Datasette shows the error as a quantity (it picks the prefix: 60 mm).
        cell = re.search(r'col-landing_error_cm type-Quantity">([0-9.]+)(?:&nbsp;|\xa0| )(mm|cm|m)<', page)
        assert cell is not None
        assert float(cell.group(1)) * {"mm": 0.1, "cm": 1.0, "m": 100.0}[cell.group(2)] == pytest.approx(6.0)
    finally:
        server.terminate()
        server.wait(timeout=10)
