"""The paper's claims across LTL seeds: the whole protocol on N fresh seeds, one ledger.

    python scripts/seeds.py --out DIR                          # LTL seeds 0-9, paper's trials
    python scripts/seeds.py --out DIR --seeds 4 --first 10 --trials 10 --jobs 2
    python scripts/seeds.py --out DIR --contender my_controller.py:braitenberg

Runs :func:`jaxais.experiments.seeds.ltl_ledger`: for each seed s, scripts/evolve.py --out
DIR/ltl/seed_s --seed s (the LTL, its defaults), then scripts/reproduce.py --seeds
DIR/ltl/seed_s/seed --out DIR/stl/seed_s --seed s --no-baseline.
Writes DIR/seeds.json and DIR/seeds.md (per seed: claims held, H1-H4, SIE's and SRL's failure
rates and lock-up times, SIE's difference rate; per claim: on how many seeds it holds), rebuilt
after every seed, and DIR/run.json. Add --resume to go on after an interruption: finished seeds
are kept, an interrupted LTL or STL resumes exactly (jaxais.experiments.seeds says how).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from jaxais.cli import (
    ArgumentParser,
    add_ledger_arguments,
    main_wrapper,
    remake_command,
    run_script,
)
from jaxais.experiments import contenders
from jaxais.experiments.seeds import SeedRunError, headline, ltl_ledger, seed_range


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(prog="seeds.py", description=__doc__.split("\n\n")[0])
    add_ledger_arguments(p, jobs="seeds run")
    contenders.add_argument(p)  # run beside the paper's systems on every seed
    return p.parse_args(argv)


@main_wrapper("seeds.py", extra=(SeedRunError,))
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    seeds = seed_range(args.seeds, args.first)
    from jaxais.experiments.records import portable_command

    summary = ltl_ledger(
        args.out,
        seeds,
        trials=args.trials,
        jobs=args.jobs,
        contenders=args.contender or (),
        command=portable_command(remake_command("seeds.py", argv)),
        resume=args.resume,
    )
    print(f"{headline(summary)}; wrote {Path(args.out) / 'seeds.md'}")


if __name__ == "__main__":
    run_script(main)
