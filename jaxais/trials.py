"""Statistical trials (SPEC 9): n runs of each system in a world as one compiled, vmapped batch.

Trial i's world comes from (seed, i) alone (every system meets the same starts) and its dynamics
from (seed, CRC-32 of the label's name, i): no system's trials depend on what else shares the
batch. A variant tag after "@" (``"SIE@hold=1"``) keeps the plain label's worlds and streams.
:func:`make_trials` is one pure jitted function to vmap over keys and params (sweeps);
:func:`run_trials` runs systems from the host through :mod:`jaxais.runner`'s pool and returns
records: the same keys, the same numbers.
"""

from __future__ import annotations

import dataclasses
import time
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxais import envs
from jaxais.controllers import STL, Controller, System, stl_for
from jaxais.io import ArgumentTypeError
from jaxais.io import check_type as _check
from jaxais.loop import COLLISION_RULES, EpisodeConfig, outcome
from jaxais.runner import advance, rollout, run_pool, segment_length, start_batch
from jaxais.systems import LABELS

# [paper] SPEC 9: a run ends on the finish rule or at 4000 s; c > 100 fails it, Table 3 caps c.
STL_CONFIG = EpisodeConfig(tau_cap=4000.0, collision_cap=100, stop_at_collision_cap=False)
_RULE_KEYS = tuple(f"collisions_{rule}" for rule in COLLISION_RULES)  # a record's c by rule


@dataclass(frozen=True)
class Placement:
    """Where a trial's world placed its boxes [B, 2] (padded like ``World.box_region``; mask with
    ``World.box_valid``) and goal [2]."""

    boxes: np.ndarray
    goal: np.ndarray


@dataclass
class TrialSet:
    """One system's trials in one world: ``records`` (:func:`trial_records`), ``trajectories``
    ([n] arrays [T_i, 3] of poses every ``chunk`` iterations, or None), ``placements`` [n]."""

    records: list[dict[str, Any]]
    trajectories: list[np.ndarray] | None
    placements: list[Placement] = field(default_factory=list)


def base_label(name: str) -> str:
    """A label without its variant tag: ``"SIE@hold=1"`` -> ``"SIE"``."""
    return name.split("@", 1)[0]


def stream_id(system_label: str) -> int:
    """A label's random stream: CRC-32 of its base label (stable, unlike ``hash``), < 2**31."""
    return zlib.crc32(base_label(system_label).encode()) & 0x7FFFFFFF


def trial_keys(seed: int, system_label: str, n: int) -> tuple[jax.Array, jax.Array]:
    """(reset keys, run keys), each [n], of a system's trials."""
    return batch_keys(seed, ((system_label, n),))


def batch_keys(seed: int, plan: tuple[tuple[str, int], ...]) -> tuple[jax.Array, jax.Array]:
    """(reset keys, run keys) [sum of n] of ``plan``'s (label, n) trials: reset
    ``fold_in(k_worlds, i)``, run ``fold_in(fold_in(k_systems, stream_id(label)), i)``."""
    streams = np.concatenate([np.full(n, stream_id(label), np.uint32) for label, n in plan])
    trials = np.concatenate([np.arange(n, dtype=np.uint32) for _, n in plan])
    return _derive_keys(np.uint32(seed), streams, trials)


@jax.jit
def _derive_keys(seed: jax.Array, streams: jax.Array, trials: jax.Array):
    """:func:`batch_keys` compiled once per batch size (stream ids, indices: [n] uint32)."""
    return _keys(jax.random.key(seed), streams, trials)


def _keys(key: jax.Array, streams: jax.Array, trials: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(reset keys, run keys) [n] from ``key`` (:func:`batch_keys`)."""
    k_worlds, k_systems = jax.random.split(key)
    fold_each = jax.vmap(jax.random.fold_in, in_axes=(None, 0))
    run_streams = fold_each(k_systems, streams)
    return fold_each(k_worlds, trials), jax.vmap(jax.random.fold_in)(run_streams, trials)


@dataclass(frozen=True)
class TrialsConfig:
    """What :func:`make_trials` compiles in (static). ``label`` picks the random stream, so
    ``make_trials(TrialsConfig(label="SIE"))(key(seed), system)`` gives
    ``run_trials(world, {"SIE": system}, n, seed)``'s trials."""

    world: str = "world1"
    n_trials: int = 30
    label: str = "SIE"
    controller: Controller = STL
    episode: EpisodeConfig = STL_CONFIG

    def __post_init__(self):
        _check(self.world, str | Path, "TrialsConfig.world", "a world's name or TOML path")
        object.__setattr__(self, "n_trials", _integer(self.n_trials, "TrialsConfig.n_trials"))
        _check(self.controller, Controller, "TrialsConfig.controller", "a Controller")
        _check(self.episode, EpisodeConfig, "TrialsConfig.episode", "an EpisodeConfig")
        if self.controller is STL:
            _check_label(self.label, "TrialsConfig.label")


def _integer(value: Any, name: str, high: int | None = None) -> int:
    """``value`` as an int >= 1, or in [0, high) (NumPy ints are; 2.0 and True are not)."""
    _check(value, int | np.integer, name, "an integer")  # a bool is not one
    if value < 1 if high is None else not 0 <= value < high:
        rule = ">= 1" if high is None else f"in [0, 2**{high.bit_length() - 1})"
        raise ValueError(f"{name} must be {rule}, got {value!r}")
    return int(value)


def _check_label(label: Any, name: str) -> None:
    """ValueError unless ``label`` is one of the STL's labels (a variant tag allowed)."""
    _check(label, str, name, "a system label")
    if base_label(label) not in LABELS:
        raise ValueError(f"{name}: unknown system label {label!r} (one of {', '.join(LABELS)})")


def _check_run(world, systems, n_trials, seed, config, sim_params, progress, controller):
    """:func:`run_trials`' arguments checked (one line naming the first bad one): label -> n."""
    hint = f": build it with envs.load_world({world!r})" if isinstance(world, str) else ""
    _check(world, envs.World, "world", "an envs.World", hint)
    _check(systems, Mapping, "systems", "a dict label -> params (a System for the STL)")
    if not systems:
        raise ValueError("systems is empty: give at least one label -> params")
    if isinstance(n_trials, Mapping):
        missing = [k for k in systems if k not in n_trials]
        if missing:
            raise ValueError(f"n_trials has no count for {missing[0]!r}")
        counts = {k: _integer(n_trials[k], f"n_trials[{k!r}]") for k in systems}
    else:
        counts = dict.fromkeys(systems, _integer(n_trials, "n_trials"))
    _integer(seed, "seed", 2**32)  # batch_keys would wrap a larger seed onto another
    _check(config, EpisodeConfig, "config", "an EpisodeConfig (e.g. trials.STL_CONFIG)")
    _check(sim_params, envs.SimParams | None, "sim_params", "an envs.SimParams or None")
    _check(controller, Controller | None, "controller", "a Controller or None")
    if progress is not None and not callable(getattr(progress, "update", None)):
        raise ArgumentTypeError(f"progress must have an update(n) method (tqdm), got {progress!r}")
    for name, system in systems.items():
        if controller is None:  # the STL network: its labels and its params
            _check_label(name, "systems")
            hint = f": build it with make_system({base_label(name)!r}, ...)"
            _check(system, System, f"systems[{name!r}]", "a System", hint)
            system.network.validate()
    return counts


def make_trials(config: TrialsConfig):
    """An experiment as a pure jitted function ``run(key, params, sim_params=None)``: n_trials
    trials of one controller's ``params`` (e.g. a :class:`System`), each to its end, -> dict of
    [n_trials] arrays (:func:`jaxais.loop.outcome`'s and the controller's ``stats``; NaN: does
    not apply). ``jax.vmap`` it over keys and a params pytree with a leading axis (a grid);
    ``sim_params`` is traced too (noise sweeps)."""
    _check(config, TrialsConfig, "make_trials' config", "a TrialsConfig")
    world = envs.load_world(config.world)
    episode = config.episode
    n = config.n_trials
    stream = np.full(n, stream_id(config.label), np.uint32)
    trials = np.arange(n, dtype=np.uint32)

    @jax.jit
    def run_in(world, key, params, sim_params):
        dt = float(sim_params.dt)  # static: it fixes the loop's length
        # One segment of whole chunks past the time cap runs every trial to its recorded end.
        chunks = episode.max_iterations(dt) // episode.chunk + 2
        to_end = dataclasses.replace(episode, segment=chunks * episode.chunk)
        reset_keys, run_keys = _keys(key, stream, trials)
        batched = jax.tree.map(lambda a: jnp.broadcast_to(a, (n, *jnp.shape(a))), params)
        batch = start_batch(
            reset_keys, run_keys, world, sim_params, config.controller, batched, to_end
        )
        batch = advance(batch, world, sim_params, config.controller, batched, to_end)
        out = outcome(batch.runs, episode, dt, xp=jnp)
        if config.controller.stats is not None:
            out |= jax.vmap(config.controller.stats)(batch.runs.ctrl, batched)
        return out

    def run(key: jax.Array, params: Any, sim_params: envs.SimParams | None = None):
        if config.controller is STL:
            _check(params, System, "params", "a System (make_system)")
        sim_params = envs.default_params() if sim_params is None else sim_params
        _check(sim_params, envs.SimParams, "sim_params", "an envs.SimParams")
        # The world is an argument, not folded constants: XLA would round some products
        # differently, and a chaotic run's path would then differ from run_trials'.
        return run_in(world, key, params, sim_params)

    return run


def run_trials(
    world: envs.World, systems: Mapping[str, Any], n_trials: int | Mapping[str, int], seed: int,
    config: EpisodeConfig = STL_CONFIG, sim_params: envs.SimParams | None = None,
    progress: Any = None, timings: dict[str, float] | None = None,
    controller: Controller | None = None, slots: int = 1024,
) -> dict[str, TrialSet]:  # fmt: skip
    """label -> :class:`TrialSet` of each system's ``n_trials`` (an int or per label) trials:
    with ``config.record`` one rollout to the slowest end (trajectories kept), else a refilling
    pool of ``slots`` runs; the same records either way. ``systems``: label (its random stream,
    a variant tag allowed) -> params (a :class:`System` unless ``controller``, default the
    smallest STL that runs them). ``progress`` (tqdm-like) counts iterations with record, else
    trials; ``timings`` collects ``run_s``. A bad argument: one-line ValueError before any run.
    """
    counts = _check_run(world, systems, n_trials, seed, config, sim_params, progress, controller)
    _integer(slots, "slots")
    _check(timings, dict | None, "timings", "a dict or None")
    sim_params = envs.default_params() if sim_params is None else sim_params
    reset_keys, run_keys = batch_keys(seed, tuple((name, counts[name]) for name in systems))
    # Each system's parameters repeated for its trials, assembled on the host (no device work).
    params = jax.tree.map(
        lambda *xs: np.concatenate(xs),
        *[
            jax.tree.map(lambda a, n=counts[name]: np.repeat(np.asarray(a)[None], n, 0), s)
            for name, s in systems.items()
        ],
    )
    if controller is None:
        # Parts of the network no system in the batch uses (replacement, idiotypic selection,
        # learning) are left out of the program: same trials, a smaller and faster loop.
        controller = stl_for(params)
    update = None if progress is None else progress.update
    t = time.perf_counter()
    if config.record:
        # One batch to its slowest run's end: every trial's trajectory is kept.
        batch = rollout(reset_keys, run_keys, world, sim_params, controller, params, config, update)
        res = outcome(batch.runs, config, float(sim_params.dt))
        if controller.stats is not None:
            res |= jax.device_get(jax.vmap(controller.stats)(batch.runs.ctrl, params))
        # Boxes and the goal stay where reset put them: the final state holds the placement.
        res |= {"boxes": batch.runs.sim.boxes, "goal": batch.runs.sim.goal}
        chunks = np.asarray(batch.runs.t) // config.chunk
        poses = np.asarray(batch.poses)
    else:
        # Refills keep the phase of the STL's idiotope schedule (a static field, one per batch).
        period = getattr(getattr(params, "network", None), "idiotope_period", 1)
        align = segment_length(config.chunk, period)
        res = run_pool(
            reset_keys, run_keys, params, world, sim_params, controller, config, slots, align,
            update,
        )  # fmt: skip
    if timings is not None:
        timings["run_s"] = timings.get("run_s", 0.0) + time.perf_counter() - t
    placed_boxes, placed_goal = np.asarray(res["boxes"]), np.asarray(res["goal"])

    out, start = {}, 0
    for name in systems:
        part = range(start, start + counts[name])
        records = trial_records({k: v[start : part.stop] for k, v in res.items()})
        trajectories = [poses[i, : chunks[i] + 2] for i in part] if config.record else None
        placements = [Placement(boxes=placed_boxes[i], goal=placed_goal[i]) for i in part]
        out[name] = TrialSet(records, trajectories, placements)
        start += counts[name]
    return out


def trial_records(res: Mapping[str, np.ndarray]) -> list[dict[str, Any]]:
    """One dict per trial of outcome arrays [n] (:func:`~jaxais.loop.outcome`'s, the stats'):
    tau, collisions (raw), collisions_capped, collisions_<rule> (raw, each counting rule),
    fitness, failed, failed_collisions, failed_time, failed_by, trapped_s, locked_s, iterations,
    then the stats (NaN -> None)."""
    records = []
    for i in range(len(res["tau"])):
        by_c, by_t = bool(res["failed_collisions"][i]), bool(res["failed_time"][i])
        record = {
            "tau": float(res["tau"][i]),
            "collisions": int(res["collisions"][i]),
            "collisions_capped": int(res["collisions_capped"][i]),
            # c under each counting rule (jaxais.loop.COLLISION_RULES), where counted.
            **{k: int(res[k][i]) for k in _RULE_KEYS if k in res},
            "fitness": float(res["fitness"][i]),
            "failed": by_c or by_t,
            "failed_collisions": by_c,
            "failed_time": by_t,
            "failed_by": [cap for cap, on in (("collisions", by_c), ("time", by_t)) if on],
            "trapped_s": float(res["trapped_s"][i]),
            "locked_s": float(res["locked_s"][i]),
            "iterations": int(res["iterations"][i]),
        }
        # The rest are the controller's stats; NaN (does not apply) is None.
        for key in sorted(set(res) - set(record) - {"boxes", "goal", "status"}):
            value = res[key][i].item()
            record[key] = None if isinstance(value, float) and np.isnan(value) else value
        records.append(record)
    return records


def summarise(records: list[dict[str, Any]]) -> dict[str, Any]:
    """Means and failure rates of a list of trial records."""
    arr = lambda k: np.asarray([r[k] for r in records], float)
    rates = [r.get("idiotypic_difference_rate") for r in records]  # None: does not apply
    locked = [r.get("locked_s") for r in records]  # None: a record from before lock-ups
    n = len(records)
    return {
        "n": n,
        "tau": float(arr("tau").mean()),
        "collisions": float(arr("collisions_capped").mean()),
        "fitness": float(arr("fitness").mean()),
        "failure_rate": sum(r["failed"] for r in records) / n,
        "failed_by_collisions": sum(r["failed_collisions"] for r in records) / n,
        "failed_by_time": sum(r["failed_time"] for r in records) / n,
        "trapped_s": float(arr("trapped_s").mean()),
        "locked_s": None if any(x is None for x in locked) else float(np.mean(locked)),
        "idiotypic_difference_rate": (
            None if any(x is None for x in rates) else float(np.mean(rates))
        ),
    }
