"""Evolve LTL antibody sets with the genetic algorithm (SPEC 10) and write the STL's seed.

    python scripts/evolve.py --out DIR                  # 5 populations x 10 robots, 30 generations
    python scripts/evolve.py --out DIR --resume         # continue an interrupted run exactly
    python scripts/evolve.py --out DIR --diversity      # also compare 5 x 10 with 1 x 50

Writes ``DIR/summary.json`` (settings, per-generation best and mean f of every population, wall
and compile time), ``DIR/fitness.png`` (the fitness curves), ``DIR/seed/`` (the seed, for
``scripts/trials.py --seeds DIR/seed``) and ``DIR/checkpoints/`` (the GA state after every
generation). Lower f = (8c + tau)/2 is better. The same arguments give the same seed, and a run
resumed from its checkpoints ends with exactly the seed of an uninterrupted one. SIGTERM and
Ctrl-C stop the run with the last complete checkpoint intact.

``--diversity`` runs the GA ``--diversity-seeds`` times (default 3; the main run is the first)
with the given settings and as many times with one population of P x R robots, and compares the
diversity of the final generations' sets (Welch t-test and Mann-Whitney U). Those extra runs are
not checkpointed and cost about 2 x seeds - 1 main runs.
"""

from __future__ import annotations

import argparse
import importlib
import shlex
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any, NoReturn

from jaxais.cli import UserError, atomic_write, atomic_write_json, fail, main_wrapper, run_script

PROG = "evolve.py"
MAX_SEED = 2**31 - 1


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        # One line, like every other error of the script (argparse adds a usage line).
        fail(PROG, f"{message} (see --help)")


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = _Parser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("--world", default="ga_maze", help="world name or .toml path (default ga_maze)")
    p.add_argument("--populations", type=int, default=5, help="independent populations [paper: 5]")
    p.add_argument("--robots", type=int, default=10, help="robots per population [paper: 10]")
    p.add_argument("--generations", type=int, default=30, help="generations [ours: 30]")
    p.add_argument("--mutation", type=float, default=0.05, help="per-gene rate [paper: 0.05]")
    p.add_argument("--elitism", type=int, default=1, help="elite robots per population [ours: 1]")
    p.add_argument("--target-f", type=float, default=None, help="stop when every best f <= this")
    p.add_argument("--tau-cap", type=float, default=500.0, help="time cap, s [ours: 500]")
    p.add_argument("--collision-cap", type=int, default=100, help="collision cap [ours: 100]")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed of the run")
    p.add_argument("--out", required=True, help="output directory (created if missing)")
    p.add_argument("--resume", action="store_true", help="continue from DIR/checkpoints")
    p.add_argument("--diversity", action="store_true", help="compare 5 x 10 with 1 x 50")
    p.add_argument("--diversity-seeds", type=int, default=3, help="GA seeds per arm (>= 2)")
    return p.parse_args(argv)


def _config(args: argparse.Namespace):
    from jaxais.ga import ConfigError, GAConfig

    try:
        return GAConfig(
            populations=args.populations,
            robots=args.robots,
            generations=args.generations,
            mutation=args.mutation,
            elitism=args.elitism,
            target_f=args.target_f,
            tau_cap=args.tau_cap,
            collision_cap=args.collision_cap,
        )
    except ConfigError as err:
        raise UserError(f"--{err.field.replace('_', '-')} {err.reason}") from None


def _sigterm(signum: int, frame: Any) -> None:
    # Handled like Ctrl-C: the wrapper reports "interrupted"; checkpoints are already complete.
    raise KeyboardInterrupt


class _CompileClock:
    """Sums JAX's tracing, lowering and XLA compile durations (jax.monitoring events).

    Programs compiled at the same time (``jaxais.episode.compile_rollout``) each count in full,
    so the sum can exceed the wall time they took.
    """

    EVENTS = frozenset(
        {
            "/jax/core/compile/jaxpr_trace_duration",
            "/jax/core/compile/jaxpr_to_mlir_module_duration",
            "/jax/core/compile/backend_compile_duration",
        }
    )

    def __init__(self) -> None:
        self.seconds = 0.0

    def __call__(self, event: str, duration: float, **kwargs: Any) -> None:
        if event in self.EVENTS:
            self.seconds += duration

    def __enter__(self) -> _CompileClock:
        import jax

        jax.monitoring.register_event_duration_secs_listener(self)
        return self

    def __exit__(self, *exc: Any) -> None:
        import jax

        jax.monitoring.unregister_event_duration_listener(self)


def _generation_record(generation: int, evaluation, wall: float) -> dict[str, Any]:
    import numpy as np

    from jaxais.episode import FINISHED

    f, tau, c = (np.asarray(x) for x in (evaluation.fitness, evaluation.tau, evaluation.collisions))
    status = np.asarray(evaluation.status)
    pops = []
    for p in range(f.shape[0]):
        i = int(np.argmin(f[p]))
        pops.append(
            {
                "best_f": float(f[p, i]),
                "mean_f": float(f[p].mean()),
                "best_tau": float(tau[p, i]),
                "best_collisions": int(c[p, i]),
                "finished": int(np.sum(status[p] == FINISHED)),
            }
        )
    return {
        "generation": generation,
        "best_f": float(f.min()),
        "mean_f": float(f.mean()),
        "populations": pops,
        "wall_s": round(wall, 3),
    }


def _import_in_background() -> None:
    """Import orbax (the checkpoints, about 0.4 s) and matplotlib (the plot, about 0.6 s)."""
    try:  # orbax first: the checkpoints open before the GA starts, the plot comes last
        for name in ("orbax.checkpoint", "matplotlib.backends.backend_agg", "matplotlib.figure"):
            importlib.import_module(name)
    except Exception:  # noqa: BLE001 (the main thread's own imports report any problem)
        pass


def _plot(path: Path, history: list[dict[str, Any]], title: str, tau_cap: float) -> None:
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    gens = np.array([h["generation"] for h in history])
    best = np.array([[p["best_f"] for p in h["populations"]] for h in history])
    mean = np.array([[p["mean_f"] for p in h["populations"]] for h in history])
    fig = Figure(figsize=(7.5, 4.5), layout="constrained")
    FigureCanvasAgg(fig)
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
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=110))


@main_wrapper(PROG)
def main(argv: list[str] | None = None) -> dict[str, Any]:
    args = parse_args(argv)
    argv = sys.argv[1:] if argv is None else list(argv)
    config = _config(args)
    if not 0 <= args.seed <= MAX_SEED:
        raise UserError(f"--seed must be in [0, {MAX_SEED}], got {args.seed}")
    if args.diversity and args.diversity_seeds < 2:
        raise UserError(f"--diversity-seeds must be >= 2, got {args.diversity_seeds}")
    if args.diversity and config.populations < 2:
        raise UserError("--diversity needs --populations >= 2")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UserError(f"{out}: exists and is not a directory")
    previous = signal.signal(signal.SIGTERM, _sigterm)
    try:
        return _evolve(args, argv, config, out)
    finally:
        signal.signal(signal.SIGTERM, previous)


def _evolve(args: argparse.Namespace, argv: list[str], config, out: Path) -> dict[str, Any]:
    import logging

    import jax
    import numpy as np
    from tqdm import tqdm

    import jaxais
    from jaxais import compilation_cache, envs, ga, host_devices, loop_kernels
    from jaxais.checkpointing import GACheckpointer
    from jaxais.seed import save_seed

    logging.getLogger("absl").setLevel(logging.ERROR)  # orbax's info/warnings are not for users
    # Orbax and matplotlib import in the background while JAX's backend starts, the world loads
    # and the GA compiles; the main thread's own imports then find them done (or wait for them).
    threading.Thread(target=_import_in_background, daemon=True).start()
    cache_dir = compilation_cache.enable()
    loop_kernel_bytes = loop_kernels.enable()  # before JAX's backend starts and reads XLA_FLAGS
    n_devices = host_devices.enable()
    world = envs.load_world(args.world)
    sim_params = envs.default_params()
    command = shlex.join([PROG, *argv])
    # What a resume must share with the run it continues (the generation count may grow).
    run_info = {
        "world": args.world,
        "seed": args.seed,
        "config": {k: v for k, v in config.to_dict().items() if k != "generations"},
    }

    start = time.perf_counter()
    with _CompileClock() as clock, GACheckpointer(out / "checkpoints", run_info, args.resume) as ck:
        if args.resume:
            state, extra = ck.restore(config)
            if int(state.generation) > config.generations:
                raise UserError(
                    f"--generations {config.generations}: the checkpoint is already at generation"
                    f" {int(state.generation)}"
                )
            history = list(extra.get("history", []))
            earlier_wall = float(extra.get("wall_time_total_s", 0.0))
            resumed_from: int | None = int(state.generation)
        else:
            state = ga.init(jax.random.key(args.seed), config)
            history, earlier_wall, resumed_from = [], 0.0, None

        with tqdm(
            total=config.generations,
            initial=int(state.generation),
            desc=f"GA {config.populations}x{config.robots} in {world.name}",
            unit="gen",
            file=sys.stderr,
        ) as bar:
            while not ga.is_done(state, config):
                t0 = time.perf_counter()
                generation = int(state.generation)
                state, evaluation = ga.step(state, config, world, sim_params)
                record = _generation_record(generation, evaluation, time.perf_counter() - t0)
                history.append(record)
                ck.save(
                    state,
                    config,
                    {
                        "history": history,
                        "wall_time_total_s": earlier_wall + time.perf_counter() - start,
                    },
                )
                bar.set_postfix(best=f"{record['best_f']:.1f}", mean=f"{record['mean_f']:.1f}")
                bar.update(1)
        ga_wall = time.perf_counter() - start
        ga_compile = clock.seconds

        diversity = None
        if args.diversity:
            seeds = list(range(args.seed, args.seed + args.diversity_seeds))
            with tqdm(total=2 * len(seeds) - 1, desc="diversity runs", file=sys.stderr) as bar:
                diversity = ga.compare_diversity(
                    seeds,
                    config,
                    world,
                    sim_params,
                    done={args.seed: state},
                    on_run=lambda arm, s: bar.update(1),
                )
            diversity["wall_time_s"] = round(time.perf_counter() - start - ga_wall, 3)
        compile_s = clock.seconds

    out.mkdir(parents=True, exist_ok=True)
    seed = ga.best_sets(state)
    generations_run = int(state.generation)
    stopped_by = "target_f" if ga.reached_target(state, config) else "generations"
    provenance = {
        "made_by": "scripts/evolve.py",
        "command": command,
        "seed": args.seed,
        "version": jaxais.__version__,
        "world": world.name,
        "generations": generations_run,
        "config": config.to_dict(),
    }
    best = jax.tree.map(np.asarray, state.best)
    populations = [
        {
            "population": p,
            "best_f_generation_0": history[0]["populations"][p]["best_f"],
            "best_f_final_generation": history[-1]["populations"][p]["best_f"],
            "best_f_overall": float(best.fitness[p]),
            "best_tau": float(best.tau[p]),
            "best_collisions": int(best.collisions[p]),
            "best_generation": int(best.generation[p]),
        }
        for p in range(config.populations)
    ]
    wall = time.perf_counter() - start
    summary = {
        "format": "jaxais-evolve/1",
        "command": command,
        "seed": args.seed,
        "version": jaxais.__version__,
        "world": world.name,
        "config": config.to_dict(),
        "fitness": "f = (rho*c + tau)/2 with rho = 8; lower is better",
        "generations_run": generations_run,
        "stopped_by": stopped_by,
        "resumed_from_generation": resumed_from,
        "populations": populations,
        "seed_diversity": ga.diversity(seed.antibodies) if config.populations >= 2 else None,
        "generations": history,
        "diversity_comparison": diversity,
        "wall_time_s": round(wall, 3),
        "ga_wall_time_s": round(ga_wall, 3),
        "compile_time_s": round(compile_s, 3),
        "ga_compile_time_s": round(ga_compile, 3),
        "compilation_cache": cache_dir,
        "devices": n_devices,
        "loop_kernel_bytes": loop_kernel_bytes,
        "wall_time_total_s": round(earlier_wall + wall, 3),
    }
    save_seed(out / "seed", seed, provenance)
    _plot(
        out / "fitness.png",
        history,
        f"GA in {world.name}: {config.populations} x {config.robots}, seed {args.seed}",
        config.tau_cap,
    )
    atomic_write_json(out / "summary.json", summary)
    first = ", ".join(f"{p['best_f_generation_0']:.0f}" for p in populations)
    last = ", ".join(f"{p['best_f_final_generation']:.0f}" for p in populations)
    print(
        f"{generations_run} generations in {wall:.1f} s (compile {compile_s:.1f} s); best f per"
        f" population: generation 0 [{first}] -> generation {generations_run - 1} [{last}];"
        f" wrote {out}/seed, summary.json, fitness.png"
    )
    return summary


if __name__ == "__main__":
    run_script(main)
