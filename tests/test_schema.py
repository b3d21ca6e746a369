"""JSON Schemas of mission, campaign, pad and profile files: generated from the specs, shipped, and strict."""

import copy
import json

import jsonschema
import pytest
import yaml
from typer.testing import CliRunner

from preland_app.cli import app
from preland_app.config.mission import load_mission
from preland_app.errors import SpecError

from .conftest import ROOT

SHIPPED = {"mission": sorted((ROOT / "missions").glob("*.yaml")),
           "campaign": sorted((ROOT / "campaigns").glob("*.yaml")),
           "pad": sorted((ROOT / "pads").glob("*.yaml")) if (ROOT / "pads").is_dir() else [],
           "profile": sorted((ROOT / "profiles").glob("*.yaml"))}


def command_schema(kind: str) -> str:
    result = CliRunner().invoke(app, ["schema", kind])
    assert result.exit_code == 0, result.output
    return result.stdout


@pytest.mark.parametrize("kind", sorted(SHIPPED))
def test_the_shipped_schema_is_the_commands_output(kind):
    """So it cannot go stale: regenerate with `preland schema KIND > schemas/KIND.schema.json`."""
    shipped = (ROOT / "schemas" / f"{kind}.schema.json").read_text()
    assert shipped == command_schema(kind)
    jsonschema.Draft7Validator.check_schema(json.loads(shipped))


@pytest.mark.parametrize("kind", sorted(SHIPPED))
def test_every_shipped_file_names_and_satisfies_its_schema(kind):
    validator = jsonschema.Draft7Validator(json.loads(command_schema(kind)))
    for path in SHIPPED[kind]:
        text = path.read_text()
        assert text.splitlines()[0] == f"# yaml-language-server: $schema=../schemas/{kind}.schema.json", path
        errors = [f"{'.'.join(map(str, e.path))}: {e.message}" for e in validator.iter_errors(yaml.safe_load(text))]
        assert errors == [], path
    assert kind == "pad" or SHIPPED[kind]


def _fails(validator, data) -> list[str]:
    return [e.message for e in validator.iter_errors(data)]


def test_a_misspelt_key_fails_the_schema_as_it_fails_the_loader(tmp_path):
    mission_schema = jsonschema.Draft7Validator(json.loads(command_schema("mission")))
    good = yaml.safe_load((ROOT / "missions" / "thesis_square_land.yaml").read_text())
    for where, misspelt in ((("takeoff",), "altitude_rel_mm"), ((), "timeout"), (("sensors", "camera"), "fps")):
        data = copy.deepcopy(good)
        section = data
        for key in where:
            section = section.setdefault(key, {})
        section[misspelt] = 1
        assert any(f"'{misspelt}' was unexpected" in m for m in _fails(mission_schema, data)), misspelt
        path = tmp_path / "mission.yaml"
        path.write_text(yaml.safe_dump(data))
        with pytest.raises(SpecError, match="unknown key"):
            load_mission(path)
    data = copy.deepcopy(good)
    data["takeoff"]["altitude_rel_m"] = "ten"
    assert _fails(mission_schema, data)
    data = copy.deepcopy(good)
    data["land"] = {"mode": "mypackage.landing:MyLanding", "params": {"gain_per_s": 0.5}}
    assert _fails(mission_schema, data) == []  # a plugin's options: checked against its class at load time

    campaign_schema = jsonschema.Draft7Validator(json.loads(command_schema("campaign")))
    campaign = yaml.safe_load((ROOT / "campaigns" / "thesis_table3.yaml").read_text())
    for key, value in (("lable", "x"), ("environment", {"wind": {"speed": 1}}), ("params", {"LAND_SPEEED": 30})):
        data = copy.deepcopy(campaign)
        data["scenarios"][0][key] = value
        assert _fails(campaign_schema, data), key


def test_an_unknown_schema_kind_is_bad_input():
    result = CliRunner().invoke(app, ["schema", "missions"])
    assert result.exit_code == 2 and "mission, campaign, pad" in result.stderr
