"""Sweep the STL's parameters: every grid point's trials in one compiled pool of runs.

    python scripts/sweep.py --grid k1=0:2:11 --grid k2=0:2:11 --system SIE --world world1 \\
        --trials 30 --out sweep/

Writes DIR/sweep.json (per point: mean and 95 % CI of tau, c, f, the failure rate, the
idiotypic difference rate and trapped time; the run's config, wall time and throughput) and, for
one or two axes, DIR/<metric>.png (lines or heatmaps, the paper's operating point marked; the
idiotypic difference rate's 20 % contour drawn). Sweepable: jaxais.experiments.sweep.PARAMETERS.
The same arguments give the same numbers.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

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


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(prog="sweep.py", description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--grid",
        action="append",
        required=True,
        metavar="NAME=START:STOP:COUNT",
        help="an axis of the grid (repeat for more axes), e.g. k1=0:2:11 or hold=1,10,31",
    )
    p.add_argument("--system", default="SIE", choices=SYSTEMS)
    p.add_argument("--random-set", choices=tuple(RANDOM_SETS), default=None)
    p.add_argument(
        "--world", default=protocol.WORLDS[0], help=f"{', '.join(protocol.WORLDS)} or a .toml path"
    )
    p.add_argument("--trials", type=int, default=protocol.SIMULATED_TRIALS, help="per point")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--seeds", default=None, help="LTL seed directory (default: the shipped one)")
    protocol.add_cap_arguments(p)
    p.add_argument("--slots", type=int, default=1024, help="runs live at once (default 1024)")
    p.add_argument("--out", required=True, help="output directory (created if missing)")
    return p.parse_args(argv)  # fmt: skip


@main_wrapper("sweep.py")
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    if not 0 <= args.seed < 2**32:
        raise UserError(f"--seed must be in [0, 2**32), got {args.seed}")
    if args.trials < 1:
        raise UserError(f"--trials must be >= 1, got {args.trials}")
    if args.slots < 1:
        raise UserError(f"--slots must be >= 1, got {args.slots}")
    if args.random_set and args.system not in ("UIE", "URL"):
        raise UserError(f"--random-set applies to UIE and URL only, not {args.system}")
    from jaxais.experiments.sweep import parse_axis

    axes = [parse_axis(spec) for spec in args.grid]
    names = [name for name, _ in axes]
    if len(set(names)) < len(names):
        raise UserError(f"--grid names a parameter twice: {', '.join(names)}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    check_writable_dir(out)

    from tqdm import tqdm

    from jaxais import envs
    from jaxais.episode import EpisodeConfig
    from jaxais.experiments.records import build_systems, portable_command, run_config
    from jaxais.experiments.sweep import (
        PAPER_POINT,
        grid_points,
        interpolate,
        point_systems,
        run_sweep,
    )
    from jaxais.experiments.sweep_plots import save_sweep_figures
    from jaxais.immune.network import NetworkParams

    name = label(args.system, args.random_set or "R1")
    world = envs.load_world(args.world)
    config = EpisodeConfig(tau_cap=args.tau_cap, collision_cap=args.collision_cap)
    network = NetworkParams()
    systems, seed_info = build_systems([name], args.seeds, network)
    params = envs.default_params()
    points = grid_points(axes)
    point_systems(systems[name], points)  # every value in range, before the run starts
    runs = args.trials * len(points)
    start = time.perf_counter()
    with tqdm(total=runs, desc=f"{name} in {world.name}", unit="run", file=sys.stderr) as bar:
        doc = run_sweep(
            world, systems[name], name, axes, args.trials, args.seed, config, params,
            args.slots, bar.update,
        )  # fmt: skip
    doc["wall_s_total"] = time.perf_counter() - start
    doc["system"], doc["world"], doc["seed"], doc["trials"] = (
        name,
        world.name,
        args.seed,
        args.trials,
    )
    doc["paper_point"] = {
        "values": PAPER_POINT,
        "idiotypic_difference_rate": interpolate(doc, "idiotypic_difference_rate", PAPER_POINT),
    }
    cfg = run_config(world, args.world, config, network, params, seed_info)
    cfg["command"] = portable_command(
        "sweep.py " + " ".join(sys.argv[1:] if argv is None else argv)
    )
    doc["config"] = cfg
    atomic_write_json(out / "sweep.json", doc)
    figures = save_sweep_figures(doc, out)
    print(
        f"{name} in {world.name}: {doc['runs']} runs in {doc['wall_s_total']:.0f} s "
        f"({doc['runs_per_s']:.1f} runs/s, {doc['robot_iterations_per_s'] / 1e6:.2f} M useful "
        f"robot-iterations/s, compile included); wrote {out / 'sweep.json'}"
        + (f" and {len(figures)} figures" if figures else "")
    )


if __name__ == "__main__":
    run_script(main)
