"""The controller protocol: any controller runs in the task loop, and an experiment is one pure
function, ``make_trials(config) -> run(key, params)``, that ``vmap`` batches over seeds and
parameter grids.

Every program runs world1 with :data:`_stl_fixtures.CONFIG`'s short caps and two trials, so the
few programs compile once per session.
"""

from __future__ import annotations

import functools

import _stl_fixtures as F
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxais.controllers import BRAITENBERG, braitenberg_params
from jaxais.trials import TrialsConfig, make_trials, run_trials, summarise

N = 2
KEYS = ("tau", "collisions", "fitness", "trapped_s", "iterations")


def stl_run():
    return F.sie_trials(N)


@functools.cache
def braitenberg_run():
    config = TrialsConfig(
        world=F.WORLD, n_trials=N, label="BV", controller=BRAITENBERG, episode=F.CONFIG
    )
    return make_trials(config)


@functools.cache
def records(label: str, seed: int):
    """run_trials' records of ``label``'s trials (the STL's SIE, or the vehicle "BV")."""
    if label == "BV":
        systems, controller = {"BV": braitenberg_params()}, BRAITENBERG
    else:
        systems, controller = {label: F.systems()[label]}, None
    res = run_trials(F.world(), systems, N, seed, F.CONFIG, F.sim_params(), controller=controller)
    return res[label].records


def as_records(out: dict) -> list[dict]:
    out = jax.device_get(out)
    return [{k: out[k][i].item() for k in out} for i in range(N)]


def assert_same_trials(got: list[dict], want: list[dict]) -> None:
    for g, w in zip(got, want, strict=True):
        for k in KEYS:
            assert g[k] == pytest.approx(w[k], rel=1e-6), k


@pytest.mark.slow
def test_make_trials_gives_run_trials_trials():
    sie = F.systems()["SIE"]
    got = as_records(stl_run()(jax.random.key(0), sie))
    assert_same_trials(got, records("SIE", 0))
    for g, w in zip(got, records("SIE", 0), strict=True):
        assert g["idiotypic_difference_rate"] == pytest.approx(w["idiotypic_difference_rate"])
        assert g["replaced"] == w["replaced"]


@pytest.mark.slow
def test_vmap_over_seeds_and_a_parameter_grid_equals_a_loop():
    sie = F.systems()["SIE"]
    # A two-point grid of eq (7)'s k1. Each point is typed as SIE's own params (k1 a Python
    # float), so the loop reuses test_make_trials_gives_run_trials_trials' program.
    points = [sie.replace(network=sie.network.replace(k1=k1)) for k1 in (0.5, 1.5)]
    grid = jax.tree.map(lambda *a: jnp.stack(a), *points)
    keys = jax.random.split(jax.random.key(7), 2)
    batched = jax.jit(jax.vmap(stl_run(), in_axes=(0, 0)))(keys, grid)
    for i in range(2):
        point = jax.tree.map(lambda a, i=i: a[i], grid)
        one = stl_run()(keys[i], point)
        for k in one:
            np.testing.assert_array_equal(np.asarray(batched[k][i]), np.asarray(one[k]), k)


@pytest.mark.slow
def test_a_new_controller_plugs_into_the_loop_unchanged():
    # The Braitenberg vehicle is not an immune network: no antibodies, no state, no stats.
    got = as_records(braitenberg_run()(jax.random.key(3), braitenberg_params()))
    want = records("BV", 3)
    assert_same_trials(got, want)
    assert all(set(r) & {"idiotypic_difference_rate", "replaced"} == set() for r in want)
    assert all(r["iterations"] > 0 for r in want)
    assert summarise(want)["idiotypic_difference_rate"] is None  # no such rate: none reported


def test_run_trials_takes_any_label_with_a_controller_but_checks_the_stls():
    with pytest.raises(ValueError, match="unknown system label 'BV'"):
        run_trials(F.world(), {"BV": F.systems()["SIE"]}, N, 0, F.CONFIG, F.sim_params())


def test_trials_config_rejects_bad_counts():
    for bad in (0, -3, 2.5, True):
        with pytest.raises(ValueError, match="n_trials"):
            TrialsConfig(n_trials=bad)


# ------------------------------------------------------------------------ the vehicle's rules


@functools.cache
def vehicle_act():
    return jax.jit(BRAITENBERG.act)


def wheels(ir=None, blue_pixels=0, centroid=7.0) -> np.ndarray:
    pc = F.percept(
        0, ir=[0.0] * 8 if ir is None else ir, blue_pixels=blue_pixels, centroid=centroid
    )
    _, w = vehicle_act()(jax.random.key(0), jnp.int32(0), pc, braitenberg_params())
    return np.asarray(w)


def test_vehicle_cruises_straight_when_nothing_is_seen():
    np.testing.assert_allclose(wheels(), [500.0, 500.0])


@pytest.mark.parametrize(
    ("sensor", "turns"), [(7, "right"), (6, "right"), (0, "left"), (1, "left")]
)
def test_vehicle_turns_away_from_the_nearer_wall_and_slows(sensor, turns):
    ir = [0.0] * 8
    ir[sensor] = 400.0  # about 2 cm (envs.params.IR_TABLE_VALUE)
    left, right = wheels(ir)
    assert (left > right) == (turns == "right")
    assert (left + right) / 2 < 500.0


def test_vehicle_turns_toward_the_blue():
    left, right = wheels(blue_pixels=6, centroid=2.0)  # blue on the left of the image
    assert right > left
    left, right = wheels(blue_pixels=6, centroid=12.0)
    assert left > right


def test_vehicle_backs_off_a_wall_ahead_by_turning_not_by_stopping():
    left, right = wheels([4095.0, 0, 0, 0, 0, 0, 0, 4095.0])  # touching dead ahead
    assert left == -right and abs(left) == 500.0


def test_vehicle_params_are_traced_data():
    # Another speed is data, not a new program: the jitted act does not retrace.
    act = vehicle_act()
    before = act._cache_size()
    pc = F.percept(0, ir=[0.0] * 8)
    _, w = act(jax.random.key(0), jnp.int32(0), pc, braitenberg_params(speed=300.0))
    assert act._cache_size() == before
    np.testing.assert_allclose(np.asarray(w), [300.0, 300.0])


def _vehicle_as_first_written(pc, params):
    """The vehicle's act with its perception inline, as before jaxais.perception existed."""
    weights = np.array([1.0, 0.7, 0.3, 0.0, 0.0, 0.3, 0.7, 1.0], np.float32)
    right_side = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0], np.float32)
    p = jnp.clip((pc.ir - 100.0) / 500.0, 0.0, 1.0) * weights
    right, left = jnp.max(p * right_side), jnp.max(p * (1.0 - right_side))
    near = jnp.maximum(left, right)
    away = jnp.where(left >= right, 1.0, -1.0)
    toward = jnp.where(pc.blue_pixels > 0, (pc.centroid - 7.0) / 7.0, 0.0)
    turn = params.avoid * near * away + (1.0 - near) * params.steer * toward
    forward = params.speed * (1.0 - near)
    wheels = jnp.stack([forward + params.speed * turn, forward - params.speed * turn])
    return jnp.clip(wheels, -1000.0, 1000.0)


def test_vehicle_on_perception_helpers_is_bit_for_bit_the_inline_one():
    # Readings around each threshold of the proximity ramp and the centroid's range, one batch.
    rng = np.random.default_rng(0)
    n = 512
    levels = np.array([0.0, 99.0, 100.0, 101.0, 350.0, 599.0, 600.0, 601.0, 4095.0])
    ir = rng.choice(levels, (n, 8)) * rng.choice([1.0, rng.uniform(0.5, 1.5)], (n, 8))
    pc = jax.vmap(lambda i, b, c: F.percept(0, ir=i, blue_pixels=b, centroid=c))(
        jnp.asarray(ir, jnp.float32),
        jnp.asarray(rng.integers(0, 3, n), jnp.int32),
        jnp.asarray(rng.uniform(0.0, 14.0, n), jnp.float32),
    )
    params = braitenberg_params(speed=900.0, avoid=1.7, steer=1.3)  # some wheels clip
    both = jax.jit(
        jax.vmap(
            lambda pc: (BRAITENBERG.act(jax.random.key(0), 0, pc, params)[1],
                        _vehicle_as_first_written(pc, params))
        )
    )  # fmt: skip
    got, want = both(pc)
    np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
    assert np.any(np.abs(np.asarray(got)) == 1000.0)
