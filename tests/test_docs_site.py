"""The docs: the site builds in strict mode with its pictures, the generated reference is what the code gives
now, a real browser finds the pages' headings, and the README stays short and true."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from .conftest import ROOT
from .tools import browser


# The pictures the build makes (docs/figures/), each linked from at least one page: the diagrams sized for page
# width, the report's own figures wider.
DIAGRAMS = ("mission", "data-flow", "pad-thesis", "pad-paper", "cautious-states", "module-map")
REPORT_FIGURES = ("report-errors", "report-positions", "report-trajectory", "report-ecdf")
FIGURES = DIAGRAMS + REPORT_FIGURES
PNG_LIMIT_BYTES = 300_000
HISTORY_WORDS = re.compile(r"this stop|previous stop|the version before|last stop", re.IGNORECASE)


def _module(path: Path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site, built once for the module as `make docs` builds it (strict), as a preview: the report's
    figures from 1 trial a scenario (what they show is tested in test_docs_figures.py)."""
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1", "DISABLE_MKDOCS_2_WARNING": "true", "PRELAND_DOCS_TRIALS": "1"}
    result = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
                            cwd=ROOT, capture_output=True, text=True, timeout=900, env=env)
    assert result.returncode == 0, result.stderr[-4000:]
    return out


def check_png(path: Path, *, min_width: int = 900, max_width: int = 2300) -> None:
    """A readable PNG of a size for the site, not blank."""
    assert path.is_file(), path
    assert path.stat().st_size <= PNG_LIMIT_BYTES, (path.name, path.stat().st_size)
    image = cv2.imread(str(path))
    assert image is not None, path
    height, width = image.shape[:2]
    assert min_width <= width <= max_width and 300 <= height <= 2400, (path.name, width, height)
    assert image.std() > 10, f"{path.name} is blank"


def test_the_generated_reference_is_what_the_code_gives_now():
    reference = _module(ROOT / "docs" / "scripts" / "reference.py")
    assert reference.stale_pages() == [], "run: python docs/scripts/reference.py"


def test_a_changed_option_makes_the_reference_stale(monkeypatch):
    # The check is not idle: a help text changed in the app shows as a stale CLI page.
    reference = _module(ROOT / "docs" / "scripts" / "reference.py")
    import typer.main

    from preland_app.cli import app

    command = typer.main.get_command(app)
    fly = command.commands["fly"]
    monkeypatch.setattr(typer.main, "get_command", lambda _app: command)
    monkeypatch.setattr(fly, "help", fly.help + " (changed)")
    assert reference.stale_pages() == ["cli.md"]


def test_the_reference_states_the_checks_the_loader_makes():
    text = (ROOT / "docs" / "reference" / "mission.md").read_text()
    # From PathSpec.__post_init__: the range the loader enforces appears beside the field.
    assert re.search(r"\| `acceptance_radius_m` \| number \| `0\.2` \| must be within 0\.05\.\.10 m \|", text)
    cli = (ROOT / "docs" / "reference" / "cli.md").read_text()
    assert "### `preland fly`" in cli and "`--seed`" in cli


def test_the_site_builds_strictly_with_every_picture(site):
    assert (site / "index.html").is_file() and (site / "reference" / "cli" / "index.html").is_file()
    assert sorted(path.stem for path in (site / "figures").iterdir()) == sorted(FIGURES)
    for name in DIAGRAMS:
        check_png(site / "figures" / f"{name}.png", max_width=1500)
    for name in REPORT_FIGURES:
        check_png(site / "figures" / f"{name}.png")
    pages = "".join(path.read_text() for path in (ROOT / "docs").rglob("*.md"))
    for name in FIGURES:
        assert f"figures/{name}.png" in pages, f"no page shows {name}.png"
    api = (site / "reference" / "api" / "index.html").read_text()
    assert "run_campaign" in api and "landing_error_cm" in api  # rendered from the docstrings
    bench = (site / "benchmarks" / "index.html").read_text()
    assert "fault_scenarios_table.py" in bench


@pytest.mark.skipif(browser.chromium() is None, reason="no Chromium on this machine (apt-get install chromium)")
def test_headless_chromium_finds_the_home_page_and_the_cli_reference(site):
    port = browser.free_port()
    server = subprocess.Popen([sys.executable, "-m", "http.server", str(port), "--bind", "127.0.0.1",
                               "--directory", str(site)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        base = f"http://127.0.0.1:{port}"
        browser.wait_for_http(base + "/index.html", timeout_s=30, process=server)
        home = browser.dom(base + "/index.html")
        assert re.search(r"<h1[^>]*>preland", home)
        assert "Where to start" in home and "figures/mission.png" in home
        cli = browser.dom(base + "/reference/cli/")
        assert re.search(r"<h1[^>]*>Command line", cli)
        assert "preland campaign run" in cli and "preland sim serve" in cli
    finally:
        server.terminate()
        server.wait(timeout=10)


def test_the_readme_is_short_and_its_picture_is_what_its_script_draws(tmp_path, monkeypatch):
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 150
    assert "docs/assets/mission.png" in readme and "python docs/figures/mission.py docs/assets" in readme
    monkeypatch.syspath_prepend(str(ROOT / "docs" / "figures"))  # its shared helpers
    made = _module(ROOT / "docs" / "figures" / "mission.py").make(tmp_path)
    fresh = cv2.imread(str(next(p for p in made if p.name == "mission.png")))
    shipped = cv2.imread(str(ROOT / "docs" / "assets" / "mission.png"))
    assert shipped is not None and fresh.shape == shipped.shape
    assert np.mean(np.abs(fresh.astype(int) - shipped.astype(int))) < 1.0, "run: python docs/figures/mission.py docs/assets"


def test_the_docs_state_the_present():
    for path in [ROOT / "README.md", *(ROOT / "docs").rglob("*.md")]:
        found = HISTORY_WORDS.search(path.read_text())
        assert found is None, f"{path.relative_to(ROOT)}: {found.group(0)!r}: history belongs in CHANGELOG.md"


def test_citation_and_licence_match_the_sources_and_the_package():
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    titles = {reference["title"] for reference in citation["references"]}
    seeds = ROOT.parent / "shared" / "seeds"
    if seeds.is_dir():  # the sources' own title pages, where this checkout has them beside it
        text = " ".join(path.read_text() for path in seeds.glob("*.txt"))
        for title in titles:
            assert title in text, title
    assert titles == {"Precision landing for drones combining infrared and visible light sensors",
                      "Accurate Landing of Unmanned Aerial Vehicles Using Ground Pattern Recognition"}
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert 'license = "MIT"' in pyproject and citation["license"] == "MIT"
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")
    assert 'readme = "README.md"' not in pyproject
