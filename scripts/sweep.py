"""Sweep the STL's (or a --contender's) parameters (--grid) or the world's noise (--noise).

    python scripts/sweep.py --grid k1=0:2:11 --grid k2=0:2:11 --system SIE --out sweep/
    python scripts/sweep.py --noise 0,0.5,1,2,4 --system SIE,SRL,HDC --world real --out gap/
    python scripts/sweep.py --grid speed=300:700:5 --contender mine.py:braitenberg --out bv/

Writes DIR/sweep.json and sweep.png or DIR/reality_gap.json and .png (docs/formats.md): means and
95 % CIs; the same on one process or several; --resume finishes an interrupted run.
"""

from __future__ import annotations

from jaxais import distributed
from jaxais.cli import ArgumentParser, main_wrapper, remake_command, run_script
from jaxais.experiments import contenders, protocol
from jaxais.labels import RANDOM_SETS, SYSTEMS


def parse_args(argv: list[str] | None):
    p = ArgumentParser(prog="sweep.py", description=__doc__.split("\n\n")[0])
    what = p.add_mutually_exclusive_group(required=True)
    # fmt: off
    what.add_argument("--grid", action="append", metavar="NAME=START:STOP:COUNT",
                      help="an axis (repeat for more), e.g. k1=0:2:11 or hold=1,10,31")
    what.add_argument("--noise", metavar="S1,S2,...", help="scales of the world's noise (1 = its "
                      "own levels), e.g. 0,0.5,1,2")
    p.add_argument("--noise-kinds", help="which noise --noise scales (default: ir,camera,wheel)")
    p.add_argument("--system", help=f"one (--grid; default SIE) or more (--noise; default "
                   f"SIE,SRL,HDC) of {', '.join(SYSTEMS)}")
    contenders.add_argument(p, repeatable=False)  # instead of --system: --grid over its params
    p.add_argument("--random-set", choices=tuple(RANDOM_SETS))
    p.add_argument("--world", help="a world's name or .toml path (default: world1 with --grid, "
                   f"{protocol.REAL_WORLD} with --noise)")
    p.add_argument("--trials", type=int, help="trials per point (default: the paper's count)")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
    p.add_argument("--seeds", help="LTL seed directory (default: the shipped one)")
    protocol.add_cap_arguments(p)
    protocol.add_world_scale_argument(p)
    p.add_argument("--slots", type=int, default=1024, help="runs live at once (default 1024)")
    p.add_argument("--records", action="store_true", help="keep every run's record (--grid)")
    p.add_argument("--out", required=True, help="output directory (missing or empty)")
    p.add_argument("--resume", action="store_true", help="finish the interrupted run in --out")
    distributed.add_arguments(p)
    return p.parse_args(argv)  # fmt: on


@main_wrapper("sweep.py")
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    distributed.check(args)
    from jaxais import _speed  # its importlib.metadata: after the signal handlers are ours

    _speed.setup()  # the XLA flags and compilation cache of every script (docs/performance.md)
    distributed.initialize(args)  # before JAX computes anything
    import jax

    from jaxais.experiments.sweeps import sweep

    command = remake_command("sweep.py", argv)
    doc = sweep(
        args.out, grid=args.grid, noise=args.noise, noise_kinds=args.noise_kinds,
        system=args.system, random_set=args.random_set, world=args.world, trials=args.trials,
        seed=args.seed, seeds=args.seeds, tau_cap=args.tau_cap, collision_cap=args.collision_cap,
        slots=args.slots, command=command, resume=args.resume, records=args.records,
        contender=args.contender, world_scale=args.world_scale,
    )  # fmt: skip
    if jax.process_index() != 0:  # process 0 reports
        return
    its = doc.get("robot_iterations_per_s", 0) / 1e6
    what, name = f"{doc.get('runs')} runs ({its:.2f} M robot-iterations/s)", "sweep.json"
    if not args.grid:
        what, name = f"{len(doc['scales'])} levels x {doc['trials']} trials", "reality_gap.json"
    print(f"{doc['system']} in {doc['world']}: {what} in {doc['wall_s_total']:.0f} s, compile "
          f"included; wrote {name} and its figure in {args.out}")  # fmt: skip


if __name__ == "__main__":
    run_script(main)
