"""Train the neural baseline (an MLP, by OpenES); run it beside SIE and HDC in the paper's worlds.

    python scripts/train_baseline.py                          # train (defaults), then evaluate
    python scripts/train_baseline.py --eval-only              # evaluate the shipped weights
    python scripts/train_baseline.py --out /tmp/nn --generations 20 --no-eval
    python scripts/train_baseline.py --collect checkpoints/neural runs/nn-seed1   # one table

Writes params.npz, config.json, training_curve.png, evaluation.json and .md into --out: a fresh
runs/baseline-DATE-TIME by default, checkpoints/ only if asked (jaxais.experiments.baseline).
"""

from __future__ import annotations

import argparse
import datetime
import sys
from dataclasses import fields
from pathlib import Path

from jaxais import _speed
from jaxais.baselines.config import TrainConfig
from jaxais.cli import ArgumentParser, UserError, main_wrapper, run_script


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(prog="train_baseline.py", description=__doc__.split("\n\n")[0])
    # fmt: off
    p.add_argument("--out", help="output directory (default: a fresh runs/baseline-DATE-TIME)")
    p.add_argument("--weights", help="--eval-only's weights (default: --out, else the shipped)")
    p.add_argument("--into-checkpoints", action="store_true", help="allow --out in checkpoints/")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed of the training")
    p.add_argument("--eval-seed", type=int, default=0, help="PRNG seed of the trials")
    p.add_argument("--eval-only", action="store_true", help="evaluate trained weights only")
    p.add_argument("--no-eval", action="store_true", help="train only")
    p.add_argument("--seeds", default=None, help="LTL seed directory for SIE (default: shipped)")
    p.add_argument("--log-every", type=int, default=10, help="generations per log line")
    p.add_argument("--collect", nargs="+", metavar="DIR", help="tabulate evaluated runs, exit")
    g = p.add_argument_group("training (TrainConfig; defaults [ours])")
    for f in fields(TrainConfig):
        g.add_argument(f"--{f.name.replace('_', '-')}", type=type(f.default), default=f.default,
                       help=f"default {f.default}")
    # fmt: on
    return p.parse_args(argv)


@main_wrapper("train_baseline.py")
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    from jaxais.experiments import baseline as driver

    if args.collect:
        print(driver.collect_baselines(args.collect), end="")
        return
    try:
        config = TrainConfig(**{f.name: getattr(args, f.name) for f in fields(TrainConfig)})
    except ValueError as err:
        raise UserError(f"--{str(err).replace('_', '-')}") from err
    if args.eval_only and args.no_eval or args.weights and not args.eval_only:
        raise UserError("--weights goes with --eval-only, which excludes --no-eval")
    out = args.out or datetime.datetime.now().strftime("runs/baseline-%Y%m%d-%H%M%S")
    command = "train_baseline.py " + " ".join(sys.argv[1:] if argv is None else argv)
    _speed.setup()  # after the flags are checked: a bad flag answers without loading JAX
    if not args.eval_only:
        info = driver.train_baseline(
            out, config, seed=args.seed, log_every=args.log_every, command=command,
            into_checkpoints=args.into_checkpoints,
        )  # fmt: skip
        fitness = info["final"]["center_fitness"]
        print(f"trained in {info['wall_s']:.0f} s, final centre fitness {fitness:.2f}; wrote {out}")
    if not args.no_eval:
        driver.evaluate_baseline(
            (args.weights or args.out) if args.eval_only else out, out, seed=args.eval_seed,
            seeds=args.seeds, command=command, into_checkpoints=args.into_checkpoints,
        )  # fmt: skip
        print(Path(out, "evaluation.md").read_text(), end="")
        print(f"wrote {out}/evaluation.json and {out}/evaluation.md")


if __name__ == "__main__":
    run_script(main)
