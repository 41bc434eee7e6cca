"""Rerun the paper's protocol with each of our readings switched to its alternative, and tabulate.

    python scripts/ablate.py --out ablation/
    python scripts/ablate.py --out ablation/ --trials 10 --worlds world1 --variants ours,literal

Variants (jaxais.experiments.ablation.VARIANTS): "ours", one per [ours] reading of SPEC 5-9
switched to the earlier literal reading, and "literal" (every old reading together); each runs
every system in every world with the paper's trial counts and common random numbers. Writes
DIR/ablation.json, ablation.md (the table), ablation.png and run.json (config, seeds, versions,
batches, timings); jaxais.experiments.ablation.ablate. --resume finishes an interrupted run
from the batches DIR/manifest.json lists.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from jaxais.cli import ArgumentParser, main_wrapper, run_script
from jaxais.experiments import protocol


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(prog="ablate.py", description=__doc__.split("\n\n")[0])
    # fmt: off
    p.add_argument("--out", required=True, help="output directory (missing or empty)")
    p.add_argument("--resume", action="store_true", help="finish the interrupted run in --out")
    p.add_argument("--trials", type=int, default=None,
                   help=f"trials per system and world (default: the paper's "
                   f"{protocol.SIMULATED_TRIALS}, {protocol.REAL_TRIALS} in {protocol.REAL_WORLD})")
    p.add_argument("--worlds", default=",".join(protocol.WORLDS), help="comma-separated worlds")
    p.add_argument("--variants", default=None,
                   help="comma-separated variants (default: all; names as in ablation.md)")
    p.add_argument("--seeds", default=None, help="LTL seed directory (default: the shipped one)")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed of the trials")
    protocol.add_cap_arguments(p)
    p.add_argument("--no-share", action="store_true",
                   help="run every variant's every system, even one the same as another's")
    # fmt: on
    return p.parse_args(argv)


@main_wrapper("ablate.py")
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    from jaxais import _speed
    from jaxais.experiments import ablation

    _speed.setup(cpu_device_per_core=True)
    doc, run = ablation.ablate(
        args.out,
        worlds=[w for w in args.worlds.split(",") if w],
        variants=None if args.variants is None else [v for v in args.variants.split(",") if v],
        trials=args.trials,
        seed=args.seed,
        seeds=args.seeds,
        tau_cap=args.tau_cap,
        collision_cap=args.collision_cap,
        share=not args.no_share,
        resume=args.resume,
    )
    print(ablation.markdown(doc), end="")
    out = Path(args.out)
    print(
        f"\n{len(run['variants'])} variants x {len(run['worlds'])} worlds in "
        f"{len(run['calls'])} batches; total {run['timings_s']['total_s']:.0f} s. "
        f"Wrote {out / 'ablation.md'}, ablation.json, ablation.png, run.json."
    )


if __name__ == "__main__":
    run_script(main)
