"""JSON Schemas of the world format and the results formats, generated from their definitions.

The world schema is :data:`jaxais.envs.world.FIELDS` (what the loader reads: every key, its kind,
whether it is required, the range it keeps alone); the rules that involve other fields (regions
inside the arena, a box's one of ``center`` or ``region``, the surface count) stay in the loader,
which an editor's schema check does not replace. A results schema (docs/formats.md's table:
trials, sweep, reality gap, robustness map) is the shape of what the writers themselves produce
(:func:`jaxais.trials.trial_records`, :func:`jaxais.experiments.records.results_document`,
:func:`jaxais.experiments.sweeps.sweep_document` and its kin,
:func:`jaxais.experiments.robustness.summarise`) for example outcomes; objects keyed by a name
the run chooses (axes, labels, claims) are maps. :func:`write` ships them as
``docs/schema/*.schema.json``; the tests keep the shipped files equal to these.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = [
    "SCHEMAS",
    "reality_gap_schema",
    "robustness_schema",
    "schemas",
    "sweep_schema",
    "trials_schema",
    "world_schema",
    "write",
]

DRAFT = "https://json-schema.org/draft/2020-12/schema"
SCHEMAS = {
    "world": "world.schema.json",
    "trials": "trials.schema.json",
    "sweep": "sweep.schema.json",
    "reality_gap": "reality_gap.schema.json",
    "robustness": "robustness.schema.json",
}
"""Each schema's file name in ``docs/schema/``."""


def world_schema() -> dict[str, Any]:
    """The JSON Schema of a world file (TOML, read as JSON by editors such as taplo)."""
    from jaxais.envs.world import FIELDS

    def value(field) -> dict[str, Any]:
        if field.kind in ("table", "tables"):
            raise AssertionError(field)  # tables are handled by table()
        out: dict[str, Any] = {"type": "string" if field.kind == "str" else "number"}
        if field.choices:
            out["enum"] = list(field.choices)
        if field.low is not None:
            out["exclusiveMinimum" if field.open_low else "minimum"] = field.low
        if field.high is not None:
            out["maximum"] = field.high
        if field.kind.startswith("vec"):
            n = int(field.kind[3:])
            out = {"type": "array", "items": out, "minItems": n, "maxItems": n}
        return out

    def table(path: str) -> dict[str, Any]:
        properties = {}
        for key, field in FIELDS[path].items():
            if field.kind == "table":
                schema = table(key)
            elif field.kind == "tables":
                schema = {"type": "array", "items": table(key)}
            else:
                schema = value(field)
            properties[key] = {"description": field.doc, **schema}
        required = [key for key, field in FIELDS[path].items() if field.required]
        return {
            "type": "object",
            "properties": properties,
            **({"required": required} if required else {}),
            "additionalProperties": False,
        }

    return {
        "$schema": DRAFT,
        "$id": SCHEMAS["world"],
        "title": "jaxais world",
        "description": "A world file (envs/worlds/world1.toml documents every field). The "
        "loader also checks what involves several fields: regions inside the arena, sizes "
        "within half of it, one of a box's center or region, the goal sized by its shape, at "
        "most 64 surfaces.",
        **table(""),
    }


def _infer(examples: list[Any], maps: frozenset[str] = frozenset(), at: str = "") -> dict[str, Any]:
    """The schema that every one of ``examples`` (JSON values) fits: objects by their keys
    (required: those in every example; more allowed), lists by their items, types united.
    ``maps``: the paths (``at``: "points[].values", "claims.*") of objects keyed by names the
    run chooses, whose values share one schema (``additionalProperties``)."""
    kinds = {
        "null" if x is None
        else "boolean" if isinstance(x, bool)
        else "integer" if isinstance(x, int)
        else "number" if isinstance(x, float)
        else "string" if isinstance(x, str)
        else "array" if isinstance(x, list)
        else "object"
        for x in examples
    }  # fmt: skip
    if "integer" in kinds and "number" in kinds:
        kinds.discard("integer")
    out: dict[str, Any] = {"type": sorted(kinds)[0] if len(kinds) == 1 else sorted(kinds)}
    objects = [x for x in examples if isinstance(x, dict)]
    if objects and at in maps:
        values = [v for x in objects for v in x.values()]
        out["additionalProperties"] = _infer(values, maps, f"{at}.*") if values else {}
    elif objects:
        keys = list(dict.fromkeys(k for x in objects for k in x))
        path = lambda k: f"{at}.{k}" if at else k
        out["properties"] = {
            k: _infer([x[k] for x in objects if k in x], maps, path(k)) for k in keys
        }
        out["required"] = [k for k in keys if all(k in x for x in objects)]
    items = [item for x in examples if isinstance(x, list) for item in x]
    if items:
        out["items"] = _infer(items, maps, f"{at}[]")
    return out


def _config(schema: dict[str, Any]) -> None:
    """``schema``'s ``config``: every parameter the run used, as a trials file's."""
    schema["properties"]["config"] = {
        "type": "object",
        "description": "every parameter the run used (docs/formats.md)",
    }


def _results(
    name: str, fmt: str, title: str, description: str, schema: dict[str, Any]
) -> dict[str, Any]:
    """A results schema, its ``format`` the writer's tag ``fmt``."""
    schema["properties"]["format"] = {"const": fmt}
    return {"$schema": DRAFT, "$id": SCHEMAS[name], "title": title,
            "description": f"{description} ({fmt}, docs/formats.md).", **schema}  # fmt: skip


def _example_outcomes(n: int, stats: bool, selected: bool = True) -> dict[str, Any]:
    """Outcome arrays [n] as :func:`jaxais.loop.outcome` gives them (one trial failed both
    ways), with the STL controller's stats (``stats``; ``selected=False``: a run without an
    idiotypic selection, whose rate is NaN) or none."""
    import numpy as np

    res = {
        "tau": np.linspace(50.0, 4000.0, n),
        "collisions": np.arange(n) * 60,
        "collisions_capped": np.minimum(np.arange(n) * 60, 100),
        "fitness": np.linspace(60.0, 2400.0, n),
        "failed_collisions": np.arange(n) * 60 > 100,
        "failed_time": np.arange(n) == n - 1,
        "trapped_s": np.zeros(n),
        "locked_s": np.zeros(n),
        "iterations": np.arange(n) + 1000,
    }
    if stats:
        res |= {"idiotypic_difference_rate": np.full(n, 0.2), "replaced": np.zeros(n, int)}
        res["idiotypic_difference_rate"][0] = np.nan if not selected else 0.1
    return res


def trials_schema() -> dict[str, Any]:
    """The JSON Schema of a trials file (``jaxais-trials/1``, docs/formats.md): the writers'
    output for a paper system with and without a random set, with and without stats."""
    from jaxais.experiments.records import FORMATS, results_document
    from jaxais.trials import TrialSet, summarise, trial_records

    docs = []
    for label, stats, selected in (("SIE", True, True), ("UIE-R1", True, False), ("HDC", 0, 0)):
        records = trial_records(_example_outcomes(3, stats, selected))
        doc = results_document(label, "world1", 0, TrialSet(records, None), {"world": {}})
        docs.append(json.loads(json.dumps(doc)))
    schema = _infer(docs)
    schema["properties"]["format"] = {"const": FORMATS["trials"]}
    schema["properties"]["config"] = {
        "type": "object",
        "description": "every parameter the run used (docs/formats.md)",
    }
    summary = schema["properties"]["summary"]
    assert set(summary["required"]) == set(summarise(docs[0]["trials"]))
    record = schema["properties"]["trials"]["items"]
    # The records' fields beyond the loop's are the controller's stats: numbers or null.
    stats = [k for k in record["properties"] if k not in docs[-1]["trials"][0]]
    for key in stats:
        record["properties"].pop(key)
    record["required"] = list(docs[-1]["trials"][0])
    record["additionalProperties"] = {"type": ["number", "null"]}
    return {
        "$schema": DRAFT,
        "$id": SCHEMAS["trials"],
        "title": "jaxais trials file",
        "description": "One system's trials in one world (jaxais-trials/1, docs/formats.md).",
        **schema,
    }


def _points(stats: bool, selected: bool = True) -> dict[str, Any]:
    from jaxais.experiments.sweeps import summarise_point

    return summarise_point(_example_outcomes(3, stats, selected))


def sweep_schema() -> dict[str, Any]:
    """The JSON Schema of ``sweep.json`` (``jaxais-sweep/1``): the writers' documents of a paper
    system's k1 x k2 grid with its runs kept (``--records``) and of a contender's grid."""
    import numpy as np

    from jaxais.experiments.sweeps import finish_document, sweep_document
    from jaxais.trials import trial_records

    axes = [("k1", np.array([0.5, 1.0])), ("k2", np.array([1.0, 1.5]))]
    grid = [{"k1": a, "k2": b} for a in (0.5, 1.0) for b in (1.0, 1.5)]
    points = [{"values": v, **_points(True, i > 0)} for i, v in enumerate(grid)]
    points[0]["trials"] = trial_records(_example_outcomes(3, True))
    paper = sweep_document(axes, {"k1": 0.85, "k2": 1.1}, points, 12, 12000, 1.0)
    speed = [("speed", np.array([0.5]))]
    own = sweep_document(speed, {"speed": 1.0}, [{"values": {"speed": 0.5}, **_points(False)}],
                         3, 3000, 1.0)  # fmt: skip
    docs = [
        finish_document(
            doc,
            names=[name],
            world="world1",
            seed=0,
            trials=3,
            wall_total=1.0,
            config={},
            paper_point=name == "SIE",
        )
        for doc, name in ((paper, "SIE"), (own, "MINE"))
    ]
    maps = frozenset({"axes", "base_values", "points[].values"})
    schema = _infer(json.loads(json.dumps(docs)), maps)
    _config(schema)
    fmt = docs[0]["format"]
    return _results("sweep", fmt, "jaxais sweep", "A grid over a system's parameters", schema)


def reality_gap_schema() -> dict[str, Any]:
    """The JSON Schema of ``reality_gap.json`` (``jaxais-reality-gap/1``): the writer's
    document of two noise scales, a system with the STL's stats and one without."""
    from jaxais.experiments.sweeps import NOISE_KINDS, finish_document, noise_document

    levels = {n: 0.1 for names in NOISE_KINDS.values() for n in names}
    points = [
        {"scale": k, "levels": levels, "systems": {"SIE": _points(True), "HDC": _points(False)}}
        for k in (0.0, 1.0)
    ]
    doc = noise_document(list(NOISE_KINDS), [0.0, 1.0], points, 1.0)
    doc = finish_document(doc, names=["SIE", "HDC"], world="real", seed=0, trials=3,
                          wall_total=1.0, config={}, paper_point=False)  # fmt: skip
    schema = _infer([json.loads(json.dumps(doc))], frozenset({"points[].systems"}))
    _config(schema)
    title, about = "jaxais reality gap", "Systems under scaled noise"
    return _results("reality_gap", doc["format"], title, about, schema)


def robustness_schema() -> dict[str, Any]:
    """The JSON Schema of ``robustness.json`` (``jaxais-robustness/1``): the writer's document
    of a map's cells (claims held, not held, not evaluated, and one evaluated in no cell)."""
    from jaxais.experiments.robustness import summarise

    axes = {"ltl_seed": [0, 1], "scale": [1.0, 2.0], "rule": ["episode", "reading"]}
    outcomes = (True, False, None)
    cells = [
        {"ltl_seed": s, "trial_seed": s, "scale": k, "rule": r,
         "claims": {"world1/H1": outcomes[(s + i) % 3], "H3": outcomes[i % 2], "H4": None}}
        for s in axes["ltl_seed"] for i, k in enumerate(axes["scale"]) for r in axes["rule"]
    ]  # fmt: skip
    doc = summarise(cells, axes) | {"command": "robustness.py --out OUT"}
    maps = frozenset({"cells[].claims", "claims", "claims.*.marginals", "claims.*.marginals.*"})
    schema = _infer([json.loads(json.dumps(doc))], maps)
    title, about = "jaxais robustness map", "Claims over unstated choices"
    return _results("robustness", doc["format"], title, about, schema)


def schemas() -> dict[str, dict[str, Any]]:
    """Every schema by its file name (:data:`SCHEMAS`; NAME's is made by ``NAME_schema``)."""
    return {file: globals()[f"{name}_schema"]() for name, file in SCHEMAS.items()}


def text(schema: dict[str, Any]) -> str:
    """A schema as its file holds it."""
    return json.dumps(schema, indent=2) + "\n"


def write(folder: str | Path) -> list[Path]:
    """Write every schema into ``folder`` (``docs/schema``); returns the files."""
    from jaxais.io import atomic_write_text

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    return [atomic_write_text(folder / name, text(s)) for name, s in schemas().items()]


if __name__ == "__main__":  # regenerate docs/schema/
    for path in write(Path(__file__).resolve().parents[2] / "docs" / "schema"):
        print(path)
