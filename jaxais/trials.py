"""Statistical trials (SPEC 9): n runs of each system in a world as one compiled, vmapped batch.

Randomness is split so results do not depend on what else shares a batch: trial i's world
placement comes from (seed, i) alone, so every system meets the same start configurations (common
random numbers), and its dynamics from (seed, system label, i), where the label enters by a hash
of its name (:func:`stream_id`), not by its place in a list: adding, removing or reordering
systems changes no other system's trials. A label may carry a variant tag after "@"
(``"SIE@hold=1"``): the same system with other data (``scripts/ablate.py`` batches several
variants of one system), which meets the same worlds and random streams as the plain label.

Two ways to run them:

- :func:`make_trials` builds an experiment as one pure function, ``run(key, params)`` ->
  per-trial arrays, jitted, which ``vmap`` batches over seeds (keys) and parameter grids (a
  params pytree with a leading axis): what sweeps are made of.
- :func:`run_trials` runs several systems' trials from the host, with a progress bar, through
  :mod:`jaxais.runner`'s refilling pool (or as one rollout, to keep every trajectory), and
  returns trial records (what the scripts and the paper's tables use). Its trials are those of
  ``make_trials``: the same keys, the same numbers.

Both run any :class:`~jaxais.controllers.Controller` (default: the STL network).
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
from jaxais.loop import EpisodeConfig, outcome
from jaxais.runner import advance, rollout, run_pool, segment_length, start_batch
from jaxais.systems import LABELS

STL_CONFIG = EpisodeConfig(tau_cap=4000.0, collision_cap=100, stop_at_collision_cap=False)
"""The paper's STL protocol (SPEC 9): a run ends on the finish rule or at 4000 s, nothing else;
more than 100 collisions fails it, and Table 3 uses c capped at 100."""


@dataclass(frozen=True)
class Placement:
    """Where a trial's world put the objects it places at random (they never move in a run).

    Attributes:
        boxes: [B, 2] box centres, padded like ``World.box_region`` (a fixed box at its
            centre; padding rows far outside the arena: mask with ``World.box_valid``).
        goal: [2] goal centre.
    """

    boxes: np.ndarray
    goal: np.ndarray


@dataclass
class TrialSet:
    """The trials of one system in one world.

    Attributes:
        records: one dict per trial: tau (s), collisions (the raw count), collisions_capped
            (at 100, what Table 3 averages), fitness (with the capped c), failed,
            failed_collisions (c > 100), failed_time (4000 s reached), failed_by (a list of
            "collisions", "time"; both can hold), trapped_s, locked_s (trapped with the same
            antibody selected for each antigen, :class:`~jaxais.loop.EpisodeConfig`),
            idiotypic_difference_rate,
            iterations, replaced.
        trajectories: [n] arrays [T_i, 3] of poses sampled every ``chunk`` iterations, or None.
        placements: [n] :class:`Placement`: each trial's boxes and goal, to draw its trajectory
            in the world it ran in.
    """

    records: list[dict[str, Any]]
    trajectories: list[np.ndarray] | None
    placements: list[Placement] = field(default_factory=list)


def base_label(name: str) -> str:
    """A label without its variant tag: ``"SIE@hold=1"`` -> ``"SIE"``."""
    return name.split("@", 1)[0]


def stream_id(system_label: str) -> int:
    """The number that names a label's random stream: a CRC-32 of its base label (a stable
    hash, unlike Python's ``hash``), in [0, 2**31)."""
    return zlib.crc32(base_label(system_label).encode()) & 0x7FFFFFFF


def trial_keys(seed: int, system_label: str, n: int) -> tuple[jax.Array, jax.Array]:
    """(reset keys, run keys), each [n], of a system's trials."""
    return batch_keys(seed, ((system_label, n),))


def batch_keys(seed: int, plan: tuple[tuple[str, int], ...]) -> tuple[jax.Array, jax.Array]:
    """(reset keys, run keys), each [sum of n], of several systems' trials in ``plan``'s
    (label, n) order.

    From ``k_worlds, k_systems = split(key(seed))``: trial i's reset key is
    ``fold_in(k_worlds, i)`` for every system (the same world); its run key is
    ``fold_in(stream, i)`` with ``stream = fold_in(k_systems, stream_id(label))``, which depends
    on the label's name alone.
    """
    streams = np.concatenate([np.full(n, stream_id(label), np.uint32) for label, n in plan])
    trials = np.concatenate([np.arange(n, dtype=np.uint32) for _, n in plan])
    return _derive_keys(np.uint32(seed), streams, trials)


@jax.jit
def _derive_keys(seed: jax.Array, streams: jax.Array, trials: jax.Array):
    """:func:`batch_keys` given the seed and, per trial, its stream id and index ([n] uint32):
    one small program per batch size, whatever the seed and the systems."""
    return _keys(jax.random.key(seed), streams, trials)


def _keys(key: jax.Array, streams: jax.Array, trials: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(reset keys, run keys) [n] of the trials with these stream ids and indices, from ``key``
    (:func:`batch_keys`)."""
    k_worlds, k_systems = jax.random.split(key)
    fold_each = jax.vmap(jax.random.fold_in, in_axes=(None, 0))
    run_streams = fold_each(k_systems, streams)
    return fold_each(k_worlds, trials), jax.vmap(jax.random.fold_in)(run_streams, trials)


@dataclasses.dataclass(frozen=True)
class TrialsConfig:
    """What :func:`make_trials` compiles in (static: it fixes shapes and the program).

    Attributes:
        world: a built-in world's name or a world TOML file (``envs.load_world``).
        n_trials: trials per call.
        label: the system's label, whose name chooses the random stream (:func:`batch_keys`):
            ``make_trials(TrialsConfig(label="SIE"))(key(seed), system)`` gives the trials of
            ``run_trials(world, {"SIE": system}, n, seed)``.
        controller: the controller (default: the STL network, for a :class:`System`).
        episode: caps and recording (default: the paper's STL protocol).
    """

    world: str = "world1"
    n_trials: int = 30
    label: str = "SIE"
    controller: Controller = STL
    episode: EpisodeConfig = dataclasses.field(default_factory=lambda: STL_CONFIG)

    def __post_init__(self):
        _check(self.world, str | Path, "TrialsConfig.world", "a world's name or TOML path")
        object.__setattr__(self, "n_trials", _integer(self.n_trials, "TrialsConfig.n_trials"))
        _check(self.controller, Controller, "TrialsConfig.controller", "a Controller")
        _check(self.episode, EpisodeConfig, "TrialsConfig.episode", "an EpisodeConfig")
        if self.controller is STL:
            _check_label(self.label, "TrialsConfig.label")


def _integer(value: Any, name: str, high: int | None = None) -> int:
    """``value`` as an int >= 1, or in [0, high) (NumPy integers are integers; 2.0 and True
    are not)."""
    _check(value, int | np.integer, name, "an integer")
    if isinstance(value, bool):
        raise ArgumentTypeError(f"{name} must be an integer, got {value!r}")
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
    """:func:`run_trials`' arguments checked, one line naming the first bad one.

    Returns:
        label -> its number of trials.
    """
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
    """An experiment as a pure function: ``run(key, params, sim_params=None)``.

    ``run`` plays ``config.n_trials`` trials of ``config.controller`` with ``params`` (one
    controller's params, e.g. a :class:`System`; every trial gets them) in ``config.world``,
    each to its end, and returns a dict of arrays [n_trials]: :func:`jaxais.loop.outcome`'s
    (tau, collisions, collisions_capped, fitness, failed_collisions, failed_time, trapped_s,
    locked_s, status, iterations) and the controller's ``stats`` (for the STL:
    idiotypic_difference_rate, NaN where not idiotypic, and replaced). It is jitted, and
    ``jax.vmap`` batches it over keys (seeds) and over a params pytree with a leading axis (a
    grid: several values of k1, of b, of the penalties ...); ``sim_params`` (default
    ``envs.default_params()``) is traced too, so the simulator's noise levels can be swept.

    Example::

        run = make_trials(TrialsConfig(world="world1", n_trials=30))
        out = run(jax.random.key(0), make_system("SIE", load_seed()[0]))
        out["tau"].mean()
    """
    _check(config, TrialsConfig, "make_trials' config", "a TrialsConfig")
    world = envs.load_world(config.world)
    episode = config.episode
    n = config.n_trials
    stream = np.full(n, stream_id(config.label), np.uint32)
    trials = np.arange(n, dtype=np.uint32)

    @jax.jit
    def run_in(world, key, params, sim_params):
        dt = float(sim_params.dt)  # static: it fixes the loop's length
        # One call of the task loop runs every trial to its end: a segment of whole chunks past
        # the time cap (the iteration after the cap records the run's end).
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
        # The world is an argument of the program, not constants folded into it: folded, XLA
        # rounds some products differently, and a run's path (chaotic over thousands of
        # steps) would then differ from run_trials'.
        return run_in(world, key, params, sim_params)

    return run


def run_trials(
    world: envs.World,
    systems: Mapping[str, Any],
    n_trials: int | Mapping[str, int],
    seed: int,
    config: EpisodeConfig = STL_CONFIG,
    sim_params: envs.SimParams | None = None,
    progress: Any = None,
    timings: dict[str, float] | None = None,
    controller: Controller | None = None,
    slots: int = 1024,
) -> dict[str, TrialSet]:
    """Run every system's trials: with ``config.record``, as one batch to its slowest run's end
    (every trajectory kept, :func:`jaxais.runner.rollout`); otherwise through a refilling pool
    (:func:`jaxais.runner.run_pool`), where a run that ended frees its slot for the next. The
    records are the same either way.

    Args:
        world: the world.
        systems: label -> the controller's params (a :class:`System` for the STL network).
            A label names the system's random stream (:func:`batch_keys`); the STL's labels
            come from :data:`jaxais.systems.LABELS`, optionally with a variant tag after "@"
            (``"SIE@hold=1"``: then the random streams of the plain label).
        n_trials: trials per system (or per label).
        seed: the run's seed, in [0, 2**32).
        config: caps and recording (``config.record`` keeps every trial's trajectory).
        progress: optional tqdm-like object with ``update(n)``, advanced in simulated
            iterations of the batch with ``config.record``, else in trials ended.
        timings: optional dict collecting ``run_s`` (compiles included).
        controller: the controller every system runs (default: the STL network, the smallest
            variant that runs these systems, :func:`~jaxais.controllers.stl_for`).
        slots: runs live at once in the pool (without ``config.record``).

    Returns:
        label -> :class:`TrialSet`.

    Raises:
        ValueError: one line naming the bad argument, before anything runs (a wrong type, e.g.
            a world's name for ``world``: :class:`ArgumentTypeError`, also a TypeError).
    """
    counts = _check_run(world, systems, n_trials, seed, config, sim_params, progress, controller)
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
    """The records (:class:`TrialSet`) of trials' outcome arrays [n]: :func:`~jaxais.loop.outcome`
    and the controller's stats (the placement and ``status`` are not recorded: failed_time and
    the iterations say the status)."""
    records = []
    for i in range(len(res["tau"])):
        by_c, by_t = bool(res["failed_collisions"][i]), bool(res["failed_time"][i])
        record = {
            "tau": float(res["tau"][i]),
            "collisions": int(res["collisions"][i]),
            "collisions_capped": int(res["collisions_capped"][i]),
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
