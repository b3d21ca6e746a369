"""The documentation's figures (docs/figures/): every module is found, the diagrams are derived from the code, and
build.py publishes through mkdocs-gen-files' open.

The pictures themselves (readable PNGs at the site paths the pages link to) are checked in the site the docs
build test builds (test_docs_site.py), which makes every one of them.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ROOT / "docs" / "figures"
PACKAGE = ROOT / "preland_app"

# The figure modules (their pictures are checked in the built site, test_docs_site.py).
EXPECTED = {"mission", "data_flow", "pads", "cautious_states", "module_map", "report"}


def _load_build():
    name = "preland_docs_figures_build_under_test"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, FIGURES / "build.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


@pytest.fixture(scope="module")
def build():
    return _load_build()


@pytest.fixture(scope="module")
def modules(build):
    had_cache = (FIGURES / "__pycache__").exists()
    loaded = {module.__name__.removeprefix(build.MODULE_PREFIX): module for module in build.figure_modules()}
    # mkdocs would publish a __pycache__ under docs/ as site files.
    assert had_cache or not (FIGURES / "__pycache__").exists()
    return loaded


def test_every_figure_module_is_found_and_named(modules):
    assert set(modules) == EXPECTED
    assert all(callable(module.make) for module in modules.values())


def test_module_map_graph_is_computed_from_the_source(modules):
    module_map = modules["module_map"]
    graph = module_map.import_graph()
    packages = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()}
    top_level = {p.name for p in PACKAGE.glob("*.py")}
    assert set(graph.modules) == packages | top_level
    assert {"cli", "campaign", "config", "landing", "sensing", "sim", "runtime", "vehicle", "field",
            "mavlink"} <= packages
    for package in packages:
        assert graph.modules[package] == len(list((PACKAGE / package).rglob("*.py")))
    # The CLI imports the campaign package inside its commands; the runtime imports the simulator on loading.
    assert graph.edges[("cli", "campaign")] == module_map.DEFERRED
    assert graph.edges[("runtime", "sim")] == module_map.AT_LOAD
    assert ("campaign", "cli") not in graph.edges and all(a != b for a, b in graph.edges)
    assert "errors.py" in module_map.base_units(graph)
    drawing = module_map.route(graph)
    assert set(drawing.centres) == set(graph.modules)
    assert module_map.problems(drawing) == []


def test_module_map_reads_relative_and_type_checking_imports(modules, tmp_path):
    package = tmp_path / "pkg"
    (package / "a").mkdir(parents=True)
    (package / "b").mkdir()
    (package / "__init__.py").write_text("__version__ = '1'\n")
    (package / "a" / "__init__.py").write_text("")
    (package / "b" / "__init__.py").write_text("")
    (package / "top.py").write_text("")
    (package / "a" / "x.py").write_text(
        "from typing import TYPE_CHECKING\nfrom .. import __version__\nfrom ..top import thing\n"
        "if TYPE_CHECKING:\n    from ..b import y\n\ndef f():\n    from pkg.b import z\n")
    graph = modules["module_map"].import_graph(package)
    assert graph.edges == {("a", "__init__.py"): "at load", ("a", "top.py"): "at load", ("a", "b"): "deferred"}
    assert graph.modules == {"__init__.py": 1, "a": 2, "b": 1, "top.py": 1}


def test_cautious_states_are_the_enums_and_transitions_reach_what_the_code_enters(modules):
    from preland_app.landing.cautious_retry import RetryPhase
    from preland_app.sim.precland_retry import RetryState

    cautious = modules["cautious_states"]
    machines = {machine.states: machine for machine in cautious.MACHINES}
    assert set(machines) == {RetryPhase, RetryState}
    for states, machine in machines.items():
        assert sorted(machine.members()) == sorted(member.name for member in states)
        assert machine.members()[0] == "TRACKING" and set(machine.order) == {m.name for m in states}
        entered = cautious.entered_in_code(machine.source, states.__name__)
        assert len(entered) >= 5
        assert machine.targets() == entered, machine.title
        drawn = {s for s, _, _ in machine.steps} | {s for lane in machine.lanes for s in lane[2]}
        assert drawn <= set(machine.members())


def test_a_new_cautious_state_is_drawn_without_transitions(modules):
    import dataclasses
    import enum

    import matplotlib.pyplot as plt

    cautious = modules["cautious_states"]
    states = enum.Enum("RetryPhase", [(m.name, m.value) for m in cautious.COMPANION.states] + [("HOVERING", "h")])
    machine = dataclasses.replace(cautious.COMPANION, states=states)
    assert machine.members()[-1] == "HOVERING"
    figure, axes = plt.subplots()
    cautious._draw(axes, machine)
    assert any("new: transitions not drawn" in text.get_text() for text in axes.texts)
    plt.close(figure)


def test_data_flow_boxes_name_modules_and_names_the_tree_has(modules):
    data_flow = modules["data_flow"]
    assert data_flow.unknown_names() == []
    named = [path for box in data_flow.BOXES for path, _ in data_flow._named(box)]
    assert {"runtime/embedded.py", "mission.py", "landing/base.py", "campaign/trials.py",
            "campaign/driver.py", "vehicle/protocol.py"} <= set(named)
    wrong = data_flow.Box("x", 0, 0, 1, 1, "x", ("mission.py: MissionRunner, NoSuchRunner", "sensing/nope.py",
                                                 "campaign/spec.py:", "load_campaign,", "loadCampaign"), "#fff")
    assert data_flow.unknown_names((wrong,)) == ["mission.py: NoSuchRunner", "sensing/nope.py",
                                                 "campaign/spec.py: loadCampaign"]


def test_pad_headers_come_from_the_pad_specs(modules):
    from preland_app.sensing.pad import PAD_PRESETS

    for preset, pad in PAD_PRESETS.items():
        text = " ".join(modules["pads"].describe(preset, pad))
        assert pad.dictionary in text and all(f"id {m.id}: {m.side_m * 100:g} cm" in text for m in pad.markers)


def test_report_figures_map_to_their_site_names(modules):
    report = modules["report"]
    assert report.site_name(Path("out/thesis_table3_errors.png"), "thesis_table3") == "report-errors.png"
    assert report.site_name(Path("out/thesis_table3.md"), "thesis_table3") is None
    assert report.site_name(Path("out/other_errors.png"), "thesis_table3") is None


def test_a_preview_build_runs_the_report_campaign_with_the_trials_it_names(modules, monkeypatch):
    report = modules["report"]
    monkeypatch.delenv(report.PREVIEW_TRIALS_ENV, raising=False)
    assert report.preview_trials() is None  # the published site: the campaign's own trials
    monkeypatch.setenv(report.PREVIEW_TRIALS_ENV, "2")
    assert report.preview_trials() == 2
    for bad in ("0", "two", "-1"):
        monkeypatch.setenv(report.PREVIEW_TRIALS_ENV, bad)
        with pytest.raises(ValueError, match="PRELAND_DOCS_TRIALS"):
            report.preview_trials()


def test_publish_copies_each_figure_into_the_site_once(build, tmp_path):
    written = {}

    class Sink:
        def __init__(self, name):
            self.name = name

        def __enter__(self):
            return self

        def write(self, data):
            written[self.name] = data

        def __exit__(self, *exc):
            return False

    def fake_open(name, mode):
        assert mode == "wb"
        return Sink(name)

    def figure(name, *files):
        def make(out_dir):
            out_dir.mkdir(parents=True, exist_ok=True)
            for file in files:
                (out_dir / file).write_bytes(f"{name}:{file}".encode())
            return [out_dir / file for file in files]
        return SimpleNamespace(__name__=build.MODULE_PREFIX + name, make=make)

    one, two = figure("one", "a.png", "b.png"), figure("two", "c.png")
    assert build.publish(fake_open, [one, two]) == ["figures/a.png", "figures/b.png", "figures/c.png"]
    assert written == {"figures/a.png": b"one:a.png", "figures/b.png": b"one:b.png", "figures/c.png": b"two:c.png"}
    with pytest.raises(ValueError, match="figures/a.png: written by .*one and .*three"):
        build.publish(fake_open, [one, figure("three", "a.png")])
    with pytest.raises(ValueError, match="no figure module nope"):
        build.figure_modules(["nope"])
    assert [m.__name__ for m in build.figure_modules(["pads"])] == [build.MODULE_PREFIX + "pads"]
