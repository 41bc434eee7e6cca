"""Shared, compiled-once pieces for the STL, trial and script tests.

Compiling a program that holds the simulator and the controller costs tens of seconds on a small
CPU, so every test of these files uses the same world, batch size, episode config and systems,
and gets its jitted functions from the cached builders below (one compilation per session).
"""

from __future__ import annotations

import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxais import envs
from jaxais.controllers import STL, Bout, Percept, STLState, System
from jaxais.immune.antibodies import sample_antibodies
from jaxais.immune.network import NetworkParams
from jaxais.immune.readings import LITERAL, Readings
from jaxais.immune.reinforcement import PenaltyCounters
from jaxais.loop import EpisodeConfig, draws, iterate, start
from jaxais.seed import Seed, save_seed
from jaxais.systems import make_system

WORLD = "world1"
BATCH = 4
"""Runs per batched program (every batched test uses exactly this many)."""
CONFIG = EpisodeConfig(
    tau_cap=20.0,
    collision_cap=5,
    stop_at_collision_cap=True,
    chunk=25,
    segment=500,
    record=True,
)
"""Short caps: 625 iterations at most, stopped at 5 collisions (the GA's option, so both caps
are met in short runs)."""
X, Y = 5, 8


@functools.cache
def world() -> envs.World:
    return envs.load_world(WORLD)


@functools.cache
def sim_params() -> envs.SimParams:
    return envs.default_params()


# ---------------------------------------------------------------------------------- systems


def random_seed(seed: int = 0, x: int = X) -> Seed:
    """A made-up LTL seed: random valid sets, plausible tau and c, L in [0, 100]."""
    k_ab, k_l = jax.random.split(jax.random.key(seed))
    antibodies = jax.tree.map(np.asarray, sample_antibodies(k_ab, (x, Y)))
    L = np.asarray(jax.random.uniform(k_l, (x, Y), minval=0.0, maxval=100.0), np.float32)
    tau = np.linspace(90.0, 400.0, x).astype(np.float32)
    collisions = (np.arange(x) % 4).astype(np.int32)
    return Seed(antibodies=antibodies, tau=tau, collisions=collisions, L=L)


def write_seed(path: Path, seed: int = 0) -> Path:
    """A seed directory made with :func:`save_seed` from :func:`random_seed`."""
    return save_seed(path, random_seed(seed), {"command": "tests", "seed": seed, "version": "t"})


@functools.cache
def systems() -> dict[str, System]:
    """SIE, SRL (seeded by :func:`random_seed`), UIE-R1, URL-R1 and HDC."""
    seed = random_seed()
    return {
        name: make_system(name, seed if name in ("SIE", "SRL") else None)
        for name in ("SIE", "SRL", "UIE-R1", "URL-R1", "HDC")
    }


def leaf_array(x) -> np.ndarray:
    """A pytree leaf as NumPy (PRNG keys as their key data)."""
    if jnp.issubdtype(jnp.result_type(x), jax.dtypes.prng_key):
        return np.asarray(jax.random.key_data(x))
    return np.asarray(x)


def tree_equal(a, b) -> bool:
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    return len(la) == len(lb) and all(
        np.array_equal(leaf_array(x), leaf_array(y)) for x, y in zip(la, lb, strict=True)
    )


def stack(items: list) -> object:
    return jax.tree.map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]), *items)


def unstack(tree: object, i: int) -> object:
    return jax.tree.map(lambda a: a[i], tree)


# ---------------------------------------------------------------------------------- controller


@functools.cache
def init_fn():
    """``STL.init`` under one ``jax.jit``."""
    return jax.jit(STL.init)


@functools.cache
def learn_fn():
    """``STL.learn`` under one ``jax.jit`` (every unit test calls this one)."""
    return jax.jit(STL.learn)


@functools.cache
def act_fn():
    """``STL.act`` under one ``jax.jit``."""
    return jax.jit(STL.act)


def percept(
    m, m_prev=0, v=0.0, v_prev=0.0, blue_pixels=0, centroid=7.0, t=1, tick=None, ir=None
) -> Percept:
    """A hand-made percept with fixed dtypes (so the jitted functions never retrace); the batch
    tick defaults to t (as in a running run), the IR readings to Vm ahead (ps0)."""
    ir = [v, 0, 0, 0, 0, 0, 0, 0] if ir is None else ir
    return Percept(
        m=jnp.int32(m),
        m_prev=jnp.int32(m_prev),
        v=jnp.float32(v),
        v_prev=jnp.float32(v_prev),
        ir=jnp.asarray(ir, jnp.float32),
        blue_pixels=jnp.int32(blue_pixels),
        centroid=jnp.float32(centroid),
        t=jnp.int32(t),
        tick=jnp.int32(t if tick is None else tick),
    )


def system(
    *,
    learning: bool = True,
    idiotypic: bool = False,
    replacement: bool = False,
    base: str = "UIE-R1",
    readings: Readings = LITERAL,
) -> System:
    """A system with the given switches over ``base``'s antibodies (default network; the
    literal per-iteration readings unless given, so one call of act is one selection)."""
    s = systems()[base]
    return s.replace(
        learning=jnp.asarray(learning),
        idiotypic=jnp.asarray(idiotypic),
        replacement=jnp.asarray(replacement),
        network=NetworkParams(),
        readings=jax.tree.map(jnp.asarray, readings),
    )


def state(
    sys_: System,
    P,
    *,
    sigma0=None,
    I=None,
    N=None,
    acting: int = 0,
    held: int = 0,
    left: int = 0,
    unseen_run: int = 0,
    obstacle_run: int = 0,
    clear_run: int = 1,
    antibodies=None,
    bout_key: int = 0,
) -> STLState:
    """A hand-made network state (sigma0 defaults to the column means of P); the antibody
    acting is A[acting, held], with ``left`` iterations of its bout (whose behaviour numbers are
    those ``wheel_speeds`` draws from ``jax.random.key(bout_key)``) to go."""
    P = jnp.asarray(P, jnp.float32)
    return STLState(
        antibodies=sys_.antibodies if antibodies is None else antibodies,
        P=P,
        sigma0=jnp.mean(P, axis=0) if sigma0 is None else jnp.asarray(sigma0, jnp.float32),
        I=jnp.zeros(P.shape, jnp.float32) if I is None else jnp.asarray(I, jnp.float32),
        N=jnp.full(P.shape, 1000.0, jnp.float32) if N is None else jnp.asarray(N, jnp.float32),
        counters=PenaltyCounters(
            unseen_run=jnp.int32(unseen_run),
            obstacle_run=jnp.int32(obstacle_run),
            clear_run=jnp.int32(clear_run),
        ),
        acting=jnp.int32(acting),
        bout=Bout(
            antigen=jnp.int32(held),
            left=jnp.int32(left),
            u=jax.random.uniform(jax.random.key(bout_key), (2,)),
        ),
        differences=jnp.int32(0),
        selections=jnp.int32(0),
        replaced=jnp.int32(0),
        chosen=jnp.full(P.shape[1], -1, jnp.int32),
    )


# ---------------------------------------------------------------------------------- episode


@functools.cache
def start_fn():
    """``vmap(start)`` over BATCH runs, jitted once."""
    return jax.jit(jax.vmap(start, in_axes=(0, 0, None, None, None, 0)), static_argnums=(4,))


def iterate_key(key, run, tick, world, sim_params, controller, params, config):
    """``iterate`` with the randomness of ``key`` (as the runner draws it)."""
    return iterate(draws(key, world), run, tick, world, sim_params, controller, params, config)


@functools.cache
def iterate_fn():
    """Unbatched :func:`iterate_key` (STL controller, :data:`CONFIG`), jitted once."""
    return jax.jit(iterate_key, static_argnums=(5, 7))


@functools.cache
def iterate_batch_fn():
    """``vmap(iterate_key)`` over BATCH runs (keys and runs batched), jitted once."""
    return jax.jit(
        jax.vmap(iterate_key, in_axes=(0, 0, None, None, None, None, 0, None)),
        static_argnums=(5, 7),
    )


BATCH_LABELS = ("SIE", "UIE-R1", "URL-R1", "HDC")


def batch_params() -> System:
    """[BATCH] stacked systems (one of each kind that learns differently)."""
    return stack([systems()[k] for k in BATCH_LABELS])


def start_runs(reset_keys: jax.Array, run_keys: jax.Array, params: System | None = None):
    """BATCH runs at t = 0 (batched Run)."""
    params = batch_params() if params is None else params
    return start_fn()(reset_keys, run_keys, world(), sim_params(), STL, params)


def step_one(run, key: jax.Array, params: System, tick=None, config=CONFIG):
    """One unbatched iteration from ``key`` (the tick defaults to run.t)."""
    tick = run.t if tick is None else jnp.int32(tick)
    return iterate_fn()(key, run, tick, world(), sim_params(), STL, params, config)


@functools.cache
def sie_trials(n: int = 2):
    """``make_trials``' run of SIE in :data:`WORLD` with :data:`CONFIG`, ``n`` trials."""
    from jaxais.trials import TrialsConfig, make_trials

    return make_trials(TrialsConfig(world=WORLD, n_trials=n, label="SIE", episode=CONFIG))
