"""Sweep the STL's parameters, or the world's noise: whole landscapes with confidence intervals.

    python scripts/sweep.py --grid k1=0:2:11 --grid k2=0:2:11 --system SIE --world world1 \\
        --trials 30 --out sweep/
    python scripts/sweep.py --noise 0,0.5,1,2,4 --system SIE,SRL,HDC --world real --out gap/

--grid: every point's trials run as one compiled pool of runs (jaxais.runner.run_pool). Writes
DIR/sweep.json (per point: mean and 95 % CI of tau, c, f, the failure rate, the idiotypic
difference rate and trapped time; the run's config, wall time and throughput) and, for one or
two axes, DIR/sweep.png (lines or heatmaps, the operating point marked, the idiotypic difference
rate's 20 % contour drawn). Sweepable: jaxais.experiments.sweep.PARAMETERS.

--noise: the world's IR, camera and wheel noise (or --noise-kinds) scaled by each factor (1 = the
world's own levels), every system at every level. Writes DIR/reality_gap.json and
DIR/reality_gap.png (f and failure rate against noise).

The same arguments give the same numbers, on one process or several (--coordinator ...).
"""

from __future__ import annotations

import argparse
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
from jaxais.labels import RANDOM_SETS, SYSTEMS, label

NOISE_SYSTEMS = "SIE,SRL,HDC"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(prog="sweep.py", description=__doc__.split("\n\n")[0])
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument(
        "--grid",
        action="append",
        metavar="NAME=START:STOP:COUNT",
        help="an axis of the grid (repeat for more axes), e.g. k1=0:2:11 or hold=1,10,31",
    )
    what.add_argument(
        "--noise",
        metavar="S1,S2,...",
        help="noise scales of the world's noise (1 = its own levels), e.g. 0,0.5,1,2,4",
    )
    p.add_argument(
        "--noise-kinds", default="ir,camera,wheel", help="which noise --noise scales (default all)"
    )
    p.add_argument(
        "--system",
        default=None,
        help=f"the system (--grid; default SIE) or systems (--noise; default {NOISE_SYSTEMS}), "
        f"of {', '.join(SYSTEMS)}",
    )
    p.add_argument("--random-set", choices=tuple(RANDOM_SETS), default=None)
    p.add_argument(
        "--world",
        default=None,
        help=f"{', '.join(protocol.WORLDS)} or a .toml path "
        f"(default: world1 with --grid, {protocol.REAL_WORLD} with --noise)",
    )
    p.add_argument(
        "--trials",
        type=int,
        default=None,
        help="trials per point (default: the paper's count in that world)",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--seeds", default=None, help="LTL seed directory (default: the shipped one)")
    protocol.add_cap_arguments(p)
    p.add_argument("--slots", type=int, default=1024, help="runs live at once (default 1024)")
    p.add_argument("--out", required=True, help="output directory (created if missing)")
    distributed.add_arguments(p)
    return p.parse_args(argv)  # fmt: skip


def _systems(args: argparse.Namespace) -> list[str]:
    names = (args.system or ("SIE" if args.grid else NOISE_SYSTEMS)).split(",")
    for name in names:
        if name not in SYSTEMS:
            raise UserError(f"--system: unknown system {name!r} (one of {', '.join(SYSTEMS)})")
    if args.grid and len(names) != 1:
        raise UserError("--grid sweeps one system: give --system NAME")
    if args.random_set and not {"UIE", "URL"} & set(names):
        raise UserError("--random-set applies to UIE and URL only")
    return [label(n, args.random_set or "R1") for n in names]


def _scales(text: str) -> list[float]:
    try:
        scales = [float(v) for v in text.split(",")]
    except ValueError:
        raise UserError(f"--noise must be comma-separated numbers, got {text!r}") from None
    if not all(0 <= s < float("inf") for s in scales):
        raise UserError(f"--noise scales must be finite and >= 0, got {text!r}")
    return scales


@main_wrapper("sweep.py")
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    args.world = args.world or (protocol.REAL_WORLD if args.noise else protocol.WORLDS[0])
    if args.trials is None:
        args.trials = protocol.trials_for_world(args.world)
    if not 0 <= args.seed < 2**32:
        raise UserError(f"--seed must be in [0, 2**32), got {args.seed}")
    if args.trials < 1:
        raise UserError(f"--trials must be >= 1, got {args.trials}")
    if args.slots < 1:
        raise UserError(f"--slots must be >= 1, got {args.slots}")
    names = _systems(args)
    distributed.check(args)
    from jaxais.experiments import sweep

    if args.grid:
        axes = [sweep.parse_axis(spec) for spec in args.grid]
        axis_names = [name for name, _ in axes]
        if len(set(axis_names)) < len(axis_names):
            raise UserError(f"--grid names a parameter twice: {', '.join(axis_names)}")
    else:
        scales = _scales(args.noise)
        kinds = args.noise_kinds.split(",")
        if set(kinds) - set(sweep.NOISE_KINDS):
            raise UserError(f"--noise-kinds: one or more of {', '.join(sweep.NOISE_KINDS)}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    check_writable_dir(out)

    from tqdm import tqdm

    distributed.initialize(args)  # before JAX computes anything
    import jax

    from jaxais import envs
    from jaxais.experiments.records import build_systems, portable_command, run_config
    from jaxais.experiments.sweep_plots import save_noise_figure, save_sweep_figures
    from jaxais.immune.network import NetworkParams
    from jaxais.loop import EpisodeConfig

    world = envs.load_world(args.world)
    config = EpisodeConfig(tau_cap=args.tau_cap, collision_cap=args.collision_cap)
    network = NetworkParams()
    systems, seed_info = build_systems(names, args.seeds, network)
    params = envs.default_params()
    if args.grid:
        points = sweep.grid_points(axes)
        sweep.point_systems(systems[names[0]], points)  # every value in range, before any run
        total, unit = args.trials * len(points), "run"
    else:
        [sweep.noisy_world(world, s, kinds) for s in scales]  # every scale valid, likewise
        total, unit = len(scales), "level"
    # Every process runs every step (and computes the same numbers); process 0 reports and writes.
    lead = jax.process_index() == 0
    start = time.perf_counter()
    desc = f"{','.join(names)} in {world.name}"
    with tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, disable=not lead) as bar:
        if args.grid:
            doc = sweep.run_sweep(
                world, systems[names[0]], names[0], axes, args.trials, args.seed, config,
                params, args.slots, bar.update,
            )  # fmt: skip
        else:
            doc = sweep.run_noise_sweep(
                world, systems, scales, args.trials, args.seed, config, params, kinds,
                bar.update,
            )  # fmt: skip
    doc["wall_s_total"] = time.perf_counter() - start
    doc |= {"system": ",".join(names), "world": world.name, "seed": args.seed}
    doc["trials"] = args.trials
    if args.grid:
        doc["paper_point"] = {
            "values": sweep.PAPER_POINT,
            "idiotypic_difference_rate": sweep.interpolate(
                doc, "idiotypic_difference_rate", sweep.PAPER_POINT
            ),
        }
    cfg = run_config(world, args.world, config, network, params, seed_info)
    cfg["command"] = portable_command(
        "sweep.py " + " ".join(sys.argv[1:] if argv is None else argv)
    )
    cfg["processes"] = jax.process_count()
    cfg["devices"] = jax.device_count()
    doc["config"] = cfg
    if not lead:
        return
    if args.grid:
        atomic_write_json(out / "sweep.json", doc)
        figures = save_sweep_figures(doc, out)
        print(
            f"{desc}: {doc['runs']} runs in {doc['wall_s_total']:.0f} s "
            f"({doc['runs_per_s']:.1f} runs/s, {doc['robot_iterations_per_s'] / 1e6:.2f} M "
            f"useful robot-iterations/s, compile included); wrote {out / 'sweep.json'}"
            + (f" and {len(figures)} figure" if figures else "")
        )
    else:
        atomic_write_json(out / "reality_gap.json", doc)
        save_noise_figure(doc, out)
        print(
            f"{desc}: {len(scales)} noise levels x {len(names)} systems x {args.trials} trials "
            f"in {doc['wall_s_total']:.0f} s; wrote {out / 'reality_gap.json'} and the figure"
        )


if __name__ == "__main__":
    run_script(main)
