"""What a run records (trials, reproduce, ablate): one system's results document in one world,
with every parameter it used, so a run can be regenerated from its JSON."""

from __future__ import annotations

import dataclasses
import math
import os
import platform
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

import jaxais
from jaxais import envs
from jaxais.controllers import System
from jaxais.immune.network import NetworkParams
from jaxais.immune.readings import DEFAULT
from jaxais.io import UserError, check_type, read_json_object
from jaxais.loop import EpisodeConfig
from jaxais.seed import Seed, default_seed_dir, load_seed
from jaxais.systems import make_system, parse_label
from jaxais.trials import TrialSet, summarise

FORMATS = {
    "trials": "jaxais-trials/1",
    "sweep": "jaxais-sweep/1",
    "reality_gap": "jaxais-reality-gap/1",
}  # each results file's format tag (docs/formats.md)
SHIPPED_SEED = "shipped (checkpoints/default)"  # not where this machine installed it


def portable_path(path: str | Path) -> str:
    """``path`` relative to the working directory, else its name: no record names a machine's
    directories."""
    p = Path(path).resolve()
    try:
        return str(p.relative_to(Path.cwd().resolve()))
    except ValueError:
        return p.name


def portable_command(command: str) -> str:
    """``command`` with every absolute path in it made portable (:func:`portable_path`)."""
    return " ".join(portable_path(w) if w.startswith("/") else w for w in command.split())


def versions() -> dict[str, str]:
    """The versions that made a run, and JAX's backend."""
    import jax
    import jaxlib

    return {
        "jaxais": jaxais.__version__,
        "jax": jax.__version__,
        "jaxlib": jaxlib.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
        "backend": jax.default_backend(),
    }


def load_ltl_seed(seeds_dir: str | Path | None) -> tuple[Seed, dict[str, Any]]:
    """(the LTL seed, default the shipped one, and its portable path and provenance)."""
    path = default_seed_dir() if seeds_dir is None else Path(seeds_dir)
    seed, meta = load_seed(path)
    made_by = {k: meta.get(k) for k in ("command", "seed", "version") if k in meta}
    if isinstance(made_by.get("command"), str):  # evolve.py's command may name /tmp/...
        made_by["command"] = portable_command(made_by["command"])
    shipped = seeds_dir is None or path.resolve() == default_seed_dir().resolve()
    return seed, {"path": SHIPPED_SEED if shipped else portable_path(path), "made_by": made_by}


def build_systems(
    labels: list[str],
    seeds_dir: str | Path | None,
    network: NetworkParams | None = None,
    loaded: tuple[Seed, dict[str, Any]] | None = None,
) -> tuple[dict[str, System], dict[str, Any]]:
    """(label -> System, the seed's description or None), reading the LTL seed (unless
    ``loaded`` by :func:`load_ltl_seed`) only when a seeded system needs it."""
    seed, seed_info = None, None
    if any(parse_label(name)[0] in ("SIE", "SRL") for name in labels):
        seed, seed_info = loaded if loaded is not None else load_ltl_seed(seeds_dir)
    systems = {name: make_system(name, seed, network=network) for name in labels}
    return systems, seed_info


def scaled_world(name: str | Path, scale: float = 1.0) -> tuple[envs.World, envs.SimParams]:
    """(the world, the simulator's parameters) at world ``scale`` (checked by
    :func:`protocol.check_world_scale`): every coordinate, region and obstacle size and the
    camera's range [ours, 2 m] times ``scale``; the robot, the target block and the heights as
    they are. Scale 1: ``envs.load_world(name)`` and ``envs.default_params()``."""
    if scale == 1:
        return envs.load_world(name), envs.default_params()
    return envs.load_world(name, scale=scale), scaled_params(scale)


def scaled_params(scale: float = 1.0) -> envs.SimParams:
    """The simulator's parameters at world ``scale``: the camera's range [ours, 2 m:
    ``envs.SimParams.camera_range``] grows with the world."""
    params = envs.default_params()
    if scale == 1:
        return params
    return envs.default_params(camera_range=float(params.camera_range) * scale)


def run_config(
    world: envs.World,
    world_source: str,
    config: EpisodeConfig,
    network: NetworkParams,
    sim_params: envs.SimParams,
    seed_info: dict[str, Any] | None,
    scale: float = 1.0,
) -> dict[str, Any]:
    """Every parameter a run used, as plain JSON (with the versions that made it; ``scale``:
    the world's, :func:`scaled_world`)."""
    plain = lambda x: np.asarray(x).tolist()
    fields = lambda obj: {f.name: plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    source = world_source if world_source == world.name else portable_path(world_source)
    where = {"name": world.name, "source": source}
    if scale != 1:  # recorded only when scaled: a default run's config is as it was
        where["scale"] = scale
    return {
        "world": where,
        "episode": dataclasses.asdict(config),
        "network": fields(network),
        "readings": fields(DEFAULT),
        "simulator": fields(sim_params),
        "ltl_seed": seed_info,
        "versions": versions(),
    }


def results_document(
    label: str,
    world_name: str,
    seed: int,
    trials: TrialSet,
    config: dict[str, Any],
) -> dict[str, Any]:
    """The results.json of one system in one world (a label such as "NN": no random set)."""
    try:
        system, random_set = parse_label(label)
    except ValueError:
        system, random_set = label, None
    return {
        "format": FORMATS["trials"],
        "system": system,
        "label": label,
        "world": world_name,
        "random_set": random_set,
        "seed": seed,
        "config": config,
        "trials": trials.records,
        "summary": summarise(trials.records),
    }


def records_frame(source: str | os.PathLike[str] | Mapping[str, Any], runs: bool = False):
    """A results file (a path or its JSON) as a ``pandas.DataFrame`` (docs/formats.md): a
    trials file's trials; a sweep's points (the axes, n, per metric its mean, ``_low`` and
    ``_high``) or with ``runs`` its kept runs; a reality gap's (scale, label) rows. One-line
    ValueError otherwise: a wrong type, a missing field (named), or a record holding a NaN or an
    infinity (named by its index and label: results files hold finite numbers, ``null`` where a
    value does not apply)."""
    check_type(source, str | os.PathLike | Mapping, "records_frame's source",
               "a results file's path or its JSON document (a dict)")  # fmt: skip
    check_type(runs, bool, "records_frame's runs", "a bool")
    try:
        import pandas as pd
    except ImportError:
        raise UserError("records_frame needs pandas: pip install pandas") from None
    where = "the document" if isinstance(source, Mapping) else str(source)
    doc = source if isinstance(source, Mapping) else read_json_object(source)
    fmt = doc.get("format")
    named: list[tuple[str, dict[str, Any]]] = []  # (the record's name in an error, its row)
    if fmt == FORMATS["trials"]:
        head = {k: _field(doc, k, where) for k in ("label", "system", "world", "random_set")}
        head["seed"] = _field(doc, "seed", where)
        for i, r in enumerate(_objects(doc, "trials", where)):
            named.append((f"trial {i} (label {head['label']!r})", {**head, "trial": i, **r}))
    elif fmt == FORMATS["sweep"] and runs:
        points = _objects(doc, "points", where)
        if any("trials" not in p for p in points):
            raise UserError(f"{where} kept no runs: run the sweep with --records")
        for j, p in enumerate(points):
            values = _field(p, "values", f"{where}: point {j}", Mapping, "an object")
            for i, r in enumerate(_objects(p, "trials", f"{where}: point {j}")):
                named.append((f"point {j}'s trial {i}", {**values, "trial": i, **r}))
    elif fmt == FORMATS["sweep"]:
        for j, p in enumerate(_objects(doc, "points", where)):
            values = _field(p, "values", f"{where}: point {j}", Mapping, "an object")
            named.append((f"point {j}", {**values, **_flat(p)}))
    elif fmt == FORMATS["reality_gap"] and not runs:
        for j, p in enumerate(_objects(doc, "points", where)):
            systems = _field(p, "systems", f"{where}: point {j}", Mapping, "an object")
            for k, v in systems.items():
                check_type(v, Mapping, f"{where}: point {j}'s {k!r}", "an object")
                row = {"scale": _field(p, "scale", f"{where}: point {j}"), "label": k, **_flat(v)}
                named.append((f"point {j}'s label {k!r}", row))
    elif fmt == FORMATS["reality_gap"]:
        raise UserError(f"{where}: a reality gap keeps no runs (runs=True reads a sweep's)")
    else:
        known = ", ".join(FORMATS.values())
        raise UserError(f"{where}: not a jaxais results file (format {fmt!r}; reads {known})")
    for name, row in named:
        for key, value in row.items():
            if isinstance(value, float | np.floating) and not math.isfinite(value):
                raise UserError(
                    f"{where}: {name} holds {key} = {value}: a results file holds finite numbers "
                    "(null where a value does not apply); it was damaged or edited"
                )
    return pd.DataFrame([row for _, row in named])


def _field(doc: Mapping[str, Any], key: str, where: str, kind: Any = object, what: str = "") -> Any:
    """``doc[key]``, or a one-line UserError naming the missing field (or its wrong type)."""
    if key not in doc:
        raise UserError(f"{where}: no {key!r} field (docs/formats.md)")
    check_type(doc[key], kind, f"{where}: {key!r}", what)
    return doc[key]


def _objects(doc: Mapping[str, Any], key: str, where: str) -> list[Mapping[str, Any]]:
    """``doc[key]`` checked to be a list of JSON objects (each named by its index if not)."""
    items = _field(doc, key, where, list, "a list of objects")
    for i, item in enumerate(items):
        check_type(item, Mapping, f"{where}: {key}[{i}]", "an object")
    return items


def _flat(summary: Mapping[str, Any]) -> dict[str, Any]:
    """A point's summary (``sweeps.summarise_point``) as flat columns."""

    out = {}
    for k, v in summary.items():
        if isinstance(v, Mapping) and "ci" in v:
            out |= {k: v["mean"], f"{k}_low": v["ci"][0], f"{k}_high": v["ci"][1]}
        elif k not in ("values", "trials"):
            out[k] = v  # n, or None (no idiotypic rate for a system without selection)
    return out
