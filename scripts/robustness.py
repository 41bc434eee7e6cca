"""How robust each of the paper's claims is: the protocol over LTL seeds x world scales x counting.

    python scripts/robustness.py --out docs/robustness                  # seeds 0-9, scales 1,2
    python scripts/robustness.py --out DIR --ltl ledger/ltl --jobs 2    # the ledger's LTL runs
    python scripts/robustness.py --out DIR --seeds 2 --scales 1,2 --trials 4

Runs :func:`jaxais.experiments.robustness.run`: for each LTL seed s (DIR/ltl/seed_s or --ltl's,
evolved only where missing) and world scale K, scripts/reproduce.py --seeds LTL/seed_s/seed
--out DIR/stl/seed_s_scale_K --seed s --no-baseline --world-scale K; each run's claims count c
per contact episode and per reading, so the rules cost no extra runs. Writes DIR/robustness.json
(jaxais-robustness/1), robustness.md, robustness.png and run.json (wall and CPU time), rebuilt
after every run; --resume goes on after an interruption with the same results.
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
from jaxais.experiments import protocol
from jaxais.experiments.seeds import SeedRunError, seed_range


def _floats(text: str) -> list[float]:
    try:
        return [float(v) for v in text.split(",") if v]
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be comma-separated numbers, got {text!r}") from None


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(prog="robustness.py", description=__doc__.split("\n\n")[0])
    # fmt: off
    add_ledger_arguments(p, jobs="runs")
    p.add_argument("--scales", type=_floats, default=[1.0, 2.0],
                   help="world scales, comma-separated (default 1,2)")
    p.add_argument("--rules", default=",".join(protocol.COUNTING_RULES),
                   help=f"collision counting rules (default {','.join(protocol.COUNTING_RULES)})")
    p.add_argument("--ltl", default=None,
                   help="the seeds ledger's LTL folder (its seed_s; default DIR/ltl)")
    # fmt: on
    return p.parse_args(argv)


@main_wrapper("robustness.py", extra=(SeedRunError,))
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    seeds = seed_range(args.seeds, args.first)
    from jaxais.experiments import robustness
    from jaxais.experiments.records import portable_command

    doc = robustness.run(
        args.out, seeds, args.scales,
        [r for r in args.rules.split(",") if r], args.trials, args.jobs, args.ltl,
        command=portable_command(remake_command("robustness.py", argv)), resume=args.resume,
    )  # fmt: skip
    print(f"{robustness.headline(doc)}; wrote {Path(args.out) / 'robustness.md'}")


if __name__ == "__main__":
    run_script(main)
