"""Draw a world and a few robots' trajectories under a built-in demo controller.

    python scripts/render.py --world world1 --steps 3000 --out world1.png \\
        [--robots 3] [--seed 0] [--gif world1.gif] [--every 10] [--fps 25]

Loads the world (a built-in name or a path to a .toml world file), resets ``--robots`` robots
with keys split from ``--seed``, drives them all for ``--steps`` iterations with a
Braitenberg-style controller (avoid obstacles on the IR readings, steer towards blue pixels) in
one jitted ``lax.scan`` over a ``vmap``-ped step, and writes a PNG of the world with every
trajectory (and with ``--gif`` an animation of every ``--every``-th iteration). Outputs are
written atomically. User errors end with one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from jaxais.cli import ArgumentParser, UserError, check_output_file, main_wrapper, run_script

PROG = "render.py"
FIGURE_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg")

# Demo controller constants (speed units; IR readings are 0..4095, ~120 at 5 cm from the rim).
CRUISE = 500.0
"""Forward wheel speed with nothing nearby."""
AVOID_GAIN = 0.6
"""Turn (speed units) per unit of left/right IR imbalance."""
AVOID_MAX_TURN = 600.0
BLOCKED_IR = 800.0
"""A front reading at which forward motion stops (the robot turns on the spot)."""
TRACK_GAIN = 60.0
"""Turn per column of blue-centroid offset from the image centre."""
TRACK_QUIET_IR = 200.0
"""Blue is tracked only while no front reading exceeds this (obstacles come first)."""
MAX_GIF_FRAMES = 1000
"""Pillow holds every frame in memory (0.6 MB each) until the GIF is written."""


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
    p.add_argument("--every", type=int, default=10, help="GIF frame every N iterations")
    p.add_argument("--fps", type=float, default=25.0, help="GIF frames per second")
    return p.parse_args(argv)


def check_args(args: argparse.Namespace) -> None:
    """Reject bad values before JAX is even imported."""
    for name in ("steps", "robots", "every"):
        value = getattr(args, name)
        if value <= 0:
            raise UserError(f"--{name} must be a positive integer, got {value}")
    if not 0 <= args.seed < 2**32:  # larger seeds are silently truncated by jax.random.key
        raise UserError(f"--seed must be in [0, 2**32), got {args.seed}")
    if not args.fps > 0:
        raise UserError(f"--fps must be positive, got {args.fps}")
    check_output_file(args.out, FIGURE_SUFFIXES)
    if args.gif is not None:
        check_output_file(args.gif, (".gif",))
        frames = args.steps // args.every + 1
        if frames > MAX_GIF_FRAMES:
            raise UserError(
                f"--gif would have {frames} frames (at most {MAX_GIF_FRAMES}): raise --every"
            )
        if Path(args.gif).resolve() == Path(args.out).resolve():
            raise UserError("--gif and --out name the same file")


def demo_wheels(obs):
    """Braitenberg-style wheel speeds [2] (left, right) from one robot's ``Observation``.

    Obstacles: the right-side sensors (ps0..ps2) turn the robot left and the left-side ones
    (ps5..ps7) turn it right, harder the closer they are; a blocked front stops forward motion
    (the robot then spins left). With the front clear, it turns towards the centroid of the
    blue pixels (column 7 is straight ahead, 0 the leftmost).

    Args:
        obs: one robot's observation (``ir`` [8], ``blue_pixels``, ``blue_centroid``).

    Returns:
        [2] wheel speeds, speed units.
    """
    import jax.numpy as jnp

    ir = obs.ir
    right = 1.0 * ir[0] + 0.7 * ir[1] + 0.3 * ir[2]
    left = 1.0 * ir[7] + 0.7 * ir[6] + 0.3 * ir[5]
    front = jnp.maximum(jnp.maximum(ir[0], ir[7]), 0.7 * jnp.maximum(ir[1], ir[6]))
    turn = jnp.clip(AVOID_GAIN * (right - left), -AVOID_MAX_TURN, AVOID_MAX_TURN)
    # Head-on (both sides equal) the imbalance vanishes: always break the tie to the left.
    turn = turn + jnp.where(front > BLOCKED_IR, 0.5 * AVOID_MAX_TURN, 0.0)
    see_blue = (obs.blue_pixels > 0) & (front < TRACK_QUIET_IR)
    turn = turn + jnp.where(see_blue, TRACK_GAIN * (7.0 - obs.blue_centroid), 0.0)
    forward = CRUISE * jnp.clip(1.0 - front / BLOCKED_IR, -0.2, 1.0)
    return jnp.stack([forward - turn, forward + turn])


def make_run(world, params, n_robots: int, n_steps: int):
    """The demo run: ``run(key) -> (states after reset, poses, wanderers)``.

    Args:
        world, params: the world and the robot constants.
        n_robots: R, robots (each in its own copy of the world).
        n_steps: T, iterations.

    Returns:
        ``run(key)`` giving the batched ``State`` after reset, robot poses [T+1, R, 3] and
        wanderer poses [T+1, R, W, 3] (row 0: after reset).

    Two compiled programs: the vmapped reset, then the first observation and the whole
    ``lax.scan`` of ``n_steps`` vmapped steps. (Compiled as one program they take XLA about
    half as long again to compile as the two apart, for the same run time.)
    """
    import jax
    import jax.numpy as jnp

    from jaxais import envs

    v_step = jax.vmap(envs.step, in_axes=(0, 0, 0, None, None))
    v_reset = jax.jit(jax.vmap(envs.reset, in_axes=(0, None, None)))
    v_observe = jax.vmap(envs.observe, in_axes=(0, 0, None, None))
    v_wheels = jax.vmap(demo_wheels)

    @jax.jit
    def rollout(key, state0, world, params):
        k_obs, k_steps = jax.random.split(key)
        obs0 = v_observe(jax.random.split(k_obs, n_robots), state0, world, params)

        def body(carry, k):
            state, obs = carry
            state, obs = v_step(jax.random.split(k, n_robots), state, v_wheels(obs), world, params)
            return (state, obs), (state.pose, state.wanderers)

        _, (poses, wanderers) = jax.lax.scan(
            body, (state0, obs0), jax.random.split(k_steps, n_steps)
        )
        poses = jnp.concatenate([state0.pose[None], poses])
        wanderers = jnp.concatenate([state0.wanderers[None], wanderers])
        return poses, wanderers

    def run(key):
        k_reset, k_run = jax.random.split(key)
        state0 = v_reset(jax.random.split(k_reset, n_robots), world, params)
        return (state0, *rollout(k_run, state0, world, params))

    return run


@main_wrapper(PROG)
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    check_args(args)

    import jax
    import numpy as np

    from jaxais import _speed, envs
    from jaxais.experiments import plotting

    _speed.setup()
    world = envs.load_world(args.world)
    params = envs.default_params()
    run = make_run(world, params, args.robots, args.steps)
    state0, poses, wanderers = jax.device_get(run(jax.random.key(args.seed)))
    poses, wanderers = np.asarray(poses), np.asarray(wanderers)

    dt = float(params.dt)
    title = f"{world.name}: {args.robots} robot(s) x {args.steps} steps ({args.steps * dt:.0f} s)"
    fig = plotting.world_figure(
        world, states=state0, trajectories=np.swapaxes(poses, 0, 1), title=title
    )
    plotting.save_figure(fig, args.out)
    written = f"wrote {args.out} ({args.robots} robot(s) x {args.steps} steps on {world.name})"
    if args.gif is not None:
        frames = plotting.animate(
            world,
            poses[:: args.every],
            wanderers[:: args.every],
            args.gif,
            fps=args.fps,
            state=jax.tree.map(lambda x: np.asarray(x)[0], state0),
            dt=dt * args.every,
        )
        written += f" and {args.gif} ({frames} frames)"
    print(f"{PROG}: {written}")


if __name__ == "__main__":
    run_script(main)
