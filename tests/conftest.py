"""Shared compiled simulator functions for the simulator tests (compiled once per world).

Compiling a step takes seconds on a CPU, so every test calls the same few jitted functions with
the same batch size: one compilation per world for the session.
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import reference_sim as ref
from _python import TEST_XLA_FLAGS

from jaxais import _speed, envs

# Every test program compiles without LLVM's optimisations (XLA's own passes still run): compiling
# is most of the suite's time, and a test checks what a program computes, not how fast. The
# scripts the tests start inherit it (tests/_python.py), as a user's XLA_FLAGS; the scripts' own
# XLA flags follow (_speed.setup), before JAX starts its backend. The few claims that hold only
# for the shipped settings (one program's bits against another's) run in a fresh interpreter
# without it (tests/_python.py: shipped_env).
os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {TEST_XLA_FLAGS}".strip()
# One compilation cache for the whole run, never the user's: the test processes (xdist's workers
# inherit the folder from the process that made it) and the scripts they start, every program
# however fast it compiled. A program that several tests, workers or script runs compile (the
# same program from a fresh jit, a fixture that two files share) compiles once.
if "JAXAIS_TESTS_CACHE" not in os.environ:
    os.environ["JAXAIS_TESTS_CACHE"] = tempfile.mkdtemp(prefix="jaxais-tests-xla-")
    atexit.register(shutil.rmtree, os.environ["JAXAIS_TESTS_CACHE"], ignore_errors=True)
os.environ[_speed.CACHE_ENV] = os.environ["JAXAIS_TESTS_CACHE"]
os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)  # read at JAX's import
_speed.setup()
XLA_FLAGS = os.environ["XLA_FLAGS"]
"""The flags every test starts with: the tests' and the scripts' own (``_speed.setup``)."""


@pytest.fixture(autouse=True)
def _suite_xla_flags():
    """After each test, the suite's XLA flags again: a script's ``main`` run in a test process
    adds its own (a device per core), which the processes that later tests of
    this worker start would otherwise inherit."""
    yield
    os.environ["XLA_FLAGS"] = XLA_FLAGS


LONGEST_FIRST = (
    "test_resume.py", "test_scripts_stl.py", "test_trials.py", "test_brax.py",
    "test_scripts_render_bench.py", "test_env_examples.py", "test_ga.py", "test_behaviour_level.py",
    "test_controllers.py", "test_ablate.py", "test_distributed.py", "test_evolve_script.py",
)  # fmt: skip
"""Test files of over about 35 s (``--durations=0``, summed per file), longest first."""


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The longest files first: ``-n 2 --dist loadfile`` hands out files in this order as the
    workers free up, so the run ends on short files, not on one worker alone in a long one."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


BATCH = 8
"""Robots per batched call (a fixed size, so that no test triggers a new compilation)."""
OBS_BATCH = 32
"""Poses per batched ``observe`` call (padded)."""


def clearances(state: envs.State, world: envs.World, params: envs.SimParams) -> jnp.ndarray:
    """[1 + W] clearance of the robot and of each wanderer to everything else, m."""
    robots = jnp.concatenate([state.pose[None, :2], state.wanderers[:, :2]])
    return jnp.stack(
        [
            envs.min_gap(robots[k], params.body_radius, envs.build_scene(state, world, params, k))
            for k in range(robots.shape[0])
        ]
    )


def _step(key, state, wheels, world, params):
    new, obs = envs.step(key, state, wheels, world, params)
    return new, obs, envs.sample_step_noise(key, world), clearances(new, world, params)


def _reset(key, world, params):
    state = envs.reset(key, world, params)
    return state, clearances(state, world, params)


class Sim:
    """Batched, jitted simulator calls on ``BATCH`` robots, and helpers to build their inputs.

    Made once per session (JAX is first touched here, not at import): each function compiles
    once per world and batch size, and every test uses the same batch sizes.
    """

    batch = BATCH

    def __init__(self) -> None:
        self.params = envs.default_params()
        self.params_np = ref.params_to_numpy(self.params)
        # Noise-free IR for the geometry tests of observe (steps keep every world's IR noise).
        self.quiet_params = envs.default_params(ir_noise=np.zeros(10, np.float32))
        self._worlds: dict[str, envs.World] = {}
        self._step_b = jax.jit(jax.vmap(_step, in_axes=(0, 0, 0, None, None)))
        self._reset_b = jax.jit(jax.vmap(_reset, in_axes=(0, None, None)))
        self._step_1 = jax.jit(envs.step)
        self._observe_b = jax.jit(jax.vmap(envs.observe, in_axes=(0, 0, None, None)))

    def world(self, name: str) -> envs.World:
        """A built-in world, loaded once."""
        if name not in self._worlds:
            self._worlds[name] = envs.load_world(name)
        return self._worlds[name]

    @staticmethod
    def keys(seed: int, n: int = BATCH) -> jax.Array:
        """``n`` keys split from ``key(seed)``."""
        return jax.random.split(jax.random.key(seed), n)

    def reset(self, world: envs.World, keys: jax.Array) -> tuple[envs.State, np.ndarray]:
        """``vmap(reset)`` over ``BATCH`` keys; also the clearances [BATCH, 1 + W]."""
        assert keys.shape == (BATCH,)
        state, gaps = self._reset_b(keys, world, self.params)
        return state, np.asarray(gaps)

    def step(self, world: envs.World, keys: jax.Array, state: envs.State, wheels: Any):
        """``vmap(step)`` over ``BATCH`` robots.

        Returns:
            (new state, observation, that step's noise draws, clearances [BATCH, 1 + W]).
        """
        assert keys.shape == (BATCH,)
        wheels = jnp.asarray(wheels, jnp.float32)
        new, obs, noise, gaps = self._step_b(keys, state, wheels, world, self.params)
        return new, obs, noise, np.asarray(gaps)

    def step_one(self, world: envs.World, key: jax.Array, state: envs.State, wheels: Any):
        """Unbatched ``step`` (jitted), for comparison with the batched one."""
        return self._step_1(key, state, jnp.asarray(wheels, jnp.float32), world, self.params)

    def observe(self, world: envs.World, states: list[envs.State]) -> dict[str, np.ndarray]:
        """Noise-free IR observations of unbatched states (any number), stacked on axis 0."""
        out: list[dict[str, np.ndarray]] = []
        for lo in range(0, len(states), OBS_BATCH):
            chunk = states[lo : lo + OBS_BATCH]
            padded = chunk + [chunk[-1]] * (OBS_BATCH - len(chunk))
            batch = jax.tree.map(lambda *xs: np.stack(xs), *padded)
            obs = self._observe_b(self.keys(lo, OBS_BATCH), batch, world, self.quiet_params)
            out.append({k: v[: len(chunk)] for k, v in ref.obs_to_numpy(obs).items()})
        return {k: np.concatenate([o[k] for o in out]) for k in out[0]}

    @staticmethod
    def with_poses(state: envs.State, poses: Any) -> envs.State:
        """A batched state with the robots' poses [BATCH, 3] replaced."""
        return state.replace(pose=jnp.asarray(poses, jnp.float32))

    def clear_poses(self, state: envs.State, world: envs.World, poses: Any) -> np.ndarray:
        """Robot poses [BATCH, 3]: each row of ``poses`` where it overlaps nothing in its robot's
        state (per the NumPy reference, with 0.1 mm to spare), else that robot's current pose."""
        wnp = ref.world_to_numpy(world)
        batch = ref.state_to_numpy(state)
        out = batch["pose"].copy()
        for i, pose in enumerate(np.asarray(poses, np.float32).astype(np.float64)):
            one = ref.unbatch(batch, i) | {"pose": pose}
            if ref.clearances(one, wnp, self.params_np).min() > 1e-4:
                out[i] = pose
        return out

    def random_clear_poses(self, state: envs.State, world: envs.World, fractions: Any):
        """:meth:`clear_poses` at ``fractions`` [BATCH, 3] of the arena's width, height and of
        a turn (0 -> -pi, 1 -> pi)."""
        arena = np.asarray(world.arena, np.float64)
        f = np.asarray(fractions, np.float64)
        poses = np.stack(
            [
                arena[0] + f[:, 0] * (arena[2] - arena[0]),
                arena[1] + f[:, 1] * (arena[3] - arena[1]),
                np.pi * (2.0 * f[:, 2] - 1.0),
            ],
            axis=1,
        )
        return self.clear_poses(state, world, poses)


PROBE_WORLD = """
# A bare 3 m x 2 m room for sensor tests; the box and goal are moved through the state.
name = "probe"

[arena]
width = 3.0
height = 2.0
wall_height = 0.1

[robot]
start_region = [0.2, 0.2, 0.8, 0.8]
start_heading = [-3.14159, 3.14159]

[goal]
shape = "box"
half_size = [0.05, 0.05]
height = 0.1
region = [1.5, 1.5, 1.8, 1.8]

[[walls]]  # a painted wall segment
from = [2.5, 0.2]
to = [2.5, 0.6]
material = "marker"

[[boxes]]  # a thin wall, 0.4 m long north-south
region = [0.5, 0.5, 2.5, 1.5]
half_size = [0.01, 0.2]
height = 0.1
"""
"""The sensor-test world (no wanderers, no noise): text of a world file."""


@pytest.fixture(scope="session")
def probe_world(tmp_path_factory: pytest.TempPathFactory) -> envs.World:
    """:data:`PROBE_WORLD`, written to a file and loaded."""
    path = tmp_path_factory.mktemp("worlds") / "probe.toml"
    path.write_text(PROBE_WORLD)
    return envs.load_world(path)


@pytest.fixture(scope="session")
def sim() -> Sim:
    """The shared batched simulator."""
    return Sim()
