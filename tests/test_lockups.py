"""Lock-ups (jaxais.loop): a robot is locked while it is trapped and its controller's choices
have not changed over the whole stay.

A tiny controller drives forward until it touches an obstacle and then parks against it; its
``choices`` stay fixed, change every ``period`` iterations, or first appear after ``first_at``
iterations (a first choice is no change). One compiled program per controller runs all cases.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxais.controllers import Controller
from jaxais.immune.antigens import COLLISION_THRESHOLD
from jaxais.loop import EpisodeConfig
from jaxais.trials import TrialsConfig, make_trials

CONFIG = EpisodeConfig(tau_cap=60.0, collision_cap=1000, finish_pixels=10_000)
"""60 s runs that only the time cap ends (no finish: more goal pixels than a camera has)."""
N = 4
SPEED = 600.0


def _controller(with_choices: bool) -> Controller:
    """Forward at SPEED until the IR reads a collision, then parked. Params: (period, first_at)
    [int32], carried in the state for ``choices(state)``: the choice flips every ``period``
    iterations (0: never) and is -1 (none yet) before ``first_at``."""

    def init(key, params):
        del key
        return (jnp.int32(0), jnp.bool_(False), params)

    def learn(key, state, pc, params):
        del key, pc, params
        return state

    def act(key, state, pc, params):
        del key, params
        t, parked, p = state
        parked = parked | (pc.v >= COLLISION_THRESHOLD)
        wheels = jnp.where(parked, 0.0, SPEED) * jnp.ones(2)
        return (t + 1, parked, p), wheels

    def choices(state):
        t, _, (period, first_at) = state
        flip = jnp.where(period > 0, (t // jnp.maximum(period, 1)) % 2, 0)
        return jnp.where(t < first_at, -1, flip)[None].astype(jnp.int32)

    return Controller(init, learn, act, choices=choices if with_choices else None)


WITH_CHOICES, WITHOUT_CHOICES = _controller(True), _controller(False)


@functools.cache
def run(with_choices: bool):
    controller = WITH_CHOICES if with_choices else WITHOUT_CHOICES
    config = TrialsConfig(
        world="world1", n_trials=N, label="PARK", controller=controller, episode=CONFIG
    )
    return make_trials(config)


@functools.cache
def outcome(period: int, first_at: int, with_choices: bool = True) -> dict[str, np.ndarray]:
    params = (jnp.int32(period), jnp.int32(first_at))
    return jax.device_get(run(with_choices)(jax.random.key(3), params))


@pytest.mark.slow
def test_a_robot_parked_against_a_wall_is_trapped_and_locked():
    out = outcome(period=0, first_at=0)
    assert np.all(out["tau"] == CONFIG.tau_cap)
    # It reaches the wall within the run and stays: most of the run is trapped time.
    assert np.all(out["trapped_s"] > 20.0), out["trapped_s"]
    # Its choice never changes: every trapped second is a locked one.
    np.testing.assert_array_equal(out["locked_s"], out["trapped_s"])


def test_a_first_choice_is_no_change():
    # The choice is -1 (none yet) for the first 5 s, then fixed: still locked all along.
    out = outcome(period=0, first_at=156)
    np.testing.assert_array_equal(out["locked_s"], outcome(0, 0)["trapped_s"])


@pytest.mark.parametrize("period", [31, 200])
def test_changing_choices_are_not_a_lock_up(period):
    # A choice that changes more often than the 10 s window never locks; the robot is as
    # trapped as before (its path does not depend on its choices).
    out = outcome(period=period, first_at=0)
    np.testing.assert_array_equal(out["trapped_s"], outcome(0, 0)["trapped_s"])
    np.testing.assert_array_equal(out["locked_s"], np.zeros(N))


def test_a_choice_held_longer_than_the_window_locks_part_of_the_stay():
    # Flipping every 20 s (625 iterations): each 20 s stretch that lies in the stay counts
    # from its 10 s mark, so some but not all of the trapped time is locked.
    out = outcome(period=625, first_at=0)
    assert np.all(out["locked_s"] > 0) and np.all(out["locked_s"] < out["trapped_s"])


@pytest.mark.slow
def test_a_controller_without_choices_is_never_locked():
    out = outcome(period=0, first_at=0, with_choices=False)
    np.testing.assert_array_equal(out["trapped_s"], outcome(0, 0)["trapped_s"])
    np.testing.assert_array_equal(out["locked_s"], np.zeros(N))
