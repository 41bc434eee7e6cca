"""One evaluation for the GA, QDax and evosax (jaxais.ga.evaluation, jaxais.search): a user's
jit of ``make_evaluator``'s function gives the GA's own numbers key for key; QDax's emitter
breeds with the GA's operators inside Table 1's limits; evosax's CMA-ES and SimpleGA search the
network's parameters through ``network_problem``; examples/qdax_map_elites.py fills an archive
with QDax unmodified and its seed runs through reproduce.py.

The GA's programs here are one batch size (8 runs: 2 x 4 robots from one start, 2 sets from 4)
in ga_maze with a 10 s cap, so each compiles once.
"""

from __future__ import annotations

import json
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _python import ROOT, run_python, script_env

from jaxais import envs, ga, search, with_params
from jaxais.immune.antibodies import mutate, sample_antibodies, take, within_limits

CONFIG = ga.GAConfig(populations=2, robots=4, tau_cap=10.0, starts=1, success_starts=4)
GRID = (2, 4)


@pytest.fixture(scope="module")
def maze() -> envs.World:
    return envs.load_world("ga_maze")


@pytest.fixture(scope="module")
def population() -> jax.Array:
    return sample_antibodies(jax.random.key(7), (2, 4, 8))


def tree_equal(a, b) -> None:
    jax.tree.map(
        np.testing.assert_array_equal, jax.tree.map(np.asarray, a), jax.tree.map(np.asarray, b)
    )


@pytest.fixture(scope="module")
def users(maze, population):
    """A user's one jitted program: the GA's evaluation of the population, the success check's of
    two sets from four starts (means over starts), and the population with a visit grid."""
    params = envs.default_params()
    one = ga.make_evaluator(maze, params, CONFIG)
    four = ga.make_evaluator(maze, params, CONFIG, starts=4)
    grid = ga.make_evaluator(maze, params, CONFIG, grid=GRID)

    @jax.jit
    def program(key, sets):
        return one(key, sets), four(key, take(sets, (0, slice(0, 2)))), grid(key, sets)

    return program(jax.random.key(3), population)


KEY_FOR_KEY = f"""
from jaxais import _speed
_speed.setup()  # evolve.py's process settings
import jax, numpy as np
from jaxais import envs, ga
from jaxais.immune.antibodies import sample_antibodies, take
config = ga.{CONFIG!r}
maze, params = envs.load_world("ga_maze"), envs.default_params()
population = sample_antibodies(jax.random.key(7), (2, 4, 8))
sets, key = take(population, (0, slice(0, 2))), jax.random.key(3)
leaves = jax.tree.leaves
equal = lambda a, b: all(np.array_equal(x, y) for x, y in zip(leaves(a), leaves(b)))
user = jax.jit(ga.make_evaluator(maze, params, config))(key, population)[0]
print("evaluate", equal(user, ga.evaluate(key, population, maze, params, config)))
user = jax.jit(ga.make_evaluator(maze, params, config, starts=4))(key, sets)[0]
checked = ga.measure(key, sets, maze, 4, params, config)
print("measure", equal(user, checked), checked.starts)
print("f", np.array_equal(checked.fitness, (8 * checked.collisions + checked.tau) / 2))
"""


@pytest.mark.slow
def test_jitted_evaluate_sets_gives_the_gas_evaluation_key_for_key():
    """A user's jit of ``make_evaluator``'s function, in a process set up as evolve.py sets it
    up, gives the GA's own evaluation and success check (four starts: means over starts)."""
    proc = run_python(KEY_FOR_KEY, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.split() == ["evaluate", "True", "measure", "True", "4", "f", "True"]


def test_grid_keeps_the_numbers_and_the_caps(users):
    (evaluation, _), (checked, _), (gridded, _) = users
    # Keeping the poses for the grid leaves every number as it is (one program).
    tree_equal(gridded, evaluation)
    assert checked.starts == 4 and evaluation.fitness.shape == (2, 4)
    assert np.all(np.asarray(evaluation.tau) <= CONFIG.tau_cap)


@pytest.mark.slow
def test_descriptors_end_pose_and_visit_grid(maze, users):
    (_, descriptors), _, (_, gridded) = users
    pose = np.asarray(descriptors.final_pose)
    assert pose.shape == (2, 4, 1, 3) and descriptors.visits is None
    x0, y0, x1, y1 = np.asarray(maze.arena)
    assert np.all((pose[..., 0] >= x0) & (pose[..., 0] <= x1))
    assert np.all((pose[..., 1] >= y0) & (pose[..., 1] <= y1))
    visits = np.asarray(gridded.visits)
    assert visits.shape == (2, 4, *GRID)
    np.testing.assert_allclose(visits.sum(axis=(-2, -1)), 1.0, rtol=1e-6)
    # Every run starts in the start region (the south-west cell of a 2 x 4 grid) and ends where
    # its final pose is: both cells hold time.
    assert np.all(visits[..., 0, 0] > 0)
    col = np.minimum((pose[..., 0, 0] - x0) / (x1 - x0) * GRID[1], GRID[1] - 1).astype(int)
    row = np.minimum((pose[..., 0, 1] - y0) / (y1 - y0) * GRID[0], GRID[0] - 1).astype(int)
    assert np.all(np.take_along_axis(visits.reshape(8, -1), (row * 4 + col).reshape(8, 1), 1) > 0)
    xy = np.asarray(search.final_position(maze)(descriptors))
    assert xy.shape == (2, 4, 2) and np.all((xy >= 0) & (xy <= 1))
    centre = np.asarray(search.mean_position(gridded))
    assert centre.shape == (2, 4, 2) and np.all((centre > 0) & (centre < 1))


def test_qdax_emitter_breeds_with_the_gas_operators_within_table_1():
    from qdax.core.containers.mapelites_repertoire import (
        MapElitesRepertoire,
        compute_euclidean_centroids,
    )
    from qdax.core.emitters.standard_emitters import MixingEmitter

    sets = sample_antibodies(jax.random.key(0), (6, 8))
    mutation, variation = search.qdax_mutation(), search.qdax_variation()
    # Thin wrappers: the GA's own resampling at 5 %, key for key.
    key = jax.random.key(1)
    tree_equal(mutation(sets, key), mutate(key, sets, 0.05))
    centroids = compute_euclidean_centroids((3, 2), 0.0, 1.0)
    descriptors = jnp.asarray(np.asarray(centroids))  # one set per cell
    repertoire = MapElitesRepertoire.init(sets, -jnp.arange(6.0), descriptors, centroids)
    emitter = MixingEmitter(mutation, variation, variation_percentage=0.5, batch_size=64)
    children, _ = jax.jit(emitter.emit)(repertoire, None, jax.random.key(2))
    assert children.shape == (64, 8)
    assert children.type.dtype == jnp.int32 and children.direction.dtype == jnp.int32
    assert np.all(np.asarray(within_limits(children)))
    # Crossover takes each antigen's antibody from a parent: with mutation off, every child
    # antibody is one of the parents' at that antigen.
    other = take(sets, slice(None, None, -1))
    pure = search.qdax_variation(mutate=False)(sets, other, jax.random.key(3))
    from_a = np.asarray(pure.type) == np.asarray(sets.type)
    from_b = np.asarray(pure.type) == np.asarray(other.type)
    assert np.all(from_a | from_b)


def test_network_problem_refuses_bad_ranges():
    from _stl_fixtures import systems

    sie = systems()["SIE"]
    run = lambda key, system: {}
    for ranges, words in [
        ({}, "at least one"),
        ({"k9": (0, 1)}, "unknown parameter 'k9'"),
        ({"k1": (0, np.inf)}, "finite"),
        ({"k1": (-1, 1)}, "within (0.0, inf)"),
        ({"k1": (1, 1)}, "low < high"),
        ({"k1": "ab"}, "(low, high)"),
    ]:
        with pytest.raises(ValueError) as info:
            search.network_problem(run, sie, ranges)
        assert words in str(info.value) and "\n" not in str(info.value), info.value


@pytest.mark.slow
def test_evosax_cma_es_and_simple_ga_search_the_network_through_network_problem():
    from _stl_fixtures import sie_trials, systems
    from evosax.algorithms import CMA_ES, SimpleGA

    problem = search.network_problem(
        sie_trials(2), systems()["SIE"], {"k1": (0, 2), "k2": (0.5, 1.5)}
    )
    assert problem.num_dims == 2
    population = jax.vmap(problem.sample)(jax.random.split(jax.random.key(0), 4))
    assert np.all((population["k1"] >= 0) & (population["k1"] <= 2))
    assert np.all((population["k2"] >= 0.5) & (population["k2"] <= 1.5))
    state0 = problem.init(jax.random.key(1))
    solution = problem.sample(jax.random.key(2))
    for es in (CMA_ES(population_size=4, solution=solution), SimpleGA(4, solution=solution)):
        params = es.default_params

        @jax.jit
        def generation(key, population, fitness, es=es, params=params):
            k_init, k_ask, k_eval = jax.random.split(key, 3)
            if isinstance(es, SimpleGA):  # population-based: problem.sample's start
                state = es.init(k_init, population, fitness, params)
            else:
                state = es.init(k_init, problem.sample(k_init), params)
            xs, state = es.ask(k_ask, state, params)
            f, _, _ = problem.eval(k_eval, xs, state0)
            return xs, f

        first, _, _ = problem.eval(jax.random.key(4), population, state0)
        xs, f = generation(jax.random.key(5), population, first)
        assert f.shape == (4,) and np.all(np.isfinite(f)), es
        # A candidate's cost is make_trials' mean f of that candidate, common random numbers.
        one = sie_trials(2)(jax.random.key(4), with_params(systems()["SIE"], {
            "k1": population["k1"][0], "k2": population["k2"][0]}))["fitness"].mean()  # fmt: skip
        np.testing.assert_allclose(first[0], one, rtol=1e-6)


@pytest.mark.slow
def test_map_elites_example_exports_a_seed_in_the_usual_format(tmp_path):
    env = script_env()
    me = subprocess.run(
        [sys.executable, "examples/qdax_map_elites.py", "--tiny", "--out", str(tmp_path / "me")],
        cwd=ROOT, capture_output=True, text=True, env=env, timeout=600,
    )  # fmt: skip
    assert me.returncode == 0, me.stderr[-3000:]
    assert "MAP-Elites in ga_maze: 2 iterations of 16" in me.stdout
    summary = json.loads((tmp_path / "me" / "summary.json").read_text())
    assert len(set(summary["seed"]["cells"])) == 5  # five cells, five behaviours
    assert (tmp_path / "me" / "archive.png").stat().st_size > 0
    from jaxais.seed import load_seed

    seed, meta = load_seed(tmp_path / "me" / "seed")
    assert seed.antibodies.shape == (5, 8) and np.all(within_limits(seed.antibodies))
    assert meta["made_by"] == "examples/qdax_map_elites.py"
    assert meta["command"].startswith("qdax_map_elites.py --tiny")
    # The usual format: the seed seeds SIE as any LTL seed does, through the loader reproduce.py's
    # --seeds uses (tests/test_scripts_stl.py runs reproduce.py on a seed folder; the full seed's
    # reproduction is docs/map_elites/reproduction), in the trials program compiled above.
    from _stl_fixtures import sie_trials

    from jaxais.systems import make_system

    res = sie_trials(2)(jax.random.key(0), make_system("SIE", tmp_path / "me" / "seed"))
    assert res["fitness"].shape == (2,) and np.all(np.isfinite(res["fitness"]))
    assert np.all(res["iterations"] > 0)
