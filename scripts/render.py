"""Draw a world and a few robots' trajectories under a built-in demo controller.

    python scripts/render.py --world world1 --steps 3000 --out world1.png \\
        [--robots 3] [--seed 0] [--gif world1.gif] [--every 10] [--fps 25]

Robots reset with keys split from --seed run a Braitenberg-style controller (avoid obstacles on
the IR readings, steer towards blue pixels); the PNG shows every trajectory and --gif animates
every --every-th iteration (jaxais.experiments.demo.render).
"""

from __future__ import annotations

import argparse

from jaxais.cli import ArgumentParser, UserError, check_output_file, main_wrapper, run_script
from jaxais.io import check_memory

PROG = "render.py"
FIGURE_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg")


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(
        prog=PROG,
        description="Render a world and demo-controller trajectories to a PNG (and a GIF).",
    )
    p.add_argument("--world", default="world1", help="built-in world name or .toml path")
    p.add_argument("--steps", type=int, default=3000, help="iterations per robot (32 ms each)")
    p.add_argument("--out", required=True, help="output figure (.png, .pdf, .svg, .jpg)")
    p.add_argument("--robots", type=int, default=3, help="number of robots (separate runs)")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed")
    p.add_argument("--gif", default=None, help="also write an animation to this .gif")
    gif = dict(default=argparse.SUPPRESS)  # given without --gif, refused
    p.add_argument("--every", type=int, help="GIF frame every N iterations (10)", **gif)
    p.add_argument("--fps", type=float, help="GIF frames per second (25)", **gif)
    return p.parse_args(argv)


@main_wrapper(PROG)
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    check_output_file(args.out, FIGURE_SUFFIXES)
    animation = {k: v for k, v in vars(args).items() if k in ("every", "fps")}
    if args.gif is not None:
        check_output_file(args.gif, (".gif",))
    elif animation:
        raise UserError(f"--{next(iter(animation))} applies to --gif only")
    # Every robot's every pose is kept (3 float32), on the host and the device, and copied.
    check_memory(args.robots * args.steps, 48, "--robots x --steps")
    from jaxais import _speed

    _speed.setup()
    from jaxais.experiments.demo import render

    world, frames = render(
        args.out, world=args.world, steps=args.steps, robots=args.robots, seed=args.seed,
        gif=args.gif, **animation,
    )  # fmt: skip
    written = f"wrote {args.out} ({args.robots} robot(s) x {args.steps} steps on {world})"
    if frames is not None:
        written += f" and {args.gif} ({frames} frames)"
    print(f"{PROG}: {written}")


if __name__ == "__main__":
    run_script(main)
