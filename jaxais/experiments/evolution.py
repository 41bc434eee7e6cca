"""The LTL experiment (``scripts/evolve.py``): evolve antibody sets into ``out``: ``checkpoints/``
(every generation, with the breeding operators' names; ``resume`` continues exactly, with the
same operators), ``seed/`` (with its crossing rates in fresh starts the GA never used),
``summary.json`` and ``fitness.png``. :func:`check_seed` writes nothing.
"""

from __future__ import annotations

import contextlib
import shlex
import time
from pathlib import Path
from typing import Any

import jax
import numpy as np

import jaxais
from jaxais import envs
from jaxais.checkpointing import CheckpointError, GACheckpointer
from jaxais.experiments.diversity import compare_diversity, diversity
from jaxais.experiments.records import portable_path
from jaxais.ga import driver
from jaxais.ga.config import CROSSING_STARTS, MAX_SEED, ConfigError, GAConfig
from jaxais.ga.operators import Operators, default_operators
from jaxais.io import (
    INTEGER,
    RUN_BYTES,
    atomic_write_json,
    check_bool,
    check_memory,
    check_path,
    check_type,
)
from jaxais.seed import Seed, load_seed, save_seed

__all__ = ["check_seed", "evolve", "measure_crossing", "report"]

_COMPILE_EVENTS = frozenset(
    f"/jax/core/compile/{e}_duration"
    for e in ("jaxpr_trace", "jaxpr_to_mlir_module", "backend_compile")
)


@contextlib.contextmanager
def _compile_clock():
    """A one-element list: the seconds of JAX's traces, lowerings and compiles within the block."""
    seconds = [0.0]

    def listen(event: str, duration: float, **kwargs: Any) -> None:
        if event in _COMPILE_EVENTS:
            seconds[0] += duration

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        yield seconds
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)


def _check(seed: int, crossing_starts: int, config: GAConfig) -> None:
    check_type(seed, INTEGER, "seed", "an integer")
    check_type(crossing_starts, INTEGER, "crossing_starts", "an integer")
    check_type(config, GAConfig, "config", "a GAConfig or None")
    if not 0 <= seed <= MAX_SEED:
        raise ConfigError("seed", f"must be in [0, {MAX_SEED}], got {seed}")
    if crossing_starts < 1:
        raise ConfigError("crossing_starts", f"must be >= 1, got {crossing_starts}")
    # A generation's runs, and the fresh starts of every population's best, run at once.
    p, flag = config.populations, "--populations x --robots x --starts"
    check_memory(p * config.robots * config.starts, RUN_BYTES, flag)
    starts = max(config.success_starts, crossing_starts)
    which = "success" if starts > crossing_starts else "crossing"
    check_memory(p * starts, RUN_BYTES, f"--populations x --{which}-starts")


def _generation_record(generation: int, evaluation, best, wall: float) -> dict[str, Any]:
    """One generation's history line: its evaluation and each population's best so far."""
    f, tau, c = (np.asarray(x) for x in (evaluation.fitness, evaluation.tau, evaluation.collisions))
    crossings = np.asarray(evaluation.crossings)
    pops = []
    for p in range(f.shape[0]):
        i = int(np.argmin(f[p]))
        pops.append(
            {
                "best_f": float(f[p, i]),
                "mean_f": float(f[p].mean()),
                "best_tau": float(tau[p, i]),
                "best_collisions": float(c[p, i]),
                "best_crossings": int(crossings[p, i]),
                "crossing_rate": float(crossings[p].mean() / evaluation.starts),
                "best_so_far": {
                    "f": float(best.fitness[p]),
                    "crossings": int(best.crossings[p]),
                    "starts": int(best.starts[p]),
                },
            }
        )
    return {
        "generation": generation,
        "best_f": float(f.min()),
        "mean_f": float(f.mean()),
        "populations": pops,
        "wall_s": round(wall, 3),
    }


def _plot(path: Path, history: list[dict[str, Any]], title: str, tau_cap: float) -> None:
    from jaxais.experiments.plotting import new_figure, save_figure

    gens = np.array([h["generation"] for h in history])
    best = np.array([[p["best_f"] for p in h["populations"]] for h in history])
    mean = np.array([[p["mean_f"] for p in h["populations"]] for h in history])
    fig = new_figure((7.5, 4.5))
    ax = fig.add_subplot()
    for p in range(best.shape[1]):
        color = f"C{p % 10}"
        ax.plot(gens, best[:, p], color=color, marker=".", label=f"population {p}: best")
        ax.plot(gens, mean[:, p], color=color, linestyle="--", alpha=0.6, label=f"{p}: mean")
    ax.axhline(tau_cap / 2, color="0.5", linestyle=":", linewidth=1, label="time cap, 0 collisions")
    ax.set_xlabel("generation")
    ax.set_ylabel("f = (8c + τ)/2  (lower is better)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize="x-small", ncol=2)
    save_figure(fig, path, dpi=110)


def measure_crossing(
    seed: Seed, world: envs.World, config: GAConfig, run_seed: int, starts: int
) -> dict[str, Any]:
    """The "crossing" entry: ``seed``'s sets' rates in ``starts`` starts of ``crossing_key``."""
    key = driver.crossing_key(run_seed)
    # In rollouts of success_starts starts per set: the success check's compiled program.
    batch = config.success_starts or None
    ev = driver.measure(key, seed.antibodies, world, starts, envs.default_params(), config, batch)
    ev = jax.tree.map(np.asarray, ev)
    return {
        "starts": starts,
        "rate": [float(c) / starts for c in ev.crossings],
        "tau_cap": float(config.tau_cap),
        "collision_cap": int(config.collision_cap),
        "world": world.name,
        "mean_tau": [float(t) for t in ev.tau],
        "mean_collisions": [float(c) for c in ev.collisions],
        "keys": f"jaxais.ga.crossing_key({run_seed}), not used by the GA",
    }


def _run_info(world: str, seed: int, config: GAConfig) -> dict[str, Any]:
    """What a resume must share with the run it continues (the generation count may grow; the
    operators are checked against each checkpoint's record)."""
    config_info = {k: v for k, v in config.to_dict().items() if k != "generations"}
    return {"world": world, "seed": seed, "config": config_info}


def _check_operators(extra: dict[str, Any], config: GAConfig, names: dict[str, str]) -> None:
    """CheckpointError (one line) unless the checkpoint's run bred with the operators ``names``
    (a checkpoint without the record ran ``config``'s defaults)."""
    ran = extra.get("operators") or default_operators(config).names()
    for role, name in names.items():
        if ran.get(role) != name:
            raise CheckpointError(f"--resume: this run used {role} {ran.get(role)!r}, not {name!r}")


def evolve(
    out: str | Path,
    seed: int = 0,
    config: GAConfig | None = None,
    world: str = "ga_maze",
    resume: bool = False,
    crossing_starts: int = CROSSING_STARTS,
    diversity_seeds: int | None = None,
    argv: list[str] | None = None,
    operators: Operators | None = None,
) -> dict[str, Any]:
    """Evolve the LTL seed with PRNG seed ``seed`` into ``out``; returns the summary it writes.

    ``resume`` continues ``out/checkpoints`` (same arguments and operators; ``generations`` may
    grow); ``diversity_seeds`` also compares P × R with 1 × PR over GA seeds ``seed``,
    ``seed + 1``, ... (not checkpointed); ``argv`` is recorded as the command; ``operators``:
    the GA's selection, crossover and mutation (default: ``config``'s,
    :func:`jaxais.ga.operators.default_operators`), their names recorded in every checkpoint
    and the summary. Raises ConfigError (out of range) or ValueError (nothing to resume,
    another run's or a corrupt checkpoint, other operators than the run's, a bad world).
    """
    check_path(out, "evolve's out", "a folder's path")
    check_path(world, "world", "a world's name or TOML path")
    check_bool(resume, "resume")
    if diversity_seeds is not None:
        check_type(diversity_seeds, INTEGER, "diversity_seeds", "an integer or None")
    if argv is not None:
        check_type(argv, list | tuple, "argv", "a list of strings (the command's words)")
    config = GAConfig() if config is None else config
    _check(seed, crossing_starts, config)
    if operators is not None:
        check_type(operators, Operators, "evolve's operators", "a jaxais.ga.Operators")
    names = (default_operators(config) if operators is None else operators).names()
    if diversity_seeds is not None and diversity_seeds < 2:
        raise ConfigError("diversity_seeds", f"must be >= 2, got {diversity_seeds}")
    if diversity_seeds is not None and config.populations < 2:
        raise ConfigError("diversity", "needs --populations >= 2")
    if diversity_seeds is not None and names != default_operators(config).names():
        raise ConfigError("diversity", "runs the config's default operators only")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out}: exists and is not a directory")
    world_obj = envs.load_world(world)
    sim_params = envs.default_params()
    run_info = _run_info(world, seed, config)
    start = time.perf_counter()
    with _compile_clock() as clock, GACheckpointer(out / "checkpoints", run_info, resume) as ck:
        history, earlier_wall, resumed_from = [], 0.0, None
        state = jax.random.key(seed)
        if resume:
            state, extra = ck.restore(config)
            _check_operators(extra, config, names)
            if int(state.generation) > config.generations:
                raise ValueError(
                    f"--generations {config.generations}: the checkpoint is already at generation"
                    f" {int(state.generation)}"
                )
            history = list(extra.get("history", []))
            earlier_wall = float(extra.get("wall_time_total_s", 0.0))
            resumed_from = int(state.generation)
        t0 = [time.perf_counter()]

        def save(state, evaluation) -> None:
            best = jax.tree.map(np.asarray, state.best)
            wall = time.perf_counter() - t0[0]
            history.append(_generation_record(int(state.generation) - 1, evaluation, best, wall))
            total = earlier_wall + time.perf_counter() - start
            ck.save(
                state, config, {"history": history, "wall_time_total_s": total, "operators": names}
            )
            t0[0] = time.perf_counter()

        desc = f"GA {config.populations}x{config.robots} in {world_obj.name}"
        state = driver.run(state, config, world_obj, sim_params, save, desc, operators)
        ga_wall, ga_compile = time.perf_counter() - start, clock[0]

        comparison = None
        if diversity_seeds is not None:
            from tqdm.auto import tqdm

            seeds = list(range(seed, seed + diversity_seeds))
            with tqdm(total=2 * len(seeds) - 1, desc="diversity runs") as bar:
                comparison = compare_diversity(
                    seeds, config, world_obj, sim_params, {seed: state}, lambda *_: bar.update(1)
                )
            comparison["wall_time_s"] = round(time.perf_counter() - start - ga_wall, 3)

        ltl_seed = driver.best_sets(state)
        t_crossing = time.perf_counter()
        crossing = measure_crossing(ltl_seed, world_obj, config, seed, crossing_starts)
        crossing_wall = time.perf_counter() - t_crossing
        compile_s = clock[0]

    out.mkdir(parents=True, exist_ok=True)
    generations_run = int(state.generation)
    best = jax.tree.map(np.asarray, state.best)
    populations = [
        {
            "population": p,
            "best_f_generation_0": history[0]["populations"][p]["best_f"],
            "best_f_final_generation": history[-1]["populations"][p]["best_f"],
            "best_f_overall": float(best.fitness[p]),
            "best_tau": float(best.tau[p]),
            "best_collisions": float(best.collisions[p]),
            "best_crossings": int(best.crossings[p]),
            "best_starts": int(best.starts[p]),
            "best_generation": int(best.generation[p]),
            "crossing_rate": crossing["rate"][p],
        }
        for p in range(config.populations)
    ]
    wall = time.perf_counter() - start
    if argv is not None:  # recorded without this machine's directories
        argv = [portable_path(a) if a.startswith("/") else a for a in argv]
    ident = {
        "command": None if argv is None else shlex.join(["evolve.py", *argv]),
        "seed": seed,
        "version": jaxais.__version__,
        "world": world_obj.name,
    }
    summary = {
        "format": "jaxais-evolve/1",
        **ident,
        "config": config.to_dict(),
        "operators": names,
        "fitness": "f = (rho*c + tau)/2 with rho = 8; lower is better",
        "generations_run": generations_run,
        "stopped_by": driver.stopped_by(state, config),
        "resumed_from_generation": resumed_from,
        "populations": populations,
        "seed_diversity": diversity(ltl_seed.antibodies) if config.populations >= 2 else None,
        "generations": history,
        "diversity_comparison": comparison,
        "crossing": crossing,
        "wall_time_s": round(wall, 3),
        "crossing_wall_time_s": round(crossing_wall, 3),
        "ga_wall_time_s": round(ga_wall, 3),
        "compile_time_s": round(compile_s, 3),
        "ga_compile_time_s": round(ga_compile, 3),
        "wall_time_total_s": round(earlier_wall + wall, 3),
    }
    provenance = {
        "made_by": "scripts/evolve.py",
        **ident,
        "generations": generations_run,
        "config": config.to_dict(),
        "operators": names,
    }
    save_seed(out / "seed", ltl_seed, provenance, crossing=crossing)
    title = f"GA in {world_obj.name}: {config.populations} x {config.robots}, seed {seed}"
    _plot(out / "fitness.png", history, title, config.tau_cap)
    atomic_write_json(out / "summary.json", summary)
    return summary


def check_seed(
    seed_dir: str | Path,
    config: GAConfig | None = None,
    world: str = "ga_maze",
    seed: int = 0,
    crossing_starts: int = CROSSING_STARTS,
) -> dict[str, Any]:
    """The crossing rates of the seed in ``seed_dir`` as :func:`evolve` measures them, and those
    recorded in its seed.json (writes nothing)."""
    check_path(seed_dir, "seed_dir", "a seed directory's path")
    check_path(world, "world", "a world's name or TOML path")
    config = GAConfig() if config is None else config
    _check(seed, crossing_starts, config)
    ltl_seed, meta = load_seed(seed_dir)
    world_obj = envs.load_world(world)
    start = time.perf_counter()
    crossing = measure_crossing(ltl_seed, world_obj, config, seed, crossing_starts)
    return {
        "seed_dir": str(seed_dir),
        "crossing": crossing,
        "recorded_crossing": meta.get("crossing"),
        "wall_time_s": round(time.perf_counter() - start, 3),
    }


def _crossing_line(c: dict[str, Any]) -> str:
    rates = ", ".join(f"{r:.2f}" for r in c["rate"])
    return (
        f"crossing rate per seed set in {c['starts']} fresh starts (time cap {c['tau_cap']:g} s):"
        f" [{rates}], lowest {min(c['rate']):.2f}"
    )


def report(result: dict[str, Any], where: str | Path) -> str:
    """What ``scripts/evolve.py`` prints for a :func:`check_seed` or :func:`evolve` result."""
    if "recorded_crossing" in result:
        lines = [f"{where}: {_crossing_line(result['crossing'])}"]
        if result["recorded_crossing"] is not None:
            recorded = _crossing_line(result["recorded_crossing"])
            lines.append(f"{where}: recorded in its seed.json: {recorded}")
        return "\n".join(lines)
    f0, f1 = (
        ", ".join(f"{p[k]:.0f}" for p in result["populations"])
        for k in ("best_f_generation_0", "best_f_final_generation")
    )
    n = result["generations_run"]
    return (
        f"{n} generations in {result['wall_time_s']:.1f} s (compile"
        f" {result['compile_time_s']:.1f} s), stopped by {result['stopped_by']}; best f per"
        f" population: generation 0 [{f0}] -> generation {n - 1} [{f1}]; wrote {Path(where)}/seed,"
        f" summary.json, fitness.png\n{_crossing_line(result['crossing'])}"
    )
