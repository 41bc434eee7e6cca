"""Tournament selection for the LTL genetic algorithm, written in this one file: no library edit.

The GA's selection, crossover and mutation are functions passed in (``jaxais.ga.operators``).
This file writes tournament selection, evolves a seed with it through the library call behind
``scripts/evolve.py`` (checkpoints that record the operators' names, ``seed/``,
``summary.json``), then runs the seed's SIE through a few trials in world1::

    python examples/tournament_ga.py --out runs/tournament          # CONFIG: the shipped GA
    python examples/tournament_ga.py --out runs/tournament --resume # continue it
    python examples/tournament_ga.py --tiny                         # TINY: what the tests run
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxais import EpisodeConfig, GAConfig, envs, ga, make_system, run_trials
from jaxais.experiments.evolution import evolve

CONFIG = {"ga": GAConfig(), "crossing_starts": 50, "trials": 10, "tau_cap": 4000.0}
TINY = {
    "ga": GAConfig(populations=2, robots=4, generations=2, tau_cap=2.0, success_starts=4),
    "crossing_starts": 4,
    "trials": 2,
    "tau_cap": 2.0,
}


def tournament_selection(size: int) -> ga.Operator:
    """Tournament selection of ``size``: each parent is the robot of lowest f (ties: the first
    drawn) among ``size`` drawn uniformly with replacement from its population."""

    def select(key: jax.Array, evaluation: ga.Evaluation, n: int) -> jax.Array:
        f = evaluation.fitness  # [R]: one population (the GA vmaps over them)
        drawn = jax.random.randint(key, (n, size), 0, f.shape[0])  # [n, size] contestants
        return drawn[jnp.arange(n), jnp.argmin(f[drawn], axis=1)].astype(jnp.int32)

    return ga.Operator(f"tournament{size}", select)


def main(settings: dict[str, Any], out: Path, resume: bool = False, seed: int = 0) -> dict:
    """Evolve with tournament selection into ``out``, then run the seed's SIE in world1."""
    config = settings["ga"]
    # The config's crossover and mutation, tournament selection instead of roulette.
    operators = ga.default_operators(config).replace(selection=tournament_selection(3))
    summary = evolve(
        out,
        seed,
        config,
        resume=resume,
        crossing_starts=settings["crossing_starts"],
        operators=operators,
    )
    best = [round(p["best_f_overall"], 1) for p in summary["populations"]]
    print(
        f"GA with {summary['operators']['selection']} selection: {summary['generations_run']}"
        f" generations of {config.populations} x {config.robots}, best f per population {best}"
    )
    sie = make_system("SIE", out / "seed")  # the seed evolve exported
    episode = EpisodeConfig(tau_cap=settings["tau_cap"])
    world = envs.load_world("world1")
    trials = run_trials(world, {"SIE": sie}, settings["trials"], seed=seed, config=episode)
    f = np.array([r["fitness"] for r in trials["SIE"].records])
    print(f"SIE with the tournament seed in world1: {len(f)} trials, mean f {f.mean():.1f}")
    return {"summary": summary, "fitness": f}


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="output directory (default: a temporary one)")
    parser.add_argument("--resume", action="store_true", help="continue the run in --out")
    parser.add_argument("--tiny", action="store_true", help="tiny settings (CI)")
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="tournament_ga-")) / "run"
    main(TINY if args.tiny else CONFIG, out, resume=args.resume)
