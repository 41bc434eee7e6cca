"""Reproduce the paper end to end: every system in every world, Tables 3-5, H1-H4, a report.

    python scripts/reproduce.py --out results/
    python scripts/reproduce.py --out results/ --trials 1000          # tight intervals
    python scripts/reproduce.py --out results/ --evolve --contender mine.py:braitenberg

Runs :func:`jaxais.experiments.reproduce` (SPEC 9; --evolve: a fresh LTL seed first; --contender:
your controller beside the paper's systems), over every process's devices (process 0 writes):
DIR/tables.json, claims.json, report.md, figures/, trials/, run.json (all it takes to regenerate
them) and manifest.json (the worlds done: --resume finishes an interrupted run).
"""

from __future__ import annotations

import argparse

from jaxais import distributed
from jaxais.cli import ArgumentParser, UserError, main_wrapper, remake_command, run_script
from jaxais.experiments import contenders, protocol
from jaxais.experiments.reproduction import LTLRunError, check_reproduce, headline, reproduce


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(prog="reproduce.py", description=__doc__.split("\n\n")[0])
    # fmt: off
    p.add_argument("--out", required=True, help="output directory (missing or empty)")
    p.add_argument("--resume", action="store_true", help="finish the interrupted run in --out")
    p.add_argument("--trials", type=int, default=None,
                   help=f"trials per system and world (default: the paper's "
                   f"{protocol.SIMULATED_TRIALS}, {protocol.REAL_TRIALS} in {protocol.REAL_WORLD})")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--seeds", help="LTL seed directory (default: checkpoints/default)")
    src.add_argument("--evolve", action="store_true",
                     help="run the LTL (scripts/evolve.py, defaults, PRNG seed --seed) first and "
                     "use its seed")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed of the trials (and of --evolve)")
    nn = p.add_mutually_exclusive_group()
    nn.add_argument("--baseline", default=None, help="the neural contender NN's weights "
                    "(default: the shipped checkpoints/neural; scripts/train_baseline.py)")
    nn.add_argument("--no-baseline", action="store_true", help="run the paper's systems only")
    contenders.add_argument(p)  # run beside the paper's systems in every world
    p.add_argument("--worlds", default=",".join(protocol.WORLDS), help="comma-separated "
                   "worlds: the paper's, or world files PATH.toml (the simulated protocol)")
    protocol.add_cap_arguments(p)
    protocol.add_world_scale_argument(p)
    p.add_argument("--explain", action="append", metavar="PATH", help="what the report's 'why' "
                   "reads (repeat): a run of more trials, seeds.json, robustness.json")
    distributed.add_arguments(p)
    p.add_argument("--generations", type=int, help="LTL generation cap with --evolve (default: "
                   "evolve.py's)")
    return p.parse_args(argv)  # fmt: on


@main_wrapper("reproduce.py", extra=(LTLRunError,))
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    kw = dict(trials=args.trials, seed=args.seed, seeds=args.seeds, evolve=args.evolve,
              generations=args.generations, worlds=args.worlds, tau_cap=args.tau_cap,
              collision_cap=args.collision_cap, contenders=args.contender,
              world_scale=args.world_scale, explain=args.explain or ())  # fmt: skip
    check_reproduce(args.out, **kw)  # a bad flag answers before JAX loads
    distributed.check(args)
    if args.evolve and args.coordinator:
        raise UserError("--evolve runs on one process; evolve first, then pass --seeds DIR")
    from jaxais import _speed  # its importlib.metadata: after the signal handlers are ours

    _speed.setup(cpu_device_per_core=True)
    distributed.initialize(args)  # before JAX computes anything
    result = reproduce(
        args.out, baseline=not args.no_baseline if args.baseline is None else args.baseline,
        command=remake_command("reproduce.py", argv),
        resume=args.resume, **kw,
    )  # fmt: skip
    if result is not None:  # the writing process
        print(headline(result))


if __name__ == "__main__":
    run_script(main)
