"""Train the neural baseline (an MLP, by OpenES); run it beside SIE and HDC in the paper's worlds.

    python scripts/train_baseline.py                          # train (defaults), then evaluate
    python scripts/train_baseline.py --eval-only              # evaluate the shipped weights
    python scripts/train_baseline.py --out /tmp/nn --generations 20 --no-eval
    python scripts/train_baseline.py --collect checkpoints/neural runs/nn-seed1   # one table

Writes params.npz, config.json, training_curve.png, evaluation.json and .md into --out: a fresh
runs/baseline-DATE-TIME by default, checkpoints/ only if asked (jaxais.experiments.baseline);
--resume finishes an interrupted run, skipping the stage (training) DIR/manifest.json lists.
"""

from __future__ import annotations

import argparse
import datetime
from dataclasses import fields
from pathlib import Path

from jaxais import _speed
from jaxais.baselines.config import TrainConfig
from jaxais.cli import ArgumentParser, UserError, main_wrapper, remake_command, run_script


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(prog="train_baseline.py", description=__doc__.split("\n\n")[0])
    # fmt: off
    p.add_argument("--out", help="output directory (default: a fresh runs/baseline-DATE-TIME)")
    p.add_argument("--resume", action="store_true", help="finish the interrupted run in --out")
    p.add_argument("--weights", help="--eval-only's weights (default: the shipped)")
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
    _speed.setup()  # after the flags are checked: a bad flag answers without loading JAX
    info, _ = driver.baseline(
        out, config, train=not args.eval_only, evaluate=not args.no_eval, seed=args.seed,
        eval_seed=args.eval_seed, weights=args.weights, seeds=args.seeds,
        log_every=args.log_every, command=remake_command("train_baseline.py", argv),
        into_checkpoints=args.into_checkpoints, resume=args.resume,
    )  # fmt: skip
    if info is not None:
        fitness = info["final"]["center_fitness"]
        print(f"trained in {info['wall_s']:.0f} s, final centre fitness {fitness:.2f}; wrote {out}")
    if not args.no_eval:
        print(Path(out, "evaluation.md").read_text(), end="")
        print(f"wrote {out}/evaluation.json and {out}/evaluation.md")


if __name__ == "__main__":
    run_script(main)
