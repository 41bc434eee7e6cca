"""MAP-Elites (QDax, unmodified) as the LTL: an archive of antibody sets over where in ga_maze
they spend their time, and five of its elites exported as an LTL seed (beyond the paper).

QDax's ``MAPElites`` scores with the GA's own evaluation (``jaxais.ga.make_evaluator``: the
maze compiled in, LTL controller, the GA's caps) and breeds with the GA's own operators
(``jaxais.search.qdax_mutation`` / ``qdax_variation``: Table 1's limits); the descriptor is the
visit grid's centroid (``jaxais.search.mean_position``). The whole search is one jitted
``scan``. The five best cells' sets, re-measured from ``check_starts`` fresh starts as the GA
checks its bests, become the seed (``jaxais.seed.save_seed``: the checkpoints/default layout),
which ``scripts/reproduce.py --seeds OUT/seed`` runs::

    pip install -e '.[qdax]'
    python examples/qdax_map_elites.py --out runs/map_elites          # CONFIG: the docs' run
    python examples/qdax_map_elites.py --tiny --out /tmp/me           # TINY: what the tests run
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
from importlib.metadata import version
from pathlib import Path
from typing import Any

import jax
import numpy as np
from qdax.core.containers.mapelites_repertoire import compute_euclidean_centroids
from qdax.core.emitters.standard_emitters import MixingEmitter
from qdax.core.map_elites import MAPElites
from qdax.utils.metrics import default_qd_metrics

from jaxais import GAConfig, envs, ga, search
from jaxais.experiments.evolution import measure_crossing
from jaxais.immune.antibodies import sample_antibodies
from jaxais.seed import Seed, save_seed

CONFIG = {
    "ga": GAConfig(),  # the GA's caps: 500 s, 100 collisions
    "batch": 32,
    "iterations": 250,
    "cells": (10, 5),  # the archive: 10 x 5 cells over the descriptor's [0, 1]^2
    "visit_grid": (10, 20),  # rows, cols of the visit grid the descriptor is read from
    "check_starts": 10,  # the GA's success_starts
    "candidates": 20,  # best cells re-measured before five are chosen
    "crossing_starts": 50,  # evolve.py's crossing measurement of the seed
}
TINY = {
    "ga": GAConfig(tau_cap=60.0),
    "batch": 16,
    "iterations": 2,
    "cells": (20, 10),
    "visit_grid": (4, 8),
    "check_starts": 2,
    "candidates": 6,
    "crossing_starts": 2,
}
N_SEED = 5  # sets in an LTL seed


def search_archive(config: dict[str, Any], key: jax.Array):
    """MAP-Elites for ``config['iterations']``: (the repertoire, the metrics per iteration)."""
    world = envs.load_world("ga_maze")
    evaluate = ga.make_evaluator(world, config=config["ga"], grid=config["visit_grid"])
    scoring = search.qdax_scoring(evaluate, search.mean_position)
    emitter = MixingEmitter(
        mutation_fn=search.qdax_mutation(config=config["ga"]),
        variation_fn=search.qdax_variation(config=config["ga"]),
        variation_percentage=0.5,
        batch_size=config["batch"],
    )
    # QDax maximises -f; the worst f is (ρ·cap + τ cap) / 2, so offset makes every cell's score
    # positive in its QD score.
    worst = (8.0 * config["ga"].collision_cap + config["ga"].tau_cap) / 2
    metrics = functools.partial(default_qd_metrics, qd_offset=worst)
    me = MAPElites(scoring, emitter, metrics)
    centroids = compute_euclidean_centroids(config["cells"], 0.0, 1.0)
    k_init, k_me, k_run = jax.random.split(key, 3)
    genotypes = sample_antibodies(k_init, (config["batch"], 8))

    @jax.jit
    def run(genotypes, key):
        k_init, k_scan = jax.random.split(key)
        repertoire, state, _ = me.init(genotypes, centroids, k_init)
        (repertoire, _, _), metrics = jax.lax.scan(
            lambda carry, k: me.scan_update(carry, k),
            (repertoire, state, k_scan),
            jax.random.split(k_scan, config["iterations"]),
        )
        return repertoire, metrics

    del k_me
    return run(genotypes, k_run)


def export_seed(repertoire, config: dict[str, Any], key: jax.Array) -> tuple[Seed, dict]:
    """The seed: of the ``candidates`` best filled cells, the five best sets re-measured from
    ``check_starts`` fresh starts (the GA's checked bests: one lucky run does not make an
    elite), with that record's τ, c and L."""
    fitness = np.asarray(repertoire.fitnesses).reshape(-1)
    filled = np.flatnonzero(np.isfinite(fitness))
    if filled.size < N_SEED:
        raise SystemExit(f"only {filled.size} cells filled: run more iterations for a seed")
    cells = filled[np.argsort(-fitness[filled], kind="stable")][: config["candidates"]]
    sets = jax.tree.map(lambda x: np.asarray(x)[cells], repertoire.genotypes)
    world = envs.load_world("ga_maze")
    record = ga.measure(key, sets, world, config["check_starts"], config=config["ga"])
    best = np.argsort(np.asarray(record.fitness), kind="stable")[:N_SEED]
    pick = lambda x: np.asarray(x)[best]
    seed = Seed(
        antibodies=jax.tree.map(pick, sets),
        tau=pick(record.tau).astype(np.float32),
        collisions=np.rint(pick(record.collisions)).astype(np.int32),
        L=pick(record.L).astype(np.float32),
    )
    chosen = {
        "cells": [int(c) for c in cells[best]],
        "archive_f": [float(-fitness[c]) for c in cells[best]],
        "checked_f": [float(f) for f in pick(record.fitness)],
        "crossing_rate": [float(c) / config["check_starts"] for c in pick(record.crossings)],
    }
    return seed, chosen


def plot_archive(repertoire, config: dict[str, Any], path: Path) -> None:
    """The archive's f per cell over the maze (cells are descriptor space, scaled to the arena)."""
    from matplotlib.colors import Normalize

    from jaxais.experiments.plotting import draw_world, new_figure, save_figure

    world = envs.load_world("ga_maze")
    x0, y0, x1, y1 = (float(v) for v in world.arena)
    cols, rows = config["cells"]
    f = -np.asarray(repertoire.fitnesses).reshape(-1)
    c = np.asarray(repertoire.centroids)  # [cells, 2] in [0, 1]
    grid = np.full((rows, cols), np.nan)
    row = np.minimum((c[:, 1] * rows).astype(int), rows - 1)
    col = np.minimum((c[:, 0] * cols).astype(int), cols - 1)
    grid[row, col] = np.where(np.isfinite(f), f, np.nan)
    fig = new_figure((8.0, 4.6))
    ax = fig.add_subplot()
    image = ax.imshow(grid, origin="lower", extent=(x0, x1, y0, y1), cmap="viridis_r",
                      norm=Normalize(np.nanmin(grid), np.nanmax(grid)), alpha=0.85)  # fmt: skip
    draw_world(ax, world)
    fig.colorbar(image, ax=ax, label="f of the cell's elite (lower is better)")
    filled = int(np.isfinite(f).sum())
    ax.set_title(f"MAP-Elites archive in ga_maze: {filled} of {f.size} cells, by mean position")
    save_figure(fig, path, dpi=110)


def main(config: dict[str, Any], out: Path, seed: int = 0) -> dict[str, Any]:
    """Search, export the seed to ``out/seed`` and the archive's picture and summary."""
    key = jax.random.key(seed)
    k_search, k_check = jax.random.split(key)
    t0 = time.perf_counter()
    repertoire, metrics = search_archive(config, k_search)
    jax.block_until_ready(repertoire)
    seconds = time.perf_counter() - t0
    seed_sets, chosen = export_seed(repertoire, config, k_check)
    command = "qdax_map_elites.py " + " ".join(sys.argv[1:])
    provenance = {"made_by": "examples/qdax_map_elites.py", "command": command.strip(),
                  "seed": seed, "version": version("jaxais"), "world": "ga_maze",
                  "config": config["ga"].to_dict(), "map_elites": chosen}  # fmt: skip
    # The GA's crossing measurement (evolve.py's: crossing_key(seed), never used by the search).
    world = envs.load_world("ga_maze")
    crossing = measure_crossing(seed_sets, world, config["ga"], seed, config["crossing_starts"])
    save_seed(out / "seed", seed_sets, provenance, crossing=crossing)
    plot_archive(repertoire, config, out / "archive.png")
    coverage = np.asarray(metrics["coverage"])
    summary = {
        "iterations": config["iterations"],
        "batch": config["batch"],
        "cells": list(config["cells"]),
        "coverage_percent": [float(coverage[0]), float(coverage[-1])],
        "max_fitness": float(np.asarray(metrics["max_fitness"])[-1]),
        "search_seconds": round(seconds, 1),
        "seed": chosen,
        "crossing_rate": crossing["rate"],
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(
        f"MAP-Elites in ga_maze: {config['iterations']} iterations of {config['batch']}, "
        f"coverage {coverage[0]:.0f}% -> {coverage[-1]:.0f}%, seed f "
        f"{[round(f, 1) for f in chosen['checked_f']]}; wrote {out}/seed, archive.png"
    )
    return summary


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--tiny", action="store_true", help="TINY's budget (what the tests run)")
    p.add_argument("--out", required=True, help="output directory (seed/, archive.png, ...)")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed")
    args = p.parse_args()
    Path(args.out).mkdir(parents=True, exist_ok=True)
    main(TINY if args.tiny else CONFIG, Path(args.out), args.seed)
