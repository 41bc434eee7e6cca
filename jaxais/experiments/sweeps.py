"""Parameter landscapes: a grid over the STL's traced parameters, all points' trials as one pool.

Network constants and readings are traced System data, so every grid point is one compiled
program with other numbers; :func:`run_sweep` runs all points x trials through
:func:`jaxais.runner.run_pool`. Trial i of every point gets trial i's placement and streams of
``run_trials`` (common random numbers: the paper's point reproduces the plain trials). Per point:
mean and 95 % CI of tau, c (capped), f, trapped time (t interval), failure rate (Wilson) and the
idiotypic difference rate (t; idiotypic systems only). Also the reality gap (noise scaled).
"""

from __future__ import annotations

import itertools
import math
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np
from scipy import stats as sps
from tqdm.auto import tqdm

from jaxais import envs
from jaxais.controllers import System, stl_for
from jaxais.experiments import protocol
from jaxais.experiments.one_system import check_types
from jaxais.experiments.records import (
    FORMATS,
    build_systems,
    portable_command,
    run_config,
    scaled_world,
)
from jaxais.experiments.stats import CI_LEVEL
from jaxais.immune.network import BOUNDS, NetworkParams
from jaxais.immune.readings import readings as make_readings
from jaxais.io import (
    RUN_BYTES,
    Run,
    atomic_write_json,
    check_memory,
    check_names,
    check_number,
    check_path,
    check_type,
    open_run,
)
from jaxais.labels import SYSTEMS, label, parse_label
from jaxais.lock import scoped
from jaxais.loop import EpisodeConfig
from jaxais.runner import run_pool, segment_length
from jaxais.systems import FIXED, PARAMETERS, USED_BY, system_params, with_params
from jaxais.trials import batch_keys, run_trials, trial_records

# The axes' names, the systems that use each (USED_BY) and those that cannot be axes (FIXED)
# are read from the parameters' declarations (jaxais.systems).
MAX_AXIS = 10**6  # values of one axis at most (the grid's size is bounded by its memory)
_WHOLE = {int: (np.int32, "an integer parameter"), bool: (bool, "a switch, 0 (off) or 1 (on)")}

# Summarised per point (c capped at 100): name -> its outcome array.
METRICS = {"tau": "tau", "c": "collisions_capped", "f": "fitness", "trapped_s": "trapped_s"}
PAPER_POINT = {"k1": 0.85, "k2": 1.10}  # [paper] section 5: ~20 % idiotypic difference rate


def parse_axis(spec: str, kinds: dict[str, type] | None = None) -> tuple[str, np.ndarray]:
    """``"k1=0:2:11"`` (11 points from 0 to 2) or ``"k1=0.5,0.85,1.1"`` -> (name, values); a
    switch (``alpha_on_self=0,1``) takes 0 and 1. ``kinds``: a contender's parameters, name ->
    float, int or bool (:func:`leaf_kinds`); default the STL's. ValueError (one line) on a bad
    spec."""
    name, sep, values = spec.partition("=")
    name = name.strip()
    if not sep or not values.strip():
        raise ValueError(f"--grid {spec!r}: write NAME=START:STOP:COUNT or NAME=V1,V2,...")
    if kinds is None and name in FIXED:
        raise ValueError(f"--grid {name}: not traced ({FIXED[name]})")
    known = {n: kind for n, (_, kind) in PARAMETERS.items()} if kinds is None else kinds
    if name not in known:
        whose = "" if kinds is None else " of the contender"
        raise ValueError(f"--grid {name}: unknown parameter{whose} (one of {', '.join(known)})")
    kind = known[name]
    try:
        if ":" in values:
            start, stop, count = values.split(":")
            n = int(count)
            if not 1 <= n <= MAX_AXIS:
                raise ValueError
            grid = np.linspace(float(start), float(stop), n)
        else:
            grid = np.array([float(v) for v in values.split(",")])
    except ValueError:
        raise ValueError(
            f"--grid {spec!r}: write NAME=START:STOP:COUNT (1 <= COUNT <= {MAX_AXIS:.0e}) or "
            "NAME=V1,V2,..."
        ) from None
    if not np.all(np.isfinite(grid)):
        raise ValueError(f"--grid {spec!r}: values must be finite")
    if np.unique(grid).size < grid.size:
        raise ValueError(f"--grid {spec!r}: a value twice (each point runs once)")
    if kind in _WHOLE:  # a value its dtype changes is not one
        dtype, what = _WHOLE[kind]
        if not np.array_equal(grid.astype(dtype), grid):
            raise ValueError(f"--grid {name}: {what}, got {values}")
        grid = grid.astype(dtype)
    return name, grid


def grid_points(axes: Sequence[tuple[str, np.ndarray]]) -> list[dict[str, Any]]:
    """Every combination of the axes' values, the last axis fastest."""
    names = [name for name, _ in axes]
    return [
        dict(zip(names, (v.item() for v in combo), strict=True))
        for combo in itertools.product(*(values for _, values in axes))
    ]


def _leaves(params: Any) -> dict[str, tuple[Any, Any]]:
    """A pytree's leaves by key path, ``name -> (path, leaf)``: names join the keys with dots
    (``speed``, ``network.k1``, ``w.0``)."""
    named = {}
    for path, leaf in jax.tree_util.tree_flatten_with_path(params)[0]:
        keys = [getattr(k, "key", getattr(k, "name", getattr(k, "idx", k))) for k in path]
        named[".".join(map(str, keys))] = (path, leaf)
    return named


def leaf_kinds(params: Any) -> dict[str, type]:
    """A contender's sweepable parameters: each scalar leaf's name -> bool, int or float."""
    kinds = {}
    for name, (_, leaf) in _leaves(params).items():
        a = np.asarray(leaf)
        if a.ndim == 0 and a.dtype.kind in "biuf":
            kinds[name] = {"b": bool, "i": int, "u": int}.get(a.dtype.kind, float)
    return kinds


def point_params(base: Any, points: Sequence[dict[str, Any]]) -> Any:
    """A contender's ``base`` params once per point, each named leaf set to the point's value
    in the leaf's dtype, stacked [P]."""
    leaves = _leaves(base)
    by_path = [{leaves[k][0]: v for k, v in point.items()} for point in points]

    def stack(path, b):
        return np.stack([np.asarray(p.get(path, b), np.asarray(b).dtype) for p in by_path])

    return jax.tree_util.tree_map_with_path(stack, base)


def point_systems(base: System, points: Sequence[dict[str, Any]]) -> System:
    """``base`` once per point with its values, stacked [P]; ValueError on a value out of range."""
    ours = {name: np.asarray(v).item() for name, v in vars(base.readings).items()}
    for point in points:  # checked here: with_params would clip a value out of its range
        base.network.replace(**{k: v for k, v in point.items() if k in BOUNDS}).validate()
        readings = {k: v for k, v in point.items() if PARAMETERS[k][0] == "readings"}
        make_readings(**(ours | readings))  # the readings' own checks: hold >= 1 ...
    systems = [with_params(base, point) for point in points]
    # Each value in its base leaf's dtype (an int32 hold stays int32: the same program).
    return jax.tree.map(
        lambda b, *xs: np.stack([np.asarray(x, np.asarray(b).dtype) for x in xs]), base, *systems
    )


def _t_interval(x: np.ndarray) -> dict[str, Any]:
    """The mean of ``x``'s finite values and its Student's t interval."""
    x = x[np.isfinite(x)]
    mean = float(np.mean(x)) if x.size else math.nan
    ci = [mean, mean]
    if x.size >= 2:
        t = sps.t.ppf(0.5 + CI_LEVEL / 2, x.size - 1)
        half = float(t * np.std(x, ddof=1) / math.sqrt(x.size))
        ci = [mean - half, mean + half]
    return {"mean": mean, "ci": ci}


def _wilson(k: int, n: int) -> dict[str, Any]:
    """The rate of k successes in n and its Wilson score interval."""
    z = sps.norm.ppf(0.5 + CI_LEVEL / 2)
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return {"mean": p, "ci": [max(0.0, centre - half), min(1.0, centre + half)]}


def summarise_point(result: dict[str, np.ndarray]) -> dict[str, Any]:
    """One point's means and intervals from its trials' outcome arrays [n]."""
    out: dict[str, Any] = {"n": int(result["tau"].size)}
    for name, key in METRICS.items():
        out[name] = _t_interval(np.asarray(result[key], np.float64))
    failed = np.asarray(result["failed_collisions"]) | np.asarray(result["failed_time"])
    out["failure_rate"] = _wilson(int(failed.sum()), failed.size)
    if "idiotypic_difference_rate" in result:
        idio = np.asarray(result["idiotypic_difference_rate"], np.float64)
        out["idiotypic_difference_rate"] = None if np.isnan(idio).all() else _t_interval(idio)
    return out


def chunks(n_points: int, n_trials: int, slots: int) -> list[tuple[int, int]]:
    """The grid's chunks, ``(first point, end)``: each of at least ``slots`` runs (the last joins
    the one before it), so that every chunk's pool is as wide as one pool of the whole grid.
    XLA's rounding of a run can depend on the width of the batch it runs in (a rare step, which
    a chaotic run then amplifies), though not on its batch mates."""
    los = list(range(0, n_points, -(-slots // n_trials)))
    if len(los) > 1 and (n_points - los[-1]) * n_trials < slots:
        los.pop()
    return list(zip(los, [*los[1:], n_points], strict=True))


def run_sweep(
    world: envs.World,
    base: System,
    label: str,
    axes: Sequence[tuple[str, np.ndarray]],
    n_trials: int,
    seed: int,
    config: EpisodeConfig,
    sim_params: envs.SimParams,
    slots: int = 1024,
    progress: Callable[[int], None] | None = None,
    run: Run | None = None,
    records: bool = False,
    controller: Any = None,
) -> dict[str, Any]:
    """Every grid point's ``n_trials`` trials of ``base`` with the point's values, in
    :func:`chunks` of whole points: a System, or with ``controller`` a contender's params.

    ``label`` names the random streams (as in ``run_trials``); ``axes`` are :func:`parse_axis`'s;
    ``progress`` gets the runs ended; each chunk is a unit of ``run`` (a held one is not rerun);
    ``records`` keeps each point's trial records. Returns the sweep.json document, points in
    :func:`grid_points` order.
    """
    points = grid_points(axes)
    if controller is None:  # the STL: the smallest network that runs the grid
        grid = point_systems(base, points)
        controller = stl_for(grid)
        align = segment_length(config.chunk, int(base.network.idiotope_period))
    else:
        grid = point_params(base, points)
        align = segment_length(config.chunk)
    start = time.perf_counter()
    out_points, iterations = [], 0
    for lo, hi in chunks(len(points), n_trials, slots):
        unit = f"points {lo}-{hi - 1}"
        if run is not None and unit in run.units:  # a chunk finished before a resume
            got = run.units[unit]
            if progress is not None:
                progress(n_trials * (hi - lo))
        else:
            # Trial i of every point: run_trials' trial i of ``label`` (common random numbers).
            reset_keys, run_keys = batch_keys(seed, ((label, n_trials),) * (hi - lo))
            params = jax.tree.map(lambda a, lo=lo, hi=hi: np.repeat(a[lo:hi], n_trials, 0), grid)
            res = run_pool(reset_keys, run_keys, params, world, sim_params, controller,
                           config, slots=slots, align=align, progress=progress)  # fmt: skip
            got = {"points": [], "iterations": int(np.sum(res["iterations"], dtype=np.int64))}
            for p in range(hi - lo):
                part = {k: v[p * n_trials : (p + 1) * n_trials] for k, v in res.items()}
                got["points"].append({"values": points[lo + p], **summarise_point(part)})
                if records:
                    got["points"][-1]["trials"] = trial_records(part)
            if run is not None:
                run.finish(unit, got)
        out_points += got["points"]
        iterations += got["iterations"]
    wall = time.perf_counter() - start
    runs = n_trials * len(points)
    names = [name for name, _ in axes]
    if isinstance(base, System):
        base_values = system_params(base, names)
    else:
        leaves = _leaves(base)
        base_values = {name: leaves[name][1] for name in names}
    return sweep_document(axes, base_values, out_points, runs, iterations, wall)


def sweep_document(
    axes: Sequence[tuple[str, np.ndarray]],
    base_values: dict[str, Any],
    points: list[dict[str, Any]],
    runs: int,
    iterations: int,
    wall: float,
) -> dict[str, Any]:
    """:func:`run_sweep`'s document (``jaxais-sweep/1``, docs/formats.md) of its ``points``
    (:func:`summarise_point`'s, each with its ``values``); :func:`sweep` adds the run's facts."""
    return {
        "format": FORMATS["sweep"],
        "axes": {name: np.asarray(values).tolist() for name, values in axes},
        "base_values": {k: np.asarray(v).item() for k, v in base_values.items()},
        "points": points,
        "runs": runs,
        "robot_iterations": iterations,
        "wall_s": wall,
        "runs_per_s": runs / wall,
        "robot_iterations_per_s": iterations / wall,
    }


def surface(doc: dict[str, Any], metric: str) -> np.ndarray:
    """A metric's point means on the grid, shape [len(axis) for each axis] (NaN where none)."""
    shape = [len(v) for v in doc["axes"].values()]
    values = [math.nan if p.get(metric) is None else p[metric]["mean"] for p in doc["points"]]
    return np.asarray(values, np.float64).reshape(shape)


def interpolate(doc: dict[str, Any], metric: str, at: dict[str, float]) -> float | None:
    """A metric's bilinear mean at ``at`` in a 2-D sweep over its axes, or None (outside, other)."""
    names = list(doc["axes"])
    if len(names) != 2 or set(names) != set(at):
        return None
    from scipy.interpolate import RegularGridInterpolator

    axes = [np.asarray(doc["axes"][n], np.float64) for n in names]
    if any(a.size < 2 for a in axes):
        return None
    f = RegularGridInterpolator(axes, surface(doc, metric), bounds_error=False)
    value = float(f([[at[n] for n in names]])[0])
    return None if math.isnan(value) else value


NOISE_KINDS: dict[str, tuple[str, ...]] = {
    "ir": ("ir_noise",),
    "camera": ("camera_miss", "camera_shift"),
    "wheel": ("wheel_noise",),
}  # World fields by kind; SimParams.ir_noise (SPEC 2) stays on in every world, not scaled


def noisy_world(world: envs.World, scale: float, kinds: Sequence[str] = tuple(NOISE_KINDS)):
    """``world`` with the noise levels of ``kinds`` times ``scale`` (probabilities capped at 1);
    the levels are static (a noiseless world draws no noise): each scale is its own program."""
    if scale < 0 or not math.isfinite(scale):
        raise ValueError(f"noise scales must be finite and >= 0, got {scale}")
    unknown = sorted(set(kinds) - set(NOISE_KINDS))
    if unknown:
        raise ValueError(
            f"unknown noise kind(s) {', '.join(unknown)} (of {', '.join(NOISE_KINDS)})"
        )
    levels = {}
    for kind in kinds:
        for name in NOISE_KINDS[kind]:
            value = float(getattr(world, name)) * scale
            levels[name] = min(value, 1.0) if name.startswith("camera") else value
    return world.replace(**levels)


def _arrays(records: Sequence[dict[str, Any]]) -> dict[str, np.ndarray]:
    """Trial records as the outcome arrays :func:`summarise_point` reads."""
    keys = (*METRICS.values(), "failed_collisions", "failed_time")
    out = {k: np.asarray([r[k] for r in records]) for k in keys}
    rates = np.asarray([r.get("idiotypic_difference_rate") for r in records], np.float64)
    if not np.isnan(rates).all():  # None (does not apply) reads as NaN
        out["idiotypic_difference_rate"] = rates
    return out


def run_noise_sweep(
    world: envs.World,
    systems: dict[str, System],
    scales: Sequence[float],
    n_trials: int,
    seed: int,
    config: EpisodeConfig,
    sim_params: envs.SimParams | None = None,
    kinds: Sequence[str] = tuple(NOISE_KINDS),
    progress: Callable[[int], None] | None = None,
    run: Run | None = None,
) -> dict[str, Any]:
    """Every system's trials in ``world`` with its noise scaled by each of ``scales`` (1 = its
    own levels); one batch per scale, the same seed (common random numbers); a scale is a unit
    of ``run``. Returns the reality_gap.json document."""
    start = time.perf_counter()
    worlds = [noisy_world(world, s, kinds) for s in scales]  # every scale checked first
    points = []
    for i, (scale, w) in enumerate(zip(scales, worlds, strict=True)):
        if run is not None and f"scale {i}" in run.units:
            points.append(run.units[f"scale {i}"])
        else:
            res = run_trials(w, systems, n_trials, seed, config, sim_params)
            levels = {n: float(getattr(w, n)) for names in NOISE_KINDS.values() for n in names}
            summary = {k: summarise_point(_arrays(ts.records)) for k, ts in res.items()}
            points.append({"scale": float(scale), "levels": levels, "systems": summary})
            if run is not None:
                run.finish(f"scale {i}", points[-1])
        if progress is not None:
            progress(1)
    return noise_document(kinds, scales, points, time.perf_counter() - start)


def noise_document(
    kinds: Sequence[str], scales: Sequence[float], points: list[dict[str, Any]], wall: float
) -> dict[str, Any]:
    """:func:`run_noise_sweep`'s document (``jaxais-reality-gap/1``) of its ``points`` (each
    ``{"scale", "levels", "systems": {label: summarise_point's}}``)."""
    return {
        "format": FORMATS["reality_gap"],
        "kinds": list(kinds),
        "scales": [float(s) for s in scales],
        "points": points,
        "wall_s": wall,
    }


def finish_document(
    doc: dict[str, Any],
    *,
    names: Sequence[str],
    world: str,
    seed: int,
    trials: int,
    wall_total: float,
    config: dict[str, Any],
    paper_point: bool,
) -> dict[str, Any]:
    """``doc`` (:func:`sweep_document`'s or :func:`noise_document`'s) with what :func:`sweep`
    knows of the run: its systems, world, seed, trials, total wall time, ``config`` (a trials
    file's, with the command, processes and devices) and, for a grid over a paper system's k1
    and k2 (``paper_point``), the idiotypic difference rate interpolated at the paper's point."""
    doc = doc | {"wall_s_total": wall_total, "system": ",".join(names), "world": world,
                 "seed": seed, "trials": trials}  # fmt: skip
    if paper_point:
        rate = interpolate(doc, "idiotypic_difference_rate", PAPER_POINT)
        doc["paper_point"] = {"values": PAPER_POINT, "idiotypic_difference_rate": rate}
    return doc | {"config": config}


def _contender(contender: Any, grid: Any, system: Any, random_set: Any, seeds: Any) -> Any:
    """The sweep's contender (:func:`jaxais.experiments.contenders.resolve`'s), or None."""
    if contender is None:
        return None
    if grid is None:
        raise ValueError("--contender sweeps a --grid of its parameters (--noise runs --system)")
    if system is not None or random_set or seeds:
        raise ValueError("--contender replaces --system (and --random-set and --seeds)")
    from jaxais.experiments.contenders import one

    return one(contender)


@scoped  # its folder's lock goes when it returns or raises
def sweep(
    out: str | Path,
    *,
    grid: Sequence[str] | None = None,
    noise: str | Sequence[float] | None = None,
    noise_kinds: str | Sequence[str] | None = None,
    system: str | None = None,
    random_set: str | None = None,
    world: str | None = None,
    trials: int | None = None,
    seed: int = 0,
    seeds: str | Path | None = None,
    tau_cap: float | None = None,
    collision_cap: int | None = None,
    slots: int = 1024,
    command: str | None = None,
    resume: bool = False,
    records: bool = False,
    contender: Any = None,
    world_scale: float = 1.0,
) -> dict[str, Any]:
    """A grid over the STL's parameters (``grid``: :func:`parse_axis` specs) or the reality gap
    (``noise``: scales of the world's noise, or them comma-separated), written into ``out``
    (missing or empty; ``resume`` finishes an interrupted run) as sweep.json/.png or
    reality_gap.json/.png; returns it.

    ``contender`` (instead of ``system``): a grid over a contender's parameters, named by their
    key paths in its params pytree (``speed``, ``network.k1``; :func:`leaf_kinds`), given as a
    spec ``[LABEL=]FILE.py:NAME``, a ``(controller, params)`` tuple or a ``Contender``.
    ``world_scale`` scales the world and the camera's range (:func:`records.scaled_world`).

    Defaults as ``scripts/sweep.py --help`` says. Under ``jax.distributed`` every process computes
    the same numbers and process 0 writes. ValueError (one line) on a bad argument, before any run.
    """
    from jaxais.experiments.sweep_plots import save_noise_figure, save_sweep_figures  # imports us

    check_path(out, "--out", "a folder's path")
    check_types(world=world, trials=trials, seed=seed, seeds=seeds, slots=slots,
                random_set=random_set, command=command, resume=resume, records=records)  # fmt: skip
    if grid is not None:  # one string is one axis
        grid = [grid] if isinstance(grid, str) else grid
        check_type(grid, list | tuple, "--grid", "axis specs NAME=START:STOP:COUNT (a list)")
        for spec in grid:
            check_type(spec, str, "--grid", "axis specs NAME=START:STOP:COUNT (strings)")
    if isinstance(noise, str):  # scripts/sweep.py's --noise
        try:
            noise = [float(v) for v in noise.split(",")]
        except ValueError:
            raise ValueError(f"--noise must be comma-separated numbers, got {noise!r}") from None
    elif noise is not None:
        check_type(noise, list | tuple | np.ndarray, "--noise", "scales (a list of numbers)")
        noise = [check_number(v, "--noise") for v in noise]
    kinds_given = noise_kinds  # as given, for the manifest (a resume compares it)
    if noise_kinds is not None:
        noise_kinds = check_names(noise_kinds, "--noise-kinds")
    if system is not None:
        system = ",".join(check_names(system, "--system"))
    if (grid is None) == (noise is None):
        raise ValueError("give one of grid (parameter axes) and noise (noise scales)")
    if world is None:  # "" is a world the loader refuses, not the default
        world = protocol.REAL_WORLD if noise is not None else protocol.WORLDS[0]
    trials = protocol.trials_for_world(world) if trials is None else trials
    protocol.check_seed(seed)
    world_scale = protocol.check_world_scale(world_scale, [str(world)])
    tau_cap, collision_cap = protocol.check_caps(tau_cap, collision_cap)
    if trials < 1:
        raise ValueError(f"--trials must be >= 1, got {trials}")
    if slots < 1:
        raise ValueError(f"--slots must be >= 1, got {slots}")
    entrant = _contender(contender, grid, system, random_set, seeds)
    system = ("SIE" if grid is not None else "SIE,SRL,HDC") if system is None else system
    names = [entrant.label] if entrant else system.split(",")
    unknown = [] if entrant else [name for name in names if name not in SYSTEMS]
    if unknown:
        raise ValueError(f"--system: unknown system {unknown[0]!r} (one of {', '.join(SYSTEMS)})")
    if len(set(names)) < len(names):
        raise ValueError(f"--system names a system twice: {','.join(names)}")
    if records and grid is None:
        raise ValueError("--records keeps the runs of a --grid sweep, not of --noise")
    if grid is not None and len(names) != 1:
        raise ValueError("--grid sweeps one system: give --system NAME")
    if random_set and not {"UIE", "URL"} & set(names):
        raise ValueError("--random-set applies to UIE and URL only")
    if entrant is None:
        names = [label(n, random_set or "R1") for n in names]
    if grid is not None:
        own = None if entrant is None else leaf_kinds(entrant.params)
        axes = [parse_axis(spec, own) for spec in grid]
        axis_names = [name for name, _ in axes]
        if len(set(axis_names)) < len(axis_names):
            raise ValueError(f"--grid names a parameter twice: {', '.join(axis_names)}")
        if entrant is None:  # a paper system may not use an axis; a contender uses all its own
            code = parse_label(names[0])[0]
            for name in axis_names:
                if code not in USED_BY.get(name, SYSTEMS):
                    users = ", ".join(USED_BY[name])
                    raise ValueError(f"--grid {name}: {code} does not use it (only {users} do)")
        points = math.prod(len(v) for _, v in axes)
        check_memory(points, RUN_BYTES, "--grid points")  # before the points are listed
    elif not all(0 <= s < math.inf for s in noise):
        raise ValueError(f"--noise scales must be finite and >= 0, got {list(noise)}")
    elif len(set(noise)) < len(noise):
        raise ValueError(f"--noise names a scale twice: {list(noise)}")
    if grid is not None and noise_kinds is not None:
        raise ValueError("--noise-kinds applies to --noise only")
    kinds = tuple(NOISE_KINDS if noise_kinds is None else noise_kinds)
    if not kinds or len(set(kinds)) < len(kinds) or set(kinds) - set(NOISE_KINDS):
        raise ValueError(f"--noise-kinds: one or more of {', '.join(NOISE_KINDS)}, each once")
    pool = points if grid is not None else len(names)  # runs per trial index in one pool
    check_memory(trials, pool * RUN_BYTES, "--trials")
    loaded, params = scaled_world(world, world_scale)
    config = EpisodeConfig(tau_cap=tau_cap, collision_cap=collision_cap)
    network = NetworkParams()
    if entrant is None:
        systems, seed_info = build_systems(names, seeds, network)
    else:
        systems, seed_info = {entrant.label: entrant.params}, None
    if grid is not None:
        points = grid_points(axes)
        if entrant is None:
            point_systems(systems[names[0]], points)  # every value in range, before any run
        total, unit = trials * len(points), "run"
    else:
        total, unit = len(noise), "level"
    # Every process runs every step (and computes the same numbers); process 0 reports and writes.
    lead = jax.process_index() == 0
    settings = dict(grid=grid, noise=noise, noise_kinds=kinds_given, system=names, world=world,
                    trials=trials, seed=seed, seeds=None if seeds is None else str(seeds),
                    tau_cap=tau_cap, collision_cap=collision_cap, slots=slots)  # fmt: skip
    if entrant is not None:  # recorded only when given: earlier runs' manifests stay valid
        settings["contender"] = entrant.source
    if world_scale != 1:  # so too the world's scale
        settings["world_scale"] = world_scale
    run = open_run(out, "sweep", settings, resume=resume, write=lead)
    start = time.perf_counter()
    desc = f"{','.join(names)} in {loaded.name}"
    with tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, disable=not lead) as bar:
        if grid is not None:
            doc = run_sweep(
                loaded, systems[names[0]], names[0], axes, trials, seed, config, params, slots,
                bar.update, run, records, None if entrant is None else entrant.controller,
            )  # fmt: skip
        else:
            doc = run_noise_sweep(
                loaded, systems, noise, trials, seed, config, params, kinds, bar.update, run
            )
    wall_total = time.perf_counter() - start
    cfg = run_config(loaded, world, config, network, params, seed_info, world_scale)
    if entrant is not None:
        from jaxais.experiments.contenders import contender_config

        cfg = contender_config(cfg, entrant.source)
    cfg |= {
        "command": None if command is None else portable_command(command),
        "processes": jax.process_count(),
        "devices": jax.device_count(),
    }
    doc = finish_document(doc, names=names, world=loaded.name, seed=seed, trials=trials,
                          wall_total=wall_total, config=cfg,
                          paper_point=grid is not None and entrant is None)  # fmt: skip
    if lead:
        name = "sweep" if grid is not None else "reality_gap"
        atomic_write_json(run.out / f"{name}.json", doc)
        (save_sweep_figures if grid is not None else save_noise_figure)(doc, run.out)
        run.complete()
    return doc
