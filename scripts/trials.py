"""Run n STL trials of one system in one world and write results.json.

    python scripts/trials.py --system SIE --world world1 --trials 30 --seed 0 --out results.json
    python scripts/trials.py --system UIE --random-set R2 --world world2 --out u.json --plot u.png

The trials run in a compiled, vmapped pool of slots, each refilled when its trial ends (a trial
stops when it finishes or hits a cap: 4000 s, 100 collisions); the progress bar counts trials
ended. With --plot they run as one batch that keeps every trajectory, and the bar counts
simulated iterations of the longest-running trial. The pool is sharded over every process's
devices with the jax.distributed flags (as in scripts/sweep.py; process 0 writes). The same
arguments give the same results.json, byte for byte.
"""

from __future__ import annotations

import argparse
import sys
import time

from jaxais import distributed
from jaxais.cli import (
    ArgumentParser,
    UserError,
    atomic_write_json,
    check_output_file,
    main_wrapper,
    run_script,
)
from jaxais.experiments import protocol
from jaxais.labels import RANDOM_SETS, SYSTEMS, label


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(prog="trials.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--system", required=True, choices=SYSTEMS)
    p.add_argument(
        "--world", default=protocol.WORLDS[0], help=f"{', '.join(protocol.WORLDS)} or a .toml path"
    )
    p.add_argument(
        "--trials",
        type=int,
        default=protocol.SIMULATED_TRIALS,
        help=f"trials (default: {protocol.SIMULATED_TRIALS}, the paper's in a simulated world)",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--random-set",
        choices=tuple(RANDOM_SETS),
        default=None,
        help="the unseeded systems' fixed random set (default R1)",
    )
    p.add_argument(
        "--seeds",
        default=None,
        help="LTL seed directory (default: the shipped checkpoints/default)",
    )
    protocol.add_cap_arguments(p)
    p.add_argument("--out", required=True, help="results JSON file")
    p.add_argument("--plot", default=None, help="also draw the trajectories to this PNG")
    distributed.add_arguments(p)
    return p.parse_args(argv)  # fmt: skip


@main_wrapper("trials.py")
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    if not 0 <= args.seed < 2**32:
        raise UserError(f"--seed must be in [0, 2**32), got {args.seed}")
    if args.trials < 1:
        raise UserError(f"--trials must be >= 1, got {args.trials}")
    if args.random_set and args.system not in ("UIE", "URL"):
        raise UserError(f"--random-set applies to UIE and URL only, not {args.system}")
    if args.seeds and args.system not in ("SIE", "SRL"):
        raise UserError(f"--seeds applies to the seeded systems SIE and SRL, not {args.system}")
    check_output_file(args.out, (".json",))
    if args.plot:
        check_output_file(args.plot, (".png",))
    distributed.check(args)

    # Imported after the flags are checked: a bad flag answers at once, without loading JAX.
    from tqdm import tqdm

    from jaxais import _speed, envs
    from jaxais.experiments.records import build_systems, results_document, run_config
    from jaxais.immune.network import NetworkParams
    from jaxais.loop import EpisodeConfig
    from jaxais.trials import run_trials

    _speed.setup(cpu_device_per_core=True)
    distributed.initialize(args)  # before JAX computes anything
    import jax

    lead = jax.process_index() == 0  # every process runs its share; process 0 writes
    name = label(args.system, args.random_set or "R1")
    world = envs.load_world(args.world)
    config = EpisodeConfig(
        tau_cap=args.tau_cap, collision_cap=args.collision_cap, record=bool(args.plot)
    )
    network = NetworkParams()
    systems, seed_info = build_systems([name], args.seeds, network)
    params = envs.default_params()
    start = time.perf_counter()
    total, unit = (config.max_iterations(params.dt), "it") if args.plot else (args.trials, "run")
    desc = f"{name} in {world.name}"
    with tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, disable=not lead) as bar:
        results = run_trials(world, systems, args.trials, args.seed, config, params, bar)
        bar.update(bar.total - bar.n)
    wall = time.perf_counter() - start
    if not lead:
        return
    cfg = run_config(world, args.world, config, network, params, seed_info)
    cfg["command"] = "trials.py " + " ".join(sys.argv[1:] if argv is None else argv)
    doc = results_document(name, world.name, args.seed, results[name], cfg)
    atomic_write_json(args.out, doc)
    if args.plot:
        from jaxais.experiments.plotting import save_figure, world_figure

        trajs = results[name].trajectories
        labels = [f"trial {i}" for i in range(len(trajs))]
        # Each trial's boxes and goal where its world placed them (outlined in its colour).
        fig = world_figure(
            world,
            states=results[name].placements,
            trajectories=trajs,
            title=f"{name} in {world.name}",
            labels=labels,
        )
        save_figure(fig, args.plot)
    s = doc["summary"]
    rate = s["idiotypic_difference_rate"]
    print(
        f"{name} in {world.name}: {s['n']} trials, mean tau {s['tau']:.0f} s, "
        f"c {s['collisions']:.1f}, f {s['fitness']:.0f}, failed {100 * s['failure_rate']:.0f} %"
        + (f", idiotypic difference rate {100 * rate:.1f} %" if rate is not None else "")
        + f"; {wall:.1f} s wall; wrote {args.out}"
    )


if __name__ == "__main__":
    run_script(main)
