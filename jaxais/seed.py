"""The LTL seed on disk: five evolved antibody sets with their τ_i, c_i and L_ij.

A seed directory holds ``seed.json`` (readable, with provenance and an optional ``"crossing"``
entry: how often each set crossed the LTL maze, SPEC 10) and ``arrays/``, an orbax checkpoint of
the same numbers at full precision; loading checks one against the other.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from importlib import resources
from pathlib import Path
from typing import Any

import jax
import numpy as np

from jaxais.envs.struct import pytree_dataclass
from jaxais.immune.antibodies import Antibodies, from_dicts, take, to_dicts, within_limits
from jaxais.io import check_type
from jaxais.orbax_reads import forget_abandoned_reads

SEED_JSON = "seed.json"
ARRAYS_DIR = "arrays"
CROSSING = "crossing"  # seed.json's optional crossing rates (:func:`check_crossing`)
_FIELDS = ("type", "speed", "freq", "angle", "direction", "right_freq", "right_angle")
SEED_FORMAT = "jaxais-seed/1"


def _bad_values(seed: Seed) -> str | None:
    """What is wrong with a seed's τ, c or L (eq 1 needs τ + ρc > 0), or None."""
    tau, c, L = (np.asarray(a, np.float64) for a in (seed.tau, seed.collisions, seed.L))
    if not (np.all(np.isfinite(tau)) and np.all(tau > 0)):
        return f"seed task times must be finite and > 0 s, got {tau.tolist()}"
    if not (np.all(np.isfinite(c)) and np.all(c >= 0)):
        return f"seed collision counts must be >= 0, got {c.tolist()}"
    if not (np.all(np.isfinite(L)) and np.all(L >= 0)):
        return "seed RL scores L must be finite and >= 0"
    return None


class SeedError(ValueError):
    """A seed directory is missing, incomplete or corrupt (one line)."""


@pytree_dataclass
class Seed:
    """Evolved sets: antibodies [x, 8], their robots' tau [x] (s) and collisions [x], and
    L [x, 8], each antibody's cumulative RL score."""

    antibodies: Antibodies
    tau: np.ndarray
    collisions: np.ndarray
    L: np.ndarray


def default_seed_dir() -> Path:
    """The shipped seed, ``checkpoints/default`` (evolve.py's defaults)."""
    return Path(str(resources.files("jaxais.checkpoints").joinpath("default")))


def _arrays(seed: Seed) -> dict[str, np.ndarray]:
    out = {f"ab_{f}": np.asarray(getattr(seed.antibodies, f)) for f in _FIELDS}
    out.update(
        tau=np.asarray(seed.tau, np.float32),
        collisions=np.asarray(seed.collisions, np.int32),
        L=np.asarray(seed.L, np.float32),
    )
    return out


def check_crossing(entry: Any, x: int) -> str | None:
    """What is wrong with a crossing entry for ``x`` sets, or None: it needs ``starts`` >= 1,
    ``rate`` (x whole fractions of ``starts``) and ``tau_cap`` > 0; other keys are free."""
    if not isinstance(entry, dict):
        return "not a JSON object"
    starts, rate, cap = entry.get("starts"), entry.get("rate"), entry.get("tau_cap")
    if isinstance(starts, bool) or not isinstance(starts, int) or starts < 1:
        return f"starts must be an integer >= 1, got {starts!r}"
    if not isinstance(rate, list) or len(rate) != x:
        return f"rate must be a list of {x} fractions"
    for r in rate:
        if isinstance(r, bool) or not isinstance(r, int | float) or not 0.0 <= r <= 1.0:
            return f"rate holds {r!r}, not a fraction in [0, 1]"
        if abs(r * starts - round(r * starts)) > 1e-6:
            return f"rate {r!r} is not a whole number of crossings out of {starts}"
    if isinstance(cap, bool) or not isinstance(cap, int | float) or not 0.0 < cap < float("inf"):
        return f"tau_cap must be a positive number, got {cap!r}"
    return None


def seed_to_json(
    seed: Seed, provenance: dict[str, Any], crossing: dict[str, Any] | None = None
) -> dict[str, Any]:
    """seed.json's document: provenance, ``crossing``, one entry per set."""
    seed = jax.tree.map(np.asarray, seed)
    sets = [
        {
            "set": i,
            "tau": float(seed.tau[i]),
            "collisions": int(seed.collisions[i]),
            "L": [float(x) for x in seed.L[i]],
            "antibodies": to_dicts(take(seed.antibodies, i)),
        }
        for i in range(seed.tau.shape[0])
    ]
    doc = {"format": SEED_FORMAT, **provenance}
    if crossing is not None:
        problem = check_crossing(crossing, len(sets))
        if problem:
            raise ValueError(f"crossing entry: {problem}")
        doc[CROSSING] = crossing
    return {**doc, "sets": sets}


def save_seed(
    path: str | Path,
    seed: Seed,
    provenance: dict[str, Any],
    crossing: dict[str, Any] | None = None,
) -> Path:
    """Write a seed directory atomically (built beside ``path``, then renamed into place);
    ``provenance`` (command, seed, version ...) and ``crossing`` go into seed.json."""
    import orbax.checkpoint as ocp

    check_type(seed, Seed, "save_seed's seed", "a Seed")
    check_type(provenance, dict, "provenance", "a dict (command, seed, version, ...)")
    path = Path(path).absolute()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=path.parent))
    try:
        with ocp.StandardCheckpointer() as ckpt:
            ckpt.save(tmp / ARRAYS_DIR, _arrays(seed))
        doc = seed_to_json(seed, provenance, crossing)
        (tmp / SEED_JSON).write_text(json.dumps(doc, indent=1))
        old = path.with_name(f".{path.name}.old")
        shutil.rmtree(old, ignore_errors=True)
        if path.exists():
            path.rename(old)
        tmp.rename(path)
        shutil.rmtree(old, ignore_errors=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return path


def load_seed(path: str | Path | None = None) -> tuple[Seed, dict[str, Any]]:
    """(seed, its parsed seed.json) from ``path`` (default: shipped), or a one-line SeedError."""

    import orbax.checkpoint as ocp

    check_type(path, str | Path | None, "load_seed's path", "a seed directory or None")
    path = default_seed_dir() if path is None else Path(path)
    hint = "make one with scripts/evolve.py --out DIR and pass --seeds DIR/seed"
    if not path.is_dir():
        raise SeedError(f"{path}: no such seed directory ({hint})")
    if not (path / SEED_JSON).is_file() or not (path / ARRAYS_DIR).is_dir():
        raise SeedError(
            f"{path}: not a seed directory, {SEED_JSON} or {ARRAYS_DIR}/ missing ({hint})"
        )
    forget_abandoned_reads()  # a failed read must end with our one-line error alone
    part = SEED_JSON  # which part is damaged, for the message
    try:
        meta = json.loads((path / SEED_JSON).read_text())
        part = f"{ARRAYS_DIR}/"
        with ocp.StandardCheckpointer() as ckpt:
            arrays = ckpt.restore((path / ARRAYS_DIR).absolute())
        arrays = {k: np.asarray(v) for k, v in arrays.items()}
        antibodies = Antibodies(**{f: arrays[f"ab_{f}"] for f in _FIELDS})
        seed = Seed(antibodies, arrays["tau"], arrays["collisions"], arrays["L"])
    except Exception as err:  # noqa: BLE001 (any failure to read is a corrupt seed)
        msg = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise SeedError(f"{path}: corrupt seed ({part}: {msg[:160]}); {hint}") from None
    fmt = meta.get("format") if isinstance(meta, dict) else None
    if fmt != SEED_FORMAT:
        raise SeedError(
            f"{path}: {SEED_JSON} has format {fmt!r}, this jaxais reads {SEED_FORMAT!r} ({hint})"
        )
    x = seed.tau.shape[0]
    if seed.antibodies.type.shape != (x, 8) or seed.L.shape != (x, 8) or x < 1:
        raise SeedError(f"{path}: seed arrays have inconsistent shapes ({hint})")
    problem = _bad_values(seed)
    if problem:
        raise SeedError(f"{path}: {problem} ({hint})")
    if not bool(np.all(within_limits(antibodies))):  # NumPy: host arrays
        raise SeedError(f"{path}: seed antibodies break Table 1's limits ({hint})")
    # The readable file must describe the same sets as the arrays, number for number (the JSON
    # holds each float32 as its shortest round-tripping decimal, so equality is exact).
    f32 = lambda a: np.asarray(a, np.float32)  # every field as float32 (direction as 0/1)
    try:
        readable = [
            Seed(from_dicts(s["antibodies"]), f32(s["tau"]), f32(s["collisions"]), f32(s["L"]))
            for s in meta["sets"]
        ]
    except (KeyError, TypeError, ValueError) as err:
        raise SeedError(f"{path}: {SEED_JSON} is malformed ({err}); {hint}") from None
    same = len(readable) == x and all(
        np.array_equal(f32(a), f32(b))
        for i, one in enumerate(readable)
        for a, b in zip(jax.tree.leaves(one), jax.tree.leaves(take(seed, i)), strict=True)
    )
    if not same:
        raise SeedError(f"{path}: {SEED_JSON} disagrees with {ARRAYS_DIR}/ ({hint})")
    if CROSSING in meta:
        problem = check_crossing(meta[CROSSING], x)
        if problem:
            raise SeedError(f"{path}: {SEED_JSON} is malformed (crossing: {problem}); {hint}")
    return seed, meta
