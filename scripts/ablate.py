"""Rerun the paper's protocol with each of our readings switched to its alternative, and tabulate.

    python scripts/ablate.py --out ablation/
    python scripts/ablate.py --out ablation/ --trials 10 --worlds world1 --variants ours,literal

The engine's readings of what the paper leaves open ([ours] in SPEC 5-9) each have a named
alternative, the earlier literal reading (jaxais.experiments.ablation.VARIANTS): "ours", one
variant per reading switched, and "literal" (every old reading together). Each variant runs every
system in every world with the paper's trial counts (30 per simulated world, 20 in `real`;
jaxais.experiments.protocol). Variants that differ only in traced data (the readings, the HDC's
antibodies) run as one compiled batch per world; a variant with another episode rule or
simulator parameters is its own batch. Every variant meets the same worlds and random streams
(common random numbers). Writes DIR/ablation.json (per variant: settings, claims reproduced and
held, SIE/HDC/URL-R1 mean f and failure rate per world), DIR/ablation.md (the table),
DIR/ablation.png and DIR/run.json (the config, seeds, versions, batches and timings).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

from jaxais.cli import (
    ArgumentParser,
    UserError,
    atomic_write_json,
    atomic_write_text,
    check_writable_dir,
    main_wrapper,
    run_script,
)
from jaxais.experiments import protocol


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(prog="ablate.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output directory (created if missing)")
    p.add_argument(
        "--trials",
        type=int,
        default=None,
        help=f"trials per system and world (default: the paper's {protocol.SIMULATED_TRIALS}, "
        f"{protocol.REAL_TRIALS} in {protocol.REAL_WORLD})",
    )
    p.add_argument(
        "--worlds", default=",".join(protocol.WORLDS), help="comma-separated subset of worlds"
    )
    p.add_argument(
        "--variants",
        default=None,
        help="comma-separated subset of the variants (default: all; names as in ablation.md)",
    )
    p.add_argument(
        "--seeds",
        default=None,
        help="LTL seed directory (default: the shipped checkpoints/default)",
    )
    p.add_argument("--seed", type=int, default=0, help="PRNG seed of the trials")
    protocol.add_cap_arguments(p)
    p.add_argument(
        "--no-share",
        action="store_true",
        help="run every variant's every system, even one that is the same data as another's",
    )
    return p.parse_args(argv)  # fmt: skip


@main_wrapper("ablate.py")
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    worlds = [w for w in args.worlds.split(",") if w]
    unknown = sorted(set(worlds) - set(protocol.WORLDS))
    if unknown or not worlds:
        raise UserError(
            f"--worlds: unknown world(s) {unknown} (choose from {', '.join(protocol.WORLDS)})"
        )
    if len(set(worlds)) != len(worlds):
        raise UserError(f"--worlds: a world is named twice in {args.worlds!r}")
    if not 0 <= args.seed < 2**32:
        raise UserError(f"--seed must be in [0, 2**32), got {args.seed}")
    if args.trials is not None and args.trials < 2:
        raise UserError(f"--trials must be >= 2 (t-tests need two per group), got {args.trials}")
    if not 0 < args.tau_cap <= 1e6 or args.collision_cap < 1:
        raise UserError("--tau-cap must be in (0, 1e6] and --collision-cap >= 1")
    names = None if args.variants is None else [v for v in args.variants.split(",") if v]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    check_writable_dir(out)

    # Imported after the cheap checks: a bad flag answers without loading JAX.
    from tqdm import tqdm

    from jaxais import _speed
    from jaxais.experiments import ablation
    from jaxais.experiments.plotting import save_figure
    from jaxais.experiments.records import load_ltl_seed, versions
    from jaxais.trials import STL_CONFIG

    try:
        variants = ablation.select(names)
    except ValueError as err:
        raise UserError(f"--variants: {err}") from None
    _speed.setup(cpu_device_per_core=True)
    started = time.perf_counter()
    # Read once, and early: a missing or corrupt seed fails before any trial runs.
    ltl_seed, seed_info = load_ltl_seed(args.seeds)
    base = dataclasses.replace(STL_CONFIG, tau_cap=args.tau_cap, collision_cap=args.collision_cap)
    n_trials = {
        w: args.trials if args.trials is not None else protocol.trials_for_world(w) for w in worlds
    }
    with tqdm(unit="run", file=sys.stderr, desc="ablation") as bar:  # run_ablation sets the total
        result = ablation.run_ablation(
            worlds, variants, args.seed, ltl_seed, n_trials, base,
            share=not args.no_share, progress=bar,
        )  # fmt: skip
    wall = time.perf_counter() - started

    doc = ablation.document(result, variants, n_trials)
    atomic_write_json(out / "ablation.json", doc)
    table = ablation.markdown(doc)
    atomic_write_text(out / "ablation.md", "# Ablation of our readings\n\n" + table)
    save_figure(ablation.figure(doc), out / "ablation.png")
    # The command that regenerates the run, every flag explicit, without the output directory.
    command = (
        f"ablate.py --out DIR --worlds {','.join(worlds)} "
        f"--variants {','.join(v.name for v in variants)} --seed {args.seed} "
        f"--tau-cap {args.tau_cap:g} --collision-cap {args.collision_cap}"
        + ("" if args.trials is None else f" --trials {args.trials}")
        + ("" if args.seeds is None else f" --seeds {seed_info['path']}")
        + (" --no-share" if args.no_share else "")
    )
    run = {
        "command": command,
        "seed": args.seed,
        "trials": n_trials,
        "worlds": worlds,
        "variants": [v.name for v in variants],
        "episode": {"tau_cap": base.tau_cap, "collision_cap": base.collision_cap},
        "share_identical_systems": not args.no_share,
        "ltl_seed": seed_info,
        "versions": versions(),
        "cpu_cores": os.cpu_count(),
        "calls": result.calls,
        "timings_s": {"total_s": wall, "run_s": sum(c["run_s"] for c in result.calls)},
    }
    atomic_write_json(out / "run.json", run)
    print(table, end="")
    print(
        f"\n{len(variants)} variants x {len(worlds)} worlds in {len(result.calls)} batches; "
        f"total {wall:.0f} s. "
        f"Wrote {out / 'ablation.md'}, ablation.json, ablation.png, run.json."
    )


if __name__ == "__main__":
    run_script(main)
