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


SHIPPED_RESULTS = {
    "sweep": [ROOT / "docs" / "sweep" / "sweep.json"],
    "reality_gap": [ROOT / "docs" / "sweep" / "reality_gap.json"],
    "robustness": sorted((ROOT / "docs").glob("robustness/robustness.json")),
}


@pytest.mark.parametrize("name", sorted(SHIPPED_RESULTS))
def test_every_shipped_results_file_fits_its_schema(name):
    validator = jsonschema.Draft202012Validator(
        json.loads((SHIPPED / schema.SCHEMAS[name]).read_text())
    )
    for path in SHIPPED_RESULTS[name]:
        errors = [
            f"{list(e.path)}: {e.message}"
            for e in validator.iter_errors(json.loads(path.read_text()))
        ]
        assert not errors, (path, errors[:3])


def _points_of(doc: dict) -> dict:
    return doc["points"][0]


@pytest.mark.parametrize(
    ("name", "spoil"),
    [
        ("sweep", lambda d: d.update(format="jaxais-sweep/2")),
        ("sweep", lambda d: _points_of(d).pop("f")),
        ("sweep", lambda d: _points_of(d)["values"].update(k1="big")),  # a value is a number
        ("sweep", lambda d: d["base_values"].update(k2=None)),
        ("reality_gap", lambda d: _points_of(d)["systems"]["SIE"].pop("n")),
        ("reality_gap", lambda d: _points_of(d)["systems"].update(HDC={"n": "3"})),
        ("robustness", lambda d: d["cells"][0]["claims"].update(H1="yes")),
        ("robustness", lambda d: d["cells"][0].pop("rule")),
        ("robustness", lambda d: d["claims"]["H3"]["marginals"]["scale"].update({"2": "all"})),
    ],
)
def test_results_schemas_take_the_writers_documents_and_refuse_others(name, spoil):
    make = {"sweep": schema.sweep_schema, "reality_gap": schema.reality_gap_schema,
            "robustness": schema.robustness_schema}[name]  # fmt: skip
    validator = jsonschema.Draft202012Validator(make())
    doc = _written(name)
    assert validator.is_valid(doc)
    bad = copy.deepcopy(doc)
    spoil(bad)
    assert not validator.is_valid(bad)


def _written(name: str) -> dict:
    """A document as the writer produces it, other than the schema's own examples."""
    import numpy as np

    from jaxais.experiments import robustness, sweeps

    point = sweeps.summarise_point(schema._example_outcomes(4, stats=True))
    if name == "sweep":
        axes = [("k1", np.array([0.2])), ("k2", np.array([0.7]))]
        points = [{"values": {"k1": 0.2, "k2": 0.7}, **point}]
        doc = sweeps.sweep_document(axes, {"k1": 0.85, "k2": 1.1}, points, 4, 400, 2.0)
    elif name == "reality_gap":
        levels = {n: 0.0 for names in sweeps.NOISE_KINDS.values() for n in names}
        doc = sweeps.noise_document(["ir"], [2.0], [{"scale": 2.0, "levels": levels,
                                                     "systems": {"SIE": point}}], 2.0)  # fmt: skip
    else:
        cells = [{"ltl_seed": 4, "trial_seed": 4, "scale": 1.0, "rule": "episode",
                  "claims": {"H3": True}}]  # fmt: skip
        axes = {"ltl_seed": [4], "scale": [1.0], "rule": ["episode"]}
        return json.loads(json.dumps(robustness.summarise(cells, axes) | {"command": "x"}))
    facts = dict(names=["SIE"], world="world2", seed=1, trials=4, wall_total=2.0)
    doc = sweeps.finish_document(doc, **facts, config={"world": {}}, paper_point=False)
    return json.loads(json.dumps(doc))
