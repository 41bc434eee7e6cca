"""The JSON Schemas in docs/schema/ (``jaxais.experiments.schema``): the shipped files are the
generated ones, every built-in world fits the world schema, and the schema refuses what the
loader refuses field by field (the cross-field rules are the loader's alone)."""

from __future__ import annotations

import copy
import json
import tomllib
from pathlib import Path

import jsonschema
import pytest

from jaxais import envs
from jaxais.experiments import schema

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = ROOT / "docs" / "schema"


@pytest.fixture(scope="module")
def world_validator() -> jsonschema.Draft202012Validator:
    doc = json.loads((SHIPPED / schema.SCHEMAS["world"]).read_text())
    jsonschema.Draft202012Validator.check_schema(doc)
    return jsonschema.Draft202012Validator(doc)


def test_shipped_schemas_are_the_generated_ones():
    generated = schema.schemas()
    assert sorted(p.name for p in SHIPPED.glob("*.schema.json")) == sorted(generated)
    for name, doc in generated.items():
        assert (SHIPPED / name).read_text() == schema.text(doc), (
            f"docs/schema/{name} is stale: run python -m jaxais.experiments.schema"
        )
        jsonschema.Draft202012Validator.check_schema(doc)


def test_every_builtin_world_fits_the_world_schema(world_validator):
    for name in envs.BUILTIN_WORLDS:
        doc = tomllib.loads(envs.world_path(name).read_text())
        errors = [e.message for e in world_validator.iter_errors(doc)]
        assert not errors, (name, errors)


def _mutated(doc: dict, path: str, value: object) -> dict:
    """``doc`` with ``path`` ("goal.shape", "pillars.0.radius") set to ``value`` (a missing
    sentinel: deleted)."""
    out = copy.deepcopy(doc)
    *parents, last = path.split(".")
    target = out
    for part in parents:
        target = target[int(part)] if isinstance(target, list) else target[part]
    if value is _MISSING:
        del target[last]
    else:
        target[last] = value
    return out


_MISSING = object()


@pytest.mark.parametrize(
    ("path", "value"),
    [
        ("name", _MISSING),
        ("name", 3),
        ("pilars", [{"center": [0.5, 0.5], "radius": 0.05}]),  # a misspelt table
        ("arena.width", -1.0),
        ("arena.width", 101.0),
        ("arena.wall_height", 0.0),
        ("arena.depth", 1.0),
        ("goal.shape", "cube"),
        ("goal.region", [0.2, 1.3, 1.3]),
        ("robot.start_heading", [-7.0, 0.0]),
        ("pillars.0.radius", "big"),
        ("pillars.0.material", "glass"),
        ("boxes.0.height", 11.0),
        ("noise", {"camera_miss_prob": 1.5}),
        ("noise", {"ir_relative_std": -0.1}),
    ],
)
def test_the_schema_refuses_what_the_loader_refuses(path, value, world_validator):
    doc = _mutated(tomllib.loads(envs.world_path("world1").read_text()), path, value)
    assert not world_validator.is_valid(doc), path
    with pytest.raises(envs.WorldError):
        envs.world.parse_world(doc, "mutated.toml")


def test_cross_field_rules_stay_the_loaders(world_validator):
    # Inside the schema's ranges, outside the arena: only the loader can tell.
    doc = tomllib.loads(envs.world_path("world1").read_text())
    doc["robot"]["start_region"] = [0.15, 0.1, 2.35, 0.25]
    assert world_validator.is_valid(doc)
    with pytest.raises(envs.WorldError, match="outside the arena"):
        envs.world.parse_world(doc, "wide.toml")


def test_trials_schema_takes_the_writers_documents_and_refuses_others():
    validator = jsonschema.Draft202012Validator(schema.trials_schema())
    from jaxais.experiments.records import results_document
    from jaxais.trials import TrialSet, trial_records

    records = trial_records(schema._example_outcomes(2, stats=True))
    doc = json.loads(json.dumps(results_document("SRL", "real", 3, TrialSet(records, None), {})))
    assert validator.is_valid(doc)
    for key, value in [("format", "jaxais-trials/2"), ("seed", "0"), ("summary", None)]:
        assert not validator.is_valid({**doc, key: value}), key
    bad = copy.deepcopy(doc)
    del bad["trials"][1]["tau"]
    assert not validator.is_valid(bad)
