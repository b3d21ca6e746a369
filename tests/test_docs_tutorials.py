"""The tutorials (docs/tutorials/*.md) run as a reader runs them: every shell and Python block, in page order.
The pages that fly a vehicle run from test_docs_tutorials_vehicle.py, through `check_tutorial`.

Conventions of the pages (this test is their only reader):

* ```sh blocks run in one `bash -euo pipefail` process per page, in page order, in a fresh folder holding
  copies of the repository's missions/, campaigns/ and profiles/ (so relative paths work as in a checkout),
  with preland's venv first on PATH. Background jobs (`... &`) are killed at the end.
* ```python blocks run in one Python process per page, in page order, sharing a namespace, in the same
  folder, after the page's sh blocks (a page's Python reads what its shell made, never the reverse).
* A block preceded by `<!-- file: NAME -->` is written to NAME (in page order, before the blocks after it
  run) and not executed; any language (yaml, python, toml).
* `<!-- not-run: REASON -->` before a block: shown, not run (building ArduPilot, a real drone's serial
  port). Each needs a reason, and a page has at most MAX_NOT_RUN of them.
* `<!-- output -->` before a ```text title="Output" block (the title shows on the site): what the reader sees. Each of its lines, in order, matches a
  line the page's commands printed (stdout and stderr); `...` in a line matches anything, a line that is
  only `...` is skipped.
* `<!-- stdin: A | B -->` before a ```sh block: what the reader types at its prompts, one item a line.
* Other blocks (```text, ```toml, ```yaml without `file:`) are shown, not run. No other shell languages.

Placeholders the test sets: `$ARDUCOPTER` (the SITL binary: $PRELAND_SITL_BINARY when set, else the stand-in
tests/tools/fake_sitl.py behind a wrapper script); the field page's UDP port 14550 becomes a free port and its
served vehicle's `--speedup 8` becomes STAND_IN_SPEEDUP.

`pip install` runs into a throwaway venv layered over preland's (its own site-packages first, then the
venv's), so the shared venv is never changed.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shlex
import shutil
import signal
import sqlite3
import subprocess
import sys
import sysconfig
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import yaml

from preland_app.runtime.sitl import SITL_ENV

from .conftest import ROOT
from .ports import free_udp_port
from .procs import alive

TUTORIALS = ROOT / "docs" / "tutorials"
PAGES = ["index.md", "first-mission.md", "first-campaign.md", "own-land-mode.md", "sitl.md", "field-trial.md"]
# The pages that fly a vehicle over MAVLink in wall time (a SITL, a served vehicle): test_docs_tutorials_vehicle.py
# runs them, so that `make test` runs them on another xdist worker while this module runs the others.
VEHICLE_PAGES = ["field-trial.md", "sitl.md"]
# This module's pages, the longest first: xdist hands a worker its next file once at most two of its tests are
# left, and those two should be short.
SIMULATED_PAGES = ["own-land-mode.md", "first-campaign.md", "first-mission.md", "index.md"]
MAX_NOT_RUN = 2
PAGE_TIMEOUT_S = 300
FIELD_PORT = "14550"
FIELD_SPEEDUP = "--speedup 8"
STAND_IN = ROOT / "tests" / "tools" / "fake_sitl.py"
# The speed-up of the simulated vehicles the pages fly against in wall time (the SITL stand-in, whatever preland
# asks of it, and the field page's `sim serve --speedup 8`). The companion must keep up with them over MAVLink:
# at 8x on a loaded 2-core CI machine a page's flight once ended as a lost link (the companion's MAVSDK
# callback blocked for more than a wall second) and a SITL campaign's trial did not land.
STAND_IN_SPEEDUP = 4
SHOWN_LANGUAGES = {"sh", "python", "yaml", "toml", "text"}
DIRECTIVE = re.compile(r"<!--\s*(file|not-run|output|stdin)\s*(?::\s*(.*?))?\s*-->")
FENCE = re.compile(r'^(?P<indent> *)```(?P<lang>[\w-]*)(?:\s+title="(?P<title>[^"]*)")?\s*$')


@dataclass
class Block:
    lang: str
    text: str
    line: int  # of the opening fence, 1-based
    directives: dict[str, str] = field(default_factory=dict)

    @property
    def runs(self) -> bool:
        return self.lang in ("sh", "python") and not {"file", "not-run"} & self.directives.keys()


def parse_blocks(text: str) -> list[Block]:
    """The fenced blocks of a page, each with the directive comments just above it (blank lines between)."""
    lines = text.splitlines()
    blocks, index = [], 0
    while index < len(lines):
        opening = FENCE.match(lines[index])
        if not opening:
            index += 1
            continue
        assert opening["lang"], f"line {index + 1}: a block without a language"
        indent, start = opening["indent"], index
        body = []
        index += 1
        while index < len(lines) and lines[index].rstrip() != f"{indent}```":
            body.append(lines[index][len(indent):] if lines[index].startswith(indent) else lines[index].lstrip())
            index += 1
        assert index < len(lines), f"line {start + 1}: the block is not closed"
        index += 1
        directives = {}
        above = start - 1
        while above >= 0 and not lines[above].strip():
            above -= 1
        while above >= 0 and (found := DIRECTIVE.fullmatch(lines[above].strip())):
            directives[found[1]] = found[2] or ""
            above -= 1
        blocks.append(Block(lang=opening["lang"], text="\n".join(body) + "\n", line=start + 1,
                            directives=directives))
    return blocks


# --- the environment a page runs in ----------------------------------------------------------------------

def overlay_venv(folder: Path) -> Path:
    """A venv whose own site-packages come first and preland's venv's after (so `pip install` lands here),
    with `python`, `pip` and `preland` in its bin; returns that bin."""
    import venv

    venv.EnvBuilder(with_pip=False, symlinks=True).create(folder)
    bin_dir = folder / "bin"
    python = bin_dir / "python"
    own = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                              capture_output=True, text=True, check=True, timeout=60).stdout.strip())
    shared = sysconfig.get_paths()["purelib"]  # preland's venv, which runs this test
    (own / "_preland_docs_overlay.pth").write_text(f"import site; site.addsitedir({shared!r})\n")
    (bin_dir / "pip").write_text(f'#!/bin/sh\nexec {shlex.quote(str(python))} -m pip "$@"\n')
    (bin_dir / "preland").write_text(f"#!{python}\nimport sys\nfrom preland_app.cli.app import main\n\n"
                                     "if __name__ == '__main__':  # campaign workers import this file\n"
                                     "    sys.exit(main())\n")
    for script in ("pip", "preland"):
        (bin_dir / script).chmod(0o755)
    return bin_dir


def sitl_binary(folder: Path) -> Path:
    """$PRELAND_SITL_BINARY when it is set, else a wrapper that runs the stand-in at STAND_IN_SPEEDUP."""
    real = os.environ.get(SITL_ENV)
    if real:
        return Path(real)
    wrapper = folder / "arducopter"
    wrapper.write_text(f'#!/bin/sh\nexec {shlex.quote(sys.executable)} {shlex.quote(str(STAND_IN))} "$@" '
                       f"--speedup {STAND_IN_SPEEDUP}\n")
    wrapper.chmod(0o755)
    return wrapper


@dataclass
class Run:
    cwd: Path
    output: str
    launches: Path
    port: str = FIELD_PORT

    def adapt(self, page: str, text: str) -> str:
        """The page's text as run: the field page's port is a free one, its vehicle's speed-up the tests' own."""
        if page != "field-trial.md":
            return text
        return text.replace(FIELD_PORT, self.port).replace(FIELD_SPEEDUP, f"--speedup {STAND_IN_SPEEDUP:g}")


PYTHON_DRIVER = """
import json, sys, traceback
namespace = {"__name__": "__main__"}
for name, source in json.load(open(sys.argv[1])):
    try:
        exec(compile(source, name, "exec"), namespace)
    except BaseException:
        traceback.print_exc()
        sys.exit(f"{name} failed")
"""


def run_page(page: str, blocks: list[Block], tmp_path: Path) -> Run:
    work = tmp_path / "work"
    work.mkdir()
    for folder in ("missions", "campaigns", "profiles"):
        shutil.copytree(ROOT / folder, work / folder)
    bin_dir = overlay_venv(tmp_path / "venv")
    launches = tmp_path / "sitl-launches"
    launches.mkdir()
    port = str(free_udp_port())
    adapt = Run(cwd=work, output="", launches=launches, port=port).adapt
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
           "ARDUCOPTER": str(sitl_binary(tmp_path)), "FAKE_SITL_LOG_DIR": str(launches), "MPLBACKEND": "Agg"}
    for name in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME"):
        env.pop(name, None)

    script = ["trap 'kill $(jobs -p) 2>/dev/null || true' EXIT"]
    python_blocks = []
    for number, block in enumerate(blocks):
        name = f"{page}:{block.line}"
        if "file" in block.directives:
            target = block.directives["file"]
            delimiter = "PRELAND_DOCS_EOF"
            assert delimiter not in block.text
            script += [f"# {name}", f"mkdir -p \"$(dirname {shlex.quote(target)})\"",
                       f"cat > {shlex.quote(target)} <<'{delimiter}'", block.text.rstrip("\n"), delimiter]
        elif block.runs and block.lang == "sh":
            body = adapt(page, block.text).rstrip("\n")
            if "stdin" in block.directives:
                typed = tmp_path / f"stdin-{number}"
                typed.write_text("".join(f"{item.strip()}\n" for item in block.directives["stdin"].split("|")))
                body = f"{{\n{body}\n}} < {shlex.quote(str(typed))}"
            script += [f"echo \"+ block {name} at ${{EPOCHREALTIME:-}}\" >&2", body]
        elif block.runs and block.lang == "python":
            python_blocks.append((name, adapt(page, block.text)))
    (tmp_path / "page.sh").write_text("\n".join(script) + "\n")
    commands = [["bash", "-euo", "pipefail", str(tmp_path / "page.sh")]]
    if python_blocks:
        (tmp_path / "page-python.json").write_text(json.dumps(python_blocks))
        commands.append([str(bin_dir / "python"), "-c", PYTHON_DRIVER, str(tmp_path / "page-python.json")])
    output = []
    for command in commands:
        process = subprocess.Popen(command, cwd=work, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                   stderr=subprocess.STDOUT, text=True, start_new_session=True)
        try:
            text, _ = process.communicate(timeout=PAGE_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            text, _ = process.communicate()
            pytest.fail(f"{page}: not done after {PAGE_TIMEOUT_S} s:\n{text[-4000:]}")
        finally:
            try:  # anything the page left running in its process group (a server, a SITL)
                os.killpg(process.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        output.append(text)
        (tmp_path / "output.txt").write_text("".join(output))  # to read after a failure
        assert process.returncode == 0, f"{page}: {command[0]} exited {process.returncode}:\n{text[-6000:]}"
    return Run(cwd=work, output="".join(output), launches=launches, port=port)


# --- checks common to every page -------------------------------------------------------------------------

def nav_pages() -> set[str]:
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text().replace("!!python", "python"))
    pages = set()

    def walk(entries):
        for entry in entries:
            if isinstance(entry, str):
                pages.add(entry)
            elif isinstance(entry, dict):
                for value in entry.values():
                    walk(value) if isinstance(value, list) else pages.add(value)

    walk(config["nav"])
    return pages


def check_links(page: str, text: str) -> None:
    """Relative links only, each to a page in mkdocs.yml's nav or to a figure the site builds."""
    pages = nav_pages()
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        assert not target.startswith(("/", "http://", "https://")), f"{page}: {target}: not a relative link"
        path = target.split("#")[0]
        resolved = os.path.normpath(os.path.join("tutorials", path))
        if resolved.startswith("figures/"):
            assert resolved.endswith(".png"), f"{page}: {target}"
        else:
            assert resolved in pages, f"{page}: {target} is not a page of the site's nav"


def check_shown_output(page: str, blocks: list[Block], run: Run) -> None:
    output = run.output
    printed = [line.strip() for line in output.splitlines()]
    for block in blocks:
        if "output" not in block.directives:
            continue
        assert block.lang == "text", f"{page}:{block.line}: output blocks are ```text"
        position = 0
        for shown in run.adapt(page, block.text).splitlines():
            shown = shown.strip()
            if not shown or shown == "...":
                continue
            pattern = re.compile(r"\s+".join(re.escape(word) for word in shown.split()).replace(r"\.\.\.", ".*"))
            for index in range(position, len(printed)):
                if pattern.fullmatch(printed[index]):
                    position = index + 1
                    break
            else:
                raise AssertionError(f"{page}:{block.line}: shown {shown!r}, not printed (in this order):\n{output}"
                                     f"{stored_outcomes(run.cwd)}")


def stored_outcomes(folder: Path) -> str:
    """Every trial's outcome and message in the stores a page wrote, for a failure's report."""
    lines = []
    for db in sorted(folder.glob("*.db")):
        with contextlib.closing(sqlite3.connect(db)) as connection:
            try:
                rows = connection.execute("SELECT scenario, trial_index, source, outcome, message FROM trials").fetchall()
            except sqlite3.Error as error:
                rows = [(f"unreadable: {error}",)]
        lines += [f"{db.name}: " + " | ".join(map(str, row)) for row in rows]
    return "\n--- stored trials ---\n" + "\n".join(lines) if lines else ""


def json_objects(output: str) -> list[dict]:
    """Every JSON object the page printed, compact (`--json`) or indented (`python -m json.tool`)."""
    decoder, found = json.JSONDecoder(), []
    offset = 0
    for line in output.splitlines(keepends=True):
        if line.startswith("{"):
            try:
                found.append(decoder.raw_decode(output, offset)[0])
            except json.JSONDecodeError:
                pass
        offset += len(line)
    return found


def trials(db: Path, campaign: str) -> list[dict]:
    assert db.exists(), f"{db} was not written"
    connection = sqlite3.connect(db)
    connection.row_factory = sqlite3.Row
    try:
        rows = connection.execute("SELECT * FROM trials WHERE campaign = ? ORDER BY scenario_index, trial_index, "
                                  "source", (campaign,)).fetchall()
    finally:
        connection.close()
    return [{**dict(row), "details": json.loads(row["details"])} for row in rows]


def report_files(folder: Path, campaign: str) -> None:
    for suffix in (".md", ".csv", "_errors.png", "_positions.png", "_trajectory.png"):
        path = folder / f"{campaign}{suffix}"
        assert path.is_file() and path.stat().st_size > 0, f"{path} was not written"


# --- what each page leads to -------------------------------------------------------------------------------

def check_index(run: Run, text: str) -> None:
    links = re.findall(r"\]\(([\w-]+\.md)\)", text)
    order = [page for page in PAGES if page != "index.md"]
    assert [link for link in dict.fromkeys(links) if link in order] == order, "the tutorials, in their order"


def check_first_mission(run: Run, text: str) -> None:
    flights = json_objects(run.output)
    assert flights and all(flight["outcome"] == "landed" for flight in flights)
    irlock = [flight for flight in flights if flight["land_mode"] == "irlock"]
    assert irlock and irlock[0]["seed"] == 2 and irlock[0]["scoring_reference"] == "pad"
    assert (run.cwd / "first.json").read_text() == (run.cwd / "again.json").read_text()  # same seed, same flight
    assert json.loads((run.cwd / "first.json").read_text())["landing_error_cm"] is not None
    assert re.search(r"land mode\s+marker", run.output) and re.search(r"take-off altitude\s+6.0 m", run.output)
    assert re.search(r"^seed 3: landed, [\d.]+ cm from the pad$", run.output, re.M)


def check_first_campaign(run: Run, text: str) -> None:
    rows = trials(run.cwd / "results.db", "first")
    assert len(rows) == 4 and {row["scenario"] for row in rows} == {"GPS only", "IR-LOCK / random 0.5"}
    assert all(row["outcome"] == "landed" and row["source"] == "sim" for row in rows)
    faulted = [row for row in rows if row["land_mode"] == "irlock"]
    assert all(row["details"]["irlock_fault"] == "random:0.5" and row["details"]["irlock_dropped"] > 0
               for row in faulted)
    report_files(run.cwd / "report", "first")
    assert (run.cwd / "trial.png").stat().st_size > 0
    assert "campaign first: 0 trial(s) run, 4 in results.db" in run.output  # --resume repeated nothing


def check_own_land_mode(run: Run, text: str) -> None:
    assert len(re.findall(r"^land mode\s+my_land:BeaconLand$", run.output, re.M)) == 2  # by import path
    assert len(re.findall(r"^outcome\s+landed ", run.output, re.M)) == 2
    assert re.search(r"^irlock dropped\s+[1-9]\d*$", run.output, re.M)  # the fault reached the plugin
    (by_name,) = [f for f in json_objects(run.output) if f["land_mode"] == "beacon_land"]
    assert by_name["outcome"] == "landed" and by_name["details"]["beacon_seen"] > 0
    rows = trials(run.cwd / "tuning.db", "tuning")
    assert len(rows) == 4 and all(row["outcome"] == "landed" and row["land_mode"] == "my_land:BeaconLand"
                                  for row in rows)
    assert all(row["details"]["beacon_seen"] > 0 for row in rows)
    report_files(run.cwd / "tuning-report", "tuning")
    assert re.search(r"^beacon_land\s+my-land 0\.1\.0\s+pad\s+irlock", run.output, re.M), "preland modes"
    assert not list(Path(sysconfig.get_paths()["purelib"]).glob("*my_land*"))  # the shared venv is unchanged


def check_sitl(run: Run, text: str) -> None:
    assert re.search(r"^runtime\s+sitl$", run.output, re.M) and re.search(r"^outcome\s+landed ", run.output, re.M)
    rows = trials(run.cwd / "sitl.db", "sitl_first")
    assert all(row["outcome"] == "landed" for row in rows)
    assert sorted(row["source"] for row in rows) == ["sim", "sim", "sitl", "sitl"]
    assert all(row["details"]["runtime"] == "sitl" for row in rows if row["source"] == "sitl")
    assert int(re.search(r"^(\d+)$", run.output, re.M)[1]) > 10  # HEARTBEATs in the telemetry log
    assert (run.cwd / "flight.tlog").stat().st_size > 10_000
    report_files(run.cwd / "sitl-report", "sitl_first")
    if not os.environ.get(SITL_ENV):  # every stand-in launched was stopped
        launched = [json.loads(p.read_text()) for p in run.launches.glob("*.json")]
        assert len(launched) >= 3
        assert not [launch for launch in launched if alive(launch["pid"], launch["started"])]


def check_field_trial(run: Run, text: str) -> None:
    assert "preflight: PLND_ENABLED is 0" in run.output
    rows = trials(run.cwd / "rehearsal.db", "field_day")
    simulated = [row for row in rows if row["source"] == "sim"]
    (field_trial,) = [row for row in rows if row["source"] == "field"]
    assert len(simulated) == 3 and all(row["outcome"] == "landed" for row in simulated)
    assert field_trial["scenario"] == "IR-LOCK" and field_trial["landing_error_cm"] == 3.0
    assert field_trial["offset_north_cm"] == 1.8 and field_trial["offset_east_cm"] == -2.4
    assert "recorded field trial 0 of field_day / IR-LOCK: 3 cm" in run.output
    assert (run.cwd / "flight.tlog").stat().st_size > 10_000
    assert re.search(r"runtime\s+mavlink", run.output)
    assert "| IR-LOCK [field] |" in (run.cwd / "rehearsal-report" / "field_day.md").read_text()


CHECKS = {"index.md": check_index, "first-mission.md": check_first_mission,
          "first-campaign.md": check_first_campaign, "own-land-mode.md": check_own_land_mode,
          "sitl.md": check_sitl, "field-trial.md": check_field_trial}


def test_every_page_is_run_by_one_module():
    assert sorted(VEHICLE_PAGES + SIMULATED_PAGES) == sorted(PAGES) == sorted(CHECKS)
    assert sorted(path.name for path in TUTORIALS.glob("*.md")) == sorted(PAGES)


@pytest.mark.parametrize("page", SIMULATED_PAGES)
def test_tutorial(page, tmp_path):
    check_tutorial(page, tmp_path)


def check_tutorial(page: str, tmp_path: Path) -> None:
    """Run `page` as a reader runs it, in `tmp_path`, and check what it shows and leads to."""
    text = (TUTORIALS / page).read_text()
    lines = len(text.splitlines())
    assert page == "index.md" or 60 <= lines <= 200, f"{page}: {lines} lines"
    blocks = parse_blocks(text)
    for block in blocks:
        assert block.lang in SHOWN_LANGUAGES, f"{page}:{block.line}: ```{block.lang}"
    not_run = [block for block in blocks if "not-run" in block.directives]
    assert all(block.directives["not-run"] for block in not_run), f"{page}: a not-run block without a reason"
    assert len(not_run) <= MAX_NOT_RUN, f"{page}: {len(not_run)} blocks not run"
    check_links(page, text)
    run = run_page(page, blocks, tmp_path) if any(b.runs or "file" in b.directives for b in blocks) else \
        Run(cwd=tmp_path, output="", launches=tmp_path)
    check_shown_output(page, blocks, run)
    CHECKS[page](run, text)
