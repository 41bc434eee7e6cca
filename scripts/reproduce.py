"""Reproduce the paper end to end: every system in every world, Tables 3-5, H1-H4, a report.

    python scripts/reproduce.py --out results/
    python scripts/reproduce.py --out results/ --trials 1000          # tight intervals
    python scripts/reproduce.py --out results/ --evolve               # fresh LTL seed first

Runs the paper's protocol (SPEC 9): 30 trials of each system per simulated world and 20 in
`real`; the unseeded systems with both random sets R1 and R2 in the simulated worlds and R1 only
in `real`. All systems of a world run as one compiled, vmapped pool of runs, each slot refilled
when its run ends (sharded over every process's devices with the jax.distributed flags, as in
scripts/sweep.py; process 0 writes). Writes DIR/tables.json,
DIR/claims.json (the paper's 32 claims, each held or not, also read with 95 % confidence
intervals, and a summary), DIR/report.md (opening with the claims ledger; Table 3 with 95 %
bootstrap intervals; figures in DIR/figures/), every trial in DIR/trials/ and DIR/run.json
(the config, seeds and timings needed to regenerate it all). Only the first trial of each
system is drawn (run again with its trajectory recorded); the records of all trials are kept.
SIE also runs with a selection every iteration (``hold=1``, trials/WORLD_SIE_hold1.json) for
the report's calibration point: its idiotypic difference rate beside the paper's 20 %.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
import subprocess
import sys
import time
from pathlib import Path

from jaxais import distributed
from jaxais.cli import (
    ArgumentParser,
    UserError,
    atomic_write_json,
    check_writable_dir,
    main_wrapper,
    run_script,
)
from jaxais.experiments import protocol


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(prog="reproduce.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output directory (created if missing)")
    p.add_argument(
        "--trials",
        type=int,
        default=None,
        help=f"trials per system and world (default: the paper's {protocol.SIMULATED_TRIALS}, "
        f"{protocol.REAL_TRIALS} in {protocol.REAL_WORLD})",
    )
    src = p.add_mutually_exclusive_group()
    src.add_argument(
        "--seeds",
        default=None,
        help="LTL seed directory (default: the shipped checkpoints/default)",
    )
    src.add_argument(
        "--evolve",
        action="store_true",
        help="run the LTL (scripts/evolve.py, defaults, PRNG seed --seed) first and use its seed",
    )
    p.add_argument("--seed", type=int, default=0, help="PRNG seed of the trials (and of --evolve)")
    nn = p.add_mutually_exclusive_group()
    nn.add_argument(
        "--baseline",
        default=None,
        help="trained neural controller beside SIE and HDC (default: the shipped "
        "checkpoints/neural; scripts/train_baseline.py makes one)",
    )
    nn.add_argument("--no-baseline", action="store_true", help="run the paper's systems only")
    p.add_argument(
        "--worlds", default=",".join(protocol.WORLDS), help="comma-separated subset of worlds"
    )
    protocol.add_cap_arguments(p)
    distributed.add_arguments(p)
    p.add_argument(
        "--generations",
        type=int,
        default=None,
        help="LTL generation cap with --evolve (default: evolve.py's)",
    )
    return p.parse_args(argv)  # fmt: skip


def _ltl_summary(seed_dir: Path) -> dict | None:
    """The evolve.py summary next to a seed (DIR/seed -> DIR/summary.json), if there is one."""
    for candidate in (seed_dir / "summary.json", seed_dir.parent / "summary.json"):
        if candidate.is_file():
            try:
                return json.loads(candidate.read_text())
            except (OSError, ValueError):
                return None
    return None


def _check_fresh_ltl_dir(ltl_dir: Path, args: argparse.Namespace) -> None:
    """Refuse to run the LTL into a folder an earlier ``--evolve`` left (evolve.py would refuse
    too, with advice for its own flags), saying how to go on without losing that run."""
    if not ltl_dir.exists() or (ltl_dir.is_dir() and not any(ltl_dir.iterdir())):
        return
    if not ltl_dir.is_dir():
        raise UserError(f"{ltl_dir} exists and is not a folder; remove it to run the LTL there")
    if (ltl_dir / "seed").is_dir():
        raise UserError(
            f"{ltl_dir} exists from an earlier --evolve run; remove it, or pass --seeds "
            f"{ltl_dir / 'seed'} instead of --evolve to reuse its seed"
        )
    generations = [] if args.generations is None else ["--generations", str(args.generations)]
    resume = shlex.join(
        ["scripts/evolve.py", "--out", str(ltl_dir), "--seed", str(args.seed), *generations]
    )
    raise UserError(
        f"{ltl_dir} holds an unfinished LTL run; remove it, or finish it with "
        f"'{resume} --resume' and then pass --seeds {ltl_dir / 'seed'} instead of --evolve"
    )


@main_wrapper("reproduce.py")
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    worlds = [w for w in args.worlds.split(",") if w]
    unknown = sorted(set(worlds) - set(protocol.WORLDS))
    if unknown or not worlds:
        raise UserError(
            f"--worlds: unknown world(s) {unknown} (choose from {', '.join(protocol.WORLDS)})"
        )
    if not 0 <= args.seed < 2**32:
        raise UserError(f"--seed must be in [0, 2**32), got {args.seed}")
    if args.trials is not None and args.trials < 2:
        raise UserError(f"--trials must be >= 2 (t-tests need two per group), got {args.trials}")
    if args.tau_cap <= 0 or args.collision_cap < 1:
        raise UserError("--tau-cap must be > 0 and --collision-cap >= 1")
    if args.generations is not None and args.generations < 1:
        raise UserError(f"--generations must be >= 1, got {args.generations}")
    distributed.check(args)
    if args.evolve and args.coordinator:
        raise UserError("--evolve runs on one process; evolve first, then pass --seeds DIR")
    out = Path(args.out)
    if args.evolve:
        _check_fresh_ltl_dir(out / "ltl", args)
    out.mkdir(parents=True, exist_ok=True)
    check_writable_dir(out)

    import numpy as np
    from tqdm import tqdm

    from jaxais import _speed, envs
    from jaxais.baselines.config import NN_LABEL
    from jaxais.baselines.neural import NEURAL, load_params
    from jaxais.experiments import claims, report, stats
    from jaxais.experiments.plotting import draw_world
    from jaxais.experiments.records import (
        build_systems,
        load_ltl_seed,
        portable_command,
        results_document,
        run_config,
        versions,
    )
    from jaxais.immune.network import NetworkParams
    from jaxais.loop import EpisodeConfig
    from jaxais.seed import default_seed_dir
    from jaxais.trials import run_trials

    _speed.setup(cpu_device_per_core=True)
    distributed.initialize(args)  # before JAX computes anything
    import jax

    # Every process runs every trial's share (and gets every number); process 0 writes.
    lead = jax.process_index() == 0
    started = time.perf_counter()
    timings: dict[str, float] = {}
    seeds_dir = Path(args.seeds) if args.seeds else default_seed_dir()
    if args.evolve:
        ltl_dir = out / "ltl"
        cmd = [sys.executable, str(Path(__file__).with_name("evolve.py")), "--out", str(ltl_dir),
               "--seed", str(args.seed)]  # fmt: skip
        if args.generations is not None:
            cmd += ["--generations", str(args.generations)]
        t = time.perf_counter()
        if subprocess.run(cmd).returncode != 0:
            raise UserError("the LTL run (scripts/evolve.py) failed; see its message above")
        timings["ltl_s"] = time.perf_counter() - t
        seeds_dir = ltl_dir / "seed"
    # Read once, and early: a missing or corrupt seed (or baseline) fails before any trial runs.
    loaded = load_ltl_seed(seeds_dir)
    if not args.no_baseline:
        try:
            nn_params, nn_info = load_params(args.baseline)
        except ValueError as err:
            raise UserError(f"--baseline: {err}") from None
        # What made the weights (train_baseline.py's config.json holds the rest).
        nn_info = {"config": nn_info.get("config"), "seed": nn_info.get("seed")}

    network = NetworkParams()
    params = envs.default_params()
    config = EpisodeConfig(tau_cap=args.tau_cap, collision_cap=args.collision_cap)
    # The report draws each system's first trial: it runs again, alone and recorded (the same
    # keys, so the same run as in the pooled trials).
    example = dataclasses.replace(config, record=True)
    results_by_world, baseline_by_world, trajectories, placements, configs = {}, {}, {}, {}, {}
    # SIE again with a selection every iteration: its difference rate beside the paper's 20 %
    # (the report's calibration point), on the plain label's worlds and random streams.
    calibration_by_world, calibrated = {}, "SIE@hold=1"
    (out / "trials").mkdir(exist_ok=True)
    for name in worlds:
        world = envs.load_world(name)
        labels = list(protocol.systems_for_world(name))
        n = args.trials if args.trials is not None else protocol.trials_for_world(name)
        systems, seed_info = build_systems(labels, seeds_dir, network, loaded)
        sie = systems["SIE"]
        hold1 = {calibrated: sie.replace(readings=sie.readings.replace(hold=np.int32(1)))}
        world_t: dict[str, float] = {}
        k = len(labels) + 1 + (not args.no_baseline)
        with tqdm(total=n * k, desc=f"{name}: {k} systems x {n} trials",
                  unit="run", file=sys.stderr, disable=not lead) as bar:  # fmt: skip
            results = run_trials(world, systems | hold1, n, args.seed, config, params, bar, world_t)
            calibration = results.pop(calibrated)
            if not args.no_baseline:
                baseline_by_world[name] = run_trials(
                    world, {NN_LABEL: nn_params}, n, args.seed, config, params, bar, world_t,
                    controller=NEURAL,
                )  # fmt: skip
        first = run_trials(world, systems, 1, args.seed, example, params, None, world_t)
        for key, value in world_t.items():
            timings[f"{name}_{key}"] = value
            timings[key] = timings.get(key, 0.0) + value
        cfg = run_config(world, name, config, network, params, seed_info)
        configs[name] = cfg
        results_by_world[name] = {k: v.records for k, v in results.items()}
        calibration_by_world[name] = {"SIE": calibration.records}
        trajectories[name] = {k: v.trajectories[0][:, :2] for k, v in first.items()}
        placements[name] = {k: v.placements[0] for k, v in first.items()}
        if not lead:
            continue
        for label, trial_set in results.items():
            doc = results_document(label, name, args.seed, trial_set, cfg)
            atomic_write_json(out / "trials" / f"{name}_{label}.json", doc)
        hold1_cfg = {**cfg, "readings": {**cfg["readings"], "hold": 1}}
        doc = results_document(calibrated, name, args.seed, calibration, hold1_cfg)
        atomic_write_json(out / "trials" / f"{name}_SIE_hold1.json", doc)
        for label, trial_set in baseline_by_world.get(name, {}).items():
            # The run's config without the network's parts, with what made the weights.
            nn_cfg = {k: v for k, v in cfg.items() if k not in ("network", "readings", "ltl_seed")}
            nn_cfg["baseline"] = nn_info
            doc = results_document(label, name, args.seed, trial_set, nn_cfg)
            atomic_write_json(out / "trials" / f"{name}_{label}.json", doc)

    if not lead:
        return
    t = time.perf_counter()
    cis = stats.table3_ci(results_by_world)  # once, for the tables and the claims
    tables = stats.build_tables(results_by_world, cis=cis)
    tables["calibration"] = stats.calibration(
        results_by_world, calibration_by_world, {"k1": network.k1, "k2": network.k2}
    )
    if baseline_by_world:
        records = {w: {k: ts.records for k, ts in d.items()} for w, d in baseline_by_world.items()}
        tables["baseline"] = stats.baseline_tables(results_by_world, records)
        tables["baseline"]["weights"] = nn_info
    atomic_write_json(out / "tables.json", tables)
    ledger = claims.claims(results_by_world, cis=cis)
    timings["statistics_s"] = time.perf_counter() - t
    claims_doc = claims.document(ledger)
    atomic_write_json(out / "claims.json", claims_doc)
    timings["total_s"] = time.perf_counter() - started
    run = {
        "command": portable_command(
            "reproduce.py " + " ".join(sys.argv[1:] if argv is None else argv)
        ),
        "seed": args.seed,
        "trials": args.trials,
        "ltl_seed": loaded[1],
        "worlds": configs,
        "versions": versions(),
        "timings_s": timings,
    }
    atomic_write_json(out / "run.json", run)
    loaded = {name: envs.load_world(name) for name in worlds}
    report_path = report.write_report(
        out,
        tables,
        results_by_world,
        report.load_paper_tables(),
        _ltl_summary(seeds_dir),
        {k: v for k, v in run.items() if k != "timings_s"},
        timings,
        trajectories,
        lambda ax, world_name, placement=None: draw_world(ax, loaded[world_name], placement),
        claims_ledger=ledger,
        example_placements=placements,
        baseline=tables.get("baseline"),
    )
    verdicts = ", ".join(
        f"{h} {'supported' if v['supported'] else 'not supported'}"
        for h, v in tables["hypotheses"].items()
    )
    counts, ci_counts = claims_doc["summary"], claims_doc["ci_summary"]
    print(f"{counts['reproduced']} of {counts['evaluated']} evaluated claims reproduced "
          f"({counts['total']} in all; {ci_counts['reproduced_with_ci']} of them with separated "
          f"95 % CIs, {ci_counts['contradicted_with_ci']} contradicted by them); {verdicts}. "
          f"Total {timings['total_s']:.0f} s (compile {timings.get('compile_s', 0):.0f} s). "
          f"Report: {report_path}")  # fmt: skip


if __name__ == "__main__":
    run_script(main)
