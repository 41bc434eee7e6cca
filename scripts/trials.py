"""Run n STL trials of one system in one world and write results.json.

    python scripts/trials.py --system SIE --world world1 --trials 30 --seed 0 --out results.json
    python scripts/trials.py --system UIE --random-set R2 --world world2 --out u.json --plot u.png
    python scripts/trials.py --contender my_controller.py:braitenberg --out b.json

Runs :func:`jaxais.experiments.trials` in a pool of slots, each refilled when its trial ends
(the bar counts trials ended); with --plot as one batch keeping every trajectory (the bar counts
iterations). The pool is sharded over every process's devices with the jax.distributed flags (as
in scripts/sweep.py; process 0 writes). The same arguments give the same results.json, byte for
byte.
"""

from __future__ import annotations

import argparse
import sys
import time

from jaxais import distributed
from jaxais.cli import ArgumentParser, main_wrapper, run_script
from jaxais.experiments import contenders, protocol
from jaxais.experiments.one_system import check_trials, trials
from jaxais.labels import RANDOM_SETS, SYSTEMS


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(prog="trials.py", description=__doc__.split("\n\n")[0])
    # fmt: off
    who = p.add_mutually_exclusive_group(required=True)
    who.add_argument("--system", choices=SYSTEMS, help="one of the paper's systems")
    contenders.add_argument(p, repeatable=False, group=who)
    p.add_argument("--world", default=protocol.WORLDS[0],
                   help=f"{', '.join(protocol.WORLDS)} or a .toml path")
    p.add_argument("--trials", type=int, default=protocol.SIMULATED_TRIALS,
                   help=f"trials (default: {protocol.SIMULATED_TRIALS}, the paper's in a "
                   "simulated world)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--random-set", choices=tuple(RANDOM_SETS), default=None,
                   help="the unseeded systems' fixed random set (default R1)")
    p.add_argument("--seeds", default=None,
                   help="LTL seed directory (default: the shipped checkpoints/default)")
    protocol.add_cap_arguments(p)
    protocol.add_world_scale_argument(p)
    p.add_argument("--out", required=True, help="results JSON file")
    p.add_argument("--plot", default=None, help="also draw the trajectories to this PNG")
    distributed.add_arguments(p)
    # fmt: on
    return p.parse_args(argv)


@main_wrapper("trials.py")
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    kw = dict(world=args.world, trials=args.trials, seed=args.seed, random_set=args.random_set,
              seeds=args.seeds, tau_cap=args.tau_cap, collision_cap=args.collision_cap,
              plot=args.plot, world_scale=args.world_scale)  # fmt: skip
    system = args.system or contenders.check_specs([args.contender])[0][1]  # a spec: its form
    check_trials(system, args.out, **kw)  # a bad flag answers before JAX loads
    distributed.check(args)
    from jaxais import _speed  # its importlib.metadata: after the signal handlers are ours

    _speed.setup(cpu_device_per_core=True)
    distributed.initialize(args)  # before JAX computes anything
    command = "trials.py " + " ".join(sys.argv[1:] if argv is None else argv)
    start = time.perf_counter()
    doc = trials(system, args.out, command=command, **kw)
    if doc is None:  # not the writing process
        return
    s, rate = doc["summary"], doc["summary"]["idiotypic_difference_rate"]
    print(
        f"{doc['label']} in {doc['world']}: {s['n']} trials, mean tau {s['tau']:.0f} s, "
        f"c {s['collisions']:.1f}, f {s['fitness']:.0f}, failed {100 * s['failure_rate']:.0f} %"
        + (f", idiotypic difference rate {100 * rate:.1f} %" if rate is not None else "")
        + f"; {time.perf_counter() - start:.1f} s wall; wrote {args.out}"
    )


if __name__ == "__main__":
    run_script(main)
