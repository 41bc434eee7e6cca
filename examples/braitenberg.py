"""A Braitenberg-style vehicle as a contender: your controller beside the paper's systems.

This file is all a new controller takes; nothing in jaxais changes. It defines a controller
(pure functions of one robot, :class:`jaxais.controllers.Controller`) over the perception
helpers of :mod:`jaxais.perception`, and ``braitenberg()`` returning ``(controller, params)``,
so every experiment takes it by spec:

    python scripts/reproduce.py --out results --contender examples/braitenberg.py:braitenberg
    python scripts/trials.py --contender BV=examples/braitenberg.py:braitenberg --out bv.json
    python scripts/sweep.py --out sweep_bv --contender examples/braitenberg.py:braitenberg \
        --grid speed=300:700:3

or from Python, ``x.reproduce("results", contenders={"BV": braitenberg()})``. Run this file
(``--tiny``: a few short trials, as CI does) to see it drive.
"""

from __future__ import annotations

import argparse

import jax.numpy as jnp

from jaxais import perception
from jaxais.controllers import Controller, no_learning, no_state

# Each side's sensors weighted by how far forward they look (ps0..ps7; the rear ones not at all).
_FRONT = jnp.array([1.0, 0.8, 0.4, 0.0, 0.0, 0.4, 0.8, 1.0])
_RIGHT = perception.SENSOR_SIDE == perception.RIGHT
_LEFT = perception.SENSOR_SIDE == perception.LEFT


def act(key, state, pc, params):
    """Crossed excitation (Braitenberg's vehicle 3b): each side's proximity slows the other
    wheel less than its own, so the robot veers away; with nothing near it steers toward the
    blue centroid. ``params``: {"speed", "avoid", "steer"} float32 scalars."""
    del key
    p = perception.proximity(pc.ir) * _FRONT
    right, left = jnp.max(jnp.where(_RIGHT, p, 0.0)), jnp.max(jnp.where(_LEFT, p, 0.0))
    toward = perception.centroid_offset(pc.centroid, pc.blue_pixels)  # + the blue is right
    free = 1.0 - jnp.maximum(left, right)
    turn = params["avoid"] * (left - right) + free * params["steer"] * toward  # + turns right
    forward = params["speed"] * (free - 0.5 * jnp.maximum(left, right))  # backs off when close
    wheels = jnp.stack([forward + params["speed"] * turn, forward - params["speed"] * turn])
    return state, perception.clip_wheels(wheels)


# Built once: compiled programs are cached by the controller's identity.
CONTROLLER = Controller(init=no_state, learn=no_learning, act=act)


def braitenberg(speed: float = 500.0, avoid: float = 1.2, steer: float = 0.6):
    """A Braitenberg-style vehicle (crossed excitation; steers to the blue when clear).

    Returns the contender ``(controller, params)``, the gains as float32 leaves (a sweep's
    axes by name: ``speed``, ``avoid``, ``steer``)."""
    gains = {"speed": speed, "avoid": avoid, "steer": steer}
    return CONTROLLER, {k: jnp.float32(v) for k, v in gains.items()}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--tiny", action="store_true", help="4 trials capped at 60 s (CI)")
    args = p.parse_args()
    import jaxais.experiments as x

    n, cap = (4, 60.0) if args.tiny else (30, None)
    doc = x.trials(braitenberg(), label="BV", trials=n, tau_cap=cap, progress=False)
    s = doc["summary"]
    print(f"BV in world1: {s['n']} trials, mean tau {s['tau']:.0f} s, c {s['collisions']:.1f}")


if __name__ == "__main__":
    main()
