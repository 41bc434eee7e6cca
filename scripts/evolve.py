"""Evolve LTL antibody sets with the genetic algorithm (SPEC 10) and write the STL's seed.

    python scripts/evolve.py --out DIR                  # 5 populations x 10 robots
    python scripts/evolve.py --out DIR --resume         # continue an interrupted run exactly
    python scripts/evolve.py --out DIR --diversity      # also compare 5 x 10 with 1 x 50
    python scripts/evolve.py --check-seed DIR/seed      # measure an existing seed, evolve nothing

Writes ``DIR/summary.json`` (settings, per-generation best and mean f of every population, how
the run stopped, the seed's crossing rates, wall and compile time), ``DIR/fitness.png`` (the
fitness curves), ``DIR/seed/`` (the seed, for ``scripts/trials.py --seeds DIR/seed``) and
``DIR/checkpoints/`` (the GA state after every generation). Lower f = (8c + tau)/2 is better.
The same arguments give the same seed, and a run resumed from its checkpoints ends with exactly
the seed of an uninterrupted one. SIGTERM and Ctrl-C stop the run with the last complete
checkpoint intact.

Each robot runs the maze from ``--starts`` random starts per generation (f, tau, c and L are means
over them); after each generation every population's best robot runs again from
``--success-starts`` fresh starts, which make the populations' bests (pooled while a set stays
best, and carried into the next generation as its elite), and the run stops once every population's
best crossed the maze in at least ``--success-rate`` of them and still does after
``--success-starts`` more (or at ``--generations``). Then each seed set runs from
``--crossing-starts`` fresh starts whose keys the GA never used, and the fraction in which it
crosses the maze (finishes within the time cap) is printed and stored in ``seed.json`` ("crossing")
and ``summary.json``. ``--check-seed DIR`` measures that for an existing seed directory (with
``--world``, ``--tau-cap``, ``--seed``) and prints it, writing nothing.

``--diversity`` runs the GA ``--diversity-seeds`` times (default 3; the main run is the first)
with the given settings and as many times with one population of P x R robots, and compares the
diversity of the final generations' sets (Welch t-test and Mann-Whitney U). Those extra runs are
not checkpointed and cost about 2 x seeds - 1 main runs.
"""

from __future__ import annotations

import argparse
import shlex
import sys
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


def _rate_or_none(text: str) -> float | None:
    """``--success-rate``: a number, or ``none`` for no success stop."""
    if text.strip().lower() in ("none", "off"):
        return None
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a fraction or 'none', got {text!r}") from None


# The defaults are jaxais.ga.GAConfig's (tests/test_evolve_script.py checks that they agree);
# they are repeated here so that --help and bad flags answer before JAX is imported.
def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = _Parser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("--world", default="ga_maze", help="world name or .toml path (default ga_maze)")
    p.add_argument("--populations", type=int, default=5, help="independent populations [paper: 5]")
    p.add_argument("--robots", type=int, default=10, help="robots per population [paper: 10]")
    p.add_argument("--generations", type=int, default=200, help="generation cap [ours: 200]")
    p.add_argument("--mutation", type=float, default=0.05, help="per-gene rate [paper: 0.05]")
    p.add_argument("--elitism", type=int, default=1, help="elite robots per population [ours: 1]")
    p.add_argument("--target-f", type=float, default=None, help="stop when every best f <= this")
    p.add_argument("--tau-cap", type=float, default=500.0, help="time cap, s [ours: 500]")
    p.add_argument("--collision-cap", type=int, default=100, help="collision cap [ours: 100]")
    p.add_argument(
        "--starts", type=int, default=1, help="random starts per robot and generation [ours: 1]"
    )
    p.add_argument(
        "--success-starts",
        type=int,
        default=10,
        help="fresh starts of each population's best per generation (0: no checks) [ours: 10]",
    )
    p.add_argument(
        "--success-rate",
        type=_rate_or_none,
        default=0.95,
        help="stop once every best crosses in this fraction of them ('none': never) [ours: 0.95]",
    )
    p.add_argument(
        "--crossover",
        choices=("uniform", "rl"),
        default="uniform",
        help="each antigen's antibody from either parent, or from the one with the higher RL"
        " score L (SPEC 10's rule) [ours: uniform]",
    )
    p.add_argument(
        "--crossing-starts",
        type=int,
        default=50,
        help="fresh starts per seed set of the final crossing measurement [ours: 50]",
    )
    p.add_argument("--seed", type=int, default=0, help="PRNG seed of the run")
    p.add_argument("--out", default=None, help="output directory (created if missing)")
    p.add_argument("--resume", action="store_true", help="continue from DIR/checkpoints")
    p.add_argument("--diversity", action="store_true", help="compare 5 x 10 with 1 x 50")
    p.add_argument("--diversity-seeds", type=int, default=3, help="GA seeds per arm (>= 2)")
    p.add_argument(
        "--check-seed",
        default=None,
        metavar="DIR",
        help="measure the crossing rates of the seed in DIR and exit (no GA, no --out)",
    )
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
            starts=args.starts,
            success_starts=args.success_starts,
            success_rate=args.success_rate,
            crossover=args.crossover,
        )
    except ConfigError as err:
        raise UserError(f"--{err.field.replace('_', '-')} {err.reason}") from None


class _CompileClock:
    """Sums JAX's tracing, lowering and XLA compile durations (jax.monitoring events)."""

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


def _generation_record(generation: int, evaluation, best, wall: float) -> dict[str, Any]:
    """One generation's line of the history: its evaluation (means over each robot's starts)
    and, after the success check, each population's best so far."""
    import numpy as np

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
    if args.crossing_starts < 1:
        raise UserError(f"--crossing-starts must be >= 1, got {args.crossing_starts}")
    if args.check_seed is not None:
        for flag, used in (("--out", args.out), ("--resume", args.resume)):
            if used:
                raise UserError(f"--check-seed measures a seed and writes nothing: drop {flag}")
        if args.diversity:
            raise UserError("--check-seed measures a seed and writes nothing: drop --diversity")
        return _check_seed(args, config)
    if args.out is None:
        raise UserError("--out DIR is required (or --check-seed DIR to measure a seed)")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UserError(f"{out}: exists and is not a directory")
    # SIGINT and SIGTERM are jaxais.cli's (one line; checkpoints are written whole or not).
    return _evolve(args, argv, config, out)


def _evolve(args: argparse.Namespace, argv: list[str], config, out: Path) -> dict[str, Any]:
    import logging

    import jax
    import numpy as np
    from tqdm import tqdm

    import jaxais
    from jaxais import _speed, envs, ga
    from jaxais.checkpointing import GACheckpointer
    from jaxais.experiments.records import portable_path
    from jaxais.seed import save_seed

    # orbax reports a failed save to us as an exception, which becomes the one-line error; its
    # own logs and its background threads' reports of the same failure (hundreds of lines on a
    # full disk) are not for users.
    logging.getLogger("absl").setLevel(logging.CRITICAL)
    _speed.setup(one_kernel_loops=True)
    world = envs.load_world(args.world)
    sim_params = envs.default_params()
    # Recorded without this machine's directories (jaxais.experiments.records.portable_path).
    command = shlex.join([PROG, *(portable_path(a) if a.startswith("/") else a for a in argv)])
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
                best = jax.tree.map(np.asarray, state.best)
                record = _generation_record(generation, evaluation, best, time.perf_counter() - t0)
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

        seed = ga.best_sets(state)
        t_crossing = time.perf_counter()
        crossing = _measure_crossing(seed, world, sim_params, config, args)
        crossing_wall = time.perf_counter() - t_crossing
        compile_s = clock.seconds

    out.mkdir(parents=True, exist_ok=True)
    generations_run = int(state.generation)
    stopped_by = ga.stopped_by(state, config)
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
            "best_collisions": float(best.collisions[p]),
            "best_crossings": int(best.crossings[p]),
            "best_starts": int(best.starts[p]),
            "best_generation": int(best.generation[p]),
            "crossing_rate": crossing["rate"][p],
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
        "crossing": crossing,
        "wall_time_s": round(wall, 3),
        "crossing_wall_time_s": round(crossing_wall, 3),
        "ga_wall_time_s": round(ga_wall, 3),
        "compile_time_s": round(compile_s, 3),
        "ga_compile_time_s": round(ga_compile, 3),
        "wall_time_total_s": round(earlier_wall + wall, 3),
    }
    save_seed(out / "seed", seed, provenance, crossing=crossing)
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
        f"{generations_run} generations in {wall:.1f} s (compile {compile_s:.1f} s), stopped by"
        f" {stopped_by}; best f per population: generation 0 [{first}] -> generation"
        f" {generations_run - 1} [{last}]; wrote {out}/seed, summary.json, fitness.png"
    )
    print(_crossing_line(crossing))
    return summary


def _measure_crossing(seed, world, sim_params, config, args: argparse.Namespace) -> dict[str, Any]:
    """The seed's crossing rates in ``--crossing-starts`` fresh starts (the "crossing" entry of
    seed.json and summary.json, :func:`jaxais.seed.check_crossing`'s format)."""
    import jax
    import numpy as np

    from jaxais import ga

    key = ga.crossing_key(args.seed)
    # In rollouts of success_starts starts per set: the success check's compiled program.
    batch = config.success_starts or None
    ev = ga.measure(
        key, seed.antibodies, world, args.crossing_starts, sim_params, config, batch_starts=batch
    )
    ev = jax.tree.map(np.asarray, ev)
    return {
        "starts": args.crossing_starts,
        "rate": [float(c) / args.crossing_starts for c in ev.crossings],
        "tau_cap": float(config.tau_cap),
        "collision_cap": int(config.collision_cap),
        "world": world.name,
        "mean_tau": [float(t) for t in ev.tau],
        "mean_collisions": [float(c) for c in ev.collisions],
        "keys": f"jaxais.ga.crossing_key({args.seed}), not used by the GA",
    }


def _crossing_line(crossing: dict[str, Any]) -> str:
    rates = ", ".join(f"{r:.2f}" for r in crossing["rate"])
    return (
        f"crossing rate per seed set in {crossing['starts']} fresh starts (time cap"
        f" {crossing['tau_cap']:g} s): [{rates}], lowest {min(crossing['rate']):.2f}"
    )


def _check_seed(args: argparse.Namespace, config) -> dict[str, Any]:
    """``--check-seed DIR``: measure an existing seed's crossing rates; write nothing."""
    import logging

    from jaxais import _speed, envs
    from jaxais.seed import load_seed

    logging.getLogger("absl").setLevel(logging.ERROR)
    _speed.setup(one_kernel_loops=True)
    seed, meta = load_seed(args.check_seed)
    world = envs.load_world(args.world)
    start = time.perf_counter()
    crossing = _measure_crossing(seed, world, envs.default_params(), config, args)
    recorded = meta.get("crossing")
    summary = {
        "seed_dir": str(args.check_seed),
        "crossing": crossing,
        "recorded_crossing": recorded,
        "wall_time_s": round(time.perf_counter() - start, 3),
    }
    print(f"{args.check_seed}: {_crossing_line(crossing)}")
    if recorded is not None:
        print(f"{args.check_seed}: recorded in its seed.json: {_crossing_line(recorded)}")
    return summary


if __name__ == "__main__":
    run_script(main)
