"""A world and a few robots' trajectories under a Braitenberg-style demo controller, drawn: one
jitted ``lax.scan`` over a vmapped step, then a figure (and optionally a GIF)."""

from __future__ import annotations

import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxais import envs
from jaxais.experiments import plotting, protocol
from jaxais.experiments.one_system import check_types
from jaxais.io import check_memory, check_number, check_output_file, check_path

# Demo controller constants (speed units; IR readings are 0..4095, ~120 at 5 cm from the rim).
CRUISE = 500.0  # forward speed with nothing nearby
AVOID_GAIN = 0.6  # turn per unit of left/right IR imbalance
AVOID_MAX_TURN = 600.0
BLOCKED_IR = 800.0  # a front reading that stops forward motion (the robot turns on the spot)
TRACK_GAIN = 60.0  # turn per column of blue-centroid offset
TRACK_QUIET_IR = 200.0  # blue is tracked only below this front reading (obstacles come first)
FIGURE_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg")  # the figures render draws
MAX_GIF_FRAMES = 1000  # Pillow holds every frame (0.6 MB each) until the GIF is written


def demo_wheels(obs: envs.Observation) -> jnp.ndarray:
    """Wheel speeds [2] from one robot's observation: away from the nearer side's IR (a blocked
    front spins it left), else towards the blue centroid (column 7 is straight ahead)."""
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


def make_run(world: envs.World, params: envs.SimParams, n_robots: int, n_steps: int):
    """``run(key) -> (states after reset, poses [T+1, R, 3], wanderers [T+1, R, W, 3])``; reset
    and scan compile apart (as one program XLA takes half as long again)."""
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


def render(
    out: str | os.PathLike[str],
    *,
    world: str = "world1",
    steps: int = 3000,
    robots: int = 3,
    seed: int = 0,
    gif: str | os.PathLike[str] | None = None,
    every: int = 10,
    fps: float = 25.0,
) -> tuple[str, int | None]:
    """Draw ``robots`` demo runs of ``steps`` iterations in ``world`` into the figure ``out`` (and
    ``gif``, every ``every``-th iteration); returns (world name, GIF frames or None). One-line
    ValueError on a bad argument (types first, then ranges, then the memory the poses need),
    before anything runs."""
    check_path(out, "--out", f"a figure's path ({', '.join(FIGURE_SUFFIXES)})")
    check_types(world=world, steps=steps, robots=robots, seed=seed, gif=gif, every=every)
    check_number(fps, "--fps")
    for name, value in (("steps", steps), ("robots", robots), ("every", every)):
        if value <= 0:
            raise ValueError(f"--{name} must be a positive integer, got {value}")
    protocol.check_seed(seed)
    if not fps > 0:
        raise ValueError(f"--fps must be positive, got {fps}")
    check_output_file(out, FIGURE_SUFFIXES)
    if gif is not None:
        check_output_file(gif, (".gif",))
        if steps // every + 1 > MAX_GIF_FRAMES:
            raise ValueError(
                f"--gif would have {steps // every + 1} frames (at most {MAX_GIF_FRAMES}): "
                "raise --every"
            )
        if Path(gif).resolve() == Path(out).resolve():
            raise ValueError("--gif and --out name the same file")
    w = envs.load_world(world)
    # Every pose of every robot and wanderer is kept (3 float32), on the device and the host,
    # and copied: 48 bytes each.
    check_memory(robots * (steps + 1), 48 * (1 + w.n_wanderers), "--robots x --steps")
    params = envs.default_params()
    state0, poses, wanderers = jax.device_get(
        make_run(w, params, robots, steps)(jax.random.key(seed))
    )
    dt = float(params.dt)
    title = f"{w.name}: {robots} robot(s) x {steps} steps ({steps * dt:.0f} s)"
    fig = plotting.world_figure(
        w, states=state0, trajectories=np.swapaxes(poses, 0, 1), title=title
    )
    plotting.save_figure(fig, out)
    if gif is None:
        return w.name, None
    frames = plotting.animate(
        w, poses[::every], wanderers[::every], gif, fps=fps, state=state0, dt=dt * every
    )
    return w.name, frames
