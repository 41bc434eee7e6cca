"""Evolve LTL antibody sets with the genetic algorithm (SPEC 10) and write the STL's seed.

python scripts/evolve.py --out DIR [--resume] [--diversity]  # DIR/seed, summary.json, ...
python scripts/evolve.py --check-seed DIR/seed  # measure an existing seed, evolve nothing
Your own selection, crossover, mutation: evolution.evolve(operators=...), examples/tournament_ga.py
"""

import argparse
import dataclasses
import logging
import sys

from jaxais.cli import ArgumentParser, UserError, main_wrapper, run_script
from jaxais.ga.config import CROSSING_STARTS, ConfigError, GAConfig


def fraction_or_none(text: str) -> float | None:
    return None if text.strip().lower() in ("none", "off") else float(text)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(prog="evolve.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--world", default="ga_maze", help="world name or .toml path")
    types = {"target_f": float, "success_rate": fraction_or_none}
    for f in dataclasses.fields(GAConfig):  # defaults, types and help: GAConfig's
        kind = {"choices": ("uniform", "rl")} if f.name == "crossover" else {}
        flag, type_ = f"--{f.name.replace('_', '-')}", types.get(f.name, type(f.default))
        p.add_argument(flag, default=f.default, type=type_, help=f.metadata["help"], **kind)
    add = p.add_argument
    add("--crossing-starts", type=int, default=CROSSING_STARTS, help="starts per set to measure")
    add("--seed", type=int, default=0, help="PRNG seed of the run")
    add("--out", help="output directory (created if missing)")
    add("--resume", action="store_true", help="continue from DIR/checkpoints")
    add("--diversity", action="store_true", help="compare 5 x 10 with 1 x 50")
    add("--diversity-seeds", type=int, default=argparse.SUPPRESS, help="GA seeds per arm (3)")
    add("--check-seed", metavar="DIR", help="measure the seed in DIR and exit (no GA, no --out)")
    args = p.parse_args(argv)
    if "diversity_seeds" in args and not args.diversity:
        p.error("--diversity-seeds applies with --diversity only")
    args.config = GAConfig(**{f.name: getattr(args, f.name) for f in dataclasses.fields(GAConfig)})
    return args


@main_wrapper("evolve.py")
def run(argv: list[str] | None = None) -> dict:
    try:
        return _run(parse_args(argv), argv)
    except ConfigError as err:
        raise UserError(f"--{err.field.replace('_', '-')} {err.reason}") from None


def _run(args: argparse.Namespace, argv: list[str] | None) -> dict:
    for flag in ("out", "resume", "diversity") if args.check_seed else ():
        if getattr(args, flag):
            raise UserError(f"--check-seed measures a seed and writes nothing: drop --{flag}")
    if args.out is None and args.check_seed is None:
        raise UserError("--out DIR is required (or --check-seed DIR to measure a seed)")
    from jaxais import _speed
    from jaxais.experiments import evolution

    logging.getLogger("absl").setLevel(logging.CRITICAL)  # orbax's failures: our one line
    _speed.setup()
    given = dict(config=args.config, world=args.world, seed=args.seed)
    given["crossing_starts"] = args.crossing_starts
    if args.check_seed is not None:
        result = evolution.check_seed(args.check_seed, **given)
    else:
        given |= dict(resume=args.resume, argv=sys.argv[1:] if argv is None else list(argv))
        seeds = getattr(args, "diversity_seeds", 3) if args.diversity else None
        result = evolution.evolve(args.out, **given, diversity_seeds=seeds)
    print(evolution.report(result, args.check_seed or args.out))
    return result


def main(argv: list[str] | None = None) -> None:  # a console script exits with what it returns
    run(argv)


if __name__ == "__main__":
    run_script(main)
